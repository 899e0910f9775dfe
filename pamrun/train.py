"""``pamrun train``: DDPG or TD3 on PamWalker-v0 with TorchRL (thesis §9.5).

One loop, top to bottom: a TorchRL collector (one process, or ``train.workers``
processes) fills a ``TensorDictReplayBuffer``; after ``train.init_random_frames`` of
uniform random actions, each collected frame buys ``train.updates_per_frame`` gradient
updates of the loss (``DDPGLoss``/``TD3Loss``) with a ``SoftUpdate`` of the targets. Every
finished episode is a row of ``episodes.csv`` and a point in TensorBoard (reward, average
reward, Q0: the three curves of thesis Fig. 10.24); agents whose episode reward reaches
``train.save_threshold`` are saved (MATLAB's SaveAgentCriteria), and ``checkpoints/last.pt``
holds what a later resume needs, written atomically.
"""

from __future__ import annotations

import csv
import functools
import math
import os
import random
import signal
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from pamrun import agents, checkpoints, plots
from pamrun.config import Config, to_object, upgrade_saved_config
from pamrun.runio import Progress, git_commit, package_versions, read_json, run_dir, write_json
from pamrun.runtime import usable_cores

# What a training writes in its directory besides .hydra/ and pamrun_config.yaml.
LEFTOVERS = ("episodes.csv", "evals.csv", "run.json", "tensorboard", "training.png", "evals.png")
NEW_RUN = {"frames": 0, "episodes": 0, "updates": 0, "wall_time_s": 0.0}  # a run's counters at its start
CSV_FIELDS = ("episode", "frames", "reward", "avg_reward", "q0", "length", "distance_m", "wall_time_s",
              "physics_error")


def make_env(cfg: Config):
    """PamWalker-v0 with this config in TorchRL's GymWrapper; reads ``distance`` from info.

    (TorchRL's ``GymEnv`` reserves the keyword ``env``, so the Gymnasium env is built here.)
    """
    import gymnasium as gym
    from torchrl.envs import GymWrapper
    from torchrl.envs.gym_like import default_info_dict_reader

    import pamrun  # noqa: F401  (registers the env in worker processes too)

    env = GymWrapper(gym.make(
        "pamrun/PamWalker-v0",
        body=asdict(cfg.body), muscle=asdict(cfg.muscle), reward=asdict(cfg.reward), env=asdict(cfg.env),
    ))
    env.set_info_dict_reader(default_info_dict_reader(["distance", "physics_error"]))
    return env


def make_collector(cfg: Config, policy, total_frames: int, start_random: int):
    """TorchRL's collector for ``train.workers`` envs: in this process (one worker), in worker
    processes stepping in lockstep, or with ``train.async_collection`` in worker processes
    that keep stepping while the learner updates (each batch then comes from the policy of
    one or more batches before)."""
    from torchrl.collectors import AsyncCollector, Collector, MultiAsyncCollector, MultiSyncCollector

    # auto_register_policy_transforms: adds the InitTracker the OU noise needs to restart per episode.
    kwargs = dict(frames_per_batch=cfg.train.frames_per_batch, total_frames=total_frames,
                  init_random_frames=start_random, auto_register_policy_transforms=True)
    make = functools.partial(make_env, cfg)
    if cfg.train.async_collection:
        if cfg.train.workers == 1:
            return AsyncCollector(make, policy, **kwargs)
        return MultiAsyncCollector([make] * cfg.train.workers, policy, **kwargs)
    if cfg.train.workers == 1:
        return Collector(make, policy, **kwargs)
    return MultiSyncCollector([make] * cfg.train.workers, policy, **kwargs)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


