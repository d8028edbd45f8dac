"""A policy spec: everything needed to run a published walking policy on a robot.

A small YAML file (`format: legcal-policy/1`) written by whoever has the policy, in
the words of its deployment config, never in code:

    format: legcal-policy/1
    name: my_walker
    model: {file: policy.pt, format: torchscript}   # torchscript | torch.export | onnx
    joints: [left_hip_pitch_joint, ...]   # the policy's joint order (names in the leg map)
    default_q: [...]                      # rad, in the policy's order
    action: {scale: 0.25, clip: null}     # target = default_q + scale * action
    pd: {kp: [...], kd: [...], torque_limit: null}   # per joint, the policy's order
    rates: {physics_hz: 500, control_hz: 50}
    command: [0.5, 0.0, 0.0]              # vx (m/s), vy (m/s), yaw rate (rad/s)
    observation:                          # in order; each term's values x scale, then clipped
      - {term: ang_vel, scale: 0.25}
      - {term: gravity}
      - {term: command, scale: [2.0, 2.0, 0.25]}
      - {term: joint_pos, scale: 1.0}     # minus default_q; optional mask: [joint names]
      - {term: joint_vel, scale: 0.05}
      - {term: last_action}
      - {term: phase, period: 0.8}        # sin, cos of one clock

Relative paths are relative to the spec file. Joints are mapped by name onto the leg
map (any order); a joint the leg map lacks is refused. The terms (`TERMS`) and what
each reads are in `legcal_bench.policies.observation`.
"""

from __future__ import annotations

import difflib
import numbers
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from legcal_bench.errors import ConfigError
from legcal_bench.inputs import read_text, shown

SPEC_FORMAT = "legcal-policy/1"
WALKERS_DIR = Path(__file__).resolve().parent / "walkers"  # our own policies: walkers/<robot>/policy.yaml
MODEL_FORMATS = ("torchscript", "torch.export", "onnx")
MAX_PHYSICS_HZ = 1e6  # a physics step of 1 us: any faster is a typo, not a setting


@dataclass(frozen=True)
class ObsTerm:
    term: str
    scale: tuple[float, ...] = (1.0,)  # one, or one per value
    clip: float | None = None
    mask: tuple[str, ...] | None = None  # joint terms: only these joints (names), in the policy's order
    period: float | None = None  # phase: the clock's period (s)
    offsets: tuple[float, ...] | None = None  # foot_phase: each foot's phase offset (fraction of a period)
    # gait_phase: per foot an angle initial[i] + 2 pi frequency t, laid out as `layout`
    # ("grouped": all cos then all sin; "interleaved": cos, sin per foot), frozen at its
    # initial value while the command is zero if `stop_at_zero_command`.
    frequency: float | None = None
    initial: tuple[float, ...] | None = None
    layout: str | None = None
    stop_at_zero_command: bool = False
    name: str | None = None  # sensor: the MJCF sensor's name
    size: int | None = None  # sensor: its values
    history: int = 1  # the last `history` control steps' values, oldest first (the first repeated after reset)


@dataclass(frozen=True)
class Hold:
    """A joint the policy does not drive, held by its servo at `q` (rad); `kp`, `kd` for
    PD servos (`actuators: pd`), None with the model's own actuators."""

    joint: str
    q: float
    kp: float | None = None
    kd: float | None = None


