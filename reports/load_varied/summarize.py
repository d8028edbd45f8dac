"""Summarize the load-varied protocol check (see README.md here): per robot and stance
set, the knee compliance's closest other parameter once the offsets absorbed what they
can (cosine, from the confound report) and the posterior standard deviations of the
knee compliance and knee encoder scale, over the seeds' result files."""

import json
import sys
from pathlib import Path

import numpy as np

here = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent)
print("| robot | stances | knee compliance: closest other parameter beyond the offsets (cosine, mean of legs x seeds) "
      "| partner | knee compliance std (rad/N m) | knee encoder-scale std |")
print("|---|---|---|---|---|---|")
for robot in ("a3", "a2", "unitree_g1"):
    for variant, stances in (("default", "I II III IV"), ("pushed", "I II III IV push press")):
        cos, partners, std_c, std_s = [], set(), [], []
        for f in sorted(here.glob(f"{robot}_{variant}_s*.json")):
            e = json.loads(f.read_text())["diagnostics"]["effects"]
            params = e["confounds"]["effects"]["compliance"]["parameters"]
            for side in ("left", "right"):
                name = next(k for k in params if k.endswith(f"{side}_knee"))
                c = params[name]["closest_beyond_offsets"]
                cos.append(c["cosine"])
                partners.add(c["parameter"].split(".")[0] + (" knee" if "knee" in c["parameter"] else " ankle pitch"))
                std_c.append(e["parameters"][name]["std"])
                std_s.append(e["parameters"][name.replace("compliance", "encoder_scale")]["std"])
        if cos:
            print(f"| {robot} | {stances} | {np.mean(cos):.2f} ({min(cos):.2f}-{max(cos):.2f}, n={len(cos)}) | "
                  f"{', '.join(sorted(partners))} | {np.mean(std_c):.2e} | {np.mean(std_s):.2e} |")
