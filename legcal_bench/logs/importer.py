"""`import_log`: a robot's log in, a session set of recordings out.

Read (through the mapping file) → align onto one clock → find the static
double-support segments (or take the user's time ranges) → one recording per segment,
with the declared sensor model (or `unknown`) and the motion as declared (measured here
for the summary, and again, as for any recording, when they are calibrated) → the
session folder, written whole, with the import's timeline in its manifest and a
timeline plot.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from legcal_bench.data.recording import SESSION_FILES, Recording, is_session_dir, write_manifest
from legcal_bench.errors import LogImportError
from legcal_bench.estimation.checks.motion import resolve_motion
from legcal_bench.files.atomic import replace_dir
from legcal_bench.logs.align import align
from legcal_bench.logs.detect import REASONS, Detected, detect
from legcal_bench.logs.mapping import load_mapping
from legcal_bench.logs.read import log_kind, read_log
from legcal_bench.logs.timeline import intervals, plot_timeline
from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.sensors import SensorModel

TIMELINE_PNG = SESSION_FILES[1]


@dataclass
class ImportSummary:
    robot: str
    out: str
    segments: list[dict]
    intervals: list[dict]
    gaps: list[dict]
    streams: dict
    duration_s: float
    frames: int
    sensor_declared: bool
    warnings: list[str] = field(default_factory=list)


def parse_ranges(specs: list[str] | None) -> list[tuple[float, float]] | None:
    """`--ranges 12.5:30 40:52` (seconds from the log's first stamp)."""
    if not specs:
        return None
    out = []
    for s in specs:
        try:
            a, b = (float(x) for x in s.split(":"))
        except ValueError:
            raise LogImportError(f"--ranges {s!r}: give START:END in seconds from the log's start, e.g. "
                                 "12.5:30") from None
        if not (np.isfinite(a) and np.isfinite(b) and 0 <= a < b):
            raise LogImportError(f"--ranges {s!r}: need 0 <= START < END")
        out.append((a, b))
    return out


def _knees(legmap: LegMap) -> list[int]:
    return [i for i, r in enumerate(legmap.joint_roles) if r == "knee"]


def import_log(logs: list[str | Path], map_path: str | Path, legmap: LegMap, out: str | Path,
               heldout: list[str] | None = None, ranges: list[tuple[float, float]] | None = None,
               plot: bool = True) -> ImportSummary:
    logs = [Path(p) for p in logs]
    if not logs:
        raise LogImportError("--log: give at least one log (a bag, a .csv or a .parquet)")
    out = Path(out)
    if out.exists() and not (out.is_dir() and (not any(out.iterdir()) or is_session_dir(out))):
        raise LogImportError(f"--out {out} exists and is not a session folder: give a new folder")
    mapping = load_mapping(map_path, legmap, table=log_kind(logs) == "table")
    streams = read_log(logs, mapping, legmap.joint_names)
    aligned = align(streams, mapping)
    kin = LegKinematics(legmap)
    found = detect(aligned, kin, mapping.detection, _knees(legmap), legmap.knee_straight_rad, ranges)
    _check_degrees(found, aligned, mapping, legmap)
    names = [s.name for s in found.segments]
    for h in heldout or []:
        if h not in names:
            raise LogImportError(f"--heldout {h}: no such segment; the segments found: {names}")
    for s in found.segments:
        if s.name in (heldout or []):
            s.kind = "heldout"
    warnings = _warnings(found, aligned, mapping)
    spans = intervals(aligned.time, found)
    summary = ImportSummary(
        robot=legmap.name, out=str(out), segments=[s.to_dict() for s in found.segments], intervals=spans,
        gaps=aligned.gaps, streams={k: {**v, "from": streams.sources.get(k, "")} for k, v in aligned.stats.items()},
        duration_s=float(aligned.time[-1] - aligned.time[0]), frames=int(aligned.time.size),
        sensor_declared=mapping.sensor_declared, warnings=warnings)
    training = [s for s in found.segments if s.kind != "heldout"]
    if not training:
        raise LogImportError(_nothing_found(found, aligned, mapping))
    sensor = mapping.sensor_model if mapping.sensor_declared else SensorModel.unknown()
    recordings = [Recording(
        name=s.name, kind=s.kind, stance=s.stance, robot=legmap.name, joint_names=legmap.joint_names,
        time=aligned.time[s.start:s.stop].copy(), q_enc=aligned.q_enc[s.start:s.stop].copy(),
        imu_acc=aligned.imu_acc[s.start:s.stop].copy(), imu_gyro=aligned.imu_gyro[s.start:s.stop].copy(),
        ft=None if aligned.ft is None else aligned.ft[s.start:s.stop].copy(), sensor_model=sensor,
        sensor_declared=mapping.sensor_declared, source="robot", session=logs[0].stem, motion=mapping.motion,
    ) for s in found.segments]
    # The motion as the data show it (calibration measures it again, as for any recording):
    # a declaration the data contradict is named now, before anything is calibrated.
    evidence: dict = {}
    _, motion_warnings = resolve_motion(kin, recordings, evidence)
    for seg in summary.segments:
        seg["motion"] = evidence[seg["name"]]["motion"]
    summary.warnings += motion_warnings
    warnings = summary.warnings
    manifest = {
        "robot": legmap.name, "mode": "robot", "files": [f"{r.name}.npz" for r in recordings],
        "import": {"logs": [str(p.resolve()) for p in logs], "mapping": str(Path(map_path).resolve()),
                   "time_source": mapping.time_source, "clock": mapping.clock,
                   "gap_tolerance_s": mapping.gap_tolerance_s, "sensor_declared": mapping.sensor_declared,
                   "declared_motion": mapping.motion, "duration_s": summary.duration_s, "frames": summary.frames,
                   "streams": summary.streams, "gaps": summary.gaps, "segments": summary.segments,
                   "intervals": spans, "warnings": warnings,
                   "ranges": [[float(a), float(b)] for a, b in ranges] if ranges else None},
    }

    def write(folder: Path) -> None:
        for r in recordings:
            r.save(folder / f"{r.name}.npz")
        write_manifest(folder, manifest)
        if plot:
            plot_timeline(found, aligned, folder / TIMELINE_PNG, f"{legmap.name}: {', '.join(p.name for p in logs)}",
                          spans)

    replace_dir(out, write, keep_if=is_session_dir)
    return summary


def _check_degrees(found: Detected, aligned, mapping, legmap: LegMap) -> None:
    """Joints declared in degrees whose readings never leave +-2 pi (so, as degrees, the
    legs barely move: under 6.3 deg at every such joint over the whole log), in a log where
    fewer than two foot placements are found: the readings are radians. Refused, named."""
    deg = [i for i, n in enumerate(legmap.joint_names) if mapping.joint_map[n].scale != 1.0]
    if not deg or len({s.stance for s in found.segments if s.kind == "stance"}) >= 2:
        return
    reading = np.abs(aligned.q_enc[:, deg]) / np.array([mapping.joint_map[legmap.joint_names[i]].scale for i in deg])
    if reading.max() > 2 * np.pi or not reading.max() > 0:
        return
    names = [legmap.joint_names[i] for i in deg]
    raise LogImportError(
        f"{mapping.path}: field 'joints.map.{names[0]}.unit' is deg"
        + (f" (and {len(names) - 1} more joints)" if len(names) > 1 else "")
        + f", but the readings of {'these joints' if len(names) > 1 else 'it'} stay within +-{reading.max():.3g} over "
        f"the whole log ({aligned.time[-1]:.1f} s): as degrees the legs would barely move (under "
        f"{reading.max():.2g} deg), and the import finds no two distinct foot placements; the readings are radians: "
        "write `unit: rad`")


def _warnings(found: Detected, aligned, mapping) -> list[str]:
    out = []
    for name, st in aligned.stats.items():
        if st["dropped_count"]:
            first = st["dropped"][0]
            missing = sum(d["missing"] for d in st["dropped"])
            out.append(f"stream '{name}': {st['dropped_count']} interval(s) with dropped messages (about {missing} "
                       f"message(s) in the first {len(st['dropped'])}; first at {first['t0']:.3f}-{first['t1']:.3f} s); "
                       "frames there are interpolated across when the gap is within gap_tolerance_s")
        if st["duplicates"]:
            out.append(f"stream '{name}': {st['duplicates']} message(s) with a repeated stamp were dropped (the "
                       "first of each kept)")
    for g in aligned.gaps:
        out.append(f"stream '{g['stream']}' has a gap of {g['seconds']:.3f} s at {g['t0']:.2f}-{g['t1']:.2f} s "
                   f"(longer than gap_tolerance_s {mapping.gap_tolerance_s:g} s): frames inside it are left out and a "
                   "segment there is split")
    if not mapping.sensor_declared:
        out.append("sensor_model is unknown: conservative bounds are applied (docs/recording-format.md) and every "
                   "result says so; declare the datasheet values in the mapping file for a tighter calibration")
    if not any(s.kind == "standing" for s in found.segments):
        out.append("no straight-leg standing segment found: the knee prior is off (calibration still runs); "
                   "log a few seconds standing with straight knees")
    stances = {s.stance for s in found.segments if s.kind == "stance"}
    if len(stances) < 2:
        out.append(f"{len(stances)} stance placement(s) found: the offsets need stances with different foot "
                   "placements and posture motion (the paper uses four); see the timeline")
    return out


def _nothing_found(found: Detected, aligned, mapping) -> str:
    counts = {k: int(np.sum(found.reason == k)) for k in REASONS}
    worst = sorted(((n, k) for k, n in counts.items() if n), reverse=True)
    why = "; ".join(f"{REASONS[k]}: {n / max(len(aligned.time), 1):.0%} of frames" for n, k in worst[:4])
    return (f"no static double-support segment for training in the log ({aligned.time[-1]:.1f} s, "
            f"{len(aligned.time)} frames): {why}. If the robot did stand in double support, check the joint map's "
            f"signs and units and the IMU rotation, loosen `detection` in {mapping.path}, or give the times with "
            "--ranges START:END")