@dataclass(frozen=True)
class PolicySpec:
    name: str
    path: Path  # the spec file
    model_file: Path
    model_format: str
    joints: tuple[str, ...]
    default_q: tuple[float, ...]
    action_scale: float
    action_clip: float | None
    kp: tuple[float, ...]
    kd: tuple[float, ...]
    torque_limit: tuple[float, ...] | None
    physics_hz: float
    control_hz: float
    command: tuple[float, float, float]
    observation: tuple[ObsTerm, ...]
    notes: dict = field(default_factory=dict)
    # Whole-body policies and the simulation settings a policy was trained with.
    hold: tuple[Hold, ...] = ()  # actuated joints the policy does not drive, held
    actuators: str = "pd"  # pd: PD servos with kp, kd; model: the MJCF's own actuators
    action_clip_joints: tuple[float, ...] | None = None  # per-joint clip (policy order)
    action_clip_range: bool = False  # clip the joint targets to the joints' ranges (the MJCF's)
    floor_friction: tuple[float, float, float] | None = None  # sliding, torsional, rolling
    keyframe: str | int | None = None  # the MJCF keyframe the robot starts from
    # (time s, command) pairs, times increasing from 0: the command from each time on
    # (`command` when empty).
    command_schedule: tuple[tuple[float, tuple[float, float, float]], ...] = ()

    def command_at(self, t: float) -> tuple[float, float, float]:
        """The command at time `t` since reset."""
        out = self.command
        for start, command in self.command_schedule:
            if t + 1e-9 < start:
                break
            out = command
        return out

    @property
    def decimation(self) -> int:
        return int(round(self.physics_hz / self.control_hz))

    @property
    def settings(self) -> str:
        """The simulation settings the spec gives the walking env, in words (every result
        states them)."""
        parts = [f"{len(self.joints)} joints driven" + (f", {len(self.hold)} held" if self.hold else ""),
                 "the model's own actuators" if self.actuators == "model" else "PD servos",
                 f"physics {self.physics_hz:g} Hz, control {self.control_hz:g} Hz"]
        if self.floor_friction is not None:
            parts.append(f"floor friction {self.floor_friction[0]:g}")
        if self.keyframe is not None:
            parts.append(f"starting from keyframe {self.keyframe!r}")
        if self.command_schedule:
            parts.append("commands " + ", ".join(f"{list(c)} from {t:g} s" for t, c in self.command_schedule))
        return "; ".join(parts)

    @property
    def privileged(self) -> list[str]:
        """Terms the robot cannot measure, taken from the simulator."""
        from legcal_bench.policies.observation import TERMS

        return [t.term for t in self.observation if TERMS[t.term].privileged]


def _numbers(v, n: int | None, where: str, positive: bool = False, strict: bool = False) -> tuple[float, ...]:
    """`n` finite numbers (any count >= 1 with None), a list or one number; >= 0 with
    `positive`, > 0 with `strict`."""
    items = list(v) if isinstance(v, (list, tuple)) else [v]
    a = None
    if items and all(isinstance(x, numbers.Real) and not isinstance(x, bool) for x in items):
        try:
            a = np.array([float(x) for x in items])
        except OverflowError:
            a = None
    if a is None or not np.isfinite(a).all() or (n is not None and len(a) != n) or (
            positive and (a < 0).any()) or (strict and (a <= 0).any()):
        want = "one finite number" if n == 1 else f"{n} finite numbers" if n is not None else "finite numbers"
        raise ConfigError(f"{where}: must be {want}{' > 0' if strict else ' >= 0' if positive else ''}, got {shown(v)}")
    return tuple(float(x) for x in a)


def _unknown(where: str, d: dict, known, what: str = "fields") -> None:
    """Refuse keys of `d` not in `known`, each named with the closest known one (a
    misspelt key would otherwise be ignored)."""
    bad = [k for k in d if k not in known]
    if bad:
        hints = []
        for k in bad:
            close = difflib.get_close_matches(str(k), [str(x) for x in known], n=1)
            hints.append(repr(k) + (f" (did you mean {close[0]!r}?)" if close else ""))
        raise ConfigError(f"{where}: unknown {what} [{', '.join(hints)}]; known: {sorted(map(str, known))}")


def _holds(v, joints: list, actuators: str, w: str) -> tuple[Hold, ...]:
    """`hold: {joint: angle}` (model actuators) or `{joint: {q: angle, kp: .., kd: ..}}` (PD servos)."""
    if v is None:
        return ()
    if not isinstance(v, dict):
        raise ConfigError(f"{w}: field 'hold' must map joints the policy does not drive to the angle (rad) their "
                          f"servos hold, e.g. {{waist_yaw_joint: 0.0}}, got {shown(v)}")
    out = []
    for name, e in v.items():
        where = f"{w}: hold.{name}"
        if not isinstance(name, str) or not name:
            raise ConfigError(f"{where}: a held joint is named by its name in the robot's MJCF (a string)")
        if name in joints:
            raise ConfigError(f"{where}: the policy drives this joint ('joints'); hold only the others")
        e = e if isinstance(e, dict) else {"q": e}
        _unknown(where, e, ("q", "kp", "kd"), "keys (q in rad, kp, kd)")
        q = _numbers(e.get("q"), 1, f"{where}.q (rad)")[0]
        kp = kd = None
        if actuators == "pd":
            kp = _numbers(e.get("kp"), 1, f"{where}.kp (N m/rad; PD servos need gains)", strict=True)[0]
            kd = _numbers(e.get("kd"), 1, f"{where}.kd (N m s/rad)", True)[0]
        out.append(Hold(name, q, kp, kd))
    return tuple(out)


def builtin_policies() -> list[str]:
    """Names of our own shipped policies (`--policy a3` = policies/walkers/a3/policy.yaml)."""
    return sorted(p.parent.name for p in WALKERS_DIR.glob("*/policy.yaml"))


