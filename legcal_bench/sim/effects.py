"""A simulated reality that differs from the model (issue #16): effects applied on the
recording side, by physics, never by an estimator's formula.

The calibrator always gets the nominal robot; the simulator runs a copy changed by
the effects below. Recordings do not say which effect is present; the ground truth
does (`Reality.describe`, in each truth file's meta). Specs are `name:key=value,...`
(several at once); a target left out (`joint`, `link`, `side`) is drawn from the
collection seed. Units at this edge: degrees, millimetres, N m/rad, fractions.

  imu_tilt:roll=0.5,pitch=0            the IMU mounted tilted (deg), in the sensor path
  encoder_scale:joint=left_knee,scale=0.005
                                       the encoder reads (q - offset) / (1 + scale)
  link_length:link=left_shank,mm=2     a copy of the MJCF with the link between two
                                       joints lengthened along the line between their
                                       axes (thigh: last hip joint to knee; shank: knee
                                       to the first ankle joint)
  hip_axis:joint=left_hip_pitch,about=z,deg=0.5
                                       the MJCF copy with that joint's axis rotated about
                                       its body's x, y or z axis
  joint_axis:joint=left_knee,about=x,deg=0.5
                                       the same for any leg joint (`hip_axis` is the hips')
  link_offset:link=left_shank,axis=y,mm=3
                                       the MJCF copy with the link's far joint moved across
                                       (a bent link): along x, y or z of the robot's frame
                                       at the zero posture
  link_twist:link=left_thigh,deg=1     the MJCF copy with the link twisted about its own
                                       long axis (the line between its two joints): the
                                       far joint's body and everything below it turned
  compliance:joint=left_knee,k=1e4     the MJCF copy with a spring (stiffness k, N m/rad)
                                       in series between the motor, whose angle the
                                       encoder reads, and the link: a passive hinge
                                       `legcal_compliance_<joint>` on the same body and axis
  shim:side=left,roll=0.5,pitch=0      a wedge under one sole (deg): that sole's placement
                                       tilted about its own origin (weld, kinematic modes);
                                       with stance=II only in that stance's session (a
                                       pebble under one foot once), else in every session
  slope:roll=0.3,pitch=0               the floor tilted (deg): both placements rotated about
                                       the stance frame's origin, gravity unchanged (weld,
                                       kinematic modes)

The generic route for an effect nobody anticipated is an edited MJCF given as the
simulated model (`collect --sim-model`).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from legcal_bench.errors import ConfigError
from legcal_bench.geometry.poses import wxyz
from legcal_bench.robots.legmap import SIDES, LegMap
from legcal_bench.sim.names import EFFECTS_HELP, KINDS
from legcal_bench.sim.sensors import SimSensors

COMPLIANCE_PREFIX = "legcal_compliance_"  # a passive series hinge after the motor joint it names
COMPLIANCE_DAMPING_RATIO = 0.7  # of the spring against the motor's armature
MIN_ARMATURE = 0.01  # kg m^2, given to a motor joint without one (a rotor always has some)
LINKS = ("thigh", "shank")
ABOUT = ("x", "y", "z")


@dataclass(frozen=True)
class RealityEffect:
    """One parsed effect spec; `values` in the spec's units, targets as written (or None)."""

    kind: str
    values: dict
    spec: str


def parse_effect(spec: str) -> RealityEffect:
    s = str(spec).strip()
    name, _, rest = s.partition(":")
    if name not in KINDS:
        raise ConfigError(f"--effect {spec!r}: unknown effect {name!r}; use {EFFECTS_HELP}")
    kind = KINDS[name]
    values = {k: d for k, (_, d) in kind.keys.items()}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        k, eq, v = item.partition("=")
        if not eq or k not in kind.keys:
            raise ConfigError(f"--effect {spec!r}: {item!r} is not key=value with a key of {name} "
                              f"({', '.join(kind.keys)})")
        if kind.keys[k][0] == "number":
            try:
                values[k] = float(v)
            except ValueError:
                raise ConfigError(f"--effect {spec!r}: {k}={v!r} is not a number") from None
            if not np.isfinite(values[k]):
                raise ConfigError(f"--effect {spec!r}: {k} must be finite")
        else:
            values[k] = v.strip()
    missing = [k for k, (t, d) in kind.keys.items() if t == "number" and values[k] is None]
    if missing:
        raise ConfigError(f"--effect {spec!r}: give {', '.join(missing)} (e.g. {name}:{missing[0]}=...)")
    if name == "compliance" and values["k"] <= 0:
        raise ConfigError(f"--effect {spec!r}: k is a stiffness in N m/rad and must be > 0 (e.g. k=1e4)")
    if name == "encoder_scale" and values["scale"] <= -1:
        raise ConfigError(f"--effect {spec!r}: scale must be > -1 (a fraction, e.g. 0.005)")
    return RealityEffect(name, values, s)


