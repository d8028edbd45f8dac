"""`--option key=value` typed from the calibrator's constructor: one parser for
`calibrate` and `walk-eval`, refusing unknown keys and wrong types by name."""

from __future__ import annotations

import math

import pytest

from legcal_bench.calibrators.base import CalibrationResult, Calibrator
from legcal_bench.calibrators.registry import describe_options, parse_options
from legcal_bench.cli import main
from legcal_bench.errors import CalibrationError


def _no_correction(self, robot, recordings):
    """These classes exist for their constructors' options; calibrating returns zero offsets."""
    return CalibrationResult(calibrator=self.name, robot=robot.name, offsets_rad={n: 0.0 for n in robot.joint_names})


class Typed(Calibrator):
    name = "typed"

    def __init__(self, count: int = 3, weight: float = 1.0, flag: bool = False, label: str = "a",
                 scale: float | None = None, raw=None):
        pass

    calibrate = _no_correction


class Loose(Calibrator):
    name = "loose"

    def __init__(self, **options):
        self.options = options

    calibrate = _no_correction


class Unresolvable(Calibrator):
    """An annotation naming a type not importable here: `get_type_hints` fails."""

    name = "unresolvable"

    def __init__(self, count: int = 1, shape: NotDefinedAnywhere = None):  # noqa: F821
        pass

    calibrate = _no_correction


@pytest.mark.parametrize("pair, value", [
    ("count=2", 2), ("count=-7", -7), ("weight=2", 2.0), ("weight=1e-3", 1e-3), ("weight=-0.5", -0.5),
    ("flag=true", True), ("flag=YES", True), ("flag=1", True), ("flag=False", False), ("flag=no", False),
    ("flag=0", False), ("label=leg_length,imu_tilt", "leg_length,imu_tilt"), ("label=2", "2"), ("label=", ""),
    ("scale=none", None), ("scale=NULL", None), ("scale=0.25", 0.25), ("raw=[1, 2]", [1, 2]), ("raw=sensor", "sensor"),
])
def test_each_value_is_read_as_its_annotation(pair, value):
    got = parse_options(Typed, [pair])[pair.split("=")[0]]
    assert got == value and type(got) is type(value)


def test_float_takes_any_number_literal():
    assert math.isinf(parse_options(Typed, ["weight=inf"])["weight"])
    assert math.isnan(parse_options(Typed, ["weight=nan"])["weight"])


@pytest.mark.parametrize("pair, message", [
    ("count=2.5", r"option count='2.5': expected an integer; calibrator 'typed' takes count \(int, default 3\), "
                  r"e.g. --option count=3"),
    ("count=true", r"option count='true': expected an integer"),
    ("weight=heavy", r"option weight='heavy': expected a number; .*weight \(float, default 1.0\)"),
    ("flag=maybe", r"option flag='maybe': expected true/false/1/0/yes/no; .*flag \(bool, default False\), "
                   r"e.g. --option flag=false"),
    ("scale=big", r"option scale='big': expected a number or none; .*scale \(float \| None, default None\), "
                  r"e.g. --option scale=0.1"),
])
def test_a_value_of_the_wrong_type_names_the_option_and_its_type(pair, message):
    with pytest.raises(CalibrationError, match=message):
        parse_options(Typed, [pair])


def test_an_unknown_key_lists_the_options_with_types_and_defaults():
    with pytest.raises(CalibrationError, match=r"calibrator 'typed' has no option \['nope'\] \(--option\); its "
                                               r"options: count \(int, default 3\), weight \(float, default 1.0\), "
                                               r"flag \(bool, default False\), label \(str, default 'a'\), "
                                               r"scale \(float \| None, default None\), raw \(any, default None\)$"):
        parse_options(Typed, ["count=1", "nope=1"])
    with pytest.raises(CalibrationError, match=r"'interfoot' has no option \['nope'\].*lambda_q \(float \| None, "
                                               r"default None\).*max_outer \(int, default 15\)"):
        parse_options("interfoot", ["nope=1"])
    with pytest.raises(CalibrationError, match=r"calibrator 'zero' has no option \['x'\] \(--option\); its options: "
                                               r"none"):
        parse_options("zero", ["x=1"])


def test_a_pair_without_equals_and_an_unknown_calibrator_are_refused():
    with pytest.raises(CalibrationError, match=r"--option 'lambda_q': write key=value, e.g. --option lambda_q=0.1"):
        parse_options("interfoot", ["lambda_q"])
    with pytest.raises(CalibrationError, match=r"unknown calibrator 'nope'; registered: \["):
        parse_options("nope", ["a=1"])


