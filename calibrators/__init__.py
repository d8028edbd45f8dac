"""Calibration methods. `base` is the interface every method implements (and the
entry-point registry that finds them); `interfoot` (the paper's), `yamane` (sole
heights + IMU) and `zero` (no correction) are legcal-bench's own, registered exactly
as a third-party method would be."""
