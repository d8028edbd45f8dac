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
  mount_offset:side=left,axis=y,mm=4   the MJCF copy with a hip's mounting point moved: the
                                       body carrying the first joint of that leg's chain
                                       (and the whole leg) moved along x, y or z of the
                                       robot's frame at the zero posture
  joint_offset:joint=left_ankle_roll,axis=x,mm=3
                                       the same for any leg joint's body (side_role or the
                                       leg map's joint name): that joint and all below it
                                       moved, e.g. the distance between the ankle axes
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

Plug-ins add more (docs/effect-plugins.md): any class of the entry-point group
`legcal_bench.effects` that sets `sim_keys` ({key: (kind, default)}, kind "number" or
"text") and `simulate(values, edit)` is an effect name here too. `simulate` gets the
spec's values (in the spec's units) and a `ModelEdit` (the simulated robot's MJCF copy,
its leg map, kinematics, sole frames and sensors, with helpers to move a body, site or
geom by a motion written in the robot's frame at the zero posture) and returns the
truth (a dict, SI units). The MJCF-changing kinds above go through the same
`ModelEdit`. This module finds plug-ins through their entry points only (duck-typed):
the simulation layer does not import the estimation layer that defines `Effect`.

The generic route for an effect nobody anticipated is an edited MJCF given as the
simulated model (`collect --sim-model`).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass, field, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from legcal_bench.errors import ConfigError
from legcal_bench.geometry.poses import from_wxyz, wxyz
from legcal_bench.robots.frames import mjcf_element
from legcal_bench.robots.holds import OWN_PREFIX, hold_angles
from legcal_bench.robots.legmap import SIDES, FrameSpec, LegMap
from legcal_bench.sim.names import EFFECT_GROUP, EFFECTS_HELP, KINDS
from legcal_bench.sim.sensors import SimSensors

COMPLIANCE_PREFIX = OWN_PREFIX + "compliance_"  # a passive series hinge after the motor joint it names (not held)
COMPLIANCE_DAMPING_RATIO = 0.7  # of the spring against the motor's armature
MIN_ARMATURE = 0.01  # kg m^2, given to a motor joint without one (a rotor always has some)
LINKS = ("thigh", "shank")
ABOUT = ("x", "y", "z")
PLUGIN_KEY_KINDS = ("number", "text")  # of a plug-in's `sim_keys`


@dataclass(frozen=True)
class RealityEffect:
    """One parsed effect spec; `values` in the spec's units, targets as written (or None).
    `plugin`: the effect plug-in's class (None for a built-in kind)."""

    kind: str
    values: dict
    spec: str
    plugin: type | None = field(default=None, compare=False)


def effect_plugins() -> dict[str, type]:
    """Installed effect plug-ins with physics for simulation: name -> class, for each entry
    point of the group `legcal_bench.effects` whose class sets `sim_keys` (a built-in
    kind's name is never taken by one). Scanned once per import path (`sys.path`)."""
    return dict(_plugins(tuple(sys.path))[0])


@lru_cache(maxsize=8)
def _plugins(path: tuple[str, ...]) -> tuple[tuple, tuple, tuple]:
    """((name, class) with physics, names without (fit only), (name, error) that failed to load)."""
    from importlib.metadata import entry_points

    sim, fit_only, failed, seen = [], [], [], set()
    for ep in entry_points(group=EFFECT_GROUP):
        if ep.name in KINDS or ep.name in seen:
            continue
        seen.add(ep.name)
        try:
            cls = ep.load()
        except Exception as e:  # noqa: BLE001 - a broken plug-in is reported, not fatal to the others
            failed.append((ep.name, f"{type(e).__name__}: {e}"))
            continue
        (sim.append((ep.name, cls)) if getattr(cls, "sim_keys", None) else fit_only.append(ep.name))
    return tuple(sim), tuple(fit_only), tuple(failed)


def _plugin_keys(name: str, cls: type, spec: str) -> dict:
    keys = cls.sim_keys
    ok = isinstance(keys, dict) and all(
        isinstance(k, str) and isinstance(v, (tuple, list)) and len(v) == 2 and v[0] in PLUGIN_KEY_KINDS
        for k, v in keys.items())
    if not ok or not callable(getattr(cls, "simulate", None)):
        raise ConfigError(f"--effect {spec!r}: effect plug-in {name!r} ({cls.__module__}.{cls.__qualname__}) "
                          "needs sim_keys = {key: (kind, default)} with kind 'number' or 'text', and a method "
                          "simulate(values, edit) (docs/effect-plugins.md)")
    return dict(keys)


def _unknown(spec: str, name: str) -> ConfigError:
    sim, fit_only, failed = _plugins(tuple(sys.path))
    if name in fit_only:
        return ConfigError(f"--effect {spec!r}: effect {name!r} is installed (entry-point group {EFFECT_GROUP}) "
                           "for fitting only: its class sets no sim_keys/simulate, the physics a simulation needs "
                           "(docs/effect-plugins.md)")
    broken = dict(failed)
    if name in broken:
        return ConfigError(f"--effect {spec!r}: effect plug-in {name!r} (entry-point group {EFFECT_GROUP}) failed "
                           f"to load: {broken[name]}")
    listed = "; ".join(f"{n} ({', '.join(cls.sim_keys)})" for n, cls in sim) or "none"
    return ConfigError(f"--effect {spec!r}: unknown effect {name!r}; use {EFFECTS_HELP}. Installed plug-ins with "
                       f"physics: {listed}")


def parse_effect(spec: str) -> RealityEffect:
    s = str(spec).strip()
    name, _, rest = s.partition(":")
    plugin = None
    if name in KINDS:
        keys = KINDS[name].keys
    else:
        plugin = effect_plugins().get(name)
        if plugin is None:
            raise _unknown(spec, name)
        keys = _plugin_keys(name, plugin, spec)
    values = {k: d for k, (_, d) in keys.items()}
    for item in filter(None, (p.strip() for p in rest.split(","))):
        k, eq, v = item.partition("=")
        k = k.strip()
        if not eq or k not in keys:
            raise ConfigError(f"--effect {spec!r}: {item!r} is not key=value with a key of {name} "
                              f"({', '.join(keys)})")
        if keys[k][0] == "number":
            try:
                values[k] = float(v)
            except ValueError:
                raise ConfigError(f"--effect {spec!r}: {k}={v!r} is not a number") from None
            if not np.isfinite(values[k]):
                raise ConfigError(f"--effect {spec!r}: {k} must be finite")
        else:
            values[k] = v.strip()
    missing = [k for k, (t, d) in keys.items() if t == "number" and values[k] is None]
    if missing:
        raise ConfigError(f"--effect {spec!r}: give {', '.join(missing)} (e.g. {name}:{missing[0]}=...)")
    if name == "compliance" and values["k"] <= 0:
        raise ConfigError(f"--effect {spec!r}: k is a stiffness in N m/rad and must be > 0 (e.g. k=1e4)")
    if name == "encoder_scale" and values["scale"] <= -1:
        raise ConfigError(f"--effect {spec!r}: scale must be > -1 (a fraction, e.g. 0.005)")
    return RealityEffect(name, values, s, plugin)


def _plugin_truth(e: RealityEffect, out) -> dict:
    """A plug-in's truth as plain JSON values (NumPy scalars and arrays converted): it is
    written into every truth file's meta."""
    import json

    def plain(o):
        if hasattr(o, "tolist"):
            return o.tolist()
        raise TypeError(f"{type(o).__name__} is not a JSON value")

    if not isinstance(out, dict):
        raise ConfigError(f"--effect {e.spec!r}: effect plug-in {e.kind!r}: simulate() must return the truth as a "
                          f"dict (SI units), not {type(out).__name__}")
    try:
        return json.loads(json.dumps(out, default=plain))
    except (TypeError, ValueError) as err:
        raise ConfigError(f"--effect {e.spec!r}: effect plug-in {e.kind!r}: simulate()'s truth must hold JSON "
                          f"values (numbers, text, lists): {err}") from None


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


def _pose(R: np.ndarray, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, p
    return T


def _inv(T: np.ndarray) -> np.ndarray:
    return _pose(T[:3, :3].T, -T[:3, :3].T @ T[:3, 3])


ORIENTATIONS = ("quat", "axisangle", "euler", "xyaxes", "zaxis")  # an MJCF element's ways to write its rotation


def _orientation(el, compiler) -> np.ndarray:
    """The rotation matrix an MJCF body, site or geom element writes (any of MuJoCo's
    forms, in the model's compiler angle unit and Euler sequence)."""
    degrees = (compiler.angle or "degree") == "degree"
    if el.quat is not None:
        return from_wxyz(el.quat).as_matrix()
    if el.axisangle is not None:
        a = np.asarray(el.axisangle, float)
        return Rotation.from_rotvec(a[:3] / np.linalg.norm(a[:3]) * (np.radians(a[3]) if degrees else a[3])).as_matrix()
    if el.euler is not None:  # MuJoCo: lower case = rotating axes; SciPy: lower case = fixed axes
        return Rotation.from_euler((compiler.eulerseq or "xyz").swapcase(), el.euler, degrees=degrees).as_matrix()
    if el.xyaxes is not None:
        a = np.asarray(el.xyaxes, float)
        x = a[:3] / np.linalg.norm(a[:3])
        y = a[3:] - (a[3:] @ x) * x
        y /= np.linalg.norm(y)
        return np.column_stack([x, y, np.cross(x, y)])
    if el.zaxis is not None:
        z = np.asarray(el.zaxis, float) / np.linalg.norm(el.zaxis)
        c = np.cross([0.0, 0.0, 1.0], z)
        if np.linalg.norm(c) < 1e-12:
            return np.eye(3) if z[2] > 0 else Rotation.from_rotvec([np.pi, 0, 0]).as_matrix()
        return Rotation.from_rotvec(c / np.linalg.norm(c) * np.arctan2(np.linalg.norm(c), z[2])).as_matrix()
    return np.eye(3)


@dataclass(frozen=True)
class SoleFrame:
    """A leg's sole frame as the simulated robot has it: an MJCF site, or (leg map
    `sole: {body, pos, rpy}`) a pose on a body; `pose` in the robot frame at the zero
    posture, with the edits made so far. Give it to `ModelEdit.move` (and `rotate`,
    `translate`) to move the sole frame itself."""

    side: str
    body: str  # the MJCF body the sole is fixed to
    site: str | None  # the MJCF site that is the sole frame, or None (a leg-map pose on `body`)
    pose: np.ndarray  # (4, 4)


class ModelEdit:
    """The simulated robot being changed, handed to an effect plug-in's `simulate(values,
    edit)`; the built-in MJCF kinds use it too.

    Attributes:
      mjcf     the dm_control `mjcf.RootElement` of the simulated robot's MJCF copy: change
               it freely (bodies, joints, sites, geoms, sensors); it is exported with its
               assets once every effect has run
      legmap   the simulated robot's leg map (`LegMap`); a moved leg-map frame (`move` of a
               `sole` on a body) replaces it
      kin      `LegKinematics` of the simulated robot as loaded, before any edit (the legs'
               chains: `kin.poe[side].cols` the leg-map indices of a leg's joints, hip first)
      sensors  the simulated sensors (`legcal_bench.sim.sensors.SimSensors`); replace it
               (`dataclasses.replace`) to change a sensor's errors
      rng      NumPy generator of the collection seed, for a target the spec left out
      spec     the spec being applied (for messages)

    Poses and motions are 4x4 matrices in the robot's (pelvis) frame at the zero posture
    (leg joints at zero, held joints at their angles), computed by MuJoCo on the current
    copy: a motion D moves an element's pose T to D T."""

    def __init__(self, legmap: LegMap, sensors: SimSensors, rng: np.random.Generator, spec: str = ""):
        from dm_control import mjcf

        self.legmap, self.sensors, self.rng, self.spec = legmap, sensors, rng, spec
        self.mjcf = mjcf_element(legmap.mjcf)
        self._kin = None
        self._live = None  # (MjModel, MjData, inverse pelvis pose) at the zero posture

    @property
    def kin(self):
        if self._kin is None:
            from legcal_bench.robots.kinematics import LegKinematics

            self._kin = LegKinematics(self.legmap)
        return self._kin

    # ----------------------------------------------------------------- looking up
    def error(self, message: str) -> ConfigError:
        """A ConfigError about the spec being applied (raise it)."""
        return ConfigError(f"--effect {self.spec!r}: {message}")

    def choose(self, text: str | None, options, what: str) -> str:
        """`text` if it is one of `options`, a draw from `rng` if None, else a ConfigError."""
        return _choice(text, options, self.rng, self.spec, what)

    def joint(self, text: str | None, roles=None) -> int:
        """The leg-map index of the leg joint `text` names (side_role like `left_knee`, or the
        leg map's joint name; drawn if None), among `roles` if given."""
        return _resolve_joint(self.legmap, text, self.rng, self.spec, roles)

    def chain(self, side: str) -> list[int]:
        """Leg-map indices of `side`'s joints in chain order, pelvis to foot."""
        return [int(c) for c in self.kin.poe[side].cols]

    def joint_body(self, index: int):
        """The MJCF body element carrying leg joint `index` (leg-map order)."""
        return self.mjcf.find("joint", self.legmap.joint_names[index]).parent

    def find(self, kind: str, name: str):
        """The MJCF element of `kind` (body, site, geom, joint, ...) named `name`, or a ConfigError."""
        el = self.mjcf.find(kind, name)
        if el is None:
            raise self.error(f"no {kind} named {name!r} in {self.legmap.mjcf}")
        return el

    def sole(self, side: str) -> SoleFrame:
        """`side`'s sole frame as edited so far."""
        spec = self.legmap.legs[side].sole
        if spec.site is not None:
            site = self.find("site", spec.site)
            return SoleFrame(side, site.parent.full_identifier, spec.site, self.pose(site))
        body = self.find("body", spec.body)
        local = _pose(Rotation.from_euler("xyz", spec.rpy).as_matrix(), spec.pos)
        return SoleFrame(side, spec.body, None, self.pose(body) @ local)

    def collision_geoms(self, body) -> list:
        """The geoms directly on MJCF `body` (an element or its name) that collide (contype
        or conaffinity nonzero, defaults applied): a foot's contact surfaces."""
        import mujoco

        body = self.find("body", body) if isinstance(body, str) else body
        model = self._zero()[0]
        out = []
        for g in body.geom:
            gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, g.full_identifier)
            if model.geom_contype[gid] or model.geom_conaffinity[gid]:
                out.append(g)
        return out

    def pose(self, el) -> np.ndarray:
        """(4, 4) pose of a body, site or geom element (a geom's frame as written, before
        MuJoCo re-centres a mesh) in the robot frame at the zero posture."""
        if isinstance(el, SoleFrame):
            return self.sole(el.side).pose
        if el.tag == "body" or el is self.mjcf.worldbody:
            return self._body_pose(el)
        return self._body_pose(el.parent) @ self._local(el)

    def joint_anchor(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """(anchor point, unit axis) of leg joint `index` in the robot frame at the zero posture."""
        import mujoco

        model, data, inv_pelvis = self._zero()
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, self.legmap.joint_names[index])
        return inv_pelvis[:3, :3] @ data.xanchor[jid] + inv_pelvis[:3, 3], inv_pelvis[:3, :3] @ data.xaxis[jid]

    # ----------------------------------------------------------------- changing
    def move(self, el, D: np.ndarray) -> None:
        """Move a body (with everything on and below it), a site or a geom, or a `SoleFrame`
        (the sole frame itself), by the rigid motion D (4, 4; robot frame, zero posture)."""
        D = np.asarray(D, dtype=float)
        if isinstance(el, SoleFrame):
            return self._move_sole(el.side, D)
        T_p = self._body_pose(el.parent)
        D_p = _inv(T_p) @ D @ T_p  # the motion in the parent body's frame
        if el.tag in ("geom", "site") and el.fromto is not None:
            ends = np.asarray(el.fromto, float).reshape(2, 3) @ D_p[:3, :3].T + D_p[:3, 3]
            el.fromto = ends.ravel().tolist()
        else:
            T = D_p @ self._local(el)
            for attr in ORIENTATIONS:
                setattr(el, attr, None)
            el.pos, el.quat = T[:3, 3].tolist(), wxyz(Rotation.from_matrix(T[:3, :3])).tolist()
        if el.tag == "body":
            self._live = None

    def translate(self, el, vector) -> None:
        """`move` by a translation (m, robot frame at the zero posture)."""
        self.move(el, _pose(np.eye(3), np.asarray(vector, dtype=float)))

    def rotate(self, el, rotvec, point) -> None:
        """`move` by the rotation `rotvec` (axis times angle, rad, robot frame) about `point`
        (m, robot frame at the zero posture)."""
        R = Rotation.from_rotvec(np.asarray(rotvec, dtype=float)).as_matrix()
        point = np.asarray(point, dtype=float)
        self.move(el, _pose(R, point - R @ point))

    # ----------------------------------------------------------------- internals
    def _move_sole(self, side: str, D: np.ndarray) -> None:
        spec = self.legmap.legs[side].sole
        if spec.site is not None:
            return self.move(self.find("site", spec.site), D)
        T_b = self._body_pose(self.find("body", spec.body))
        T = _inv(T_b) @ D @ T_b @ _pose(Rotation.from_euler("xyz", spec.rpy).as_matrix(), spec.pos)
        frame = FrameSpec(body=spec.body, pos=tuple(float(x) for x in T[:3, 3]),
                          rpy=tuple(float(x) for x in Rotation.from_matrix(T[:3, :3]).as_euler("xyz")))
        legs = dict(self.legmap.legs)
        legs[side] = replace(legs[side], sole=frame)
        self.legmap = replace(self.legmap, legs=legs)

    def _local(self, el) -> np.ndarray:
        """An element's pose in its parent body's frame, as written."""
        if el.tag in ("geom", "site") and el.fromto is not None:
            a, b = np.asarray(el.fromto, float).reshape(2, 3)
            z = (b - a) / np.linalg.norm(b - a)
            c = np.cross([0.0, 0.0, 1.0], z)
            R = (Rotation.from_rotvec(c / np.linalg.norm(c) * np.arctan2(np.linalg.norm(c), z[2])).as_matrix()
                 if np.linalg.norm(c) > 1e-12 else np.eye(3))
            return _pose(R, (a + b) / 2)
        return _pose(_orientation(el, self.mjcf.compiler), el.pos if el.pos is not None else np.zeros(3))

    def _body_pose(self, body) -> np.ndarray:
        import mujoco

        model, data, inv_pelvis = self._zero()
        if body is self.mjcf.worldbody:
            return inv_pelvis
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body.full_identifier)
        return inv_pelvis @ _pose(data.xmat[bid].reshape(3, 3), data.xpos[bid])

    def _zero(self):
        """MuJoCo's compilation of the current copy at the zero posture (kept until a body moves)."""
        if self._live is None:
            import mujoco

            model = mujoco.MjModel.from_xml_string(self.mjcf.to_xml_string(), self.mjcf.get_assets())
            data = mujoco.MjData(model)
            data.qpos[:] = model.qpos0
            for name, angle in [(n, 0.0) for n in self.legmap.joint_names] + list(hold_angles(self.legmap).items()):
                data.qpos[model.jnt_qposadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)]] = angle
            mujoco.mj_kinematics(model, data)
            pelvis = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, self.legmap.pelvis)
            self._live = (model, data, _inv(_pose(data.xmat[pelvis].reshape(3, 3), data.xpos[pelvis])))
        return self._live

    def export(self, workdir: Path, springs=()) -> LegMap:
        """Write the copy (with its assets) into `workdir`, add the series `springs` ((leg
        index, k) of `compliance`), and return the simulated robot's leg map on it."""
        self._live = None
        model = self._zero()[0]  # the current copy (a joint_axis edit changes no body pose, yet counts here)
        workdir.mkdir(parents=True, exist_ok=True)
        name = f"{Path(self.legmap.mjcf).stem}_reality.xml"
        (workdir / name).write_text(self.mjcf.to_xml_string())  # as `mjcf.export_with_assets`, its assets ...
        _place_assets(self.mjcf, Path(self.legmap.mjcf).parent, workdir)  # ... linked where unchanged
        _add_series_springs(workdir / name, self.legmap, list(springs), model)
        # The edited MJCF is the model for Pinocchio too (a URDF robot's URDF is not edited).
        return replace(self.legmap, mjcf=(workdir / name).resolve(), urdf=None)


