"""A standing controller as real robots run while they are calibrated: centre-of-pressure
regulation with the ankles and shear and twist yielding with the legs, from the ankle
force/torque sensors (issue #38).

Position servos hold the targets the nominal model and the (offset) encoders give; on a
real floor the offsets strain the closed chain and the posture's load moves between heel
and toe, so each sole presses harder on one edge: it sinks unevenly into the floor
(tilts) and, past a point, lifts that edge. At every control tick (500 Hz) the regulator
reads each ankle sensor's wrench, carries it to the sole's origin and frame and takes
the centre of pressure (p_x = -tau_y / f_z, p_y = tau_x / f_z; the sign of the sensor's
convention cancels). What the centre of mass asks of the soles is kept: the part of the
whole robot's centre of pressure off the line between the soles' support centres, which
only the soles' moments can carry (each sole its share). The rest of each sole's offset
from its support centre is the chain's strain, and the ankle yields to it:

    d(rotation of the sole against the shank)/dt = (+dev_y about x, -dev_x about y) / (TIME_CONSTANT_S * lever),

lever = kp / f_z the centre of pressure's shift per rad of ankle target (m/rad), so the
deviation settles with that time constant whatever the robot's gains and weight. The
sole rotation maps to the ankle joints (roles `ankle_pitch`, `ankle_roll`) through their
columns of the sole Jacobian at the reset posture; a leg without ankle roll rolls its
sole with the hip roll instead (which moves it sideways too, as the shear yield below
allows): with pitch only, 20 of 50 five-joint sets rocked a sole past 1 deg. Two simpler
laws fail: centring each sole's own centre of pressure is positive feedback through the
body's lean (quasi-statically the ankle strategy inverts the sign), and keeping the
load-weighted common part leaves the lateral edge loading the load split between the
feet could carry.

The same strain pushes the soles sideways and twists them about their normals: standing
still, the floor's horizontal forces on the two soles cancel (but for the body's small
accelerations, taken out as their mean) and so does nothing ask for a twist, so all of
it is the legs' disagreement, and stiff hip-yaw servos with yaw offsets of opposite sign
twist a sole on the floor beyond friction (+-3.5 deg turned the A3-like robot's right
sole 1.5 deg: tests/sim/test_standing.py). Each leg yields to its sole's shear and twist
as foot damping control does (Kajita et al., 2010):
the sole's twist that relieves the wrench w with the time constant above is the leg's
compliance J K^-1 J' times w over it, of which the slide and the turn about the normal
are asked for, mapped to the leg's joints: on a six-joint leg the smallest joint change
that gives them, on a shorter leg the least squares that also holds tilt and height
(left free there, the knees drifted by 5 deg over a wide squat and rocked a sole).

The same offsets move the pelvis, and with it the centre of mass: while the servo
targets blend from the true posture to the offset ones (the settle of each stance), 3-4
deg of offsets at an ankle or a knee carry it 50-100 mm from where the posture was
planned, which tipped a lunge's robot over a sole's edge (factory offsets plus
`random:3`: 2-3 of 50 sets per built-in robot before this part). Like a real robot's
stabilizer, the legs then move the pelvis horizontally (each leg's least squares,
without the directions a straight knee cannot move) so that the whole robot's centre of
pressure, low-passed (COP_FILTER_S), returns to the plan's centre of mass (`com_ref`:
the posture with the commanded joint angles on the robot's model, which the simulator
sets at each stance's reset), with time constant COM_TIME_CONSTANT_S. The centre of
pressure answers the pelvis's push at once and the other way (the ankles' torque, the
body's acceleration), so the loop is slow: 1 s with a 0.3 s filter oscillated and tipped
the A2-like robot in a squat, a 0.05 s filter at 2 s too; 3 s and 0.2 s held all four
sets that tried them (A2-like seeds 15, 34, 49, A3-like 38). The part acts during the
settle only (`hold_com`) and its correction then stays: acting on through the recorded
postures kept the body moving and cost the zero-noise contact floor 10-14 % (A3-like
0.0213 -> 0.0235 deg, G1 0.0256 -> 0.0292 deg, `legcal-bench contact-floor --cases
'contact zero'`); the straight-leg phase's targets are the true posture, so there it is
off.

The corrections are capped (MAX_CORRECTION_RAD per joint): the cap stops a runaway, not
the work, so it must exceed what the offsets ask of one joint, the sum over the joints
in series about one axis (hip roll and ankle roll: 2 x (1.2 + 3) deg for factory
offsets plus `random:3`); at 5 deg it bound on 2-3 of 50 such sets per robot. Only the
targets move; the encoders read what the joints do, so the recordings carry no trace of
the controller beyond the postures it leads to.
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
MAX_CORRECTION_RAD = np.deg2rad(10.0)  # the regulator's authority per joint
COM_TIME_CONSTANT_S = 3.0  # the centre of mass's return to the plan
COP_FILTER_S = 0.2  # the whole robot's centre of pressure, low-passed for it
LEG_RCOND = 0.02  # a leg's directions weaker than this (relative singular value) are not used
SHEAR_SIGN = -1.0  # the ankle sensors' force and yaw moment as the floor's wrench on the sole


class CopRegulator:
    """Leg target corrections (n,): the ankles keep each sole's centre of pressure where the
    centre of mass asks, the legs yield to each sole's shear and twist and move the pelvis
    to keep the centre of mass where the plan put it (`com_ref`, world x y)."""

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
        # The joints that level each sole: its ankles, and where the leg has no ankle roll
        # the hip roll, the one other joint that rolls the sole (it moves it sideways too,
        # which the shear yield takes up).
        roles = legmap.joint_roles
        self.ankles = [[c for c in cols if roles[c] in ("ankle_pitch", "ankle_roll")
                        or (roles[c] == "hip_roll" and not any(roles[d] == "ankle_roll" for d in cols))]
                       for cols in self.legs]
        self.kin = kin
        # Each sole's support centre (its corners' centroid) in its frame.
        self.centre = [tuple(float(v) for v in np.mean(kin.corners[s], axis=0)) for s in SIDES]
        # The ankles' stiffness: kp / f_z is the centre of pressure's shift per rad of ankle target.
        self.ankle_kp = [float(np.mean(self.kp[cols])) for cols in self.ankles]
        self.u = np.zeros(n)
        self.tick = 0
        # (n, 12): both soles' rotation rates about x, y, both soles' strain wrenches
        # (f_x, f_y, tau_z), the pelvis's horizontal velocity (world) -> the corrections' rates.
        self.drive_map = None
        self.com_ref = (0.0, 0.0)  # the plan's centre of mass on the floor (world x, y)
        self.hold_com = True  # False: the centre of mass is left where the servos put it
        self.cop = (0.0, 0.0)  # the whole robot's centre of pressure, low-passed

    def reset(self, q: np.ndarray, sole_rotations: np.ndarray) -> None:
        """Start from no correction, the centre of pressure at `com_ref`; the maps from sole
        and pelvis motion to joints at angles `q` (n,), the soles' world orientations
        `sole_rotations` (2, 3, 3)."""
        from legcal_bench.robots.kinematics import joint_frame_kinematics

        self.u[:] = 0.0
        self.tick = 0
        self.cop = self.com_ref
        fk = joint_frame_kinematics(self.kin, np.asarray(q, dtype=float)[None])
        n = len(self.u)
        self.drive_map = np.zeros((n, 12))
        rotation_map, shear_map, pelvis_map = self.drive_map[:, :4], self.drive_map[:, 4:10], self.drive_map[:, 10:]
        asked = np.zeros((6, 6))
        asked[[0, 1, 5], [0, 1, 5]] = 1.0
        for k, J in enumerate((fk.J_L[0], fk.J_R[0])):
            cols = self.legs[k]
            local = [cols.index(c) for c in self.ankles[k]]
            # Joint change -> sole rotation about its x and y (rad per rad); inverted in
            # least squares (hip roll and ankle pitch on a leg without an ankle roll).
            rotation_map[self.ankles[k], 2 * k:2 * k + 2] = np.linalg.pinv(J[3:5][:, local])
            # Shear and yaw: the sole's twist that relieves a strain wrench w (sole frame,
            # at its origin) with time constant TIME_CONSTANT_S is the leg's compliance
            # J K^-1 J' times w over it; of that twist only the slide (x, y) and the turn
            # about the normal are asked for, and it maps back to the leg's joints: a
            # six-joint leg by the smallest joint change that gives the three asked rows,
            # a shorter leg in least squares over all six rows (with three rows left
            # free its knees drifted by 5 deg over a wide squat and rocked a sole;
            # holding them on six-joint legs too took the G1's zero-noise contact floor
            # from 0.025 to 0.045 deg), without the directions a straight knee cannot move.
            compliance = (J / self.kp[cols]) @ J.T
            solve = np.linalg.pinv(asked @ J) if J.shape[1] == 6 else np.linalg.pinv(J, rcond=LEG_RCOND) @ asked
            # The sensors' wrench turned into the floor's on the sole (SHEAR_SIGN).
            shear_map[cols, 3 * k:3 * k + 3] = SHEAR_SIGN * solve @ compliance[:, [0, 1, 5]] / TIME_CONSTANT_S
            # The pelvis moving by v (world, horizontal) moves the sole by -v relative to
            # it, its orientation kept: in the sole's frame -R_s' v, in least squares
            # without the directions a straight knee cannot move (the straight-leg
            # phase: a singular value below LEG_RCOND of the largest would ask the knee
            # for tens of degrees per centimetre).
            sole_twist = np.zeros((6, 2))
            sole_twist[:3] = -np.asarray(sole_rotations[k]).T[:, :2]
            pelvis_map[cols] = np.linalg.pinv(J, rcond=LEG_RCOND) @ sole_twist

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
        # The centre of mass back to the plan: the pelvis moves against the low-passed
        # whole robot's centre of pressure's distance from the plan's centre of mass.
        a = self.dt / COP_FILTER_S
        self.cop = cf = (self.cop[0] + a * (tx - self.cop[0]), self.cop[1] + a * (ty - self.cop[1]))
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
        if self.hold_com:
            drive += [(self.com_ref[0] - cf[0]) / COM_TIME_CONSTANT_S, (self.com_ref[1] - cf[1]) / COM_TIME_CONSTANT_S]
        else:
            drive += [0.0, 0.0]
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
