"""The effect plug-in guide (docs/effect-plugins.md, issue #41): its example plug-in
(docs/examples/effect_plugin, a sole plate bent by a degree) registered from a temporary
distribution's entry point, and the guide's walk-through run command by command: the
session set collected with the plug-in's physics, `diagnose` without the plug-in's
fitting model (the library's effects only: no library effect may be named) and with it
(the bent sole selected, its angle recovered within its error bars, the offsets back).
The guide's code is the file's, and its commands run as written against the installed
wheel (tests/docs/test_snippets.py, which checks each output line the guide quotes and
then `check_walkthrough_outputs`), so neither can drift."""

import json
import re
import shlex
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.data.recording import list_segments, load_truth
from legcal_bench.errors import ConfigError
from legcal_bench.sim.effects import parse_effect
from tests.estimation.plugin_install import install_example

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "docs" / "examples" / "effect_plugin"
GUIDE = REPO / "docs" / "effect-plugins.md"
INSTALL = ["pip", "install", "-e", "docs/examples/effect_plugin"]


@pytest.fixture
def sole_bend(tmp_path, monkeypatch):
    """The example installed as `pip install -e` would (`plugin_install.install_example`)."""
    install_example(EXAMPLE, "legcal_sole_bend", "sole_bend", tmp_path / "site", monkeypatch)


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


def test_the_guide_shows_the_example_as_it_is():
    text = GUIDE.read_text()
    assert (EXAMPLE / "legcal_sole_bend.py").read_text() in re.findall(r"```python\n(.*?)```", text, re.S)
    entry = re.search(r'^sole_bend = "(.*)"$', (EXAMPLE / "pyproject.toml").read_text(), re.M).group(1)
    assert f'sole_bend = "{entry}"' in text
    commands = [c for c, _ in walkthrough()]
    assert commands[0] == INSTALL and all(c[0] == "legcal-bench" for c in commands[1:])


def test_a_misspelt_effect_names_the_installed_plugin(sole_bend):
    with pytest.raises(ConfigError, match=r"unknown effect 'sole_bent'.*Installed plug-ins with physics: .*"
                                          r"sole_bend \(side, deg\)"):
        parse_effect("sole_bent:side=left,deg=1")


def check_walkthrough_outputs(runs: Path) -> None:
    """What the guide's walk-through made under `runs` (its commands run as written, the
    plug-in installed by its `pip install -e`, against the installed wheel from a fresh
    folder: tests/docs/test_snippets.py, which also checks the output lines it quotes)."""
    # Collected with the plug-in's physics: the truth names it, nothing in the recordings does.
    truth = load_truth(list_segments(runs / "sole_bend")[0]).meta["reality"]["effects"]
    assert truth == [{"effect": "sole_bend:side=left,deg=1", "kind": "sole_bend", "side": "left",
                      "angle_rad": pytest.approx(np.deg2rad(1.0))}]
    # Without the plug-in's model: no library effect is named for it.
    before = json.loads((runs / "sole_bend_library" / "diagnosis.json").read_text())
    assert before["verdict"] != "selected" and before["selected"] == [], before["summary"]
    # With it: the bent sole, its angle within its error bars, the offsets back to the truth.
    after = json.loads((runs / "sole_bend_diagnosis" / "diagnosis.json").read_text())
    assert after["verdict"] == "selected" and after["selected"] == ["sole_bend"], after["summary"]
    left, right = after["parameters"]["sole_bend.left_pitch"], after["parameters"]["sole_bend.right_pitch"]
    assert left["std"] < np.deg2rad(0.1) and right["std"] < np.deg2rad(0.1)
    assert abs(left["value"] - np.deg2rad(1.0)) < 4 * left["std"] and abs(right["value"]) < 4 * right["std"]
    assert after["truth"]["after"] < 0.02 and after["truth"]["after"] < 0.1 * after["truth"]["before"]  # deg RMS
