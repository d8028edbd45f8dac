"""What a model-gap effect is confounded with, computed for the robot and data at hand
(issue #16): principal angles between the column spaces of the noise-whitened data
Jacobian.

For an effect block E (columns J_E) and the offsets (J_q): the cosines of the principal
angles between span(J_E) and span(J_q); a cosine of 1 means some combination of the
effect's parameters moves the residuals exactly as some combination of offsets does, so
no amount of these data separates them. Per parameter, the sine of the angle between
its column and the span of every other column (offsets and the other effects' in the
fit) is how much of its signal is its own: 1/sine inflates its standard deviation over
a fit of it alone. A parameter whose sine is below `CONFOUND_SINE` is not estimable
from these data and is held at zero in the fit (named in the report).
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import orth, subspace_angles

CONFOUND_SINE = 1e-3  # a column this close to the span of the others is not estimable
CLOSE_COSINE = 0.7  # above this, two effects (or an effect and the offsets) are reported as close


def _sine_to_span(col: np.ndarray, others: np.ndarray, Q: np.ndarray | None = None) -> float:
    """The sine of `col`'s angle to the span of `others` (Q: their `orth`, if in hand)."""
    n = np.linalg.norm(col)
    if n == 0:
        return 0.0
    if others.shape[1] == 0:
        return 1.0
    Q = orth(others) if Q is None else Q
    return float(np.linalg.norm(col - Q @ (Q.T @ col)) / n)


def describe_offsets(a: np.ndarray, joint_names: list[str], keep: float = 0.25) -> str:
    """'+0.71 left_hip_pitch_joint +0.71 right_hip_pitch_joint': an offsets direction's
    large entries, sign fixed so the largest is positive."""
    a = a / np.abs(a).max()
    a = a if a[np.argmax(np.abs(a))] > 0 else -a
    a = a / np.linalg.norm(a)
    idx = [i for i in np.argsort(-np.abs(a)) if abs(a[i]) >= keep * np.abs(a).max()]
    return " ".join(f"{a[i]:+.2f} {joint_names[i]}" for i in idx)


def confound_report(J: np.ndarray, model, joint_names: list[str]) -> dict:
    """Per effect of `model` (an `EffectModel`), from the whitened data Jacobian J
    (rows, n): principal-angle cosines against the offsets and against each other
    effect, the offsets combination its most confounded direction mimics, and each
    parameter's own-signal sine; plus the parameters not estimable (`held`)."""
    Jq = J[:, :model.n_offsets]
    out: dict = {"effects": {}, "held": []}
    Qq = orth(Jq)
    beyond = J - Qq @ (Qq.T @ J)  # every column with the offsets' span removed
    norms = np.linalg.norm(beyond, axis=0)
    for e in model.effects:
        sl = model.slices[e.name]
        JE = J[:, sl]
        angles = subspace_angles(JE, Jq)
        cos = np.cos(angles)
        # The effect direction closest to the offsets' span and the offsets it mimics.
        QE = orth(JE)
        U, _, Vt = np.linalg.svd(Qq.T @ QE)
        mimic = np.linalg.lstsq(Jq, Qq @ U[:, 0], rcond=None)[0]
        b = np.linalg.lstsq(JE, QE @ Vt[0], rcond=None)[0]
        names = [model.names[i] for i in range(sl.start, sl.stop)]
        params = {}
        for i in range(sl.start, sl.stop):
            rest = np.delete(J, i, axis=1)
            params[model.names[i]] = {"sine_to_offsets": _sine_to_span(J[:, i], Jq, Qq),
                                      "sine_to_all_others": _sine_to_span(J[:, i], rest)}
            # The closest other parameter once the offsets absorbed what they can (what a fit confuses it with).
            others = [j for j in range(model.n_offsets, J.shape[1]) if j != i]
            if others:
                c = np.abs(beyond[:, others].T @ beyond[:, i]) / np.maximum(
                    norms[others] * norms[i], np.finfo(float).tiny)
                j = others[int(np.argmax(c))]
                params[model.names[i]]["closest_beyond_offsets"] = {"parameter": model.names[j],
                                                                    "cosine": float(c.max())}
        vs = {}
        for o in model.effects:
            if o.name != e.name:
                vs[o.name] = float(np.cos(subspace_angles(JE, J[:, model.slices[o.name]])).max())
        entry = {"cosines_to_offsets": cos.tolist(), "max_cosine_to_offsets": float(cos.max()),
                 "confounded_with_offsets": bool(np.sqrt(max(0.0, 1 - cos.max() ** 2)) < CONFOUND_SINE),
                 "closest_direction": describe_offsets(b, names) if np.abs(b).max() > 0 else "",
                 "mimics_offsets": describe_offsets(mimic, joint_names) if np.abs(mimic).max() > 0 else "",
                 "max_cosine_to_effects": vs, "parameters": params}
        out["effects"][e.name] = entry
        out["held"] += [n for n, p in params.items() if p["sine_to_all_others"] < CONFOUND_SINE]
    return out


def confound_lines(report: dict) -> list[str]:
    """Plain sentences for the report's findings (warnings and the CLI)."""
    lines = []
    for name, e in report["effects"].items():
        c = e["max_cosine_to_offsets"]
        if e["confounded_with_offsets"]:
            lines.append(f"{name}: {e['closest_direction']} is confounded with the offsets ({e['mimics_offsets']}): "
                         f"principal-angle cosine {c:.6f}; these data cannot tell them apart (held at zero)")
        elif c > CLOSE_COSINE:
            lines.append(f"{name}: {e['closest_direction']} is close to offsets {e['mimics_offsets']} (cosine "
                         f"{c:.3f}): estimable, with its standard deviation inflated")
        for other, co in e["max_cosine_to_effects"].items():
            if co > CLOSE_COSINE and name < other:
                lines.append(f"{name} and {other} are close (principal-angle cosine {co:.3f})")
    held = [h for h in report["held"] if not any(h.startswith(f"{n}.") and e["confounded_with_offsets"]
                                                  for n, e in report["effects"].items())]
    if held:
        lines.append(f"not estimable from these data (held at zero): {', '.join(held)}")
    return lines