class EpisodeLog:
    """What a run records as it goes: episodes.csv, TensorBoard, and the running average."""

    def __init__(self, out: Path, window: int, writer, episodes: int = 0):
        self.path = out / "episodes.csv"
        rows = self.read(self.path) if self.path.exists() else []
        history = [float(r["reward"]) for r in rows]
        self.flagged = [int(r.get("physics_error") or 0) for r in rows]
        if not rows or list(rows[0]) != list(CSV_FIELDS):
            self.write_rows(self.path, rows)  # a new log, or one an older pamrun wrote: today's header
        self.file = self.path.open("a", newline="")
        self.csv = csv.DictWriter(self.file, fieldnames=CSV_FIELDS)
        self.rewards: list[float] = history
        self.window = window
        self.writer = writer
        self.best = max(self.rewards, default=-math.inf)
        self.episodes = episodes

    def add(self, episode: dict, q0: float, frames: int, wall_time_s: float) -> dict:
        """One finished episode: its row (numbered from the run's count) in the CSV and TensorBoard."""
        self.episodes += 1
        self.rewards.append(episode["reward"])
        self.flagged.append(int(episode["physics_error"]))
        row = {"episode": self.episodes, "frames": frames, "reward": episode["reward"],
               "avg_reward": float(np.mean(self.rewards[-self.window:])), "q0": q0, "length": episode["length"],
               "distance_m": episode["distance_m"], "wall_time_s": round(wall_time_s, 3),
               "physics_error": int(episode["physics_error"])}
        self.best = max(self.best, row["reward"])
        self.csv.writerow({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()})
        self.file.flush()  # a killed process loses no finished episode
        for key in ("reward", "avg_reward", "q0", "length", "distance_m", "physics_error"):
            self.writer.add_scalar(f"episode/{key}", row[key], self.episodes)
        return row

    def losses(self, actor_critic: tuple[float, float], updates: int) -> None:
        self.writer.add_scalar("loss/actor", actor_critic[0], updates)
        self.writer.add_scalar("loss/critic", actor_critic[1], updates)

    def batch(self, cfg: Config, frames: int, updates: int, elapsed_s: float, progress: Progress) -> None:
        """Throughput and exploration in TensorBoard, and the progress line, after each batch."""
        self.writer.add_scalar("throughput/frames_per_s", frames / elapsed_s, frames)
        self.writer.add_scalar("throughput/updates_per_s", updates / elapsed_s, frames)
        noise_std = math.sqrt(cfg.algo.noise_variance) * agents.noise_scale(cfg.algo, frames)
        self.writer.add_scalar("exploration/noise_std", noise_std, frames)
        avg = float(np.mean(self.rewards[-self.window:])) if self.rewards else float("nan")
        progress.update(frames, f"episodes {self.episodes}  avg {avg:.2f}  best {self.best:.2f}  "
                                f"{frames / elapsed_s:.0f} frames/s  {updates / elapsed_s:.1f} updates/s")

    def sync(self) -> None:
        """Make the rows durable before a checkpoint refers to them (machine loss)."""
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self) -> None:
        self.file.close()

    @staticmethod
    def read(path: Path) -> list[dict]:
        """The rows of an episodes.csv; a damaged file stops with one line naming it."""
        return read_log(path, "episode", "reward", "episode log")

    @staticmethod
    def write_rows(path: Path, rows: list[dict]) -> None:
        write_log(path, CSV_FIELDS, [{**{"physics_error": 0}, **r} for r in rows])

    @classmethod
    def truncate(cls, out: Path, episodes: int) -> None:
        """Forget what was logged after the last checkpoint: those episodes will be run again."""
        path = out / "episodes.csv"
        if path.exists():
            cls.write_rows(path, [r for r in cls.read(path) if int(r["episode"]) <= episodes])


class EvalLog:
    """Evaluations during training: evals.csv, TensorBoard ``eval/*`` and checkpoints/best_eval.pt.

    ``best_eval.pt`` is only ever replaced by an agent that ranks before it (``eval.rank_by``);
    its evaluation is stored in it, so a resumed run keeps comparing against it."""

    def __init__(self, out: Path, cfg: Config, writer):
        from pamrun.evaluate import EVALS_FIELDS, TrainingEvaluator

        self.path, self.best_path = out / "evals.csv", out / "checkpoints" / checkpoints.BEST_EVAL
        self.evaluator = TrainingEvaluator(cfg)
        self.writer = writer
        self.best = checkpoints.load_agent(self.best_path).meta.get("eval") if self.best_path.exists() else None
        new = not self.path.exists()
        self.file = self.path.open("a", newline="")
        self.csv = csv.DictWriter(self.file, fieldnames=EVALS_FIELDS, extrasaction="ignore")
        if new:
            self.csv.writeheader()

    def run(self, actor, policy_state: dict, cfg: Config, counters: dict) -> dict:
        """Evaluate ``actor`` (its weights: ``policy_state``) now; log it, keep it if it is the
        best so far; return the result."""
        result = self.evaluator(actor)
        best = not result["physics_error_rate"] and self.evaluator.better(result, self.best)
        if best:
            # its numbers and the seeds they came from (pamrun eval reports on others: evaluate.held_out)
            self.best = {k: v for k, v in result.items() if isinstance(v, (int, float, bool)) or k == "seeds"}
            meta = {"frames": counters["frames"], "episode": counters["episodes"], "eval": self.best}
            checkpoints.save_agent_record(self.best_path, policy_state, cfg, meta)
        row = {**result, "frames": counters["frames"], "episodes": counters["episodes"],
               "wall_time_s": round(counters["wall_time_s"], 3), "best": int(best)}
        self.csv.writerow({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()})
        self.file.flush()
        for key in ("walk_pass_rate", "stand_rate", "fall_rate", "distance_mean", "duration_mean",
                    "max_abs_y_max", "return_mean", "eval_s"):
            self.writer.add_scalar(f"eval/{key}", result[key], counters["frames"])
        return result

    def close(self) -> None:
        self.file.close()
        self.evaluator.close()

    @staticmethod
    def read(path: Path) -> list[dict]:
        """The rows of an evals.csv; a damaged file stops with one line naming it."""
        return read_log(path, "frames", "walk_pass_rate", "evaluation log")

    @classmethod
    def truncate(cls, out: Path, frames: int) -> None:
        """Forget evaluations made after the last checkpoint: those frames will be run again."""
        from pamrun.evaluate import EVALS_FIELDS

        path = out / "evals.csv"
        if path.exists():
            write_log(path, EVALS_FIELDS, [r for r in cls.read(path) if int(r["frames"]) <= frames])


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


