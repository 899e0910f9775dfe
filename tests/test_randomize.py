"""Domain randomisation during training (pamrun/task/randomize.py) and the gait reward options
(reward.kstop, reward.kspeed, train.walk_weights)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pamrun.config import ConfigError, to_object
from pamrun.task.env import PamWalkerEnv
from pamrun.task.reward import REWARD_KEYS
from pamrun.task.spec import EnvSpec
from tests.conftest import compose_config


def walker(cfg, names, prob=1.0, reach=1.0, count=1):
    from pamrun.task.randomize import RandomizedWalker

    return RandomizedWalker(EnvSpec.from_config(cfg), {n: cfg.eval.perturbations[n] for n in names}, prob, reach, count)


def test_each_episode_draws_a_perturbation_reproducibly(cfg):
    """With the env's seed, the same draws; a drawn perturbation is applied at its strength (mass
    factor 1 + s (1.1 - 1)); a push comes at a drawn time inside the episode's middle."""
    env = walker(cfg, ["mass_heavy", "push_forward"], prob=1.0, reach=1.0)
    draws = []
    for k in range(12):
        env.reset(seed=100 + k)
        ((name, s),) = env.drawn
        assert name in ("mass_heavy", "push_forward") and 0 <= s <= 1
        if name == "mass_heavy":
            assert env.env.mass_kg == pytest.approx(env.nominal.mass_kg * (1 + 0.1 * s), rel=1e-6)
        else:
            e = env.env.env_cfg
            assert e.push_impulse_ns[0] == pytest.approx(10 * s) and 1.0 <= e.push_time_s <= e.episode_s - 1.1
        draws.append(env.drawn)
    assert len({n for ((n, _),) in draws}) == 2
    again = walker(cfg, ["mass_heavy", "push_forward"])
    assert [(again.reset(seed=100 + k), again.drawn)[1] for k in range(12)] == draws
    obs, *_ = env.step(np.zeros(10))
    assert obs.shape == env.observation_space.shape
    env.close()


def test_no_draw_keeps_the_nominal_env(cfg):
    env = walker(cfg, ["lag_x2"], prob=0.0)
    for k in range(3):
        env.reset(seed=k)
        assert env.env is env.nominal and env.drawn == ()
    env.close()


def test_a_perturbed_episode_combines_distinct_perturbations(cfg):
    """train.randomize_count: that many perturbations at once, each at its own strength (factors
    compose); the pushes, which set the same values, never come together."""
    names = ["mass_heavy", "friction_low", "push_forward", "push_backward", "push_sideways"]
    env = walker(cfg, names, count=3)
    friction = env.nominal.body_cfg.friction_static
    seen = set()
    for k in range(20):
        env.reset(seed=k)
        drawn = dict(env.drawn)
        assert len(drawn) == 3 and sum(n.startswith("push") for n in drawn) <= 1
        assert len(drawn) - sum(n.startswith("push") for n in drawn) >= 2
        seen |= set(drawn)
        s = drawn.get("friction_low", 0.0)
        assert env.env.body_cfg.friction_static == pytest.approx(friction * (1 - 0.3 * s))
        s = drawn.get("mass_heavy", 0.0)
        assert env.env.mass_kg == pytest.approx(env.nominal.mass_kg * (1 + 0.1 * s), rel=1e-6)
    assert seen == set(names)
    env.close()
    with pytest.raises(ConfigError, match="randomize_count"):
        to_object(compose_config("train.randomize_count=0"))


def test_weights_draw_a_perturbation_more_often(cfg):
    """train.randomize_weights: a name of weight 20 among three comes first with chance 20/22
    (the uniform draw's 1/3); names it leaves out keep weight 1; the same seed, the same draws."""
    from pamrun.task.randomize import RandomizedWalker

    names = ["mass_heavy", "friction_low", "lag_x2"]
    spec = EnvSpec.from_config(cfg)

    def draws(weights):
        env = RandomizedWalker(spec, {n: cfg.eval.perturbations[n] for n in names}, 1.0, 1.0, 1, weights)
        env.reset(seed=7)
        out = [(env.draw(), env.drawn[0][0])[1] for _ in range(200)]
        env.close()
        return out

    weighted = draws({"friction_low": 20.0})
    assert weighted.count("friction_low") / 200 > 0.8  # expected 0.91; Binomial(200, 0.91) <= 160: ~1e-5
    assert {"mass_heavy", "lag_x2"} <= set(weighted) and weighted == draws({"friction_low": 20.0})
    assert draws({}).count("friction_low") / 200 < 0.5  # uniform: 1/3
    for override, key in (("push_forward=2", "randomize_weights.push_forward"),
                          ("friction_low=0", "randomize_weights.friction_low")):
        with pytest.raises(ConfigError, match=key):
            to_object(compose_config("train.randomize=[friction_low]", f"+train.randomize_weights.{override}"))