def floor_key(side: str, stance: str) -> str:
    """The `Reality.floor` key of a shim under `side` in `stance`'s session only."""
    return f"{side}@{stance}"


def floor_stances(floor: dict) -> set[str]:
    """The stances a per-stance shim in `floor` names."""
    return {k.partition("@")[2] for k in floor if "@" in k}


def joint_label(legmap: LegMap, index: int) -> str:
    """`left_knee`-style name of leg joint `index` (side and role)."""
    return f"{legmap.side_of(index)}_{legmap.joint_roles[index]}"


def _resolve_joint(legmap: LegMap, text: str | None, rng, spec: str, roles=None) -> int:
    labels = [joint_label(legmap, i) for i in range(legmap.n_joints)]
    allowed = [i for i in range(legmap.n_joints) if roles is None or legmap.joint_roles[i] in roles]
    if text is None:
        return int(rng.choice(allowed))
    if text in labels and labels.index(text) in allowed:
        return labels.index(text)
    if text in legmap.joint_names and legmap.joint_names.index(text) in allowed:
        return legmap.joint_names.index(text)
    raise ConfigError(f"--effect {spec!r}: joint {text!r} is not one of {[labels[i] for i in allowed]} "
                      "(side_role, or the leg map's joint name)")


def _choice(text, options, rng, spec: str, what: str) -> str:
    if text is None:
        return str(rng.choice(list(options)))
    if text not in options:
        raise ConfigError(f"--effect {spec!r}: {what} {text!r} is not one of {list(options)}")
    return text


@dataclass
class Reality:
    """The simulated robot and sensors with the effects applied, and the truth about them."""

    sim_legmap: LegMap
    sensors: SimSensors
    # side -> (4, 4) tilt of that sole's placement in every session, "side@stance" -> in
    # that stance's session only; "slope" -> the floor's tilt
    floor: dict = field(default_factory=dict)
    truth: list = field(default_factory=list)  # one dict per effect: its resolved target and SI values

    def describe(self) -> dict:
        return {"effects": self.truth, "sim_model": str(self.sim_legmap.mjcf)}


