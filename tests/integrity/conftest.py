"""A calibrator registered the way a third-party package registers it: a module and a
`*.dist-info` folder whose entry_points.txt names it under `legcal_bench.calibrators`,
in a folder put on sys.path and PYTHONPATH (so worker processes find it too)."""

import importlib
import sys

import pytest


@pytest.fixture
def install_plugin(tmp_path, monkeypatch):
    def install(module: str, source: str, entry: str, cls: str):
        site = tmp_path / "site"
        site.mkdir(exist_ok=True)
        (site / f"{module}.py").write_text(source)
        info = site / f"{module}-0.1.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 0.1\n")
        (info / "entry_points.txt").write_text(f"[legcal_bench.calibrators]\n{entry} = {module}:{cls}\n")
        monkeypatch.syspath_prepend(str(site))
        monkeypatch.setenv("PYTHONPATH", str(site) + ((":" + p) if (p := __import__("os").environ.get("PYTHONPATH"))
                                                       else ""))
        importlib.invalidate_caches()
        sys.modules.pop(module, None)
        return site

    return install
