"""An effect plug-in for legcal-bench: a sole plate bent about its pitch axis.

Each foot's sole plate may sit pitched by a small angle relative to the ankle (a bent or
badly shimmed plate). The fitting model is one angle per leg, a rotation about the sole
frame's y axis right after the sole frame (the last element of the leg's chain, M_sole);
the physics for simulation turns the sole frame and the foot's collision geoms of one
leg by that angle about the sole's origin, so a welded sole and a sole on a contact
floor both meet a bent plate.

About y it is separable from the offsets: after an ankle-roll joint, the rotation
R_x(q_roll) R_y(a) is an ankle-pitch offset only while q_roll = 0; the stances' ankle-roll
excursions turn part of it into a yaw of the sole. About x it would be an ankle-roll
offset (up to a millimetre's shift of the sole) and could not be told from one.

Installed with `pip install -e docs/examples/effect_plugin` (the entry point in
pyproject.toml, group `legcal_bench.effects`); docs/effect-plugins.md walks through it.
"""

import numpy as np

from legcal_bench.estimation.modelgap.effects import Effect
from legcal_bench.robots.legmap import SIDES

LIMIT_RAD = np.deg2rad(5.0)  # a plate bent further than this is broken, not miscalibrated


class SoleBend(Effect):
    name = "sole_bend"
    summary = "each sole plate pitched relative to its ankle (about the sole's y axis)"
    remedy = "stances with wider ankle-roll excursions (or the soles' pitch measured on a surface plate)"

    # Fitting model: parameters, where they enter the chain, their admissible range.
    def parameters(self, kin):
        return [(f"{side}_pitch", "rad") for side in SIDES]

    def factors(self, kin):
        out = []
        for i, side in enumerate(SIDES):
            after = 2 * len(kin.poe[side].cols)  # element 2k: M_sole, the chain's last (k joints)
            gens = np.zeros((len(SIDES), 6))
            gens[i, 4] = 1.0  # twist [v, w]: a rotation about the sole frame's y axis, through its origin
            out.append((side, after, gens))
        return out

    def bounds(self, kin):
        return [(-LIMIT_RAD, LIMIT_RAD)] * len(SIDES)

    # Physics for simulation: `collect --effect sole_bend:side=left,deg=1`.
    sim_keys = {"side": ("text", None), "deg": ("number", None)}

    def simulate(self, values, edit):
        side = edit.choose(values["side"], SIDES, "side")
        angle = float(np.deg2rad(values["deg"]))
        sole = edit.sole(side)
        axis, origin = sole.pose[:3, 1], sole.pose[:3, 3]  # the sole's y axis and origin, robot frame
        for geom in edit.collision_geoms(sole.body):
            edit.rotate(geom, axis * angle, origin)
        edit.rotate(sole, axis * angle, origin)
        return {"side": side, "angle_rad": angle}