def build_reality(legmap: LegMap, sim_legmap: LegMap, specs, sensors: SimSensors, workdir: str | Path,
                  seed: int = 0) -> Reality:
    """Apply the effect `specs` to `sim_legmap` and `sensors`. MJCF edits go to a copy
    of the simulated robot's MJCF written under `workdir` (which must outlive the
    simulator's set-up)."""
    effects = [parse_effect(s) for s in specs]
    rng = np.random.default_rng(np.random.SeedSequence([seed, 16]))
    mount = np.array(sensors.errors.imu_mount_rpy)
    scale = np.array(sensors.encoder_scale if sensors.encoder_scale else np.zeros(legmap.n_joints))
    floor, truth, edits = {}, [], []
    for e in effects:
        v = e.values
        if e.kind == "imu_tilt":
            mount[:2] += np.deg2rad([v["roll"], v["pitch"]])
            truth.append({"effect": e.spec, "kind": e.kind, "roll_rad": float(np.deg2rad(v["roll"])),
                          "pitch_rad": float(np.deg2rad(v["pitch"]))})
        elif e.kind == "encoder_scale":
            j = _resolve_joint(legmap, v["joint"], rng, e.spec)
            scale[j] += v["scale"]
            truth.append({"effect": e.spec, "kind": e.kind, "joint": joint_label(legmap, j), "scale": v["scale"]})
        elif e.kind == "shim":
            side = _choice(v["side"], SIDES, rng, e.spec, "side")
            T = np.eye(4)
            T[:3, :3] = Rotation.from_euler("xy", np.deg2rad([v["roll"], v["pitch"]])).as_matrix()
            key = side if v["stance"] is None else floor_key(side, v["stance"])
            floor[key] = floor.get(key, np.eye(4)) @ T
            truth.append({"effect": e.spec, "kind": e.kind, "side": side, "roll_rad": float(np.deg2rad(v["roll"])),
                          "pitch_rad": float(np.deg2rad(v["pitch"])), "stance": v["stance"]})
        elif e.kind == "slope":
            T = np.eye(4)
            T[:3, :3] = Rotation.from_euler("xy", np.deg2rad([v["roll"], v["pitch"]])).as_matrix()
            floor["slope"] = T @ floor.get("slope", np.eye(4))
            truth.append({"effect": e.spec, "kind": e.kind, "roll_rad": float(np.deg2rad(v["roll"])),
                          "pitch_rad": float(np.deg2rad(v["pitch"]))})
        elif e.kind in ("link_length", "link_offset", "link_twist"):
            link = v["link"]
            if link is None:
                link = f"{rng.choice(SIDES)}_{rng.choice(LINKS)}"
            side, _, part = link.partition("_")
            if side not in SIDES or part not in LINKS:
                raise ConfigError(f"--effect {e.spec!r}: link {link!r} is not one of "
                                  f"{[f'{s}_{p}' for s in SIDES for p in LINKS]}")
            if e.kind == "link_length":
                edits.append(("link_length", (side, part, v["mm"] * 1e-3)))
                truth.append({"effect": e.spec, "kind": e.kind, "link": link, "length_m": v["mm"] * 1e-3})
            elif e.kind == "link_offset":
                axis = _choice(v["axis"], ABOUT, rng, e.spec, "axis")
                edits.append(("link_offset", (side, part, np.eye(3)[ABOUT.index(axis)] * v["mm"] * 1e-3)))
                truth.append({"effect": e.spec, "kind": e.kind, "link": link, "axis": axis,
                              "offset_m": v["mm"] * 1e-3})
            else:
                edits.append(("link_twist", (side, part, np.deg2rad(v["deg"]))))
                truth.append({"effect": e.spec, "kind": e.kind, "link": link, "angle_rad": float(np.deg2rad(v["deg"]))})
        elif e.kind in ("hip_axis", "joint_axis"):
            roles = ("hip_pitch", "hip_roll", "hip_yaw") if e.kind == "hip_axis" else None
            j = _resolve_joint(legmap, v["joint"], rng, e.spec, roles=roles)
            about = _choice(v["about"], ABOUT, rng, e.spec, "about")
            edits.append(("joint_axis", (j, about, np.deg2rad(v["deg"]))))
            truth.append({"effect": e.spec, "kind": e.kind, "joint": joint_label(legmap, j), "about": about,
                          "angle_rad": float(np.deg2rad(v["deg"]))})
        elif e.kind == "compliance":
            j = _resolve_joint(legmap, v["joint"], rng, e.spec)
            edits.append(("compliance", (j, v["k"])))
            truth.append({"effect": e.spec, "kind": e.kind, "joint": joint_label(legmap, j),
                          "stiffness_nm_per_rad": v["k"], "compliance_rad_per_nm": 1.0 / v["k"]})
    sensors = replace(sensors, errors=replace(sensors.errors, imu_mount_rpy=tuple(float(x) for x in mount)),
                      encoder_scale=tuple(float(x) for x in scale) if np.any(scale) else ())
    if edits:
        sim_legmap = _edited_model(sim_legmap, edits, Path(workdir))
    return Reality(sim_legmap, sensors, floor, truth)


def _edited_model(legmap: LegMap, edits: list, workdir: Path) -> LegMap:
    """A copy of `legmap`'s MJCF with the edits, exported (with its assets) into `workdir`."""
    import mujoco
    import pinocchio as pin
    from dm_control import mjcf

    from legcal_bench.robots.kinematics import LegKinematics

    kin = LegKinematics(legmap)
    m = mjcf.from_path(str(legmap.mjcf))
    compiled = mujoco.MjModel.from_xml_path(str(legmap.mjcf))
    model, data = kin.model, kin.data
    pin.forwardKinematics(model, data, kin.q_full(np.zeros(legmap.n_joints)))
    pin.updateFramePlacements(model, data)

    def body_rotation(name: str) -> np.ndarray:
        return data.oMf[model.getFrameId(name, pin.FrameType.BODY)].rotation

    for kind, args in edits:
        if kind in ("link_length", "link_offset", "link_twist"):
            side, part, delta = args
            chain = [int(c) for c in kin.poe[side].cols]
            roles = [legmap.joint_roles[c] for c in chain]
            k = roles.index("knee") if part == "thigh" else roles.index("knee") + 1
            joint = m.find("joint", legmap.joint_names[chain[k]])
            u = kin.poe[side].M[k][:3, 3]  # joint k's anchor in joint k-1's frame (that body's axes)
            u = u / np.linalg.norm(u)
            prev_body = model.frames[model.getFrameId(legmap.joint_names[chain[k - 1]], pin.FrameType.JOINT)]
            R_prev = data.oMi[prev_body.parentJoint].rotation
            child = joint.parent
            R_parent = body_rotation(child.parent.name) if child.parent.name else np.eye(3)
            pos = np.asarray(child.pos if child.pos is not None else np.zeros(3), float)
            if kind == "link_length":
                child.pos = (pos + R_parent.T @ R_prev @ u * delta).tolist()
            elif kind == "link_offset":  # delta: a vector in the robot's frame at the zero posture
                child.pos = (pos + R_parent.T @ delta).tolist()
            else:  # twist the child body (and its subtree) about the link's axis through its origin
                R_child = body_rotation(child.name)
                R_rel = R_parent.T @ R_child
                turn = Rotation.from_rotvec(R_parent.T @ R_prev @ u * delta).as_matrix()
                for attr in ("euler", "axisangle", "xyaxes", "zaxis"):
                    setattr(child, attr, None)
                child.quat = wxyz(Rotation.from_matrix(turn @ R_rel)).tolist()
        elif kind == "joint_axis":
            j, about, angle = args
            joint = m.find("joint", legmap.joint_names[j])
            axis = np.asarray(joint.axis if joint.axis is not None else (0, 0, 1), float)
            R = Rotation.from_rotvec(np.eye(3)[ABOUT.index(about)] * angle).as_matrix()
            joint.axis = (R @ axis).tolist()
    workdir.mkdir(parents=True, exist_ok=True)
    name = f"{Path(legmap.mjcf).stem}_reality.xml"
    mjcf.export_with_assets(m, str(workdir), out_file_name=name)
    _add_series_springs(workdir / name, legmap, [args for kind, args in edits if kind == "compliance"], compiled)
    return replace(legmap, mjcf=(workdir / name).resolve())