def resolve_policy(path: str | Path) -> Path:
    """A spec path from the working directory, else an installed example
    (`examples/<file>`) or the name of one of our shipped policies
    (`legcal_bench.files.packaged`)."""
    from legcal_bench.files.packaged import packaged

    return packaged(path, {name: WALKERS_DIR / name / "policy.yaml" for name in builtin_policies()})


def load_policy_spec(path: str | Path) -> PolicySpec:
    """Read and check a spec (a path, or a shipped policy's name); ConfigError naming
    the field and the fix."""
    import yaml

    from legcal_bench.policies.observation import TERMS

    path = resolve_policy(path)
    if not path.exists():
        raise ConfigError(f"policy spec {path}: no such file; give a spec YAML or one of our policies "
                          f"({', '.join(builtin_policies())})")
    text = read_text("policy spec", path, "policy spec")  # a folder, unreadable or not UTF-8: named
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise ConfigError(f"policy spec {path}: not a readable YAML file ({e})") from None
    except RecursionError:
        raise ConfigError(f"policy spec {path}: not a readable YAML file (nested too deeply)") from None
    w = f"policy spec {path}"
    if not isinstance(doc, dict) or doc.get("format") != SPEC_FORMAT:
        got = shown(doc.get("format")) if isinstance(doc, dict) else f"{shown(doc)} (the file is not a YAML mapping)"
        raise ConfigError(f"{w}: field 'format' must be {SPEC_FORMAT!r}, got {got} (see docs/policy-spec.md)")
    _unknown(w, doc, ("format", "name", "model", "joints", "default_q", "action", "pd", "rates", "command",
                      "observation", "notes", "hold", "actuators", "sim", "command_schedule"))
    name = doc.get("name", path.stem)
    if not isinstance(name, str) or not name.strip():
        raise ConfigError(f"{w}: field 'name' is {shown(name)}: give the policy's name (a string), or leave the "
                          "field out for the file's name")
    notes = doc.get("notes") or {}
    if not isinstance(notes, dict):
        raise ConfigError(f"{w}: field 'notes' is {shown(notes)}: notes are a mapping of your own keys to values "
                          "(e.g. {made_by: ..., source: ...})")
    model = doc.get("model")
    mfile = model.get("file") if isinstance(model, dict) else None
    if not isinstance(model, dict) or not isinstance(mfile, str) or not mfile.strip() or "\0" in mfile:
        raise ConfigError(f"{w}: field 'model' must be {{file: <path>, format: {' | '.join(MODEL_FORMATS)}}}, got "
                          f"{shown(model)}")
    _unknown(f"{w}: model", model, ("file", "format"), "keys")
    fmt = model.get("format")
    if not isinstance(fmt, str) or fmt not in MODEL_FORMATS:
        raise ConfigError(f"{w}: model.format {fmt!r}: use one of {MODEL_FORMATS}")
    model_file = (path.parent / Path(mfile).expanduser()).resolve()
    if model_file.is_dir():
        raise ConfigError(f"{w}: model.file {mfile!r} is a folder ({model_file}); give the network's file itself")
    if not model_file.is_file():
        from legcal_bench.files.packaged import EXTERNAL_HINT, from_examples

        raise ConfigError(f"{w}: model.file {mfile!r}: no such file ({model_file}); "
                          + (EXTERNAL_HINT if from_examples(path) else "paths are relative to the spec"))
    joints = doc.get("joints")
    if not isinstance(joints, list) or not joints or not all(isinstance(j, str) and j for j in joints) or len(
            set(joints)) != len(joints):
        raise ConfigError(f"{w}: field 'joints' must list the policy's joint names, each once, in its order, got "
                          f"{shown(joints)}")
    n = len(joints)
    default_q = _numbers(doc.get("default_q"), n, f"{w}: default_q (rad, one per joint)")
    action = doc.get("action", {})
    if not isinstance(action, dict):
        raise ConfigError(f"{w}: field 'action' must be {{scale: <number>, clip: <number or null>}}, got "
                          f"{shown(action)}")
    _unknown(f"{w}: action", action, ("clip", "scale"), "keys")
    scale = _numbers(action.get("scale", 1.0), 1, f"{w}: action.scale")[0]
    clip, clip_joints, clip_range = None, None, False
    if action.get("clip") == "joint_range":
        clip_range = True
    elif isinstance(action.get("clip"), list):
        clip_joints = _numbers(action["clip"], n, f"{w}: action.clip (one bound per joint)", strict=True)
    elif action.get("clip") is not None:
        clip = _numbers(action["clip"], 1, f"{w}: action.clip (a number, one per joint, or joint_range)",
                        strict=True)[0]
    actuators = doc.get("actuators", "pd")
    if not isinstance(actuators, str) or actuators not in ("pd", "model"):
        raise ConfigError(f"{w}: field 'actuators' is {shown(actuators)}: use pd (PD servos with pd.kp, pd.kd) or "
                          "model (the robot's MJCF actuators, their gains and ranges)")
    pd = doc.get("pd")
    if actuators == "model" and pd is None:
        pd = {"kp": [0.0] * n, "kd": [0.0] * n}  # unused: the model's actuators
    if not isinstance(pd, dict):
        raise ConfigError(f"{w}: field 'pd' must be {{kp: [...], kd: [...]}} (N m/rad, N m s/rad, one per joint), "
                          f"got {shown(pd)}")
    _unknown(f"{w}: pd", pd, ("kp", "kd", "torque_limit"), "keys")
    # PD servos need stiffness on every joint; with the model's actuators the gains are unused.
    kp = _numbers(pd.get("kp"), n, f"{w}: pd.kp (N m/rad, one per joint)", True, strict=actuators == "pd")
    kd = _numbers(pd.get("kd"), n, f"{w}: pd.kd (N m s/rad, one per joint)", True)
    tl = None if pd.get("torque_limit") is None else _numbers(pd["torque_limit"], n, f"{w}: pd.torque_limit (N m)",
                                                              strict=True)
    hold = _holds(doc.get("hold"), joints, actuators, w)
    sim = doc.get("sim") or {}
    if not isinstance(sim, dict) or set(sim) - {"floor_friction", "keyframe"}:
        raise ConfigError(f"{w}: field 'sim' must be {{floor_friction: <number or [sliding, torsional, rolling]>, "
                          f"keyframe: <name or index>}}, got {shown(sim)}")
    friction = None
    if sim.get("floor_friction") is not None:
        f = _numbers(sim["floor_friction"], None, f"{w}: sim.floor_friction", True)
        if len(f) not in (1, 3):
            raise ConfigError(f"{w}: sim.floor_friction: one number (sliding) or three (sliding, torsional, rolling)")
        friction = (f[0], 0.005, 0.0001) if len(f) == 1 else f
    keyframe = sim.get("keyframe")
    if keyframe is not None and (isinstance(keyframe, bool) or not isinstance(keyframe, (str, int))
                                 or (isinstance(keyframe, int) and keyframe < 0)):
        raise ConfigError(f"{w}: sim.keyframe is {shown(keyframe)}: give a keyframe's name or index (>= 0) in the "
                          "robot's MJCF")
    rates = doc.get("rates", {})
    if not isinstance(rates, dict):
        raise ConfigError(f"{w}: field 'rates' must be {{physics_hz: ..., control_hz: ...}}, got {shown(rates)}")
    _unknown(f"{w}: rates", rates, ("physics_hz", "control_hz"), "keys")
    physics_hz = _numbers(rates.get("physics_hz", 500), 1, f"{w}: rates.physics_hz", strict=True)[0]
    control_hz = _numbers(rates.get("control_hz", 50), 1, f"{w}: rates.control_hz", strict=True)[0]
    if physics_hz > MAX_PHYSICS_HZ:
        raise ConfigError(f"{w}: rates.physics_hz = {physics_hz:g}: at most {MAX_PHYSICS_HZ:g} (a physics step of "
                          "1 us); give the rate the policy was trained with")
    ratio = physics_hz / control_hz
    if physics_hz < control_hz or abs(ratio - round(ratio)) > 1e-6:
        raise ConfigError(f"{w}: rates: physics_hz ({physics_hz:g}) must be a whole multiple of control_hz "
                          f"({control_hz:g})")
    command = _numbers(doc.get("command", [0.0, 0.0, 0.0]), 3, f"{w}: command [vx m/s, vy m/s, yaw rate rad/s]")
    schedule = []
    entries = doc.get("command_schedule") or []
    if not isinstance(entries, list):
        raise ConfigError(f"{w}: field 'command_schedule' is {shown(entries)}: list {{t: <s since reset>, "
                          "command: [vx, vy, yaw rate]} entries, times increasing")
    for i, e in enumerate(entries):
        where = f"{w}: command_schedule[{i}]"
        if not isinstance(e, dict) or set(e) != {"t", "command"}:
            raise ConfigError(f"{where}: give {{t: <s since reset>, command: [vx, vy, yaw rate]}}, got {shown(e)}")
        t_i = _numbers(e["t"], 1, f"{where}.t (s)", True)[0]
        if schedule and t_i <= schedule[-1][0]:
            raise ConfigError(f"{where}.t: times must increase ({t_i:g} after {schedule[-1][0]:g})")
        schedule.append((t_i, _numbers(e["command"], 3, f"{where}.command [vx, vy, yaw rate]")))
    obs = doc.get("observation")
    if not isinstance(obs, list) or not obs:
        raise ConfigError(f"{w}: field 'observation' must list the observation terms in order (terms: "
                          f"{', '.join(TERMS)}), got {shown(obs)}")
    terms = []
    for i, t in enumerate(obs):
        wt = f"{w}: observation[{i}]"
        if not isinstance(t, dict) or not isinstance(t.get("term"), str) or t["term"] not in TERMS:
            raise ConfigError(f"{wt}: 'term' must be one of {list(TERMS)}, got {shown(t)}")
        _unknown(wt, t, ("term", "scale", "clip", "mask", "period", "offsets", "frequency", "initial", "layout",
                         "stop_at_zero_command", "name", "size", "history"), "keys")
        gait = {}
        if t["term"] == "gait_phase":
            gait["frequency"] = _numbers(t.get("frequency"), 1, f"{wt}: frequency (Hz)", strict=True)[0]
            gait["initial"] = _numbers(t.get("initial", [0.0, np.pi]), None, f"{wt}: initial (rad, one per foot)")
            gait["layout"] = t.get("layout", "grouped")
            if not isinstance(gait["layout"], str) or gait["layout"] not in ("grouped", "interleaved"):
                raise ConfigError(f"{wt}: layout {gait['layout']!r}: grouped ([cos f1, cos f2, ..., sin f1, ...]) or "
                                  "interleaved ([cos f1, sin f1, cos f2, sin f2, ...])")
            stop = t.get("stop_at_zero_command", False)
            if not isinstance(stop, bool):
                raise ConfigError(f"{wt}: stop_at_zero_command is {shown(stop)}: true or false")
            gait["stop_at_zero_command"] = stop
        if t["term"] == "sensor":
            size = t.get("size")
            if not isinstance(t.get("name"), str) or not t["name"] or isinstance(size, bool) or not isinstance(
                    size, int) or size < 1:
                raise ConfigError(f"{wt}: term sensor needs 'name' (an MJCF sensor of the robot) and 'size' (its "
                                  f"values, e.g. 3), got name {shown(t.get('name'))}, size {shown(size)}")
            gait.update(name=t["name"], size=size)
        history = t.get("history", 1)
        if isinstance(history, bool) or not isinstance(history, int) or history < 1:
            raise ConfigError(f"{wt}: history must be a whole number of control steps >= 1 (the last k frames of "
                              f"the term, oldest first), got {shown(history)}")
        gait["history"] = history
        mask = t.get("mask")
        if mask is not None:
            if not TERMS[t["term"]].per_joint:
                raise ConfigError(f"{wt}: 'mask' applies to joint terms only "
                                  f"({[k for k, v in TERMS.items() if v.per_joint]})")
            if not isinstance(mask, list) or not all(isinstance(m, str) and m in joints for m in mask):
                raise ConfigError(f"{wt}: 'mask' must list joint names from 'joints', got {shown(mask)}")
        period = t.get("period")
        if TERMS[t["term"]].needs_period:
            if period is None:
                raise ConfigError(f"{wt}: term {t['term']!r} needs 'period' (s)")
            period = _numbers(period, 1, f"{wt}: period (s)", strict=True)[0]
        offsets = None
        if t["term"] == "foot_phase":
            offsets = _numbers(t.get("offsets", [0.0, 0.5]), None, f"{wt}: offsets (fractions of a period)")
        terms.append(ObsTerm(t["term"], _numbers(t.get("scale", 1.0), None, f"{wt}: scale"),
                             None if t.get("clip") is None else _numbers(t["clip"], 1, f"{wt}: clip", strict=True)[0],
                             tuple(mask) if mask is not None else None, period, offsets, **gait))
    spec = PolicySpec(name, path, model_file, fmt, tuple(joints), default_q, scale, clip,
                      kp, kd, tl, physics_hz, control_hz, command, tuple(terms), notes,
                      hold=hold, actuators=actuators, action_clip_joints=clip_joints, action_clip_range=clip_range,
                      floor_friction=friction, keyframe=keyframe, command_schedule=tuple(schedule))
    from legcal_bench.policies.observation import observation_size

    for i, t in enumerate(spec.observation):
        size = observation_size(spec, (t,))
        if len(t.scale) not in (1, size):
            raise ConfigError(f"{w}: observation[{i}] ({t.term}): scale has {len(t.scale)} values; give 1 or {size}")
    return spec
