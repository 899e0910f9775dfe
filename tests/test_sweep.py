"""`pamrun sweep`: intervals and verdicts, end-to-end sweeps (joblib, Ray), failures, skip and
resume, the SLURM config, and the Optuna search."""

from __future__ import annotations

import csv
import json
import math
import os
import signal
import subprocess
import sys
import time

import pytest
import torch

from pamrun.config import CONF_DIR, register_configs
from pamrun.sweep.grid import collect_jobs, compare, group_key, mean_ci
from pamrun.sweep.overrides import sweep_dir_for, swept_keys
from tests.conftest import run_pamrun

TINY = ["experiment=walk", "train=smoke", "train.max_frames=400", "train.init_random_frames=200", "train.updates_per_frame=0.25",
        "train.save_threshold=-80", "eval.episodes=2", "eval.episode_s=2", "eval.walk_duration_s=2"]


# --------------------------------------------------------------------------- statistics and naming


def test_mean_and_95_interval():
    mean, half = mean_ci([1.0, 2.0, 3.0])
    assert mean == 2.0 and half == pytest.approx(4.302653 * 1.0 / math.sqrt(3), rel=1e-6)  # t(0.975, 2) s / sqrt(n)
    assert math.isnan(mean_ci([5.0])[1]) and mean_ci([5.0])[0] == 5.0
    assert all(math.isnan(v) for v in mean_ci([]))


def _row(setting, values, m="final_avg_reward"):
    mean, half = mean_ci(values)
    return {"setting": setting, m: mean, f"{m}_ci95": half, f"{m}_n": len(values), f"{m}_values": values}


def test_verdict_says_how_sure():
    m = "final_avg_reward"
    clear = compare([_row("a", [10.0, 10.2, 9.9, 10.1]), _row("b", [5.0, 5.2, 4.9, 5.1])], m, "maximize")
    assert clear.startswith("By final avg reward (higher is better), the best setting is a (10.05 ± ")
    assert "runner-up b" in clear and "a real difference at 95 %" in clear
    unsure = compare([_row("a", [10.0, 2.0, 7.0]), _row("b", [9.0, 3.0, 6.0])], m, "maximize")
    assert "not distinguishable at 95 %" in unsure
    assert "too few seeds" in compare([_row("a", [1.0]), _row("b", [0.0])], m, "maximize")


def test_sweep_folder_is_a_function_of_the_command():
    a = sweep_dir_for(["-m", "reward.kz=30,60", "seed=0,1", "train=smoke"])
    assert a == sweep_dir_for(["train=smoke", "seed=0,1", "reward.kz=30,60", "hydra/launcher=ray_cluster",
                               "sweep.jobs=1", "-m"])
    assert a.startswith("multirun/sweep-reward.kz-seed-")
    assert a != sweep_dir_for(["-m", "reward.kz=30,60", "seed=0,1,2", "train=smoke"])
    assert swept_keys(["reward.kz=30,60", "seed=range(3)", "train=smoke", "body.knee_limits_deg=[0,90]"]) == (
        ["reward.kz", "seed"], ["train", "body.knee_limits_deg"])
    assert group_key(["seed=1", "reward.kz=30", "algo=td3"], ["seed"]) == ("algo=td3", "reward.kz=30")


# --------------------------------------------------------------------------- end to end on this machine


@pytest.fixture(scope="module")
def smoke_sweep(tmp_path_factory):
    """2 settings x 2 seeds, two jobs at a time (joblib), tiny budgets."""
    sweep_dir = tmp_path_factory.mktemp("sweep") / "sw"
    args = ["sweep", "-m", "reward.kz=30,60", "seed=0,1", *TINY, f"hydra.sweep.dir={sweep_dir}"]
    proc = run_pamrun(*args)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return sweep_dir, args, proc


