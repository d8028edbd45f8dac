"""The parser classes of the `legcal-bench` command line (standard library only: start-up
stays light).

- `LegcalParser`: a value that starts with a minus sign and a digit (`-0.02`,
  `-0.02,0.01,...`, `-1e-3`, `-1:2`) is a value, never an option: no option of
  legcal-bench starts with `-<digit>` (`build_parser` checks), so `--offsets -0.02,0.01`
  needs no `=`. Plain argparse takes such a token for an unknown option unless it is a
  plain negative number.
- `HelpFormatter`: every option's help shows its default, `(default: X)` appended
  unless the text already says what the default is (`help_text`).
- `TopParser`: the top-level help lists the commands under the headings of
  `legcal_bench.cli.groups.COMMAND_GROUPS`.
"""

from __future__ import annotations

import argparse
import re

# A token that is a value although it starts with "-": a minus sign, then a digit or a
# decimal point and a digit (a number, a comma list starting with one, a range).
NEGATIVE_VALUE = re.compile(r"^-\.?\d")
_SAYS_DEFAULT = re.compile(r"\bdefault\b", re.IGNORECASE)


def shown(value) -> str:
    """A default as a user would type it: lists space-separated, floats without trailing
    zeros."""
    if isinstance(value, (list, tuple)):
        return " ".join(shown(v) for v in value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def takes_value(action: argparse.Action) -> bool:
    """An option followed by a value (not a flag such as --json, not -h)."""
    return bool(action.option_strings) and action.nargs != 0


def help_text(action: argparse.Action) -> str | None:
    """`action.help` with its default appended, `(default: X)`, for an option that takes a
    value and has a default, unless the text already says its default (the word
    'default'). Flags, required options and options whose default is None (their help says
    what happens when they are not given) are left as written. Not %-escaped."""
    text = action.help
    if text is None or text == argparse.SUPPRESS or not takes_value(action) or action.required:
        return text
    if action.default is None or action.default == argparse.SUPPRESS or _SAYS_DEFAULT.search(text):
        return text
    return f"{text} (default: {shown(action.default) or 'none'})"


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter with every option's default shown (`help_text`)."""

    def _get_help_string(self, action):
        text = help_text(action)
        if text is None or text is action.help:
            return text
        return action.help + text[len(action.help):].replace("%", "%%")  # argparse %-formats the help


class LegcalParser(argparse.ArgumentParser):
    """A parser that takes `-0.02,0.01` for a value (`NEGATIVE_VALUE`) and shows defaults."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def _parse_optional(self, arg_string):
        if NEGATIVE_VALUE.match(arg_string):
            return None  # a positional token, i.e. a value
        return super()._parse_optional(arg_string)


class TopParser(LegcalParser):
    """The top-level parser: its help lists the commands under the headings of
    `COMMAND_GROUPS` instead of one flat list; the subcommands stay direct subcommands."""

    def commands(self) -> dict[str, argparse.ArgumentParser]:
        return dict(self._subcommands().choices)

    def _subcommands(self) -> argparse._SubParsersAction:
        return next(a for a in self._actions if isinstance(a, argparse._SubParsersAction))

    def format_help(self) -> str:
        from legcal_bench.cli.groups import COMMAND_GROUPS

        summaries = {a.dest: a.help for a in self._subcommands()._choices_actions}
        formatter = self._get_formatter()
        formatter.add_usage(self.usage, self._actions, self._mutually_exclusive_groups)
        formatter.add_text(self.description)
        for heading, purpose, commands in COMMAND_GROUPS:
            formatter.start_section(heading)
            formatter.add_text(purpose)
            formatter.add_arguments([argparse.Action([], dest=c, metavar=c, help=summaries.get(c) or "")
                                     for c in commands])
            formatter.end_section()
        for group in self._action_groups:
            actions = [a for a in group._group_actions if not isinstance(a, argparse._SubParsersAction)]
            if actions:
                formatter.start_section(group.title)
                formatter.add_text(group.description)
                formatter.add_arguments(actions)
                formatter.end_section()
        formatter.add_text(self.epilog)
        return formatter.format_help()


def pool_options(p: argparse.ArgumentParser, scheduler: bool = True, note: str = "") -> None:
    """`--workers` and (with `scheduler`) `--scheduler`, in one wording for every command
    that runs its work in a pool; `note` adds to the workers' help."""
    p.add_argument("--workers", type=int, default=2, help="local worker processes, at least 1" + note)
    if scheduler:
        p.add_argument("--scheduler", default=None,
                       help="a Dask scheduler address (tcp://host:8786): the work runs there instead; refused at "
                            "once if nothing answers there (default: none, local worker processes)")
