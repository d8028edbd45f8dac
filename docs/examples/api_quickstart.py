"""The Python API in a few lines: collect a session, calibrate, score, diagnose, walk,
and the closed-loop evaluation (short settings so it runs in about a minute; the
defaults are the paper's: 12 s stances, 20 s walks, 35 trials)."""

import numpy as np

import legcal_bench as lb

out = "runs/api_quickstart"
lb.collect(f"{out}/set", robot="a3", sensors="realistic", seed=0, stance_s=6.0, heldout=1, heldout_s=4.0)

result = lb.calibrate(f"{out}/set", robot="a3")  # interfoot, its default (sensor) setting
result.save(f"{out}/result.json")  # what `legcal-bench calibrate --out` writes
print("offsets (deg):", np.rad2deg(result.offsets_vector(["left_knee_joint", "right_knee_joint"])).round(3))

scores = lb.score(f"{out}/set", result)  # what `legcal-bench score --json` prints
print(f"recovery RMS {scores['recovery']['rms_error_deg']:.4f} deg; held-out foot height RMS "
      f"{scores['heldout']['foot_height_rms_mm']['after']:.3f} mm")

report = lb.diagnose(f"{out}/set", robot="a3", result=result)  # what diagnosis.json holds
print(report["summary"])

w = lb.walk(robot="a3", policy="a3", offsets="paper@3", correction=result, seconds=3.0)
print("corrected walk:", "upright" if w.upright else "fell", f"{w.summary()['distance_m']:.2f} m")

summary, trials = lb.walk_eval(robot="a3", policy="a3", offsets="paper@3", trials=1, seconds=2.0)
print("closed loop, trials:", len(trials))
