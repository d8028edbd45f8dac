"""The door's checks (`legcal_bench.inputs`): each refuses with the field, the value and
the fix; good values pass through converted."""

import math
import os
from pathlib import Path

import pytest

from legcal_bench import inputs
from legcal_bench.errors import ConfigError


@pytest.mark.parametrize("value, message", [
    ("abc", "rate = 'abc': expected a number > 0"), (None, "expected a number"), (True, "expected a number"),
    (math.nan, "expected a finite number"), ("inf", "expected a finite number"), (0, "out of range"),
    (-50, "out of range, expected a number > 0")])
def test_a_positive_number_refuses_with_field_and_range(value, message):
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        inputs.positive("rate", value)


def test_good_values_pass_converted():
    assert inputs.positive("rate", "50") == 50.0 and inputs.count("workers", 2.0) == 2
    assert inputs.seed("seed", "7") == 7 and inputs.non_negative("settle_s", 0) == 0.0
    assert inputs.number("x", 1.0, low=0, high=1) == 1.0
    with pytest.raises(ConfigError, match=r"x = 1.0: out of range, expected a number in \[0, 1\)"):
        inputs.number("x", 1.0, low=0, high=1, high_open=True)


@pytest.mark.parametrize("value", [-1, 2**32, 1.5, "x", "1e3"])
def test_a_seed_is_a_32_bit_unsigned_integer(value):
    with pytest.raises(ConfigError, match="seed = .*non-negative integer"):
        inputs.seed("seed", value)


def test_workers_count_and_choices():
    for bad in (0, -1):
        with pytest.raises(ConfigError, match=r"workers = -?\d: out of range, expected an integer >= 1"):
            inputs.count("workers", bad)
    with pytest.raises(ConfigError, match=r"mode = 'wled': expected one of weld, kinematic; did you mean 'weld'\?"):
        inputs.choice("mode", "wled", ["weld", "kinematic"])


def test_unknown_keys_are_named_with_the_closest():
    with pytest.raises(ConfigError, match=r"protocol p.yaml: unknown key 'stnaces' \(did you mean 'stances'\?\)"):
        inputs.known_keys("protocol p.yaml", {"stances": 1, "stnaces": 2}, ["stances", "settle_s"])
    inputs.known_keys("p", {"stances": 1}, ["stances"])


def test_output_folders_are_checked_before_the_work(tmp_path):
    assert inputs.output_folder("--out", tmp_path / "a" / "b") == tmp_path / "a" / "b"
    assert not (tmp_path / "a").exists()  # the folders the probe made are removed again
    (tmp_path / "f").write_text("x")
    with pytest.raises(ConfigError, match="is a file, not a folder"):
        inputs.output_folder("--out", tmp_path / "f")
    with pytest.raises(ConfigError, match="is a file, so the folder cannot be made"):
        inputs.output_folder("--out", tmp_path / "f" / "sub")
    inputs.output_folder("--out", tmp_path / "x")  # a writable one passes
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]  # no probe file left


def test_a_folder_no_file_can_be_made_in_is_refused_with_the_reason_although_os_access_says_yes():
    # /proc takes no new folder, not even from root (for whom os.access says yes to all).
    assert os.access("/proc", os.W_OK | os.X_OK) or os.geteuid() != 0
    with pytest.raises(ConfigError, match=r"--out '/proc/nope/x': cannot make the folder '/proc/nope' "
                                          r"\(No such file or directory\); give a folder you can write to"):
        inputs.output_folder("--out", "/proc/nope/x")
    with pytest.raises(ConfigError, match=r"--urdf-out '/proc/nope/r.urdf': cannot make the folder '/proc/nope'"):
        inputs.output_file("--urdf-out", "/proc/nope/r.urdf")
    # An existing folder no file can be written into: the probe file's failure, with its reason.
    with pytest.raises(ConfigError, match=r"--out '/proc/self': cannot write into '/proc/self' \(.+\); give a"):
        inputs.output_folder("--out", "/proc/self")


def test_an_output_file_needs_a_folder_and_is_not_touched(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(ConfigError, match="is a file, so the file cannot be made in it"):
        inputs.output_file("--out", tmp_path / "f" / "r.json")
    with pytest.raises(ConfigError, match="is a folder, not a file"):
        inputs.output_file("--out", tmp_path)
    assert inputs.output_file("--out", tmp_path / "f") == tmp_path / "f"  # an existing file may be replaced
    assert (tmp_path / "f").read_text() == "x"
    inputs.output_file("--out", tmp_path / "new" / "deeper" / "r.json")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f"]


def test_a_folder_another_process_wrote_into_meanwhile_stays(tmp_path, monkeypatch):
    import tempfile

    real = tempfile.mkstemp

    def mkstemp(**kw):  # another process writes into the made folder during the probe
        (tmp_path / "a" / "theirs").write_text("y")
        return real(**kw)

    monkeypatch.setattr(tempfile, "mkstemp", mkstemp)
    inputs.output_folder("--out", tmp_path / "a" / "b")
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == ["theirs"]


def test_text_files_are_utf8_and_files(tmp_path):
    (tmp_path / "ok.yaml").write_text("a: 1\n", encoding="utf-8")
    assert inputs.read_text("leg map", tmp_path / "ok.yaml") == "a: 1\n"
    (tmp_path / "bad.yaml").write_bytes(b"a: \xff\xfe\n")
    with pytest.raises(ConfigError, match=r"not UTF-8 text \(byte 3: b'\\xff'\); save it as UTF-8"):
        inputs.read_text("leg map", tmp_path / "bad.yaml")
    with pytest.raises(ConfigError, match="is a folder; give the leg map itself"):
        inputs.read_text("leg map", tmp_path, "leg map")
    with pytest.raises(ConfigError, match="no such leg map"):
        inputs.read_text("leg map", tmp_path / "none.yaml", "leg map")


def _check_many(args):
    root, i = args
    from legcal_bench import inputs as _inputs

    failures = []
    for _ in range(300):
        try:
            _inputs.output_folder("--out", f"{root}/runs/bench/data{i % 2}")
        except ConfigError as e:
            failures.append(str(e))
    return failures


def test_checks_at_once_under_one_new_parent_do_not_refuse_each_other(tmp_path):
    """Test workers (and parallel commands) check outputs under one new parent at once:
    one removing the folders it made must not make the other's check fail (it did:
    "cannot make the folder 'runs/bench/data'", or a vanished folder taken for a file)."""
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(4) as pool:
        assert pool.map(_check_many, [(str(tmp_path), i) for i in range(4)]) == [[]] * 4
