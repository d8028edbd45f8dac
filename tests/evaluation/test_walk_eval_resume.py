"""`walk-eval` never loses a run (issue #40, item 5): each trial written as it finishes,
a killed run resumed to the report an uninterrupted run writes, no user text in a file
name, `random:<deg>@<seed>`, and words (not "0/0" or "nan") where no trial calibrated."""

from __future__ import annotations

import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

REPO = Path(__file__).resolve().parents[2]
# Tiny: two trials of 1 s walks on the A3-like robot with our policy, run here (no workers).
BASE = ["walk-eval", "--robot", "a3", "--policy", "a3", "--offsets", "random:3@5", "--workers", "1", "--quiet"]
ARGS = [*BASE, "--trials", "2", "--seconds", "1"]


def _report(folder: Path) -> tuple[str, dict, bytes]:
    """(report.md, report.json, paths.png) with the code's description taken out: the
    tree may change under a test (other work in the checkout), the report may not."""
    data = json.loads((folder / "report.json").read_text())
    code = data.pop("code")
    return (folder / "report.md").read_text().replace(code, "<code>"), data, (folder / "paths.png").read_bytes()


def test_a_killed_run_resumes_to_the_report_of_an_uninterrupted_run(tmp_path, capsys):
    from legcal_bench.cli import main

    killed, whole = tmp_path / "killed", tmp_path / "whole"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    p = subprocess.Popen([sys.executable, "-c", "import sys; from legcal_bench.cli import main; sys.exit(main())",
                          *ARGS, "--out", str(killed)], cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.monotonic() + 180
        while not list((killed / "trials").glob("*.json")):
            assert p.poll() is None, p.stderr.read().decode()[-2000:]
            assert time.monotonic() < deadline, "no trial file within 180 s"
            time.sleep(0.05)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(p.pid, signal.SIGKILL)  # the process this test started (its own group)
        p.wait()
        p.stderr.close()
    assert len(list((killed / "trials").glob("*.json"))) == 1 and not (killed / "report.md").exists()

    assert main([*ARGS, "--out", str(killed)]) == 0  # the rerun: takes the finished trial, runs the other
    assert "resumed: 1 of 2 trial(s)" in capsys.readouterr().out
    assert main([*ARGS, "--out", str(whole)]) == 0
    assert "resumed:" not in capsys.readouterr().out
    assert _report(killed) == _report(whole)
    names = sorted(p.name for p in (killed / "trials").iterdir())
    assert names == sorted(p.name for p in (whole / "trials").iterdir())  # the same keys, whichever folder
    assert [n[:6] for n in names] == ["s0000_", "s0001_"]
    timings = json.loads((killed / "timings.json").read_text())["evaluations"][0]["trials"]
    assert [t["computed"] for t in timings] == ["an earlier run", "this run"]

    # Other settings into the same folder: other keys, their own trials, never the others'.
    assert main([*BASE, "--trials", "1", "--seconds", "0.5", "--out", str(whole)]) == 0
    assert "resumed:" not in capsys.readouterr().out
    assert len(list((whole / "trials").glob("*.json"))) == 3
    data = json.loads((whole / "report.json").read_text())
    assert data["summaries"][0]["config"]["seconds"] == 0.5 and len(data["trials"][0]) == 1


def test_random_with_a_seed_fixes_the_pattern():
    from legcal_bench.errors import OffsetSpecError
    from legcal_bench.evaluation.walk import PATTERN_SEED_BASE, trial_offsets
    from legcal_bench.robots import load_robot
    from legcal_bench.sim.offsets import resolve_offsets, with_magnitude

    legmap = load_robot("a3")
    default = [trial_offsets("random:3", legmap, s) for s in range(3)]
    # Unchanged without @seed: trial s draws from PATTERN_SEED_BASE + s.
    assert np.array_equal(default[1], np.random.default_rng(PATTERN_SEED_BASE + 1).uniform(-1, 1, 12) * np.deg2rad(3))
    assert all(np.array_equal(a, trial_offsets(f"random:3@{PATTERN_SEED_BASE}", legmap, s))
               for s, a in enumerate(default))
    seeded = [trial_offsets("random:3@7", legmap, s) for s in range(3)]
    assert all(np.array_equal(a, trial_offsets("random:3@7", legmap, s)) for s, a in enumerate(seeded))  # reproducible
    assert not any(np.array_equal(a, b) for a in seeded for b in default)  # not the default patterns
    assert not np.array_equal(seeded[0], seeded[1]) and np.array_equal(seeded[1], trial_offsets("random:3@8", legmap, 0))
    assert np.abs(seeded[0]).max() <= np.deg2rad(3)
    # One pattern (a session set's offsets): the seed fixes it whatever the caller's generator.
    assert np.array_equal(resolve_offsets("random:3@7", legmap, np.random.default_rng(99)),
                          resolve_offsets("random:3@7", legmap))
    assert with_magnitude("random:3@7", 1.5) == "random:1.5@7" and with_magnitude("paper@3", 2) == "paper@2"
    for bad, said in (("random:3@x", "whole number"), ("random:3@-1", "whole number"), ("random:x@1", "random:<deg>"),
                      ("random:12@1", r"\[0, 10\]")):
        with pytest.raises(OffsetSpecError, match=said):
            trial_offsets(bad, legmap, 0)
    with pytest.raises(OffsetSpecError, match="a sweep needs"):
        with_magnitude("paper", 1)


def test_explicit_offsets_at_full_precision_make_a_report_with_fixed_file_names(tmp_path, capsys):
    from legcal_bench.cli import main
    from legcal_bench.reports.closed_loop import plot_title

    dq = np.random.default_rng(3).uniform(-0.05, 0.05, 12)
    spec = ",".join(repr(float(x)) for x in dq)  # ~250 characters
    assert main(["walk-eval", "--robot", "a3", "--policy", "a3", f"--offsets={spec}", "--trials", "1", "--seconds",
                 "0.5", "--workers", "1", "--quiet", "--out", str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["paths.png", "report.json", "report.md", "timings.json",
                                                          "trials"]
    assert all(re.fullmatch(r"s\d{4}_[0-9a-f]{16}\.json", p.name) for p in (tmp_path / "trials").iterdir())
    md = (tmp_path / "report.md").read_text()
    assert "## offsets `12 explicit offsets`" in md and spec in md  # the exact spec stays in the text
    data = json.loads((tmp_path / "report.json").read_text())
    title = plot_title(data["summaries"][0]["config"], data["trials"][0][0])
    assert all(len(line) <= 80 for line in title.splitlines()) and f"{np.degrees(dq[0]):+.1f}" in title
    assert not re.search(r"\"(static_s|wall_s|walk_s)\"", json.dumps(data))  # timings apart
    assert "static_s" in (tmp_path / "timings.json").read_text()


def test_a_run_with_no_calibrated_trial_says_so_in_words(monkeypatch, tmp_path, capsys):
    import legcal_bench.protocol.collect as collect_module
    from legcal_bench.cli import main
    from legcal_bench.errors import HoldError

    def cannot_hold(*args, **kwargs):
        raise HoldError("segment stance_I: the robot did not hold the posture. Fix: stiffer gains")

    monkeypatch.setattr(collect_module, "collect", cannot_hold)
    assert main(["walk-eval", "--robot", "a3", "--policy", "a3", "--trials", "2", "--seconds", "0.5", "--workers",
                 "1", "--out", str(tmp_path), "--quiet"]) == 0
    printed, md = capsys.readouterr().out, (tmp_path / "report.md").read_text()
    for text in (printed, md):
        assert "No trial was calibrated" in text and "| corrected | no calibrated trial |" in text
        assert "No leg-odometry check" in text and "2 trial(s) without a calibration" in text
        assert "0/0" not in text and not re.search(r"\bnan\b|\binf\b|nanx|infx", text, re.IGNORECASE)
    assert "offsets paper@3: no trial was calibrated" in printed
    s = json.loads((tmp_path / "report.json").read_text())["summaries"][0]
    assert s["calibrated"] == 0 and s["ratios"]["pelvis_rms_mm"] == {"corrected_over_uncorrected": None,
                                                                    "corrected_over_oracle": None}


def test_the_oracle_wording_follows_its_distance_from_nominal():
    from legcal_bench.reports.closed_loop import oracle_text

    def summary(oracle_mm, spread_mm):
        d = {"mean": oracle_mm, "max": 1.5 * oracle_mm, "n": 3}
        sp = {"mean": spread_mm, "std": 1.0, "n": 3}
        return {"config": {"policy": "examples/unitree_g1.policy.yaml"},
                "oracle_distance": {"pelvis_rms_mm": d, "foot_strike_rms_mm": d},
                "nominal_spread": {"pelvis_rms_mm": sp, "foot_strike_rms_mm": sp},
                "ratios": {k: {"corrected_over_uncorrected": 0.01, "corrected_over_oracle": 2.0}
                           for k in ("pelvis_rms_mm", "foot_strike_rms_mm")}}

    at_rounding, within, farther = (oracle_text(summary(o, 30.0)) for o in (0.2, 12.0, 60.0))
    assert "repeats the nominal walk up to rounding" in at_rounding and "2.00x" not in at_rounding
    assert "within the nominal seed-to-seed spread" in within and "2.00x" in within
    assert "farther from the nominal walk than the nominal seed-to-seed spread" in farther
    assert "pelvis 60.0 mm mean, 90.0 mm max" in farther and "unitree_g1.policy.yaml" in farther
    assert not any("up to rounding" in t and "repeats" in t for t in (within, farther))
