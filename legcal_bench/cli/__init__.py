"""The `legcal-bench` command line: one module per command group. Degrees appear only
here, at the edge.

Only a `LegcalError` (bad input: the message names the field and the fix) exits with
code 2 and a one-line message; anything else is a bug and keeps its traceback.

Start-up stays light (a test checks): building the parser imports no numerical package;
each command imports what it needs inside its `cmd_*` function. The facts its options
show (effect, offset and sensor preset names; the training defaults) live in
standard-library modules that the simulation and training import too
(`legcal_bench.sim.names`, `legcal_bench.evaluation.distill_config`).
"""

from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

from legcal_bench.cli import benchmark, calibration, data, logs, reports, robots, walking  # noqa: E402
from legcal_bench.errors import LegcalError  # noqa: E402

GROUPS = (data, logs, robots, calibration, walking, benchmark, reports)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="legcal-bench", description="Humanoid leg joint-offset calibration benchmark")
    sub = p.add_subparsers(dest="command", required=True)
    for group in GROUPS:
        group.add_commands(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except LegcalError as e:
        print(f"legcal-bench {args.command}: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
