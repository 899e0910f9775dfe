"""Terrain (env.slope_deg, env.step_height_m, env.rough_height_m; pamrun.physics.terrain): the
flat floor's model unchanged when off, the feet on each ground, the fall check measured from
the ground, the checks, and the suite's terrain entries through ``pamrun eval``."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from pamrun.config import BodyConfig, ConfigError, EnvConfig, to_object
from pamrun.physics import body
from pamrun.physics.terrain import ground_height_m
from pamrun.task.env import PamWalkerEnv
from tests.conftest import compose_config, run_pamrun

TERRAINS = {"slope_up": {"slope_deg": 10.0}, "slope_down": {"slope_deg": -10.0}, "step_up": {"step_height_m": 0.05},
            "step_down": {"step_height_m": -0.05}, "uneven": {"rough_height_m": 0.03}}


def test_with_the_options_off_the_model_is_the_flat_floors():
    flat = body.build_spec(BodyConfig()).to_xml()
    assert body.build_spec(BodyConfig(), env=EnvConfig()).to_xml() == flat
    model, off = body.build_model(BodyConfig()), body.build_model(BodyConfig(), env=EnvConfig())
    assert off.ngeom == model.ngeom
    np.testing.assert_array_equal(off.geom_solref, model.geom_solref)
    assert not PamWalkerEnv(env=EnvConfig()).on_terrain


def _stand_at(env: PamWalkerEnv, x: float, lift_m: float) -> None:
    """The standing robot moved to ``x``, its soles ``lift_m`` above the ground's height there."""
    env.reset(seed=0)
    env.data.qpos[0] = x
    env.data.qpos[2] += lift_m
    mujoco.mj_forward(env.model, env.data)


@pytest.mark.parametrize("name", TERRAINS)
def test_the_feet_stand_on_each_ground(name):
    """The robot set down 2.5 m ahead lands on the terrain's geom, every contact on its surface
    (the ground's height there; uneven ground within its +-h), and the env steps on."""
    cfg = EnvConfig(**TERRAINS[name])
    env = PamWalkerEnv(env=cfg)
    assert env.on_terrain
    x = 2.5
    # high enough that no sole starts inside the ground (a 10 deg slope rises 3 cm over half a foot)
    _stand_at(env, x, ground_height_m(cfg, x) + 0.05)
    for _ in range(20):
        env.step(np.zeros(env.action_space.shape, np.float32))
    d, m = env.data, env.model
    assert d.ncon > 0 and sum(env.foot_forces_n()) > 0.5 * env.weight_n
    terrain = {"slope_up": "slope", "slope_down": "slope", "step_up": "step", "step_down": "floor", "uneven": "rough_"}
    for c in d.contact[: d.ncon]:
        assert any((mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or "").startswith(terrain[name]) for g in c.geom)
        tolerance = cfg.rough_height_m + 0.01  # the contact point: mid-penetration; a dome's top or the dip between
        assert abs(c.pos[2] - ground_height_m(cfg, c.pos[0])) < tolerance, (c.pos, name)
    if name.startswith(("slope_up", "step_up")):
        assert min(c.pos[2] for c in d.contact[: d.ncon]) > 0.03  # well above the flat floor's z = 0


