"""The simulation's names that the command line shows: the reality effects and their
keys, the offset presets, the sensor presets. Standard library only, so that a
command's `--help` and an argument error (which print them) load no numerical package;
the simulation modules import them from here."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EffectKind:
    name: str
    keys: dict  # key -> (kind, default): kind "joint" | "link" | "side" | "about" | "stance" | "number"
    help: str


KINDS = {k.name: k for k in (
    EffectKind("imu_tilt", {"roll": ("number", 0.0), "pitch": ("number", 0.0)}, "IMU mounting tilt (deg)"),
    EffectKind("encoder_scale", {"joint": ("joint", None), "scale": ("number", None)},
               "encoder scale error (fraction): the encoder reads (q - offset) / (1 + scale)"),
    EffectKind("link_length", {"link": ("link", None), "mm": ("number", None)}, "link lengthened (mm)"),
    EffectKind("hip_axis", {"joint": ("joint", None), "about": ("about", "z"), "deg": ("number", None)},
               "joint axis rotated about its body's axis (deg)"),
    EffectKind("joint_axis", {"joint": ("joint", None), "about": ("about", "z"), "deg": ("number", None)},
               "any leg joint's axis rotated about its body's axis (deg)"),
    EffectKind("link_offset", {"link": ("link", None), "axis": ("about", "y"), "mm": ("number", None)},
               "link bent: its far joint moved across (mm, robot frame at the zero posture)"),
    EffectKind("link_twist", {"link": ("link", None), "deg": ("number", None)},
               "link twisted about its long axis (deg)"),
    EffectKind("mount_offset", {"side": ("side", None), "axis": ("about", "y"), "mm": ("number", None)},
               "a hip's mounting point moved: the body of the leg's first joint (mm, robot frame at the zero "
               "posture)"),
    EffectKind("joint_offset", {"joint": ("joint", None), "axis": ("about", "y"), "mm": ("number", None)},
               "a leg joint's body, and all below it, moved (mm, robot frame at the zero posture)"),
    EffectKind("compliance", {"joint": ("joint", None), "k": ("number", None)},
               "series spring between motor and link (N m/rad)"),
    EffectKind("shim", {"side": ("side", None), "roll": ("number", 0.0), "pitch": ("number", 0.0),
                        "stance": ("stance", None)},
               "wedge under one sole (deg), in every session or only in one stance's (stance=NAME)"),
    EffectKind("slope", {"roll": ("number", 0.0), "pitch": ("number", 0.0)}, "floor slope (deg)"),
)}
# Effect plug-ins: classes of this entry-point group that set `sim_keys` also bring
# their physics (`legcal_bench.sim.effects.ModelEdit`; docs/effect-plugins.md).
EFFECT_GROUP = "legcal_bench.effects"
EFFECTS_HELP = ("NAME:key=value,... with NAME one of " + "; ".join(
    f"{k.name} ({', '.join(k.keys)}: {k.help})" for k in KINDS.values())
    + f"; or an installed effect plug-in with physics for simulation (entry-point group {EFFECT_GROUP}, "
    "docs/effect-plugins.md)")

# legcal_bench.sim.offsets parses these.
PRESETS_HELP = ("none | paper | paper@<deg> | paper-base | random:<deg> | one radian per leg joint, comma-separated "
                "(leg-map order)")

# legcal_bench.sim.sensors.SENSOR_PRESETS, in this order: every effect off; an
# uncalibrated IMU; the same IMU after an IMU calibration.
SENSOR_PRESET_NAMES = ("zero", "realistic", "calibrated-imu")
