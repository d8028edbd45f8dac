"""The commands as users meet them: one table, read by the top-level `--help`
(`legcal_bench.cli.parsing.TopParser`), the generated reference page
(`legcal_bench.cli.reference.markdown`) and the tests. Everyday commands come first;
the report generators of legcal-bench's maintainers come last, under one heading.

Every command stays a direct subcommand (`legcal-bench bench-speed`): the headings only
order the help. A command added to a module's `add_commands` must be listed here, once
(`build_parser` refuses otherwise)."""

from __future__ import annotations

# (heading, what the commands under it are for, the commands in the order shown)
COMMAND_GROUPS: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("calibrate a robot",
     "from a robot's log (or a simulated session set) to offsets applied on the robot",
     ("import", "check", "calibrate", "score", "report", "export", "diagnose")),
    ("benchmark a method",
     "calibrators compared over robots, floors and seeds; results under runs/ unless --out names a folder",
     ("bench", "sweep", "compare", "leaderboard")),
    ("walking",
     "walking policies with encoder offsets, and the closed-loop evaluation of a calibrator",
     ("walk", "walk-eval", "train-policy")),
    ("simulate and data",
     "the robots, simulated session sets and logs, and the design of stances and motions",
     ("info", "render", "collect", "simulate-log", "design", "excite")),
    ("maintainers: reports",
     "reports on legcal-bench itself; each writes under runs/ unless --out names the committed folder to update",
     ("reproduce", "bench-speed", "bench-env", "robots-check", "data-checks", "effects-table", "contact-table",
      "contact-floor", "contact-holds", "verdicts", "imu-mount", "vendor-cases", "regression")),
)


def grouped_commands() -> list[str]:
    """Every command of the table, in the order the help shows them."""
    return [c for _, _, commands in COMMAND_GROUPS for c in commands]


def group_of(command: str) -> str:
    """The heading `command` is listed under (KeyError for a command the table lacks)."""
    for heading, _, commands in COMMAND_GROUPS:
        if command in commands:
            return heading
    raise KeyError(command)
