"""Whether to apply a calibration result: each warning classed by what it means for the
offsets, and the verdict the classes add up to.

A check that warns returns a `Finding`: its text (a `str`, so every place that shows,
joins or saves warnings keeps working) and its meaning for the offsets:

- `HARMLESS`: nothing the offsets depend on (a declaration the data corrected, frames
  the contact filter removed);
- `LIMITS`: some combinations are less certain than the rest, and the warning states
  which and by how much (the pitch sums against the IMU's tilt, a combination the data
  do not determine); the others stand;
- `DOUBTS`: the result may be off; look before applying it (a stance whose contact
  failed, a residual the declared noise does not explain, a warning no check of the
  framework classed, such as a plug-in's own);
- `INVALIDATES`: evidence against the result (offsets at the solver's bound, channels
  exchanged or read with the opposite sign, an IMU that moves against both soles alike
  or whose vertical does not fit the posture, soles that are not on one plane).

The verdict: `DO_NOT_APPLY` when any finding invalidates the result, `REVIEW` when any
doubts it, else `APPLY` (limits stated). Standard library only.
"""

from __future__ import annotations

HARMLESS, LIMITS, DOUBTS, INVALIDATES = "harmless", "limits", "doubts", "invalidates"
MEANINGS = (HARMLESS, LIMITS, DOUBTS, INVALIDATES)  # in rising order of consequence
APPLY, REVIEW, DO_NOT_APPLY = "apply", "review", "do-not-apply"
VERDICTS = (APPLY, REVIEW, DO_NOT_APPLY)
_VERDICT_OF = {HARMLESS: APPLY, LIMITS: APPLY, DOUBTS: REVIEW, INVALIDATES: DO_NOT_APPLY}
# A warning without a class (a plug-in's own, or a result written before verdicts): doubts.
UNCLASSED = DOUBTS


class Finding(str):
    """A warning's text with its meaning for the offsets (`meaning`, one of `MEANINGS`)."""

    meaning: str

    def __new__(cls, text: str, meaning: str) -> "Finding":
        if meaning not in MEANINGS:
            raise ValueError(f"meaning {meaning!r}: one of {', '.join(MEANINGS)}")
        self = super().__new__(cls, text)
        self.meaning = meaning
        return self

    def __reduce__(self):  # across worker processes with its meaning
        return (Finding, (str(self), self.meaning))


def classed(texts: list[str], meaning: str) -> list[Finding]:
    """Each warning text of one check, with the check's meaning."""
    return [Finding(t, meaning) for t in texts]


def meaning_of(warning: str) -> str:
    return getattr(warning, "meaning", UNCLASSED)


def judge(warnings: list[str]) -> dict:
    """The verdict of a result's warnings: {"verdict", "reasons": [{"meaning", "text"}],
    "counts": per meaning}; reasons ordered most serious first."""
    reasons = [{"meaning": meaning_of(w), "text": str(w)} for w in warnings]
    reasons.sort(key=lambda r: -MEANINGS.index(r["meaning"]))
    worst = reasons[0]["meaning"] if reasons else HARMLESS
    return {"verdict": _VERDICT_OF[worst], "reasons": reasons,
            "counts": {m: sum(r["meaning"] == m for r in reasons) for m in MEANINGS}}


def check_verdict(v: dict, where: str) -> None:
    """A stored verdict's shape (a result file read back); ValueError naming `where`."""
    if not isinstance(v, dict) or v.get("verdict") not in VERDICTS or not isinstance(v.get("reasons"), list):
        raise ValueError(f"{where}: field 'verdict' must be an object with 'verdict' one of {', '.join(VERDICTS)} "
                         "and a list 'reasons'")
    for r in v["reasons"]:
        if not isinstance(r, dict) or r.get("meaning") not in MEANINGS or not isinstance(r.get("text"), str):
            raise ValueError(f"{where}: each of verdict.reasons must be {{'meaning': one of {', '.join(MEANINGS)}, "
                             "'text': the warning}")


def headline(v: dict) -> str:
    """One line: the verdict and why, for the first line of a summary."""
    n = v["counts"]
    if v["verdict"] == DO_NOT_APPLY:
        why = (f"{n[INVALIDATES]} finding(s) invalidate the result; first: "
               f"{_short(next(r['text'] for r in v['reasons'] if r['meaning'] == INVALIDATES))}")
    elif v["verdict"] == REVIEW:
        why = (f"{n[DOUBTS]} finding(s) put it in doubt; look at them before applying; first: "
               f"{_short(next(r['text'] for r in v['reasons'] if r['meaning'] == DOUBTS))}")
    elif n[LIMITS]:
        why = f"{n[LIMITS]} warning(s) state combinations known less well"
    else:
        why = "no finding against it"
    return f"verdict: {v['verdict']} ({why})"


def _short(text: str, n: int = 160) -> str:
    return text if len(text) <= n else text[:n - 3] + "..."
