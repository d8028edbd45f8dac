"""The encoder-scale rows' parameters whose truth is zero (the joints the effect was not
injected on), per robot: mean z = estimate / posterior std, the share below zero and the
count beyond 3 sigma. An unbiased fit centres them on zero.

    python reports/effects/null_scales.py reports/effects/effects_table.json [older.json ...]

(e.g. an older table: git show d61c981:reports/effects/effects_table.json > /tmp/old.json)
"""
import json, sys, numpy as np
for f in sys.argv[1:]:
    d = json.load(open(f))
    print(f, "commit", d.get("code", {}).get("commit", "?")[:7])
    for robot in ("a3", "a2", "unitree_g1"):
        z = [p["z"] for r in d["rows"] if r["robot"] == robot and r["effect"] == "encoder_scale"
             for n, p in r["parameters"].items() if p["true"] == 0.0 and p["z"] is not None]
        print(f"  {robot}: zero-truth scale parameters n={len(z)} mean z {np.mean(z):+.2f}, share negative {np.mean(np.array(z) < 0):.2f}, |z|>3 {np.sum(np.abs(z) > 3)}")
