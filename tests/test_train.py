"""End-to-end `pamrun train` with a tiny budget and a fixed seed."""

from __future__ import annotations

import copy
import csv
import json
import shutil

import pytest
import torch

from pamrun.config import to_object
from tests.conftest import compose_config, run_pamrun

TINY = ["experiment=walk", "train=smoke", "train.max_frames=600", "train.init_random_frames=200", "train.updates_per_frame=0.25",
        "train.checkpoint_every_frames=200", "seed=1"]


def train_here(run_dir, *overrides: str) -> str:
    """``pamrun train overrides...`` in this process (no Hydra, no subprocess); its status."""
    from pamrun.training.recipe import train

    return train(to_object(compose_config(*overrides)), run_dir, list(overrides))


def test_train_in_process_is_reproducible(tmp_path):
    """``pamrun.training.recipe.train(cfg, out)`` runs in this process, with no Hydra: the same seed gives
    the same episodes.csv, every column but wall time, also with the walking recipe's start-pose
    noise (whose first episode once started from an unseeded reset), and a run.json that says so.
    TensorBoard's ``reward_terms/*`` has each weighted term's episode sum, adding up to its reward."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from pamrun.runs.directory import read_episodes
    from pamrun.task.reward import REWARD_KEYS
    from pamrun.training.recipe import train

    cfg = to_object(compose_config(*TINY, "train.max_frames=400", "train.eval_every_frames=0"))
    assert cfg.env.reset_noise_rad > 0 and cfg.algo.name == "td3"  # the default recipe: experiment=walk
    runs = []
    for name in ("a", "b"):
        assert train(copy.deepcopy(cfg), tmp_path / name, ["seed=1"]) == "max_frames"
        runs.append([{k: v for k, v in r.items() if k != "wall_time_s"} for r in read_episodes(tmp_path / name)])
    assert len(runs[0]) > 2 and runs[0] == runs[1]
    events = EventAccumulator(str(tmp_path / "a" / "tensorboard")).Reload()  # each weighted term, per episode
    weighted = [k for k in REWARD_KEYS if getattr(cfg.reward, k)]
    assert sorted(t for t in events.Tags()["scalars"] if t.startswith("reward_terms/")) == sorted(
        f"reward_terms/{k}" for k in weighted)
    for i, episode in enumerate(events.Scalars("episode/reward")):
        terms = [events.Scalars(f"reward_terms/{k}")[i] for k in weighted]
        assert {t.step for t in terms} == {episode.step}
        assert sum(t.value for t in terms) == pytest.approx(episode.value, rel=1e-4)
    info = json.loads((tmp_path / "a" / "run.json").read_text())
    assert info["command"] == "pamrun train seed=1" and info["frames"] == 400


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["ddpg", "td3"])
def test_train_leaves_its_files(tmp_path, algo):
    run_dir = tmp_path / algo
    assert train_here(run_dir, f"algo={algo}", *TINY, "train.save_threshold=-1e9", "train.keep_saved=2") == "max_frames"
    run = json.loads((run_dir / "run.json").read_text())
    assert run["status"] == "max_frames" and run["frames"] == 600 and run["algo"] == algo
    assert run["updates"] == 100  # (600 - 200) frames * 0.25
    rows = list(csv.DictReader((run_dir / "episodes.csv").open()))
    assert len(rows) == run["episodes"] >= 1
    assert [int(r["episode"]) for r in rows] == list(range(1, len(rows) + 1))
    assert set(rows[0]) >= {"reward", "avg_reward", "q0", "length", "distance_m", "frames", "wall_time_s"}
    assert list((run_dir / "tensorboard").glob("events.out.tfevents.*"))
    last = torch.load(run_dir / "checkpoints" / "last.pt", weights_only=True)
    assert {k: last["counters"][k] for k in ("frames", "episodes", "updates")} == {
        "frames": 600, "episodes": run["episodes"], "updates": 100}
    # Threshold saves: every episode qualifies, only the best keep_saved stay.
    saved = sorted((run_dir / "checkpoints").glob("agent_*.pt"))
    assert len(saved) == 2 and len(run["saved_agents"]) == 2
    best = max(float(r["reward"]) for r in rows)
    metas = [torch.load(p, weights_only=True)["meta"] for p in saved]
    assert max(m["reward"] for m in metas) == pytest.approx(best, abs=1e-4)


@pytest.mark.slow
def test_threshold_not_reached_saves_nothing(tmp_path):
    """Also: its stdout is a pipe, so its progress is plain lines (the first batch's, one after the
    evaluation at 400 frames, the last), with the budget's fraction, time remaining and evaluation."""
    import re

    run_dir = tmp_path / "none"
    proc = run_pamrun("train", *TINY, "train.max_frames=400", "train.save_threshold=1e9", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not list((run_dir / "checkpoints").glob("agent_*.pt"))
    assert (run_dir / ".hydra" / "config.yaml").exists()  # the command: Hydra's run directory
    lines = [line for line in proc.stdout.splitlines() if line.startswith("frames ")]
    assert re.fullmatch(r"frames 200/400 \(50\.0%\)  eta \S+  \d+ frames/s  \S+ updates/s  episodes \d+  avg .*",
                        lines[0])
    assert lines[-1].startswith("frames 400/400 (100.0%)  eta 0s") and re.search(
        r"  eval: stand \d+/2 walk \d/2 \(\d+-\d+ %\) targets \d+/13$", lines[-1])


@pytest.mark.slow
def test_unknown_algo_fails_before_the_run_dir(tmp_path):
    run_dir = tmp_path / "bad"
    proc = run_pamrun("train", "algo=ppo", f"hydra.run.dir={run_dir}")
    assert proc.returncode != 0 and "ppo" in proc.stderr
    proc = run_pamrun("train", "algo.batch_size=-1", f"hydra.run.dir={run_dir}")
    assert proc.returncode != 0 and "algo.batch_size" in proc.stderr + proc.stdout
    assert not run_dir.exists()


@pytest.mark.slow
def test_killed_run_resumes_without_losing_or_duplicating(tmp_path):
    """SIGKILL mid-run, then `resume=`: the run completes with one row per episode."""
    import os
    import signal
    import subprocess
    import sys
    import time

    run_dir = tmp_path / "killed"
    args = [sys.executable, "-m", "pamrun.cli", "train", *TINY, "train.max_frames=1400",
            "train.save_threshold=-1e9", "train.keep_saved=1000", f"hydra.run.dir={run_dir}"]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.time() + 240
    last = run_dir / "checkpoints" / "last.pt"
    while time.time() < deadline:
        if last.exists():
            try:
                if torch.load(last, weights_only=True)["counters"]["frames"] >= 600:
                    break
            except Exception:  # being replaced right now: atomic rename, try again
                pass
        time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    killed_at = torch.load(last, weights_only=True)["counters"]
    assert 600 <= killed_at["frames"] < 1400
    assert json.loads((run_dir / "run.json").read_text())["status"] == "running"

    done = run_pamrun("train", f"resume={run_dir}")
    assert done.returncode == 0, done.stderr[-3000:]
    run = json.loads((run_dir / "run.json").read_text())
    assert run["status"] == "max_frames" and run["frames"] == 1400
    assert run["resumed"][0]["frames"] == killed_at["frames"]
    rows = list(csv.DictReader((run_dir / "episodes.csv").open()))
    assert [int(r["episode"]) for r in rows] == list(range(1, run["episodes"] + 1))
    frames = [int(r["frames"]) for r in rows]
    assert frames == sorted(frames)
    agents = sorted(p.name for p in (run_dir / "checkpoints").glob("agent_*.pt"))
    episodes_saved = [int(n.split("_")[1][2:]) for n in agents]
    assert len(set(episodes_saved)) == len(episodes_saved) == run["episodes"]  # one per episode, none lost
    # The original config was kept; the resume's own Hydra files went elsewhere.
    assert (run_dir / ".hydra" / "overrides.yaml").read_text().count("max_frames=1400") == 1
    assert (run_dir / ".hydra-resume").exists()


def test_plot_training_redraws_from_csv(tmp_path):
    run_dir = tmp_path / "plot"
    run_dir.mkdir()
    (run_dir / "episodes.csv").write_text(
        "episode,frames,reward,avg_reward,q0,length,distance_m,wall_time_s\n"
        "1,40,-10.5,-10.5,0.1,40,0.01,1.0\n2,90,-5.0,-7.75,0.2,50,0.02,2.0\n"
    )
    proc = run_pamrun("plot", "training", f"dir={run_dir}", f"hydra.run.dir={tmp_path / 'job'}")
    assert proc.returncode == 0, proc.stderr
    assert (run_dir / "training.png").stat().st_size > 5000


@pytest.mark.slow
def test_evaluations_during_training(tmp_path):
    """A smoke run evaluates its actor every 400 frames: evals.csv, eval/* in TensorBoard, best_eval.pt."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    from pamrun.learning.checkpoints import find_checkpoints, load_agent

    run_dir = tmp_path / "evals"
    assert train_here(run_dir, "algo=td3", "train=smoke", "seed=2") == "max_frames"
    rows = list(csv.DictReader((run_dir / "evals.csv").open()))
    assert [int(r["frames"]) for r in rows] == [400, 800, 1200]
    for r in rows:
        assert 0 <= float(r["walk_pass_rate"]) <= float(r["stand_rate"]) <= 1
        assert float(r["stand_rate"]) + float(r["fall_rate"]) <= 1 + 1e-9
        assert 0 < float(r["duration_mean"]) <= 10.0 and float(r["eval_s"]) > 0
    assert rows[0]["best"] == "1" and sum(int(r["best"]) for r in rows) >= 1
    best = load_agent(run_dir / "checkpoints" / "best_eval.pt")
    last_best = [r for r in rows if r["best"] == "1"][-1]
    assert best.meta["frames"] == int(last_best["frames"])
    assert best.meta["eval"]["distance_mean"] == pytest.approx(float(last_best["distance_mean"]), abs=1e-4)
    n = to_object(compose_config("train=smoke")).train.eval_episodes
    assert best.meta["eval"]["seeds"] == [0, n - 1]  # the selection block, so pamrun eval can tell held-out seeds
    assert run_dir / "checkpoints" / "best_eval.pt" in find_checkpoints(str(run_dir))  # pamrun eval sees it
    assert (run_dir / "evals.png").stat().st_size > 10_000
    events = EventAccumulator(str(run_dir / "tensorboard")).Reload()
    assert {"eval/walk_pass_rate", "eval/stand_rate", "eval/distance_mean", "eval/eval_s"} <= set(events.Tags()["scalars"])
    assert [e.step for e in events.Scalars("eval/distance_mean")] == [400, 800, 1200]


def test_evaluation_is_deterministic_and_matches_pamrun_eval(tmp_path, cfg):
    """The evaluator's numbers for an actor are pamrun eval's for the same agent file."""
    from pamrun.evaluation.episodes import agent_env, aggregate, evaluate_agents
    from pamrun.evaluation.evaluator import TrainingEvaluator
    from pamrun.learning.checkpoints import agent_record, load_agent
    from pamrun.learning.networks import make_actor

    torch.manual_seed(0)
    cfg.train.eval_episodes, cfg.eval.episodes, cfg.eval.episode_s, cfg.eval.walk_duration_s = 3, 3, 2.0, 2.0
    actor = make_actor(cfg.algo, 43, 10).module
    evaluator = TrainingEvaluator(cfg)
    first, again = evaluator(actor), evaluator(actor)
    assert json.dumps({k: v for k, v in first.items() if k != "eval_s"}) == json.dumps(
        {k: v for k, v in again.items() if k != "eval_s"})  # (NaN gait metrics included)
    torch.save(agent_record(actor.state_dict(), cfg, {}), tmp_path / "a.pt")
    agent = load_agent(tmp_path / "a.pt")
    episodes = evaluate_agents([agent], [agent_env(agent, cfg)], 3, cfg.eval.selection_seed, workers=1)[0]
    reference = aggregate(episodes, cfg.eval)
    assert first["distance_mean"] == pytest.approx(reference["distance_mean"], abs=1e-6)
    assert first["duration_mean"] == pytest.approx(reference["duration_mean"])


@pytest.mark.slow
def test_the_default_recipe_runs_end_to_end(tmp_path):
    """``pamrun train train=smoke`` on the default recipe (experiment=gait): randomised episodes,
    mirroring, the three stages announced, evaluations, a finished run that says which recipe it ran."""
    from pamrun.runs.directory import saved_config

    run_dir = tmp_path / "default"
    proc = run_pamrun("train", "train=smoke", "seed=1", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = " ".join(proc.stdout.replace("│", " ").split())  # the header table's cells, unwrapped
    assert "kflight 2 once it stands" in out and "kflight 20 once every episode walks" in out
    run = json.loads((run_dir / "run.json").read_text())
    assert run["status"] == "max_frames" and run["frames"] == 1200
    assert len(list(csv.DictReader((run_dir / "evals.csv").open()))) == 3
    saved = saved_config(run_dir)
    assert saved.algo.mirror_loss == 0.6 and saved.train.mirror and saved.train.gait_weights == {"kflight": 20.0}
    assert saved.eval.rank_by[1] == "walk_targets_met" and (run_dir / "checkpoints" / "best_eval.pt").exists()


@pytest.mark.slow
def test_stop_on_walk(tmp_path):
    """With a walk test an untrained (standing) actor passes, the run stops at its first evaluation."""
    run_dir = tmp_path / "walked"
    proc = run_pamrun("train", *TINY, "train.max_frames=2000", "train.eval_every_frames=200", "train.stop_on_walk=true",
                      "eval.episode_s=0.5", "eval.walk_duration_s=0.5", "eval.walk_distance_m=0",
                      f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    run = json.loads((run_dir / "run.json").read_text())
    rows = list(csv.DictReader((run_dir / "evals.csv").open()))
    assert run["status"] == "walked" and rows[-1]["walk_pass_rate"] == "1.0"
    assert run["frames"] == int(rows[-1]["frames"]) < 2000
    proc = run_pamrun("train", "experiment=walk", "train.stop_on_walk=true", "train.eval_every_frames=0", f"hydra.run.dir={tmp_path / 'x'}")
    assert proc.returncode != 0 and "train.stop_on_walk" in proc.stderr + proc.stdout


@pytest.mark.slow
def test_resume_forgets_evaluations_after_the_checkpoint(tmp_path):
    from pamrun.runs.directory import read_evals, truncate_logs

    run_dir = tmp_path / "r"
    train_here(run_dir, *TINY, "train.eval_every_frames=200", "train.eval_episodes=1")
    assert [r["frames"] for r in read_evals(run_dir)] == ["200", "400", "600"]
    truncate_logs(run_dir, {"frames": 400, "episodes": 1})
    assert [r["frames"] for r in read_evals(run_dir)] == ["200", "400"]
    (run_dir / "evals.csv").write_text("frames,walk_pass_rate\nten,x\n")
    with pytest.raises(SystemExit, match="evals.csv"):
        truncate_logs(run_dir, {"frames": 400, "episodes": 1})


@pytest.mark.slow
def test_async_collection(tmp_path):
    """train.async_collection: the env steps in its own process; the run's files and counters are
    those of a synchronous run."""
    run_dir = tmp_path / "async"
    assert train_here(run_dir, "algo=td3", *TINY, "train.async_collection=true") == "max_frames"
    run = json.loads((run_dir / "run.json").read_text())
    assert run["status"] == "max_frames" and run["frames"] == 600 and run["updates"] == 100
    rows = list(csv.DictReader((run_dir / "episodes.csv").open()))
    assert [int(r["episode"]) for r in rows] == list(range(1, run["episodes"] + 1))
    assert sum(int(r["length"]) for r in rows) <= 600


def test_walk_curriculum_reweights_replay_samples_to_the_reward_with_walk_kvx(cfg):
    """``train.walk_kvx``: once walking, a sample from the replay buffer has the reward the env
    pays with reward.kvx = walk_kvx for the same step (same start, same actions), from the
    unweighted terms the buffer stores; before, the env's own reward."""
    from pamrun.learning.curriculum import WalkCurriculum
    from pamrun.training.recipe import make_buffer, make_env

    cfg.train.walk_kvx, cfg.train.init_random_frames, cfg.train.actor_start_frames = 4.0, 1000, 0
    rollouts = []
    for kvx in (cfg.reward.kvx, 4.0):
        walk_cfg = copy.deepcopy(cfg)
        walk_cfg.reward.kvx = kvx
        env = make_env(walk_cfg)
        env.set_seed(0)
        torch.manual_seed(0)  # the same random actions
        rollouts.append(env.rollout(60, break_when_any_done=True))
        env.close()
    base, walk = rollouts
    assert torch.equal(base["action"], walk["action"]) and len(base) > 10
    assert not torch.allclose(base["next", "reward"], walk["next", "reward"])
    curriculum = WalkCurriculum(cfg)
    buffer = make_buffer(cfg, curriculum)
    buffer.extend(base)
    curriculum.replay([{"stand_rate": "1.0", "frames": "1000"}])  # the untrained actor stands: not yet
    assert not curriculum.walking
    sample = buffer.sample(200)
    assert torch.equal(sample["next", "reward"], base["next", "reward"][sample["index"]])
    assert curriculum.observe(0.9, 2000) is False and curriculum.observe(1.0, 2000) is True
    assert curriculum.observe(1.0, 3000) is False and curriculum.since == 2000  # it starts once
    sample = buffer.sample(200)
    assert torch.allclose(sample["next", "reward"], walk["next", "reward"][sample["index"]], atol=1e-5)
    assert torch.equal(buffer.storage[:len(base)]["next", "reward"], base["next", "reward"])  # the stored ones: the env's
    resumed = WalkCurriculum(cfg)
    resumed.replay([{"stand_rate": "0.5", "frames": "1200"}, {"stand_rate": "1", "frames": "1400"}])
    assert resumed.walking and resumed.since == 1400
    cfg.train.walk_kvx = None
    off = WalkCurriculum(cfg)
    off.replay([{"stand_rate": "1", "frames": "1400"}])
    assert not off.walking


@pytest.mark.slow
def test_walk_curriculum_in_a_run(tmp_path, capsys):
    """A run with train.walk_kvx starts the walking stage at its first standing evaluation after
    the actor learns, says so, and records it in run.json and TensorBoard."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    run_dir = tmp_path / "curriculum"
    train_here(run_dir, *TINY, "train.max_frames=1000", "train.eval_every_frames=200", "train.eval_episodes=1",
               "train.walk_kvx=4", "train.walk_noise_beta=1", "eval.episode_s=0.25", "eval.walk_duration_s=0.25")
    rows = list(csv.DictReader((run_dir / "evals.csv").open()))
    first = next(int(r["frames"]) for r in rows if float(r["stand_rate"]) == 1 and int(r["frames"]) > 200)
    assert first < 1000  # the learner then learns from relabelled samples of the collector's batches
    assert json.loads((run_dir / "run.json").read_text())["updates"] == 200
    assert json.loads((run_dir / "run.json").read_text())["walk_kvx_from_frames"] == first
    assert "train.walk_kvx = 4" in capsys.readouterr().out
    events = EventAccumulator(str(run_dir / "tensorboard")).Reload()
    assert [(e.step, e.value) for e in events.Scalars("curriculum/kvx")] == [(first, 4.0)]
    # white exploration (TD3's, algo.noise_beta 0) until it stands, pink from the next batch on
    betas = [(e.step, e.value) for e in events.Scalars("exploration/noise_beta")]
    assert {v for step, v in betas if step <= first} == {0.0} and {v for step, v in betas if step > first} == {1.0}
    train_here(run_dir, f"resume={run_dir}", "train.max_frames=1200")  # the stage carries over a resume
    out = " ".join(capsys.readouterr().out.split())
    assert f"Walking stage of the curriculum since {first} frames" in out and "1/f^0 -> 1/f^1" in out
    events = EventAccumulator(str(run_dir / "tensorboard")).Reload()
    assert {e.value for e in events.Scalars("exploration/noise_beta") if e.step > 1000} == {1.0}
    proc = run_pamrun("train", "experiment=walk", "train.walk_kvx=4", "train.eval_every_frames=0", "train.stop_on_walk=false",
                      f"hydra.run.dir={tmp_path / 'x'}")
    assert proc.returncode != 0 and "train.walk_kvx" in proc.stderr + proc.stdout


def test_a_crossq_run_trains_and_resumes_with_its_critics_statistics(tmp_path):
    """``algo.crossq=true``: a run saves no critic targets and its critics' renormalisation state,
    which a resume takes up (the count of training batches runs on from the checkpoint's)."""
    run_dir = tmp_path / "crossq"
    crossq = ("algo.crossq=true", "algo.actor_update_every=3", "algo.adam_beta1=0.5", "train.eval_every_frames=0")
    assert train_here(run_dir, *TINY, *crossq) == "max_frames"
    state = torch.load(run_dir / "checkpoints" / "last.pt", weights_only=False)["networks"]
    assert state["critic_targets"] == {}
    assert int(state["critics"]["0.net.0.num_batches_tracked"]) == 100  # (600 - 200 random) x 0.25 updates
    assert train_here(run_dir, f"resume={run_dir}", "train.max_frames=800") == "max_frames"
    state = torch.load(run_dir / "checkpoints" / "last.pt", weights_only=False)["networks"]
    assert int(state["critics"]["1.net.3.num_batches_tracked"]) == 150


@pytest.mark.slow
def test_resume_takes_a_new_budget_and_names_what_it_ignores(tmp_path):
    """``resume=<dir> train.max_frames=...`` extends a finished run; any other value on a resume's
    command line is named as ignored, and the run keeps its own config."""
    from pamrun.runs.directory import saved_config

    run_dir = tmp_path / "extend"
    proc = run_pamrun("train", *TINY, "train.eval_every_frames=0", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    proc = run_pamrun("train", f"resume={run_dir}", "train.max_frames=800", "algo.actor_lr=0.5")
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = " ".join(proc.stdout.split())
    assert "train.max_frames 600 -> 800" in out and "ignored" in out and "algo.actor_lr=0.5" in out
    run = json.loads((run_dir / "run.json").read_text())
    assert run["status"] == "max_frames" and run["frames"] == 800
    saved = saved_config(run_dir)
    assert saved.train.max_frames == 800 and saved.algo.actor_lr == 1e-4  # the walking recipe's
    proc = run_pamrun("train", f"resume={run_dir}")
    assert proc.returncode == 0 and "already finished its budget (800 frames" in " ".join(proc.stdout.split())


@pytest.mark.slow
def test_a_run_started_from_a_trained_agent_begins_with_its_networks(tmp_path):
    """``train.init_from``: a run's last.pt gives the new run its actor, critics, targets and replay
    buffer (not the buffer where reward.*, env.*, body.* or muscle.* differs, or where its transitions lack a term this run's
    stages weigh that its pamrun did not compute, or where the last.pt was copied without its buffer
    folder: training computes every term, so a term the source never weighed comes along); an
    agent file its actor alone (the critics new,
    the buffer empty; with algo.anchor, a frozen copy of it in last.pt, and the anchor's weight as it
    fades in TensorBoard); the agent is evaluated at frame 0;
    the counters start at 0. With no updates
    the networks end as they began, so last.pt shows what was taken."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    from pamrun.learning import checkpoints
    from pamrun.learning.curriculum import FEATURES
    from pamrun.runs.directory import saved_config
    from pamrun.task.reward import REWARD_KEYS

    source = tmp_path / "source"
    assert train_here(source, *TINY, "train.max_frames=400", "train.eval_every_frames=0") == "max_frames"
    a = torch.load(source / "checkpoints" / "last.pt", weights_only=True)
    still = ["train.max_frames=400", "train.init_random_frames=0", "train.updates_per_frame=0"]

    full = tmp_path / "full"
    assert train_here(full, *TINY, *still, f"train.init_from={source / 'checkpoints' / 'last.pt'}") == "max_frames"
    b = torch.load(full / "checkpoints" / "last.pt", weights_only=True)
    for part in ("actor", "critics", "actor_target", "critic_targets"):
        assert all(torch.equal(v, b["networks"][part][k]) for k, v in a["networks"][part].items()), part
    assert b["counters"]["frames"] == 400 and b["counters"]["updates"] == 0 and b["buffer"]["length"] == 800
    rows = list(csv.DictReader((full / "evals.csv").open()))
    assert [int(r["frames"]) for r in rows] == [0, 400]  # the agent it starts from, then train=smoke's own
    assert rows[0]["return_mean"] == rows[1]["return_mean"]  # the same actor, deterministic evaluations

    agent = source / "checkpoints" / "actor_only.pt"
    torch.save({"actor": a["actor"], "meta": {}}, agent)
    half = tmp_path / "half"
    assert train_here(half, *TINY, *still, "train.eval_every_frames=0", f"train.init_from={agent}",
                      "algo.anchor=0.4", "algo.anchor_fade_start_frames=100", "algo.anchor_fade_frames=200") == "max_frames"
    faded = EventAccumulator(str(half / "tensorboard")).Reload().Scalars("curriculum/anchor")
    assert [e.step for e in faded] == [200, 400] and faded[0].value == pytest.approx(0.2) and faded[1].value == 0
    c = torch.load(half / "checkpoints" / "last.pt", weights_only=True)
    for part in ("actor", "anchor_actor"):  # algo.anchor: the actor it started from, kept for a resume
        assert all(torch.equal(v, c["networks"][part][k]) for k, v in a["networks"]["actor"].items()), part
    assert not all(torch.equal(v, c["networks"]["critics"][k]) for k, v in a["networks"]["critics"].items())
    assert c["buffer"]["length"] == 400

    other = tmp_path / "other"  # rewards summed with another reward.kv: the buffer stays behind
    assert train_here(other, *TINY, *still, "train.eval_every_frames=0", "reward.kv=0.5",
                      f"train.init_from={source / 'checkpoints' / 'last.pt'}") == "max_frames"
    d = torch.load(other / "checkpoints" / "last.pt", weights_only=True)
    assert d["buffer"]["length"] == 400
    assert all(torch.equal(v, d["networks"]["critics"][k]) for k, v in a["networks"]["critics"].items())

    speed = tmp_path / "speed"  # gathered in an env that asked another speed (kspeed's, kstep's): left behind
    assert train_here(speed, *TINY, *still, "train.eval_every_frames=0", "env.target_speed_m_s=0.8",
                      f"train.init_from={source / 'checkpoints' / 'last.pt'}") == "max_frames"
    assert torch.load(speed / "checkpoints" / "last.pt", weights_only=True)["buffer"]["length"] == 400

    assert a["buffer"]["terms"] == sorted(REWARD_KEYS)  # training computes every term, at any weight
    stored = TensorDictReplayBuffer(storage=LazyTensorStorage(saved_config(source).train.buffer_size))
    checkpoints.load_buffer(source / "checkpoints", a["buffer"], stored)
    assert stored[:]["next", FEATURES, "kslip"].abs().sum() > 0  # kslip's, at weight 0 in the source
    every = tmp_path / "every"  # so a run that weighs kslip, which the source never weighed, takes its buffer
    assert train_here(every, *TINY, *still, "+train.walk_weights.kslip=1",
                      f"train.init_from={source / 'checkpoints' / 'last.pt'}") == "max_frames"
    assert torch.load(every / "checkpoints" / "last.pt", weights_only=True)["buffer"]["length"] == 800

    older = tmp_path / "older"  # the source's last.pt as a pamrun that did not compute kslip would have saved it
    shutil.copytree(source / "checkpoints", older)
    state = torch.load(older / "last.pt", weights_only=True)
    state["buffer"]["terms"].remove("kslip")
    torch.save(state, older / "last.pt")
    f_dir = tmp_path / "uncomputed"  # weighing kslip, it leaves that buffer (0 for kslip) behind
    assert train_here(f_dir, *TINY, *still, "+train.walk_weights.kslip=1",
                      f"train.init_from={older / 'last.pt'}") == "max_frames"
    assert torch.load(f_dir / "checkpoints" / "last.pt", weights_only=True)["buffer"]["length"] == 400
    via = tmp_path / "via"  # weighing no new term it takes it, and its own last.pt still says kslip is not carried
    assert train_here(via, *TINY, *still, "train.eval_every_frames=0", f"train.init_from={older / 'last.pt'}") == "max_frames"
    v = torch.load(via / "checkpoints" / "last.pt", weights_only=True)["buffer"]
    assert v["length"] == 800 and "kslip" not in v["terms"]
    assert train_here(tmp_path / "from_via", *TINY, *still, "+train.walk_weights.kslip=1",
                      f"train.init_from={via / 'checkpoints' / 'last.pt'}") == "max_frames"
    assert torch.load(tmp_path / "from_via" / "checkpoints" / "last.pt", weights_only=True)["buffer"]["length"] == 400
    g_dir = tmp_path / "computed"  # f_dir's env computed kslip (its walking stage's): its buffer comes along
    assert train_here(g_dir, *TINY, *still, "+train.walk_weights.kslip=2",
                      f"train.init_from={f_dir / 'checkpoints' / 'last.pt'}") == "max_frames"
    assert torch.load(g_dir / "checkpoints" / "last.pt", weights_only=True)["buffer"]["length"] == 800
    moved = tmp_path / "moved"  # a last.pt and its buffer outside their run directory: the record still says
    shutil.copytree(f_dir / "checkpoints", moved)
    assert train_here(tmp_path / "from_moved", *TINY, *still, "+train.walk_weights.kslip=2",
                      f"train.init_from={moved / 'last.pt'}") == "max_frames"
    assert torch.load(tmp_path / "from_moved" / "checkpoints" / "last.pt", weights_only=True)["buffer"]["length"] == 800
    alone = tmp_path / "alone"  # a last.pt copied without its buffer: its networks, an empty buffer
    alone.mkdir()
    shutil.copy(f_dir / "checkpoints" / "last.pt", alone)
    assert train_here(tmp_path / "from_alone", *TINY, *still, "+train.walk_weights.kslip=2",
                      f"train.init_from={alone / 'last.pt'}") == "max_frames"
    e = torch.load(tmp_path / "from_alone" / "checkpoints" / "last.pt", weights_only=True)
    assert e["buffer"]["length"] == 400
    assert all(torch.equal(v, e["networks"]["critics"][k]) for k, v in a["networks"]["critics"].items())


@pytest.mark.slow
def test_an_agent_that_does_not_fit_fails_before_the_run_dir(tmp_path):
    """A missing file, an agent of another observation size (here one told its commanded speed), or a
    last.pt whose replay buffer, which this run would take, lacks a file, stops ``pamrun train``
    naming train.init_from before anything is written."""
    source = tmp_path / "source"
    assert train_here(source, *TINY, "train.max_frames=200", "train.eval_every_frames=0",
                      "env.speed_command=true") == "max_frames"
    for init, words in ((tmp_path / "nowhere.pt", "no such file"), (source / "checkpoints" / "last.pt", "observations")):
        run_dir = tmp_path / "bad"
        proc = run_pamrun("train", *TINY, f"train.init_from={init}", f"hydra.run.dir={run_dir}")
        assert proc.returncode != 0 and "train.init_from" in proc.stderr and words in proc.stderr, proc.stderr[-2000:]
        assert not run_dir.exists()
    partial = tmp_path / "partial"  # a last.pt with its buffer copied in part: the missing file is named
    shutil.copytree(source / "checkpoints", partial)
    victim = max((p for p in partial.glob("buffer*/**/*") if p.is_file()), key=lambda p: p.stat().st_size)
    victim.unlink()
    proc = run_pamrun("train", *TINY, "env.speed_command=true", f"train.init_from={partial / 'last.pt'}",
                      f"hydra.run.dir={run_dir}")
    assert proc.returncode != 0 and "replay buffer file missing" in proc.stderr, proc.stderr[-2000:]
    assert victim.name in proc.stderr and not run_dir.exists()


def test_a_run_from_a_trained_agent_has_learned_before_frame_0(cfg):
    """Its "stand, learned" milestone can come at the evaluation of frame 0; a new actor's cannot."""
    from pamrun.task.criteria import stands_learned

    assert not stands_learned(1.0, 0, cfg)
    cfg.train.init_from = "agents/walker_td3_seed0.pt"
    assert stands_learned(1.0, 0, cfg) and not stands_learned(0.9, 0, cfg)


def test_a_run_from_a_trained_agent_starts_at_the_walking_stage(cfg):
    """Its curriculum weighs the replay samples with train.walk_weights from frame 0, with no
    evaluation needed; a new actor's waits for the stand milestone."""
    from pamrun.learning.curriculum import WalkCurriculum

    cfg.train.walk_weights = {"kflight": 10.0}
    assert not WalkCurriculum(cfg).walking
    cfg.train.init_from = "agents/walker_td3_seed0.pt"
    curriculum = WalkCurriculum(cfg)
    assert curriculum.walking and curriculum.since == 0 and curriculum.transform.delta["kflight"] == 10.0
    assert "train.init_from" in curriculum.describe()


def test_the_gait_stage_follows_the_first_evaluation_that_passes_every_episode(cfg):
    """train.gait_weights: stand, then walk at the stand milestone, then gait at the walking
    stage's first evaluation whose episodes all pass; a resume's replay of evals.csv finds the same."""
    from pamrun.learning.curriculum import WalkCurriculum

    cfg.train.walk_weights, cfg.train.gait_weights = {"kspeed": 4.0, "kflight": 2.0}, {"kflight": 20.0}
    curriculum, rows = WalkCurriculum(cfg), []
    for frames, stand, walk in ((20000, 0.9, 0.0), (60000, 1.0, 1.0), (70000, 1.0, 0.9), (80000, 1.0, 1.0)):
        started = curriculum.observe(stand, frames, walk)
        rows.append({"frames": frames, "stand_rate": stand, "walk_pass_rate": walk})
        assert started == (frames in (60000, 80000)), frames
        assert curriculum.stage == {20000: "stand", 60000: "walk", 70000: "walk", 80000: "gait"}[frames]
    assert curriculum.since == 60000 and curriculum.gait_since == 80000
    assert curriculum.transform.delta["kflight"] == 20.0 and curriculum.transform.delta["kspeed"] == 4.0
    assert curriculum.changed()["kflight"] == 20.0 and "Gait stage" in curriculum.describe()
    again = WalkCurriculum(cfg)
    again.replay(rows)
    assert (again.stage, again.since, again.gait_since) == ("gait", 60000, 80000)


def test_the_gait_stage_can_start_at_a_march_that_covers_a_distance(cfg):
    """train.gait_from_distance_m: the gait stage starts at the walking stage's first evaluation in
    which every episode stands the whole episode and the shortest covers that distance, passes or
    not; a fall or a shorter episode does not start it, and a resume's replay finds the same."""
    from pamrun.learning.curriculum import WalkCurriculum

    cfg.train.walk_weights, cfg.train.gait_weights = {"kspeed": 4.0}, {"kflight": 20.0, "kstep": 100.0}
    cfg.train.gait_from_distance_m = 2.0
    curriculum, rows = WalkCurriculum(cfg), []
    for frames, stand, distance_min, stage in ((60000, 1.0, 0.1, "walk"),  # stands still: walking starts
                                               (70000, 1.0, 0.3, "walk"),  # stands, but barely moves
                                               (80000, 0.9, 2.5, "walk"),  # far, but one episode fell
                                               (90000, 1.0, 1.9, "walk"),
                                               (100000, 1.0, 2.1, "gait")):  # no walk test passed
        curriculum.observe(stand, frames, 0.0, distance_min)
        rows.append({"frames": frames, "stand_rate": stand, "walk_pass_rate": 0.0, "distance_min": distance_min})
        assert curriculum.stage == stage, frames
    assert curriculum.gait_since == 100000 and curriculum.transform.delta["kstep"] == 100.0 - cfg.reward.kstep
    assert "train.gait_from_distance_m" in curriculum.describe()
    again = WalkCurriculum(cfg)
    again.replay(rows)
    assert (again.stage, again.gait_since) == ("gait", 100000)


def test_a_run_from_a_trained_agent_starts_at_its_last_stage(cfg):
    """train.init_from: the curriculum is at the gait stage from frame 0 where train.gait_weights are set
    (whatever its first evaluation), at the walking stage otherwise, and a resume's replay keeps it there."""
    from pamrun.learning.curriculum import WalkCurriculum

    cfg.train.init_from, cfg.train.walk_weights, cfg.train.gait_from_distance_m = "agent.pt", {"kspeed": 4.0}, 2.0
    walking = WalkCurriculum(cfg)
    assert (walking.stage, walking.since) == ("walk", 0) and "kstep" not in walking.changed()
    cfg.train.gait_weights = {"kstep": 100.0}
    curriculum = WalkCurriculum(cfg)
    assert (curriculum.stage, curriculum.since, curriculum.gait_since) == ("gait", 0, 0)
    assert curriculum.transform.delta["kstep"] == 100.0 - cfg.reward.kstep
    assert curriculum.transform.delta["kspeed"] == 4.0 - cfg.reward.kspeed
    assert "Gait stage of the curriculum from the first frame" in curriculum.describe()
    curriculum.replay([{"frames": 0, "stand_rate": 0.9, "walk_pass_rate": 0.0, "distance_min": 0.5}])
    assert curriculum.stage == "gait"


def test_adapted_weights_hold_on_the_distance_milestone(cfg):
    """With train.gait_from_distance_m, train.adapt_weights rise after each evaluation in which every
    episode stands and covers the distance (walk test passed or not) and fall back after a fall or
    a shorter march."""
    from pamrun.learning.curriculum import WalkCurriculum

    cfg.train.walk_weights, cfg.train.gait_weights = {"kspeed": 4.0}, {"kstep": 10.0}
    cfg.train.gait_from_distance_m, cfg.train.adapt_weights, cfg.train.adapt_factor = 2.0, {"kstep": 100.0}, 2.0
    curriculum, seen = WalkCurriculum(cfg), []
    for frames, stand, distance_min in ((60000, 1.0, 0.0), (70000, 1.0, 2.5), (80000, 1.0, 2.5), (90000, 1.0, 3.0),
                                        (100000, 0.9, 3.0), (110000, 1.0, 1.0)):
        curriculum.observe(stand, frames, 0.0, distance_min)
        seen.append(curriculum.adapted()["kstep"] if curriculum.stage == "gait" else None)
    assert seen == [None, 10.0, 20.0, 40.0, 20.0, 10.0]


def test_gait_from_distance_needs_gait_weights_and_a_positive_distance():
    from pamrun.config import ConfigError

    for overrides in (("experiment=walker", "train.gait_from_distance_m=2"),
                      ("experiment=gait", "train.gait_from_distance_m=0"),
                      ("experiment=gait", "train.gait_from_distance_m=-1")):
        with pytest.raises(ConfigError, match=r"train\.gait_from_distance_m"):
            to_object(compose_config(*overrides))
    assert to_object(compose_config("experiment=gait", "train.gait_from_distance_m=2")).train.gait_from_distance_m == 2.0


def test_adapted_weights_rise_while_the_walk_holds_and_fall_back_when_it_fails(cfg):
    """train.adapt_weights: in the gait stage each all-pass evaluation multiplies them by
    train.adapt_factor up to their caps, each other divides them down to the gait stage's own;
    the replay buffer's samples follow, and a resume's replay of evals.csv finds the same weights."""
    from pamrun.learning.curriculum import WalkCurriculum

    cfg.train.walk_weights, cfg.train.gait_weights = {"kspeed": 4.0, "kda": 0.5}, {"kflight": 20.0}
    cfg.train.adapt_weights, cfg.train.adapt_factor = {"kda": 1.0, "kflight": 100.0}, 2.0
    curriculum, rows, seen = WalkCurriculum(cfg), [], []
    for frames, walk in zip(range(60000, 140000, 10000), (0.0, 1.0, 1.0, 1.0, 0.9, 0.5, 0.9, 1.0)):
        curriculum.observe(1.0, frames, walk)
        rows.append({"frames": frames, "stand_rate": 1.0, "walk_pass_rate": walk})
        seen.append(curriculum.adapted() if curriculum.stage == "gait" else None)
    assert curriculum.gait_since == 70000 and seen[:2] == [None, {"kda": 0.5, "kflight": 20.0}]
    assert seen[2:] == [{"kda": 1.0, "kflight": 40.0}, {"kda": 1.0, "kflight": 80.0},  # kda at its cap
                        {"kda": 0.5, "kflight": 40.0}, {"kda": 0.5, "kflight": 20.0},  # never below the stage's
                        {"kda": 0.5, "kflight": 20.0}, {"kda": 1.0, "kflight": 40.0}]
    base = cfg.reward.kda
    assert curriculum.transform.delta["kda"] == 1.0 - base and curriculum.transform.delta["kflight"] == 40.0
    assert "train.adapt_weights" in curriculum.describe()
    again = WalkCurriculum(cfg)
    again.replay(rows)
    assert again.adapted() == {"kda": 1.0, "kflight": 40.0}


def test_adapted_weights_name_a_bad_key_a_bad_cap_and_need_the_gait_stage():
    from pamrun.config import ConfigError

    gait = ("experiment=gait", "seed=1")
    for overrides, key in ((("+train.adapt_weights.kfly=2",), "train.adapt_weights.kfly"),
                           (("+train.adapt_weights.kda=-1",), "train.adapt_weights.kda"),
                           (("+train.adapt_weights.kda=0.1",), "train.adapt_weights.kda"),  # below the stage's 0.5
                           (("+train.adapt_weights.kland=1",), "train.adapt_weights.kland"),  # 0 in the gait stage
                           (("+train.adapt_weights.kda=2", "train.adapt_factor=1"), "train.adapt_factor"),
                           (("experiment=walker", "+train.adapt_weights.kda=2"), "train.adapt_weights")):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            to_object(compose_config(*gait, *overrides))
    assert to_object(compose_config(*gait, "+train.adapt_weights.kda=2")).train.adapt_weights == {"kda": 2.0}


def test_gait_weights_need_a_walking_stage_and_name_a_bad_key():
    from pamrun.config import ConfigError

    with pytest.raises(ConfigError, match="train.gait_weights"):
        to_object(compose_config("experiment=thesis", "+train.gait_weights.kflight=20"))
    with pytest.raises(ConfigError, match="train.gait_weights.kfly"):
        to_object(compose_config("experiment=walker", "+train.gait_weights.kfly=20"))


def test_walk_noise_beta_needs_td3_a_walking_stage_and_a_spectrum():
    from pamrun.config import ConfigError

    for overrides, key in ((("experiment=gait", "train.walk_noise_beta=3"), "train.walk_noise_beta"),
                           (("experiment=gait", "train.walk_noise_beta=-1"), "train.walk_noise_beta"),
                           (("experiment=thesis", "algo=td3", "train.walk_noise_beta=1"), "train.walk_noise_beta"),  # no walking stage
                           (("experiment=gait", "algo=sac", "train.walk_noise_beta=1"), "train.walk_noise_beta")):
        with pytest.raises(ConfigError, match=key.replace(".", r"\.")):
            to_object(compose_config(*overrides))
    assert to_object(compose_config("experiment=gait", "train.walk_noise_beta=1")).train.walk_noise_beta == 1.0


@pytest.mark.slow
def test_a_walker_fine_tuned_with_gait_weights_starts_at_the_gait_stage(tmp_path):
    """The shipped walker passes its frame-0 evaluation, so a fine-tune of it with train.gait_weights
    is at the gait stage from frame 0: run.json records both switches, the console says so. Its
    train.adapt_weights follow each later evaluation, in TensorBoard's curriculum/*."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    run_dir = tmp_path / "gait"
    status = train_here(run_dir, "experiment=walker", "train.init_from=agents/walker_td3_seed0.pt",
                        "+train.gait_weights.kflight=20", "+train.adapt_weights.kflight=30", "train.adapt_factor=1.5",
                        "train.max_frames=200", "train.eval_every_frames=200",
                        "train.eval_episodes=2", "train.select_perturbations=[]", "train.eval_video_every=0",
                        "train.init_random_frames=0", "train.updates_per_frame=0.1")
    assert status == "max_frames"
    rows = list(csv.DictReader((run_dir / "evals.csv").open()))
    assert rows[0]["frames"] == "0" and rows[0]["walk_pass_rate"] == "1.0"
    info = json.loads((run_dir / "run.json").read_text())
    assert info["walk_kvx_from_frames"] == 0 and info["gait_weights_from_frames"] == 0
    adapted = {e.step: e.value for e in EventAccumulator(str(run_dir / "tensorboard")).Reload().Scalars("curriculum/kflight")}
    assert adapted[200] == (30.0 if rows[1]["walk_pass_rate"] == "1.0" else 20.0)  # raised only where all passed