def test_the_robot_starts_on_flat_ground_and_the_fall_check_reads_the_ground():
    cfg = EnvConfig(slope_deg=-15.0)
    env = PamWalkerEnv(env=cfg)
    env.reset(seed=0)
    mujoco.mj_forward(env.model, env.data)
    names = {mujoco.mj_id2name(env.model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(env.model.ngeom)}
    assert {"floor", "slope"} <= names
    assert not env._fell()
    # standing 10 m down the slope: 2.4 m below the start, still standing
    _stand_at(env, 10.0, ground_height_m(cfg, 10.0))
    assert env.data.qpos[2] < 0 and not env._fell()
    env.data.qpos[2] = ground_height_m(cfg, 10.0) + 0.3  # torso 0.3 m above the ground: fallen
    assert env._fell()


def test_uneven_ground_is_the_same_for_every_model():
    a, b = (body.build_model(BodyConfig(), env=EnvConfig(rough_height_m=0.01)) for _ in range(2))
    np.testing.assert_array_equal(a.geom_pos, b.geom_pos)
    tops = np.array([a.geom_pos[g, 2] + a.geom_size[g, 0] for g in range(a.ngeom)
                     if (mujoco.mj_id2name(a, mujoco.mjtObj.mjOBJ_GEOM, g) or "").startswith("rough_")])
    assert 0 <= tops.min() and tops.max() <= 0.02 and tops.std() > 0.004  # drawn within 1 +- 1 cm, not flat


@pytest.mark.parametrize("key, value, message", [
    ("slope_deg", 20.0, "must lie in [-15.0, 15.0]"), ("step_height_m", -0.2, "must lie in [-0.1, 0.1]"),
    ("rough_height_m", 0.1, "must lie in [0, 0.05]"), ("rough_height_m", -0.01, "must lie in [0, 0.05]"),
    ("terrain_x_m", 0.1, "must be >= 0.3"),
])
def test_bad_terrain_values_name_their_key(key, value, message):
    with pytest.raises(ConfigError) as err:
        to_object(compose_config(f"env.{key}={value}"))
    assert err.value.key == f"env.{key}" and message in err.value.message


def test_one_terrain_at_a_time():
    with pytest.raises(ConfigError) as err:
        EnvConfig(slope_deg=3.0, rough_height_m=0.01)
    assert err.value.key == "rough_height_m" and "one terrain at a time" in err.value.message


def test_a_bad_slope_on_the_command_line_writes_nothing(tmp_path):
    out = tmp_path / "run"
    proc = run_pamrun("train", "env.slope_deg=20", f"hydra.run.dir={out}")
    assert proc.returncode != 0 and not out.exists()
    assert "invalid configuration: env.slope_deg: must lie in [-15.0, 15.0], got 20.0" in proc.stderr, proc.stderr


def test_the_robustness_suite_holds_the_terrain_entries():
    ecfg = to_object(compose_config()).eval
    terrain = ["slope_up", "slope_down", "step_up", "uneven"]
    assert ecfg.suites["robustness"][-4:] == terrain and ecfg.suites["terrain"] == ["nominal", *terrain]
    assert ecfg.perturbations["slope_down"].values == {"env": {"slope_deg": -3.0}}


@pytest.mark.slow
def test_the_shipped_walker_meets_the_terrain_through_pamrun_eval(tmp_path):
    """The terrain suite of the shipped walker, two short episodes per entry: each entry's
    robot walks onto its ground (1 m ahead) and the report has every entry."""
    out = tmp_path / "ev"
    proc = run_pamrun("eval", "ckpt=agents/walker_td3_seed0.pt", "eval.suite=terrain", "eval.episodes=2",
                      "eval.episode_s=3.0", "eval.walk_duration_s=3.0", "eval.walk_distance_m=0", "eval.workers=1",
                      f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    episodes = [json.loads(line) for line in (out / "robustness_episodes.jsonl").open()]
    assert sorted({e["perturbation"] for e in episodes}) == sorted(["nominal", "slope_up", "slope_down", "step_up",
                                                                     "uneven"])
    assert all(e["distance_m"] > 1.2 for e in episodes)  # past terrain_x_m: on the terrain
    assert "slope 3 deg up" in proc.stdout


def test_the_height_reward_and_randomisation_know_the_terrain():
    """reward.kz measures the torso's height from the ground under it; domain randomisation draws
    one terrain at a time."""
    from pamrun.task.randomize import RandomizedWalker
    from pamrun.task.spec import EnvSpec

    cfg = EnvConfig(slope_deg=-10.0)
    env = PamWalkerEnv(env=cfg)
    _stand_at(env, 5.0, ground_height_m(cfg, 5.0))
    *_, info = env.step(np.zeros(env.action_space.shape, np.float32))
    assert env.data.qpos[2] < env.z0 - 0.5 and info["reward_unweighted"]["kz"] > -1e-3  # 0.7 m lower, on its feet
    ecfg = to_object(compose_config()).eval
    names = ["slope_up", "uneven", "step_up"]
    walker = RandomizedWalker(EnvSpec(), {n: ecfg.perturbations[n] for n in names}, 1.0, 1.0, 2)
    for seed in range(6):
        walker.reset(seed=seed)
        assert len(walker.drawn) == 1


def test_the_gait_clock_measures_a_swinging_foots_lift_from_the_ground_under_it():
    """The robot standing on a 10 cm step scores the gait clock's swing clearance as it does on
    the floor: its feet, on the ground, have not lifted (counted from z = 0 they would have
    cleared 10 cm, and a foot the clock swings would miss 0.25 less)."""
    from pamrun.task import clock

    scores = {}
    for name, terrain in (("floor", {}), ("step", {"step_height_m": 0.1})):
        cfg = EnvConfig(gait_period_s=0.8, swing_clearance_m=0.05, **terrain)
        env = PamWalkerEnv(env=cfg, features=["kgait"])
        _stand_at(env, 2.5, ground_height_m(cfg, 2.5))
        scores[name], swinging = [], []
        for _ in range(12):
            swinging.append(max(clock.swing_weights(env.gait_phase(), cfg.swing_share)))
            *_, info = env.step(np.zeros(env.action_space.shape, np.float32))
            scores[name].append(info["reward_unweighted"]["kgait"])
        env.close()
    assert max(swinging) > 0.9  # a foot the clock swings, standing on the ground
    assert np.allclose(scores["step"], scores["floor"], atol=0.02), (scores["step"], scores["floor"])
