"""Scores against the simulator's ground truth (recovery, held-out foot height)."""
