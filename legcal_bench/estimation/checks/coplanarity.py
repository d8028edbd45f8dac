"""Per-stance contact check (issue #16): were both soles on one plane in each stance?

In static double support on a flat floor, each stance's mean inter-foot transform M_s
(the right sole in the left sole's frame) lies in the floor's plane: the right sole's
normal is the left's and its origin is at the left's height. The inter-foot rows are
relative to M_s, so only the flat-ground rows pin it; a stance whose soles were not on
one plane (a shim, a pebble, an uneven tile under one foot) leaves its inter-foot rows
clean and biases every offset through its flat-ground rows.

The check, per stance s: c_s, the right sole's tilt about x and y (rad) and its height
(m) in the left sole's frame at M_s, evaluated at the offsets of the other stances
(zero on one plane): the offsets re-estimated without s (one Gauss-Newton step of
the whitened problem of the other stances: exact for linear least squares), carried
to c_s. Its covariance is

    Sigma_s = D Sigma_M D^T + J_c Cov(dq_-s) J_c^T,

Sigma_M = sigma_q^2 / N^2 sum_k G_k G_k^T the mean's covariance from encoder noise
(G_k the frame's inter-foot Jacobian), J_c = D mean_k G_k, Cov(dq_-s) the noise-only
covariance of the other stances' estimate (the inverse of their whitened information,
`legcal_bench.estimation.information.whitening`; with a fixed error of the IMU's vertical as a
nuisance within the declared tilt bound, `legcal_bench.estimation.checks.contact`).
chi2 with 3 degrees of freedom per contact segment, judged at the stances' shared misfit
where they share one beyond the declared noise (`shared_misfit`: the median chi2/dof
over the stances, a Birge ratio: the stated fallback where the noise model does not hold,
as on a contact floor whose soles rock and give under load); a stance is flagged at a family-wise false-alarm rate `ALPHA` over the
stances (Bonferroni) when its soles are also off one plane by more than `MIN_TILT_RAD`
or `MIN_HEIGHT_M` (smaller departures are below what matters at the encoder's
resolution, whatever their significance).

Which sole: the stance's mean left-sole tilt against the IMU, less the other stances'
mean (the IMU's mounting tilt is common to all), follows a wedge under the left sole
and stays put under a wedge under the right one.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from legcal_bench.estimation.information.tails import chi2_sf

ALPHA = 0.01  # family-wise false-alarm rate over a calibration's stances
# Practical floor: a departure this small moves the offsets by less than the encoder
# noise floor of a 4-stance fit (~0.001 deg); a significant but smaller one is not flagged.
MIN_TILT_RAD = np.deg2rad(0.01)
MIN_HEIGHT_M = 2e-4
LEFT_SHARE = 0.5  # the left sole's share of the tilt above which the wedge is named as under it


def coplanarity(M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(c (3,), D (3, 6)): the departure from one plane of inter-foot pose `M` (4, 4) —
    the right sole's normal n in the left sole's frame read as a tilt about x (-n_y) and
    about y (n_x), rad, and the right sole's height (m) — and its Jacobian w.r.t. a
    right perturbation M Exp(xi), xi = (rho, theta)."""
    R, p = M[:3, :3], M[:3, 3]
    c = np.array([-R[1, 2], R[0, 2], p[2]])
    D = np.zeros((3, 6))
    # d(R e_z) = R [theta]x e_z = -R [e_z]x theta; d p = R rho.
    ez_hat = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    dn = -(R @ ez_hat)
    D[0, 3:], D[1, 3:] = -dn[1], dn[0]
    D[2, :3] = R[2]
    return c, D


@dataclass(frozen=True)
class StanceContact:
    """One stance's contact check (SI units; `tilt_rad` the right sole's tilt about x and
    y of the left sole's frame)."""

    recording: str
    tilt_rad: tuple[float, float]  # the departure from one plane at the other stances' offsets
    height_m: float
    fit_tilt_rad: tuple[float, float]  # the same at the offsets fitted to every stance
    fit_height_m: float
    std: tuple[float, float, float]  # of the departure (rad, rad, m), at the noise scale
    chi2: float  # against the declared noise (judged at chi2 / noise_scale)
    dof: int
    p_value: float
    significant: bool
    flagged: bool
    sole: str  # "left", "right" or "unclear": where the wedge sits, when flagged
    noise_scale: float = 1.0  # `shared_misfit`: the variance scale the chi2 was judged at

    def to_dict(self) -> dict:
        return asdict(self)

    def text(self) -> str:
        d, h = np.rad2deg(self.tilt_rad), self.height_m * 1e3
        where = f"under the {self.sole} sole" if self.sole != "unclear" else "under one sole"
        scaled = f", judged at {self.noise_scale:.1f}x the declared noise's variance" if self.noise_scale > 1 else ""
        return (f"stance {self.recording}: the soles were not on one plane: the right sole tilted "
                f"{d[0]:+.3f} deg about x, {d[1]:+.3f} deg about y, and its height {h:+.2f} mm relative to the "
                f"left, at the other stances' offsets (chi2 {self.chi2:.0f} on {self.dof} dof{scaled}, "
                f"p = {self.p_value:.2g}); a wedge, pebble or uneven floor {where}?")


