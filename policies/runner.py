"""Run a policy from its spec on a robot: joints mapped by name onto the leg map,
observations composed from the spec's terms, actions turned into joint targets.

`PolicyRunner(spec, legmap)` is the policy as the robot's software runs it: `reset()`,
then each control step `act(obs, info, time)` -> the joint targets, one per leg joint, in leg-map order
(encoder space; the env's servos track them on the corrected encoders).
`walking_config()` gives the env the spec's gains, default pose and rates.
"""

from __future__ import annotations

import numpy as np

from legcal_bench.errors import ConfigError
from legcal_bench.policies.models import load_model
from legcal_bench.policies.observation import ObsContext, bind, build_observation, observation_size
from legcal_bench.policies.spec import PolicySpec, load_policy_spec
from legcal_bench.robots.legmap import LegMap
from legcal_bench.sim.walking import WalkingConfig


def extra_joints(spec: PolicySpec, legmap: LegMap) -> list[str]:
    """A whole-body policy's joints beyond the leg map's leg joints (in the policy's
    order), then the joints its spec holds: the body vector's entries after the legs."""
    return [j for j in spec.joints if j not in legmap.joint_names] + [h.joint for h in spec.hold]


def joint_index(spec: PolicySpec, legmap: LegMap) -> np.ndarray:
    """Column of each of the policy's joints in the body vector (the leg map's leg
    joints, then `extra_joints`); ConfigError if the policy leaves a leg joint undriven."""
    undriven = [j for j in legmap.joint_names if j not in spec.joints]
    if undriven:
        others = [j for j in spec.joints if j not in legmap.joint_names]
        raise ConfigError(f"policy spec {spec.path}: its joints must include the leg map's {legmap.n_joints} leg "
                          f"joints ({legmap.name}), by name, in any order (a whole-body policy lists its other "
                          "joints too: waist, arms); "
                          + (f"not in the leg map: {others}; " if others else "")
                          + f"leg joints the policy does not drive: {undriven}")
    body = list(legmap.joint_names) + extra_joints(spec, legmap)
    return np.array([body.index(j) for j in spec.joints])


class PolicyRunner:
    """`model`: a network already in memory (obs -> action), e.g. a policy being
    trained; by default the spec's file is loaded."""

    def __init__(self, spec: PolicySpec | str, legmap: LegMap, model=None):
        self.spec = spec if isinstance(spec, PolicySpec) else load_policy_spec(spec)
        self.legmap = legmap
        self.index = joint_index(self.spec, legmap)
        self.terms = bind(self.spec)
        self.n_obs = observation_size(self.spec)
        self.model = model if model is not None else load_model(
            self.spec.model_file, self.spec.model_format, self.n_obs, len(self.spec.joints),
            f"policy spec {self.spec.path}")
        self.default_q = np.asarray(self.spec.default_q)
        self.command = np.asarray(self.spec.command, dtype=float)
        self.last_action = np.zeros(len(self.spec.joints))
        self.extra = extra_joints(self.spec, legmap)
        self.n_body = legmap.n_joints + len(self.extra)
        self.hold_q = np.array([h.q for h in self.spec.hold])
        self.target_range = _joint_ranges(self.spec, legmap, self.extra) if self.spec.action_clip_range else None
        self.clip_joints = (None if self.spec.action_clip_joints is None
                            else np.asarray(self.spec.action_clip_joints))
        self.history: list[list] = [[] for _ in self.terms]  # terms with a history: their last values

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def privileged(self) -> list[str]:
        return self.spec.privileged

    def reset(self) -> None:
        self.last_action = np.zeros(len(self.spec.joints))
        self.history = [[] for _ in self.terms]
        getattr(self.model, "reset", lambda: None)()

    def observation(self, obs: dict, info: dict, time: float) -> np.ndarray:
        if self.spec.command_schedule:
            self.command = np.asarray(self.spec.command_at(time), dtype=float)
        return build_observation(self.terms, ObsContext(obs, info, time, self.last_action, self.command, self.index,
                                                        self.default_q), self.history)

    def act(self, obs: dict, info: dict, time: float) -> np.ndarray:
        """Joint targets (one per leg joint, leg-map order, rad) for this control step."""
        return self.targets(self.model(self.observation(obs, info, time)))

    def targets(self, action: np.ndarray) -> np.ndarray:
        """Apply an action (policy order, clipped per the spec): it becomes the last
        action; the joint targets in leg-map order."""
        a = action if self.spec.action_clip is None else np.clip(action, -self.spec.action_clip,
                                                                  self.spec.action_clip)
        if self.clip_joints is not None:
            a = np.clip(a, -self.clip_joints, self.clip_joints)
        self.last_action = a
        target = np.empty(self.n_body)
        target[self.index] = self.default_q + self.spec.action_scale * a
        if len(self.hold_q):
            target[self.n_body - len(self.hold_q):] = self.hold_q
        if self.target_range is not None:
            target = np.clip(target, self.target_range[0], self.target_range[1])
        return target

    def action_of(self, target: np.ndarray) -> np.ndarray:
        """The action (policy order) that gives these joint targets (leg-map order)."""
        return (np.asarray(target)[self.index] - self.default_q) / self.spec.action_scale

    def walking_config(self, **overrides) -> WalkingConfig:
        return walking_config(self.spec, self.legmap, **overrides)


