"""The arena: a flat floor, its contact parameters, and the lighting, separate from
any robot (dm_control's arena/robot split). Scenes add a robot to it."""

from __future__ import annotations

from dm_control import mjcf

from legcal_bench.errors import ConfigError

# The static contact floor (docs/contact-floor.md has the table and its reasons; fixed
# before issue #38's work on the contact floor began). A rubber sole pad (Shore A ~60,
# E ~3.6 MPa, 5 mm) over the whole sole sinks 16 um under half the A3-like robot's
# weight, 21 um under the G1's; over half the sole, twice that. The floor owns the
# contact's parameters (geom priority): MuJoCo would otherwise average its solref and
# solimp with the robot's foot geoms' (their defaults, timeconst 0.02 s), and the soles
# sank 265 um (A3-like, results version 8 and before; contact-floor with priority 0); with the floor's own, 32 um
# (`legcal-bench contact-floor` measures it per robot). Friction: dry rubber on a hard
# floor, 1.2 sliding; torsional and rolling as the static floor has had since issue #5.
FLOOR_FRICTION = (1.2, 0.02, 0.002)
FLOOR_SOLREF = (0.004, 1.0)
FLOOR_SOLIMP = (0.9, 0.95, 0.001, 0.5, 2.0)
FLOOR_PRIORITY = 1  # above every robot geom's default 0: the floor's parameters hold


# `floor_parameters`: the keys a floor spec may set, and what each replaces.
FLOOR_KEYS = {
    "timeconst": "solref[0], s",
    "dampratio": "solref[1]",
    "dmin": "solimp[0]",
    "dmax": "solimp[1]",
    "friction": "sliding friction",
}


def floor_parameters(spec: str | None) -> dict:
    """The static contact floor's parameters with `spec` ("key=value,...", keys of
    FLOOR_KEYS; None or "": the table's) applied, as add_floor's keyword arguments.
    ConfigError naming the key and the fix."""
    solref, solimp, friction = list(FLOOR_SOLREF), list(FLOOR_SOLIMP), list(FLOOR_FRICTION)
    for item in filter(None, (spec or "").split(",")):
        key, _, value = item.partition("=")
        key = key.strip()
        if key not in FLOOR_KEYS:
            raise ConfigError(f"floor {spec!r}: unknown key {key!r}; use key=value pairs of {sorted(FLOOR_KEYS)}")
        try:
            v = float(value)
        except ValueError:
            raise ConfigError(f"floor {spec!r}: {key}={value!r} is not a number") from None
        if not v > 0 or (key in ("dmin", "dmax") and v >= 1):
            raise ConfigError(f"floor {spec!r}: {key}={v:g} must be positive" + (" and below 1" if key in ("dmin", "dmax")
                                                                                 else ""))
        if key == "timeconst":
            solref[0] = v
        elif key == "dampratio":
            solref[1] = v
        elif key == "dmin":
            solimp[0] = v
        elif key == "dmax":
            solimp[1] = v
        else:
            friction[0] = v
    return {"solref": tuple(solref), "solimp": tuple(solimp), "friction": tuple(friction)}


def add_floor(m: mjcf.RootElement, contact: bool, static_friction: bool = True,
              friction: tuple = FLOOR_FRICTION, solref: tuple = FLOOR_SOLREF, solimp: tuple = FLOOR_SOLIMP,
              condim: int | None = None, priority: bool = False) -> None:
    """A light and a checkered plane at z = 0. With `contact`, the floor collides;
    `static_friction` (for standing still) makes friction behave as static: soft
    friction lets loaded soles creep by millimetres, so an elliptic cone with a high
    impedance ratio and a no-slip pass are used, with torsional and rolling friction
    (condim 6), and the floor's parameters define its contacts (`FLOOR_PRIORITY`).
    Without it (walking) the floor takes the given contact parameters, mixed with the
    feet's as MuJoCo mixes them (the larger friction), or with `priority` its own (a
    policy's training floor), and sliding friction only (condim 3). Explicit `<pair>`
    contacts in a robot's model keep their own parameters. Without contact, every contact is disabled
    (nothing else in a static scene needs one)."""
    m.worldbody.add("light", pos=[0, -1, 3], dir=[0, 0.3, -1], directional=True, diffuse=[0.7, 0.7, 0.7])
    tex = m.asset.add("texture", name="legcal_grid", type="2d", builtin="checker", width=256, height=256,
                      rgb1=[0.82, 0.84, 0.86], rgb2=[0.72, 0.74, 0.78])
    mat = m.asset.add("material", name="legcal_floor", texture=tex, texrepeat=[8, 8], texuniform=True)
    collide = 1 if contact else 0
    floor = m.worldbody.add("geom", name="legcal_floor", type="plane",
                            size=[5, 5, 0.1] if static_friction else [30, 30, 0.1], material=mat,
                            contype=collide, conaffinity=collide, friction=list(friction),
                            condim=condim or (6 if static_friction else 3), solref=list(solref), solimp=list(solimp))
    if static_friction or priority:  # `priority` (walking): the floor's friction, not the larger of the two
        floor.priority = FLOOR_PRIORITY
    if contact and static_friction:
        m.option.cone = "elliptic"
        m.option.impratio = 10
        m.option.noslip_iterations = 5
    elif not contact:
        m.option.flag.contact = "disable"
