"""The Python API (issue #35): the docs show the example as it is (it runs as written
against the installed wheel in tests/docs/test_snippets.py), each call returns what the
command writes, and importing the package stays light."""

import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
EXAMPLE = REPO / "docs" / "examples" / "api_quickstart.py"


def test_the_docs_show_the_example_as_it_is():
    blocks = re.findall(r"```python\n(.*?)```", (REPO / "docs" / "python-api.md").read_text(), re.S)
    assert EXAMPLE.read_text() in blocks


def test_importing_the_package_loads_no_heavy_module():
    out = subprocess.run([sys.executable, "-c", "import sys, legcal_bench; print(sorted(m for m in ('numpy', "
                          "'scipy', 'mujoco', 'pinocchio', 'torch') if m in sys.modules))"],
                         capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    assert "calibrate" in dir(__import__("legcal_bench"))
