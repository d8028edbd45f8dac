"""The calibrator registry and its options (`legcal_bench.calibrators.registry`).

Calibrators are found through the entry-point group `legcal_bench.calibrators`
(`available_calibrators`, `calibrator_class`) and built with checked options
(`get_calibrator`). One parser for every command that takes calibrator options (`calibrate`, `walk-eval`):
the text is converted by the constructor parameter's annotation, so `--option
max_outer=3` arrives as the int 3 wherever it is given, `--option effects=leg_length`
stays a string, and an unknown key or a value of the wrong type is refused before any
data is read, naming the calibrator's options with their types and defaults. Ranges stay
the constructor's to check (`base.number_option`); this module only types the text.
"""

from __future__ import annotations

import inspect
import json
import types
import typing
from dataclasses import dataclass
from typing import Any

from importlib.metadata import entry_points

from legcal_bench.calibrators.base import ENTRY_POINT_GROUP, Calibrator
from legcal_bench.errors import CalibrationError

EMPTY = inspect.Parameter.empty
NONE_WORDS = ("none", "null")
_BOOL = {"true": True, "1": True, "yes": True, "false": False, "0": False, "no": False}


def _bool(text: str) -> bool:
    try:
        return _BOOL[text.strip().lower()]
    except KeyError:
        raise ValueError(text) from None


# Tried in this order for a union (`int | float`): the narrowest reading first.
CONVERT = {bool: _bool, int: int, float: float, str: str}
EXAMPLES = {bool: "true", int: "1", float: "0.1", str: "text"}
WORDS = {bool: "true/false/1/0/yes/no", int: "an integer", float: "a number", str: "text"}
# Simple annotations still typed when `get_type_hints` cannot resolve the signature.
BUILTIN_NAMES = {"bool": bool, "int": int, "float": float, "str": str, "None": type(None)}


def _json_or_text(text: str) -> Any:
    try:
        return json.loads(text)
    except json.JSONDecodeError:
        return text


def _members(tp: Any) -> tuple:
    """The types of an annotation: a union's members, else the annotation alone."""
    return typing.get_args(tp) if typing.get_origin(tp) in (typing.Union, types.UnionType) else (tp,)


def _from_text(annotation: str) -> Any:
    """An unresolved annotation string as types when it is a union of builtins
    ("float | None"), else unannotated."""
    parts = [BUILTIN_NAMES.get(p.strip()) for p in annotation.split("|")]
    return EMPTY if None in parts else typing.Union[tuple(parts)] if len(parts) > 1 else parts[0]


def type_name(tp: Any) -> str:
    if tp is EMPTY:
        return "any"
    if tp is type(None):
        return "None"
    if len(_members(tp)) > 1:
        return " | ".join(type_name(m) for m in _members(tp))
    return tp.__name__ if isinstance(tp, type) else str(tp).replace("typing.", "")


@dataclass(frozen=True)
class OptionSpec:
    """One constructor parameter: its name, resolved annotation (EMPTY: none) and default
    (EMPTY: required)."""

    name: str
    type: Any = EMPTY
    default: Any = EMPTY

    def describe(self) -> str:
        return f"{self.name} ({type_name(self.type)}, " + (
            "required)" if self.default is EMPTY else f"default {self.default!r})")

    def example(self) -> str:
        d = self.default
        if d is not EMPTY and d is not None and d != "":
            return str(d).lower() if isinstance(d, bool) else str(d)
        kinds = [m for m in _members(self.type) if m in EXAMPLES]
        return EXAMPLES[kinds[0]] if kinds else "1"

    def convert(self, text: str, calibrator: str) -> Any:
        """`text` read as this option's type: bool true/false/1/0/yes/no, int integers
        only, float any number literal, str as given, `X | None` also none/null;
        other or no annotations: JSON when it parses, else the text."""
        members = _members(self.type)
        if type(None) in members and text.strip().lower() in NONE_WORDS:
            return None
        kinds = [m for m in members if m is not type(None)]
        if self.type is EMPTY or not kinds or any(k not in CONVERT for k in kinds):
            return _json_or_text(text)
        for kind in CONVERT:
            if kind in kinds:
                try:
                    return CONVERT[kind](text)
                except (ValueError, OverflowError):
                    pass
        accepts = " or ".join(WORDS[k] for k in CONVERT if k in kinds) + (" or none" if type(None) in members else "")
        raise CalibrationError(f"option {self.name}={text!r}: expected {accepts}; calibrator {calibrator!r} takes "
                               f"{self.describe()}, e.g. --option {self.name}={self.example()}")


