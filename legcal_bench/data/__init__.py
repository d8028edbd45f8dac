"""The recording format shared by simulation and real robots, and its validating loader."""
