"""The calibration report (issue #39 item 5, test f): for a simulated session and for the
same session imported from a robot log, the report renders: every section, every
figure it references (a PNG; the figures themselves are looked at by a person, not
here), every leg joint's offset, each stance's inter-foot spread smaller after the
offsets than before, and the commands that reproduce it (an `import` only for the
imported session)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import legcal_bench.api as lb
from legcal_bench.calibrators.base import CalibrationResult
from legcal_bench.cli import main
from legcal_bench.data.recording import load_session
from legcal_bench.errors import ConfigError
from legcal_bench.logs.importer import import_log
from legcal_bench.logs.write import mapping_document, write_log, write_mapping
from legcal_bench.protocol.collect import CollectConfig, collect
from legcal_bench.reports.calibration_report import SECTIONS, spreads, write_calibration_report
from legcal_bench.robots import load_robot
from legcal_bench.robots.kinematics import LegKinematics
from tests.logs.test_import import as_log  # the session written back to back as one log

PNG = b"\x89PNG\r\n\x1a\n"
HELDOUT_SEGMENT = "stance_S5"  # the collect session's held-out recording, found as the fifth stance of the log
# The tests share the reports `reports` makes: one process runs them all (built once).
pytestmark = pytest.mark.xdist_group("calibration_report")


@pytest.fixture(scope="module")
def legmap():
    return load_robot("a3")


@pytest.fixture(scope="module")
def reports(tmp_path_factory, legmap):
    """{"collect": (report.md, session, result), "import": (...)}: a small kinematic session
    calibrated and reported; the same session written as a CSV log, imported, calibrated
    and reported through the CLI."""
    root = tmp_path_factory.mktemp("calibration_report")
    collect(CollectConfig(robot="a3", mode="kinematic", heldout=1, stance_s=4.0, standing_s=3.0), root / "set",
            progress=False)
    lb.calibrate(root / "set", robot="a3").save(root / "result.json")
    out = {"collect": (write_calibration_report(root / "set", root / "result.json", root / "report"),
                       root / "set", root / "result.json")}

    recs = load_session(root / "set", robot=legmap)
    streams, sources, signs, spans = as_log(recs, legmap)
    log = write_log(root / "log.csv", streams, "csv")
    mapping = write_mapping(root / "map.yaml", mapping_document(
        "a3", legmap.joint_names, sources, signs, "csv", recs[0].sensor_model, ft=recs[0].ft is not None))
    import_log([log], mapping, legmap, root / "session", heldout=[HELDOUT_SEGMENT], ranges=spans)
    result = lb.calibrate(root / "session", robot="a3")
    result.settings["robot_spec"] = "a3"  # as `legcal-bench calibrate` records it
    result.save(root / "imported.json")
    assert main(["report", "--bags", str(root / "session"), "--result", str(root / "imported.json"),
                 "--out", str(root / "imported_report")]) == 0
    out["import"] = (root / "imported_report" / "report.md", root / "session", root / "imported.json")
    return out


def _table_rows(md: str, header_start: str) -> list[list[str]]:
    """The rows of the markdown table whose header begins with `header_start`."""
    lines = md.splitlines()
    i = next(k for k, line in enumerate(lines) if line.startswith(header_start))
    rows = []
    for line in lines[i + 2:]:
        if not line.startswith("|"):
            break
        rows.append([c.strip() for c in line.strip("|").split("|")])
    return rows


@pytest.mark.parametrize("which", ["collect", "import"])
def test_the_report_renders(reports, legmap, which):
    page, session, _ = reports[which]
    md = page.read_text()
    html = page.with_suffix(".html").read_text()
    assert html.startswith("<!DOCTYPE html>") and "<table>" in html and "<style>" in html
    for name in SECTIONS:
        assert f"\n## {name}\n" in md, name
        assert f"<h2>{name}</h2>" in html, name
    images = re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", md)
    assert {"residuals.png", "posterior_std.png", "weakest_combinations.png"} <= set(images)
    assert ("timeline.png" in images) == (which == "import")  # a simulated session has no timeline
    assert sorted(re.findall(r'<img alt="[^"]*" src="([^"]+)"', html)) == sorted(images)
    for name in images:
        f = page.parent / name
        assert f.is_file() and f.read_bytes()[:8] == PNG, name
    offsets = {r[0].strip("`"): r for r in _table_rows(md, "| joint | offset (deg)")}
    assert list(offsets) == legmap.joint_names
    data = json.loads(page.with_suffix(".json").read_text())
    for n in legmap.joint_names:  # the table's degrees are the result's radians
        assert float(offsets[n][1]) == pytest.approx(data["offsets_deg"][n], abs=6e-5)
        assert float(offsets[n][2]) > 0  # a posterior standard deviation from the declared noise


@pytest.mark.parametrize("which", ["collect", "import"])
def test_each_stance_spreads_less_after_the_offsets(reports, which):
    """The calibration removed the offsets' signature from every stance and the held-out
    session (as the report prints it); standing barely moves, so it stays at the noise."""
    page = reports[which][0]
    rows = _table_rows(page.read_text(), "| recording | kind | stance | frames | translation before")
    kinds = [r[1] for r in rows]
    assert kinds.count("stance") >= 4 and "held-out" in kinds
    for name, kind, _, _, t_before, t_after, r_before, r_after in rows:
        if kind == "standing":
            continue
        assert float(t_after) < 0.6 * float(t_before), (name, t_before, t_after)  # well above the noise here
        assert float(r_after) < float(r_before), (name, r_before, r_after)


def test_the_offsets_with_the_wrong_sign_spread_more(reports, legmap):
    """The before/after check can fail: the offsets subtracted (q_enc - offset, the wrong
    convention) make every stance spread more than the raw encoders."""
    _, session, result = reports["collect"]
    recs = [r for r in load_session(session, robot=legmap) if r.kind == "stance"]
    dq = CalibrationResult.load(result).offsets_vector(legmap.joint_names)
    for s in spreads(LegKinematics(legmap), recs, -dq):
        assert s.translation_mm_after > s.translation_mm_before, s


def test_the_commands_reproduce_the_session(reports):
    md = {k: v[0].read_text() for k, v in reports.items()}
    commands = {k: re.findall(r"```bash\n(.*?)```", m, re.S) for k, m in md.items()}
    for k, cmds in commands.items():
        text = "\n".join(cmds)
        for verb in ("calibrate", "export", "report"):
            assert f"legcal-bench {verb}" in text, (k, verb)
        assert ("legcal-bench import" in text) == (k == "import"), k
    imported = next(c for c in commands["import"] if c.startswith("legcal-bench import"))
    session, result = reports["import"][1:]
    for words in ("--robot a3", f"--log {session.parent / 'log.csv'}", f"--map {session.parent / 'map.yaml'}",
                  f"--out {session}", f"--heldout {HELDOUT_SEGMENT}", "--ranges 0:"):
        assert words in imported, words
    assert "legcal-bench collect" in "\n".join(commands["collect"])
    calibrate = next(c for c in commands["import"] if c.startswith("legcal-bench calibrate"))
    assert f"--bags {session}" in calibrate and f"--out {result}" in calibrate and "--option" not in calibrate


def test_a_report_folder_is_replaced_and_nothing_else(reports, tmp_path):
    page, session, result = reports["collect"]
    again = write_calibration_report(session, result, page.parent)  # an earlier report: replaced
    assert again == page and page.is_file()
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="holds other files"):
        write_calibration_report(session, result, other)
    assert (other / "notes.txt").read_text() == "mine"
    np.testing.assert_equal(sorted(p.name for p in other.iterdir()), ["notes.txt"])
