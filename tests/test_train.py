"""End-to-end `pamrun train` with a tiny budget and a fixed seed."""

from __future__ import annotations

import csv
import json

import pytest
import torch

from tests.test_config import run_pamrun

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
    last = torch.load(run_dir / "checkpoints" / "last.pt", weights_only=False)
    assert last["counters"] == {"frames": 600, "episodes": run["episodes"], "updates": 100}
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
