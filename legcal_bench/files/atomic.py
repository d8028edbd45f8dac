"""Atomic file writes: a result file is either whole or absent, never half-written."""

from __future__ import annotations

import json
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import Any, Callable

from legcal_bench.errors import ConfigError


def atomic_write(path: str | Path, write: Callable[[Any], None], mode: str = "w") -> Path:
    """Call `write(fileobj)` on a temporary file beside `path`, then rename it over `path`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    sweep_beside(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=_prefix(path), suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes 0600; results are shared files
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _prefix(path: Path) -> str:
    """A partial file or folder beside `path`: hidden, named for it and this process."""
    return f".{path.name}.p{os.getpid()}."


def sweep_beside(path: str | Path) -> list[Path]:
    """Remove the partial files and folders beside `path` (`_prefix`) whose process is
    gone: a write killed outright (SIGKILL) leaves them; the next write to the same
    place removes them. A live process's (a concurrent writer's) are left alone."""
    from legcal_bench.files.scratch import alive

    path = Path(path)
    pattern = re.compile(rf"^\.{re.escape(path.name)}\.p(\d+)\..*\.(tmp|old)$")
    removed = []
    try:
        entries = list(os.scandir(path.parent))
    except OSError:
        return removed
    for e in entries:
        m = pattern.match(e.name)
        if m and not alive(int(m.group(1))):
            if e.is_dir(follow_symlinks=False):
                shutil.rmtree(e.path, ignore_errors=True)
            else:
                try:
                    os.unlink(e.path)
                except OSError:
                    pass
            removed.append(Path(e.path))
    return removed


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> Path:
    return atomic_write(path, lambda f: f.write(text))


def atomic_write_json(path: str | Path, obj: Any) -> Path:
    return atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=True) + "\n")


def rows_json(obj: Any) -> str:
    """`obj` as JSON a row per line: each key of a top-level dict on its own line, each
    item of a top-level list (or of a list under a top-level key) on its own line,
    compact within (no indentation: a report's rows without the bulk indenting adds,
    still one row per line in a diff). Keys sorted; `json.loads` gives `obj` back."""
    def one(o: Any) -> str:
        return json.dumps(o, sort_keys=True, separators=(",", ":"))

    def items(xs: list) -> list[str]:
        return [one(x) + ("," if i < len(xs) - 1 else "") for i, x in enumerate(xs)]

    if isinstance(obj, list) and obj:
        return "\n".join(["[", *items(obj), "]"]) + "\n"
    if not isinstance(obj, dict) or not obj:
        return one(obj) + "\n"
    lines = ["{"]
    keys = sorted(obj)
    for i, k in enumerate(keys):
        v, end = obj[k], "," if i < len(keys) - 1 else ""
        if isinstance(v, list) and v:
            lines += [f"{one(k)}:[", *items(v), "]" + end]
        else:
            lines.append(f"{one(k)}:{one(v)}{end}")
    return "\n".join(lines + ["}"]) + "\n"


def atomic_write_dir(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call `write(folder)` on a temporary folder beside `path`, then rename it to `path`
    (which must not exist): the folder appears whole or not at all."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    sweep_beside(path)
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=_prefix(path), suffix=".tmp"))
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return path


def replace_dir(path: str | Path, write: Callable[[Path], None], keep_if: Callable[[Path], bool]) -> Path:
    """`atomic_write_dir`, replacing an existing `path` if `keep_if(path)` says it may be
    (e.g. it holds only an earlier result of the same kind); otherwise an existing,
    non-empty `path` is refused with a ConfigError naming the fix. The old folder is
    renamed aside, the new one renamed in, the old one removed: `path` is never a
    mixture of the two."""
    path = Path(path)
    if path.exists() and not (path.is_dir() and (not any(path.iterdir()) or keep_if(path))):
        raise ConfigError(f"--out {path} exists and holds other files; give a new folder (it is replaced only "
                          "when it holds an earlier result of the same kind)")
    if not path.exists():
        return atomic_write_dir(path, write)
    sweep_beside(path)
    old = Path(tempfile.mkdtemp(dir=path.parent, prefix=_prefix(path), suffix=".old"))
    tmp = Path(tempfile.mkdtemp(dir=path.parent, prefix=_prefix(path), suffix=".tmp"))
    try:
        write(tmp)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(old, ignore_errors=True)
        raise
    os.replace(path, old / "previous")
    os.replace(tmp, path)
    shutil.rmtree(old, ignore_errors=True)
    return path
