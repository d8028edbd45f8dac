"""Every snippet of the README and the docs runs as written, from a fresh folder, against
the wheel built from this checkout and installed in a fresh virtual environment
(`tests/docs/snippets.py`): a command that only works from the repository root, or a
file the wheel does not carry, fails here. Documented smoke sizes (`<!-- smoke: ... -->`)
keep the long commands short; a block that cannot run says why (`<!-- not run: ... -->`).
A document's own checks on what its commands made follow its run."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.docs import snippets as sn

RUN = [d for d in sn.DOCUMENTS if any(not s.not_run for s in sn.snippets(d))]
# The guides whose commands repeat the README's paths at more length (a suite, two
# closed-loop evaluations): `make test-slow` runs them, keeping `make test` in its budget.
SLOW = ("docs/guides/benchmark.md", "docs/guides/closed-loop.md")


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> Path:
    """The wheel and an environment with it (its bin/), built once per test run (about
    3 s): the first test process builds them under the run's shared temporary folder,
    holding a lock, and the others use them. A document that installs a package (`pip
    install`) gets an environment of its own (`_environment_for`)."""
    import fcntl

    shared = tmp_path_factory.getbasetemp().parent  # the run's folder (each xdist process has one below it)
    work = shared / "wheel"
    with open(shared / "wheel.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not (work / "venv" / "bin" / "legcal-bench").is_file():
            shutil.rmtree(work, ignore_errors=True)
            work.mkdir()
            sn.install(sn.build_wheel(work), work / "venv")
    return work / "venv" / "bin"


def _environment_for(document: str, installed: Path, tmp_path: Path) -> Path:
    """The shared environment, or a fresh one with the same wheel for a document that
    installs a package into it (the effect plug-in guide's `pip install -e`)."""
    if not any(argv[0] == "pip" for s in sn.snippets(document) if not s.not_run and s.kind != "python"
               for argv, _ in s.commands()):
        return installed
    wheel = next((installed.parent.parent / "dist").glob("legcal_bench-*.whl"))
    return sn.install(wheel, tmp_path / "venv")


def test_every_runnable_block_runs_or_says_why_not():
    seen = {d: sn.snippets(d) for d in sn.DOCUMENTS}
    assert len(RUN) >= 8, RUN
    for document, blocks in seen.items():
        for s in blocks:
            assert s.not_run is None or len(s.not_run) > 20, (document, s.not_run)  # a reason, not a shrug
            if s.kind != "python" and not s.not_run:
                for argv, _ in s.commands():
                    assert argv[0] in ("legcal-bench", "pytest", "pip", "python"), (document, argv)
    not_run = [(d, s.not_run) for d, b in seen.items() for s in b if s.not_run]
    assert len(not_run) <= 3, not_run  # the checkout's set-up and templates for one's own files only


def test_the_wheel_carries_the_policies_recipes_and_examples(installed):
    import subprocess

    code = ("import legcal_bench, pathlib; root = pathlib.Path(legcal_bench.__file__).parent; "
            "print(sorted(str(p.relative_to(root)) for p in root.rglob('*') "
            "if p.parts[-2] in ('a2', 'a3', 'teachers', 'examples') and p.is_file()))")
    out = subprocess.run([str(installed / "python"), "-c", code], capture_output=True, text=True, check=True,
                         cwd=installed.parent, env=sn.environment(installed)).stdout
    for f in ("policies/walkers/a3/policy.yaml", "policies/walkers/a3/policy.onnx", "policies/walkers/a2/policy.pt",
              "policies/teachers/a3.yaml", "examples/unitree_g1.legmap.yaml", "examples/a3_twin.urdf"):
        assert f in out, f
    where = subprocess.run([str(installed / "python"), "-c", "import legcal_bench; print(legcal_bench.__file__)"],
                           capture_output=True, text=True, check=True, cwd=installed.parent,
                           env=sn.environment(installed)).stdout
    assert where.startswith(str(installed.parent)), where  # the wheel's copy, not the checkout's
    # The console script (the snippets' commands run through legcal_bench.cli.main, as it does).
    top = subprocess.run([str(installed / "legcal-bench"), "--help"], capture_output=True, text=True, check=True,
                         cwd=installed.parent, env=sn.environment(installed)).stdout
    assert "calibrate a robot" in top and "maintainers: reports" in top, top


@pytest.mark.parametrize("document", [pytest.param(d, marks=pytest.mark.slow) if d in SLOW else d for d in RUN])
def test_the_documents_snippets_run_against_the_installed_wheel(document, installed, tmp_path):
    outputs = sn.run_document(document, _environment_for(document, installed, tmp_path), tmp_path / "work")
    check = CHECKS.get(document)
    if check is not None:
        check(tmp_path / "work", "\n".join(out for _, out in outputs))


# ----------------------------------------------------------- each document's own checks
def _log_import(work: Path, stdout: str) -> None:
    from tests.logs.test_guide import check_guide_outputs

    check_guide_outputs(work / "demo", stdout)


def _effect_plugins(work: Path, stdout: str) -> None:
    from tests.estimation.test_effect_plugin import check_walkthrough_outputs

    check_walkthrough_outputs(work / "runs")


def _python_api(work: Path, stdout: str) -> None:
    assert "recovery RMS" in stdout and "closed loop, trials: 1" in stdout
    back = json.loads((work / "runs" / "api_quickstart" / "result.json").read_text())  # the CLI's format
    assert back["calibrator"] == "interfoot" and back["settings"]["setting"] == "sensor"


def _readme(work: Path, stdout: str) -> None:
    result = json.loads((work / "demo" / "result.json").read_text())
    truth = json.loads((work / "demo" / "truth.json").read_text())["offsets_rad"]
    err = np.rad2deg([result["offsets_rad"][n] - truth[n] for n in truth])
    assert np.abs(err).max() < 0.5, err  # the log path recovers the offsets (the guide's test is tighter)
    assert re.search(r"passed", stdout)  # the envs' smoke test ran
    assert (work / "runs" / "walk_eval" / "a3_paper3" / "report.md").is_file()


CHECKS = {"docs/log-import.md": _log_import, "docs/effect-plugins.md": _effect_plugins,
          "docs/python-api.md": _python_api, "README.md": _readme}