def resolve(calibrator: str | type) -> tuple[str, type]:
    """(name, class) of a registered calibrator's name or a Calibrator class."""
    if isinstance(calibrator, str):
        return calibrator, calibrator_class(calibrator)
    return getattr(calibrator, "name", "") or calibrator.__name__, calibrator


def option_specs(cls: type) -> dict[str, OptionSpec] | None:
    """The constructor's keyword parameters by name; None when it takes **kwargs (any key).
    The base class's `**options` only refuses options, so a calibrator without its own
    constructor (zero) takes none."""
    init = cls.__init__
    if init is Calibrator.__init__ or init is object.__init__:
        return {}
    params = [p for p in list(inspect.signature(init).parameters.values())[1:] if p.kind is not p.VAR_POSITIONAL
              and p.kind is not p.POSITIONAL_ONLY]
    if any(p.kind is p.VAR_KEYWORD for p in params):
        return None
    try:
        hints = typing.get_type_hints(init)
    except Exception:  # an annotation naming something not importable here: read the simple ones as text
        hints = {p.name: _from_text(p.annotation) if isinstance(p.annotation, str) else p.annotation
                 for p in params}
    return {p.name: OptionSpec(p.name, hints.get(p.name, EMPTY), p.default) for p in params}


def describe_options(calibrator: str | type) -> str:
    """The calibrator's options as `name (type, default value)`, comma-separated, for
    error messages and help texts."""
    specs = option_specs(resolve(calibrator)[1])
    if specs is None:
        return "any key=value (its constructor takes **kwargs; values read as JSON, else text)"
    return ", ".join(s.describe() for s in specs.values()) or "none"


def check_names(calibrator: str | type, keys) -> None:
    """Refuse option names the calibrator's constructor does not take, listing the ones it does."""
    name, cls = resolve(calibrator)
    specs = option_specs(cls)
    unknown = [] if specs is None else sorted(set(keys) - set(specs))
    if unknown:
        what = "--setting/--solver/--option" if set(unknown) & {"setting", "solver"} else "--option"
        raise CalibrationError(f"calibrator {name!r} has no option {unknown} ({what}); its options: "
                               f"{describe_options(cls)}")


def parse_options(calibrator: str | type, pairs: list[str] | None) -> dict[str, Any]:
    """`--option key=value` pairs as the calibrator's constructor arguments, each typed by
    its parameter's annotation (a later pair of the same key wins)."""
    name, cls = resolve(calibrator)
    texts = {}
    for pair in pairs or []:
        if "=" not in pair:
            raise CalibrationError(f"--option {pair!r}: write key=value, e.g. --option lambda_q=0.1")
        k, v = pair.split("=", 1)
        texts[k.strip()] = v
    check_names(cls, texts)
    specs = option_specs(cls)
    if specs is None:
        return {k: _json_or_text(v) for k, v in texts.items()}
    return {k: specs[k].convert(v, name) for k, v in texts.items()}


def available_calibrators() -> dict[str, type[Calibrator]]:
    """Every calibrator registered in the entry-point group, by name."""
    found: dict[str, type[Calibrator]] = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        try:
            cls = ep.load()
        except ImportError as e:
            raise CalibrationError(f"entry point {ep.name!r} ({ep.value}) cannot be imported: {e}; reinstall the "
                                   "package that registers it (pip install -e .)") from None
        if not (isinstance(cls, type) and issubclass(cls, Calibrator)):
            raise CalibrationError(f"entry point {ep.name!r} ({ep.value}) is not a Calibrator subclass")
        found[ep.name] = cls
    return found


def calibrator_class(name: str) -> type[Calibrator]:
    """The registered calibrator class `name`, or a CalibrationError listing the registered ones."""
    found = available_calibrators()
    if name not in found:
        raise CalibrationError(f"unknown calibrator {name!r}; registered: {sorted(found)} "
                               f"(add yours under the entry-point group '{ENTRY_POINT_GROUP}')")
    return found[name]


def get_calibrator(name: str, **options: Any) -> Calibrator:
    """The registered calibrator `name` with `options`; an option it does not take is a
    CalibrationError listing the ones it does, with their types and defaults (the
    `--option` text is typed by `options.parse_options` before it gets here)."""
    cls = calibrator_class(name)
    check_names(cls, options)
    return cls(**options)
