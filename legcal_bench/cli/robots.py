"""`legcal-bench info` and `render`: the robots."""

from __future__ import annotations

import argparse
import json
from dataclasses import asdict
from functools import partial
from pathlib import Path

from legcal_bench import inputs


def door(a: argparse.Namespace, **checks) -> None:
    """Options checked at the door, before any work: `checks` maps an option's dest to a
    check of `legcal_bench.inputs` (called as check(option, value)); an option not given
    (None) passes, a list is checked item by item. The ConfigError names the option, the
    value and the fix; the command prints it in one line and exits 2."""
    for dest, check in checks.items():
        value = getattr(a, dest)
        option = "--" + dest.replace("_", "-")
        for v in value if isinstance(value, list) else [value]:
            if v is not None:
                check(option, v)


# Checks `door` takes, beside inputs.seed, inputs.positive, inputs.count, inputs.output_folder, inputs.output_file.
COUNT0 = partial(inputs.count, low=0)  # a count where none is meaningful
# Seeds, trials, repeats to run: each is a set collected, a walk or a probe run, and a plan
# holds one entry for each; beyond this many, a typo (whose plan would exhaust memory and
# whose run would not end), refused with the number.
MAX_RUNS = 100_000
RUN_COUNT = partial(inputs.count, high=MAX_RUNS, fix="seeds, trials or repeats to run")


def frame_count(field: str, value) -> int:
    """A budget of frames to simulate (`design`, `excite`): at most what a recording of this
    library holds (`legcal_bench.logs.mapping.MAX_FRAMES`, 11 h at 50 Hz); beyond it a
    typo whose time array alone would take gigabytes, refused with the number."""
    from legcal_bench.logs.mapping import MAX_FRAMES  # on the check's path only: start-up stays light

    return inputs.count(field, value, high=MAX_FRAMES, fix=f"a recording holds at most {MAX_FRAMES:,} frames")


def floor_mode(field: str, value: str) -> str:
    """A floor mode of the simulation (kinematic, weld, contact); a misspelling named."""
    from legcal_bench.sim.scene import MODES

    return inputs.choice(field, value, MODES)

RENDER_OUT = "runs/render/robot.png"


def robot_args(p: argparse.ArgumentParser, default: str | None = "a3", unset: str = "") -> None:
    """--robot (`unset`: what the command does without one, when `default` is None) and --mjcf."""
    p.add_argument("--robot", default=default,
                   help="built-in robot name (a2, a3, pair_ryp, pair_pry) or the path of a leg-map YAML "
                        f"(default: {default if default is not None else 'none, ' + unset})")
    p.add_argument("--mjcf", default=None, help="use this MJCF instead of the one the leg map names (default: the "
                                                "leg map's)")


