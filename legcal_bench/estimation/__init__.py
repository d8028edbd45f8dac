"""What the estimators share: IMU levelling, the paper's residuals and Jacobians,
frame selection, noise levels, observability and the information gain."""
