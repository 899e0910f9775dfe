"""End-to-end `pamrun train` with a tiny budget and a fixed seed."""

from __future__ import annotations

import csv
import json

import pytest
import torch

from tests.conftest import run_pamrun

TINY = ["train=smoke", "train.max_frames=600", "train.init_random_frames=200", "train.updates_per_frame=0.25",
        "train.checkpoint_every_frames=200", "seed=1"]


@pytest.mark.parametrize("algo", ["ddpg", "td3"])
def test_train_leaves_its_files(tmp_path, algo):
    run_dir = tmp_path / algo
    proc = run_pamrun("train", f"algo={algo}", *TINY, "train.save_threshold=-1e9", "train.keep_saved=2",
                      f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
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
    assert (run_dir / ".hydra" / "config.yaml").exists()


def test_threshold_not_reached_saves_nothing(tmp_path):
    run_dir = tmp_path / "none"
    proc = run_pamrun("train", *TINY, "train.max_frames=400", "train.save_threshold=1e9", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert not list((run_dir / "checkpoints").glob("agent_*.pt"))


def test_unknown_algo_fails_before_the_run_dir(tmp_path):
    run_dir = tmp_path / "bad"
    proc = run_pamrun("train", "algo=ppo", f"hydra.run.dir={run_dir}")
    assert proc.returncode != 0 and "ppo" in proc.stderr
    proc = run_pamrun("train", "algo.batch_size=-1", f"hydra.run.dir={run_dir}")
    assert proc.returncode != 0 and "algo.batch_size" in proc.stderr + proc.stdout
    assert not run_dir.exists()


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
