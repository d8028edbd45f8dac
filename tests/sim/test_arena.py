"""The contact floor's parameters (issue #38, docs/contact-floor.md): what the table says
is what the soles stand on, and a robustness spec changes one of them, checked."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from legcal_bench.errors import ConfigError
from legcal_bench.robots import load_robot
from legcal_bench.sim.arena import FLOOR_FRICTION, FLOOR_SOLIMP, FLOOR_SOLREF, floor_parameters
from legcal_bench.sim.double_support import DoubleSupportSim
from legcal_bench.sim.sensors import sim_sensors


def _sole_contacts(floor=None):
    lm = load_robot("a3")
    sim = DoubleSupportSim(lm, "contact", np.zeros(lm.n_joints), sim_sensors("zero"), settle_s=0.2,
                           contact_floor=floor)
    from legcal_bench.protocol.stances import STANCES, fit_stance, settled_placement

    pl = settled_placement(fit_stance(STANCES["I"], sim.nominal).stance, sim.true_kin)
    sim.reset(pl.left, pl.right, pl.nominal)
    d, m = sim.data, sim.scene.model
    floor_geom = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "legcal_floor")
    # Copies: the contacts are views into the simulation's data, gone with it.
    return [(d.contact[i].solref.copy(), d.contact[i].solimp.copy(), d.contact[i].friction.copy())
            for i in range(d.ncon) if floor_geom in (d.contact[i].geom1, d.contact[i].geom2)]


def test_the_soles_stand_on_the_tables_parameters():
    """Until results version 9 MuJoCo averaged them with the feet's defaults (timeconst
    0.012 s in the contacts, where the table says 0.004 s)."""
    contacts = _sole_contacts()
    assert len(contacts) >= 8
    for solref, solimp, friction in contacts:
        assert np.allclose(solref, FLOOR_SOLREF) and np.allclose(solimp, FLOOR_SOLIMP)
        assert friction[0] == pytest.approx(FLOOR_FRICTION[0])


def test_a_floor_spec_changes_one_parameter_and_is_checked():
    contacts = _sole_contacts(floor_parameters("timeconst=0.008,friction=0.8"))
    assert contacts and all(solref[0] == pytest.approx(0.008) and friction[0] == pytest.approx(0.8)
                            for solref, _, friction in contacts)
    for spec, message in (("stiff=2", r"unknown key 'stiff'; use key=value pairs of \['dampratio'"),
                          ("timeconst=-1", r"timeconst=-1 must be positive"),
                          ("dmax=1.2", r"dmax=1.2 must be positive and below 1"),
                          ("friction=high", r"friction='high' is not a number")):
        with pytest.raises(ConfigError, match=message):
            floor_parameters(spec)
