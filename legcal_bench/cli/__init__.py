"""The `legcal-bench` command line: one module per command group. Degrees appear only
here, at the edge.

Only a `LegcalError` (bad input: the message names the field and the fix) exits with
code 2 and a one-line message; anything else is a bug and keeps its traceback.

Start-up stays light (a test checks): building the parser imports no numerical package;
each command imports what it needs inside its `cmd_*` function.
"""

from __future__ import annotations

import argparse
import os
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

from legcal_bench.cli import benchmark, calibration, data, reports, robots, walking  # noqa: E402
from legcal_bench.errors import LegcalError  # noqa: E402

GROUPS = (data, robots, calibration, walking, benchmark, reports)


class CommandParser(argparse.ArgumentParser):
    """A command's parser that can add its options on first use (`build`: when arguments
    are parsed into it or its usage or help is printed). For a command whose options show
    a fact of a heavy module (a simulation preset, a training default): the other commands
    and `legcal-bench --help` never import that module."""

    def __init__(self, *args, build=None, **kwargs):
        super().__init__(*args, **kwargs)
        self._build = build

    def _complete(self) -> None:
        if self._build is not None:
            build, self._build = self._build, None
            build(self)

    def parse_known_args(self, args=None, namespace=None):
        self._complete()
        return super().parse_known_args(args, namespace)

    def format_usage(self) -> str:
        self._complete()
        return super().format_usage()

    def format_help(self) -> str:
        self._complete()
        return super().format_help()


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="legcal-bench", description="Humanoid leg joint-offset calibration benchmark")
    sub = p.add_subparsers(dest="command", required=True, parser_class=CommandParser)
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
