"""The effect plug-in guide (docs/effect-plugins.md, issue #41): its example plug-in
(docs/examples/effect_plugin, a sole plate bent by a degree) registered from a temporary
distribution's entry point, and the guide's walk-through run command by command: the
session set collected with the plug-in's physics, `diagnose` without the plug-in's
fitting model (the library's effects only: no library effect may be named) and with it
(the bent sole selected, its angle recovered within its error bars, the offsets back).
The guide's code is the file's and its commands are the ones run here, so neither can
drift; each output line the guide quotes must begin as the command's output does."""

import importlib
import json
import re
import shlex
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.cli import main
from legcal_bench.data.recording import list_segments, load_truth
from legcal_bench.errors import ConfigError
from legcal_bench.sim.effects import parse_effect

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "docs" / "examples" / "effect_plugin"
GUIDE = REPO / "docs" / "effect-plugins.md"
INSTALL = ["pip", "install", "-e", "docs/examples/effect_plugin"]


@pytest.fixture
def sole_bend(tmp_path, monkeypatch):
    """The example installed as `pip install -e` would: its module and a dist-info with its
    entry point on a new import path (here and, through PYTHONPATH, in subprocesses)."""
    site = tmp_path / "site"
    info = site / "legcal_sole_bend-0.1.dist-info"
    info.mkdir(parents=True)
    (site / "legcal_sole_bend.py").write_text((EXAMPLE / "legcal_sole_bend.py").read_text())
    entry = re.search(r'^sole_bend = "(.*)"$', (EXAMPLE / "pyproject.toml").read_text(), re.M).group(1)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: legcal_sole_bend\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[legcal_bench.effects]\nsole_bend = {entry}\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", ":".join(filter(None, [str(site), __import__("os").environ.get("PYTHONPATH")])))
    importlib.invalidate_caches()
    sys.modules.pop("legcal_sole_bend", None)


def walkthrough() -> list[tuple[list[str], list[str]]]:
    """(command, the output lines the guide quotes after it) of each `$ ` line in the
    guide's console blocks, in order."""
    out = []
    for block in re.findall(r"```console\n(.*?)```", GUIDE.read_text(), re.S):
        for line in block.replace("\\\n", " ").splitlines():
            if line.startswith("$ "):
                out.append((shlex.split(line[2:]), []))
            elif line.strip() and out:
                out[-1][1].append(line.strip())
    return out


def _head(line: str) -> str:
    """A quoted output line up to its first number or parenthesis: the words, not the figures."""
    return re.split(r"[\d(]", line, maxsplit=1)[0].strip()


def test_the_guide_shows_the_example_as_it_is():
    text = GUIDE.read_text()
    assert (EXAMPLE / "legcal_sole_bend.py").read_text() in re.findall(r"```python\n(.*?)```", text, re.S)
    entry = re.search(r'^sole_bend = "(.*)"$', (EXAMPLE / "pyproject.toml").read_text(), re.M).group(1)
    assert f'sole_bend = "{entry}"' in text
    commands = [c for c, _ in walkthrough()]
    assert commands[0] == INSTALL and all(c[0] == "legcal-bench" for c in commands[1:])


def test_the_guides_walkthrough_finds_the_bent_sole_only_once_the_plugin_is_installed(sole_bend, tmp_path,
                                                                                       monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError, match=r"unknown effect 'sole_bent'.*Installed plug-ins with physics: .*"
                                          r"sole_bend \(side, deg\)"):
        parse_effect("sole_bent:side=left,deg=1")
    steps = walkthrough()
    assert steps[0][0] == INSTALL  # done by the fixture
    runs, seconds = {}, {}
    for command, quoted in steps[1:]:
        t0 = time.perf_counter()
        assert main(command[1:]) == 0, command
        seconds[" ".join(command[:2])] = seconds.get(" ".join(command[:2]), 0) + time.perf_counter() - t0
        printed = capsys.readouterr().out
        for line in quoted:
            assert _head(line) in printed, (command, line)
        runs[command[1] + ("_library" if "--effects" in command else "")] = command
    print(f"walk-through seconds: {seconds}")

    def out(name: str) -> Path:
        c = runs[name]
        return Path(c[c.index("--out") + 1])

    # Collected with the plug-in's physics: the truth names it, nothing in the recordings does.
    truth = load_truth(list_segments(out("collect"))[0]).meta["reality"]["effects"]
    assert truth == [{"effect": "sole_bend:side=left,deg=1", "kind": "sole_bend", "side": "left",
                      "angle_rad": pytest.approx(np.deg2rad(1.0))}]
    # Without the plug-in's model: no library effect is named for it.
    before = json.loads((out("diagnose_library") / "diagnosis.json").read_text())
    assert before["verdict"] != "selected" and before["selected"] == [], before["summary"]
    # With it: the bent sole, its angle within its error bars, the offsets back to the truth.
    after = json.loads((out("diagnose") / "diagnosis.json").read_text())
    assert after["verdict"] == "selected" and after["selected"] == ["sole_bend"], after["summary"]
    left, right = after["parameters"]["sole_bend.left_pitch"], after["parameters"]["sole_bend.right_pitch"]
    assert left["std"] < np.deg2rad(0.1) and right["std"] < np.deg2rad(0.1)
    assert abs(left["value"] - np.deg2rad(1.0)) < 4 * left["std"] and abs(right["value"]) < 4 * right["std"]
    assert after["truth"]["after"] < 0.02 and after["truth"]["after"] < 0.1 * after["truth"]["before"]  # deg RMS
