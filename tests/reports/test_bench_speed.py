"""bench-speed's summary: the ratio's direction, stage rows, targets, the offsets check
(the probes themselves run in `legcal-bench bench-speed`, minutes a group)."""

from __future__ import annotations

import json

import pytest

from legcal_bench.reports.bench_speed import DEFAULT_GROUPS, GROUPS, HERE, summarize


def _run(cases: dict) -> dict:
    return {"cases": cases}


def test_times_speed_up_as_old_over_new_and_rates_as_new_over_old():
    runs = {"calibration": {
        "old": [_run({"interfoot_end_to_end_sensor": {"unit": "s", "values": [2.0, 2.2, 1.8],
                                                      "offsets": [0.0, 0.01],
                                                      "stages": {"solve": [1.0, 1.0, 1.0], "gls": [0.0, 0.0, 0.0]}},
                      "collect_weld_frames_per_s": {"unit": "frames/s", "values": [1000.0]}})],
        "new": [_run({"interfoot_end_to_end_sensor": {"unit": "s", "values": [0.5, 0.4, 0.6],
                                                      "offsets": [0.0, 0.01 + 1e-9],
                                                      "stages": {"solve": [0.25, 0.25, 0.25], "gls": [0.1, 0.1, 0.1]}},
                      "collect_weld_frames_per_s": {"unit": "frames/s", "values": [3000.0]}})]}}
    rows, stages = summarize(runs)
    by = {r["case"]: r for r in rows}
    e2e = by["interfoot_end_to_end_sensor"]
    assert (e2e["old"], e2e["new"], e2e["speedup"]) == (2.0, 0.5, 4.0)
    assert e2e["target"] == "<= 0.15" and e2e["met"] is False
    assert e2e["max_offset_difference_deg"] == pytest.approx(5.7295779513e-08)
    assert by["collect_weld_frames_per_s"]["speedup"] == 3.0
    st = {s["stage"]: s for s in stages}
    assert st["solve"]["speedup"] == 4.0
    assert st["gls"]["speedup"] is None  # the baseline did not run that stage


def test_a_case_only_one_version_has_gets_no_ratio():
    runs = {"startup": {"old": [], "new": [_run({"help": {"unit": "s", "values": [0.3, 0.2, 0.4]}})]}}
    (row,), _ = summarize(runs)
    assert row["old"] is None and row["speedup"] is None and row["new"] == 0.3 and row["met"] is True


def test_the_default_groups_have_their_probe_scripts():
    assert all((HERE / GROUPS[g][0]).is_file() for g in DEFAULT_GROUPS)


def test_a_stopped_run_resumes_from_the_probe_runs_it_kept(tmp_path, monkeypatch):
    from legcal_bench.reports import bench_speed

    calls = []

    def probe(group, repeats, pythonpath, data, robot, src):
        calls.append(group)
        if len(calls) == 2:
            raise RuntimeError("the second probe run fails")
        return _run({"help": {"unit": "s", "values": [0.1 * len(calls)]}})

    monkeypatch.setattr(bench_speed, "run_probe", probe)
    kwargs = dict(baseline="none", groups=("startup",), rounds=3, progress=False)
    with pytest.raises(RuntimeError, match="second"):
        bench_speed.run_bench_speed(tmp_path, **kwargs)
    assert (tmp_path / bench_speed.PARTIAL_NAME).is_file() and len(calls) == 2
    bench_speed.run_bench_speed(tmp_path, **kwargs)  # the first round's run is kept; two more
    assert len(calls) == 4 and not (tmp_path / bench_speed.PARTIAL_NAME).exists()
    kept = json.loads((tmp_path / "report.json").read_text())["runs"]["startup"]["new"]
    assert [r["cases"]["help"]["values"] for r in kept] == [[0.1], [pytest.approx(0.3)], [pytest.approx(0.4)]]
    calls.clear()
    bench_speed.run_bench_speed(tmp_path, **{**kwargs, "rounds": 1})  # a finished run starts afresh
    assert len(calls) == 1


def test_a_report_is_written_again_from_its_runs(tmp_path, monkeypatch):
    from legcal_bench.reports import bench_speed

    monkeypatch.setattr(bench_speed, "run_probe", lambda *a: _run({"help": {"unit": "s", "values": [0.2]}}))
    first = bench_speed.run_bench_speed(tmp_path, baseline="none", groups=("startup",), rounds=1, progress=False)
    assert "| `legcal-bench --help`, s | – | 0.200 | – | <= 0.5 | yes |" in first
    monkeypatch.setitem(bench_speed.TARGETS, "help", ("help, relabelled", None))
    again = bench_speed.rerender(tmp_path)
    assert "| help, relabelled | – | 0.200 |" in again and "Medians over 1 rounds" in again