@pytest.mark.slow
def test_smoke_sweep_trains_evaluates_and_summarises(smoke_sweep):
    sweep_dir, _, proc = smoke_sweep
    jobs = collect_jobs(sweep_dir)
    assert sorted(j["job"] for j in jobs) == ["reward.kz=30,seed=0", "reward.kz=30,seed=1", "reward.kz=60,seed=0",
                                              "reward.kz=60,seed=1"]
    for j in jobs:
        assert j["status"] == "done", j
        job_dir = sweep_dir / j["job"]
        run = json.loads((job_dir / "run.json").read_text())
        assert run["frames"] == 400 and run["status"] == "max_frames"
        board = json.loads((job_dir / "eval" / "leaderboard.json").read_text())
        assert j["metrics"]["best_distance_m"] == max(a["distance_mean"] for a in board["agents"])
        rows = list(csv.DictReader((job_dir / "episodes.csv").open()))
        assert j["metrics"]["final_avg_reward"] == pytest.approx(float(rows[-1]["avg_reward"]))
        first = next((int(r["frames"]) for r in rows if float(r["reward"]) >= -80), None)
        assert j["metrics"]["frames_to_first_save"] == first
        kz = float(j["overrides"][0].split("=")[1])
        assert torch.load(job_dir / "checkpoints" / "last.pt", weights_only=True)["config"]["reward"]["kz"] == kz
        events = b"".join(p.read_bytes() for p in (job_dir / "tensorboard").glob("events.out.tfevents.*"))
        assert b"hparams" in events and b"sweep/final_avg_reward" in events
    # The summary: one row per setting, mean and interval over its two seeds.
    rows = {r["setting"]: r for r in csv.DictReader((sweep_dir / "summary.csv").open())}
    assert set(rows) == {"reward.kz=30", "reward.kz=60"}
    for setting, row in rows.items():
        values = [j["metrics"]["final_avg_reward"] for j in jobs if j["overrides"][0] == setting]
        # Student's t interval of two values, written out: t(0.975, 1) = 12.706, s = |a - b| / sqrt(2).
        assert float(row["final_avg_reward"]) == pytest.approx(sum(values) / 2)
        assert float(row["final_avg_reward_ci95"]) == pytest.approx(12.7062 * abs(values[0] - values[1]) / 2, rel=1e-4)
        assert row["done"] == "2" and row["failed"] == "0" and row["seeds"] == "0 1"
    md = (sweep_dir / "summary.md").read_text()
    assert "| reward.kz=30 | 2/2 |" in md and "Welch's t-test" in md
    assert (sweep_dir / "curves.png").stat().st_size > 10_000
    assert "Sweep summary" in proc.stdout and "Joblib.Parallel(n_jobs=2" in proc.stderr + proc.stdout


@pytest.mark.slow
def test_rerunning_a_finished_sweep_does_no_work(smoke_sweep):
    sweep_dir, args, _ = smoke_sweep
    before = {j["job"]: (j["end"], j["attempts"]) for j in collect_jobs(sweep_dir)}
    # no training and no evaluation rewritten (what a re-run would cost is what it must not do)
    stamps = {p: p.stat().st_mtime_ns for pattern in ("*/checkpoints/last.pt", "*/eval/leaderboard.json")
              for p in sweep_dir.glob(pattern)}
    assert len(stamps) == 8
    proc = run_pamrun(*args)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stdout.count("already done, skipped") == 4
    assert {j["job"]: (j["end"], j["attempts"]) for j in collect_jobs(sweep_dir)} == before
    assert {p: p.stat().st_mtime_ns for p in stamps} == stamps and "Sweep summary" in proc.stdout


@pytest.mark.slow
def test_summarize_on_demand(smoke_sweep, tmp_path):
    sweep_dir = smoke_sweep[0]
    (sweep_dir / "summary.csv").unlink()
    proc = run_pamrun("sweep", "summarize", f"dir={sweep_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert (sweep_dir / "summary.csv").exists() and "reward.kz=60" in proc.stdout
    assert not (sweep_dir / ".hydra").exists()  # a read-only command leaves no Hydra files behind


@pytest.mark.slow
def test_a_failing_job_is_recorded_and_the_others_finish(tmp_path):
    sweep_dir = tmp_path / "fail"
    proc = run_pamrun("sweep", "-m", "body.height_m=1.8,-1", "seed=0", *TINY, f"hydra.sweep.dir={sweep_dir}")
    assert proc.returncode == 1, proc.stderr[-3000:]  # after finishing the others, it says some did not
    assert proc.stderr.strip().splitlines()[-1] == "pamrun: 1 sweep job(s) did not finish: body.height_m=-1 (failed)"
    jobs = {j["job"]: j for j in collect_jobs(sweep_dir)}
    assert jobs["body.height_m=1.8"]["status"] == "done"
    bad = jobs["body.height_m=-1"]
    assert bad["status"] == "failed" and "body.height_m" in bad["error"]
    assert (sweep_dir / "body.height_m=-1" / "error.txt").exists()
    md = (sweep_dir / "summary.md").read_text()
    assert "body.height_m=-1" in md and "Jobs not done" in md
    assert "not done" in proc.stdout and "body.height_m=-1" in proc.stdout


@pytest.mark.slow
def test_an_interrupted_sweep_resumes_its_jobs(tmp_path):
    """SIGKILL a sweep mid-training; the same command resumes the job from its last checkpoint."""
    sweep_dir = tmp_path / "killed"
    args = ["sweep", "-m", "seed=3", "experiment=walk", "train=smoke", "train.max_frames=1400", "train.init_random_frames=200",
            "train.updates_per_frame=0.25", "train.checkpoint_every_frames=200", "eval.episodes=1",
            "eval.episode_s=1", "eval.walk_duration_s=1", f"hydra.sweep.dir={sweep_dir}"]
    proc = subprocess.Popen([sys.executable, "-m", "pamrun.cli", *args], stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)
    last = sweep_dir / "default" / "checkpoints" / "last.pt"
    deadline = time.time() + 240
    while time.time() < deadline:
        try:
            if torch.load(last, weights_only=True)["counters"]["frames"] >= 400:
                break
        except Exception:  # not there yet, or being replaced (atomic rename)
            pass
        time.sleep(0.5)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    killed_at = torch.load(last, weights_only=True)["counters"]["frames"]
    assert 400 <= killed_at < 1400
    assert json.loads((sweep_dir / "default" / "job.json").read_text())["status"] == "running"

    done = run_pamrun(*args)
    assert done.returncode == 0, done.stderr[-3000:]
    job = json.loads((sweep_dir / "default" / "job.json").read_text())
    assert job["status"] == "done" and job["attempts"] == 2
    run = json.loads((sweep_dir / "default" / "run.json").read_text())
    assert run["frames"] == 1400 and run["resumed"][0]["frames"] == killed_at
    assert (sweep_dir / "default" / "eval" / "selection.json").exists()


@pytest.mark.slow
def test_the_ray_launcher_runs_a_sweep_on_a_local_ray_instance(tmp_path):
    sweep_dir = tmp_path / "ray"
    proc = run_pamrun("sweep", "-m", "seed=0,1", *TINY, "hydra/launcher=ray_cluster",
                      "hydra.launcher.ray.init.num_cpus=2", f"hydra.sweep.dir={sweep_dir}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "Ray Launcher is launching 2 jobs" in proc.stderr + proc.stdout
    assert [j["status"] for j in collect_jobs(sweep_dir)] == ["done", "done"]
    assert (sweep_dir / "summary.csv").exists()


def test_the_slurm_launcher_config_composes():
    from hydra import compose, initialize_config_dir
    from hydra.utils import instantiate

    register_configs()
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = compose("config_sweep", overrides=["hydra/launcher=slurm", "hydra.launcher.partition=cpu", "seed=0"],
                      return_hydra_config=True)
    launcher = cfg.hydra.launcher
    assert launcher._target_.endswith("SlurmLauncher")
    assert launcher.partition == "cpu" and launcher.cpus_per_task == 8 and launcher.timeout_min == 2880
    assert type(instantiate(launcher)).__name__ == "SlurmLauncher"
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        local = compose("config_sweep", overrides=["sweep.jobs=3"], return_hydra_config=True)
    assert local.hydra.launcher._target_.endswith("JoblibLauncher") and local.hydra.launcher.n_jobs == 3


# --------------------------------------------------------------------------- Optuna


@pytest.mark.slow
def test_optuna_search_averages_seeds_and_resumes(tmp_path):
    import optuna

    study_dir = tmp_path / "study"
    base = ["sweep", "optuna", "++sweep.optuna.params={reward.kz: 'float:10:100'}", "sweep.optuna.seeds=[0,1]",
            "sweep.metric=final_avg_reward", *TINY, f"hydra.run.dir={study_dir}"]
    proc = run_pamrun(*base, "sweep.optuna.trials=1")
    assert proc.returncode == 0, proc.stderr[-3000:]
    trials = list(csv.DictReader((study_dir / "trials.csv").open()))
    assert len(trials) == 1 and trials[0]["state"] == "COMPLETE" and trials[0]["seeds_done"] == "2"
    jobs = collect_jobs(study_dir / trials[0]["dir"])
    assert sorted(j["job"] for j in jobs) == ["seed=0", "seed=1"]
    expected = sum(j["metrics"]["final_avg_reward"] for j in jobs) / 2
    assert float(trials[0]["value"]) == pytest.approx(expected)

    # A trial cut off mid-way (left RUNNING in the study) is run again with its parameters.
    study = optuna.load_study(study_name="pamrun", storage=f"sqlite:///{study_dir / 'study.db'}")
    cut = study.ask({"reward.kz": optuna.distributions.FloatDistribution(10, 100)})
    kz = cut.params["reward.kz"]
    proc = run_pamrun(*base, "sweep.optuna.trials=2")
    assert proc.returncode == 0, proc.stderr[-3000:]
    trials = list(csv.DictReader((study_dir / "trials.csv").open()))
    assert len(trials) == 2 and [t["state"] for t in trials] == ["COMPLETE", "COMPLETE"]
    assert float(trials[1]["reward.kz"]) == pytest.approx(kz)
    best = json.loads((study_dir / "best.json").read_text())
    assert best["value"] == max(float(t["value"]) for t in trials)
    # Nothing left to do: the same command again runs no trial.
    proc = run_pamrun(*base, "sweep.optuna.trials=2")
    assert "2 trial(s) done, 0 to run" in proc.stdout
    assert (study_dir / "optuna.png").exists()
