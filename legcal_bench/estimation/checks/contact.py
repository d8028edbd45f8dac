"""The per-stance contact check on a fit: were each stance's soles on one flat floor?
(`legcal_bench.estimation.checks.coplanarity` judges one stance; this runs it on the
stance problem, every stance tested against the others.)

One test for every caller (issue #60): the calibrator runs `contact_check` on its own
fit's segments, `legcal-bench check` runs it through `recordings_contact_check` on the
framework's fit of the same recordings; both judge it on the noise-weighted problem, so
they flag the same stances. (`datacheck.soles_coplanar` is a gross screen: soles 20 mm
or 10 degrees off one plane, a wrong sole frame, not this test.)"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from legcal_bench.estimation.checks.coplanarity import StanceContact, check_stances, shared_misfit
from legcal_bench.estimation.information.noise import noise_sigmas
from legcal_bench.estimation.information.tails import chi2_logsf
from legcal_bench.estimation.problem.fit import NOISE_TILT, FrameWhitening, frame_whitening, offsets_fit
from legcal_bench.estimation.problem.stance import Prepared, Segment, StanceProblem, noise_weights, prepare_sensor

CONTACT_CHECKS = ("flag", "drop", "off")


def contact_check(prep: Prepared, segments: list[Segment], dq0: np.ndarray,
                  solved: bool = False, start: FrameWhitening | None = None) -> list[StanceContact] | None:
    """The per-stance coplanarity check of `segments` (a fit's, after trimming), from
    offsets `dq0`: on the noise-weighted problem without priors whatever the fit's
    setting (a prior's pull would show as a departure), stances tested against the
    others; the worst flagged stance is set aside and the rest tested again without it,
    while three or more remain (one bad stance would otherwise spoil the others'
    predictions). Each round is judged at the shared misfit of the stances other than the
    least consistent one, among themselves (`coplanarity.shared_misfit`: 1 where the
    declared noise holds, the stated fallback where it does not). `solved`: `dq0` is the optimum of `prep`'s weights over `segments`,
    so where those are the noise weights it is taken as it is, not solved for again.
    None when the recordings declare no noise to judge it against or have a single
    stance. `start`: the offsets-only fit's `frame_whitening` at `dq0` over `segments`, if
    in hand (read where `dq0` is taken as it is)."""
    sig = noise_sigmas(prep.stances[0].sensor_model, prep.kin.dims.leg_length)
    if sig is None or len({s.recording for s in segments}) < 2:
        return None
    weights = noise_weights(sig)
    problem = StanceProblem(prep.kin, segments, weights, None, [], prep.options.bound)
    if solved and prep.w == weights:
        dq = np.asarray(dq0, dtype=float)
    else:
        dq, _ = problem.solve(dq0, prep.options)
        start = None  # at another point
    final: dict[str, StanceContact] = {}
    items, scale = _stance_items(prep, problem, dq, start), 1.0
    while True:
        raw, worst = check_stances(items, sig["encoder"]), None
        # judged at the shared misfit of the stances other than the worst; that scale is
        # never below 1 (`shared_misfit`), so it can only clear flags: where no stance is
        # flagged at the declared noise, the sub-problem it needs is not solved
        if len(raw) >= 3 and not any(c.flagged for c in raw):
            scale = 1.0
        elif len(raw) >= 3:
            # the least consistent stance (log p, then chi2/dof where log p underflows too)
            worst = min(raw, key=lambda c: (chi2_logsf(c.chi2, c.dof), -c.chi2 / c.dof)).recording
            sub, dq_sub, sub_items = _without(prep, problem, dq, worst, weights)
            scale = shared_misfit([c.chi2 / c.dof for c in check_stances(sub_items, sig["encoder"])])
        results = raw if scale == 1.0 else check_stances(items, sig["encoder"], scale=scale)
        bad = [c for c in results if c.flagged]
        if not bad or len(results) <= 2:
            final.update({c.recording: c for c in results})
            break
        flagged = max(bad, key=lambda c: c.chi2)
        final[flagged.recording] = flagged
        if flagged.recording != worst:
            sub, dq_sub, sub_items = _without(prep, problem, dq, flagged.recording, weights)
        problem, dq, items = sub, dq_sub, sub_items
    return [final[n] for n in dict.fromkeys(s.recording for s in segments)]


def _without(prep: Prepared, problem: StanceProblem, dq: np.ndarray, name: str, weights):
    """(problem, offsets, stance items) of `problem` without the stance `name`, solved
    from `dq`."""
    sub = StanceProblem(prep.kin, [s for s in problem.segments if s.recording != name], weights, None, [],
                        prep.options.bound)
    dq_sub, _ = sub.solve(dq, prep.options)
    return sub, dq_sub, _stance_items(prep, sub, dq_sub)


def recordings_contact_check(legmap, recordings, dq0: np.ndarray | None = None) -> list[StanceContact] | None:
    """`contact_check` on `recordings` (their stances and standing): the framework's fit
    (declared-noise weights; solve, trim, solve, from `dq0`, zeros by default), judged as
    the calibrator judges its own. None as `contact_check`; raises `CalibrationError`
    where the recordings cannot be fitted."""
    training = [r for r in recordings if r.kind in ("stance", "standing")]
    prep = prepare_sensor(legmap, training)
    problem = StanceProblem.of(prep)
    dq, _, _ = problem.solve_trimmed(np.zeros(legmap.n_joints) if dq0 is None else np.asarray(dq0, float),
                                     prep.options)
    prep = replace(prep, options=replace(prep.options, bound=problem.bound))
    return contact_check(prep, problem.segments, dq, solved=True)


def _stance_items(prep: Prepared, problem: StanceProblem, dq: np.ndarray,
                  start: FrameWhitening | None = None) -> list[dict]:
    """`check_stances`'s input of each segment: its departure from one plane at the
    offsets of the other stances, and their covariance. The others' offsets come with a fixed error of the IMU's vertical as a nuisance, within the
    recordings' declared bound (`SensorModel.tilt_bound`, the prior's standard
    deviation): on a robot whose hip does not start with pitch, such a tilt moves the
    offsets differently with each stance's posture, and a realistic (uncalibrated) IMU
    would otherwise read as soles off one plane. `start`: the offsets-only fit's
    `frame_whitening` at `dq` over these segments, if in hand."""
    segs = problem.segments
    names = list(dict.fromkeys(s.recording for s in segs))
    fw = frame_whitening(prep, offsets_fit(prep, dq, segs)) if start is None else start
    fr = fw.frames
    bound = prep.stances[0].sensor_model.tilt_bound
    tilt = np.arange(fr.model.n)[fr.model.slices[NOISE_TILT]][:2] if bound > 0 else np.zeros(0, dtype=int)
    nj = prep.kin.legmap.n_joints  # the offsets' columns; then the IMU tilt's
    cols = np.r_[np.arange(nj), tilt]
    prior = np.zeros((len(cols), len(cols)))
    prior[nj:, nj:] = np.eye(len(tilt)) / bound**2 if bound > 0 else 0.0
    W = fw.W
    Jw = W @ fr.J[:, :, cols]
    info = {n: np.einsum("kri,krj->ij", Jw[fr.recording == n], Jw[fr.recording == n]) for n in names}
    total = sum(info.values()) + prior
    means = problem.means_at(dq)
    zw = np.einsum("nij,nj->ni", W, fr.r)
    prior_rows = np.sqrt(prior)[nj:]
    # The offsets' change without each stance: one Gauss-Newton step on the other
    # stances' whitened rows (the IMU tilt within its prior): the estimate whose
    # covariance `cov` is. (A step on the row-weighted rows, as before issue #58, has two
    # to three times that spread, more where a stance's posture extrapolates the others':
    # clean realistic sets read as soles off one plane at chi2 ~20-200 on 3 dof.)
    delta = {}
    for n in names:
        others = fr.recording != n
        A = np.vstack([Jw[others].reshape(-1, len(cols)), prior_rows])
        delta[n] = -np.linalg.lstsq(A, np.r_[zw[others].ravel(), np.zeros(len(prior_rows))], rcond=None)[0][:nj]
    items = []
    for i, s in enumerate(segs):
        m = fr.segment == i
        items.append({"recording": s.recording, "M": means[i], "G": fr.J_fixed[m, :6, :nj],
                      "delta": delta[s.recording],
                      "cov": np.linalg.pinv(total - info[s.recording], hermitian=True)[:nj, :nj],
                      "left_tilt": fr.r[m, 7:9].mean(axis=0)})
    return items
