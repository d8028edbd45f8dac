import json
from pathlib import Path

import numpy as np
import pytest

from legcal_bench.cli import main
from legcal_bench.data.recording import load_recording, load_truth

G1_LEGMAP = Path(__file__).resolve().parents[2] / "examples" / "unitree_g1.legmap.yaml"
FAST = ["--stance-seconds", "1", "--heldout-seconds", "0.6", "--standing-seconds", "0.4", "--quiet"]


def test_collect_g1_through_its_leg_map(tmp_path, capsys):
    for mode in ("kinematic", "weld", "contact"):
        out = tmp_path / mode
        assert main(["collect", "--robot", str(G1_LEGMAP), "--mode", mode, "--heldout", "2", "--out", str(out),
                     "--json", *FAST]) == 0
        summary = json.loads(capsys.readouterr().out)
        assert [s["name"] for s in summary["segments"]] == [
            "standing", "stance_I", "stance_II", "stance_III", "stance_IV", "heldout_1", "heldout_2"]
        rec = load_recording(out / "stance_II.npz")
        assert rec.robot == "unitree_g1" and rec.q_enc.shape == (50, 12)
        truth = load_truth(out / "stance_II.npz")
        np.testing.assert_allclose(truth.q_true - rec.q_enc, np.tile(truth.offsets, (50, 1)), atol=2e-3)


def test_collect_with_a_different_sim_model(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["collect", "--robot", "pair_pry", "--sim-model", "a3", "--mode", "kinematic",
                 "--stances", "I", "--heldout", "0", "--out", str(out), *FAST]) == 0
    assert load_recording(out / "stance_I.npz").robot == "pair_pry"
    assert load_truth(out / "stance_I.npz").meta["sim_robot"] == "a3"


def test_bad_inputs_exit_2_with_a_message(tmp_path, capsys):
    assert main(["collect", "--robot", "a9", "--out", str(tmp_path)]) == 2
    assert "unknown robot 'a9'" in capsys.readouterr().err
    assert main(["collect", "--offsets", "random:x", "--out", str(tmp_path)]) == 2
    assert "random:<deg>" in capsys.readouterr().err
    assert main(["collect", "--stances", "V", "--out", str(tmp_path), "--quiet"]) == 2
    assert "stance 'V'" in capsys.readouterr().err
    assert main(["bench", "--suite", "smoke", "--stances", "I", "V", "--out", str(tmp_path), "--quiet"]) == 2
    assert "stance 'V'" in capsys.readouterr().err
    assert main(["bench", "--suite", "smoke", "--effect-seeds", "20", "--out", str(tmp_path), "--quiet"]) == 2
    assert "--effect-seeds: the modelgap suite's option" in capsys.readouterr().err
    assert main(["bench", "--suite", "smoke", "--cases", "library", "--out", str(tmp_path), "--quiet"]) == 2
    assert "--cases: the modelgap suite's option" in capsys.readouterr().err
    assert main(["bench", "--suite", "modelgap", "--robots", "a3", "--outside-robots", "a2", "--out", str(tmp_path),
                 "--quiet"]) == 2
    assert "--outside-robots: a2 not among the robots run (a3)" in capsys.readouterr().err