def _imports_outside_fallbacks(tree) -> list[tuple[str, str, int]]:
    """(module, name, line) of each `from legcal_bench... import name` not inside a try
    whose handler catches ImportError (a probe's fallback for an older layout)."""
    import ast

    guarded = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Try) and any(
                h.type is None or "ImportError" in ast.dump(h.type) for h in node.handlers):
            for inner in node.body:
                guarded |= {id(n) for n in ast.walk(inner)}
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("legcal_bench") and id(node) not in guarded:
            out += [(node.module, a.name, node.lineno) for a in node.names]
    return out


def test_the_probes_use_only_what_the_oldest_baseline_has():
    """Each probe runs on the baseline's package too (`bench-speed`'s default BASELINE, the
    oldest it compares against): a name it imports from legcal_bench outside an
    ImportError fallback must exist in that commit's source, or the old side of every
    comparison fails (the probes once had to keep `tempfile` for this: files.scratch is
    younger than the baseline)."""
    import ast
    import re
    import subprocess

    from legcal_bench.reports.bench_speed import BASELINE, _repo_root

    root = _repo_root()
    if subprocess.run(["git", "cat-file", "-e", f"{BASELINE}^{{commit}}"], cwd=root, capture_output=True).returncode:
        pytest.skip(f"this clone lacks the baseline commit {BASELINE} (a shallow clone): nothing to compare with")

    def source(module: str) -> str | None:
        parts = module.split(".")
        top = parts[1] if len(parts) > 1 else ""
        base = [top] + parts[2:] if top in ("calibrators", "envs", "policies", "examples") else parts
        for path in ("/".join(base) + ".py", "/".join(base) + "/__init__.py"):
            r = subprocess.run(["git", "show", f"{BASELINE}:{path}"], cwd=root, capture_output=True, text=True)
            if r.returncode == 0:
                return r.stdout
        return None

    missing = []
    probes = sorted({script for script, _, _ in GROUPS.values()})
    for probe in probes:
        for module, name, line in _imports_outside_fallbacks(ast.parse((HERE / probe).read_text())):
            text = source(module)
            defined = text is not None and (source(f"{module}.{name}") is not None or re.search(
                rf"^(def|class) {name}\b|^{name}\s*[:=]|^from \S+ import .*\b{name}\b|^import .*\b{name}\b",
                text, re.M))
            if not defined:
                missing.append(f"{probe}:{line}: {module}.{name}")
    assert not missing, f"not in {BASELINE}: {missing}"
    assert len(probes) == 5


def test_the_tests_probe_runs_the_suite_as_its_trees_make_test_does(tmp_path, monkeypatch):
    # Its process count, and bytecode caching where that tree's Makefile lets Python cache.
    import subprocess

    from legcal_bench.reports import tests_probe

    seen = []
    monkeypatch.setattr(subprocess, "run", lambda argv, cwd, env, **kw: seen.append((argv, env)) or
                        subprocess.CompletedProcess(argv, 0, "1 passed in 1.0s\n", ""))
    monkeypatch.setenv("PYTHONDONTWRITEBYTECODE", "1")
    monkeypatch.delenv("TEST_WORKERS", raising=False)
    (tmp_path / "Makefile").write_text("test:\n\tpython -m pytest -n $(TEST_WORKERS)\n")
    assert tests_probe.run_suite(str(tmp_path))["counts"] == {"passed": 1}
    (tmp_path / "Makefile").write_text("unexport PYTHONDONTWRITEBYTECODE\ntest:\n\tpython -m pytest -n $(TEST_WORKERS)\n")
    tests_probe.run_suite(str(tmp_path))
    (old_argv, old_env), (new_argv, new_env) = seen
    assert old_argv[3:5] == new_argv[3:5] == ["-n", "2"]
    assert old_env["PYTHONDONTWRITEBYTECODE"] == "1" and "PYTHONDONTWRITEBYTECODE" not in new_env


