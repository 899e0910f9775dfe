"""`pamrun eval`: walk test, ranking, parallel = serial, end to end, and bad checkpoints."""

from __future__ import annotations

import csv
import json
import os
import pickle
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from pamrun.config import ConfigError, EvalConfig, to_object
from pamrun.evaluation.agents import load_agents
from pamrun.evaluation.episodes import (
    agent_env,
    aggregate,
    evaluate_agents,
    run_episode,
)
from pamrun.evaluation.ranking import rank
from pamrun.learning.checkpoints import CheckpointError, find_checkpoints, load_agent
from pamrun.physics.body import JOINTS
from pamrun.task.criteria import stood, walk_passed
from pamrun.task.observation import N_JOINTS, OBS_SIZE
from tests.conftest import compose_config, run_pamrun

ECFG = EvalConfig()  # the walk test: 10 s, |y| <= 0.5 m, at least 7 m


def episode(duration=10.0, fell=False, y=0.1, distance=7.5, ret=100.0):
    return {"duration_s": duration, "fell": fell, "max_abs_y_m": y, "distance_m": distance, "return": ret,
            "speed_m_s": distance / duration, "pressure_change_kpa": 3.0}


# --------------------------------------------------------------------------- walk test and ranking


@pytest.mark.parametrize("ep, passed", [
    (episode(), True),
    (episode(y=0.5), True),  # on the band's edge is inside
    (episode(y=0.5001), False),
    (episode(fell=True), False),
    (episode(duration=9.975), False),  # one control step short of 10 s
    (episode(distance=7.0), True),  # exactly 7 m forward
    (episode(distance=6.99), False),  # stood and walked, but not far enough
])
def test_walk_test_of_one_episode(ep, passed):
    assert walk_passed(ep, ECFG) is passed
    assert stood(ep, ECFG) is (not ep["fell"] and ep["duration_s"] >= 10.0)


def test_agent_passes_only_when_every_episode_does():
    agg = aggregate([episode(distance=8.0), episode(distance=6.0), episode(fell=True, duration=4.0, distance=2.0)],
                    ECFG)
    assert agg["walk_pass_rate"] == pytest.approx(1 / 3) and agg["walk_test"] is False
    assert agg["stand_rate"] == pytest.approx(2 / 3)
    assert agg["distance_mean"] == pytest.approx(16 / 3) and agg["distance_min"] == 2.0
    assert agg["fall_rate"] == pytest.approx(1 / 3)
    assert agg["distance_std"] == pytest.approx(np.std([8.0, 6.0, 2.0]))
    assert agg["duration_mean"] == pytest.approx(8.0) and agg["max_abs_y_max"] == 0.1
    assert aggregate([episode(), episode()], ECFG)["walk_test"] is True


def row(agent, rate, dist, falls=0.0, ret=0.0):
    return {"agent": agent, "walk_pass_rate": rate, "distance_mean": dist, "fall_rate": falls, "return_mean": ret}


def test_rank_by_pass_rate_then_distance():
    rows = [row("a", 0.5, 9.0), row("b", 1.0, 6.0), row("c", 1.0, 7.0), row("d", 0.0, 11.0)]
    ranked = rank(rows, ["walk_pass_rate", "distance_mean"])
    assert [r["agent"] for r in ranked] == ["c", "b", "a", "d"]
    assert [r["rank"] for r in ranked] == [1, 2, 3, 4]


def test_an_agent_can_be_ranked_by_the_walk_targets_it_meets():
    """eval.rank_by takes walk_targets_met: among agents that all pass, the one nearer a walk first."""
    from pamrun.config import to_object
    from tests.conftest import compose_config

    cfg = to_object(compose_config("eval.rank_by=[walk_pass_rate,walk_targets_met,distance_mean]"))
    rows = [{**row("run", 1.0, 9.0), "walk_targets_met": 2}, {**row("walk", 1.0, 8.0), "walk_targets_met": 6},
            {**row("fall", 0.5, 9.5), "walk_targets_met": 9}]
    assert [r["agent"] for r in rank(rows, cfg.eval.rank_by)] == ["walk", "run", "fall"]


def test_rank_ascending_nan_last_and_ties_by_name():
    rows = [row("z", 0, 1, falls=0.2), row("y", 0, 1, falls=0.2), row("x", 0, 1, falls=0.0),
            row("w", 0, 1, falls=float("nan"))]
    assert [r["agent"] for r in rank(rows, ["-fall_rate"])] == ["x", "y", "z", "w"]
    assert [r["agent"] for r in rank(rows, ["return_mean"])] == ["w", "x", "y", "z"]


