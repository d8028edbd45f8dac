"""The whole command line as one markdown page, for a generated docs page:
`legcal_bench.cli.reference.markdown()`.

Built from the parser itself (`build_parser`) and the headings of
`legcal_bench.cli.groups.COMMAND_GROUPS`: each group, its commands with their
descriptions and usage, and every option with its help and default. Deterministic: the
usage lines are wrapped at a fixed width (not the terminal's) and nothing depends on
the environment. Standard library only, like the parser.

    python -c "from legcal_bench.cli.reference import markdown; print(markdown(), end='')" > docs/cli.md
"""

from __future__ import annotations

import argparse
import re

from legcal_bench.cli.groups import COMMAND_GROUPS
from legcal_bench.cli.parsing import shown, takes_value

WIDTH = 100  # the usage lines' width, whatever the terminal


def markdown() -> str:
    """The command-line reference as markdown (ends with one newline)."""
    from legcal_bench.cli import build_parser

    top = build_parser()
    commands = top.commands()
    summaries = {a.dest: a.help or "" for a in top._subcommands()._choices_actions}
    out = ["# Command-line reference", "",
           "Generated from the parser by `legcal_bench.cli.reference.markdown()`; `legcal-bench COMMAND --help` "
           "prints the same. Every command is a direct subcommand (`legcal-bench COMMAND [options]`); the "
           "headings only group them. Commands write under `runs/` unless an option names another place; the "
           "committed folders (`leaderboard/`, `reports/`, `policies/`) change only when `--out` names them.", ""]
    for heading, purpose, names in COMMAND_GROUPS:
        out += [f"## {_text(heading.capitalize())}", "", _text(purpose[0].upper() + purpose[1:]) + ".", "",
                "| command | what it does |", "|---|---|"]
        out += [f"| [`{n}`](#legcal-bench-{n}) | {_cell(summaries[n])} |" for n in names]
        out.append("")
        for name in names:
            out += _command(name, commands[name])
    return "\n".join(out).rstrip("\n") + "\n"


def _command(name: str, parser: argparse.ArgumentParser) -> list[str]:
    lines = [f"### legcal-bench {name}", "", _text(parser.description or ""), "",
             "```text", _usage(parser), "```", "",
             "| option | default | what it does |", "|---|---|---|"]
    for action in parser._actions:
        if not action.option_strings or isinstance(action, argparse._HelpAction):
            continue
        lines.append(f"| {_invocation(action)} | {_default(action)} | {_cell(_help(parser, action))} |")
    return lines + [""]


def _usage(parser: argparse.ArgumentParser) -> str:
    formatter = argparse.HelpFormatter(parser.prog, width=WIDTH)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups, prefix="")
    return formatter.format_help().strip("\n")


def _invocation(action: argparse.Action) -> str:
    formatter = argparse.HelpFormatter("legcal-bench", width=WIDTH)
    return "<br>".join(f"`{part}`" for part in formatter._format_action_invocation(action).split(", "))


def _default(action: argparse.Action) -> str:
    if action.required:
        return "required"
    if not takes_value(action):
        return "off"  # a flag
    if action.default is None or action.default == argparse.SUPPRESS or action.default == []:
        return "none"  # the help says what that means
    return f"`{shown(action.default)}`" if shown(action.default) else '`""`'


def _help(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """The help text as `--help` shows it (%-expanded), without the default appended:
    the table has a column for it."""
    return argparse.HelpFormatter(parser.prog, width=WIDTH)._expand_help(action) if action.help else ""


_SPECIAL = {"|": r"\|", "<": "&lt;", ">": "&gt;", "*": r"\*"}


def _text(s: str) -> str:
    """Prose for markdown: `<deg>` shown, not taken for HTML; `*.npz` not emphasis;
    code spans (backticks) kept as they are."""
    parts = re.split(r"(`[^`]*`)", s)
    return "".join(p if p.startswith("`") else "".join(_SPECIAL.get(c, c) for c in p) for p in parts)


_cell = _text  # a table cell: the pipes outside code spans escaped (inside them, Python-Markdown's tables keep them)