def write_log(path: Path, fields: tuple[str, ...], rows: list[dict]) -> None:
    """Rewrite a CSV log with these rows, atomically."""
    from pamrun.runio import atomic_write

    def write(tmp: Path) -> None:
        with tmp.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
            w.writeheader()
            w.writerows(rows)

    atomic_write(path, write)


def train(dcfg: DictConfig) -> None:
    """The Hydra task of ``pamrun train``: the recipe, top to bottom."""
    from pamrun.runio import console as make_console
    from torch.utils.tensorboard import SummaryWriter

    from pamrun.env import space_sizes

    console = make_console()
    cfg, out, resuming = open_run(to_object(dcfg), run_dir(), console, HydraConfig.get().overrides.task)
    ckpt_dir = out / "checkpoints"
    seed_everything(cfg.seed)
    torch.set_num_threads(cfg.train.threads or max(1, usable_cores() - cfg.train.workers + 1))
    learner = agents.make_learner(cfg.algo, *space_sizes(cfg.muscle), action_spec(cfg))
    buffer = make_buffer(cfg)
    counters = resume(out, learner, buffer) if resuming else dict(NEW_RUN)
    if counters["frames"] >= cfg.train.max_frames or counters["episodes"] >= cfg.train.max_episodes:
        return console.print(f"{out} already finished its budget ({counters['frames']} frames, "
                             f"{counters['episodes']} episodes): nothing to do. To train on, give it a "
                             f"larger one: pamrun train resume={out} train.max_frames=...", soft_wrap=True)
    frames = counters["frames"]
    agents.set_noise_scale(learner.explore, agents.noise_scale(cfg.algo, frames))
    log = EpisodeLog(out, cfg.train.avg_window, SummaryWriter(str(out / "tensorboard")), counters["episodes"])
    tracker = EpisodeTracker()
    evals = EvalLog(out, cfg, log.writer) if cfg.train.eval_every_frames else None
    curriculum = WalkCurriculum(cfg, EvalLog.read(out / "evals.csv") if resuming and evals else [])
    run_info = start_run_info(out, cfg, resuming, frames)
    if curriculum.walking:
        run_info.setdefault("walk_kvx_from_frames", curriculum.since)
        console.print(f"Walking stage of the curriculum (since {curriculum.since} frames): the learner's "
                      f"forward weight is train.walk_kvx = {curriculum.kvx:g}.", soft_wrap=True)
    saved = checkpoints.scan_saved(ckpt_dir)
    collector = make_collector(cfg, learner.explore, cfg.train.max_frames - frames,
                               max(0, cfg.train.init_random_frames - frames))
    collector.set_seed(cfg.seed + frames)
    clock = Clock(counters["wall_time_s"])
    update_budget, status, failure = 0.0, None, None
    console.print(header_table(cfg, out))
    progress = Progress(console, cfg.train.max_frames, frames)
    # Ctrl-C must stop the run with a final checkpoint even when whatever started pamrun ignored
    # SIGINT (a script's `cmd &`, some CI runners): Python then keeps SIG_IGN and would never
    # raise KeyboardInterrupt, and the run would train on to its budget.
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _terminate),
                signal.SIGINT: signal.signal(signal.SIGINT, signal.default_int_handler)}
    try:
        for batch in collector:
            batch = batch.reshape(-1)
            n = batch.numel()
            frames += n
            buffer.extend(batch)
            saved = record_episodes(tracker.add(batch), cfg, learner, log, frames, clock.seconds(), saved, ckpt_dir)
            learn_frames = frames - max(cfg.train.init_random_frames, frames - n)  # frames past the random phase
            if learn_frames > 0:
                update_budget = learn(learner, buffer, log, update_budget + learn_frames * cfg.train.updates_per_frame,
                                      actor=frames >= cfg.train.actor_start_frames, relabel=curriculum.relabel)
                collector.update_policy_weights_()
            agents.set_noise_scale(learner.explore, agents.noise_scale(cfg.algo, frames))
            log.batch(cfg, frames, learner.updates, clock.seconds(), progress)
            if frames % cfg.train.checkpoint_every_frames < n:
                log.sync()
                checkpoints.save_last(ckpt_dir, cfg, learner, buffer, run_counters(frames, log, learner, clock))
            if evals and frames % cfg.train.eval_every_frames < n:
                result = evals.run(learner.actor.module, learner.policy_state(), cfg,
                                   run_counters(frames, log, learner, clock))
                if curriculum.observe(result["stand_rate"], frames):
                    log.writer.add_scalar("curriculum/kvx", curriculum.kvx, frames)
                    run_info["walk_kvx_from_frames"] = frames
                    console.print(f"Stands in every evaluation episode at {frames} frames: the learner's forward "
                                  f"weight is now train.walk_kvx = {curriculum.kvx:g} (was reward.kvx = "
                                  f"{cfg.reward.kvx:g}).")
                if result["walk_test"] and cfg.train.stop_on_walk:
                    status = "walked"
                    break
            status = stop_reason(cfg, log, clock.seconds())
            if status:
                break
    except BaseException as err:
        status, failure = stopped_by(err)
        if status == "failed":
            raise
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
        progress.stop()
        collector.shutdown()
        if evals:
            evals.close()
        close_run(out, cfg, learner, buffer, run_counters(frames, log, learner, clock), log, run_info,
                  status or "max_frames", saved)
    plots.training_curves(out / "episodes.csv", out / "training.png")
    if (out / "evals.csv").exists():
        plots.eval_curves(out / "evals.csv", out / "evals.png", cfg.eval.walk_distance_m, cfg.eval.episode_s)
    console.print(summary_table(run_info, log, saved, out))
    end_of_run(console, out, status, failure, log)


