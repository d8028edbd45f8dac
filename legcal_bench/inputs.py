"""Inputs checked at the door: one rule per concept (a number in a range, a seed, a
count, a writable output folder, a text file, a mapping's keys), the same for the
command line, the Python API and the Gymnasium envs' keyword arguments.

Every check raises `ConfigError` (a `LegcalError`: the CLI prints it in one line and
exits 2) naming the field, the value given and the fix, before any simulation or
solve starts. The commands call them first thing (`legcal_bench.cli.robots.door`).

Standard library only: the CLI's parser imports this module, and its start-up stays
light.
"""

from __future__ import annotations

import math
import numbers
import os
from pathlib import Path

from legcal_bench.errors import ConfigError

SEED_MAX = 2**32 - 1  # numpy's legacy seeding and MuJoCo's take a 32-bit unsigned seed


def shown(value) -> str:
    """A value as a message shows it: null, or its repr, shortened to 80 characters."""
    if value is None:
        return "null"
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def is_finite_number(value) -> bool:
    """A finite int or float (not a bool, a string, or an int too large for a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def number(field: str, value, *, low: float | None = None, high: float | None = None, low_open: bool = False,
           high_open: bool = False, integer: bool = False, fix: str = "") -> float | int:
    """`value` as a finite number (an int with `integer`) within [low, high] (open at an
    end with `low_open` / `high_open`); a string is parsed. Else ConfigError naming
    `field`, the value and the range, and `fix` when given."""
    what = "an integer" if integer else "a number"
    hint = f" ({fix})" if fix else ""
    if isinstance(value, bool) or value is None:
        raise ConfigError(f"{field} = {value!r}: expected {what}{_range(low, high, low_open, high_open)}{hint}")
    try:
        if isinstance(value, str):
            x = int(value.strip()) if integer else float(value.strip())
        elif integer:
            if isinstance(value, numbers.Integral):
                x = int(value)
            elif isinstance(value, numbers.Real) and float(value).is_integer():
                x = int(value)
            else:
                raise ValueError
        else:
            x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{field} = {value!r}: expected {what}{_range(low, high, low_open, high_open)}{hint}") \
            from None
    if not math.isfinite(x):
        raise ConfigError(f"{field} = {value!r}: expected a finite number{_range(low, high, low_open, high_open)}"
                          f"{hint}")
    if (low is not None and (x < low or (low_open and x == low))) or \
            (high is not None and (x > high or (high_open and x == high))):
        raise ConfigError(f"{field} = {value!r}: out of range, expected {what}"
                          f"{_range(low, high, low_open, high_open)}{hint}")
    return x


def _range(low, high, low_open, high_open) -> str:
    if low is None and high is None:
        return ""
    if high is None:
        return f" {'>' if low_open else '>='} {_num(low)}"
    if low is None:
        return f" {'<' if high_open else '<='} {_num(high)}"
    return f" in {'(' if low_open else '['}{_num(low)}, {_num(high)}{')' if high_open else ']'}"


def _num(x: float) -> str:
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def positive(field: str, value, *, high: float | None = None, fix: str = "") -> float:
    """A finite number > 0 (at most `high`)."""
    return number(field, value, low=0.0, low_open=True, high=high, fix=fix)


def non_negative(field: str, value, *, high: float | None = None, fix: str = "") -> float:
    """A finite number >= 0 (at most `high`)."""
    return number(field, value, low=0.0, high=high, fix=fix)


def count(field: str, value, *, low: int = 1, high: int | None = None, fix: str = "") -> int:
    """An integer >= `low` (1: a count of things to run; 0 where none is meaningful)."""
    return number(field, value, low=low, high=high, integer=True, fix=fix)


def seed(field: str, value) -> int:
    """A random seed: an integer in [0, 2^32 - 1]."""
    return number(field, value, low=0, high=SEED_MAX, integer=True, fix="a seed is a non-negative integer")


def choice(field: str, value, options) -> str:
    """One of `options` (strings); a misspelling gets the closest option named."""
    import difflib  # on the error's path only: the CLI's start-up stays light

    options = list(options)
    if value in options:
        return value
    close = difflib.get_close_matches(str(value), options, n=1)
    hint = f"; did you mean {close[0]!r}?" if close else ""
    raise ConfigError(f"{field} = {value!r}: expected one of {', '.join(map(str, options))}{hint}")


def known_keys(where: str, mapping: dict, allowed, fix: str = "") -> None:
    """Refuse keys of `mapping` not in `allowed` (a misspelt key would otherwise be
    ignored silently), each named with the closest allowed key."""
    allowed = list(allowed)
    bad = [k for k in mapping if k not in allowed]
    if not bad:
        return
    import difflib

    parts = []
    for k in bad:
        close = difflib.get_close_matches(str(k), [str(a) for a in allowed], n=1)
        parts.append(f"{k!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    raise ConfigError(f"{where}: unknown key{'s' if len(bad) > 1 else ''} {', '.join(parts)}; known: "
                      f"{', '.join(map(str, allowed))}" + (f" ({fix})" if fix else ""))


PROBE_PREFIX = ".legcal-probe-"  # the probe file `output_folder` creates and deletes at once


def output_folder(field: str, path) -> Path:
    """An output folder that can be written, proved by writing, before the work (so that
    a long run does not end on an unwritable path; `os.access` would not do: as root it
    says yes to every folder, and it knows nothing of read-only or virtual file systems).

    It creates the missing folders of `path`, then creates and deletes a probe file
    (`PROBE_PREFIX`...) in `path`, then removes again the folders it created (each only
    if still empty: a folder another process wrote into meanwhile stays). An existing
    folder is left as it was. Refused with a ConfigError naming `field`, the path, the
    operating system's reason and the fix: a file where the folder or one of its parents
    should be, a folder that cannot be made, a folder no file can be written into."""
    if path is None or str(path).strip() == "":
        raise ConfigError(f"{field}: no folder given (give a folder to write into)")
    p = Path(path).expanduser()
    if _not_folder(p):
        raise ConfigError(f"{field} {str(path)!r}: is a file, not a folder (give a folder to write into)")
    _writable(field, str(path), p)
    return p


def output_file(field: str, path) -> Path:
    """A file that can be written: not a folder, and its folder writable (`output_folder`'s
    probe, the same folders created and removed again); the file itself is not touched."""
    if path is None or str(path).strip() == "":
        raise ConfigError(f"{field}: no file given")
    p = Path(path).expanduser()
    if p.is_dir():
        raise ConfigError(f"{field} {str(path)!r}: is a folder, not a file (give a file path)")
    folder = p.parent if str(p.parent) else Path(".")
    if _not_folder(folder):
        raise ConfigError(f"{field} {str(path)!r}: {str(folder)!r} is a file, so the file cannot be made in it "
                          f"(give a path in a folder)")
    _writable(field, str(path), folder)
    return p


RACE_TRIES = 5  # another process's check may remove, between two steps, a folder it made


def _writable(field: str, given: str, folder: Path) -> None:
    """Prove `folder` writable: make its missing parents and itself, create and delete a
    probe file in it, remove the folders made (`output_folder`). Two checks at once under
    one new parent (parallel commands, test workers) may see the other remove a folder
    it made while this one stands in it: the check starts over, `RACE_TRIES` times."""
    for attempt in range(RACE_TRIES):
        try:
            return _writable_once(field, given, folder, last=attempt == RACE_TRIES - 1)
        except _Raced:
            continue


def _not_folder(path: Path) -> bool:
    """Something other than a folder is at `path` (one look: a folder removed meanwhile
    is not taken for a file)."""
    import stat

    try:
        return not stat.S_ISDIR(os.stat(path).st_mode)
    except (FileNotFoundError, NotADirectoryError):
        return False


class _Raced(Exception):
    """A folder vanished between two steps of a check (another check removed it)."""


def _writable_once(field: str, given: str, folder: Path, last: bool) -> None:
    import tempfile  # on the check's path only: the CLI's start-up stays light

    missing = []
    nearest = folder
    while not nearest.exists() and not nearest.is_symlink():
        missing.append(nearest)
        if nearest.parent == nearest:
            break
        nearest = nearest.parent
    if _not_folder(nearest):
        raise ConfigError(f"{field} {given!r}: {str(nearest)!r} is a file, so the folder cannot be made there "
                          f"(give a folder path)")
    made = []
    try:
        for d in reversed(missing):
            try:
                d.mkdir()
            except FileExistsError:
                if not d.is_dir():
                    raise
                continue  # made meanwhile by another process: not ours to remove
            made.append(d)
    except OSError as e:
        _remove(made)
        if isinstance(e, (FileNotFoundError, FileExistsError)) and not last:  # a folder came and went meanwhile
            raise _Raced from None
        raise ConfigError(f"{field} {given!r}: cannot make the folder {str(d)!r} ({e.strerror or e}); give a folder "
                          f"you can write to") from None
    try:
        fd, probe = tempfile.mkstemp(prefix=PROBE_PREFIX, dir=folder)
    except OSError as e:
        _remove(made)
        if isinstance(e, FileNotFoundError) and not last:
            raise _Raced from None
        raise ConfigError(f"{field} {given!r}: cannot write into {str(folder)!r} ({e.strerror or e}); give a folder "
                          f"you can write to") from None
    os.close(fd)
    os.unlink(probe)
    _remove(made)


def _remove(made: list[Path]) -> None:
    """The folders `_writable` made, deepest first, each only if still empty."""
    for d in reversed(made):
        try:
            d.rmdir()
        except OSError:
            return  # not empty (another process wrote into it): it and its parents stay


def read_text(field: str, path, what: str = "file") -> str:
    """A text file's contents, UTF-8; a missing file, a folder, unreadable or
    undecodable bytes refused with the file and the fix named."""
    p = Path(path)
    if p.is_dir():
        raise ConfigError(f"{field} {str(path)!r}: is a folder; give the {what} itself")
    try:
        raw = p.read_bytes()
    except FileNotFoundError:
        raise ConfigError(f"{field} {str(path)!r}: no such {what}") from None
    except OSError as e:
        raise ConfigError(f"{field} {str(path)!r}: cannot read the {what} ({e.strerror})") from None
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise ConfigError(f"{field} {str(path)!r}: the {what} is not UTF-8 text (byte {e.start}: "
                          f"{raw[e.start:e.start + 1]!r}); save it as UTF-8") from None