def test_a_case_the_baseline_lacks_is_reported_as_such_not_a_key_error(tmp_path, monkeypatch):
    # The default baseline's probe runs have no `interfoot_door` (the door is younger).
    from legcal_bench.reports import bench_speed

    runs = {"calibration": {
        "old": [_run({"interfoot_solve": {"unit": "s", "values": [0.2]}})],
        "new": [_run({"interfoot_solve": {"unit": "s", "values": [0.1]},
                      "interfoot_door": {"unit": "s", "values": [0.3]}})]}}
    rows, _ = summarize(runs)
    door = next(r for r in rows if r["case"] == "interfoot_door")
    assert door["old"] is None and door["speedup"] is None and door["new"] == 0.3
    text = bench_speed.render(tmp_path, runs, {"command": "c", "provenance": {"commit": "x", "dirty": False},
                                                "baseline": "4bd338d", "rounds": 1, "repeats": {}})
    assert "| 0.300 | not in the baseline |" in text and "| 0.100 | 2.00x |" in text


def test_the_baseline_is_a_checkout_whose_packages_are_its_own(tmp_path):
    """A local clone at the commit (git works in it, so its tests run), and imported from
    it, the packages pyproject maps from other folders are the clone's too, not the
    editable install's of the code at hand."""
    import os
    import subprocess
    import sys

    from legcal_bench.reports.bench_speed import _repo_root, install_baseline

    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=_repo_root(), capture_output=True, text=True,
                          check=True).stdout.strip()
    src = install_baseline(head, tmp_path / "baseline")
    assert subprocess.run(["git", "rev-parse", "HEAD"], cwd=src, capture_output=True, text=True,
                          check=True).stdout.strip() == head
    assert subprocess.run(["git", "status", "--porcelain"], cwd=src, capture_output=True, text=True,
                          check=True).stdout == ""  # the links are excluded: the clone is not dirty
    where = subprocess.run(
        [sys.executable, "-c", "import legcal_bench.calibrators as c, legcal_bench.envs as e; "
                               "from importlib.metadata import entry_points; "
                               "print(c.__file__); print(e.__file__); "
                               "print(entry_points(group='legcal_bench.calibrators')['interfoot'].load().__module__ "
                               "and __import__('sys').modules['legcal_bench.calibrators.interfoot'].__file__)"],
        env={**os.environ, "PYTHONPATH": str(src)}, cwd=tmp_path, capture_output=True, text=True, check=True)
    for line in where.stdout.split():
        assert os.path.realpath(line).startswith(os.path.realpath(src)), line
    with pytest.raises(Exception, match="not a commit"):
        install_baseline("no-such-commit", tmp_path / "other")


def test_the_calibration_probe_runs_and_reports_on_the_code_at_hand(collected):
    # What bench-speed runs for its calibration group, on a small set (one repeat): every
    # case reports a time and the offsets, the stages of the end-to-end ones. No speed.
    from legcal_bench.reports import bench_speed
    from legcal_bench.reports.speed_probe import CALIBRATION_CASES

    data = collected(robot="a3", mode="kinematic", sensors="realistic", seed=0, heldout=0, stance_s=4.0)
    out = bench_speed.run_probe("calibration", 1, None, str(data), "a3", bench_speed.HERE.parents[1])
    assert set(out["cases"]) == {*CALIBRATION_CASES, "interfoot_door"}
    for name, case in out["cases"].items():
        assert len(case["values"]) == 1 and case["values"][0] > 0 and len(case["offsets"]) == 12, name
    assert {"solve", "total"} <= set(out["cases"]["interfoot_end_to_end"]["stages"])
    rows, stages = summarize({"calibration": {"old": [], "new": [out]}})
    assert len(rows) == len(out["cases"]) and stages


def test_the_readme_speed_line_is_the_report_it_names(tmp_path):
    # Written by `bench-speed --out R --readme README.md`; edited by hand, or a report
    # rerun without it, fails here.
    import re

    from legcal_bench.reports.bench_speed import SPEED_LINE_END, SPEED_LINE_START, speed_line, write_speed_line

    root = HERE.parents[1]
    text = (root / "README.md").read_text()
    m = re.search(re.escape(SPEED_LINE_START) + r"(\S+) -->\n(.*)\n" + re.escape(SPEED_LINE_END), text)
    assert m, "README.md has no speed line"
    report = json.loads((root / m.group(1) / "report.json").read_text())
    assert m.group(2) == speed_line(report)
    assert "calibrate (inter-foot, default setting)" in m.group(2) and report["baseline"] in m.group(2)
    # Written again into a copy: the same README; into a file without markers: appended.
    copy = tmp_path / "README.md"
    copy.write_text(text)
    write_speed_line(copy, root / m.group(1))
    assert copy.read_text().replace(str(root) + "/", "") == text
    bare = tmp_path / "bare.md"
    bare.write_text("# title\n")
    line = write_speed_line(bare, root / m.group(1))
    assert bare.read_text().startswith("# title\n\n" + SPEED_LINE_START) and line in bare.read_text()