def stopped_by(err: BaseException) -> tuple[str, Exception | None]:
    """The run.json status of a training stopped by ``err`` (``failed``: a crash to re-raise)."""
    if isinstance(err, KeyboardInterrupt):
        return "interrupted", None
    if isinstance(err, Terminated):
        return "terminated", None
    if isinstance(err, checkpoints.CheckpointError):  # a checkpoint could not be written (disk full)
        return "checkpoint_failed", err
    return "failed", None


def end_of_run(console, out: Path, status: str | None, failure: Exception | None, log: "EpisodeLog") -> None:
    """How a run that did not finish its budget says so: the next command, and its exit code."""
    if status in STOPPED_EXIT:
        console.print(f"Stopped ({status}) with a final checkpoint. Continue with: pamrun train resume={out}",
                      soft_wrap=True)
        raise SystemExit(STOPPED_EXIT[status])
    if failure is not None:
        again = f"pamrun train resume={out}" if (out / "checkpoints" / checkpoints.LAST).exists() else \
            "the same command (no checkpoint yet: it starts clean)"
        raise SystemExit(f"pamrun: training stopped: {failure}. Then continue with: {again}")
    if status == "physics_unstable":
        console.print(f"[red]Stopped: the physics blew up in {sum(log.flagged[-100:])} of the last "
                      f"{len(log.flagged[-100:])} episodes.[/red] The robot is unstable in MuJoCo at this setting: "
                      "check body.mass_kg and body.height_m, the muscles' strength (muscle.size, muscle.count, "
                      "muscle.max_pressure_kpa) against them, and env.physics_dt_s.")
        raise SystemExit(1)