def _joint_ranges(spec: PolicySpec, legmap: LegMap, extra: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(low, high) of the body vector's joints from the robot's MJCF (unlimited: +-inf)."""
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(legmap.mjcf))
    low, high = [], []
    for name in list(legmap.joint_names) + extra:
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, name)
        if j < 0:
            raise ConfigError(f"policy spec {spec.path}: joint '{name}' is not in {legmap.mjcf}")
        lim = bool(m.jnt_limited[j])
        low.append(m.jnt_range[j, 0] if lim else -np.inf)
        high.append(m.jnt_range[j, 1] if lim else np.inf)
    return np.array(low), np.array(high)


def walking_config(spec: PolicySpec, legmap: LegMap, **overrides) -> WalkingConfig:
    """The walking env's servo gains, default pose, rates and simulation settings from a
    spec (the body vector's order: the leg joints in leg-map order, then a whole-body
    policy's others, then the held joints)."""
    index = joint_index(spec, legmap)
    extra = extra_joints(spec, legmap)
    n, k = legmap.n_joints, len(extra)

    def body_order(v, held):
        out = np.empty(n + k)
        out[index] = v
        if spec.hold:
            out[n + k - len(spec.hold):] = held
        return out

    kp = body_order(spec.kp, [h.kp or 0.0 for h in spec.hold])
    kd = body_order(spec.kd, [h.kd or 0.0 for h in spec.hold])
    q0 = body_order(spec.default_q, [h.q for h in spec.hold])
    kw = dict(kp=tuple(kp[:n].tolist()), kd=tuple(kd[:n].tolist()), default_q=tuple(q0[:n].tolist()),
              physics_dt=1.0 / spec.physics_hz, decimation=spec.decimation,
              torque_limit=tuple(body_order(spec.torque_limit, [np.inf] * len(spec.hold))[:n].tolist())
              if spec.torque_limit is not None else None,
              extra_joints=tuple(extra), extra_kp=tuple(kp[n:].tolist()), extra_kd=tuple(kd[n:].tolist()),
              extra_default_q=tuple(q0[n:].tolist()), model_actuators=spec.actuators == "model",
              keyframe=spec.keyframe,
              sensors=tuple(t.name for t in spec.observation if t.term == "sensor"))
    if spec.floor_friction is not None:  # the floor the policy was trained on: its friction, not the feet's
        kw["floor_friction"], kw["floor_friction_exact"] = tuple(spec.floor_friction), True
    kw.update(overrides)
    return WalkingConfig(**kw)
