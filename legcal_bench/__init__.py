"""legcal-bench: a benchmark suite for humanoid leg joint-offset calibration.

Layers, each importing only from those before it (a test checks):
errors, paper, provenance, files -> geometry -> robots -> sim -> data -> protocol ->
estimation -> calibrators -> envs -> policies -> evaluation -> benchmark -> reports -> cli.
"""

from legcal_bench.provenance import package_version

__version__ = package_version()
