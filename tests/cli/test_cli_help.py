"""The command line as users read it (issue #43): the top-level help groups the commands
(everyday ones first, the maintainers' report generators under one heading) while each
stays a direct subcommand; every command has a description and every option a help text
showing its default; no default output is inside a committed folder; negative numbers
are values (`--offsets -0.02,0.01`); `reference.markdown()` renders all of it."""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from legcal_bench.cli import build_parser, main
from legcal_bench.cli.groups import COMMAND_GROUPS, grouped_commands
from legcal_bench.cli.parsing import help_text, shown, takes_value

COMMITTED = ("leaderboard", "reports", "policies", "examples", "docs")
# Options that name something a command writes (files or folders).
OUTPUTS = {"out", "data", "plots", "plot", "strip", "mjcf_out", "urdf_out", "ros2_params"}
REPORT_GENERATORS = {"reproduce", "bench-speed", "bench-env", "robots-check", "data-checks", "effects-table",
                     "contact-table", "contact-floor", "contact-holds", "verdicts", "imu-mount",
                     "vendor-cases", "regression"}
EVERYDAY = {"import", "check", "calibrate", "score", "report", "export", "diagnose", "collect", "walk", "bench"}


@pytest.fixture(scope="module")
def commands() -> dict[str, argparse.ArgumentParser]:
    return build_parser().commands()


def options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    return [a for a in parser._actions if a.option_strings and not isinstance(a, argparse._HelpAction)]


def help_output(argv: list[str], monkeypatch) -> str:
    monkeypatch.setenv("COLUMNS", "80")
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 0
    return out.getvalue()


def squeezed(text: str) -> str:
    """Without white space: help wraps lines, at hyphens too."""
    return "".join(text.split())


# ------------------------------------------------------------------- descriptions
def test_every_command_has_a_description_and_a_summary(commands):
    summaries = {a.dest: a.help for a in build_parser()._subcommands()._choices_actions}
    for name, parser in commands.items():
        assert summaries.get(name), f"{name}: no one-line help in the command list"
        assert parser.description and len(parser.description) >= 40, f"{name}: no description"


def test_every_option_has_a_help_text(commands):
    missing = [f"{name} {a.option_strings[0]}" for name, p in commands.items() for a in options(p)
               if not (a.help or "").strip()]
    assert not missing, missing


def test_every_option_shows_its_default(commands, monkeypatch):
    """An option with a value shows its default: stated in its text (then the value
    itself, so that text and code cannot drift apart) or appended by the formatter. An
    option without one (None) says what happens when it is not given. The rendered
    `--help` holds each text whole."""
    unsaid = []
    for name, parser in commands.items():
        page = squeezed(help_output([name, "--help"], monkeypatch))
        for a in options(parser):
            text = help_text(a)
            assert squeezed(text) in page, (name, a.option_strings[0])
            if not takes_value(a) or a.required:
                continue
            if a.default is None or a.default == []:
                if not re.search(r"\b(default|required)\b", text, re.IGNORECASE):
                    unsaid.append(f"{name} {a.option_strings[0]}: no default said")
            elif shown(a.default) not in text or "default" not in text.lower():
                unsaid.append(f"{name} {a.option_strings[0]}: default {shown(a.default)!r} not shown in {text!r}")
    assert not unsaid, "\n".join(unsaid)


def test_the_formatter_appends_a_default_the_text_does_not_state(monkeypatch):
    page = " ".join(help_output(["bench-env", "--help"], monkeypatch).split())
    assert "collection seed: an integer in [0, 2^32 - 1] (default: 0)" in page
    assert "floor modes to measure: kinematic, weld, contact (default: kinematic weld contact)" in page
    page = " ".join(help_output(["walk", "--help"], monkeypatch).split())
    assert "(default: realistic)" in page and "(default 20)" in page and "(default: 20)" not in page


# --------------------------------------------------------------- the grouped help
def test_top_level_help_lists_each_command_once_under_its_heading(commands, monkeypatch):
    page = help_output(["--help"], monkeypatch)
    found: dict[str, list[str]] = {}
    heading = None
    for line in page.splitlines():
        if line and not line.startswith(" ") and line.endswith(":"):
            heading = line[:-1]
            found[heading] = []
        elif heading is not None and re.match(r"^  \S", line) and line.split()[0] in commands:
            found[heading].append(line.split()[0])
    listed = [c for cs in found.values() for c in cs]
    assert sorted(listed) == sorted(commands), "every command exactly once"
    assert {h: found.get(h) for h, _, cs in COMMAND_GROUPS} == {h: list(cs) for h, _, cs in COMMAND_GROUPS}
    headings = [h for h, _, _ in COMMAND_GROUPS]
    assert headings == ["calibrate a robot", "benchmark a method", "walking", "simulate and data",
                        "maintainers: reports"]
    assert [line for line in page.splitlines() if line.endswith(":") and not line.startswith(" ")][:5] == [
        f"{h}:" for h in headings]
    assert page.startswith("usage: legcal-bench [-h] COMMAND ...")


