"""A commanded speed that changes within an episode (env.speed_schedule, eval.speed_schedule,
env.speed_changes), standing still (v* = 0, the clock stopped with env.gait_follows_speed), and
how well an episode tracks its command (pamrun.evaluation.tracking)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from pamrun.config import ConfigError, EnvConfig, to_object
from pamrun.evaluation.episodes import clock_touchdown_offsets, run_episode
from pamrun.evaluation.tracking import clock_keeping, segments, smoothed_speed, tracking_metrics, tracking_rms
from pamrun.task import clock
from pamrun.task.env import PamWalkerEnv
from tests.conftest import compose_config, run_pamrun

SCHEDULE = [[0, 0.0], [0.5, 0.6], [1.0, 1.2]]
SHIPPED = Path(__file__).parents[1] / "agents" / "walker_td3_seed0.pt"
DT = 0.025


def test_the_observation_follows_the_schedule_at_the_set_times():
    """v* (the observation's last value, info's, kspeed's target) is the schedule's from the control
    step at its time on; the start pose is the same as without a schedule."""
    env = PamWalkerEnv(env={"speed_command": True, "speed_schedule": SCHEDULE, "episode_s": 1.5,
                            "reset_noise_rad": 0.02}, features=["kspeed"])
    plain = PamWalkerEnv(env={"speed_command": True, "reset_noise_rad": 0.02})
    obs, info = env.reset(seed=4)
    plain.reset(seed=4)
    assert np.array_equal(env.data.qpos, plain.data.qpos)
    assert obs[-1] == 0.0 and info["target_speed_m_s"] == 0.0
    for k in range(1, 61):  # step k ends at k * 25 ms
        obs, _, terminated, truncated, info = env.step(np.zeros(10))
        expected = 0.0 if k < 20 else 0.6 if k < 40 else 1.2
        assert obs[-1] == np.float32(expected) and info["target_speed_m_s"] == expected, k
        vx = env.data.qvel[0]
        assert info["reward_unweighted"]["kspeed"] == pytest.approx(
            math.exp(-(((vx - expected) / env.env_cfg.speed_sigma_m_s) ** 2)))
        if terminated:
            break
    assert k == 60 and truncated
    obs, info = env.reset(seed=5)  # the next episode starts the schedule again
    assert obs[-1] == 0.0 and info["target_speed_m_s"] == 0.0
    env.close()
    plain.close()


def test_the_clock_stops_at_standing_and_runs_on_from_its_phase():
    """With env.gait_follows_speed the clock stands still while v* = 0 (kgait asks both feet down,
    kstep no step), then runs at the period of the new v*, from the phase it had."""
    cfg = {"speed_command": True, "speed_schedule": [[0, 0.0], [0.5, 0.6]], "gait_period_s": 0.8,
           "gait_follows_speed": True, "episode_s": 1.0}
    env = PamWalkerEnv(env=cfg, features=["kgait", "kstep"])
    env.reset(seed=0)
    phase0 = env.gait_phase()
    assert math.isinf(env.gait_period_s) and env.step_length_m == 0.0 and env.episode.clock_stopped
    for k in range(1, 40):
        soles = env.episode.soles
        _, _, _, _, info = env.step(np.zeros(10))
        if k < 20:
            assert env.gait_phase() == phase0
            shares = [f / env.weight_n for f in info["foot_force_n"]]
            knees = [env.data.qpos[a] for a in env.knee_addresses]
            stance = clock.followed(0.0, soles, env.episode.soles, shares, knees, env.sole_radius_m, env.env_cfg,
                                    stopped=True)
            assert info["reward_unweighted"]["kgait"] == pytest.approx(stance)
            assert math.isfinite(info["reward_unweighted"]["kstep"])
        if k == 20:
            period, length = clock.gait_at_speed(env.env_cfg, 0.6)
            assert (env.gait_period_s, env.step_length_m) == (period, length) and period > 0.8
            assert env.gait_phase() == phase0  # the change's step starts from the stopped phase
        if k > 20:
            assert env.gait_phase() == pytest.approx((phase0 + (k - 20) * DT / period) % 1.0)
    env.close()


def test_drawn_speed_changes_keep_the_start_and_stay_in_the_range():
    """env.speed_changes redraws v* in the episode (0 with chance env.speed_stop_share), the same
    per seed; the start pose and clock phase are those of the run without changes."""
    base = {"speed_command": True, "speed_range_m_s": [0.0, 1.2], "gait_period_s": 0.8, "reset_noise_rad": 0.02}
    env = PamWalkerEnv(env={**base, "speed_changes": 3, "speed_stop_share": 0.3})
    plain = PamWalkerEnv(env=base)
    seen, stops = [], 0
    for seed in range(6):
        _, info = env.reset(seed=seed)
        _, plain_info = plain.reset(seed=seed)
        assert np.array_equal(env.data.qpos, plain.data.qpos) and env.gait_phase() == plain.gait_phase()
        changes = list(env.episode.changes)
        assert len(changes) == 3 and [c[0] for c in changes] == sorted(c[0] for c in changes)
        assert all(1 <= step <= 400 and 0 <= v <= 1.2 for step, v in changes)
        speeds = [info["target_speed_m_s"]] + [v for _, v in changes]
        stops += speeds.count(0.0)
        seen.append(changes)
        assert info["target_speed_m_s"] in (0.0, plain_info["target_speed_m_s"])
    assert 0 < stops < 24
    env.reset(seed=2)
    assert env.episode.changes == seen[2]
    env.close()
    plain.close()


def test_the_features_off_leave_every_number_as_it_was():
    """A schedule of one speed equal to env.target_speed_m_s runs the same episode, reward by reward."""
    env_cfg = {"speed_command": True, "gait_period_s": 0.8, "reset_noise_rad": 0.02}
    runs = []
    for extra in ({}, {"speed_schedule": [[0, 1.0]]}):
        env = PamWalkerEnv(env={**env_cfg, **extra}, reward={"kspeed": 1.0, "kgait": 1.0, "kstep": 1.0})
        obs, _ = env.reset(seed=3)
        out = [obs]
        rng = np.random.default_rng(0)
        for _ in range(30):
            obs, reward, *_ = env.step(rng.uniform(-1, 1, 10))
            out += [obs, reward]
        runs.append(out)
        env.close()
    assert all(np.array_equal(a, b) for a, b in zip(*runs))


@pytest.mark.parametrize("override, key", [
    (["env.speed_schedule=[[0,0.5],[2,-0.1]]"], "env.speed_schedule"),  # a negative speed
    (["env.speed_schedule=[[0,0.5],[3,1],[2,0]]"], "env.speed_schedule"),  # times not increasing
    (["env.speed_schedule=[[0,0.5],[10,1]]"], "env.speed_schedule"),  # at the episode's end (10 s)
    (["env.speed_schedule=[[1,0.5]]"], "env.speed_schedule"),  # not from 0 s
    (["env.speed_schedule=[[0]]"], "env.speed_schedule"),  # ill-formed entries
    (["env.speed_schedule=[0,1]"], "env.speed_schedule"),
    (["env.speed_schedule=[[0,fast]]"], "env.speed_schedule"),
    (["env.speed_command=true", "env.speed_range_m_s=[0,1]", "env.speed_schedule=[[0,1]]"], "env.speed_schedule"),
    (["env.speed_changes=2"], "env.speed_changes"),  # nothing to draw from
    (["env.speed_command=true", "env.speed_range_m_s=[0,1]", "env.speed_changes=-1"], "env.speed_changes"),
    (["env.speed_command=true", "env.speed_range_m_s=[0,1]", "env.speed_stop_share=1.5"], "env.speed_stop_share"),
    (["env.gait_period_s=0.8", "env.gait_follows_speed=true", "env.target_speed_m_s=-0.5"], "env.target_speed_m_s"),
    (["eval.speed_schedule=[[0,0],[2.5,-0.6]]"], "eval.speed_schedule"),
    (["eval.episode_s=5", "eval.walk_duration_s=5", "eval.speed_schedule=[[0,0],[5,1]]"], "eval.speed_schedule"),
    (["eval.speed_m_s=1", "eval.speed_schedule=[[0,0],[5,1]]"], "eval.speed_schedule"),
])
def test_impossible_schedules_fail_naming_the_key(override, key):
    with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
        to_object(compose_config(*override))


def test_standing_is_a_speed_and_the_schedule_reads_the_command_line():
    cfg = to_object(compose_config("env.speed_command=true", "env.speed_range_m_s=[0,1.2]", "env.gait_period_s=0.8",
                                   "env.gait_follows_speed=true", "eval.speed_schedule=[[0,0],[2.5,0.6],[5,1.2],[7.5,0]]"))
    assert cfg.env.speed_range_m_s == [0.0, 1.2]
    assert cfg.eval.speed_schedule == [[0.0, 0.0], [2.5, 0.6], [5.0, 1.2], [7.5, 0.0]]
    assert EnvConfig(gait_period_s=0.8, gait_follows_speed=True, target_speed_m_s=0.0).target_speed_m_s == 0.0


def test_a_bad_schedule_fails_before_anything_is_written(tmp_path):
    out = tmp_path / "out"
    proc = run_pamrun("eval", f"ckpt={SHIPPED}", "eval.speed_schedule=[[0,0],[2.5,0.6],[2,1.2]]",
                      f"hydra.run.dir={out}")
    assert proc.returncode != 0
    assert "invalid configuration: eval.speed_schedule" in proc.stderr, proc.stderr
    assert not out.exists()


def _still_arrays(command: list[float], x: np.ndarray, forces: float = 100.0) -> dict:
    n = len(command)
    return {"t_s": np.arange(1, n + 1) * DT, "x_m": x, "y_m": np.zeros(n), "foot_force_n": np.full((n, 2), forces),
            "target_speed_m_s": np.asarray(command, float)}


def test_tracking_gives_back_a_known_speed_error():
    """x(t) walked 0.1 m/s slower than a constant v* gives 0.1 m/s; a schedule of 0, 0.6 and 1.2 m/s
    (5 s segments: settling 1.5 s, a 2 s window, a 1.5 s leftover) with errors +0.2, -0.1, 0 gives
    their RMS weighted by window length; a still robot drifts 0 with both feet down."""
    n = 400
    t = np.arange(1, n + 1) * DT
    assert tracking_rms(0.9 * t, np.ones(n), DT) == pytest.approx(0.1)
    command = np.r_[np.zeros(199), np.full(200, 0.6), np.full(1, 1.2)]  # v* changes at 5 s and 10 s (too late)
    assert [round(s, 6) for s, _, _ in segments(command, DT)] == [0.0, 5.0, 10.0]
    speed = np.where(t <= 5.0, 0.2, 0.5)  # +0.2 while v* = 0, -0.1 while v* = 0.6
    x = np.cumsum(speed) * DT
    # windows: [1.5, 3.5], [3.5, 5.0] (v* 0); [6.5, 8.5], [8.5, 10.0] (v* 0.6)
    expected = math.sqrt((2.0 * 0.04 + 1.5 * 0.04 + 2.0 * 0.01 + 1.5 * 0.01) / 7.0)
    assert tracking_rms(x, command, DT) == pytest.approx(expected, rel=1e-9)
    still = tracking_metrics(_still_arrays(list(np.zeros(n)), np.full(n, 0.3)), 20.0, DT)
    assert {k: still.pop(k) for k in ("speed_tracking_rms_m_s", "stand_still_feet_down_share", "stand_still_drift_m")} == {
        "speed_tracking_rms_m_s": 0.0, "stand_still_feet_down_share": 1.0, "stand_still_drift_m": 0.0}
    assert sorted(still) == ["touchdown_clock_offset", "touchdown_on_clock_share"]
    assert all(math.isnan(v) for v in still.values())  # no per-step clock offsets: an older episode's steps
    lifted = _still_arrays(list(np.zeros(n)), 0.01 * t)
    lifted["foot_force_n"][::4, 1] = 0.0  # one step in four on one foot
    metrics = tracking_metrics(lifted, 20.0, DT)
    assert metrics["stand_still_feet_down_share"] == pytest.approx(0.75, abs=0.01)
    assert metrics["stand_still_drift_m"] == pytest.approx(0.01 * (10.0 - 1.5), abs=1e-3)
    walking = tracking_metrics(_still_arrays([1.0] * n, t), 20.0, DT)
    assert math.isnan(walking["stand_still_feet_down_share"]) and math.isnan(walking["stand_still_drift_m"])
    assert math.isnan(tracking_rms(t[:80], np.ones(80), DT))  # 2 s: no window after settling
    ts, measured = smoothed_speed(t, 0.7 * t)
    assert len(ts) == n - 20 and np.allclose(measured, 0.7)


def test_clock_keeping_reads_the_offsets_at_the_touchdowns():
    """Feet landing 0.05, 0.15 and 0.05 early (right) and 0.02 and 0.4 of the period late (left) after the
    first second, a third left landing while the clock stands still, and one in the first second: the
    median offset is 0.05 and 3 of 5 land within 0.1 of their clock's touchdown. Offsets between the
    touchdowns do not count."""
    n = 240
    arrays = _still_arrays([1.0] * n, np.zeros(n), forces=0.0)
    offsets = np.full((n, 2), 0.3)
    for foot, rows, values in ((0, (20, 60, 110, 160), (0.0, 0.05, 0.15, -0.05)),
                               (1, (85, 135, 185), (0.02, 0.4, math.nan))):
        for row, value in zip(rows, values):
            arrays["foot_force_n"][row:row + 20, foot] = 100.0
            offsets[row, foot] = value
    arrays["clock_touchdown_offset"] = offsets
    assert clock_keeping(arrays, 20.0) == (pytest.approx(0.05), pytest.approx(0.6))
    arrays["clock_touchdown_offset"] = np.full((n, 2), math.nan)
    assert all(math.isnan(v) for v in clock_keeping(arrays, 20.0))


def test_an_episode_records_each_feet_clock_offset_as_ktouch_reads_it():
    """Dropped from 0.3 m with random actions on a clocked task, each foot's recorded offset at a landing
    lies beyond 0.1 of the period exactly where ktouch charges that landing; run_episode records one
    offset per foot and step, NaN without a clock."""
    env = PamWalkerEnv(env={"gait_period_s": 0.8, "swing_share": 0.4}, reward={"ktouch": 1.0})
    rng, checked = np.random.default_rng(0), 0
    for seed in range(4):
        env.reset(seed=seed)
        env.data.qpos[2] += 0.3
        before = [False, False]
        for _ in range(60):
            *_, terminated, truncated, info = env.step(rng.uniform(-0.5, 0.5, 10).astype(np.float32))
            down = [f > env.contact_n for f in info["foot_force_n"]]
            landed = [d and not b for d, b in zip(down, before)]
            if any(landed):
                offsets = clock_touchdown_offsets(env)
                assert info["reward_unweighted"]["ktouch"] == -sum(abs(o) > 0.1 for o, x in zip(offsets, landed) if x)
                checked += 1
            before = down
            if terminated or truncated:
                break
    assert checked >= 4
    episode = run_episode(lambda obs: np.zeros(10, np.float32), env, seed=1)
    assert np.shape(episode["steps"]["clock_touchdown_offset"]) == (len(episode["steps"]["t_s"]), 2)
    flat = run_episode(lambda obs: np.zeros(10, np.float32), PamWalkerEnv(), seed=1)
    assert np.isnan(flat["steps"]["clock_touchdown_offset"]).all() and math.isnan(flat["touchdown_on_clock_share"])


@pytest.mark.slow
def test_pamrun_eval_follows_a_schedule_with_the_shipped_walker(tmp_path):
    """The shipped walker has no speed command in its observation: it is evaluated with the schedule
    as the reference its tracking is measured against (the console says so), and speed.png drawn."""
    out = tmp_path / "eval"
    proc = run_pamrun("eval", f"ckpt={SHIPPED}", "eval.speed_schedule=[[0,0],[2.5,0.6],[5,1.2],[7.5,0]]",
                      "eval.episodes=2", "eval.workers=1", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr
    assert "is not told the commanded speed" in proc.stdout
    assert (out / "speed.png").stat().st_size > 10_000
    records = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    assert len(records) == 2
    for e in records:
        command = e["steps"]["target_speed_m_s"]
        assert [command[i] for i in (0, 98, 99, 198, 199, 298, 299, 399)] == [0, 0, 0.6, 0.6, 1.2, 1.2, 0, 0]
        # it walks at about 1 m/s whatever it is asked: far off the schedule, and not standing
        assert 0.3 < e["speed_tracking_rms_m_s"] < 1.2
        assert e["stand_still_feet_down_share"] < 0.9 and e["stand_still_drift_m"] > 0.5
    board = json.loads((out / "leaderboard.json").read_text())
    assert board["agents"][0]["speed_tracking_rms_m_s_mean"] > 0.3


@pytest.mark.slow
def test_a_run_trains_with_drawn_starts_and_stops(tmp_path):
    """A training whose v* changes and stops within its episodes (the clock following it, kspeed,
    kgait and kstep paying) runs, evaluates and saves its agents."""
    from tests.test_train import TINY, train_here

    run = tmp_path / "run"
    assert train_here(run, *TINY, "train.max_frames=400", "train.eval_every_frames=200", "train.eval_episodes=1",
                      "env.speed_command=true", "env.speed_range_m_s=[0,1.2]", "env.speed_changes=2",
                      "env.speed_stop_share=0.3", "env.gait_period_s=0.8", "env.gait_follows_speed=true",
                      "reward.kspeed=1", "reward.kgait=1", "reward.kstep=0.5") == "max_frames"
    assert (run / "checkpoints" / "last.pt").exists() and (run / "evals.csv").exists()
