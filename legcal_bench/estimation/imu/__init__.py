"""The pelvis IMU: levelling, tilt, motion compensation and the tilt noise the data show."""
