"""The `legcal-bench` command line: one module per command group. Degrees appear only
here, at the edge.

Only a `LegcalError` (bad input: the message names the field and the fix) exits with
code 2 and a one-line message; anything else is a bug and keeps its traceback.

Start-up stays light (a test checks): building the parser imports no numerical package;
each command imports what it needs inside its `cmd_*` function. The facts its options
show (effect, offset and sensor preset names; the training defaults) live in
standard-library modules that the simulation and training import too
(`legcal_bench.sim.names`, `legcal_bench.evaluation.distill_config`).

As users read it (issue #43): the top-level help lists the commands under the headings of
one table, `legcal_bench.cli.groups.COMMAND_GROUPS` (everyday commands first, the
maintainers' report generators last), each still a direct subcommand; every option's
help shows its default, and `-0.02,0.01` is a value, not an option
(`legcal_bench.cli.parsing`); `legcal_bench.cli.reference.markdown()` renders the whole
command line for the docs. No default output path is inside a committed folder: commands
write under runs/, and a committed report, leaderboard or shipped policy changes only
when --out names it.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

from legcal_bench.cli import benchmark, calibration, data, logs, reports, robots, walking  # noqa: E402
from legcal_bench.cli.groups import COMMAND_GROUPS, grouped_commands  # noqa: E402
from legcal_bench.cli.parsing import NEGATIVE_VALUE, LegcalParser, TopParser  # noqa: E402
from legcal_bench.errors import LegcalError  # noqa: E402

# The modules that add the commands; the headings the help lists them under are
# `COMMAND_GROUPS` (legcal_bench.cli.groups), a table of its own.
GROUPS = (data, logs, robots, calibration, walking, benchmark, reports)

__all__ = ["COMMAND_GROUPS", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    p = TopParser(prog="legcal-bench", description="Humanoid leg joint-offset calibration benchmark",
                  epilog="`legcal-bench COMMAND --help` shows a command's options, each with its default. Commands "
                         "write under runs/ unless --out (or the command's output option) names another place.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", parser_class=LegcalParser)
    for group in GROUPS:
        group.add_commands(sub)
    _check_table(p)
    return p


def _check_table(p: TopParser) -> None:
    """Every command listed once in COMMAND_GROUPS, and no option that looks like a
    negative number (the parser takes `-0.02,...` for a value)."""
    commands, listed = set(p.commands()), grouped_commands()
    if sorted(commands) != sorted(listed):
        raise RuntimeError(f"legcal_bench.cli.groups.COMMAND_GROUPS lists {sorted(listed)}, the parser has "
                           f"{sorted(commands)}: list every command under one heading, once")
    for name, parser in p.commands().items():
        for action in parser._actions:
            if any(NEGATIVE_VALUE.match(s) for s in action.option_strings):
                raise RuntimeError(f"{name} {action.option_strings}: an option may not look like a negative number")


INTERRUPTED = 130  # the shell's exit status for a command ended by Ctrl-C (128 + SIGINT)
RESUME = "nothing half-written is left (results are written whole or not at all); rerun the command to start again"


def main(argv: list[str] | None = None) -> int:
    """Run one command. Bad input (a `LegcalError`): one line, exit 2. Ctrl-C or a
    SIGTERM: one line saying what is kept and how to resume (the command's `resume`
    default, `RESUME` otherwise), exit 130; its workers and scratch folders go with it.
    Scratch folders of commands killed outright are removed first (`scratch.sweep`)."""
    from legcal_bench.files.scratch import sweep

    args = build_parser().parse_args(argv)
    sweep()
    previous = signal.signal(signal.SIGTERM, _terminate) if _main_thread() else None
    try:
        return args.func(args)
    except LegcalError as e:
        _close_bars()
        print(f"legcal-bench {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        sweep()  # the scratch folders of the workers just stopped
        _close_bars()
        print(f"legcal-bench {args.command}: interrupted; {getattr(args, 'resume', None) or RESUME}",
              file=sys.stderr)
        return INTERRUPTED
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _close_bars() -> None:
    """End the progress bars an error or Ctrl-C left open, so that the message starts a
    line of its own (an open bar would redraw after it)."""
    if "tqdm" in sys.modules:
        from tqdm import tqdm

        for bar in list(getattr(tqdm, "_instances", ())):
            bar.close()


def _terminate(signum, frame):
    """SIGTERM (a `kill`, a scheduler's time limit) stops like Ctrl-C."""
    raise KeyboardInterrupt


def _main_thread() -> bool:
    import threading

    return threading.current_thread() is threading.main_thread()


if __name__ == "__main__":
    sys.exit(main())