def resume(out: Path, learner, buffer) -> dict:
    """Learner, buffer and RNG states of the last checkpoint; forget what came after it.

    Any piece that is missing or damaged stops the resume with one line naming the file."""
    try:
        counters = checkpoints.load_last(out / "checkpoints", learner, buffer)
    except checkpoints.CheckpointError as err:
        raise SystemExit(f"pamrun: cannot resume {out}: {err}. Restore the file, or start the run again "
                         "in a new directory.") from None
    log = out / "episodes.csv"
    rows = EpisodeLog.read(log) if log.exists() else []
    if len([r for r in rows if int(r["episode"]) <= counters["episodes"]]) < counters["episodes"]:
        raise SystemExit(f"pamrun: cannot resume {out}: {log} holds {len(rows)} episodes, the checkpoint "
                         f"{counters['episodes']}: restore it, or start the run again in a new directory.")
    EpisodeLog.truncate(out, counters["episodes"])
    EvalLog.truncate(out, counters["frames"])
    checkpoints.drop_agents_after(out / "checkpoints", counters["episodes"])
    return counters


def record_episodes(finished: list[dict], cfg: Config, learner, log: "EpisodeLog", frames: int, wall_time_s: float,
                    saved: list, ckpt_dir: Path) -> list:
    """Log the episodes a batch finished (with Q0) and save the agents that reach the threshold
    (never one from an episode whose physics blew up)."""
    q0s = learner.q0(torch.stack([e["obs0"] for e in finished])) if finished else []
    for episode, q0 in zip(finished, q0s):
        row = log.add(episode, q0, frames, wall_time_s)
        if episode["reward"] >= cfg.train.save_threshold and not episode["physics_error"]:
            saved = checkpoints.save_agent(ckpt_dir, learner.policy_state(), row, cfg, saved,
                                           cfg.train.keep_saved)
    return saved


def actor_learns_from(cfg: Config) -> int:
    """Frames at the run's first actor update (after its random phase and critic warm-up)."""
    return max(cfg.train.init_random_frames, cfg.train.actor_start_frames)


def stands_learned(stand_rate: float, frames: int, cfg: Config) -> bool:
    """The "stand, learned" milestone: every evaluation episode lasts the full episode, in an
    evaluation after the actor's first update (the sized robot stands passively at zero
    command, so an untrained actor stands too: standing only counts once the actor learns)."""
    return stand_rate >= 1.0 and frames > actor_learns_from(cfg)


class WalkCurriculum:
    """``train.walk_kvx``: stand first, then walk.

    Until the "stand, learned" milestone the learner optimises the env's reward; from it on,
    every replayed transition's reward gets (walk_kvx - reward.kvx) Vx added, Vx being the
    torso's forward velocity after the step (the next observation's ``torso_velocity``), so
    the reward the critics learn is the env's with the forward weight walk_kvx, for old
    transitions as for new. A transition whose physics blew up keeps its reward (0). The
    stage is a function of evals.csv, so a resumed run takes it up where it was.
    """

    def __init__(self, cfg: Config, rows: list[dict]):
        from pamrun.env import observation_structure, space_sizes

        self.cfg, self.kvx, self.walking = cfg, cfg.train.walk_kvx, False
        self.since: int | None = None  # frames of the evaluation that started the walking stage
        self.vx = observation_structure(space_sizes(cfg.muscle)[1])["torso_velocity"].start
        for row in rows:
            self.observe(float(row["stand_rate"]), int(row["frames"]))

    def observe(self, stand_rate: float, frames: int) -> bool:
        """Take an evaluation into account; True when it starts the walking stage."""
        if self.kvx is None or self.walking or not stands_learned(stand_rate, frames, self.cfg):
            return False
        self.walking, self.since = True, frames
        return True

    def relabel(self, samples) -> None:
        """The walking stage's reward, in place, on a replay sample."""
        if self.walking and self.kvx != self.cfg.reward.kvx:
            nxt = samples["next"]
            ok = nxt["physics_error"].reshape(nxt["reward"].shape).logical_not()  # bool, or a collector's 0/1
            vx = nxt["observation"][..., self.vx:self.vx + 1] * ok
            nxt["reward"] += (self.kvx - self.cfg.reward.kvx) * vx


def learn(learner, buffer, log: "EpisodeLog", budget: float, actor: bool = True, relabel=None) -> float:
    """Spend the whole updates of ``budget`` on replay samples; return the fraction left.

    The buffer does not change between these updates, so their samples are drawn in one
    call (uniform with replacement, as one sample per update would be): one TensorDict
    operation per batch of frames instead of one per update."""
    n = int(budget)
    if n:
        batch = learner.cfg.batch_size
        samples = buffer.sample(n * batch).reshape(n, batch)
        if relabel is not None:
            relabel(samples)
        for i in range(n):
            learner.update(samples[i], actor)
            if learner.updates % 50 == 0:
                log.losses(learner.losses(), learner.updates)
    return budget - n


