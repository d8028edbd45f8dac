"""The documents' runnable snippets, and an installed wheel to run them against.

A snippet is a fenced block of README.md or a page under docs/:

- ```` ```bash ````: each line a command (`legcal-bench ...`, `pytest ...`, `pip ...`);
- ```` ```console ````: each line starting with `$ ` a command, the lines after it the
  output the page quotes;
- ```` ```python ````: a script.

An HTML comment on the line before a block changes how it runs: `<!-- smoke: --trials 2
--seconds 5 -->` gives options their smoke sizes (each replaces the option's value in
every command of the block, or is added), `<!-- not run: why -->` leaves the block out
and says why. Other blocks (yaml, toml, text) are not snippets.
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DOCUMENTS = ["README.md", *sorted(str(p.relative_to(REPO)) for p in (REPO / "docs").rglob("*.md"))]
RUNNABLE = ("bash", "console", "python")
# What a wheel is built from (pyproject.toml's packages and package data).
SOURCES = ("pyproject.toml", "README.md", "legcal_bench", "envs", "policies", "calibrators", "examples")
BLOCK = re.compile(r"(?:<!--\s*(smoke|not run):\s*(.*?)\s*-->\n)?```(\w+)\n(.*?)```", re.S)


@dataclass
class Snippet:
    document: str
    kind: str  # bash | console | python
    text: str
    smoke: list[str] = field(default_factory=list)
    not_run: str | None = None

    def commands(self) -> list[tuple[list[str], list[str]]]:
        """(argv, quoted output lines) of each command, smoke sizes applied."""
        out: list[tuple[list[str], list[str]]] = []
        for line in self.text.replace("\\\n", " ").splitlines():
            if self.kind == "console":
                if line.startswith("$ "):
                    out.append((with_smoke(shlex.split(line[2:]), self.smoke), []))
                elif line.strip() and out:
                    out[-1][1].append(line.strip())
            elif line.strip() and not line.lstrip().startswith("#"):
                out.append((with_smoke(shlex.split(line, comments=True), self.smoke), []))
        return out


def with_smoke(argv: list[str], smoke: list[str]) -> list[str]:
    """`argv` with each `--option value` of `smoke` replacing the option's value, or added."""
    argv = list(argv)
    for i in range(0, len(smoke), 2):
        option, value = smoke[i], smoke[i + 1]
        if option in argv:
            argv[argv.index(option) + 1] = value
        else:
            argv += [option, value]
    return argv


def snippets(document: str) -> list[Snippet]:
    out = []
    for m in BLOCK.finditer((REPO / document).read_text()):
        mark, note, kind, text = m.groups()
        if kind in RUNNABLE:
            out.append(Snippet(document, kind, text, shlex.split(note) if mark == "smoke" else [],
                               note if mark == "not run" else None))
    return out


def build_wheel(work: Path) -> Path:
    """The package's wheel, built from a copy of its sources (the checkout stays clean),
    with the installed build back end: no download."""
    src = work / "src"
    src.mkdir(parents=True)
    for name in SOURCES:
        (shutil.copytree if (REPO / name).is_dir() else shutil.copy)(
            REPO / name, src / name, **({"ignore": shutil.ignore_patterns("__pycache__")}
                                        if (REPO / name).is_dir() else {}))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                    "--disable-pip-version-check", "-w", str(work / "dist"), str(src)], check=True,
                   capture_output=True)
    return next((work / "dist").glob("legcal_bench-*.whl"))


def install(wheel: Path, venv: Path) -> Path:
    """A fresh virtual environment with the wheel installed, reusing this environment's
    installed dependencies (its site-packages after the venv's own, by a .pth file: no
    download, and this environment's editable legcal-bench stays out of it). Its bin/."""
    import sysconfig

    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    site = next((venv / "lib").glob("python3*/site-packages"))
    deps = Path(sysconfig.get_paths()["purelib"])
    (site / "_legcal_deps.pth").write_text(f"{deps}\n")  # processed first ('_' sorts before letters)
    for pth in deps.glob("*.pth"):  # what they run (pin's cmeel prefix) but this environment's legcal-bench
        if not pth.name.startswith("__editable__"):
            shutil.copy(pth, site / pth.name)
    # The examples built on the external models (the G1's) find them in ../shared beside a
    # checkout, by a path relative to the example file: beside the installed examples, the
    # same relative path leads to site-packages/shared.
    if (REPO.parent / "shared").is_dir():
        (site / "shared").symlink_to(REPO.parent / "shared")
    python = venv / "bin" / "python"
    subprocess.run([python, "-m", "pip", "install", "--quiet", "--no-deps", "--no-index",
                    "--disable-pip-version-check", str(wheel)], check=True, capture_output=True)
    return venv / "bin"