def test_a_name_can_reach_further_than_the_others(cfg):
    """train.randomize_reaches: friction_low's strength is drawn in [0, 2] (its own reach: the
    floor down to x0.4), mass_heavy's in [0, 1] (train.randomize_reach); a reach that makes a
    value impossible (friction x0.7 at strength 4: negative) fails naming its key before a run."""
    from pamrun.task.randomize import RandomizedWalker, check

    names = ["mass_heavy", "friction_low"]
    spec = EnvSpec.from_config(cfg)
    env = RandomizedWalker(spec, {n: cfg.eval.perturbations[n] for n in names}, 1.0, 1.0, 2, None,
                           {"friction_low": 2.0})
    env.reset(seed=3)
    strengths = {n: [] for n in names}
    for _ in range(200):
        drawn = env.draw()
        for n, s in env.drawn:
            strengths[n].append(s)
        s = dict(env.drawn)["friction_low"]
        assert drawn.body.friction_static == pytest.approx(cfg.body.friction_static * (1 - 0.3 * s))
    assert max(strengths["mass_heavy"]) <= 1.0 < max(strengths["friction_low"]) <= 2.0
    assert sum(s > 1 for s in strengths["friction_low"]) > 70  # expected 100 of 200
    env.close()
    check(to_object(compose_config("train.randomize=[friction_low]", "+train.randomize_reaches.friction_low=3")))
    for overrides, key in ((("+train.randomize_reaches.friction_low=4",), "train.randomize_reaches.friction_low"),
                           (("train.randomize_reach=4",), "train.randomize_reach"),
                           (("+train.randomize_reaches.lag_x2=2",), "randomize_reaches.lag_x2"),
                           (("+train.randomize_reaches.friction_low=-1",), "randomize_reaches.friction_low")):
        with pytest.raises(ConfigError, match=key):
            check(to_object(compose_config("train.randomize=[friction_low]", *overrides)))


def test_randomize_names_are_checked_with_the_config():
    with pytest.raises(ConfigError, match="train.randomize"):
        to_object(compose_config("train.randomize=[mass_heavy,nope]"))
    with pytest.raises(ConfigError, match="randomize_prob"):
        to_object(compose_config("train.randomize_prob=1.5"))
    with pytest.raises(ConfigError, match="walk_weights.kspeeed"):
        to_object(compose_config("+train.walk_weights.kspeeed=3"))


def test_stop_and_speed_terms():
    """kstop's term is the share of hip and ankle joints within 2 deg of a stop (knees in stance
    excepted, knees in swing counted), kspeed's exp(-((Vx - v*) / sigma)^2); both 0 by default
    (the thesis' reward)."""
    env = PamWalkerEnv(reward={"kstop": 2.0, "kspeed": 3.0}, env={"target_speed_m_s": 0.5, "speed_sigma_m_s": 0.25})
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.zeros(10))
    f = info["reward_unweighted"]
    assert f["kstop"] == 0.0  # standing: no hip or ankle at a stop
    vx = env.data.qvel[0]
    assert f["kspeed"] == pytest.approx(math.exp(-(((vx - 0.5) / 0.25) ** 2)))
    assert info["reward_terms"]["kspeed"] == pytest.approx(3.0 * f["kspeed"])
    assert PamWalkerEnv().reward_weights["kstop"] == 0.0
    env.close()


def test_walk_weights_reweight_any_term(cfg):
    """train.walk_weights: the walking stage re-weights any reward term of replay samples."""
    import torch

    from pamrun.learning.curriculum import WalkCurriculum

    cfg.train.walk_kvx, cfg.train.walk_weights, cfg.train.actor_start_frames = None, {"kspeed": 3.0}, 0
    curriculum = WalkCurriculum(cfg)
    from tensordict import TensorDict

    features = {k: torch.rand(5, dtype=torch.float64) for k in REWARD_KEYS}
    reward = torch.zeros(5, 1)
    sample = TensorDict({"next": {"reward": reward.clone(), "reward_unweighted": features}}, [5])
    assert torch.equal(curriculum.transform(sample.clone())["next", "reward"], reward)  # not yet walking
    assert curriculum.observe(1.0, cfg.train.init_random_frames + 1)
    out = curriculum.transform(sample.clone())["next", "reward"]
    assert torch.allclose(out, (3.0 - cfg.reward.kspeed) * features["kspeed"][:, None].float())
    assert "kspeed 0 -> 3" in curriculum.describe() and curriculum.changed() == {"kspeed": 3.0}


