"""An effect plug-in for legcal-bench: gear backlash, a motion-dependent encoder effect.

An encoder on the motor side of a gear reads the link's angle plus half the gear's play,
on the side of the last motion: moving up, the motor leads the link by half the play;
after a reversal it leads it the other way. Static double support moves every leg joint
up and down slowly, so the readings of each joint carry +-b/2 by the direction of its
last motion: a change of the reading law, not of the robot's geometry, and no offset
can absorb it (its sign follows the motion).

The fitting model is one width b per leg joint: q = q_enc + offset - (b / 2) d, d the
direction of the joint's last motion (+1, -1; 0 before any) read from the encoder
angles with a dead band of ten encoder noise standard deviations (`direction`). The
physics for simulation is the same law on the true angles (`BacklashLaw`), added to
the simulated encoders' reading laws, so that the recordings and the truth's clean
readings both go through it.

Installed with `pip install -e docs/examples/backlash_plugin` (the entry point in
pyproject.toml, group `legcal_bench.effects`); docs/effect-plugins.md walks through it.
"""

from dataclasses import dataclass, replace

import numpy as np

from legcal_bench.estimation.modelgap.effects import Effect

DEAD_BAND_RAD = 1e-3  # a reversal is read once the angle comes back this far: 10 encoder noise stds (realistic)
MAX_WIDTH_RAD = np.deg2rad(2.0)  # a play wider than this is a broken gear, not a calibration matter
RESOLVED_RAD = 1e-4  # what the fit can resolve: a width may sit this far below 0 (the bound's margin)


def direction(q: np.ndarray, dead_band: float = DEAD_BAND_RAD) -> np.ndarray:
    """(N, n) the direction of each column's last motion, +1 or -1 (0 before the angle
    first moves `dead_band` from where it started), of angles `q` (N, n) in time order:
    it turns once the angle has come back `dead_band` from its extreme since the last turn."""
    q = np.asarray(q, dtype=float)
    out = np.zeros_like(q)
    d = np.zeros(q.shape[1])
    extreme = q[0].copy()
    for k in range(len(q)):
        up = q[k] > extreme + dead_band
        down = q[k] < extreme - dead_band
        turn = ((d <= 0) & up) | ((d >= 0) & down)
        d = np.where(turn, np.where(up, 1.0, -1.0), d)
        extreme = np.where(turn, q[k], np.where(d > 0, np.maximum(extreme, q[k]),
                                               np.where(d < 0, np.minimum(extreme, q[k]), extreme)))
        out[k] = d
    return out


@dataclass(frozen=True)
class BacklashLaw:
    """The reading law of encoder column `joint` (the leg-map index: an encoder per
    joint; behind a transmission or linkage the encoder's column) behind a play of `width` rad: the true
    angle plus width / 2 on the side of its last motion (`SimSensors.reading_laws`)."""

    joint: int
    width: float

    def __call__(self, e: np.ndarray, time: np.ndarray) -> np.ndarray:
        out = e.copy()
        # the true angle turns at any reversal: a dead band of numerical jitter only
        out[:, self.joint] += 0.5 * self.width * direction(e[:, [self.joint]], 1e-7)[:, 0]
        return out


class Backlash(Effect):
    name = "backlash"
    summary = "gear backlash of each leg joint: the encoder reads half the play ahead, by the last motion's direction"
    remedy = "stances that reverse each joint's motion more often, or a joint moved both ways onto a stop"

    # Fitting model: one width per leg joint, through the joint map.
    def parameters(self, kin):
        return [(f"{name}_width", "rad") for name in kin.legmap.joint_names]

    def bounds(self, kin):
        return [(-RESOLVED_RAD, MAX_WIDTH_RAD)] * kin.legmap.n_joints

    def joint_map(self, kin, seg):
        d = direction(seg.q_enc)  # the frames are in time order, each segment on its own
        n = kin.legmap.n_joints
        A = np.zeros((len(seg.q_enc), n, n))
        A[:, np.arange(n), np.arange(n)] = -0.5 * d  # q = q_enc + offset - (b / 2) d
        return A

    # Physics for simulation: `collect --effect backlash:joint=left_knee,deg=0.2`.
    sim_keys = {"joint": ("text", None), "deg": ("number", None)}

    def simulate(self, values, edit):
        j = edit.joint(values["joint"])  # the joint's leg-map index (drawn if not given)
        width = float(np.deg2rad(values["deg"]))
        if not 0 < width <= MAX_WIDTH_RAD:
            raise edit.error(f"deg={values['deg']}: a backlash is a play in (0, {np.rad2deg(MAX_WIDTH_RAD):g}] deg")
        edit.sensors = replace(edit.sensors, reading_laws=edit.sensors.reading_laws + (BacklashLaw(j, width),))
        return {"joint": edit.legmap.joint_names[j], "width_rad": width}