def test_a_physics_blow_up_fails_the_walk_test_and_ranks_last():
    """A blown-up episode's 30 m mean nothing: the agent fails the walk test and ranks below every other."""
    blown = {"fell": False, "physics_error": True, "duration_s": 10.0, "max_abs_y_m": 0.0, "return": 500.0,
             "distance_m": 30.0, "speed_m_s": 3.0, "pressure_change_kpa": 1.0}
    agg = aggregate([blown, {**blown, "physics_error": False, "distance_m": 7.5}], ECFG)
    assert agg["physics_error_rate"] == 0.5 and agg["walk_pass_rate"] == 0.5 and agg["walk_test"] is False
    rows = [{**row("blown", 1.0, 30.0), "physics_error_rate": 0.5}, row("slow", 0.0, 0.5)]
    assert [r["agent"] for r in rank(rows, ["walk_pass_rate", "distance_mean"])] == ["slow", "blown"]


@pytest.mark.parametrize("override, key", [
    ("eval.rank_by=[speed]", "eval.rank_by"),
    ("eval.workers=-1", "eval.workers"),
    ("eval.episodes=0", "eval.episodes"),
    ("eval.walk_duration_s=12", "eval.walk_duration_s"),
    ("eval.video_width=641", "eval.video_width"),
    ("eval.camera=bogus", "eval.camera"),
])
def test_impossible_eval_values_name_the_key(override, key):
    with pytest.raises(ConfigError) as err:
        to_object(compose_config(override))
    assert err.value.key == key


# --------------------------------------------------------------------------- one episode, real physics


def test_episode_metrics_agree_with_its_steps(tmp_path):
    """Duration, max |y| and the pressure-change figure recomputed from the recorded steps."""
    cfg = to_object(compose_config("eval.episode_s=2.0", "eval.walk_duration_s=2.0"))
    env = agent_env(_fake_agent(tmp_path), cfg).make()
    rng = np.random.default_rng(0)
    ep = run_episode(lambda obs: rng.uniform(-0.5, 0.5, N_JOINTS).astype(np.float32), env, seed=3)
    steps = ep["steps"]
    n = len(steps["x_m"])
    assert ep["duration_s"] == pytest.approx(n * 0.025)
    assert ep["fell"] == (n < 80)
    assert ep["max_abs_y_m"] == pytest.approx(max(abs(y) for y in steps["y_m"]), abs=1e-6)  # the file rounds to 1e-6
    # Commanded pressure is 100 kPa/V * (V0 +- dV a): each joint's two muscles change by 100 dV |da| kPa.
    actions = np.vstack([np.zeros(N_JOINTS), np.asarray(steps["action"])])
    expected = 100.0 * env.muscle_cfg.dv_max_v * np.abs(np.diff(actions, axis=0)).mean()
    assert ep["pressure_change_kpa"] == pytest.approx(expected, rel=1e-4)
    assert ep["speed_m_s"] == pytest.approx(ep["distance_m"] / ep["duration_s"])
    assert len(steps["pressure_kpa"][0]) == 20 and len(steps["joint_angle_rad"][0]) == 10


def test_video_frame_strip_and_gif(tmp_path):
    """An episode's video from each camera, its frame strip and its GIF: the frames picked as asked."""
    from PIL import Image

    from pamrun.evaluation.figures import video_frames
    from pamrun.evaluation.video import frame_picks, record_video, write_gif

    assert frame_picks([0.025 * k for k in range(401)], 8, 0.1) == list(range(186, 215, 4))  # 8 x 4 steps, mid-video
    assert frame_picks([0.025 * k for k in range(11)], 8, 0.1) == [0, 1, 3, 4, 6, 7, 9, 10]  # too short: over all of it
    assert frame_picks([0.025 * k for k in range(401)], 3, 0.05, from_start=True) == [0, 2, 4]
    cfg = to_object(compose_config("eval.episode_s=0.5", "eval.walk_duration_s=0.5"))
    spec = agent_env(_fake_agent(tmp_path), cfg)
    for camera in ("fixed", "follow"):  # the last one's video is read below
        video = record_video(_fake_agent(tmp_path), spec, 0, 160, 120, tmp_path / "episode.mp4", camera)
    assert video["frames"] == round(video["duration_s"] / 0.025) + 1 >= 2
    video_frames(tmp_path / "episode.mp4", tmp_path / "frames.png", width_share=0.6)
    assert Image.open(tmp_path / "frames.png").width > 100
    gif = Image.open(write_gif(tmp_path / "episode.mp4", tmp_path / "episode.gif", seconds=0.2, width=80))
    assert gif.size == (80, 60) and gif.n_frames == 4 and gif.info["duration"] == 50 and gif.info["loop"] == 0