def test_kwargs_take_any_key_read_as_json_else_text():
    assert parse_options(Loose, ["a=2", "b=x,y", "c=true", "d=2=3"]) == {"a": 2, "b": "x,y", "c": True, "d": "2=3"}
    assert describe_options(Loose).startswith("any key=value")


def test_unresolvable_annotations_fall_back_to_their_text():
    assert parse_options(Unresolvable, ["count=4", "shape=[1, 2]"]) == {"count": 4, "shape": [1, 2]}
    with pytest.raises(CalibrationError, match=r"option count='4.5': expected an integer"):
        parse_options(Unresolvable, ["count=4.5"])


def test_the_registered_calibrators_get_typed_values():
    got = parse_options("interfoot", ["max_outer=3", "lambda_q=0.5", "lambda_f=none", "setting=sensor",
                                      "effects=leg_length,imu_tilt", "tol=1e-12"])
    assert got == {"max_outer": 3, "lambda_q": 0.5, "lambda_f": None, "setting": "sensor",
                   "effects": "leg_length,imu_tilt", "tol": 1e-12}
    assert type(got["max_outer"]) is int and type(got["lambda_q"]) is float
    assert parse_options("yamane", ["w_h=2", "n_max=40"]) == {"w_h": 2.0, "n_max": 40}
    assert parse_options("zero", []) == {}


def test_calibrate_refuses_an_unknown_key_before_reading_data(tmp_path, capsys):
    assert main(["calibrate", "--robot", "a3", "--bags", "/nonexistent", "--option", "nope=1",
                 "--out", str(tmp_path / "r.json")]) == 2
    err = capsys.readouterr().err
    assert "calibrator 'interfoot' has no option ['nope']" in err and "lambda_q (float | None, default None)" in err
    assert "nonexistent" not in err
    assert main(["calibrate", "--robot", "a3", "--bags", "/nonexistent", "--option", "max_outer=2.5",
                 "--out", str(tmp_path / "r.json")]) == 2
    assert "option max_outer='2.5': expected an integer" in capsys.readouterr().err
    assert not (tmp_path / "r.json").exists()


class _Evaluated(Exception):
    pass


@pytest.fixture
def walk_eval_options(monkeypatch):
    """Runs walk-eval up to its first trial and returns the options the trials would get
    (no policy is loaded, no walk launched)."""
    import legcal_bench.evaluation.closed_loop as closed_loop
    import legcal_bench.policies.runner as runner

    def evaluate(cfg, executor, progress):
        raise _Evaluated(cfg.options)

    monkeypatch.setattr(closed_loop, "evaluate", evaluate)
    monkeypatch.setattr(runner, "PolicyRunner", lambda *args: None)

    def run(*args):
        with pytest.raises(_Evaluated) as e:
            main(["walk-eval", "--robot", "a3", "--policy", "a3", "--workers", "1", *args])
        return e.value.args[0]

    return run


def test_walk_eval_passes_typed_options(walk_eval_options):
    got = walk_eval_options("--calibrator", "yamane", "--option", "w_h=2", "--option", "n_max=40")
    assert got == {"weights": "sensor", "w_h": 2.0, "n_max": 40}
    assert type(got["w_h"]) is float and type(got["n_max"]) is int
    got = walk_eval_options("--option", "max_outer=3", "--option", "effects=leg_length")
    assert got == {"setting": "sensor", "max_outer": 3, "effects": "leg_length"} and type(got["max_outer"]) is int


def test_walk_eval_refuses_bad_options_before_any_walk(walk_eval_options, capsys):
    assert main(["walk-eval", "--robot", "a3", "--policy", "a3", "--workers", "1", "--option", "nope=1"]) == 2
    assert "calibrator 'interfoot' has no option ['nope']" in capsys.readouterr().err
    assert main(["walk-eval", "--robot", "a3", "--policy", "a3", "--workers", "1", "--calibrator", "yamane",
                 "--setting", "matched"]) == 2
    assert "calibrator 'yamane' has no option ['setting'] (--setting/--solver/--option)" in capsys.readouterr().err
    assert main(["walk-eval", "--robot", "a3", "--policy", "a3", "--workers", "1", "--option", "lambda_q=-1"]) == 2
    assert "option lambda_q=-1: must be a number in [0, inf]\n" in capsys.readouterr().err