def test_info_lists_joint_order_and_axes(capsys):
    assert main(["info"]) == 0
    assert "pair_ryp" in capsys.readouterr().out
    assert main(["info", "--robot", "a2", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [j["role"] for j in info["joints"][:3]] == ["hip_roll", "hip_yaw", "hip_pitch"]
    assert info["joints"][2]["axis_in_pelvis_at_zero"] == [0.0, 1.0, 0.0]
    assert info["axis_warnings"] == [] and {j["angle_to_role_axis_deg"] for j in info["joints"]} == {0.0}
    assert (info["leg_joints"], info["absent_roles"]) == (6, [])


def test_info_says_which_role_a_five_joint_leg_lacks(tmp_path, capsys):
    from legcal_bench.robots.build import write_robot
    from legcal_bench.robots.design import VARIATIONS

    robot = write_robot(next(d for d in VARIATIONS if d.name == "five_joint"), tmp_path)
    assert main(["info", "--robot", str(robot)]) == 0
    out = capsys.readouterr().out
    assert "legs of 5 joints (no ankle_roll: absent_roles)" in out and "ankle_roll_joint" not in out


def test_info_reads_gains_unlimited_joints_and_canted_axes_as_they_are(tmp_path, capsys):
    import math
    from dataclasses import replace

    from legcal_bench.robots.build import write_robot
    from legcal_bench.robots.design import A3

    robot = write_robot(replace(A3, name="a3_cant45", hip_cant=math.radians(45)), tmp_path)
    xml = tmp_path / "a3_cant45.xml"
    text = xml.read_text()
    text = text.replace('name="left_knee_joint" axis="0 1 0" range="-0.08 2.6"', 'name="left_knee_joint" axis="0 1 0"')
    text = text.replace('joint="left_knee_joint" kp="2000" kv="80"', 'joint="left_knee_joint" kp="2000" kv="0"')
    assert text != xml.read_text()
    xml.write_text(text)
    assert main(["info", "--robot", str(robot), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    knee = info["joints"][3]
    assert knee["limits_deg"] is None and knee["servo"]["kd"] == 0.0 and math.copysign(1, knee["servo"]["kd"]) == 1
    assert [j["angle_to_role_axis_deg"] for j in info["joints"][:3]] == [0.0, 45.0, 45.0]
    assert len(info["axis_warnings"]) == 4
    assert main(["info", "--robot", str(robot)]) == 0
    out = capsys.readouterr().out
    assert "unlimited" in out and "-0.0" not in out and "45.0° +x" in out and "warning: joint left_hip_roll_joint" in out


def test_render_writes_a_png(tmp_path, capsys):
    out = tmp_path / "a3.png"
    assert main(["render", "--robot", "a3", "--stance", "II", "--out", str(out)]) == 0
    from PIL import Image

    img = np.asarray(Image.open(out))
    assert img.shape == (480, 640, 3) and img.std() > 10  # not a blank frame


def _zero_noise_set(tmp_path, capsys, robot: str, heldout: int) -> Path:
    """A short zero-noise kinematic session set through the CLI."""
    bags = tmp_path / "bags"
    assert main(["collect", "--robot", robot, "--mode", "kinematic", "--sensors", "zero", "--out", str(bags),
                 "--stance-seconds", "4", "--heldout-seconds", "2", "--standing-seconds", "1", "--heldout",
                 str(heldout), "--quiet"]) == 0
    capsys.readouterr()
    return bags


def test_calibrate_then_score(tmp_path, capsys):
    bags = _zero_noise_set(tmp_path, capsys, "a2", 2)
    out = tmp_path / "result.json"
    assert main(["calibrate", "--robot", "a2", "--bags", str(bags), "--calibrator", "interfoot",
                 "--setting", "matched", "--out", str(out), "--plots", str(tmp_path)]) == 0
    assert (tmp_path / "observability.png").stat().st_size > 10_000
    result = json.loads(out.read_text())
    assert set(result) >= {"offsets_rad", "pitch_sums_rad", "conditioning", "timing_s"}
    capsys.readouterr()
    assert main(["score", "--bags", str(bags), "--result", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["recovery"]["rms_error_deg"] < 1e-10
    assert set(s["recovery"]["pitch_sum_error_deg"]) == {"left", "right", "right_minus_left"}
    h = s["heldout"]
    assert h["foot_height_rms_mm"]["after"] < 1e-6 < h["foot_height_rms_mm"]["before"]
    assert h["sole_normal_rms_deg"]["after"] < 1e-8 < h["sole_normal_rms_deg"]["before"]


def test_calibrate_errors_are_clear(tmp_path, capsys):
    assert main(["calibrate", "--bags", str(tmp_path), "--out", str(tmp_path / "r.json")]) == 2
    assert "no recordings" in capsys.readouterr().err
    # A valid session set, so the error can only come from the calibrator's name.
    bags = tmp_path / "bags"
    assert main(["collect", "--robot", "a3", "--mode", "kinematic", "--stances", "I", "--heldout", "0",
                 "--out", str(bags), *FAST]) == 0
    capsys.readouterr()
    assert main(["calibrate", "--bags", str(bags), "--calibrator", "nope", "--out", str(tmp_path / "x.json")]) == 2
    err = capsys.readouterr().err
    assert "unknown calibrator 'nope'" in err and "registered: [" in err
    assert not (tmp_path / "x.json").exists()


def test_only_legcal_errors_exit_2_an_internal_error_keeps_its_traceback(monkeypatch, capsys):
    import legcal_bench.cli.robots as robots_cli
    from legcal_bench.errors import ConfigError

    def broken(_args):
        return {}["a key an internal bug forgot"]

    monkeypatch.setattr(robots_cli, "cmd_info", broken)
    with pytest.raises(KeyError, match="a key an internal bug forgot"):
        main(["info"])

    def bad_input(_args):
        raise ConfigError("--thing: use one of a, b")

    monkeypatch.setattr(robots_cli, "cmd_info", bad_input)
    assert main(["info"]) == 2
    assert capsys.readouterr().err.strip() == "legcal-bench info: error: --thing: use one of a, b"


def test_calibrate_with_yamane_then_score(tmp_path, capsys):
    """The Yamane calibrator through the CLI: its result prints, saves, reloads and
    scores (it once crashed in the result formatter after writing its JSON)."""
    bags = _zero_noise_set(tmp_path, capsys, "a3", 1)
    out = tmp_path / "yamane.json"
    assert main(["calibrate", "--robot", "a3", "--bags", str(bags), "--calibrator", "yamane",
                 "--option", "tol=1e-12", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "kappa(H_data)" in printed and f"wrote {out}" in printed
    result = json.loads(out.read_text())
    assert result["calibrator"] == "yamane" and result["settings"]["weights"] == "default"
    assert main(["score", "--bags", str(bags), "--result", str(out), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["recovery"]["rms_error_deg"] < 1e-6
    assert s["heldout"]["foot_height_rms_mm"]["after"] < 1e-4 < s["heldout"]["foot_height_rms_mm"]["before"]