# --------------------------------------------------------------------------- a real trained run


@pytest.fixture(scope="module")
def trained_run(tmp_path_factory):
    """A tiny DDPG training that saves a few agents (every episode qualifies)."""
    run_dir = tmp_path_factory.mktemp("eval") / "run"
    proc = run_pamrun("train", "experiment=walk", "train=smoke", "train.max_frames=600", "train.init_random_frames=200",
                      "train.updates_per_frame=0.25", "train.save_threshold=-1e9", "train.keep_saved=2", "seed=2",
                      f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    return run_dir


@pytest.mark.slow
def test_eval_of_a_run_directory_end_to_end(trained_run, tmp_path):
    out = tmp_path / "ev"
    proc = run_pamrun("eval", f"ckpt={trained_run}", "eval.episodes=2", "eval.workers=2", "eval.render=true",
                      "eval.video_width=320", "eval.video_height=240", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    for name in ("episodes.jsonl", "leaderboard.csv", "leaderboard.json", "best.pt", "selection.json",
                 "trajectories.png", "pressures.png", "training.png", "best_episode.mp4", "best_episode_frames.png",
                 "best_episode.gif"):
        assert (out / name).stat().st_size > 0, name
    board = json.loads((out / "leaderboard.json").read_text())
    # two threshold saves, the best by the evaluations during training, the final agent (last.pt)
    assert len(board["agents"]) == 4 and any(a["agent"].endswith("best_eval") for a in board["agents"])
    assert board["seeds"] == [1000, 1001] and board["errors"] == [] and board["held_out"] is True
    rows = list(csv.DictReader((out / "leaderboard.csv").open()))
    assert [r["agent"] for r in rows] == [a["agent"] for a in board["agents"]]
    # ranked by the default recipe's eval.rank_by: walk passes, then the walk's targets met, then distance
    assert board["rank_by"] == ["walk_pass_rate", "walk_targets_met", "distance_mean"]
    keys = [(-a["walk_pass_rate"], -a["walk_targets_met"], -a["distance_mean"]) for a in board["agents"]]
    assert keys == sorted(keys)
    # best.pt is the leaderboard's first agent, loadable without executing code.
    best = torch.load(out / "best.pt", weights_only=True)
    first = board["agents"][0]
    source = torch.load(first["path"], weights_only=True)["actor"]
    assert all(torch.equal(best["actor"][k], source[k]) for k in source)
    selection = json.loads((out / "selection.json").read_text())
    assert selection["best"] == first["agent"] and "ranks first of 4" in selection["reason"]
    # Per-step data: one record per agent and episode, one row per control step.
    records = [json.loads(line) for line in (out / "episodes.jsonl").open()]
    assert len(records) == 8  # 4 agents x 2 episodes
    for r in records:
        assert len(r["steps"]["x_m"]) == round(r["duration_s"] / 0.025) == len(r["steps"]["pressure_kpa"])
    # The video is a real H.264 stream of the best agent's first episode (+1 frame: the start pose).
    import av

    with av.open(str(out / "best_episode.mp4")) as container:
        frames = sum(1 for _ in container.decode(video=0))
    best_first = next(r for r in records if r["agent"] == first["agent"] and r["episode"] == 0)
    assert frames == len(best_first["steps"]["x_m"]) + 1
    assert "Leaderboard" in proc.stdout and first["agent"] in proc.stdout


@pytest.mark.slow
def test_parallel_and_single_worker_results_are_identical(trained_run):
    cfg = to_object(compose_config("eval.episodes=3", "eval.episode_s=3.0", "eval.walk_duration_s=3.0"))
    agents, kwargs, errors = load_agents(str(trained_run), cfg)
    assert not errors and len(agents) == 4
    serial = evaluate_agents(agents, kwargs, 3, seed=5, workers=1)
    parallel = evaluate_agents(agents, kwargs, 3, seed=5, workers=2)
    assert json.dumps(serial) == json.dumps(parallel)  # every float of every step (NaN gait metrics too)
    # Same seeds for every agent: an agent alone gets exactly what it got among the others.
    alone = evaluate_agents(agents[1:2], kwargs[1:2], 3, seed=5, workers=2)
    assert json.dumps(alone[0]) == json.dumps(serial[1])
    # Distinct seeds give distinct starts (0.01 rad noise).
    assert serial[0][0]["steps"]["joint_angle_rad"][0] != serial[0][1]["steps"]["joint_angle_rad"][0]


# --------------------------------------------------------------------------- bad input


class _RunsCode:
    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _fake_agent(tmp_path):
    """An untrained actor as an agent file (for env-level tests)."""
    from pamrun.learning.checkpoints import agent_record
    from pamrun.learning.networks import ThesisActor

    path = tmp_path / "untrained.pt"
    cfg = to_object(compose_config())
    torch.save(agent_record(ThesisActor(OBS_SIZE, N_JOINTS, (400, 300), 3e-3).state_dict(), cfg, {}), path)
    return load_agent(path, OBS_SIZE, N_JOINTS)


def _bad_files(folder, good):
    from pamrun.learning.checkpoints import agent_record
    from pamrun.learning.networks import ThesisActor

    folder.mkdir()
    malicious = _RunsCode()
    malicious.marker = folder / "code_ran"
    torch.save({"actor": malicious}, folder / "agent_ep000001_r1.0.pt")
    data = (good).read_bytes()
    (folder / "agent_ep000002_r1.0.pt").write_bytes(data[: len(data) // 2])
    cfg = to_object(compose_config())
    torch.save(agent_record(ThesisActor(45, N_JOINTS, (400, 300), 3e-3).state_dict(), cfg, {}),
               folder / "agent_ep000003_r1.0.pt")
    (folder / "agent_ep000004_r1.0.pt").write_bytes(pickle.dumps({"actor": "not weights"}))
    shutil.copy(good, folder / "agent_ep000005_r9.0.pt")
    return malicious.marker


@pytest.mark.slow
def test_bad_checkpoints_are_named_and_the_others_evaluated(trained_run, tmp_path):
    good = sorted((trained_run / "checkpoints").glob("agent_ep*.pt"))[0]
    marker = _bad_files(tmp_path / "mixed", good)
    messages = {}
    for path in sorted((tmp_path / "mixed").glob("*.pt"))[:4]:
        with pytest.raises(CheckpointError) as err:
            load_agent(path, OBS_SIZE, N_JOINTS)
        assert err.value.path == str(path)
        messages[path.name] = err.value.message
    assert not marker.exists()  # the pickle's code never ran
    assert "nothing was executed" in messages["agent_ep000001_r1.0.pt"]
    assert "truncated or corrupt" in messages["agent_ep000002_r1.0.pt"]
    assert "45 observations" in messages["agent_ep000003_r1.0.pt"]

    out = tmp_path / "ev"
    proc = run_pamrun("eval", f"ckpt={tmp_path / 'mixed'}/agent_*.pt", "eval.episodes=1", "eval.episode_s=1.0",
                      "eval.walk_duration_s=1.0", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not marker.exists()
    board = json.loads((out / "leaderboard.json").read_text())
    assert [a["agent"] for a in board["agents"]] == ["mixed/agent_ep000005_r9.0"]
    assert sorted(os.path.basename(e["path"]) for e in board["errors"]) == [
        f"agent_ep00000{i}_r1.0.pt" for i in range(1, 5)]
    assert "4 checkpoint(s) skipped" in proc.stdout and "agent_ep000002_r1.0.pt" in proc.stdout


def test_no_checkpoints_fails_before_anything_is_written(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    out = tmp_path / "ev"
    for spec in (empty, tmp_path / "missing.pt", f"{empty}/*.pt"):
        proc = run_pamrun("eval", f"ckpt={spec}", f"hydra.run.dir={out}")
        assert proc.returncode != 0
        assert "ckpt" in proc.stderr and str(spec) in proc.stderr, proc.stderr
        assert not out.exists()
    proc = run_pamrun("eval", f"hydra.run.dir={out}")
    assert proc.returncode != 0 and "no checkpoint given" in proc.stderr


SHIPPED = Path(__file__).parents[1] / "agents" / "walker_td3_seed0.pt"


def _left_ankle_roll_deg(out: Path) -> np.ndarray:
    """Every control step's left ankle roll [deg] of an evaluation's episodes.jsonl."""
    index = JOINTS.index("left_ankle_roll")
    rows = [json.loads(line) for line in (out / "episodes.jsonl").read_text().splitlines()]
    return np.degrees([step[index] for row in rows for step in row["steps"]["joint_angle_rad"]])


def test_a_key_on_the_command_line_changes_each_agents_own_env(tmp_path):
    """``pamrun eval ckpt=<agent> body.KEY=...`` runs the agent in its own robot and task with that key
    changed (here the ankle roll's stop moved from -25 to -10 deg, which the shipped walker leans
    on); a preset chosen there is said to be left out, and a change impossible in the agent's own env
    fails before anything is written, naming the key."""
    common = ["eval.episodes=2", "eval.episode_s=2", "eval.walk_duration_s=2", "eval.workers=1"]
    plain = run_pamrun("eval", f"ckpt={SHIPPED}", *common, f"hydra.run.dir={tmp_path / 'plain'}")
    assert plain.returncode == 0, plain.stderr[-2000:]
    assert _left_ankle_roll_deg(tmp_path / "plain").min() < -20  # on its stop at -25
    changed = run_pamrun("eval", f"ckpt={SHIPPED}", *common, "body.ankle_roll_limits_deg=[-10,35]",
                         "experiment=thesis", f"hydra.run.dir={tmp_path / 'changed'}")
    assert changed.returncode == 0, changed.stderr[-2000:]
    assert _left_ankle_roll_deg(tmp_path / "changed").min() > -13  # the stop is at -10 now (within its give)
    out = " ".join(changed.stdout.split())
    assert "with body.ankle_roll_limits_deg=[-10.0, 35.0]" in out
    assert "experiment=thesis chose a robot or task that no agent runs in" in out
    state = torch.load(SHIPPED, map_location="cpu", weights_only=True)
    state["config"]["env"]["slope_deg"] = 3.0  # an agent trained on a slope: one terrain at a time
    torch.save(state, tmp_path / "sloped.pt")
    proc = run_pamrun("eval", f"ckpt={tmp_path / 'sloped.pt'}", "env.step_height_m=0.02",
                      f"hydra.run.dir={tmp_path / 'no'}")
    assert proc.returncode != 0 and not (tmp_path / "no").exists()
    assert "env.step_height_m: one terrain at a time" in proc.stderr, proc.stderr


def test_only_unreadable_checkpoints_is_an_error(tmp_path):
    folder = tmp_path / "bad"
    folder.mkdir()
    (folder / "agent_ep000001_r1.0.pt").write_bytes(b"not a zip file")
    proc = run_pamrun("eval", f"ckpt={folder}", f"hydra.run.dir={tmp_path / 'ev'}")
    assert proc.returncode != 0 and "ckpt: none of its 1 checkpoint(s) is usable" in proc.stderr
    assert "agent_ep000001_r1.0.pt: " in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "ev").exists()  # refused before anything is written


@pytest.mark.slow
def test_find_checkpoints_in_a_folder_of_runs(trained_run, tmp_path):
    sweep = tmp_path / "sweep"
    for name in ("0", "1"):
        shutil.copytree(trained_run / "checkpoints", sweep / name / "checkpoints",
                        ignore=shutil.ignore_patterns("buffer*"))
    found = find_checkpoints(str(sweep))
    assert len(found) == 8 and {p.parent.parent.name for p in found} == {"0", "1"}
    assert len(find_checkpoints(str(sweep), include_last=False)) == 6  # 2 saved + best_eval per run
    assert len(find_checkpoints(str(trained_run / "checkpoints" / "last.pt"))) == 1


@pytest.mark.slow
def test_outside_a_terminal_no_table_cuts_a_path(tmp_path):
    """A log keeps every agent's whole label and path: no '…' (rich's cut) in any table."""
    deep = tmp_path / ("a_rather_long_folder_name_for_a_sweep_of_many_settings_" * 3) / "checkpoints"
    deep.mkdir(parents=True)
    shutil.copy(_fake_agent(tmp_path).path, deep / "agent_ep000001_r1.0.pt")
    out = tmp_path / "ev"
    proc = run_pamrun("eval", f"ckpt={deep / 'agent_ep000001_r1.0.pt'}", "eval.episodes=1", "eval.episode_s=0.5",
                      "eval.walk_duration_s=0.5", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    (row,) = json.loads((out / "leaderboard.json").read_text())["agents"]
    assert len(row["agent"]) > 160 and row["agent"] in proc.stdout and "…" not in proc.stdout
