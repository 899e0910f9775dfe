"""A commanded speed (env.speed_command, env.speed_range_m_s, eval.speed_m_s): the env draws v*
per episode and shows it to the policy, kspeed pays for it, and an agent trained so is told the
speed pamrun eval asks for."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pamrun.config import ConfigError, to_object
from pamrun.task.env import PamWalkerEnv
from tests.conftest import compose_config
from tests.test_train import TINY, train_here

RANGE = [0.5, 1.2]


def test_the_env_draws_and_shows_the_commanded_speed():
    """v* is drawn in the range per reset from the env's seed (the same seed: the same v* and the
    same start pose as without a command), is the observation's last value and info's, and is
    what kspeed's feature tracks."""
    told = PamWalkerEnv(env={"speed_command": True, "speed_range_m_s": RANGE, "reset_noise_rad": 0.02},
                        features=["kspeed"])
    plain = PamWalkerEnv(env={"reset_noise_rad": 0.02})
    assert told.observation_space.shape == (plain.observation_space.shape[0] + 1,)
    assert told.observation_structure["speed_command"] == slice(43, 44)
    speeds = []
    for seed in range(8):
        obs, info = told.reset(seed=seed)
        plain_obs, _ = plain.reset(seed=seed)
        assert np.array_equal(told.data.qpos, plain.data.qpos) and np.array_equal(obs[:-1], plain_obs)
        assert RANGE[0] <= info["target_speed_m_s"] <= RANGE[1] and obs[-1] == np.float32(info["target_speed_m_s"])
        speeds.append(info["target_speed_m_s"])
    assert len(set(speeds)) == 8 and max(speeds) - min(speeds) > 0.3
    assert told.reset(seed=3)[1]["target_speed_m_s"] == speeds[3]
    obs, *_, info = told.step(np.zeros(10))
    assert obs[-1] == np.float32(speeds[3])  # held for the episode
    f = info["reward_unweighted"]
    vx = told.data.qvel[0]
    assert f["kspeed"] == pytest.approx(math.exp(-(((vx - speeds[3]) / told.env_cfg.speed_sigma_m_s) ** 2)))
    from pamrun.task.symmetry import observation_map

    index, sign = observation_map(10, speed_command=True)
    assert index[-1] == 43 and sign[-1] == 1.0  # the mirror image is told the same speed
    assert np.array_equal(np.sort(index), np.arange(44))
    told.close()
    plain.close()


def test_a_ramped_command_moves_v_star_at_its_rate_and_the_clock_with_it():
    """With env.speed_ramp_m_s2 a stop from 1.2 m/s is not taken in one control step: the v* the
    policy is told and kspeed pays moves 2 m/s^2 x 25 ms = 0.05 m/s a step, the clock's period
    follows it (and stops only at 0), and info's target_speed_m_s is the command from the step it
    falls due. At 0 (the default) v* takes the command at once."""
    task = {"speed_command": True, "gait_period_s": 1.1, "step_length_m": 0.55, "gait_follows_speed": True,
            "speed_schedule": [[0, 1.2], [0.25, 0.0]]}
    seen = {}
    for ramp in (0.0, 2.0):
        env = PamWalkerEnv(env={**task, "speed_ramp_m_s2": ramp}, features=["kspeed"])
        obs, info = env.reset(seed=0)
        told, commanded, periods = [float(obs[43])], [float(info["target_speed_m_s"])], []
        for _ in range(40):
            obs, _, terminated, _, info = env.step(np.zeros(10))
            assert not terminated
            told.append(float(obs[43]))
            commanded.append(float(info["target_speed_m_s"]))
            periods.append(env.gait_period_s)
            vx = env.data.qvel[0]
            assert info["reward_unweighted"]["kspeed"] == pytest.approx(
                math.exp(-(((vx - env.episode.target_speed_m_s) / 0.5) ** 2)))
        assert commanded == [1.2] * 10 + [0.0] * 31  # the command falls due at step 10, whatever the ramp
        seen[ramp] = told, periods
        env.close()
    at_once, ramped = seen[0.0][0], seen[2.0][0]
    assert at_once[9:12] == [pytest.approx(1.2), 0.0, 0.0]
    assert np.allclose(np.diff(ramped[9:34]), -0.05, atol=1e-6) and ramped[34:] == [0.0] * 7
    periods = seen[2.0][1]  # periods[k - 1]: after step k
    assert all(b > a for a, b in zip(periods[8:31], periods[9:32])) and math.isfinite(periods[31])
    assert math.isinf(periods[32]) and math.isinf(seen[0.0][1][9])


@pytest.mark.parametrize("override, key", [
    (["env.speed_range_m_s=[0.5,1.2]"], "speed_range_m_s"),  # a drawn speed the policy is not told
    (["env.speed_command=true", "env.speed_range_m_s=[1.2,0.5]"], "speed_range_m_s"),
    (["env.speed_command=true", "env.speed_range_m_s=[-0.1,0.5]"], "speed_range_m_s"),
    (["eval.speed_m_s=-1"], "speed_m_s"),
    (["env.speed_ramp_m_s2=-1"], "speed_ramp_m_s2"),
    (["eval.speed_ramp_m_s2=-0.5"], "speed_ramp_m_s2"),
])
def test_impossible_speed_commands_fail_naming_the_key(override, key):
    with pytest.raises(ConfigError, match=key):
        to_object(compose_config(*override))


def test_a_speed_commanded_agent_trains_with_mirroring_and_is_told_the_asked_speed(tmp_path):
    """A run with the command in its observation (mirrored transitions included) saves agents of
    that size; pamrun eval's loader gives each episode eval.speed_m_s, held, and runs them."""
    from pamrun.evaluation.agents import load_agents
    from pamrun.evaluation.episodes import evaluate_agents

    run = tmp_path / "run"
    assert train_here(run, *TINY, "train.max_frames=400", "train.eval_every_frames=0", "train.mirror=true",
                      "env.speed_command=true", f"env.speed_range_m_s=[{RANGE[0]},{RANGE[1]}]") == "max_frames"
    cfg = to_object(compose_config("eval.speed_m_s=0.8", "eval.episodes=2", "eval.episode_s=1",
                                   "eval.walk_duration_s=1"))
    agents, envs, errors = load_agents(str(run / "checkpoints" / "last.pt"), cfg)
    assert not errors and agents[0].obs_size == 44
    assert envs[0].env.target_speed_m_s == 0.8 and envs[0].env.speed_range_m_s == []
    env = envs[0].make()
    assert env.reset(seed=1000)[0][-1] == np.float32(0.8)
    env.close()
    (episodes,) = evaluate_agents(agents, envs, 2, 1000, 1, keep_steps=False)
    assert len(episodes) == 2 and all(np.isfinite(e["distance_m"]) for e in episodes)
