from __future__ import annotations

import ast
import functools
import json
import os
from dataclasses import asdict
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import legcal_bench  # noqa: E402,F401  (first: its OpenBLAS kernel choice must precede numpy's loading)

import pytest

REPO = Path(__file__).resolve().parents[1]
G1_LEGMAP = REPO / "examples" / "unitree_g1.legmap.yaml"
BUILTIN = ["a2", "a3", "pair_ryp", "pair_pry"]


@functools.cache
def module_group(path: Path) -> str | None:
    """The name in a test module's `pytestmark = pytest.mark.xdist_group(name)`, if any."""
    try:
        tree = ast.parse(path.read_text(), str(path))
    except (OSError, SyntaxError, ValueError):
        return None
    for node in tree.body:
        if not (isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "pytestmark"
                                                     for t in node.targets)):
            continue
        for call in ast.walk(node.value):
            if isinstance(call, ast.Call) and getattr(call.func, "attr", None) == "xdist_group":
                arg = call.args[0] if call.args else next((k.value for k in call.keywords if k.arg == "name"), None)
                if isinstance(arg, ast.Constant):
                    return str(arg.value)
    return None


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """`--dist loadgroup` as pytest-xdist documents it, for module-level marks: a module
    whose `pytestmark` names an `xdist_group` (it shares data its tests collect once, or
    state, between its tests) runs whole, in order, in one worker; every other test goes
    to whichever worker is free. pytest-xdist 3.8's own loadgroup marks a group by editing
    the test's node id, which pytest 9.2 no longer lets it do, and silently spreads every
    test (pytest-dev/pytest-xdist#1386): this reads the group from the module instead.
    Returns None (xdist's own choice) for any other --dist."""
    if config.getvalue("dist") != "loadgroup":
        return None
    from xdist.scheduler import LoadScopeScheduling

    root = config.rootpath

    class ModuleGroupScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            if nodeid.rfind("@") > nodeid.rfind("]"):  # a node id xdist did mark (a fixed xdist)
                return nodeid.split("@")[-1]
            group = module_group(root / nodeid.split("::", 1)[0])
            return f"group:{group}" if group else nodeid

    return ModuleGroupScheduling(config, log)


# Modules with the longest single tests (tens of seconds to minutes each, issue #36's
# `--durations`): under pytest-xdist they are queued first among the tests that are not
# in an xdist group (after the groups, which xdist queues first, largest first), so that
# none of them starts last and runs alone while the other process idles. Only the order
# in which the processes take tests changes; a run without pytest-xdist keeps its order.
SLOW_FIRST = ("tests/evaluation/test_closed_loop.py", "tests/reports/test_regression.py",
              "tests/evaluation/test_modelgap.py", "tests/protocol/test_robots_as_they_come.py",
              "tests/benchmark/test_leaderboard.py", "tests/evaluation/test_distill.py", "tests/integrity/")


def pytest_collection_modifyitems(config, items):
    if hasattr(config, "workerinput"):  # a pytest-xdist worker: every worker sorts alike
        items.sort(key=lambda item: not item.nodeid.startswith(SLOW_FIRST))  # stable: modules keep their order


@pytest.fixture(scope="session")
def pool_workers() -> int:
    """Worker processes a test may start for a pool of its own (the commands' default, 2),
    but no more than the cores left to each test process when pytest-xdist runs several
    (`make test`: 2 on 2 cores leave 1 each), so pools do not oversubscribe the machine."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    runners = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    return max(1, min(2, cores // runners))


@pytest.fixture(scope="session")
def collected(tmp_path_factory):
    """collected(**config) -> the folder of a session set collected with
    `CollectConfig(**config)`, collected once per test process and shared by every test
    that asks for the same config (defaults spelled out or not). Read it (load_session
    gives fresh arrays to edit); copy it before changing its files."""
    from legcal_bench.protocol.collect import CollectConfig, collect

    cache: dict[str, Path] = {}

    def get(**config) -> Path:
        cfg = CollectConfig(**config)
        key = json.dumps(asdict(cfg), sort_keys=True)
        if key not in cache:
            out = tmp_path_factory.mktemp("collected") / "set"
            collect(cfg, out, progress=False)
            cache[key] = out
        return cache[key]

    return get


@pytest.fixture(scope="session")
def testbot_legmap(tmp_path_factory) -> Path:
    """A small synthetic robot: held waist/arm joints, soles given as poses relative to a
    foot body whose frame is rotated away from the sole."""
    from dataclasses import replace

    from legcal_bench.robots.build import write_robot
    from legcal_bench.robots.design import BASE

    design = replace(BASE.scaled("testbot", length=0.6, mass=0.5), hip_order=("hip_roll", "hip_pitch", "hip_yaw"))
    return write_robot(design, tmp_path_factory.mktemp("testbot"), upper_body=True, sole_sites=False,
                       foot_frame_rpy=(0.1, -0.2, 0.3))


@pytest.fixture(scope="session")
def all_robots(testbot_legmap) -> list[str]:
    return BUILTIN + [str(G1_LEGMAP), str(testbot_legmap)]


@pytest.fixture
def in_process_cells(monkeypatch):
    """`bench` and `sweep` (`legcal_bench.benchmark.runner.run`) compute their session sets
    and cells here, one after another, instead of in a pool of fresh worker processes
    (each of which would load the package and the simulation again, seconds per command).
    For tests that check what the cells compute; the pool itself is tested in
    tests/benchmark (test_runner, test_process_hygiene)."""
    from concurrent.futures import Executor, Future

    from legcal_bench.benchmark import runner

    class InProcess(Executor):
        def submit(self, fn, /, *args, **kwargs):
            done = Future()
            try:
                done.set_result(fn(*args, **kwargs))
            except BaseException as e:  # the pool would hand it back through the future too
                done.set_exception(e)
            return done

    monkeypatch.setattr(runner, "make_executor", lambda scheduler, workers: (InProcess(), None))


@pytest.fixture(scope="session")
def long_log():
    """The simulated long robot log of the A3-like robot (standing, stances I-IV, walking,
    stepping in place, standing; ~15 s to make): built once per test process. Modules
    using it share the xdist group "long_log", so one process builds it."""
    from legcal_bench.evaluation.long_log import simulate_long_log

    return simulate_long_log("a3", seed=0)
