"""Residual weights from a recording's declared sensor model (1/sigma per residual).

First-order noise levels: an encoder's noise (with quantization, resolution^2/12)
moves a sole by about sigma_q x leg length per joint, three joints dominating per
leg, and turns it by about sigma_q per joint, every joint of the leg (`leg_joints`,
the leg map's; by default a leg of every role); the accelerometer's noise tilts the IMU
vertical by sigma_acc / g. Returns None for a noise-free model (nothing to match:
callers keep their defaults).
"""

from __future__ import annotations

import numpy as np

from legcal_bench.robots.design import LEG_ROLES
from legcal_bench.sim.sensors import SensorModel

G = 9.81


def noise_sigmas(model: SensorModel, leg_length: float, leg_joints: int = len(LEG_ROLES)) -> dict[str, float] | None:
    sigma_q = float(np.hypot(model.encoder_noise_std, model.encoder_resolution / np.sqrt(12)))
    tilt = model.accel_noise_std / G
    if sigma_q == 0 or tilt == 0:
        return None
    return {
        "encoder": sigma_q,
        "tilt": tilt,
        # One sole relative to the pelvis: ~3 joints at lever ~ leg length.
        "height": sigma_q * leg_length * np.sqrt(3),
        # Inter-foot transform: both legs (translation: ~3 joints each; rotation: every joint).
        "feet_translation": sigma_q * leg_length * np.sqrt(6),
        "feet_rotation": sigma_q * np.sqrt(2 * leg_joints),
        # Flat rows: height difference of the soles along the IMU vertical; sole normals.
        "flat_height": float(np.hypot(sigma_q * leg_length * np.sqrt(6), tilt * 0.2)),
        "flat_normal": float(np.hypot(tilt, sigma_q * np.sqrt(leg_joints))),
    }