def run_counters(frames: int, log: "EpisodeLog", learner, clock: "Clock") -> dict:
    return {"frames": frames, "episodes": log.episodes, "updates": learner.updates, "wall_time_s": clock.seconds()}


def check_config(config) -> None:
    """``resume=<dir>`` must name a run with a checkpoint (run by pamrun.cli before any directory exists)."""
    from pamrun.config import ConfigError

    if config.resume and not (Path(config.resume) / "checkpoints" / checkpoints.LAST).exists():
        raise ConfigError("resume", f"{config.resume}: no training run to resume there (no checkpoints/last.pt)")


# What a resume takes from its command line: the budget (wall time counts the run's whole time).
RESUME_BUDGET = ("train.max_frames", "train.max_episodes", "train.max_minutes")


def open_run(cfg: Config, out: Path, console, overrides: list[str] = ()) -> tuple[Config, Path, bool]:
    """The config to run with and whether it resumes.

    ``resume=<dir>``, or the same command again in a directory whose run has a checkpoint,
    continues that run with its own config; another command there is refused. A resume
    takes from its command line (``overrides``) only a new budget (``RESUME_BUDGET``, kept
    in the run's pamrun_config.yaml) and names every other value it ignores. Files of a
    run killed before its first checkpoint are moved aside (``aborted-<time>/``) and the
    run starts clean, saying so."""
    text = OmegaConf.to_yaml(OmegaConf.structured(cfg))
    saved = out / "pamrun_config.yaml"
    has_checkpoint = (out / "checkpoints" / checkpoints.LAST).exists()
    if not cfg.resume and has_checkpoint:
        if not saved.exists() or saved.read_text() != text:
            raise SystemExit(f"pamrun: {out} already holds another training run; continue it with resume={out} "
                             "or choose another hydra.run.dir")
        console.print(f"{out} holds this run's last checkpoint: continuing it (same command).")
    if cfg.resume or has_checkpoint:
        given, cfg = cfg, load_run_config(out)
        keys = {o.split("=", 1)[0].lstrip("+~"): o for o in overrides} if given.resume else {}  # else: the same
        budget = [k.split(".", 1)[1] for k in RESUME_BUDGET if k in keys]
        budget = [name for name in budget if getattr(given.train, name) != getattr(cfg.train, name)]
        ignored = [o for k, o in keys.items() if k not in RESUME_BUDGET and k != "resume"]
        for name in budget:
            console.print(f"New budget: train.{name} {getattr(cfg.train, name)} -> {getattr(given.train, name)}")
            setattr(cfg.train, name, getattr(given.train, name))
        if budget:
            saved.write_text(OmegaConf.to_yaml(OmegaConf.structured(cfg)))
        console.print(f"Resuming {out} with its own config ({cfg.algo.name})"
                      + (f"; ignored (a resume only takes {', '.join(RESUME_BUDGET)}): {' '.join(ignored)}"
                         if ignored else "."), soft_wrap=True)
        return cfg, out, True
    leftovers = [out / name for name in LEFTOVERS if (out / name).exists()]
    leftovers += sorted((out / "checkpoints").glob("*"))
    if leftovers:
        aside = out / f"aborted-{time.strftime('%Y%m%d-%H%M%S')}"
        aside.mkdir()
        for path in leftovers:
            path.rename(aside / (("checkpoints-" if path.parent.name == "checkpoints" else "") + path.name))
        console.print(f"[yellow]A run killed before its first checkpoint left files here: moved to {aside}; "
                      "starting clean.[/yellow]")
    saved.write_text(text)
    (out / "checkpoints").mkdir(exist_ok=True)
    return cfg, out, False


def action_spec(cfg: Config):
    """The env's action spec, as TorchRL sees it (the losses and exploration need it)."""
    probe = make_env(cfg)
    spec = probe.action_spec_unbatched
    probe.close()
    return spec


def make_buffer(cfg: Config):
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    # No batch_size: learn() draws the samples of many updates in one call.
    return TensorDictReplayBuffer(storage=LazyTensorStorage(cfg.train.buffer_size))


class Terminated(Exception):
    """SIGTERM (a scheduler's time limit, ``kill``): stop like Ctrl-C, with a final checkpoint."""


