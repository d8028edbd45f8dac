"""A standing controller as real robots run while they are calibrated: centre-of-pressure
regulation with the ankles and shear and twist yielding with the legs, from the ankle
force/torque sensors (issue #38).

Position servos hold the targets the nominal model and the (offset) encoders give; on a
real floor the offsets strain the closed chain and the posture's load moves between heel
and toe, so each sole presses harder on one edge: it sinks unevenly into the floor
(tilts) and, past a point, lifts that edge. At every control tick (500 Hz) the regulator
reads each ankle sensor's wrench, carries it to the sole's origin and frame and takes the
centre of pressure (p_x = -tau_y / f_z, p_y = tau_x / f_z; the sign of the sensor's
convention cancels). What the centre of mass asks of the soles is kept: the part of the
whole robot's centre of pressure off the line between the soles' support centres, which
only the soles' moments can carry (each sole its share). The rest of each sole's offset
from its support centre is the chain's strain, and the ankle yields to it:

    d(rotation of the sole against the shank)/dt = (+dev_y about x, -dev_x about y) / (TIME_CONSTANT_S * lever),

lever = kp / f_z the centre of pressure's shift per rad of ankle target (m/rad), so the
deviation settles with that time constant whatever the robot's gains and weight. The
sole rotation maps to the ankle joints (roles `ankle_pitch`, `ankle_roll`) through their
columns of the sole Jacobian at the reset posture; a leg without ankle roll regulates
pitch only. Two simpler laws fail: centring each sole's own centre of pressure is
positive feedback through the body's lean (quasi-statically the ankle strategy inverts
the sign), and keeping the load-weighted common part leaves the lateral edge loading the
load split between the feet could carry.

The same strain pushes the soles sideways and twists them about their normals: standing
still, the floor's horizontal forces on the two soles cancel (but for the body's small
accelerations, taken out as their mean) and so does nothing ask for a twist, so all of
it is the legs' disagreement, and stiff hip-yaw servos with yaw offsets of opposite sign
twist a sole on the floor beyond friction (+-3.5 deg turned the A3-like robot's
right sole 1.5 deg: tests/sim/test_standing.py). Each leg
yields to its sole's shear and twist as foot damping control does (Kajita et al., 2010):
the sole's twist that relieves the wrench w with the time constant above is the leg's
compliance J K^-1 J' times w over it, of which the slide and the turn about the normal
are asked for (tilt and height held), mapped to the leg's joints in least squares.

The corrections are capped (MAX_CORRECTION_RAD per joint). Only the targets move; the
encoders read what the joints do, so the recordings carry no trace of the controller
beyond the postures it leads to.
"""

from __future__ import annotations

import mujoco
import numpy as np

from legcal_bench.robots.legmap import SIDES

STANDING_CONTROLLERS = ("none", "cop")
TIME_CONSTANT_S = 0.1  # the centre of pressure's settling time constant
CONTROL_PERIOD_S = 0.002  # 500 Hz, as real standing controllers run
MIN_LOAD_FRACTION = 0.05  # a sole carrying less of the robot's weight is not regulated
MAX_CORRECTION_RAD = np.deg2rad(5.0)  # the regulator's authority per joint
SHEAR_SIGN = -1.0  # the ankle sensors' force and yaw moment as the floor's wrench on the sole


