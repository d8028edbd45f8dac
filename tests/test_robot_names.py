"""The code names no robot: every robot outside the built-ins (the examples, the external
models beside a checkout, any user's) reaches it through a leg map, a policy spec or the
examples' index (`examples/cases.yaml`, `legcal_bench.files.examples`), never by a name
in the code. The names searched: every example file's stem and `name:` and every folder of
../shared/external; searched in the code's names and strings (comments, which cite what
was measured on which robot, are prose), in every module outside `assets/` folders."""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

import yaml

from legcal_bench.robots import BUILTIN

ROOT = Path(__file__).resolve().parents[1]
CODE = ("legcal_bench", "calibrators", "envs", "policies")
SUFFIXES = (".legmap.yaml", ".policy.yaml", ".yaml", ".urdf")


def robot_names() -> set[str]:
    names = set()
    for f in (ROOT / "examples").iterdir():
        for suffix in SUFFIXES:
            if f.name.endswith(suffix):
                names.add(f.name[: -len(suffix)])
                if suffix.endswith(".yaml"):
                    doc = yaml.safe_load(f.read_text()) or {}
                    if isinstance(doc.get("name"), str):
                        names.add(doc["name"])
                break
    external = ROOT.parent / "shared" / "external"
    if external.is_dir():
        names |= {d.name for d in external.iterdir() if d.is_dir()}
    names -= {"cases"}  # the examples' index itself
    return {n.lower() for n in names if n not in BUILTIN}


def code_tokens(path: Path):
    """(line, text) of every name and string token of a module."""
    for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
        if tok.type in (tokenize.NAME, tokenize.STRING) or tok.type == getattr(tokenize, "FSTRING_MIDDLE", -1):
            yield tok.start[0], tok.string


def test_the_names_searched_include_the_examples():
    names = robot_names()
    assert {"unitree_g1", "playground_g1"} <= names, names
    assert not names & set(BUILTIN)


def test_no_robot_name_in_the_code():
    names = robot_names()
    pattern = re.compile("|".join(rf"(?<![a-z0-9_]){re.escape(n)}(?![a-z0-9])" for n in sorted(names, key=len)[::-1]))
    hits = []
    for top in CODE:
        for f in sorted((ROOT / top).rglob("*.py")):
            if "assets" in f.relative_to(ROOT).parts:
                continue
            for line, text in code_tokens(f):
                m = pattern.search(text.lower())
                if m:
                    hits.append(f"{f.relative_to(ROOT)}:{line}: {m.group(0)}")
    assert not hits, "robot names in the code (give them a role in examples/cases.yaml):\n" + "\n".join(hits)


def test_the_search_finds_a_name(tmp_path):
    """The search itself works: a module naming an example robot is caught."""
    f = tmp_path / "m.py"
    f.write_text('# unitree_g1 in a comment is prose\nX = "examples/unitree_g1.legmap.yaml"\n')
    tokens = [t for _, t in code_tokens(f)]
    assert any("unitree_g1" in t for t in tokens)
    assert not any("comment" in t for t in tokens)