def _terminate(signum, frame) -> None:
    raise Terminated()


# Exit codes of a run stopped by a signal (after its final checkpoint), as a shell reports them.
STOPPED_EXIT = {"interrupted": 130, "terminated": 143}


class Clock:
    """Wall-clock seconds of training, carried over a resume."""

    def __init__(self, previous_s: float = 0.0):
        self.start = time.perf_counter() - previous_s

    def seconds(self) -> float:
        return time.perf_counter() - self.start


class EpisodeTracker:
    """Sums each collector trajectory's reward and length until it is done."""

    def __init__(self):
        self.running: dict[int, dict] = {}

    def add(self, batch) -> list[dict]:
        """The episodes this (flat) batch finishes: reward, length, first observation, distance, and
        whether the physics blew up in it (``physics_error``)."""
        finished = []
        traj = batch["collector", "traj_ids"].tolist()
        reward = batch["next", "reward"].reshape(-1).tolist()
        done = batch["next", "done"].reshape(-1).tolist()
        distance = batch["next", "distance"].reshape(-1).tolist()
        error = batch["next", "physics_error"].reshape(-1).tolist()
        for i in range(len(traj)):
            ep = self.running.setdefault(traj[i], {"reward": 0.0, "length": 0, "obs0": batch["observation"][i],
                                                   "physics_error": False})
            ep["reward"] += reward[i]
            ep["length"] += 1
            ep["physics_error"] |= bool(error[i])
            if done[i]:
                ep["distance_m"] = distance[i]
                finished.append(self.running.pop(traj[i]))
        return finished


def stop_reason(cfg: Config, log: "EpisodeLog", elapsed_s: float) -> str | None:
    """Why training stops now (``train.max_*`` or the target average), or None."""
    t = cfg.train
    recent = log.flagged[-100:]
    if len(recent) >= 20 and sum(recent) > len(recent) / 2:
        return "physics_unstable"
    if log.episodes >= t.max_episodes:
        return "max_episodes"
    if t.max_minutes and elapsed_s > 60 * t.max_minutes:
        return "max_minutes"
    if t.target_avg_reward and len(log.rewards) >= t.avg_window and \
            np.mean(log.rewards[-t.avg_window:]) >= t.target_avg_reward:
        return "target_avg_reward"
    return None


def start_run_info(out: Path, cfg: Config, resuming: bool, frames: int) -> dict:
    """run.json at the start: provenance, and ``running`` until the run ends."""
    info = read_json(out / "run.json") if resuming else {
        "command": " ".join(["pamrun", "train", *HydraConfig.get().overrides.task]),
        "git_commit": git_commit(), "versions": package_versions(), "seed": cfg.seed, "algo": cfg.algo.name,
        "start": time.strftime("%Y-%m-%dT%H:%M:%S")}
    info["status"] = "running"
    if resuming:
        info.setdefault("resumed", []).append({"at": time.strftime("%Y-%m-%dT%H:%M:%S"), "frames": frames})
    write_json(out / "run.json", info)
    return info


def close_run(out: Path, cfg: Config, learner, buffer, counters: dict, log: "EpisodeLog", info: dict, status: str,
              saved: list) -> None:
    """The final checkpoint, the log made durable and closed, and run.json with how the run ended."""
    log.sync()
    if status != "checkpoint_failed":
        checkpoints.save_last(out / "checkpoints", cfg, learner, buffer, counters)
    else:  # the episodes after the last checkpoint will be run again on resume
        counters = checkpoints.saved_counters(out / "checkpoints") or counters
    log.close()
    log.writer.close()
    info.update(status=status, end=time.strftime("%Y-%m-%dT%H:%M:%S"), frames=counters["frames"],
                episodes=counters["episodes"], wall_time_s=round(counters["wall_time_s"], 3),
                updates=counters["updates"], best_reward=log.best if counters["episodes"] else None,
                saved_agents=[str(p.name) for _, p in saved], physics_errors=sum(log.flagged))
    write_json(out / "run.json", info)