class CopRegulator:
    """Leg target corrections (n,): the ankles keep each sole's centre of pressure where the
    centre of mass asks, the legs yield to each sole's shear and twist."""

    def __init__(self, model: mujoco.MjModel, scene, kin, physics_dt: float):
        legmap = kin.legmap
        self.model = model
        self.every = max(1, int(round(CONTROL_PERIOD_S / physics_dt)))
        self.dt = self.every * physics_dt
        self.kp = np.asarray(scene.servo_kp, dtype=float)
        self.weight = float(sum(model.body_mass)) * 9.81
        adr = scene.sensor_adr
        self.force_adr = [np.arange(adr[f"{s}_force"], adr[f"{s}_force"] + 3) for s in SIDES]
        self.torque_adr = [np.arange(adr[f"{s}_torque"], adr[f"{s}_torque"] + 3) for s in SIDES]
        self.ft_site = [int(model.sensor_objid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, f"legcal_{s}_force")])
                        for s in SIDES]  # the force sensor's site
        self.sole_site = [scene.sole_site[s] for s in SIDES]
        self.ankles = []
        for side in SIDES:
            cols = list(range(legmap.n_joints))[legmap.leg_slice(side)]
            self.ankles.append([c for c in cols if legmap.joint_roles[c] in ("ankle_pitch", "ankle_roll")])
        self.kin = kin
        # Each sole's support centre (its corners' centroid) in its frame.
        self.centre = [np.mean(kin.corners[s], axis=0) for s in SIDES]
        self.legs = [list(range(legmap.n_joints))[legmap.leg_slice(s)] for s in SIDES]
        self.u = np.zeros(legmap.n_joints)
        self.tick = 0
        self.maps = None
        self.shear_maps = None

    def reset(self, q: np.ndarray) -> None:
        """Start from no correction; the ankle-to-sole-rotation maps at angles `q` (n,)."""
        from legcal_bench.robots.kinematics import frame_kinematics

        self.u[:] = 0.0
        self.tick = 0
        self._wrench = [None, None]
        fk = frame_kinematics(self.kin, np.asarray(q, dtype=float)[None])
        self.maps = []
        for k, (side, J) in enumerate(zip(SIDES, (fk.J_L[0], fk.J_R[0]))):
            cols = list(range(self.kin.legmap.n_joints))[self.kin.legmap.leg_slice(side)]
            local = [cols.index(c) for c in self.ankles[k]]
            # Joint change -> sole rotation about its x and y (rad per rad); inverted in
            # least squares (pitch only without an ankle roll).
            self.maps.append(np.linalg.pinv(J[3:5][:, local]))
        # Shear and yaw: the sole's twist that relieves a strain wrench w (sole frame, at
        # its origin) with time constant TIME_CONSTANT_S is the leg's compliance J K^-1 J'
        # times w over it; of that twist only the slide (x, y) and the turn about the
        # normal are asked for, the rest held at zero, and it maps back to the leg's
        # joints in least squares (a five-joint leg does what it can).
        self.shear_maps = []
        for side, J in zip(SIDES, (fk.J_L[0], fk.J_R[0])):
            cols = self.legs[SIDES.index(side)]
            compliance = (J / self.kp[cols]) @ J.T
            asked = np.zeros((6, 6))
            asked[[0, 1, 5], [0, 1, 5]] = 1.0
            self.shear_maps.append(np.linalg.pinv(asked @ J) @ asked @ compliance[:, [0, 1, 5]])

    def centre_of_pressure(self, data: mujoco.MjData, k: int) -> tuple[np.ndarray, np.ndarray, float] | None:
        """(sole `k`'s centre of pressure and its support centre, both in the world (3,),
        its normal force) from its ankle sensor; None if it carries too little load to say."""
        R_f = data.site_xmat[self.ft_site[k]].reshape(3, 3)
        R_s = data.site_xmat[self.sole_site[k]].reshape(3, 3)
        o = data.site_xpos[self.sole_site[k]]
        f = R_f @ data.sensordata[self.force_adr[k]]
        tau = R_f @ data.sensordata[self.torque_adr[k]]
        r = data.site_xpos[self.ft_site[k]] - o
        # r x f written out: np.cross costs more than the rest of the update at 500 Hz.
        tau = tau + np.array([r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0]])
        f_s, tau_s = R_s.T @ f, R_s.T @ tau
        if abs(f_s[2]) < MIN_LOAD_FRACTION * self.weight:
            return None
        self._wrench[k] = f, tau_s[2]
        return o + R_s @ np.array([-tau_s[1] / f_s[2], tau_s[0] / f_s[2], 0.0]), o + R_s @ self.centre[k], abs(f_s[2])

    def step(self, data: mujoco.MjData) -> np.ndarray:
        """Called once per physics step; returns the ankle target corrections (n,)."""
        self.tick += 1
        if self.tick % self.every:
            return self.u
        got = [self.centre_of_pressure(data, k) for k in range(2)]
        if any(g is None for g in got):
            return self.u
        # What the centre of mass asks of the soles stays: the whole robot's centre of
        # pressure, whose part off the line between the soles' centres only the soles'
        # moments can carry (each sole its share); along that line the load split carries
        # it. The rest of each sole's moment is what the closed chain's strain puts on it,
        # and the ankles yield to it.
        (p1, c1, f1), (p2, c2, f2) = got
        total = (f1 * p1 + f2 * p2) / (f1 + f2)
        e = (c2 - c1)[:2] / np.linalg.norm((c2 - c1)[:2])
        d = (total - c1)[:2]
        off_line = np.r_[d - (d @ e) * e, 0.0]
        for k, (p, c, fz) in enumerate(got):
            R_s = data.site_xmat[self.sole_site[k]].reshape(3, 3)
            dev = (R_s.T @ (p - c - off_line))[:2]  # in the sole's frame
            cols = self.ankles[k]
            lever = np.mean(self.kp[cols]) / fz  # m of centre of pressure per rad of ankle target
            rate = np.array([dev[1], -dev[0]]) / (TIME_CONSTANT_S * lever)  # yield: sole rotation about x, y (rad/s)
            self.u[cols] = np.clip(self.u[cols] + self.dt * (self.maps[k] @ rate), -MAX_CORRECTION_RAD,
                                   MAX_CORRECTION_RAD)
        # Shear and yaw: standing still, the floor pushes the soles sideways and twists
        # them only because the legs disagree (the two soles' horizontal forces cancel
        # but for the body's small accelerations, taken out as their mean), and each
        # leg yields to what its sole feels (foot damping control).
        (f1, t1), (f2, t2) = self._wrench
        mean = (f1 + f2) / 2
        for k, (f, tz) in enumerate(((f1, t1), (f2, t2))):
            R_s = data.site_xmat[self.sole_site[k]].reshape(3, 3)
            shear = R_s.T @ np.r_[(f - mean)[:2], 0.0]
            w = SHEAR_SIGN * np.array([shear[0], shear[1], tz])
            cols = self.legs[k]
            self.u[cols] = np.clip(self.u[cols] + (self.dt / TIME_CONSTANT_S) * (self.shear_maps[k] @ w),
                                   -MAX_CORRECTION_RAD, MAX_CORRECTION_RAD)
        return self.u
