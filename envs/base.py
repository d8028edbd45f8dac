"""A base for legcal-bench's MuJoCo environments: timing and offscreen rendering.

Subclasses own their physics (a simulator object holding the MuJoCo model and data)
and tell the base how long one env step lasts (`physics_dt` x `frame_skip`) and how to
pose a frame for rendering (`_render_scene`). `render_fps` follows from the step
duration, so a rendered episode plays at the rate it was logged.

The door (issue #42): the envs' keyword arguments, reset options and actions are
checked where they come in, with `legcal_bench.inputs`, and a bad one raises a
`ConfigError` (a `LegcalError`) naming the argument, the value and the fix, at
construction (arguments: `gym.make(id, ...)` refuses alike) or at `step` (an action of
the wrong length, not numbers, or not finite) -- never a traceback from deep in the
physics or the linear algebra.
"""

from __future__ import annotations

import inspect
import os
from abc import ABC, abstractmethod

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym
import mujoco
import numpy as np

from legcal_bench import inputs
from legcal_bench.inputs import shown
from legcal_bench.errors import ConfigError, LegcalError
from legcal_bench.sim.double_support import PHYSICS_DT_RANGE

MAX_IMAGE = 8192  # pixels a side, a rendered frame


def named(field: str, build, *args, **kwargs):
    """`build(*args, **kwargs)`, its LegcalError's message led by `field` when it does
    not name it (a loader's "unknown robot 'x'" for `sim_robot`), the error's type kept."""
    try:
        return build(*args, **kwargs)
    except LegcalError as e:
        if field.lower() in str(e).lower():
            raise
        try:
            new = type(e)(f"{field}: {e}")
        except TypeError:
            new = ConfigError(f"{field}: {e}")
        raise new from None


class MujocoEnv(gym.Env, ABC):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}
    # What an action is, for the message refusing a bad one (subclasses say).
    action_doc = "the action"

    def __init__(self, physics_dt: float, frame_skip: int, render_mode: str | None = None,
                 width: int = 640, height: int = 480):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode = {render_mode!r}: use one of {self.metadata['render_modes']} or None")
        self.physics_dt = inputs.number("physics_dt", physics_dt, low=PHYSICS_DT_RANGE[0], high=PHYSICS_DT_RANGE[1])
        self.frame_skip = inputs.count("frame_skip", frame_skip)
        self.render_mode = render_mode
        self.width = inputs.count("width", width, high=MAX_IMAGE, fix="the rendered image's width in pixels")
        self.height = inputs.count("height", height, high=MAX_IMAGE, fix="the rendered image's height in pixels")
        self.metadata = {**type(self).metadata, "render_fps": max(1, int(round(1.0 / self.dt)))}
        self._renderer: mujoco.Renderer | None = None

    @classmethod
    def _refuse_unknown(cls, unknown: dict) -> None:
        """A keyword argument the env does not take (a misspelling: `rate=50` for
        `rate_hz=50`) refused with the closest one named, as Python would only say
        "unexpected keyword argument"."""
        if unknown:
            params = inspect.signature(cls.__init__).parameters.values()
            known = [p.name for p in params if p.name != "self" and p.kind not in (p.VAR_KEYWORD, p.VAR_POSITIONAL)]
            inputs.known_keys(f"{cls.__name__} keyword arguments", unknown, known)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Gymnasium's reset (the env's random generator seeded by `seed`), the seed
        checked by the one rule for seeds (`inputs.seed`)."""
        return super().reset(seed=None if seed is None else inputs.seed("reset seed", seed), options=options)

    @staticmethod
    def _reset_options(options: dict | None, known: tuple[str, ...]) -> dict:
        """`options` as a dict; ConfigError naming unknown keys (and the closest known one)."""
        if options is not None and not isinstance(options, dict):
            raise ConfigError(f"reset options = {options!r}: give a dict of {', '.join(known)}, or None")
        options = dict(options or {})
        inputs.known_keys("reset options", options, known)
        return options

    def _action(self, action) -> np.ndarray:
        """`action` as a float array of the action space's shape: ConfigError, naming the
        action and what it should be, for one that is not numbers, has the wrong number
        of entries or has a non-finite one (NaN would reach the IK's least squares or the
        servos). Entries outside the space's bounds are the subclass's to handle."""
        shape = self.action_space.shape
        n = int(np.prod(shape))

        def want() -> str:  # the error's path only: this runs every step
            return f"{n} finite numbers, {self.action_doc}"

        try:
            a = np.asarray(action, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError(f"action = {shown(action)}: not numbers; give {want()}") from None
        if a.size != n:
            raise ConfigError(f"action: {a.size} values (shape {a.shape}), expected {n} (shape {shape}); give {want()}")
        a = a.reshape(shape)
        if not np.isfinite(a).all():
            bad = np.flatnonzero(~np.isfinite(a))
            raise ConfigError(f"action: entries {bad.tolist()} are not finite ({shown(a.ravel()[bad].tolist())}); "
                              f"give {want()}")
        return a

    @property
    def dt(self) -> float:
        """Duration of one env step (s)."""
        return self.physics_dt * self.frame_skip

    @abstractmethod
    def _render_scene(self) -> tuple[mujoco.MjModel, mujoco.MjData, np.ndarray, float]:
        """(model, data posed for this frame, camera look-at point, camera distance)."""

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        model, data, lookat, distance = self._render_scene()
        if self._renderer is None:
            self._renderer = mujoco.Renderer(model, self.height, self.width)
        cam = mujoco.MjvCamera()
        cam.lookat[:] = lookat
        cam.distance = distance
        cam.azimuth, cam.elevation = 140.0, -15.0
        self._renderer.update_scene(data, cam)
        return self._renderer.render()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