def test_the_maintainers_reports_are_grouped_last_and_everyday_commands_first():
    heading, _, maintainers = COMMAND_GROUPS[-1]
    assert heading.startswith("maintainers") and set(maintainers) == REPORT_GENERATORS
    assert not EVERYDAY & set(maintainers)
    assert sorted(grouped_commands()) == sorted(set(grouped_commands())), "a command under two headings"


def test_every_command_stays_a_direct_subcommand():
    parser = build_parser()
    for name in grouped_commands():
        a = parser.parse_args([name, *_required(parser.commands()[name])])
        assert a.command == name and a.func.__name__ == "cmd_" + name.replace("-", "_"), name


def test_a_command_missing_from_the_table_is_refused(monkeypatch):
    import legcal_bench.cli as cli

    monkeypatch.setattr(cli, "grouped_commands", lambda: [c for c in grouped_commands() if c != "bench-speed"])
    with pytest.raises(RuntimeError, match="bench-speed"):
        cli.build_parser()


# ------------------------------------------------------------------ default outputs
def _committed(path: str) -> bool:
    parts = Path(path).parts
    return bool(parts) and parts[0] in COMMITTED


def test_no_default_output_is_inside_a_committed_folder(commands):
    seen, bad = [], []
    for name, parser in commands.items():
        for a in options(parser):
            if a.dest not in OUTPUTS:
                continue
            if isinstance(a.default, str):
                seen.append(name)
                if _committed(a.default) or not a.default.startswith("runs/"):
                    bad.append(f"{name} {a.option_strings[0]} defaults to {a.default}")
            # A default the command computes is named in the help: `default <path>`.
            for path in re.findall(r"\bdefault:? ([\w.<>-]+/[\w./<>-]*)", a.help or ""):
                if _committed(path):
                    bad.append(f"{name} {a.option_strings[0]}: its help names {path} as the default")
    assert not bad, "\n".join(bad)
    for name in ("collect", "calibrate", "export", "render", "bench", "sweep", "walk-eval", "leaderboard",
                 *REPORT_GENERATORS - {"regression"}):
        assert name in seen, f"{name}: no default output path found"


def test_the_old_committed_defaults_moved_to_runs(commands):
    defaults = {(n, a.dest): a.default for n, p in commands.items() for a in options(p)}
    assert defaults[("bench", "out")] == "runs/bench" and defaults[("leaderboard", "out")] == "runs/bench"
    assert defaults[("walk-eval", "out")] == "runs/walk-eval"
    for name in REPORT_GENERATORS - {"regression"}:
        assert defaults[(name, "out")] == f"runs/{name}", name
    assert defaults[("train-policy", "out")] is None  # computed: runs/train-policy/<robot> (next test)


def test_train_policy_writes_under_runs_unless_out_names_the_shipped_folder(monkeypatch, tmp_path, capsys):
    """The shipped policy (policies/walkers/<robot>) is replaced only when --out names it."""
    import legcal_bench.evaluation.distill as distill
    import legcal_bench.files.atomic as atomic

    written = []
    monkeypatch.setattr(distill, "train", lambda *a, **k: (None, None, {"selected_iteration": 1,
                                                                         "train_seconds": 0.0}))
    monkeypatch.setattr(atomic, "replace_dir", lambda path, write, keep_if: written.append(Path(path)))
    monkeypatch.chdir(tmp_path)
    assert main(["train-policy", "--robot", "a3", "--quiet"]) == 0
    assert main(["train-policy", "--robot", "a3", "--quiet", "--out", "policies/walkers/a3"]) == 0
    assert written == [Path("runs/train-policy/a3"), Path("policies/walkers/a3")]


# ------------------------------------------------------------------ negative numbers
def _required(parser: argparse.ArgumentParser) -> list[str]:
    """Dummy values for a command's required options (parsing only)."""
    return [x for a in options(parser) if a.required for x in (a.option_strings[0], "x")]


def _negative(action: argparse.Action) -> list[tuple[str, object]]:
    """Tokens starting with a minus sign that `action` must take as its value, with the
    value each parses to."""
    if action.type is int:
        return [("-3", -3)]
    if action.type is float:
        return [("-0.02", -0.02), ("-1e-3", -1e-3), ("-.5", -0.5)]
    return [("-0.02,0.01", "-0.02,0.01"), ("-1:2", "-1:2"), ("-1e-3,2", "-1e-3,2")]


