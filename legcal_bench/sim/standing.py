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
twist a sole on the floor beyond friction (+-3.5 deg turned the A3-like robot's right
sole 1.5 deg: tests/sim/test_standing.py). Each leg yields to its sole's shear and twist
as foot damping control does (Kajita et al., 2010):
the sole's twist that relieves the wrench w with the time constant above is the leg's
compliance J K^-1 J' times w over it, of which the slide and the turn about the normal
are asked for (tilt and height held), mapped to the leg's joints in least squares.

The corrections are capped (MAX_CORRECTION_RAD per joint). Only the targets move; the
encoders read what the joints do, so the recordings carry no trace of the controller
beyond the postures it leads to.
"""

from __future__ import annotations

import math

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
        self.every = max(1, int(round(CONTROL_PERIOD_S / physics_dt)))
        self.dt = self.every * physics_dt
        self.kp = np.asarray(scene.servo_kp, dtype=float)
        self.min_load = MIN_LOAD_FRACTION * float(sum(model.body_mass)) * 9.81
        adr = scene.sensor_adr  # each sensor's first value; force and torque are 3 each
        self.force_adr = [adr[f"{s}_force"] for s in SIDES]
        self.torque_adr = [adr[f"{s}_torque"] for s in SIDES]
        self.ft_site = np.array([int(model.sensor_objid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR,
                                                                          f"legcal_{s}_force")]) for s in SIDES])
        self.sole_site = np.array([scene.sole_site[s] for s in SIDES])
        n = legmap.n_joints
        self.legs = [list(range(n))[legmap.leg_slice(s)] for s in SIDES]
        self.ankles = [[c for c in cols if legmap.joint_roles[c] in ("ankle_pitch", "ankle_roll")] for cols in self.legs]
        self.kin = kin
        # Each sole's support centre (its corners' centroid) in its frame.
        self.centre = [tuple(float(v) for v in np.mean(kin.corners[s], axis=0)) for s in SIDES]
        # The ankles' stiffness: kp / f_z is the centre of pressure's shift per rad of ankle target.
        self.ankle_kp = [float(np.mean(self.kp[cols])) for cols in self.ankles]
        self.u = np.zeros(n)
        self.tick = 0
        # (n, 10): both soles' rotation rates about x, y, then both soles' strain wrenches
        # (f_x, f_y, tau_z) -> the corrections' rates.
        self.drive_map = None

    def reset(self, q: np.ndarray) -> None:
        """Start from no correction; the maps from sole motion to joints at angles `q` (n,)."""
        from legcal_bench.robots.kinematics import frame_kinematics

        self.u[:] = 0.0
        self.tick = 0
        fk = frame_kinematics(self.kin, np.asarray(q, dtype=float)[None])
        n = len(self.u)
        self.drive_map = np.zeros((n, 10))
        rotation_map, shear_map = self.drive_map[:, :4], self.drive_map[:, 4:]
        asked = np.zeros((6, 6))
        asked[[0, 1, 5], [0, 1, 5]] = 1.0
        for k, J in enumerate((fk.J_L[0], fk.J_R[0])):
            cols = self.legs[k]
            local = [cols.index(c) for c in self.ankles[k]]
            # Joint change -> sole rotation about its x and y (rad per rad); inverted in
            # least squares (pitch only without an ankle roll).
            rotation_map[self.ankles[k], 2 * k:2 * k + 2] = np.linalg.pinv(J[3:5][:, local])
            # Shear and yaw: the sole's twist that relieves a strain wrench w (sole frame,
            # at its origin) with time constant TIME_CONSTANT_S is the leg's compliance
            # J K^-1 J' times w over it; of that twist only the slide (x, y) and the turn
            # about the normal are asked for, the rest held at zero, and it maps back to
            # the leg's joints in least squares (a five-joint leg does what it can).
            compliance = (J / self.kp[cols]) @ J.T
            # The sensors' wrench turned into the floor's on the sole (SHEAR_SIGN).
            shear_map[cols, 3 * k:3 * k + 3] = SHEAR_SIGN * (
                np.linalg.pinv(asked @ J) @ asked @ compliance[:, [0, 1, 5]] / TIME_CONSTANT_S)

    def step(self, data: mujoco.MjData) -> np.ndarray:
        """Called once per physics step; returns the target corrections (n,)."""
        self.tick += 1
        if self.tick % self.every == 0:
            self.update(data)
        return self.u

    def update(self, data: mujoco.MjData) -> None:
        """One control tick: both soles' wrenches from the ankle sensors, the corrections moved.
        Written in Python floats: at 500 Hz, numpy's per-call cost on 3-vectors was twice
        the physics' (`legcal-bench bench-speed --groups collection`, its contact case)."""
        xmat, xpos, sd = data.site_xmat, data.site_xpos, data.sensordata
        soles = []
        for k in (0, 1):
            Rf, Rs = xmat[self.ft_site[k]].tolist(), xmat[self.sole_site[k]].tolist()
            o, at = xpos[self.sole_site[k]].tolist(), xpos[self.ft_site[k]].tolist()
            a, b = self.force_adr[k], self.torque_adr[k]
            f, tau = _mv(Rf, sd[a:a + 3].tolist()), _mv(Rf, sd[b:b + 3].tolist())  # world frame
            r = (at[0] - o[0], at[1] - o[1], at[2] - o[2])  # carried from the sensor to the sole's origin
            tau = (tau[0] + r[1] * f[2] - r[2] * f[1], tau[1] + r[2] * f[0] - r[0] * f[2],
                   tau[2] + r[0] * f[1] - r[1] * f[0])
            f_s, tau_s = _mtv(Rs, f), _mtv(Rs, tau)  # the sole's frame
            if abs(f_s[2]) < self.min_load:  # a sole too lightly loaded to say
                return
            cx, cy, cz = self.centre[k]
            # The centre of pressure relative to the support centre, in the sole's frame.
            cop = (-tau_s[1] / f_s[2] - cx, tau_s[0] / f_s[2] - cy, -cz)
            c = _mv(Rs, self.centre[k])
            c = (o[0] + c[0], o[1] + c[1], o[2] + c[2])  # the support centre in the world
            p = _mv(Rs, cop)
            soles.append((Rs, f, tau_s, abs(f_s[2]), cop, c, (c[0] + p[0], c[1] + p[1])))
        # What the centre of mass asks of the soles stays: the whole robot's centre of
        # pressure, whose part off the line between the soles' centres only the soles'
        # moments can carry (each sole its share); along that line the load split carries
        # it. The rest of each sole's moment is what the closed chain's strain puts on it,
        # and the ankles yield to it.
        (_, _, _, l1, _, c1, p1), (_, _, _, l2, _, c2, p2) = soles
        tx, ty = (l1 * p1[0] + l2 * p2[0]) / (l1 + l2), (l1 * p1[1] + l2 * p2[1]) / (l1 + l2)
        ex, ey = c2[0] - c1[0], c2[1] - c1[1]
        norm = math.hypot(ex, ey)
        ex, ey = ex / norm, ey / norm
        dx, dy = tx - c1[0], ty - c1[1]
        along = dx * ex + dy * ey
        off = (dx - along * ex, dy - along * ey, 0.0)
        mx, my = (soles[0][1][0] + soles[1][1][0]) / 2, (soles[0][1][1] + soles[1][1][1]) / 2
        drive = []
        for k, (Rs, f, tau_s, load, cop, _, _) in enumerate(soles):
            o_s = _mtv(Rs, off)
            dev_x, dev_y = cop[0] - o_s[0], cop[1] - o_s[1]  # in the sole's frame
            # Yield: sole rotation about x, y (rad/s) = the strain moment over the ankles' stiffness.
            gain = load / (TIME_CONSTANT_S * self.ankle_kp[k])
            drive += [dev_y * gain, -dev_x * gain]
        for k, (Rs, f, tau_s, _, _, _, _) in enumerate(soles):
            # Shear and yaw: standing still, the floor pushes the soles sideways and twists
            # them only because the legs disagree (the two soles' horizontal forces cancel
            # but for the body's small accelerations, taken out as their mean), and each
            # leg yields to what its sole feels (foot damping control).
            shear = _mtv(Rs, (f[0] - mx, f[1] - my, 0.0))
            drive += [shear[0], shear[1], tau_s[2]]
        u = self.u + self.dt * (self.drive_map @ np.array(drive))
        np.clip(u, -MAX_CORRECTION_RAD, MAX_CORRECTION_RAD, out=self.u)


def _mv(R: list, v) -> tuple:
    """R v for a row-major 3x3 list R (9,) and a 3-vector."""
    return (R[0] * v[0] + R[1] * v[1] + R[2] * v[2], R[3] * v[0] + R[4] * v[1] + R[5] * v[2],
            R[6] * v[0] + R[7] * v[1] + R[8] * v[2])


def _mtv(R: list, v) -> tuple:
    """R' v for a row-major 3x3 list R (9,) and a 3-vector."""
    return (R[0] * v[0] + R[3] * v[1] + R[6] * v[2], R[1] * v[0] + R[4] * v[1] + R[7] * v[2],
            R[2] * v[0] + R[5] * v[1] + R[8] * v[2])
