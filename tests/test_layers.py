"""The package's structure: imports go only downward through the layers, no module
imports itself back through a cycle, and legcal_bench/ keeps only a handful of
top-level modules."""

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# Source folders and the package they install as.
ROOTS = {"legcal_bench": "legcal_bench", "envs": "legcal_bench.envs", "calibrators": "legcal_bench.calibrators",
         "policies": "legcal_bench.policies", "examples": "legcal_bench.examples"}
# Lowest first; a module may import from its own layer or any before it.
LAYERS = [
    ("core", ("legcal_bench", "legcal_bench.errors", "legcal_bench.inputs", "legcal_bench.paper",
              "legcal_bench.provenance",
              "legcal_bench.files", "legcal_bench.examples")),
    ("geometry", ("legcal_bench.geometry",)),
    ("robots", ("legcal_bench.robots",)),
    ("sim", ("legcal_bench.sim",)),
    ("data", ("legcal_bench.data",)),
    ("protocol", ("legcal_bench.protocol",)),
    ("estimation", ("legcal_bench.estimation",)),
    # Robot logs in: read, align, detect, write recordings (uses kinematics and the data format).
    ("logs", ("legcal_bench.logs",)),
    ("calibrators", ("legcal_bench.calibrators",)),
    # A policy is observation -> action (spec, network, runner): the walking env takes
    # its spec for the servos; rollouts live in evaluation.
    ("policies", ("legcal_bench.policies",)),
    ("envs", ("legcal_bench.envs",)),
    ("evaluation", ("legcal_bench.evaluation",)),
    ("benchmark", ("legcal_bench.benchmark",)),
    ("reports", ("legcal_bench.reports",)),
    # The Python API: the commands' work for scripts (the package's top level loads it lazily).
    ("api", ("legcal_bench.api",)),
    ("cli", ("legcal_bench.cli",)),
]


def modules() -> dict[str, Path]:
    out = {}
    for folder, package in ROOTS.items():
        for path in sorted((REPO / folder).rglob("*.py")):
            parts = list(path.relative_to(REPO / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


def layer(module: str) -> int:
    best, best_len = None, -1
    for i, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    assert best is not None, f"{module} is in no layer: add it to LAYERS"
    return best


def imports(module: str, path: Path, known: set[str]) -> set[str]:
    """legcal_bench modules imported anywhere in the file (functions included)."""
    tree = ast.parse(path.read_text(), str(path))
    is_pkg = path.name == "__init__.py"
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = module.split(".") if is_pkg else module.split(".")[:-1]
                pkg = pkg[: len(pkg) - (node.level - 1)]
                base = ".".join(pkg + ([base] if base else []))
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base for a in node.names]
        else:
            continue
        for n in names:
            if n.startswith("legcal_bench"):
                while n not in known and "." in n:
                    n = n.rsplit(".", 1)[0]
                out.add(n)
    out.discard(module)
    return out


def test_imports_only_go_down_the_layers():
    mods = modules()
    known = set(mods)
    upward = []
    for m, path in mods.items():
        for target in imports(m, path, known):
            if layer(target) > layer(m):
                upward.append(f"{m} ({LAYERS[layer(m)][0]}) imports {target} ({LAYERS[layer(target)][0]})")
    assert not upward, "\n".join(upward)


def test_no_import_cycles():
    mods = modules()
    known = set(mods)
    graph = {m: imports(m, p, known) for m, p in mods.items()}
    # A package's __init__ importing its own submodules is how packages expose them.
    graph = {m: {t for t in ts if not t.startswith(m + ".")} for m, ts in graph.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        stack.append(m)
        for t in sorted(graph.get(m, ())):
            if state.get(t) == 1:
                return stack[stack.index(t):] + [t]
            if state.get(t) is None:
                found = visit(t)
                if found:
                    return found
        stack.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if state.get(m) is None:
            cycle = visit(m)
            assert cycle is None, " -> ".join(cycle)


def test_the_layer_test_sees_an_upward_import(tmp_path):
    """The checker itself: a robots module importing the benchmark is caught."""
    bad = tmp_path / "bad.py"
    bad.write_text("def f():\n    from legcal_bench.benchmark.plan import plan\n")
    known = set(modules())
    found = imports("legcal_bench.robots.bad", bad, known)
    assert found == {"legcal_bench.benchmark.plan"}
    assert layer("legcal_bench.benchmark.plan") > layer("legcal_bench.robots.bad")


def test_a_handful_of_top_level_modules():
    top = sorted(p.name for p in (REPO / "legcal_bench").glob("*.py"))
    assert len(top) <= 5, top
