"""One run of a report's cases over robots, seeds and cases: the generated robots named
(`legcal_bench.robots.design.GENERATED_DESIGNS`) written for the run, each row's
`robot_spec` the name given."""

from __future__ import annotations

from pathlib import Path

from legcal_bench.files.scratch import scratch_dir


def map_robot_cases(case_fn, robots, cases, seeds: int, workers: int, label: str, progress: bool) -> list[dict]:
    """`case_fn((robot, case, seed))` for every robot, case and seed 0..seeds-1, in
    `workers` processes: its rows, `robot_spec` the robot as given."""
    from legcal_bench.files.parallel import map_with_progress
    from legcal_bench.robots.build import write_designs

    robots = list(robots)
    with scratch_dir(label.replace("-", "")) as folder:
        paths = write_designs(robots, Path(folder))
        jobs = [(r, c, s) for r in paths for c in cases for s in range(seeds)]
        rows = map_with_progress(case_fn, jobs, workers, label, progress)
    for r in rows:  # the name given, not the run's temporary path
        r["robot_spec"] = robots[paths.index(r["robot_spec"])]
    return rows
