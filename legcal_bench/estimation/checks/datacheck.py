"""Warnings derived from the data: what the recordings say about themselves.

The calibrators run these checks on their recordings after the fit and add the
findings to their result's warnings (`legcal-bench check` runs them alone). Each check
judges a stance on the raw encoders and corrected by the calibrator's estimate and keeps
the better fit: a real defect shows in both, while offsets show only raw and an estimate
spoiled by bad data only corrected. They are never refusals (a deliberate effect stays
possible); each names the stance, the channel, the size and the likely cause:

  frozen channel   an encoder or IMU channel reads bit-identical values for at least 10
                   frames and 0.2 s while another encoder moves by more than 2 mrad;
  swapped columns  with the feet fixed the inter-foot transform is constant: if it varies
                   by more than 5 mm (median distance from its median) within a stance,
                   every exchange of two columns, of the legs, and every reversed joint is
                   tried, and one that makes it 5x steadier is named;
  standing signs   the straight-leg standing phase holds one posture, so it cannot vary:
                   judged against the stances instead, at their calibration (the raw
                   encoders, the estimate, and if neither fits, the framework's fit of the
                   steady stances alone, which the standing phase cannot spoil), its soles
                   must lie on one plane (right sole within 5 mm and 1 deg of the left's),
                   the IMU's vertical must sit on the soles' as in the stances (within
                   1 deg: the IMU's mount cancels) and its knees must read straight (within
                   1.5 deg); when they do not, each channel read with the opposite sign in
                   that recording is tried, and one that fits within those limits and 5x
                   better is named (a knee's sign flipped there puts twice its reading into
                   the knee prior);
  lunge sides      a lunge of the built-in protocol must have the foot it names ahead
                   (exchanged legs that leave the inter-foot transform steady);
  IMU axes         the IMU's vertical disagrees with the soles' normals (the posture's up
                   with flat feet on a level floor) by more than 3 deg, or moves against
                   them by more than 1.5 deg RMS; a signed permutation of the
                   accelerometer's axes that fits is named;
  soles apart      in double support (stances and the straight-leg phase) the right sole
                   sits more than 20 mm above or below the left, or tilts more than 10 deg
                   against it;
  bent knees       the straight-leg phase reads a knee more than 5 deg from straight;
  slide, yaw creep, lifted heel   per stance, the change between its first and last
                   15 % of frames of the inter-foot translation (> 2 mm), of its yaw
                   (> 0.25 deg) and of each sole's tilt against the IMU's vertical
                   (> 0.5 deg; one sole: that sole lifted; both alike: the IMU moved).

The limits against clean data: `legcal-bench robots-check --seeds 2` (its `--extra`, the
external robot example: the 12-joint G1) runs these checks on default sets of the built-ins, the
G1 and six generated robots in weld and contact mode (52 sets, paper offsets, realistic
sensors, with the inter-foot estimate) and raises no warning; the largest figures there
are identical runs of 7 frames, 1.07 mm dispersion, soles 1.8 mm / 0.46 deg apart, the
IMU's vertical 0.44 deg off and 0.34 deg moving, 1.40 mm slide, 0.107 deg yaw and
0.28 deg sole tilt change, all on the G1 in contact mode but the runs
(reports/robots_check/report.md). The standing signs (issue #42), measured on clean
sets of the built-ins, the G1 and the variations (mirrored pitch axes, canted hips, kid
size, five joints) in weld and contact mode, seeds 0-1, at the operating and the
sensor-weighted estimates: the standing posture's largest figure is at most 0.28 of its
limit at the estimate that fits it best (the stances-only fit's knees, 0.3 deg from
straight as simulated), and every channel whose reversal moves the posture (all but
the hips' yaw) is named when reversed in the standing recording alone.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from legcal_bench.data.recording import Recording
from legcal_bench.estimation.checks.imu_mount import imu_mount
from legcal_bench.estimation.imu.levelling import up_in_base
from legcal_bench.estimation.verdict import DOUBTS, INVALIDATES, Finding
from legcal_bench.geometry.lie import Log, frechet_mean, inverse
from legcal_bench.robots.kinematics import LegKinematics, frame_kinematics


@dataclass(frozen=True)
class CheckLimits:
    frozen_frames: int = 10
    frozen_s: float = 0.2
    moving_rad: float = 0.002  # another encoder's span during a frozen run: the robot moved
    dispersion_m: float = 0.005
    swap_gain: float = 5.0
    lunge_m: float = 0.1  # leg lengths: a built-in stance with its feet this far apart fore-aft is a lunge
    gravity_rad: float = np.deg2rad(3.0)
    gravity_motion_rad: float = np.deg2rad(1.5)
    coplanar_m: float = 0.02
    coplanar_rad: float = np.deg2rad(10.0)
    straight_knee_rad: float = np.deg2rad(5.0)
    slide_m: float = 0.002
    yaw_rad: float = np.deg2rad(0.25)
    sole_tilt_rad: float = np.deg2rad(0.5)
    end_fraction: float = 0.15
    max_frames: int = 120  # per stance, for the column and IMU-axis searches
    # The straight-leg standing phase against the stances' calibration (`standing_signs`).
    standing_height_m: float = 0.005
    standing_tilt_rad: float = np.deg2rad(1.0)
    standing_gravity_rad: float = np.deg2rad(1.0)
    standing_knee_rad: float = np.deg2rad(1.5)


LIMITS = CheckLimits()
AXES = "xyz"


def data_warnings(kin: LegKinematics, recordings: list[Recording], dq: np.ndarray | None = None,
                  limits: CheckLimits = LIMITS) -> list[str]:
    """Every check on `recordings`; the IMU and per-stance checks judge each stance on
    the raw encoders and corrected by `dq` (the calibrator's estimate) and keep the
    better fit, the column search runs on the raw encoders.

    A finding hides its consequences: a stance with a frozen encoder or an unsteady
    inter-foot transform gets no further kinematic checks, one with a frozen IMU or a
    vertical inconsistent with the posture no tilt checks."""
    dq = np.zeros(kin.legmap.n_joints) if dq is None else np.asarray(dq, dtype=float)
    out: list[str] = list(imu_mount(kin))
    frozen: dict[str, set[str]] = {}
    for r in recordings:
        msgs, kinds = frozen_channels(r, kin.legmap.joint_names, limits)
        out += msgs
        frozen[r.name] = kinds
    for r in recordings:
        if r.kind == "standing":
            out += straight_knees(kin, r, limits)
    support = [r for r in recordings if r.kind in ("stance", "standing") and _finite(r).sum() >= 10
               and "encoder" not in frozen[r.name]]
    msgs, unsteady = swapped_columns(kin, [r for r in support if r.kind == "stance"], dq, limits)
    out += msgs
    if not msgs:  # legs exchanged on a robot whose stances keep its inter-foot transform steady
        msgs, unsteady = lunge_sides(kin, [r for r in support if r.kind == "stance"], limits)
        out += msgs
    msgs, flipped = standing_signs(kin, [r for r in support if r.kind == "standing"],
                                   [r for r in support if r.kind == "stance" and r.name not in unsteady], dq, limits,
                                   imu=lambda r: "imu" not in frozen[r.name])
    out += msgs
    out += heldout_signs(kin, recordings, dq, limits, frozen,
                         [r for r in support if r.kind == "stance" and r.name not in unsteady])
    unsteady = unsteady | flipped
    msgs, apart = soles_coplanar(kin, [r for r in support if r.name not in unsteady], dq, limits)
    out += msgs
    stances = [r for r in support if r.kind == "stance" and r.name not in unsteady | apart]
    msgs, tilted = imu_axes(kin, [r for r in stances if "imu" not in frozen[r.name]], dq, limits)
    out += msgs
    for r in stances:
        out += stance_changes(kin, r, dq, limits, tilt=r.name not in tilted and "imu" not in frozen[r.name])
    return out


def heldout_signs(kin: LegKinematics, recordings: list[Recording], dq: np.ndarray, limits: CheckLimits = LIMITS,
                  frozen: dict | None = None, stances: list[Recording] | None = None) -> list[str]:
    """A channel read with the opposite sign in a held-out session (`standing_signs` on
    its posture, knees free): its foot height would score the reversed sign, not the
    calibration. Judged against `stances` (default: the recordings' stances); `frozen`:
    each recording's frozen channel kinds (`frozen_channels`), found when not given."""
    names = kin.legmap.joint_names
    held = [r for r in recordings if r.kind == "heldout"]
    if not held:
        return []
    if frozen is None:
        frozen = {r.name: frozen_channels(r, names, limits)[1] for r in recordings}

    def usable(r: Recording) -> bool:
        return _finite(r).sum() >= 10 and "encoder" not in frozen[r.name]

    if stances is None:
        stances = [r for r in recordings if r.kind == "stance" and usable(r)]
    return standing_signs(kin, [r for r in held if usable(r)], stances, dq, limits,
                          imu=lambda r: "imu" not in frozen[r.name], straight=False)[0]


def _finite(r: Recording) -> np.ndarray:
    """Frames with finite values and an accelerometer that reads something."""
    return (np.isfinite(r.q_enc).all(axis=1) & np.isfinite(r.imu_acc).all(axis=1) & np.isfinite(r.time)
            & (np.linalg.norm(np.nan_to_num(r.imu_acc), axis=1) > 1.0))


def _longest_run(x: np.ndarray) -> tuple[int, int]:
    """(length, start) of the longest run of bit-identical consecutive values in x."""
    change = np.flatnonzero(x[1:] != x[:-1]) + 1
    bounds = np.concatenate([[0], change, [len(x)]])
    lengths = np.diff(bounds)
    i = int(np.argmax(lengths))
    return int(lengths[i]), int(bounds[i])


def frozen_channels(r: Recording, joint_names: list[str],
                    limits: CheckLimits = LIMITS) -> tuple[list[str], set[str]]:
    """Channels stuck on one value while the robot moves (a frozen encoder, a stalled
    IMU or bus): the warnings, and which sensors ("encoder", "imu") were found stuck.
    "Moves" means another encoder spans more than `moving_rad` during the run, so a
    quiet encoder holding one count while the robot stands still is not flagged; nor is
    an encoder whose joint never spans `moving_rad` in the recording (a joint the
    motion leaves still, such as a five-joint leg's hip roll in sagittal stances, reads
    one value without noise: frozen and still cannot be told apart there)."""
    groups = [(f"encoder {joint_names[j]}", r.q_enc[:, j], [k for k in range(r.q_enc.shape[1]) if k != j])
              for j in range(r.q_enc.shape[1]) if np.nanmax(r.q_enc[:, j], initial=-np.inf)
              - np.nanmin(r.q_enc[:, j], initial=np.inf) > limits.moving_rad]
    sm = r.sensor_model
    for label, data, noisy in (("IMU accelerometer", r.imu_acc, sm.accel_noise_std > 0),
                               ("IMU gyro", r.imu_gyro, sm.gyro_noise_std > 0)):
        for a in range(3):
            # An IMU declared noiseless reads one value on an axis the motion leaves still.
            if noisy or np.nanmax(data[:, a], initial=-np.inf) > np.nanmin(data[:, a], initial=np.inf):
                groups.append((f"{label} {AXES[a]}", data[:, a], list(range(r.q_enc.shape[1]))))
    found: dict[str, list[str]] = {}
    for label, x, others in groups:
        n, start = _longest_run(x)
        if n < limits.frozen_frames:
            continue
        t0, t1 = r.time[start], r.time[start + n - 1]
        span = np.ptp(r.q_enc[start:start + n][:, others], axis=0)
        if t1 - t0 < limits.frozen_s or not np.nanmax(span, initial=0.0) > limits.moving_rad:
            continue
        key = f"{t0:.2f}-{t1:.2f}"
        found.setdefault(key, []).append(label)
    out, kinds = [], set()
    for key, labels in found.items():
        kinds |= {"encoder" if lb.startswith("encoder") else "imu" for lb in labels}
        t0, t1 = key.split("-")
        what = ", ".join(labels)
        cause = ("a frozen or disconnected encoder, or a logger repeating its last value" if labels[0].startswith(
            "encoder") else "a stalled IMU or a logger repeating its last sample")
        # A frozen encoder reads no joint: the offsets fitted to it are not the robot's; a
        # frozen IMU loses the flat-ground term's frames.
        out.append(Finding(f"{r.name}: {what} read{'s' if len(labels) == 1 else ''} one unchanging value from t = "
                           f"{t0} to {t1} s while the other channels move: likely {cause}; drop those frames or the "
                           "channel's recording", INVALIDATES if labels[0].startswith("encoder") else DOUBTS))
    return out, kinds


def straight_knees(kin: LegKinematics, r: Recording, limits: CheckLimits = LIMITS) -> list[str]:
    """The straight-leg standing phase must read straight knees (within an offset's
    size): the knee prior is taken from it."""
    legmap = kin.legmap
    out = []
    for j, (name, role) in enumerate(zip(legmap.joint_names, legmap.joint_roles)):
        if role != "knee":
            continue
        q = np.nanmedian(r.q_enc[:, j])
        if abs(q - legmap.knee_straight_rad) > limits.straight_knee_rad:
            out.append(Finding(
                f"{r.name}: {name} reads {np.degrees(q - legmap.knee_straight_rad):+.1f} deg from straight "
                f"(knee_straight_rad {legmap.knee_straight_rad:g}) in the straight-leg standing phase: not a "
                "straight-leg phase, angles not in radians, or a wrong knee_straight_rad in the leg map; the knee "
                "prior taken from it would be wrong", DOUBTS))
    return out


def coplanarity(kin: LegKinematics, r: Recording, dq: np.ndarray, limits: CheckLimits = LIMITS) -> tuple[float, float]:
    """(height, tilt): the right sole's median height (m) and tilt (rad) in the left
    sole's frame, raw or corrected by `dq`, whichever is nearer one plane."""
    Q = r.q_enc[_subsample(r, limits.max_frames)]
    best = None
    for d in (np.zeros_like(dq), dq):
        C = frame_kinematics(kin, Q + d).C
        z = float(np.median(C[:, 2, 3]))
        tilt = float(np.median(np.arccos(np.clip(C[:, 2, 2], -1.0, 1.0))))
        bad = max(abs(z) / limits.coplanar_m, tilt / limits.coplanar_rad)
        if best is None or bad < best[0]:
            best = (bad, z, tilt)
    return best[1], best[2]


def soles_coplanar(kin: LegKinematics, recordings: list[Recording], dq: np.ndarray,
                   limits: CheckLimits = LIMITS) -> tuple[list[str], set[str]]:
    """In double support on a level floor both soles lie on one plane: the right sole's
    height and tilt in the left sole's frame stay near zero."""
    out, apart = [], set()
    for r in recordings:
        z, tilt = coplanarity(kin, r, dq, limits)
        if max(abs(z) / limits.coplanar_m, tilt / limits.coplanar_rad) > 1.0:
            apart.add(r.name)
            where = "above" if z > 0 else "below"
            out.append(Finding(
                f"{r.name}: the soles are not on one plane: the right sole sits {abs(z) * 1e3:.0f} mm {where} the "
                f"left and is tilted {np.degrees(tilt):.1f} deg against it (a good recording: within a few mm and "
                "degrees): angles not in radians, columns in another order than joint_names, the wrong leg map, or "
                "not double support", INVALIDATES))
    return out, apart


def _subsample(r: Recording, n: int) -> np.ndarray:
    idx = np.flatnonzero(_finite(r))
    return idx[np.linspace(0, len(idx) - 1, min(n, len(idx))).round().astype(int)]


def _dispersion(kin: LegKinematics, Qs: list[np.ndarray]) -> float:
    """Largest per-stance median distance of the inter-foot translation from its median
    (m): robust, so a short glitch (the contact filter's business) does not count."""
    worst = 0.0
    for Q in Qs:
        C = frame_kinematics(kin, Q).C
        tau = Log(inverse(frechet_mean(C, tol=1e-10)) @ C)[:, :3]
        worst = max(worst, float(np.median(np.linalg.norm(tau - np.median(tau, axis=0), axis=1))))
    return worst


def _column_candidates(kin: LegKinematics) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(description, column permutation, signs) for each plausible wiring mistake."""
    names, roles = kin.legmap.joint_names, kin.legmap.joint_roles
    side_cols = {s: [names.index(j.name) for j in kin.legmap.legs[s].joints] for s in kin.legmap.legs}
    left, right = side_cols["left"], side_cols["right"]
    n = kin.legmap.n_joints
    ident, ones = np.arange(n), np.ones(n)
    out = []
    perm = ident.copy()
    perm[left], perm[right] = right, left
    out.append(("the left and right legs' columns are exchanged", perm, ones))
    for a, b in itertools.combinations(range(kin.legmap.leg_joints), 2):
        both = ident.copy()
        for cols in (left, right):
            both[[cols[a], cols[b]]] = both[[cols[b], cols[a]]]
        out.append((f"the {roles[left[a]]} and {roles[left[b]]} columns are exchanged on both legs", both, ones))
        for side, cols in side_cols.items():
            one = ident.copy()
            one[[cols[a], cols[b]]] = one[[cols[b], cols[a]]]
            out.append((f"{names[cols[a]]} and {names[cols[b]]} are exchanged", one, ones))
    for j in range(n):
        s = ones.copy()
        s[j] = -1.0
        out.append((f"{names[j]} reads with the opposite sign", ident, s))
    return out


def swapped_columns(kin: LegKinematics, stances: list[Recording], dq: np.ndarray,
                    limits: CheckLimits = LIMITS) -> tuple[list[str], set[str]]:
    """The stances whose inter-foot transform is unsteady both on the raw encoders and
    corrected by `dq`, with the wiring mistake that explains it if one does (searched on
    the raw encoders: a wrong column order spoils the estimate). A named wiring mistake
    is the logger's, so it concerns every stance: all are returned, and their further
    checks skipped (on a short-legged robot a stance with little hip motion can stay
    under the dispersion limit with the columns exchanged, and its IMU and slide figures
    would then be read as defects of their own)."""
    Qs = {r.name: r.q_enc[_subsample(r, limits.max_frames)] for r in stances}
    disp = {n: min(_dispersion(kin, [Q]), _dispersion(kin, [Q + dq])) for n, Q in Qs.items()}
    unsteady = sorted(n for n, d in disp.items() if d > limits.dispersion_m)
    if not unsteady:
        return [], set()
    now = max(disp[n] for n in unsteady)
    msg = (f"{', '.join(unsteady)}: the inter-foot transform varies by up to {now * 1e3:.1f} mm (median) within "
           "the stance, raw and calibrated (feet fixed: under 1 mm in a good recording)")
    test = [Qs[n] for n in unsteady]
    raw = max(_dispersion(kin, [Q]) for Q in test)
    best = min(((d, _dispersion(kin, [Q[:, p] * s for Q in test])) for d, p, s in _column_candidates(kin)),
               key=lambda x: x[1])
    if best[1] * limits.swap_gain < raw:
        msg += (f": likely {best[0]} (the raw transform is steady to {best[1] * 1e3:.1f} mm with that undone); "
                "check joint_names against the logger's column order")
        return [Finding(msg, INVALIDATES)], set(Qs)
    else:
        msg += ": a foot moved, or the columns, units or leg map do not match the robot"
    return [Finding(msg, DOUBTS)], set(unsteady)


def _standing_terms(kin: LegKinematics, Q: np.ndarray, up: np.ndarray | None, ref: np.ndarray | None,
                    limits: CheckLimits, straight: bool = True) -> np.ndarray:
    """(m, k) residuals of the double-support posture Q (m, n) on flat ground, each over
    its limit: the right sole's height and tilt (x, y of its normal) in the left sole's
    frame, the IMU's vertical `up` (pelvis frame) against the soles' mean normal less the
    same in the stances (`ref`: the IMU's mount and the floor's slope cancel; skipped
    when None), and, for straight-leg standing (`straight`), each knee from straight."""
    fk = frame_kinematics(kin, Q)
    cols = [fk.C[:, 2, 3] / limits.standing_height_m, fk.C[:, 0, 2] / limits.standing_tilt_rad,
            fk.C[:, 1, 2] / limits.standing_tilt_rad]
    if up is not None and ref is not None:
        e = _gravity_vectors(fk, np.broadcast_to(up, (len(Q), 3))) - ref
        cols += list(e.T / limits.standing_gravity_rad)
    legmap = kin.legmap
    knees = [j for j, role in enumerate(legmap.joint_roles) if role == "knee" and straight]
    cols += [(Q[:, j] - legmap.knee_straight_rad) / limits.standing_knee_rad for j in knees]
    return np.stack(cols, axis=1)


def _gravity_vectors(fk, up: np.ndarray) -> np.ndarray:
    """(N, 3) n x up: the soles' mean normal against the IMU's vertical, both in the pelvis
    frame (its norm the angle between them, for small angles)."""
    n = fk.R_L[:, :, 2] + fk.R_R[:, :, 2]
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    return np.cross(n, up)


def _standing_posture(r: Recording, kin: LegKinematics) -> tuple[np.ndarray, np.ndarray]:
    """(q (n,), up (3,)): a standing recording's one posture, its frames' median encoders,
    and the IMU's median vertical in the pelvis frame."""
    ok = _finite(r)
    up = up_in_base(np.median(r.imu_acc[ok], axis=0)[None], kin.R_BI)[0]
    return np.median(r.q_enc[ok], axis=0), up


def standing_signs(kin: LegKinematics, standing: list[Recording], stances: list[Recording], dq: np.ndarray,
                   limits: CheckLimits = LIMITS, imu=lambda r: True,
                   straight: bool = True) -> tuple[list[str], set[str]]:
    """A channel read with the opposite sign in a straight-leg standing recording, or
    (`straight` False) in a held-out session, each a static double-support posture on
    flat ground whose knees need not be straight. It holds one posture, so the inter-foot transform cannot vary there (`swapped_columns`
    sees nothing); instead the posture must fit the stances' calibration: judged at the
    raw encoders, at `dq`, and when neither fits at the framework's fit of the steady
    `stances` alone (`checks.profile`: the standing phase does not enter it, so a
    knee's flipped sign there cannot spoil it), by `_standing_terms` (the IMU's term with
    the stances' as reference, for recordings where `imu(r)` and the stances agree on
    it). A posture that fits none of them is tried with each channel's sign reversed,
    and a reversal that fits within the limits and `swap_gain` times better than the
    logged posture is named. Returns the warnings and the recordings named."""
    if not standing or not stances:
        return [], set()
    names = kin.legmap.joint_names
    n = kin.legmap.n_joints
    flips = np.ones((n + 1, n))
    flips[np.arange(1, n + 1), np.arange(n)] = -1.0  # row 0: as logged; row j + 1: joint j reversed
    estimates = [np.zeros(n), np.asarray(dq, dtype=float)]
    refs: dict[int, np.ndarray | None] = {}

    def reference(k: int) -> np.ndarray | None:
        """The stances' median n x up at estimates[k]; None where they disagree (an IMU
        axis or mount the stances' own check is about)."""
        if k not in refs:
            per = []
            for r in stances:
                i = _subsample(r, limits.max_frames)
                fk = frame_kinematics(kin, r.q_enc[i] + estimates[k])
                per.append(np.median(_gravity_vectors(fk, up_in_base(r.imu_acc[i], kin.R_BI)), axis=0))
            per = np.array(per)
            mid = np.median(per, axis=0)
            spread = np.linalg.norm(per - mid, axis=1).max()
            refs[k] = mid if spread < 0.5 * limits.standing_gravity_rad else None
        return refs[k]

    def fits(q: np.ndarray, up: np.ndarray | None, k: int) -> np.ndarray:
        """Badness (the largest residual over its limit) of each sign pattern at estimates[k]."""
        terms = _standing_terms(kin, q * flips + estimates[k], up, reference(k) if up is not None else None, limits,
                                straight)
        return np.abs(terms).max(axis=1)

    out, named = [], set()
    profiled = False
    for r in standing:
        q, up = _standing_posture(r, kin)
        up = up if imu(r) else None
        bad = [fits(q, up, k) for k in range(len(estimates))]
        if min(b[0] for b in bad) <= 1.0:
            continue
        if not profiled:
            profiled = True
            from legcal_bench.estimation.checks.profile import profiled_offsets

            fitted, _ = profiled_offsets(kin.legmap, stances)
            if fitted is not None:
                estimates.append(fitted)
        bad = [fits(q, up, k) for k in range(len(estimates))]
        logged = min(b[0] for b in bad)
        if logged <= 1.0:
            continue
        k, j = min(((k, j) for k in range(len(estimates)) for j in range(1, n + 1)), key=lambda kj: bad[kj[0]][kj[1]])
        best = bad[k][j]
        if best > 1.0 or best * limits.swap_gain >= logged:
            continue
        also = [names[i - 1] for i in range(1, n + 1) if i != j and min(b[i] for b in bad) * limits.swap_gain < logged
                and min(b[i] for b in bad) <= max(1.0, 2.0 * best)]
        named.add(r.name)
        what = _standing_text(kin, q * flips[0] + estimates[k], up, reference(k) if up is not None else None, limits,
                              straight)
        knees = f", the knees within {np.degrees(limits.standing_knee_rad):g} deg of straight" if straight else ""
        # A channel read reversed in training corrupts the fit (the knee prior); in a held-out
        # session, only its score.
        out.append(Finding(f"{r.name}: the {'straight-leg standing' if straight else 'held-out'} posture does not fit the "
                   f"stances' calibration ({what}; good data: the soles within {limits.standing_height_m * 1e3:g} mm "
                   f"and {np.degrees(limits.standing_tilt_rad):g} deg of one plane, the IMU's vertical within "
                   f"{np.degrees(limits.standing_gravity_rad):g} deg{knees}): likely {names[j - 1]} reads with the "
                   "opposite sign in this recording"
                   + (f" (or {' or '.join(also)}: with {'that' if len(also) == 1 else 'each'} undone it fits "
                      "within the limits too)" if also else "")
                   + f" (with it undone the largest figure is {best:.2f} of its limit, as logged {logged:.1f} times "
                   "it); check the logger's sign for that channel in this recording: "
                   + ("a knee prior taken from it would be wrong" if straight else
                      "its held-out foot height would score the reversed sign, not the calibration"),
                   INVALIDATES if straight else DOUBTS))
    return out, named


def _standing_text(kin: LegKinematics, q: np.ndarray, up, ref, limits: CheckLimits, straight: bool = True) -> str:
    """The figures of a standing posture that exceed their limits, in display units."""
    fk = frame_kinematics(kin, q[None])
    C = fk.C[0]
    parts = []
    z, tilt = C[2, 3], np.hypot(C[0, 2], C[1, 2])
    if abs(z) > limits.standing_height_m or tilt > limits.standing_tilt_rad:
        parts.append(f"the right sole {abs(z) * 1e3:.1f} mm {'above' if z > 0 else 'below'} the left and tilted "
                     f"{np.degrees(tilt):.2f} deg against it")
    if up is not None and ref is not None:
        g = float(np.linalg.norm(_gravity_vectors(fk, up[None])[0] - ref))
        if g > limits.standing_gravity_rad:
            parts.append(f"the IMU's vertical {np.degrees(g):.2f} deg from where the stances put it on the soles")
    legmap = kin.legmap
    for j, role in enumerate(legmap.joint_roles):
        if straight and role == "knee" and abs(q[j] - legmap.knee_straight_rad) > limits.standing_knee_rad:
            parts.append(f"{legmap.joint_names[j]} {np.degrees(q[j] - legmap.knee_straight_rad):+.2f} deg from "
                         "straight")
    return ", ".join(parts) or "several figures near their limits"


def lunge_sides(kin: LegKinematics, stances: list[Recording],
                limits: CheckLimits = LIMITS) -> tuple[list[str], set[str]]:
    """Lunges recorded with the other foot ahead: for a stance of the built-in protocol
    whose feet are apart fore-aft by `lunge_m` leg lengths or more, the encoders must put
    the foot the stance names ahead. Exchanged legs keep the inter-foot transform steady
    where the stances move the legs alike (a five-joint robot's sagittal stances: its hip
    roll and yaw stay still), so `swapped_columns` cannot see them; the lunge's side can.
    Returns the warning and the stances it concerns (all of them: a wiring mistake)."""
    from legcal_bench.protocol.stances import ALL_STANCES

    L = kin.dims.leg_length
    wrong = []
    for r in stances:
        st = ALL_STANCES.get(r.stance)
        if st is None or abs(st.right_x - st.left_x) < limits.lunge_m:
            continue
        ahead = float(np.median(frame_kinematics(kin, r.q_enc[_subsample(r, limits.max_frames)]).C[:, 0, 3]))
        expected = (st.right_x - st.left_x) * L  # the right sole's x in the left sole's frame
        if ahead * expected < 0 and abs(ahead) > 0.5 * abs(expected):
            wrong.append((r.name, st.label, ahead))
    if not wrong:
        return [], set()
    shown = "; ".join(f"{name} ({label}): the right foot {abs(x) * 1e3:.0f} mm {'ahead of' if x > 0 else 'behind'} "
                      "the left" for name, label, x in wrong)
    return [Finding(f"{shown}: the lunge's other foot is ahead: likely the left and right legs' columns are "
                    "exchanged (check joint_names against the logger's column order), or the recording is not of the "
                    "stance its label names", INVALIDATES)], {r.name for r in stances}


def _gravity_errors(kin: LegKinematics, Q: np.ndarray, acc: np.ndarray) -> tuple[float, float]:
    """(median angle, RMS of its moving part) between the IMU's vertical and the soles'
    mean normal, both in the pelvis frame."""
    fk = frame_kinematics(kin, Q)
    n = fk.R_L[:, :, 2] + fk.R_R[:, :, 2]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    up = up_in_base(acc, kin.R_BI)
    e = np.cross(n, up)
    ang = np.arctan2(np.linalg.norm(e, axis=1), np.einsum("ni,ni->n", n, up))
    moving = e - np.median(e, axis=0)
    return float(np.median(ang)), float(np.sqrt((moving ** 2).sum(axis=1).mean()))


def _gravity_fit(kin: LegKinematics, Q: np.ndarray, acc: np.ndarray, dq: np.ndarray,
                 limits: CheckLimits) -> tuple[float, float, float]:
    """(badness against the limits, median angle, moving RMS) of the IMU's vertical
    against the posture's, raw or corrected by `dq`, whichever fits better."""
    return min((max(ang / limits.gravity_rad, mov / limits.gravity_motion_rad), ang, mov)
               for ang, mov in (_gravity_errors(kin, Q + d, acc) for d in (np.zeros_like(dq), dq)))


def _signed_permutations():
    for perm in itertools.permutations(range(3)):
        for signs in itertools.product((1, -1), repeat=3):
            P = np.zeros((3, 3))
            P[range(3), perm] = signs
            if not np.array_equal(P, np.eye(3)):
                yield P


def imu_axes(kin: LegKinematics, stances: list[Recording], dq: np.ndarray,
             limits: CheckLimits = LIMITS) -> tuple[list[str], set[str]]:
    """The IMU's vertical against the posture's: the warning and the stances it concerns,
    with the permutation of the accelerometer's axes that explains it if one does. Like
    the per-stance changes, each stance is judged on the raw encoders and with `dq`, and
    the better fit counts."""
    idx = [_subsample(r, limits.max_frames) for r in stances]
    Qs = [r.q_enc[i] for r, i in zip(stances, idx)]
    accs = [r.imu_acc[i] for r, i in zip(stances, idx)]

    def badness(k, P=None):
        return _gravity_fit(kin, Qs[k], accs[k] if P is None else accs[k] @ P.T, dq, limits)

    errs = [badness(k) for k in range(len(stances))]
    bad = [k for k, e in enumerate(errs) if e[0] > 1.0]
    if not bad:
        return [], set()
    k = max(bad, key=lambda k: errs[k][0])
    names = ", ".join(stances[k].name for k in bad)
    msg = (f"{names}: the IMU's vertical is up to {np.degrees(errs[k][1]):.1f} deg from the posture's (flat soles) "
           f"and moves against it by up to {np.degrees(errs[k][2]):.2f} deg RMS (good data: under "
           f"{np.degrees(limits.gravity_rad):g} and {np.degrees(limits.gravity_motion_rad):g} deg)")
    now = max(errs[k][0] for k in bad)
    fits = [(P, b) for P, b in ((P, max(badness(k, P)[0] for k in bad)) for P in _signed_permutations())
            if b <= 1.0 and b * 3 < now]
    if fits:
        # Readings the stances cannot tell apart (an axis gravity never leans along, as a
        # pelvis that never rolls leaves y's sign unseen) all fit: the one changing the
        # fewest axes is named, and the axes the fits disagree on are said to be unseen.
        P, b = min(fits, key=lambda f: (int((np.diag(f[0]) != 1).sum()), f[1]))
        unseen = [AXES[i] for i in range(3) if any(not np.array_equal(Q[i], P[i]) for Q, _ in fits)]
        reading = ", ".join(f"{AXES[i]} = {'+' if P[i].sum() > 0 else '-'}logged {AXES[int(np.argmax(abs(P[i])))]}"
                            for i in range(3))
        msg += (f": likely permuted or flipped IMU axes (reading the accelerometer as {reading} fits"
                + (f"; so do readings that differ in {' and '.join(unseen)}, along which gravity never leaned in "
                   "these stances" if unseen else "")
                + "); fix the logger's axis order or the leg map's imu frame")
    else:
        msg += (": a wrong IMU mount rotation in the leg map (imu), a sloped floor, an IMU not rigid on the pelvis, "
                "or a stance that is not static")
    return [Finding(msg, INVALIDATES)], {stances[k].name for k in bad}


def end_changes(kin: LegKinematics, r: Recording, dq: np.ndarray, limits: CheckLimits = LIMITS) -> dict | None:
    """The change between a stance's first and last `end_fraction` of frames of the
    inter-foot translation ("trans", m, in the left sole's frame), its yaw ("yaw", rad)
    and each sole's tilt against the IMU's vertical ("left", "right": the up vector's
    x, y in the sole frame), plus the feet's distance ("distance", m). Each is measured
    on the raw encoders and with `dq`, and the smaller one counts: a real change shows in
    both, while offsets (raw) or an estimate spoiled by other bad data (`dq`) show in one
    only. None for a recording too short to tell."""
    idx = np.flatnonzero(_finite(r))
    m = max(1, int(round(limits.end_fraction * len(idx))))
    if len(idx) < 2 * m + 1:
        return None
    first, last = slice(0, m), slice(len(idx) - m, len(idx))
    up = up_in_base(r.imu_acc[idx], kin.R_BI)

    def changes(d):
        fk = frame_kinematics(kin, r.q_enc[idx] + d)
        tau = Log(inverse(frechet_mean(fk.C, tol=1e-10)) @ fk.C)
        p = fk.C[:, :3, 3]
        ch = {"trans": p, "yaw": tau[:, 5:6]}
        for side, R in (("left", fk.R_L), ("right", fk.R_R)):
            ch[side] = np.einsum("nji,nj->ni", R, up)[:, :2]
        out = {k: v[last].mean(axis=0) - v[first].mean(axis=0) for k, v in ch.items()}
        out["distance"] = float(np.linalg.norm(p.mean(axis=0)))
        return out

    a, b = changes(np.zeros_like(dq)), changes(dq)
    return {k: (a[k] if np.linalg.norm(a[k]) <= np.linalg.norm(b[k]) else b[k]) for k in a}


def stance_changes(kin: LegKinematics, r: Recording, dq: np.ndarray, limits: CheckLimits = LIMITS,
                   tilt: bool = True) -> list[str]:
    """A gradual slide, yaw creep or a lifted heel, from `end_changes` (tilts only with
    `tilt`). A lifted sole explains the translation that comes with it, yaw creep the
    translation its rotation carries."""
    c = end_changes(kin, r, dq, limits)
    if c is None:
        return []
    span = f"between its first and last {limits.end_fraction:.0%} of frames"
    out = []
    lifted = False
    if tilt:
        big = {s: c[s] for s in ("left", "right") if np.linalg.norm(c[s]) > limits.sole_tilt_rad}
        alike = len(big) == 2 and (np.linalg.norm(c["left"] - c["right"])
                                   < 0.5 * max(map(np.linalg.norm, big.values())))
        if alike:
            out.append(Finding(f"{r.name}: the IMU's vertical moved {np.degrees(np.linalg.norm(c['left'])):.2f} deg "
                               f"against both soles alike {span}: likely an IMU drifting, stuck or not rigid on the "
                               "pelvis", INVALIDATES))
        else:
            for side, v in big.items():
                if abs(v[0]) >= abs(v[1]):
                    what, axis = ("heel" if v[0] < 0 else "toe"), "pitch"
                else:
                    outer = (v[1] > 0) == (side == "left")
                    what, axis = ("outer" if outer else "inner") + " edge", "roll"
                out.append(Finding(f"{r.name}: the {side} sole's tilt against the IMU's vertical changed "
                                   f"{np.degrees(np.linalg.norm(v)):.2f} deg ({axis}) {span}: likely its {what} "
                                   "lifted and stayed lifted; drop the stance or the frames after the lift", DOUBTS))
                lifted = True
    yaw = float(c["yaw"][0])
    creep = abs(yaw) > limits.yaw_rad
    if creep and not lifted:
        out.append(Finding(f"{r.name}: the inter-foot yaw changed {np.degrees(yaw):+.2f} deg {span}: likely a foot "
                           "creeping in yaw (turning on the floor); check the floor's friction, or drop the stance",
                           DOUBTS))
    trans = float(np.linalg.norm(c["trans"]))
    carried = abs(yaw) * c["distance"] if creep else 0.0
    if not lifted and trans - carried > limits.slide_m:
        axis = AXES[int(np.argmax(abs(c["trans"])))]
        out.append(Finding(f"{r.name}: the feet moved {trans * 1e3:.1f} mm relative to each other {span} (mostly "
                           f"along the left sole's {axis}): likely a foot sliding gradually; check the floor's "
                           "friction, or drop the stance", DOUBTS))
    return out


def statistics(kin: LegKinematics, r: Recording, dq: np.ndarray | None = None,
               limits: CheckLimits = LIMITS) -> dict:
    """What the checks measure on one recording, in display units (mm, deg), for
    `legcal-bench check`: each figure is the one its check compares with its limit."""
    dq = np.zeros(kin.legmap.n_joints) if dq is None else np.asarray(dq, dtype=float)
    ok = _finite(r)
    out: dict = {"name": r.name, "kind": r.kind, "frames": r.n_frames, "finite_frames": int(ok.sum()),
                 "longest_run_encoder": max(_longest_run(r.q_enc[:, j])[0] for j in range(r.q_enc.shape[1])),
                 "longest_run_imu": max(_longest_run(x[:, a])[0] for x in (r.imu_acc, r.imu_gyro) for a in range(3))}
    if r.kind not in ("stance", "standing") or ok.sum() < 10:
        return out
    Q = r.q_enc[_subsample(r, limits.max_frames)]
    out["dispersion_mm"] = 1e3 * min(_dispersion(kin, [Q]), _dispersion(kin, [Q + dq]))
    z, tilt = coplanarity(kin, r, dq, limits)
    out["soles_height_mm"], out["soles_tilt_deg"] = 1e3 * z, float(np.degrees(tilt))
    acc = r.imu_acc[_subsample(r, limits.max_frames)]
    _, ang, mov = _gravity_fit(kin, Q, acc, dq, limits)
    out["gravity_deg"], out["gravity_motion_deg"] = float(np.degrees(ang)), float(np.degrees(mov))
    c = end_changes(kin, r, dq, limits) if r.kind == "stance" else None
    if c is not None:
        out["slide_mm"] = 1e3 * float(np.linalg.norm(c["trans"]))
        out["yaw_deg"] = float(np.degrees(c["yaw"][0]))
        out["left_tilt_change_deg"] = float(np.degrees(np.linalg.norm(c["left"])))
        out["right_tilt_change_deg"] = float(np.degrees(np.linalg.norm(c["right"])))
    return out