def environment(bin_dir: Path) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return {**env, "PATH": f"{bin_dir}{os.pathsep}{env.get('PATH', '')}", "VIRTUAL_ENV": str(bin_dir.parent),
            "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "MUJOCO_GL": "egl"}


def argv_in(bin_dir: Path, argv: list[str]) -> list[str]:
    """A documented command as the installed environment runs it."""
    python = str(bin_dir / "python")
    if argv[0] == "legcal-bench":
        return [str(bin_dir / "legcal-bench"), *argv[1:]]
    if argv[0] == "pip" and argv[1:2] == ["install"]:  # offline, into the test's environment
        return [python, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", "--no-index",
                *argv[2:]]
    if argv[0] in ("pytest", "pip"):
        return [python, "-m", argv[0], *argv[1:]]
    if argv[0] == "python":
        return [python, *argv[1:]]
    raise ValueError(f"a documented command this test does not know how to run: {shlex.join(argv)}")


# Runs a list of legcal-bench commands in one interpreter of the installed environment,
# as `legcal-bench ARGS` would one by one (`legcal_bench.cli.main`): each command's exit
# code and printed output, stopping at the first that fails. One start-up (torch, MuJoCo,
# Pinocchio) per run of consecutive commands instead of one per command.
DRIVER = """import contextlib, io, json, sys, traceback
from legcal_bench.cli import main
steps, out = json.load(open(sys.argv[1])), []
for argv in steps:
    buf, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        try:
            rc = main(argv)
        except SystemExit as e:
            rc = e.code if isinstance(e.code, int) else 2
        except BaseException:
            rc, _ = 1, traceback.print_exc()
    out.append({"rc": rc, "out": buf.getvalue(), "err": err.getvalue()})
    json.dump(out, open(sys.argv[2], "w"))
    if rc != 0:
        break
"""


def run_document(document: str, bin_dir: Path, work: Path, timeout: float = 600) -> list[tuple[str, str]]:
    """Run every snippet of `document` in order in `work` (a fresh folder: the commands'
    relative paths start there; docs/examples/ is copied in, as a checkout has it):
    consecutive `legcal-bench` commands in one interpreter of the installed environment
    (`DRIVER`), python blocks as scripts, pytest and pip as their own processes. Returns
    (command, its output) of each; raises AssertionError naming the command that failed,
    with its output."""
    import json

    work.mkdir(parents=True, exist_ok=True)
    if (REPO / "docs" / "examples").is_dir():
        shutil.copytree(REPO / "docs" / "examples", work / "docs" / "examples",
                        ignore=shutil.ignore_patterns("__pycache__", "*.egg-info", "build"))
    env = environment(bin_dir)
    (work / "_commands.py").write_text(DRIVER)
    steps: list[tuple[str, list[str], list[str]]] = []  # (how, argv, quoted output)
    for i, s in enumerate(snippets(document)):
        if s.not_run:
            continue
        if s.kind == "python":
            script = work / f"snippet_{i}.py"
            script.write_text(s.text)
            steps.append(("process", [str(bin_dir / "python"), script.name], []))
        else:
            steps += [("cli", argv[1:], quoted) if argv[0] == "legcal-bench" else
                      ("process", argv_in(bin_dir, argv), quoted) for argv, quoted in s.commands()]
    done = []

    def check(shown: str, rc: int, out: str, err: str, quoted: list[str]) -> None:
        assert rc == 0, f"{document}: `{shown}` exited {rc}:\n{(out + err)[-3000:]}"
        for line in quoted:  # the words the page quotes, not its figures
            head = re.split(r"[\d(]", line, maxsplit=1)[0].strip()
            assert head in out, f"{document}: `{shown}` did not print {head!r}:\n{out[-2000:]}"
        done.append((shown, out))

    k = 0
    while k < len(steps):
        how, argv, quoted = steps[k]
        if how == "process":
            r = subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True, timeout=timeout)
            check(shlex.join(argv), r.returncode, r.stdout, r.stderr, quoted)
            k += 1
            continue
        run = [k]
        while run[-1] + 1 < len(steps) and steps[run[-1] + 1][0] == "cli":
            run.append(run[-1] + 1)
        (work / "_steps.json").write_text(json.dumps([steps[j][1] for j in run]))
        r = subprocess.run([str(bin_dir / "python"), "_commands.py", "_steps.json", "_results.json"], cwd=work,
                           env=env, capture_output=True, text=True, timeout=timeout)
        results = json.loads((work / "_results.json").read_text()) if (work / "_results.json").is_file() else []
        (work / "_results.json").unlink(missing_ok=True)
        for j, res in zip(run, results):
            check("legcal-bench " + shlex.join(steps[j][1]), res["rc"], res["out"], res["err"], steps[j][2])
        assert len(results) == len(run), (f"{document}: the commands' interpreter ended after {len(results)} of "
                                          f"{len(run)} (exit {r.returncode}):\n{(r.stdout + r.stderr)[-3000:]}")
        k = run[-1] + 1
    return done
