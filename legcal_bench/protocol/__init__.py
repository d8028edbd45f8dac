"""The stance protocol and session collection: what a robot is asked to do, and what it logs."""
