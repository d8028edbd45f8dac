"""Servo gains fit for holding static postures, and where they come from.

In order:
  1. the leg map's `servo_gains` (joint -> [kp, kd]), for every joint they name,
     position actuators included (they override the MJCF's gains);
  2. the MJCF's own position-actuator gains, if with them the robot holds stance I's
     nominal posture in weld mode (the hold check, `legcal_bench.sim.hold`, after the
     servos settle with no offsets);
  3. otherwise (or for torque motors the leg map gives no gains) the default:
     kp = k_role * m * g * L, kd = 0.04 s * kp, with m the model's total mass, L its
     leg length and k_role (per m g L) = 6 hip pitch and roll, 3.2 hip yaw and ankle
     pitch, 8 knee, 2 ankle roll: twice the A3-like robot's own servos per m g L
     (1500-2000 N m/rad on 54.5 kg, 0.935 m), which hold every stance within about 2 %
     of the leg length. The MJCF's torque limits stay as they are.
The built-in robots hold with their MJCF gains and keep them.
"""

from __future__ import annotations

import json

import mujoco
import numpy as np

from legcal_bench.robots.kinematics import LegKinematics
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.double_support import DoubleSupportSim
from legcal_bench.sim.hold import HoldReport
from legcal_bench.sim.scene import ServoGains, build_scene
from legcal_bench.sim.sensors import sim_sensors

GRAVITY = 9.81
DEFAULT_KP_PER_MGL = {"hip_pitch": 6.0, "hip_roll": 6.0, "hip_yaw": 3.2, "knee": 8.0, "ankle_pitch": 3.2,
                      "ankle_roll": 2.0}
DEFAULT_KD_S = 0.04
PROBE_SETTLE_S = 2.0
PROBE_HOLD_S = 0.5


def default_gains(legmap: LegMap, kin: LegKinematics | None = None,
                  mass: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The documented default (kp, kd) for this robot's leg joints, by role (`mass`: the
    model's total mass if already known)."""
    kin = LegKinematics(legmap) if kin is None else kin
    mgl = (total_mass(legmap) if mass is None else mass) * GRAVITY * kin.dims.leg_length
    kp = np.array([DEFAULT_KP_PER_MGL[r] * mgl for r in legmap.joint_roles])
    return kp, DEFAULT_KD_S * kp


def total_mass(legmap: LegMap) -> float:
    return float(mujoco.MjModel.from_xml_path(str(legmap.mjcf)).body_mass.sum())


def servo_gains(legmap: LegMap) -> ServoGains:
    """The gains static collection uses on this robot (see the module docstring); the
    hold probe runs once per robot and process."""
    key = json.dumps(legmap.to_dict(), sort_keys=True, default=str)
    if key not in _CACHE:
        _CACHE[key] = _choose(legmap)
    return _CACHE[key]


_CACHE: dict[str, ServoGains] = {}


def _choose(legmap: LegMap) -> ServoGains:
    from legcal_bench.protocol.stances import STANCES, fit_stance, settled_placement

    sc = build_scene(legmap, "weld")
    kp, kd, source = np.array(sc.servo_kp), np.array(sc.servo_kd), list(sc.servo_source)
    kin = LegKinematics(legmap)
    dkp, dkd = default_gains(legmap, kin, mass=float(sc.model.body_mass.sum()))  # the scene adds no mass
    notes = []
    if "none" in source:
        notes.append("torque motors without servo_gains in the leg map use the default k_role * m g L")
    for i in [i for i, s in enumerate(source) if s == "none"]:
        kp[i], kd[i], source[i] = dkp[i], dkd[i], "default"
    if "MJCF" in source:
        probe = DoubleSupportSim(legmap, "weld", np.zeros(legmap.n_joints), sim_sensors("zero"),
                                 settle_s=PROBE_SETTLE_S, servo_gains=ServoGains(tuple(kp), tuple(kd), tuple(source)))
        pl = settled_placement(fit_stance(STANCES["I"], probe.true_kin).stance, probe.true_kin)
        probe.reset(pl.left, pl.right, pl.nominal)
        n = int(round(PROBE_HOLD_S * probe.rate_hz))
        _, truth = probe.run(np.repeat(pl.nominal[None], n, axis=0), np.random.default_rng(0))
        report = HoldReport.from_truth(truth, kin.dims.leg_length)
        if report.held:
            notes.append("the MJCF's position-actuator gains hold stance I")
        else:
            notes.append("the MJCF's gains do not hold stance I (" + "; ".join(report.failures())
                         + "): the default k_role * m g L replaces them")
            for i in [i for i, s in enumerate(source) if s == "MJCF"]:
                kp[i], kd[i], source[i] = dkp[i], dkd[i], "default"
    if all(s == "leg map" for s in source):
        notes.append("all from the leg map's servo_gains")
    return ServoGains(tuple(float(v) for v in kp), tuple(float(v) for v in kd), tuple(source), "; ".join(notes))
