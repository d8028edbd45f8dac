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


def joint_index(spec: PolicySpec, legmap: LegMap) -> np.ndarray:
    """Leg-map column of each of the policy's joints; ConfigError if they differ."""
    missing = [j for j in spec.joints if j not in legmap.joint_names]
    extra = [j for j in legmap.joint_names if j not in spec.joints]
    if missing or extra:
        raise ConfigError(f"policy spec {spec.path}: its joints must be the leg map's {legmap.n_joints} leg joints "
                          f"({legmap.name}), by name, in any order; "
                          + (f"not in the leg map: {missing}; " if missing else "")
                          + (f"leg joints the policy does not drive: {extra}" if extra else ""))
    return np.array([legmap.joint_names.index(j) for j in spec.joints])


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

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def privileged(self) -> list[str]:
        return self.spec.privileged

    def reset(self) -> None:
        self.last_action = np.zeros(len(self.spec.joints))
        getattr(self.model, "reset", lambda: None)()

    def observation(self, obs: dict, info: dict, time: float) -> np.ndarray:
        return build_observation(self.terms, ObsContext(obs, info, time, self.last_action, self.command, self.index,
                                                        self.default_q))

    def act(self, obs: dict, info: dict, time: float) -> np.ndarray:
        """Joint targets (one per leg joint, leg-map order, rad) for this control step."""
        return self.targets(self.model(self.observation(obs, info, time)))

    def targets(self, action: np.ndarray) -> np.ndarray:
        """Apply an action (policy order, clipped per the spec): it becomes the last
        action; the joint targets in leg-map order."""
        a = action if self.spec.action_clip is None else np.clip(action, -self.spec.action_clip,
                                                                  self.spec.action_clip)
        self.last_action = a
        target = np.empty(self.legmap.n_joints)
        target[self.index] = self.default_q + self.spec.action_scale * a
        return target

    def action_of(self, target: np.ndarray) -> np.ndarray:
        """The action (policy order) that gives these joint targets (leg-map order)."""
        return (np.asarray(target)[self.index] - self.default_q) / self.spec.action_scale

    def walking_config(self, **overrides) -> WalkingConfig:
        return walking_config(self.spec, self.legmap, **overrides)


def walking_config(spec: PolicySpec, legmap: LegMap, **overrides) -> WalkingConfig:
    """The walking env's servo gains, default pose and rates from a spec (leg-map order)."""
    index = joint_index(spec, legmap)

    def leg_order(v):
        out = np.empty(legmap.n_joints)
        out[index] = v
        return tuple(out.tolist())

    kw = dict(kp=leg_order(spec.kp), kd=leg_order(spec.kd), default_q=leg_order(spec.default_q),
              physics_dt=1.0 / spec.physics_hz, decimation=spec.decimation,
              torque_limit=leg_order(spec.torque_limit) if spec.torque_limit is not None else None)
    kw.update(overrides)
    return WalkingConfig(**kw)