def header_table(cfg: Config, out: Path):
    from rich.table import Table

    table = Table(title="pamrun train", show_header=False)
    a, t = cfg.algo, cfg.train
    for key, value in (
        ("algorithm", f"{a.name}: actor lr {a.actor_lr:g}, critic lr {a.critic_lr:g}, batch {a.batch_size}, "
                      f"gamma {a.gamma}, tau {a.target_smoothing:g}, "
                      + (f"initial alpha {a.init_alpha:g}" if a.name == "sac" else f"noise var {a.noise_variance:g}")),
        ("robot", f"H {cfg.body.height_m} m, M {cfg.body.mass_kg} kg, coupling {cfg.muscle.coupling}"),
        ("reward", f"kvx {cfg.reward.kvx}, ky {cfg.reward.ky}, kz {cfg.reward.kz}, kv {cfg.reward.kv}, "
                   f"kt {cfg.reward.kt}"
                   + (f"; kvx {t.walk_kvx:g} once it stands (train.walk_kvx)" if t.walk_kvx is not None else "")),
        ("budget", f"{t.max_frames} frames / {t.max_episodes} episodes"
                   + (f" / {t.max_minutes:g} min" if t.max_minutes else "")
                   + (f", stop at average {t.target_avg_reward:g}" if t.target_avg_reward else "")),
        ("collection", f"{t.workers} worker(s), {t.frames_per_batch} frames per batch, "
                       f"{t.updates_per_frame:g} updates per frame"),
        ("seed", str(cfg.seed)),
        ("run directory", str(out)),
    ):
        table.add_row(key, value)
    return table


def summary_table(run_info: dict, log: EpisodeLog, saved: list, out: Path):
    from rich.table import Table

    table = Table(title=f"Training finished: {run_info['status']}", show_header=False)
    rewards = log.rewards
    best_ep = int(np.argmax(rewards)) + 1 if rewards else None
    rows = [
        ("frames / episodes / updates", f"{run_info['frames']} / {run_info['episodes']} / {run_info['updates']}"),
        ("best episode", f"#{best_ep}: reward {max(rewards):.2f}" if rewards else "none"),
        ("final average reward", f"{np.mean(rewards[-log.window:]):.2f} (last {min(len(rewards), log.window)})"
         if rewards else "none"),
        ("saved agents", f"{len(saved)}" + (f", best {saved[0][1].name}" if saved else "")),
        ("physics errors", f"{sum(log.flagged)} episode(s) flagged (never saved)" if sum(log.flagged) else "none"),
        ("best evaluation", best_eval_text(out)),
        ("episodes", str(out / "episodes.csv")),
        ("curves", str(out / "training.png") + (", evals.png" if (out / "evals.csv").exists() else "")),
        ("checkpoints", str(out / "checkpoints")),
        ("TensorBoard", f"tensorboard --logdir {out / 'tensorboard'}"),
    ]
    for key, value in rows:
        table.add_row(key, value)
    return table


def best_eval_text(out: Path) -> str:
    path = out / "checkpoints" / checkpoints.BEST_EVAL
    if not path.exists():
        return "none"
    meta = checkpoints.load_agent(path).meta
    e = meta.get("eval", {})
    seeds = "..".join(map(str, e.get("seeds", []))) or "selection block"
    walk = (f"{e['walk_passes']}/{e['episodes']} ({100 * e['walk_pass_ci_low']:.0f}-{100 * e['walk_pass_ci_high']:.0f} %)"
            if "walk_pass_ci_low" in e else f"{e.get('walk_pass_rate', 0):.0%}")
    return (f"{path.name} at {meta.get('frames')} frames: walk test {walk}, stand "
            f"{e.get('stand_rate', 0):.0%}, distance {e.get('distance_mean', float('nan')):.2f} m "
            f"on the seeds it was selected on ({seeds}; evals.csv); pamrun eval ckpt=<run> reports held-out seeds")


def load_run_config(out: Path) -> Config:
    if not (out / "checkpoints" / "last.pt").exists() or not (out / "pamrun_config.yaml").exists():
        raise SystemExit(f"pamrun: {out} holds no training run to resume (no checkpoints/last.pt)")
    return saved_run_config(out)


def saved_run_config(out: Path) -> Config:
    """The config a run directory's pamrun_config.yaml holds, over today's defaults."""
    saved = upgrade_saved_config(OmegaConf.to_container(OmegaConf.load(out / "pamrun_config.yaml")))
    return to_object(OmegaConf.merge(OmegaConf.structured(Config), saved))


def plot_training(dcfg: DictConfig) -> None:
    """``pamrun plot training dir=<run dir>``: redraw training.png from episodes.csv."""
    run = Path(dcfg.dir)
    if not (run / "episodes.csv").exists():
        raise SystemExit(f"pamrun: no episodes.csv in {run}")
    path = plots.training_curves(run / "episodes.csv", run / "training.png")
    print(f"Wrote {path}")
