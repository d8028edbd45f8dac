"""One rule for every file a user names (a robot's leg map, a policy spec, a teacher
recipe, a protocol, a log mapping), in the CLI and the Python and env APIs alike: a path
from the working directory; else a file the package ships, by its name
(`examples/<file>` for the installed examples, or the kind's own short names, e.g. `a3`
for our walking policy). So a command that works in a checkout works from any folder
against an installed wheel."""

from __future__ import annotations

from pathlib import Path

# Where the example files' own relative paths lead in a checkout: the external models
# (the Unitree G1's MJCF, its published policy) sit in ../shared beside it.
EXTERNAL_HINT = ("this example points into ../shared/external, the external models kept beside a legcal-bench "
                 "checkout (each folder's SOURCE.md says where they come from): run it from a checkout with "
                 "../shared present, or copy the example and point the field at your copy of the file")


def examples_dir() -> Path:
    """Where the example files are (a checkout's `examples/`, or the installed copy)."""
    import importlib

    return Path(importlib.import_module("legcal_bench.examples").__file__).parent


def packaged(name: str | Path, shipped: dict[str, Path] | None = None) -> Path:
    """The file `name` names: itself if it exists from the working directory; else the
    installed example `examples/<file>`; else `shipped[name]` (the kind's short names);
    else `name` unchanged, for the caller's loader to refuse ("no such file", naming its
    field)."""
    p = Path(name).expanduser()
    if p.exists():
        return p
    if p.parts[:1] == ("examples",) and len(p.parts) == 2 and (examples_dir() / p.name).exists():
        return examples_dir() / p.name
    if shipped is not None and str(name) in shipped and shipped[str(name)].exists():
        return shipped[str(name)]
    return p


def from_examples(path: Path) -> bool:
    """Whether `path` is one of the installed or checked-out example files."""
    try:
        return Path(path).resolve().parent == examples_dir().resolve()
    except OSError:
        return False