def test_slip_term_is_the_stance_feet_speed():
    """kslip's feature is minus the summed horizontal speed of the feet on the ground at both
    ends of a step: 0 for the robot standing still; a robot carried sideways on its feet at
    0.4 m/s (MuJoCo's contacts dragged along) slips about 2 x 0.4 m/s."""
    env = PamWalkerEnv(reward={"kslip": 2.0})
    env.reset(seed=0)
    for _ in range(20):
        _, _, _, _, info = env.step(np.zeros(10))
    f = info["reward_unweighted"]
    assert all(env.episode.contact) and -0.02 < f["kslip"] <= 0.0
    slips = []
    for _ in range(8):  # slide the standing robot along y: both feet drag on the floor
        env.data.qpos[1] += 0.4 * env.env_cfg.control_dt_s
        _, _, _, _, info = env.step(np.zeros(10))
        slips.append(-info["reward_unweighted"]["kslip"])
    assert np.median(slips) == pytest.approx(0.8, rel=0.25)
    assert info["reward_terms"]["kslip"] == pytest.approx(2.0 * -slips[-1])
    assert PamWalkerEnv().reward_weights["kslip"] == 0.0
    env.close()


def test_step_term_charges_each_touchdown_its_miss_of_the_step_length():
    """kstep's feature is minus (s - L*)^2 / L* summed over the feet that touch down in the step,
    with s and the touchdowns as pamrun.evaluation.metrics finds them in the same episode's info (one
    definition), and 0 in every other step; L* is env.step_length_m."""
    from pamrun.evaluation import metrics

    env = PamWalkerEnv(reward={"kstep": 2.0}, env={"step_length_m": 0.3})
    _, info = env.reset(seed=3)
    rows = {"t_s": [0.0], "foot_force_n": [info["foot_force_n"]], "sole_xyz_m": [info["sole_xyz_m"]]}
    features, terms = [0.0], [0.0]
    for k in range(60):  # open loop: the hips swing in antiphase, the swinging knee bends, until it falls
        phase, a = math.sin(2 * math.pi * 1.5 * k * 0.025), np.zeros(10)
        a[[0, 5, 2, 7]] = 0.4 * phase, -0.4 * phase, 0.8 * max(phase, 0), 0.8 * max(-phase, 0)
        _, _, fell, _, info = env.step(a)
        for key, value in (("t_s", (k + 1) * 0.025), ("foot_force_n", info["foot_force_n"]),
                           ("sole_xyz_m", info["sole_xyz_m"])):
            rows[key].append(value)
        features.append(info["reward_unweighted"]["kstep"])
        terms.append(info["reward_terms"]["kstep"])
        if fell:
            break
    table = metrics.step_table(rows, np.asarray(rows["foot_force_n"]) > env.contact_n)
    expected = np.zeros(len(features))
    for row, _, length, _ in table:
        expected[row] -= (length - 0.3) ** 2 / 0.3
    assert len(table) >= 4 and np.count_nonzero(expected) >= 4
    np.testing.assert_allclose(features, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(terms, 2.0 * np.asarray(features), rtol=1e-12)
    with pytest.raises(ConfigError, match="step_length_m"):
        PamWalkerEnv(env={"step_length_m": 0.0})
    env.close()


def test_air_term_and_info_meter_the_supply_air():
    """info["air_nl"] per step sums to pamrun.physics.muscle.air_nl over the same states (the gait
    metric's rule), kair's feature is minus it, and standing on constant pressures draws
    little."""
    from pamrun.physics.body import LEG_JOINTS, SIDES
    from pamrun.physics.muscle import MUSCLE_INNER_DIAMETER_M, air_nl

    env = PamWalkerEnv(reward={"kair": 0.5})
    _, info = env.reset(seed=0)
    assert info["air_nl"] == 0.0
    states = [(env.drive.pressure_kpa.ravel().copy(), env.drive.contraction_pct.ravel().copy())]
    rng = np.random.default_rng(0)
    total = 0.0
    for _ in range(30):
        _, _, fell, _, info = env.step(rng.uniform(-0.5, 0.5, 10))
        f = info["reward_unweighted"]
        assert f["kair"] == -info["air_nl"] <= 0 and info["reward_terms"]["kair"] == pytest.approx(0.5 * f["kair"])
        total += info["air_nl"]
        states.append((env.drive.pressure_kpa.ravel().copy(), env.drive.contraction_pct.ravel().copy()))
        assert not fell
    m = env.muscle_cfg
    counts = [getattr(m.count, j) for _ in SIDES for j in LEG_JOINTS]
    p, c = (np.array(x) for x in zip(*states))
    expected = air_nl(p, c, m.nominal_length_m, MUSCLE_INNER_DIAMETER_M[m.size], counts)
    assert total > 1.0 and total == pytest.approx(expected, rel=1e-9)
    for _ in range(40):  # zero action: the pressures settle; only the sway's contractions draw a little
        _, _, _, _, info = env.step(np.zeros(10))
    assert info["air_nl"] < 0.05 * total / 30  # under 5 % of a random command's mean per step
    env.close()