def _place_assets(model, source: Path, workdir: Path) -> None:
    """The assets of the MJCF `model` (meshes, textures), under the names its XML gives
    them (`name-sha1.ext`, dm_control's), in `workdir`: a link to the source model's own
    file where it is unchanged, else the contents written. (Copies of the G1's meshes
    were 19.5 MB a session set, written and deleted again.) The files looked for: those
    in the model's folder and its compiler's mesh, texture and asset folders."""
    from dm_control.mujoco.wrapper import util

    folders = {source} | {source / d for d in (model.compiler.meshdir, model.compiler.texturedir,
                                                model.compiler.assetdir) if d}
    originals = {p.name: p.resolve() for d in folders if d.is_dir() for p in d.iterdir() if p.is_file()}
    for vfs, contents in model.get_assets().items():
        data = util.to_binary_string(contents)
        stem, _, rest = vfs.rpartition("-")
        original = originals.get(stem + Path(rest).suffix)
        if original is not None and original.stat().st_size == len(data) and original.read_bytes() == data:
            (workdir / vfs).symlink_to(original)
        else:
            (workdir / vfs).write_bytes(data)


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
    floor, truth, springs = {}, [], []
    edit: ModelEdit | None = None

    def model(spec: str) -> ModelEdit:
        nonlocal edit
        if edit is None:
            edit = ModelEdit(sim_legmap, sensors, rng)
        edit.spec = spec
        return edit

    for e in effects:
        v = e.values
        if e.plugin is not None:
            ed = model(e.spec)
            ed.sensors = sensors
            out = _plugin_truth(e, e.plugin().simulate(dict(v), ed))
            sensors = ed.sensors
            truth.append({"effect": e.spec, "kind": e.kind, **out})
        elif e.kind == "imu_tilt":
            mount = np.array(sensors.errors.imu_mount_rpy, dtype=float)
            mount[:2] += np.deg2rad([v["roll"], v["pitch"]])
            sensors = replace(sensors, errors=replace(sensors.errors, imu_mount_rpy=tuple(float(x) for x in mount)))
            truth.append({"effect": e.spec, "kind": e.kind, "roll_rad": float(np.deg2rad(v["roll"])),
                          "pitch_rad": float(np.deg2rad(v["pitch"]))})
        elif e.kind == "encoder_scale":
            j = _resolve_joint(legmap, v["joint"], rng, e.spec)
            scale = np.array(sensors.encoder_scale if sensors.encoder_scale else np.zeros(legmap.n_joints), float)
            scale[j] += v["scale"]
            sensors = replace(sensors, encoder_scale=tuple(float(x) for x in scale) if np.any(scale) else ())
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
            axis = _choice(v["axis"], ABOUT, rng, e.spec, "axis") if e.kind == "link_offset" else None
            ed = model(e.spec)
            chain = ed.chain(side)
            roles = [legmap.joint_roles[c] for c in chain]
            k = roles.index("knee") if part == "thigh" else roles.index("knee") + 1
            far = ed.joint_body(chain[k])  # the far joint's body: it and all below it move
            u = ed.joint_anchor(chain[k])[0] - ed.joint_anchor(chain[k - 1])[0]  # the link's line, robot frame
            u /= np.linalg.norm(u)
            if e.kind == "link_length":
                ed.translate(far, u * v["mm"] * 1e-3)
                truth.append({"effect": e.spec, "kind": e.kind, "link": link, "length_m": v["mm"] * 1e-3})
            elif e.kind == "link_offset":
                ed.translate(far, np.eye(3)[ABOUT.index(axis)] * v["mm"] * 1e-3)
                truth.append({"effect": e.spec, "kind": e.kind, "link": link, "axis": axis,
                              "offset_m": v["mm"] * 1e-3})
            else:  # about the link's direction, through the far body's origin
                ed.rotate(far, u * np.deg2rad(v["deg"]), ed.pose(far)[:3, 3])
                truth.append({"effect": e.spec, "kind": e.kind, "link": link, "angle_rad": float(np.deg2rad(v["deg"]))})
        elif e.kind in ("mount_offset", "joint_offset"):
            if e.kind == "mount_offset":
                side = _choice(v["side"], SIDES, rng, e.spec, "side")
                j = model(e.spec).chain(side)[0]  # the leg's first joint, hip end
            else:
                j = _resolve_joint(legmap, v["joint"], rng, e.spec)
            axis = _choice(v["axis"], ABOUT, rng, e.spec, "axis")
            ed = model(e.spec)
            ed.translate(ed.joint_body(j), np.eye(3)[ABOUT.index(axis)] * v["mm"] * 1e-3)
            target = {"side": side} if e.kind == "mount_offset" else {}
            truth.append({"effect": e.spec, "kind": e.kind, **target, "joint": joint_label(legmap, j),
                          "body": ed.joint_body(j).name, "axis": axis, "offset_m": v["mm"] * 1e-3})
        elif e.kind in ("hip_axis", "joint_axis"):
            roles = ("hip_pitch", "hip_roll", "hip_yaw") if e.kind == "hip_axis" else None
            j = _resolve_joint(legmap, v["joint"], rng, e.spec, roles=roles)
            about = _choice(v["about"], ABOUT, rng, e.spec, "about")
            joint = model(e.spec).mjcf.find("joint", legmap.joint_names[j])
            axis = np.asarray(joint.axis if joint.axis is not None else (0, 0, 1), float)
            joint.axis = (Rotation.from_rotvec(np.eye(3)[ABOUT.index(about)] * np.deg2rad(v["deg"])).as_matrix()
                          @ axis).tolist()
            truth.append({"effect": e.spec, "kind": e.kind, "joint": joint_label(legmap, j), "about": about,
                          "angle_rad": float(np.deg2rad(v["deg"]))})
        elif e.kind == "compliance":
            j = _resolve_joint(legmap, v["joint"], rng, e.spec)
            model(e.spec)
            springs.append((j, v["k"]))
            truth.append({"effect": e.spec, "kind": e.kind, "joint": joint_label(legmap, j),
                          "stiffness_nm_per_rad": v["k"], "compliance_rad_per_nm": 1.0 / v["k"]})
    if edit is not None:
        sim_legmap = edit.export(Path(workdir), springs)
    return Reality(sim_legmap, sensors, floor, truth)


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