def check_stances(segments: list[dict], sigma_q: float, alpha: float = ALPHA,
                  scale: float = 1.0) -> list[StanceContact]:
    """The check over contact segments, each a dict with: "recording"; "M" (4, 4) its
    mean inter-foot pose at the fit; "G" (N, 6, n) its frames' inter-foot Jacobians
    w.r.t. the n leg joints (`LegMap.n_joints`; mean held); "delta" (n,) the offsets'
    change without its recording; "cov" (n, n) the noise-only covariance of that estimate; "left_tilt" (2,) its mean left-sole tilt
    against the IMU (rad). Segments of one recording are tested together, judged at
    `scale` times the declared noise's variance (`shared_misfit`)."""
    names = list(dict.fromkeys(s["recording"] for s in segments))
    left = {n: np.mean([s["left_tilt"] for s in segments if s["recording"] == n], axis=0) for n in names}
    tests = {}
    for name in names:
        chi2, dof, obs, at_fit, var = 0.0, 0, [], [], []
        for s in (s for s in segments if s["recording"] == name):
            c, D = coplanarity(s["M"])
            G = s["G"]
            n = len(G)
            Gm = G.mean(axis=0)
            sigma_M = sigma_q**2 / n**2 * np.einsum("nij,nkj->ik", G, G)
            Jc = D @ Gm
            cov = D @ sigma_M @ D.T + Jc @ s["cov"] @ Jc.T
            # The departure: c at the offsets without this stance, to first order (on one
            # plane: zero).
            e = c + Jc @ s["delta"]
            chi2 += float(e @ np.linalg.pinv(cov, rcond=1e-12, hermitian=True) @ e)
            dof += 3
            obs.append(e)
            at_fit.append(c)
            var.append(np.diag(cov))
        tests[name] = (chi2, dof, np.mean(obs, axis=0), np.mean(at_fit, axis=0),
                       np.sqrt(np.sum(var, axis=0)) / len(var))
    out = []
    for name, (chi2, dof, e, c, sd) in tests.items():
        p = float(chi2_sf(chi2 / scale, dof))
        significant = p < alpha / len(names)
        tilt = float(np.hypot(e[0], e[1]))
        flagged = significant and (tilt > MIN_TILT_RAD or abs(e[2]) > MIN_HEIGHT_M)
        others = [left[m] for m in names if m != name]
        sole = "unclear"
        if flagged and others and tilt > MIN_TILT_RAD:
            moved = float(np.linalg.norm(left[name] - np.mean(others, axis=0)))
            sole = "left" if moved > LEFT_SHARE * tilt else "right"
        out.append(StanceContact(name, (float(e[0]), float(e[1])), float(e[2]), (float(c[0]), float(c[1])),
                                 float(c[2]), tuple(float(x) * np.sqrt(scale) for x in sd), chi2, dof, p,
                                 bool(significant), bool(flagged), sole, float(scale)))
    return out


def shared_misfit(chi2_per_dof: list[float]) -> float:
    """The noise scale a stance is judged at: the median chi2 per dof of the other
    stances' tests among themselves (the stance set aside; `contact.contact_check`), where
    it exceeds 1, else 1. A misfit every stance shares (a contact floor's soles rock and
    give under a load that changes with the posture: chi2/dof 3.6-17 per stance on clean
    realistic contact sets, `reports/contact_check_realistic`) is outside the declared
    noise but no single stance's departure, so it is taken as noise (a Birge ratio); the
    stance tested is left out of it, as one stance off one plane spoils every other
    stance's prediction."""
    if not chi2_per_dof:
        return 1.0
    return max(1.0, float(np.median(chi2_per_dof)))