def _add_series_springs(path: Path, legmap: LegMap, springs: list, compiled) -> None:
    """Make the exported MJCF at `path` readable again by dm_control, and split the body of each compliant joint J in the exported MJCF at `path`: a new
    body `legcal_motor_<J>` takes the body's place and pose and carries J (the motor,
    its armature at least MIN_ARMATURE); the body itself (name, contents) hangs from it
    at the identity, on a passive hinge `legcal_compliance_<J>` with J's anchor and axis
    and stiffness k. Frames the leg map names on the body stay on the link side."""
    import xml.etree.ElementTree as ET

    import mujoco

    tree = ET.parse(path)
    root = tree.getroot()
    # dm_control writes the root default class as a nested <default class="/">, which it
    # cannot read back: its settings go up into the root <default>, references to it go;
    # and names it made up for unnamed elements ("//unnamed_geom_0") go too.
    parents = {c: p for p in root.iter() for c in p}
    for e in list(root.iter()):
        if (e.get("name") or "").startswith("//"):  # its placeholder names for unnamed elements
            del e.attrib["name"]
        if e.get("class") == "/":
            del e.attrib["class"]
            if e.tag == "default":
                outer = parents[e]
                at = list(outer).index(e)
                for i, child in enumerate(list(e)):
                    outer.insert(at + i, child)
                outer.remove(e)
    parents = {c: p for p in root.iter() for c in p}
    for j, k in springs:
        name = legmap.joint_names[j]
        joint = next(e for e in root.iter("joint") if e.get("name") == name)
        body = parents[joint]
        jid = mujoco.mj_name2id(compiled, mujoco.mjtObj.mjOBJ_JOINT, name)
        pos, axis = compiled.jnt_pos[jid], compiled.jnt_axis[jid]
        arm = max(float(compiled.dof_armature[compiled.jnt_dofadr[jid]]), MIN_ARMATURE)
        motor = ET.Element("body", {"name": f"legcal_motor_{name}"})
        for attr in ("pos", "quat", "euler", "axisangle", "xyaxes", "zaxis", "childclass"):
            if body.get(attr) is not None:
                motor.set(attr, body.get(attr))
                if attr != "childclass":
                    del body.attrib[attr]
        holder = parents[body]
        holder.insert(list(holder).index(body), motor)
        holder.remove(body)
        body.remove(joint)
        joint.set("armature", repr(arm))
        motor.append(ET.Element("inertial", {"pos": "0 0 0", "mass": "0.001", "diaginertia": "1e-07 1e-07 1e-07"}))
        motor.append(joint)
        motor.append(body)
        spring = ET.Element("joint", {
            "name": COMPLIANCE_PREFIX + name, "type": "hinge", "pos": " ".join(repr(float(x)) for x in pos),
            "axis": " ".join(repr(float(x)) for x in axis), "stiffness": repr(float(k)), "springref": "0",
            "damping": repr(2 * COMPLIANCE_DAMPING_RATIO * float(np.sqrt(k * arm))), "armature": "0",
            "frictionloss": "0", "limited": "false"})
        body.insert(0, spring)
        parents = {c: p for p in root.iter() for c in p}
    tree.write(path)


def compliance_joints(model, joint_names: list[str]) -> list[tuple[int, int]]:
    """(leg index, qpos address) of each passive series hinge in a compiled MuJoCo
    `model` (named `legcal_compliance_<leg joint>`)."""
    import mujoco

    out = []
    for i, name in enumerate(joint_names):
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, COMPLIANCE_PREFIX + name)
        if jid >= 0:
            out.append((i, int(model.jnt_qposadr[jid])))
    return out

