"""A base for legcal-bench's MuJoCo environments: timing and offscreen rendering.

Subclasses own their physics (a simulator object holding the MuJoCo model and data)
and tell the base how long one env step lasts (`physics_dt` x `frame_skip`) and how to
pose a frame for rendering (`_render_scene`). `render_fps` follows from the step
duration, so a rendered episode plays at the rate it was logged.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym
import mujoco
import numpy as np

from legcal_bench.errors import ConfigError


class MujocoEnv(gym.Env, ABC):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 50}

    def __init__(self, physics_dt: float, frame_skip: int, render_mode: str | None = None,
                 width: int = 640, height: int = 480):
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ConfigError(f"render_mode {render_mode!r}: use one of {self.metadata['render_modes']} or None")
        self.physics_dt = float(physics_dt)
        self.frame_skip = int(frame_skip)
        self.render_mode = render_mode
        self.width, self.height = int(width), int(height)
        self.metadata = {**type(self).metadata, "render_fps": int(round(1.0 / self.dt))}
        self._renderer: mujoco.Renderer | None = None

    @staticmethod
    def _reset_options(options: dict | None, known: tuple[str, ...]) -> dict:
        """`options` as a dict; ConfigError naming unknown keys."""
        options = dict(options or {})
        unknown = sorted(set(options) - set(known))
        if unknown:
            raise ConfigError(f"unknown reset options {unknown}; known: {', '.join(known)}")
        return options

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