def test_plain_argparse_takes_a_negative_list_for_an_option():
    """Why `LegcalParser` exists: without it `--offsets -0.02,0.01` is refused."""
    plain = argparse.ArgumentParser(prog="x", exit_on_error=False)
    plain.add_argument("--offsets")
    with pytest.raises((argparse.ArgumentError, SystemExit)), contextlib.redirect_stderr(io.StringIO()):
        plain.parse_args(["--offsets", "-0.02,0.01"])


def _argv(name: str, parser: argparse.ArgumentParser, action: argparse.Action, token: str) -> list[str]:
    """`name` with `action` given `token`, its other required options dummies."""
    others = [x for a in options(parser) if a.required and a is not action for x in (a.option_strings[0], "x")]
    return [name, *others, action.option_strings[0], token]


def test_negative_numbers_and_lists_starting_with_one_are_values(commands):
    parser = build_parser()
    tried = 0
    for name, sub in commands.items():
        for a in options(sub):
            if not takes_value(a) or a.choices is not None:
                continue
            for token, value in _negative(a):
                got = getattr(parser.parse_args(_argv(name, sub, a, token)), a.dest)
                many = a.nargs in ("+", "*") or isinstance(a, argparse._AppendAction)
                assert got == ([value] if many else value), (name, a.option_strings[0], token, got)
                tried += 1
    assert tried > 150


def test_the_documented_offsets_forms_parse():
    parser = build_parser()
    assert parser.parse_args(["walk", "--offsets", "-0.02,0.01,0.03"]).offsets == "-0.02,0.01,0.03"
    assert parser.parse_args(["collect", "--offsets", "-0.02,0.01", "--seed", "1"]).offsets == "-0.02,0.01"
    a = parser.parse_args(["walk-eval", "--policy", "a3", "--offsets", "-0.02,0.01", "--sweep", "-1", "2"])
    assert (a.offsets, a.sweep) == ("-0.02,0.01", [-1.0, 2.0])
    assert parser.parse_args(["sweep", "--scales", "1", "-0.5"]).scales == [1.0, -0.5]
    # an option is still an option
    a = parser.parse_args(["walk", "--offsets", "paper", "--seconds", "-2", "--json"])
    assert (a.offsets, a.seconds, a.json) == ("paper", -2.0, True)
    with pytest.raises(SystemExit), contextlib.redirect_stderr(io.StringIO()):
        parser.parse_args(["walk", "--offsets", "--json"])  # a missing value is still refused


def test_a_bad_negative_value_is_refused_by_the_command_in_one_line(capsys):
    """The value reaches the command's own check (a LegcalError: one line, exit 2), not
    argparse's 'expected one argument'."""
    assert main(["walk", "--robot", "a3", "--policy", "a3", "--seconds", "-2"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("legcal-bench walk: error: --seconds"), err


# ------------------------------------------------------------------ reference page
def test_reference_markdown_renders_every_command_option_and_heading(commands, monkeypatch):
    from legcal_bench.cli.reference import markdown

    monkeypatch.setenv("COLUMNS", "40")
    page = markdown()
    monkeypatch.setenv("COLUMNS", "250")
    assert markdown() == page, "the page depends on the terminal's width"
    for heading, _, names in COMMAND_GROUPS:
        assert f"## {heading.capitalize()}" in page
        for name in names:
            assert page.count(f"\n### legcal-bench {name}\n") == 1, name
            assert f"](#legcal-bench-{name})" in page, name
    assert sorted(re.findall(r"^### legcal-bench (\S+)$", page, re.M)) == sorted(commands)
    for name, parser in commands.items():
        section = page.split(f"\n### legcal-bench {name}\n")[1].split("\n### ")[0]
        assert parser.description.split()[0] in section
        for a in options(parser):
            assert f"`{a.option_strings[0]}" in section, (name, a.option_strings[0])
    row = next(line for line in page.splitlines() if line.startswith("| `--out OUT` | `runs/walk-eval` |"))
    assert "reports/walk_eval" in row  # the committed report: named, not defaulted
    assert "none \\| paper \\| paper@&lt;deg&gt;" in page  # a table cell's pipes and <deg> escaped
    assert page.endswith("\n") and not page.endswith("\n\n")


def test_reference_markdown_imports_no_heavy_package():
    code = ("import json, sys; from legcal_bench.cli.reference import markdown; markdown(); "
            "print(json.dumps(sorted(m for m in ('numpy', 'torch', 'mujoco', 'scipy', 'matplotlib') "
            "if m in sys.modules)))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout) == []
