"""What every method and the framework share, grouped by concept:

- `problem`: the contact-constrained problem: residuals (inter-foot transform,
  flat ground), terms, the solver, frame selection, and the fit the framework runs
  (segments, generalized least squares, frame residuals);
- `imu`: the pelvis IMU: levelling, tilt, motion compensation, tilt noise;
- `checks`: data checks before and after a fit, the per-stance contact check;
- `modelgap`: effects the offsets-only model lacks, their library, confounds and the
  score tests that trace a residual;
- `information`: noise levels, whitening, observability, the posterior, stance design
  and the information gain.
"""
