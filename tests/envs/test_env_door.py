"""The envs' door (issue #42): a bad keyword argument, reset option or action is refused
with a LegcalError naming it and the fix -- at construction (also through `gym.make`)
or at `step` -- never a traceback from the physics; good ones still reset and step."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import legcal_bench.envs
from legcal_bench.envs import env_id
from legcal_bench.sim.double_support import physics_timing
from legcal_bench.envs.static_double_support import StaticDoubleSupportEnv
from legcal_bench.envs.walking import WalkingEnv
from legcal_bench.errors import ConfigError, LegcalError

gym.register_envs(legcal_bench.envs)
pytestmark = pytest.mark.filterwarnings("ignore::DeprecationWarning")

STATIC = dict(robot="a3", mode="kinematic", information_reward=False)  # the cheapest static env
WALKING = dict(robot="a3", sensors="zero")

# (kwargs over the cheap ones, the field the message must name)
STATIC_KWARGS = [
    (dict(rate_hz=0), "rate_hz"),
    (dict(rate_hz=-50), "rate_hz"),
    (dict(rate_hz=1e6), "rate_hz"),
    (dict(rate_hz=5000.0), "rate_hz"),  # 0.2 ms a frame with a 1 ms physics step: the clock outruns the physics
    (dict(rate_hz=30.0), "rate_hz"),  # 33.3 physics steps a frame: not a whole number
    (dict(rate_hz=50.0, physics_dt=0.003), "physics_dt"),
    (dict(rate_hz="abc"), "rate_hz"),
    (dict(rate_hz=float("nan")), "rate_hz"),
    (dict(physics_dt=0), "physics_dt"),
    (dict(physics_dt=-0.001), "physics_dt"),
    (dict(physics_dt=1.0), "physics_dt"),
    (dict(offset_seed="x"), "offset_seed"),
    (dict(offset_seed=-1), "offset_seed"),
    (dict(offset_seed=1.5), "offset_seed"),
    (dict(mode="wled"), "mode"),
    (dict(offsets="papr"), "offsets"),
    (dict(offsets=[0.01, 0.02]), "offsets"),
    (dict(sensors="relistic"), "sensors"),
    (dict(sim_robot="zz"), "sim_robot"),
    (dict(knee_straight_error_rad=float("nan")), "knee_straight_error_rad"),
    (dict(knee_straight_error_rad=3.0), "knee_straight_error_rad"),
    (dict(settle_s=-1), "settle_s"),
    (dict(settle_s=1e9), "settle_s"),
    (dict(information_reward="no"), "information_reward"),
    (dict(render_mode="human"), "render_mode"),
    (dict(standing="cp"), "standing"),
    (dict(rate=50), "rate_hz"),  # a misspelt argument: the closest one is named
]
WALKING_KWARGS = [
    (dict(offset_seed="x"), "offset_seed"),
    (dict(offset_seed=2**40), "offset_seed"),
    (dict(policy=3), "policy"),
    (dict(policy="nowhere.yaml"), "policy"),
    (dict(walking="x"), "walking"),
    (dict(width=0), "width"),
    (dict(height=-5), "height"),
    (dict(render_mode="rgb_array", width=4000), "width"),  # past the model's offscreen buffer
    (dict(offsets="papr"), "offsets"),
    (dict(correction=[1.0, 2.0]), "correction"),
    (dict(correction="x"), "correction"),
    (dict(sensors="x"), "sensors"),
    (dict(render_mode="human"), "render_mode"),
    (dict(offset=0.1), "offsets"),
]


def _refused(make, field: str):
    with pytest.raises(LegcalError) as e:
        make()
    assert field in str(e.value), str(e.value)
    return e.value


@pytest.mark.parametrize("kwargs, field", STATIC_KWARGS, ids=lambda v: repr(v) if isinstance(v, dict) else v)
def test_static_env_refuses_a_bad_keyword_argument(kwargs, field):
    _refused(lambda: StaticDoubleSupportEnv(**{**STATIC, **kwargs}), field)


@pytest.mark.parametrize("kwargs, field", WALKING_KWARGS, ids=lambda v: repr(v) if isinstance(v, dict) else v)
def test_walking_env_refuses_a_bad_keyword_argument(kwargs, field):
    _refused(lambda: WalkingEnv(**{**WALKING, **kwargs}), field)


@pytest.mark.parametrize("kind, kwargs, field", [
    ("StaticDoubleSupport", dict(mode="kinematic", rate_hz=0), "rate_hz"),
    ("StaticDoubleSupport", dict(mode="kinematic", physics_dt=0), "physics_dt"),
    ("StaticDoubleSupport", dict(mode="kinematic", rate_hz=1e6), "rate_hz"),
    ("StaticDoubleSupport", dict(mode="kinematic", offset_seed="x"), "offset_seed"),
    ("StaticDoubleSupport", dict(mode="kinematic", rat_hz=50), "rate_hz"),
    ("Walking", dict(sensors="zero", offset_seed="x"), "offset_seed"),
])
def test_gym_make_refuses_alike(kind, kwargs, field):
    e = _refused(lambda: gym.make(env_id("A3", kind), **kwargs), field)
    assert isinstance(e, ConfigError)


def _nan_at(i: int):
    return lambda a: np.where(np.arange(a.size) == i, np.nan, a)


# (what is done to a good action, ...): each refused at step, naming the action.
BAD_ACTIONS = [
    ("nan", _nan_at(0)),
    ("nan-last", lambda a: np.where(np.arange(a.size) == a.size - 1, np.nan, a)),
    ("inf", lambda a: a + np.inf),
    ("-inf", lambda a: np.where(np.arange(a.size) == 1, -np.inf, a)),
    ("short", lambda a: a[:-1]),
    ("long", lambda a: np.r_[a, 0.0]),
    ("empty", lambda a: np.zeros(0)),
    ("scalar", lambda a: 0.0),
    ("strings", lambda a: ["x"] * a.size),
    ("None", lambda a: None),
    ("nested", lambda a: [a.tolist(), a.tolist()]),
]


@pytest.fixture(scope="module")
def weld_env():
    env = StaticDoubleSupportEnv(robot="a3", mode="weld", settle_s=0.05, information_reward=False)
    env.reset(seed=0)
    return env


@pytest.fixture(scope="module")
def walking_env():
    env = WalkingEnv(**WALKING)
    env.reset(seed=0)
    return env


@pytest.mark.parametrize("name, bad", BAD_ACTIONS, ids=[b[0] for b in BAD_ACTIONS])
def test_static_env_refuses_a_bad_action_in_weld_mode(weld_env, name, bad):
    good = weld_env.sim.posture
    before = weld_env.sim.time
    e = _refused(lambda: weld_env.step(bad(good)), "action")
    assert "pelvis posture" in str(e) and weld_env.sim.time == before  # nothing was simulated


@pytest.mark.parametrize("name, bad", BAD_ACTIONS, ids=[b[0] for b in BAD_ACTIONS])
def test_walking_env_refuses_a_bad_action(walking_env, name, bad):
    good = np.asarray(walking_env.sim.config.default_q)
    before = walking_env.sim.time
    e = _refused(lambda: walking_env.step(bad(good)), "action")
    assert "joint position targets" in str(e) and walking_env.sim.time == before


def test_gym_make_refuses_a_nan_action_at_step():
    env = gym.make(env_id("A3"), mode="kinematic", information_reward=False)
    _, info = env.reset(seed=0)
    _refused(lambda: env.step(np.full(6, np.nan)), "action")


@pytest.mark.parametrize("options, field", [
    ({"stance": "V"}, "stance"), ({"stanse": "I"}, "stance"), ({"jitter_m": "x"}, "jitter_m"),
    ({"jitter_m": -0.1}, "jitter_m"), ({"jitter_rad": np.nan}, "jitter_rad"), ("I", "reset options")])
def test_static_env_refuses_bad_reset_options(options, field):
    env = StaticDoubleSupportEnv(**STATIC)
    _refused(lambda: env.reset(seed=0, options=options), field)


@pytest.mark.parametrize("seed", [-1, 2**32, 1.5, "x"])
def test_both_envs_refuse_a_bad_reset_seed_by_the_one_rule(walking_env, seed):
    _refused(lambda: StaticDoubleSupportEnv(**STATIC).reset(seed=seed), "reset seed")
    _refused(lambda: walking_env.reset(seed=seed), "reset seed")


@pytest.mark.parametrize("options, field", [({"offsets": "papr"}, "offsets"), ({"correction": [0.1]}, "correction"),
                                            ({"corection": None}, "correction")])
def test_walking_env_refuses_bad_reset_options(walking_env, options, field):
    _refused(lambda: walking_env.reset(seed=0, options=options), field)


@pytest.mark.parametrize("kwargs", [
    dict(), dict(rate_hz=100.0), dict(rate_hz="50", physics_dt=0.002), dict(rate_hz=30.0, physics_dt=1 / 3000),
    dict(rate_hz=1000.0), dict(offset_seed=2**32 - 1, offsets="random:1"), dict(offset_seed=np.int64(3)),
    dict(knee_straight_error_rad=-0.01, settle_s=0), dict(information_reward=np.bool_(True)), dict(standing="none")])
def test_good_static_arguments_still_reset_and_step(kwargs):
    env = StaticDoubleSupportEnv(**{**STATIC, **kwargs})
    obs, info = env.reset(seed=1, options={"stance": "I", "jitter_m": 0.0})
    obs, reward, term, trunc, info = env.step(info["posture"].tolist())  # a list is an action too
    assert env.observation_space.contains(obs) and info["posture_reachable"] and not term
    assert env.metadata["render_fps"] == round(float(kwargs.get("rate_hz", 50)))
    assert env.dt == pytest.approx(1 / float(kwargs.get("rate_hz", 50)), rel=1e-9)
    # A finite posture outside the action space is clipped, as documented.
    env.step(env.action_space.high + 1.0)


def test_good_walking_arguments_still_reset_and_step():
    env = gym.make(env_id("A3", "Walking"), sensors="zero", offset_seed=7, offsets="random:1", width=320, height=240)
    obs, _ = env.reset(seed=0, options={"correction": None})
    u = env.unwrapped
    obs, reward, term, _, info = env.step(np.asarray(u.sim.config.default_q)[None])  # (1, n): reshaped as before
    assert env.observation_space.contains(obs) and not term and u.offsets.shape == (12,)


def test_physics_timing_is_the_simulators_stepping_rule():
    assert physics_timing(50, 0.001) == (50.0, 0.001, 20)
    assert physics_timing(30, 1 / 3000)[2] == 100
    assert physics_timing(1000, 0.001)[2] == 1
    with pytest.raises(ConfigError, match=r"rate_hz = 2000: out of range, .*at most 1000: one frame per 1 ms physics step"):
        physics_timing(2000, 0.001)
    with pytest.raises(ConfigError, match=r"whole number of physics steps, and is 33.3333; give physics_dt = "
                                          r"1 / \(34 x rate_hz\)"):
        physics_timing(30, 0.001)
