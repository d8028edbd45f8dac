"""An example effect plug-in installed as `pip install -e` would, for a test: its module
and a dist-info with its entry point on a new import path (here and, through PYTHONPATH,
in subprocesses)."""

import importlib
import os
import re
import sys
from pathlib import Path

REPO_EXAMPLES = Path(__file__).resolve().parents[2] / "docs" / "examples"


def install_example(example: Path, module: str, entry_name: str, site: Path, monkeypatch) -> str:
    """Install `example`/`module`.py with the entry point `entry_name` its pyproject.toml
    names (group legcal_bench.effects) under `site`; returns the entry point's target."""
    info = site / f"{module}-0.1.dist-info"
    info.mkdir(parents=True)
    (site / f"{module}.py").write_text((example / f"{module}.py").read_text())
    entry = re.search(rf'^{entry_name} = "(.*)"$', (example / "pyproject.toml").read_text(), re.M).group(1)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[legcal_bench.effects]\n{entry_name} = {entry}\n")
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("PYTHONPATH", ":".join(filter(None, [str(site), os.environ.get("PYTHONPATH")])))
    importlib.invalidate_caches()
    sys.modules.pop(module, None)
    return entry
