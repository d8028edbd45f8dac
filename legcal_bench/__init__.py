"""legcal-bench: a benchmark suite for humanoid leg joint-offset calibration.

Layers, each importing only from those before it (a test checks):
errors, paper, provenance, files -> geometry -> robots -> sim -> data -> protocol ->
estimation -> calibrators -> envs -> policies -> evaluation -> benchmark -> reports -> api -> cli.

The Python API (`legcal_bench.api`) is on this top level, loaded on first use so that
`import legcal_bench` (and the command's start-up) stays light:

    import legcal_bench as lb
    result = lb.calibrate("runs/set", robot="a3")
"""

import os
import platform

# One floating point on every x86-64 machine: OpenBLAS picks its kernels by CPU (AVX-512
# ones on newer Xeons, Haswell/AVX2 ones before), which moves the iterative fits by 1e-8
# (offsets) to 1e-4 (the zero-noise `alternating` rows) relative: the regression fixture
# failed on an AVX-512 machine with the same code and wheels and passed with this setting.
# It must be set before numpy loads OpenBLAS; a user's own setting wins.
if platform.machine().lower() in ("x86_64", "amd64"):
    os.environ.setdefault("OPENBLAS_CORETYPE", "Haswell")

# The API's names, loaded on first access (PEP 562); `__version__` too, as reading the
# installed metadata (importlib.metadata) costs the command's start-up tens of ms.
_API = ("collect", "import_log", "load", "calibrate", "score", "diagnose", "walk", "walk_eval")


def __getattr__(name: str):
    if name in _API:
        import importlib

        return getattr(importlib.import_module("legcal_bench.api"), name)
    if name == "__version__":
        from legcal_bench.provenance import package_version

        return package_version()
    raise AttributeError(f"module 'legcal_bench' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_API) + ["__version__"])