def cmd_info(a: argparse.Namespace) -> int:
    import numpy as np

    from legcal_bench.protocol.servos import servo_gains
    from legcal_bench.robots import BUILTIN, load_robot
    from legcal_bench.robots.design import ROLE_AXIS_NAME
    from legcal_bench.robots.holds import joint_holds
    from legcal_bench.robots.kinematics import LegKinematics, axis_warnings

    if a.robot is None:
        print("built-in robots (or pass --robot path/to/robot.legmap.yaml):")
        for e in BUILTIN.values():
            print(f"  {e.name:<10} {e.description}  [{', '.join(e.tags)}]")
        return 0
    legmap = load_robot(a.robot, a.mjcf)
    kin = LegKinematics(legmap)
    info = {
        "name": legmap.name, "mjcf": str(legmap.mjcf), **({"urdf": str(legmap.urdf)} if legmap.urdf else {}),
        "hip_order": "->".join(r.replace("hip_", "") for r in legmap.hip_order),
        "leg_joints": legmap.leg_joints, "absent_roles": list(legmap.absent_roles),
        "dims_m": asdict(kin.dims), "knee_straight_deg": float(np.rad2deg(legmap.knee_straight_rad)),
        # every non-leg joint: held at what (from the leg map, a keyframe or the model), how (rigid or servo)
        "held_joints": [h.to_dict() for h in joint_holds(legmap)],
        "joints": [],
    }
    axes = kin.joint_axes()
    signs, angles = kin.role_axes()
    gains = servo_gains(legmap)
    info["servo_gains_note"] = gains.note
    info["axis_warnings"] = axis_warnings(kin)
    for i, (name, role) in enumerate(zip(legmap.joint_names, legmap.joint_roles)):
        info["joints"].append({
            "index": i, "name": name, "role": role, "axis_in_pelvis_at_zero": np.round(axes[i], 6).tolist(),
            # The role's pelvis axis, the axis's angle to it and whether it points the other way (mirrored).
            "role_axis": ROLE_AXIS_NAME[role], "angle_to_role_axis_deg": round(float(np.degrees(angles[i])), 3),
            "mirrored": bool(signs[i] < 0),
            "limits_deg": (np.round(np.rad2deg([kin.q_lower[i], kin.q_upper[i]]), 3).tolist() if kin.limited[i]
                           else None),
            "servo": {"kp": gains.kp[i], "kd": gains.kd[i], "source": gains.source[i]}})
    if a.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{info['name']}: {info.get('urdf', info['mjcf'])}" + (f" (simulated as {info['mjcf']})" if legmap.urdf else ""))
    print(f"  legs of {legmap.leg_joints} joints" + (f" (no {', '.join(legmap.absent_roles)}: absent_roles)"
                                                      if legmap.absent_roles else ""))
    print(f"  hip order {info['hip_order']}; leg length {kin.dims.leg_length:.3f} m, "
          f"feet at y = ±{kin.dims.foot_y:.3f} m; sole {kin.dims.sole_length:.3f} x {kin.dims.sole_width:.3f} m")
    print(f"  {'#':>2} {'joint':<28} {'role':<12} {'axis (pelvis frame, q=0)':<26} {'to role axis':<16} "
          f"{'limits (deg)':<16} servo kp, kd (source)")
    for j in info["joints"]:
        ax = " ".join(f"{v:+.3f}" for v in j["axis_in_pelvis_at_zero"])
        rel = f"{j['angle_to_role_axis_deg']:4.1f}° {'-' if j['mirrored'] else '+'}{j['role_axis']}"
        lim = ("unlimited" if j["limits_deg"] is None else
               f"{j['limits_deg'][0]:+6.1f} .. {j['limits_deg'][1]:+6.1f}")
        sv = j["servo"]
        print(f"  {j['index']:>2} {j['name']:<28} {j['role']:<12} {ax:<26} {rel:<16} {lim:<16} "
              f"{sv['kp']:7.0f}, {sv['kd']:5.1f} ({sv['source']})")
    print(f"  servo gains for static collection: {gains.note}")
    for w in info["axis_warnings"]:
        print(f"  warning: {w}")
    if info["held_joints"]:
        print(f"  held joints in static collection (every joint the legs do not list; {len(info['held_joints'])}):")
        for h in info["held_joints"]:
            how = (f"servo kp {h['kp']:g}, kd {h['kd']:g} (servo_gains)" if h["how"] == "servo" else
                   "rigid (joint equality)" if h["how"] == "rigid" else "free (a ball joint: not held)")
            print(f"     {h['joint']:<28} {h['angle_deg']:+8.3f} deg  from {h['from']:<28} {how}")
    return 0


def cmd_render(a: argparse.Namespace) -> int:
    door(a, seed=inputs.seed, out=inputs.output_file)
    from PIL import Image

    from legcal_bench.envs.static_double_support import StaticDoubleSupportEnv
    from legcal_bench.files.atomic import atomic_write

    env = StaticDoubleSupportEnv(robot=a.robot, mjcf=a.mjcf, mode=a.mode, offsets="none", sensors="zero",
                                 render_mode="rgb_array")
    _, info = env.reset(seed=a.seed, options={"stance": a.stance})
    env.step(info["posture"])
    img = env.render()
    env.close()
    out = Path(a.out)
    atomic_write(out, lambda f: Image.fromarray(img).save(f, format="PNG"), mode="wb")
    print(f"wrote {out} ({img.shape[1]}x{img.shape[0]}, {env.legmap.name}, stance {a.stance}, {a.mode})")
    return 0


def add_commands(sub) -> None:
    i = sub.add_parser("info", help="list robots, or show one robot's joint order, axes and limits",
                       description="Without --robot: the built-in robots. With --robot: its leg joints in order, "
                                   "each joint's role, axis in the pelvis frame at q = 0 (and its angle to the "
                                   "role's axis), limits (deg) and the servo gains static collection uses, the leg "
                                   "dimensions (m) and any axis warnings. Writes nothing.")
    robot_args(i, default=None, unset="list the built-in robots")
    i.add_argument("--json", action="store_true", help="print the robot's description as JSON (default: text)")
    i.set_defaults(func=cmd_info)

    r = sub.add_parser("render", help="PNG of a robot in a stance (offscreen)",
                       description="Place the robot in a stance on the static env (no offsets, zero-noise "
                                   "sensors), render it offscreen (MuJoCo, MUJOCO_GL=egl by default) and write a "
                                   "PNG.")
    robot_args(r)
    r.add_argument("--stance", default="I", help="the stance to show: I, II, III, IV or standing (default I)")
    r.add_argument("--mode", default="kinematic", choices=("kinematic", "weld", "contact"),
                   help="floor model (default kinematic)")
    r.add_argument("--seed", type=int, default=0, help="placement seed: an integer in [0, 2^32 - 1] (default 0)")
    r.add_argument("--out", default=RENDER_OUT, help=f"PNG file to write, its folder made if needed (default "
                                                     f"{RENDER_OUT})")
    r.set_defaults(func=cmd_render)
