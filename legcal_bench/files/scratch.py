"""Scratch folders a killed command cannot leave behind for good.

A temporary folder's name carries the process that made it (`legcal_<what>_<pid>_…`
in the system's temporary folder); a process killed outright (SIGKILL, a power cut)
cannot remove its own, so every command removes, as it starts (`sweep`), the ones
whose process is gone. Hidden partial folders and files beside a result
(`legcal_bench.files.atomic`) carry their process the same way and are swept by the
next write to the same place.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
from contextlib import contextmanager
from pathlib import Path

PREFIX = "legcal_"
_OWNED = re.compile(r"^legcal_[A-Za-z0-9]+(?:_[A-Za-z0-9]+)*?_p(\d+)_")


def alive(pid: int) -> bool:
    """Whether process `pid` exists (on this machine)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process
        return True
    return True


@contextmanager
def scratch_dir(what: str):
    """A temporary folder named for `what` and this process, removed on the way out
    (an exception or Ctrl-C included); after SIGKILL, by the next command's `sweep`."""
    import tempfile

    path = tempfile.mkdtemp(prefix=f"{PREFIX}{what}_p{os.getpid()}_")
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)


def owner(name: str) -> int | None:
    """The process a scratch folder's name says made it, or None (not one of ours)."""
    m = _OWNED.match(name)
    return int(m.group(1)) if m else None


def sweep(folder: str | Path | None = None) -> list[Path]:
    """Remove scratch folders in `folder` (the system's temporary folder) whose process
    is gone; returns what was removed. Cheap: one directory listing."""
    root = Path(folder or _tempdir())
    removed = []
    try:
        entries = list(os.scandir(root))
    except OSError:
        return removed
    for e in entries:
        if not e.name.startswith(PREFIX):
            continue
        pid = owner(e.name)
        if pid is None or alive(pid):
            continue
        shutil.rmtree(e.path, ignore_errors=True) if e.is_dir(follow_symlinks=False) else _unlink(e.path)
        removed.append(Path(e.path))
    return removed


def _tempdir() -> str:
    """The system's temporary folder as `tempfile` chooses it, without importing it at
    every command's start (~5 ms) unless something already has."""
    if "tempfile" in sys.modules:
        return sys.modules["tempfile"].gettempdir()
    for var in ("TMPDIR", "TEMP", "TMP"):
        if os.environ.get(var) and os.path.isdir(os.environ[var]):
            return os.environ[var]
    return "/tmp" if os.path.isdir("/tmp") else os.getcwd()


def _unlink(path: str) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass
