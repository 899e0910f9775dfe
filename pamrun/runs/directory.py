"""A training run's directory, in one place: its layout, its saved config, ``run.json``, its
CSV logs, and how a run opens (new, continued, or cleaned after an early kill).

Layout (:class:`RunFiles`)::

    <run>/pamrun_config.yaml      the run's whole config (read back by saved_config, always upgraded)
         run.json                 provenance and how the run ended (status, counters, saved agents)
         episodes.csv             one row per training episode (EPISODE_FIELDS)
         evals.csv                one row per evaluation during training (EVAL_FIELDS)
         tensorboard/             the same curves for TensorBoard
         training.png, evals.png  the curves drawn at the end
         checkpoints/last.pt      resume state (pamrun.learning.checkpoints), with buffer-<frames>/ beside it
         checkpoints/best_eval.pt the best agent of the evaluations during training
         checkpoints/agent_ep*.pt agents saved at train.save_threshold

``train``, ``sweep``, ``checkpoints``, ``evaluate`` and the benchmarks all find a run's
files through this module. It imports no pamrun module above the config.
"""

from __future__ import annotations

import csv
import math
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from pamrun.config import Config, ConfigError, to_object, upgrade_saved_config
from pamrun.runs.files import (
    atomic_write,
    git_commit,
    package_versions,
    read_json,
    write_json,
)

CONFIG = "pamrun_config.yaml"
CHECKPOINTS = "checkpoints"
LAST = "last.pt"  # in checkpoints/: the resume state
BEST_EVAL = "best_eval.pt"  # in checkpoints/: the best agent by the evaluations during training
AGENT_GLOB = "agent_ep*.pt"  # in checkpoints/: agents saved at the save threshold
EPISODE_FIELDS = ("episode", "frames", "reward", "avg_reward", "q0", "length", "distance_m", "wall_time_s",
                  "physics_error")
EVAL_FIELDS = ("frames", "episodes", "wall_time_s", "eval_s", "walk_pass_rate", "stand_rate", "fall_rate",
               "distance_mean", "distance_min", "duration_mean", "max_abs_y_max", "return_mean",
               "pressure_change_mean", "select_pass_rate", "select_schedule_rate", "best",
               # gait means over the nominal episodes (pamrun.evaluation.metrics), NaN where undefined
               "speed_mean", "step_frequency_hz_mean", "stride_length_m_mean", "duty_factor_mean",
               "step_time_symmetry_mean", "step_length_symmetry_mean", "stop_share_gait_max_mean",
               "cost_of_transport_mean", "air_nl_per_m_mean", "double_support_share_mean", "flight_share_mean",
               "knee_midstance_deg_mean", "knee_swing_peak_deg_mean", "step_length_m_mean", "foot_slip_m_s_mean",
               # how many of the walk's targets those means meet (pamrun.evaluation.targets)
               "walk_targets_met")
# What a training writes besides .hydra/ and its config (an early kill's leftovers are moved aside).
LEFTOVERS = ("episodes.csv", "evals.csv", "run.json", "tensorboard", "training.png", "evals.png")
# What a resume takes from its command line: the budget (wall time counts the run's whole time).
RESUME_BUDGET = ("train.max_frames", "train.max_episodes", "train.max_minutes")


@dataclass(frozen=True)
class RunFiles:
    """The paths of one run directory."""

    out: Path

    def __post_init__(self):
        object.__setattr__(self, "out", Path(self.out))

    config = property(lambda self: self.out / CONFIG)
    run_json = property(lambda self: self.out / "run.json")
    episodes = property(lambda self: self.out / "episodes.csv")
    evals = property(lambda self: self.out / "evals.csv")
    tensorboard = property(lambda self: self.out / "tensorboard")
    training_png = property(lambda self: self.out / "training.png")
    evals_png = property(lambda self: self.out / "evals.png")
    checkpoints = property(lambda self: self.out / CHECKPOINTS)
    last = property(lambda self: self.out / CHECKPOINTS / LAST)
    best_eval = property(lambda self: self.out / CHECKPOINTS / BEST_EVAL)


def saved_config(out: Path) -> Config:
    """The config a run directory's pamrun_config.yaml holds, upgraded to today's keys and over
    today's defaults: the one reader of a run's saved config."""
    saved = upgrade_saved_config(OmegaConf.to_container(OmegaConf.load(RunFiles(out).config)))
    return to_object(OmegaConf.merge(OmegaConf.structured(Config), saved))


def config_text(cfg: Config) -> str:
    return OmegaConf.to_yaml(OmegaConf.structured(cfg))


# --------------------------------------------------------------------------- CSV logs


def read_log(path: Path, int_key: str, float_key: str, what: str) -> list[dict]:
    """The rows of one of a run's CSV logs; a damaged file stops with one line naming it."""
    try:
        rows = list(csv.DictReader(path.open()))
        for r in rows:
            int(r[int_key]), float(r[float_key])
        return rows
    except (KeyError, ValueError, TypeError, csv.Error, UnicodeDecodeError) as err:
        raise SystemExit(f"pamrun: {path}: not a pamrun {what} ({type(err).__name__}: {err}); restore it, "
                         "or start the run again in a new directory.") from None


def read_episodes(out: Path) -> list[dict]:
    return read_log(RunFiles(out).episodes, "episode", "reward", "episode log")


def read_evals(out: Path) -> list[dict]:
    path = RunFiles(out).evals
    return read_log(path, "frames", "walk_pass_rate", "evaluation log") if path.exists() else []


def write_log(path: Path, fields: tuple[str, ...], rows: list[dict]) -> None:
    """Rewrite a CSV log with these rows, atomically."""

    def write(tmp: Path) -> None:
        with tmp.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)

    atomic_write(path, write)


class CsvLog:
    """Rows appended to a CSV file, each flushed (a killed process loses no finished row)."""

    def __init__(self, path: Path, fields: tuple[str, ...]):
        new = not path.exists()
        self.file = path.open("a", newline="")
        self.csv = csv.DictWriter(self.file, fieldnames=fields, extrasaction="ignore")
        if new:
            self.csv.writeheader()

    def append(self, row: dict) -> None:
        self.csv.writerow({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()})
        self.file.flush()

    def sync(self) -> None:
        """Make the rows durable before a checkpoint refers to them (machine loss)."""
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self) -> None:
        self.file.close()


class EpisodeLog(CsvLog):
    """episodes.csv and TensorBoard's ``episode/*``, with the running average (thesis Fig. 10.24)."""

    def __init__(self, out: Path, window: int, writer, episodes: int = 0):
        path = RunFiles(out).episodes
        rows = read_episodes(out) if path.exists() else []
        if not rows or list(rows[0]) != list(EPISODE_FIELDS):  # a new log, or one an older pamrun wrote
            write_log(path, EPISODE_FIELDS, [{"physics_error": 0, **r} for r in rows])
        super().__init__(path, EPISODE_FIELDS)
        self.rewards: list[float] = [float(r["reward"]) for r in rows]
        self.flagged = [int(r.get("physics_error") or 0) for r in rows]
        self.window, self.writer, self.episodes = window, writer, episodes
        self.best = max(self.rewards, default=-math.inf)

    def add(self, episode: dict, q0: float, frames: int, wall_time_s: float) -> dict:
        """One finished episode: its row (numbered from the run's count) in the CSV and TensorBoard.

        The row is written before the count moves: a signal in between leaves the CSV one row
        ahead of a final checkpoint (a resume drops it), never behind (a resume could not go on)."""
        rewards = [*self.rewards, episode["reward"]]
        row = {"episode": self.episodes + 1, "frames": frames, "reward": episode["reward"],
               "avg_reward": float(np.mean(rewards[-self.window:])), "q0": q0, "length": episode["length"],
               "distance_m": episode["distance_m"], "wall_time_s": round(wall_time_s, 3),
               "physics_error": int(episode["physics_error"])}
        self.append(row)
        self.rewards, self.episodes = rewards, self.episodes + 1
        self.flagged.append(int(episode["physics_error"]))
        self.best = max(self.best, row["reward"])
        for key in ("reward", "avg_reward", "q0", "length", "distance_m", "physics_error"):
            self.writer.add_scalar(f"episode/{key}", row[key], self.episodes)
        return row

    def average(self) -> float:
        return float(np.mean(self.rewards[-self.window:])) if self.rewards else float("nan")


# --------------------------------------------------------------------------- open, resume, close


def check_resume(config) -> None:
    """``resume=<dir>`` must name a run with a checkpoint (run by pamrun.cli before any directory exists)."""
    if config.resume and not RunFiles(config.resume).last.exists():
        raise ConfigError("resume", f"{config.resume}: no training run to resume there (no checkpoints/last.pt)")


def open_run(cfg: Config, out: Path, console, overrides: list[str] = ()) -> tuple[Config, bool]:
    """The config to run with, and whether it resumes.

    ``resume=<dir>``, or the same command again in a directory whose run has a checkpoint,
    continues that run with its own config; another command there is refused. A resume
    takes from its command line (``overrides``) only a new budget (``RESUME_BUDGET``, kept
    in the run's pamrun_config.yaml) and names every other value it ignores. Files of a
    run killed before its first checkpoint are moved aside (``aborted-<time>/``) and the
    run starts clean, saying so."""
    files = RunFiles(out)
    files.out.mkdir(parents=True, exist_ok=True)
    text = config_text(cfg)
    if not cfg.resume and files.last.exists():
        if not files.config.exists() or files.config.read_text() != text:
            raise SystemExit(f"pamrun: {out} already holds another training run; continue it with resume={out} "
                             "or choose another hydra.run.dir")
        console.print(f"{out} holds this run's last checkpoint: continuing it (same command).")
    if cfg.resume or files.last.exists():
        return _resumed_config(cfg, out, console, overrides), True
    leftovers = [out / name for name in LEFTOVERS if (out / name).exists()] + sorted(files.checkpoints.glob("*"))
    if leftovers:
        aside = out / f"aborted-{time.strftime('%Y%m%d-%H%M%S')}"
        aside.mkdir()
        for path in leftovers:
            path.rename(aside / ((CHECKPOINTS + "-" if path.parent.name == CHECKPOINTS else "") + path.name))
        console.print(f"[yellow]A run killed before its first checkpoint left files here: moved to {aside}; "
                      "starting clean.[/yellow]")
    files.config.write_text(text)
    files.checkpoints.mkdir(exist_ok=True)
    return cfg, False


def _resumed_config(given: Config, out: Path, console, overrides: list[str]) -> Config:
    """The run's own config, with a new budget from a ``resume=`` command line."""
    if not RunFiles(out).config.exists():
        raise SystemExit(f"pamrun: {out} holds no training run to resume (no {CONFIG})")
    cfg = saved_config(out)
    keys = {o.split("=", 1)[0].lstrip("+~"): o for o in overrides} if given.resume else {}  # else: the same
    budget = [k.split(".", 1)[1] for k in RESUME_BUDGET if k in keys]
    budget = [name for name in budget if getattr(given.train, name) != getattr(cfg.train, name)]
    ignored = [o for k, o in keys.items() if k not in RESUME_BUDGET and k != "resume"]
    for name in budget:
        console.print(f"New budget: train.{name} {getattr(cfg.train, name)} -> {getattr(given.train, name)}")
        setattr(cfg.train, name, getattr(given.train, name))
    if budget:
        RunFiles(out).config.write_text(config_text(cfg))
    console.print(f"Resuming {out} with its own config ({cfg.algo.name})"
                  + (f"; ignored (a resume only takes {', '.join(RESUME_BUDGET)}): {' '.join(ignored)}"
                     if ignored else "."), soft_wrap=True)
    return cfg


def truncate_logs(out: Path, counters: dict) -> None:
    """Forget what the logs hold after the last checkpoint (``counters``): a resume runs it again.

    A log that holds fewer episodes than the checkpoint stops the resume with one line."""
    files = RunFiles(out)
    rows = read_episodes(out) if files.episodes.exists() else []
    kept = [r for r in rows if int(r["episode"]) <= counters["episodes"]]
    if len(kept) < counters["episodes"]:
        raise SystemExit(f"pamrun: cannot resume {out}: {files.episodes} holds {len(rows)} episodes, the checkpoint "
                         f"{counters['episodes']}: restore it, or start the run again in a new directory.")
    if files.episodes.exists():
        write_log(files.episodes, EPISODE_FIELDS, [{"physics_error": 0, **r} for r in kept])
    if files.evals.exists():
        write_log(files.evals, EVAL_FIELDS, [r for r in read_evals(out) if int(r["frames"]) <= counters["frames"]])


def start_run_json(out: Path, cfg: Config, resuming: bool, frames: int, overrides: list[str]) -> dict:
    """run.json at the start: provenance, and ``running`` until the run ends."""
    info = read_json(RunFiles(out).run_json) if resuming else {
        "command": " ".join(["pamrun", "train", *overrides]),
        "git_commit": git_commit(), "versions": package_versions(), "seed": cfg.seed, "algo": cfg.algo.name,
        "start": time.strftime("%Y-%m-%dT%H:%M:%S")}
    info["status"] = "running"
    if resuming:
        info.setdefault("resumed", []).append({"at": time.strftime("%Y-%m-%dT%H:%M:%S"), "frames": frames})
    write_json(RunFiles(out).run_json, info)
    return info


def end_run_json(out: Path, info: dict, status: str, counters: dict, log: EpisodeLog, saved: list) -> None:
    """run.json at the end: how the run ended, its counters and what it saved."""
    info.update(status=status, end=time.strftime("%Y-%m-%dT%H:%M:%S"), frames=counters["frames"],
                episodes=counters["episodes"], wall_time_s=round(counters["wall_time_s"], 3),
                updates=counters["updates"], best_reward=log.best if counters["episodes"] else None,
                saved_agents=[str(p.name) for _, p in saved], physics_errors=sum(log.flagged))
    write_json(RunFiles(out).run_json, info)
