"""``pamrun train``: DDPG, TD3 or SAC on PamWalker-v0 with TorchRL (thesis §9.5).

:func:`train` is the recipe, top to bottom: a TorchRL collector (one process, or
``train.workers`` processes) fills a ``TensorDictReplayBuffer``; after ``train.init_random_frames``
of uniform random actions, each collected frame buys ``train.updates_per_frame`` gradient
updates of the learner (:mod:`pamrun.learning.networks`). A :class:`Run` keeps the run's books in its
directory (:mod:`pamrun.runs.directory`): every finished episode is a row of ``episodes.csv`` and a
point in TensorBoard (reward, average reward, Q0: the three curves of thesis Fig. 10.24);
agents whose episode reward reaches ``train.save_threshold`` are saved (MATLAB's
SaveAgentCriteria); evaluations every ``train.eval_every_frames`` keep ``best_eval.pt`` and show
their gait in TensorBoard (scalars, figure, a video every ``train.eval_video_every``); and
``checkpoints/last.pt`` holds what a later resume needs, written atomically. A reward
curriculum (:mod:`pamrun.learning.curriculum`) is a transform of the replay buffer. A run from
a trained agent (``train.init_from``) starts as :mod:`pamrun.training.init_from` says.
"""

from __future__ import annotations

import functools
import math
import random
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from torch.utils.tensorboard import SummaryWriter
from torchrl.collectors import AsyncCollector, Collector, MultiAsyncCollector, MultiSyncCollector
from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer, Unbounded
from torchrl.envs import GymWrapper
from torchrl.envs.gym_like import default_info_dict_reader

import pamrun  # noqa: F401  (registers PamWalker-v0 with Gymnasium, in worker processes too)
from pamrun.config import Config, ConfigError, to_object, without_hydra
from pamrun.evaluation import board, figures
from pamrun.evaluation.evaluator import TrainingEvaluator
from pamrun.learning import checkpoints, exploration, networks
from pamrun.learning.curriculum import COMPUTED, FEATURES, FeatureReader, WalkCurriculum, weighed_terms
from pamrun.runs import directory
from pamrun.runs.directory import EVAL_FIELDS, CsvLog, EpisodeLog, RunFiles
from pamrun.runs.files import console as make_console
from pamrun.runs.files import run_dir
from pamrun.runs.machine import Terminated, stop_signals, usable_cores
from pamrun.task import randomize
from pamrun.task.observation import space_sizes
from pamrun.task.spec import EnvSpec
from pamrun.task.symmetry import action_map, mirror_batch, observation_map
from pamrun.training.console import end_of_run, header_table, summary_table
from pamrun.training.init_from import check_start, start_from
from pamrun.training.progress import TrainingProgress

NEW_RUN = {"frames": 0, "episodes": 0, "updates": 0, "wall_time_s": 0.0}  # a run's counters at its start


def make_env(cfg: Config, seed: int | None = None):
    """PamWalker-v0 with this config (redrawn per episode with ``train.randomize``) in TorchRL's
    GymWrapper (its ``GymEnv`` reserves the keyword ``env``), reading ``distance``, ``physics_error``
    and the reward's unweighted terms from info; ``seed`` seeds it before a collector's first
    reset (else its start noise comes from the OS)."""


    # every reward term at any weight, for the curriculum and any later run from this buffer; info
    # only as far as training reads it
    spec, options = EnvSpec.from_config(cfg), {"features": COMPUTED, "lean_info": True}
    env = GymWrapper(randomize.RandomizedWalker.from_config(spec, cfg, options) if cfg.train.randomize
                     else gym.make("pamrun/PamWalker-v0", **spec.sections(), **options))
    info = {"distance": Unbounded((), dtype=torch.float64), "physics_error": Unbounded((), dtype=torch.bool)}
    env.set_info_dict_reader(default_info_dict_reader(list(info), spec=info))
    env.set_info_dict_reader(FeatureReader())  # the reward's terms by key, for the curriculum
    if seed is not None:
        env.set_seed(seed)
    return env


def make_collector(cfg: Config, policy, total_frames: int, start_random: int, seed: int):
    """TorchRL's collector for ``train.workers`` envs: in this process (one worker), in worker
    processes stepping in lockstep, or with ``train.async_collection`` in worker processes
    that keep stepping while the learner updates (each batch then comes from the policy of
    one or more batches before)."""

    # auto_register_policy_transforms: adds the InitTracker the OU noise needs to restart per episode.
    kwargs = dict(frames_per_batch=cfg.train.frames_per_batch, total_frames=total_frames,
                  init_random_frames=start_random, auto_register_policy_transforms=True)
    makes = [functools.partial(make_env, cfg, seed + i) for i in range(cfg.train.workers)]
    if cfg.train.async_collection:
        collector = AsyncCollector(makes[0], policy, **kwargs) if cfg.train.workers == 1 else \
            MultiAsyncCollector(makes, policy, **kwargs)
    else:
        collector = Collector(makes[0], policy, **kwargs) if cfg.train.workers == 1 else \
            MultiSyncCollector(makes, policy, **kwargs)
    collector.set_seed(seed)
    return collector


def make_learner(cfg: Config) -> networks.Learner:

    probe = make_env(cfg)  # the env's action spec, as TorchRL sees it (the losses and exploration need it)
    spec = probe.action_spec_unbatched
    probe.close()
    sizes = space_sizes(cfg.muscle, cfg.env)
    mirror = None
    if cfg.algo.mirror_loss:  # the observation's and action's mirror images (pamrun/task/symmetry.py)
        mirror = (*observation_map(sizes[1], cfg.env.speed_command, cfg.env.gait_period_s > 0), *action_map(sizes[1]))
    return networks.make_learner(cfg.algo, *sizes, spec, mirror, colored_noise=cfg.train.walk_noise_beta is not None)


def make_buffer(cfg: Config, curriculum: WalkCurriculum):

    # No batch_size: learn() draws the samples of many updates in one call.
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(cfg.train.buffer_size))
    return buffer.append_transform(curriculum.transform)


def train(cfg: Config, out: Path, overrides: list[str] = ()) -> str:
    """Train (or resume) the run in ``out`` with ``cfg``; return how it ended (run.json's status).
    ``overrides``: the command line, recorded in run.json (a resume takes a new budget from it)."""

    console = make_console()
    randomize.check(cfg)  # before anything is written
    if cfg.train.init_from and not (cfg.resume or RunFiles(out).last.exists()):
        try:
            check_start(cfg)
        except ConfigError as err:
            raise SystemExit(f"pamrun: invalid configuration: {err}") from None
    cfg, resuming = directory.open_run(cfg, out, console, overrides)
    for seed in (random.seed, np.random.seed, torch.manual_seed):  # Python's, numpy's and torch's generators
        seed(cfg.seed)
    torch.set_num_threads(cfg.train.threads or max(1, usable_cores() - cfg.train.workers + 1))
    learner, curriculum = make_learner(cfg), WalkCurriculum(cfg)
    buffer = make_buffer(cfg, curriculum)
    counters, carried = resume(out, learner, buffer) if resuming else (dict(NEW_RUN), None)
    if cfg.train.init_from and not resuming:
        carried = start_from(cfg, learner, buffer, console)
    if carried is not None:  # a buffer an older run filled: only these terms are re-weighted truly
        curriculum.transform.carried = carried
    if counters["frames"] >= cfg.train.max_frames or counters["episodes"] >= cfg.train.max_episodes:
        console.print(f"{out} already finished its budget ({counters['frames']} frames, {counters['episodes']} "
                      f"episodes): nothing to do. To train on, give it a larger one: pamrun train "
                      f"resume={out} train.max_frames=...", soft_wrap=True)
        return "finished"
    if resuming and cfg.train.eval_every_frames:
        curriculum.replay(directory.read_evals(out))
    run = Run(cfg, out, learner, buffer, console, counters, resuming, overrides, curriculum)
    collector = make_collector(cfg, learner.explore, cfg.train.max_frames - run.frames,
                               max(0, cfg.train.init_random_frames - run.frames), cfg.seed + run.frames)
    console.print(header_table(cfg, out))
    if run.evals and cfg.train.init_from and not run.frames:
        run.evaluate()  # the agent it starts from, at frame 0
    status, failure = None, None
    try:
        with stop_signals():
            for batch in collector:
                batch = batch.reshape(-1)
                run.collect(batch)
                if run.learn(batch.numel()):
                    collector.update_policy_weights_()
                status = run.after_batch(batch.numel())
                if status:
                    break
    except BaseException as err:
        status, failure = stopped_by(err)
        if status == "failed":
            raise
    finally:
        collector.shutdown()
        run.close(status or "max_frames")
    console.print(summary_table(run.info, run.log, run.saved, out))
    end_of_run(console, out, status, failure, run.log)
    return run.info["status"]


def check_config(config) -> None:
    """What ``pamrun train`` needs beyond a valid config, checked by pamrun.cli before any
    directory exists: ``resume=`` names a run; ``train.init_from``, in a new run, an agent that fits."""
    directory.check_resume(config)
    if config.train.init_from and not config.resume:
        check_start(to_object(without_hydra(config)))


def main(dcfg) -> None:
    """The Hydra task of ``pamrun train``: its config and run directory from Hydra."""


    train(to_object(dcfg), run_dir(), list(HydraConfig.get().overrides.task))


class Run:
    """One training run's state and books: counters, logs, saved agents, evaluations, the
    exploration noise's schedule, checkpoints, and how it ends."""

    def __init__(self, cfg: Config, out: Path, learner, buffer, console, counters: dict, resuming: bool, overrides,
                 curriculum: WalkCurriculum):

        self.cfg, self.out, self.files, self.console = cfg, out, RunFiles(out), console
        self.learner, self.buffer, self.curriculum = learner, buffer, curriculum
        self.frames, self.update_budget = counters["frames"], 0.0
        self.noise_std = self.set_noise()
        self.log = EpisodeLog(out, cfg.train.avg_window, SummaryWriter(str(self.files.tensorboard)),
                              counters["episodes"])
        self.tracker = EpisodeTracker(list(weighed_terms(cfg)))  # the terms TensorBoard may show
        self.evals = Evaluations(cfg, out, self.log.writer, console) if cfg.train.eval_every_frames else None
        self.info = directory.start_run_json(out, cfg, resuming, self.frames, overrides)
        if curriculum.walking:
            self.info.setdefault("walk_kvx_from_frames", curriculum.since)
            if curriculum.stage == "gait":
                self.info.setdefault("gait_weights_from_frames", curriculum.gait_since)
            console.print(curriculum.describe(), soft_wrap=True)
        self.saved = checkpoints.scan_saved(self.files.checkpoints)
        self.clock = Clock(counters["wall_time_s"])
        self.progress = TrainingProgress(console, cfg.train, self.counters(), curriculum)

    def counters(self) -> dict:
        return {"frames": self.frames, "episodes": self.log.episodes, "updates": self.learner.updates,
                "wall_time_s": self.clock.seconds()}

    def set_noise(self) -> float:
        """The exploration noise's scale at this frame count (:func:`pamrun.learning.exploration.noise_scale`),
        and its spectrum at this stage (``train.walk_noise_beta`` from the walking stage on)."""
        scale = exploration.noise_scale(self.cfg.algo, self.frames)
        exploration.set_noise_scale(self.learner.explore, scale)
        if self.cfg.train.walk_noise_beta is not None:
            exploration.set_noise_beta(self.learner.explore, self.noise_beta())
        return math.sqrt(self.cfg.algo.noise_variance) * scale

    def noise_beta(self) -> float:
        """The exploration noise's spectrum now, 1/f^beta."""
        walk = self.cfg.train.walk_noise_beta
        return walk if walk is not None and self.curriculum.walking else self.cfg.algo.noise_beta

    def collect(self, batch) -> None:
        """A collected batch into the buffer; its finished episodes logged (with Q0) and saved
        when they reach the threshold (never one whose physics blew up)."""
        self.frames += batch.numel()
        self.buffer.extend(batch)
        if self.cfg.train.mirror:  # its mirror image too (pamrun/task/symmetry.py): the same reward, twice the data
            self.buffer.extend(mirror_batch(batch, self.cfg.env))
        finished = self.tracker.add(batch)
        q0s = self.learner.q0(torch.stack([e["obs0"] for e in finished])) if finished else []
        for episode, q0 in zip(finished, q0s):
            row = self.log.add(episode, q0, self.frames, self.clock.seconds())
            weights = self.curriculum.transform.weights  # the episode's terms as the learner weighs them now
            for key, total in episode["terms"].items():
                if weights[key]:
                    self.log.writer.add_scalar(f"reward_terms/{key}", weights[key] * total, self.log.episodes)
            if episode["reward"] >= self.cfg.train.save_threshold and not episode["physics_error"]:
                self.saved = checkpoints.save_agent(self.files.checkpoints, self.learner.policy_state(), row,
                                                    self.cfg, self.saved, self.cfg.train.keep_saved)

    def learn(self, n: int) -> bool:
        """The updates the batch's frames past the random phase buy; True if any frame did.

        The buffer does not change between these updates, so their samples are drawn in one call
        (uniform with replacement, as one sample per update would be; the buffer's transforms, a
        reward curriculum, apply to them): one TensorDict operation per batch, not per update."""
        t, learner = self.cfg.train, self.learner
        learn_frames = self.frames - max(t.init_random_frames, self.frames - n)
        self.update_budget += max(0, learn_frames) * t.updates_per_frame
        updates, self.update_budget = int(self.update_budget), self.update_budget - int(self.update_budget)
        if learner.anchor_actor is not None:
            learner.anchor_weight = networks.anchor_weight(self.cfg.algo, self.frames)
            self.log.writer.add_scalar("curriculum/anchor", learner.anchor_weight, self.frames)
        if updates:
            samples = self.buffer.sample(updates * learner.cfg.batch_size).reshape(updates, learner.cfg.batch_size)
            for i in range(updates):
                learner.update(samples[i], self.frames >= t.actor_start_frames)
                if learner.updates % 50 == 0:
                    for name, value in learner.losses().items():
                        self.log.writer.add_scalar(f"loss/{name}", value, learner.updates)
        return learn_frames > 0

    def after_batch(self, n: int) -> str | None:
        """Noise, progress, checkpoint and evaluation after a batch; why the run stops now, or None."""
        t, w, elapsed = self.cfg.train, self.log.writer, self.clock.seconds()
        self.noise_std = self.set_noise()
        w.add_scalar("throughput/frames_per_s", self.frames / elapsed, self.frames)
        w.add_scalar("throughput/updates_per_s", self.learner.updates / elapsed, self.frames)
        w.add_scalar("exploration/noise_std", self.noise_std, self.frames)
        if t.walk_noise_beta is not None:
            w.add_scalar("exploration/noise_beta", self.noise_beta(), self.frames)
        self.progress.update(self.counters(), f"avg {self.log.average():.2f}  best {self.log.best:.2f}")
        if self.frames % t.checkpoint_every_frames < n:
            self.log.sync()
            checkpoints.save_last(self.files.checkpoints, self.cfg, self.learner, self.buffer, self.counters(),
                                  self.curriculum.transform.carried)
        if self.evals and self.frames % t.eval_every_frames < n and self.evaluate()["walk_test"] and t.stop_on_walk:
            return "walked"
        return stop_reason(self.cfg, self.log, self.clock.seconds())

    def evaluate(self) -> dict:
        result = self.evals.run(self.learner.actor.module, self.learner.policy_state(), self.cfg, self.counters())
        if self.curriculum.observe(result["stand_rate"], self.frames, result["walk_pass_rate"],
                                   result["distance_min"]):
            for key, weight in self.curriculum.changed().items():
                self.log.writer.add_scalar(f"curriculum/{key}", weight, self.frames)
            self.info["gait_weights_from_frames" if self.curriculum.stage == "gait" else "walk_kvx_from_frames"] = self.frames
            self.console.print(self.curriculum.describe(), soft_wrap=True)
            self.noise_std = self.set_noise()  # the stage's noise from the next action on
        if self.curriculum.stage == "gait":
            for key, weight in self.curriculum.adapted().items():  # train.adapt_weights, after this evaluation
                self.log.writer.add_scalar(f"curriculum/{key}", weight, self.frames)
        self.progress.evaluated(result, self.counters())
        return result

    def close(self, status: str) -> None:
        """The final checkpoint, the logs made durable and closed, run.json, and the figures."""
        self.progress.stop()
        if self.evals:
            self.evals.close()
        self.log.sync()
        counters = self.counters()
        if status != "checkpoint_failed" and len(self.buffer):  # (a crash before any frame leaves nothing to keep)
            checkpoints.save_last(self.files.checkpoints, self.cfg, self.learner, self.buffer, counters,
                                  self.curriculum.transform.carried)
        else:  # the episodes after the last checkpoint will be run again on resume
            counters = checkpoints.saved_counters(self.files.checkpoints) or counters
        self.log.close()
        self.log.writer.close()
        directory.end_run_json(self.out, self.info, status, counters, self.log, self.saved)
        figures.training_curves(self.files.episodes, self.files.training_png)
        if self.files.evals.exists():
            figures.eval_curves(self.files.evals, self.files.evals_png, self.cfg.eval.walk_distance_m,
                              self.cfg.eval.episode_s)


class Evaluations:
    """Evaluations during training: evals.csv, TensorBoard ``eval/*`` and checkpoints/best_eval.pt,
    and TensorBoard's gait scalars and figure (:mod:`pamrun.evaluation.board`), with a video every
    ``train.eval_video_every``-th evaluation (counted in frames: the k-th at k x ``train.eval_every_frames``).

    ``best_eval.pt`` is only ever replaced by an agent that ranks before it (``eval.rank_by``);
    its evaluation is stored in it, so a resumed run keeps comparing against it."""

    def __init__(self, cfg: Config, out: Path, writer, console):

        self.best_path = RunFiles(out).best_eval
        self.evaluator = TrainingEvaluator(cfg)
        self.every, self.video_every = cfg.train.eval_every_frames, cfg.train.eval_video_every
        self.writer, self.console = writer, console
        self.best = checkpoints.load_agent(self.best_path).meta.get("eval") if self.best_path.exists() else None
        self.log = CsvLog(RunFiles(out).evals, EVAL_FIELDS)

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
        self.log.append({**result, "frames": counters["frames"], "episodes": counters["episodes"],
                         "wall_time_s": round(counters["wall_time_s"], 3), "best": int(best)})
        for key in ("walk_pass_rate", "stand_rate", "fall_rate", "distance_mean", "duration_mean",
                    "max_abs_y_max", "return_mean", "select_pass_rate", "select_schedule_rate", "eval_s"):
            if result[key] == result[key]:  # NaN: not measured (select_schedule_rate without a schedule)
                self.writer.add_scalar(f"eval/{key}", result[key], counters["frames"])
        self.show(actor, result, counters["frames"])
        return result

    def show(self, actor, result: dict, frames: int) -> None:
        """TensorBoard's gait scalars and figure of this evaluation, and its video when one is due,
        each with its cost (``eval/figure_s``, ``eval/video_s``)."""
        start = time.perf_counter()
        board.log_gait(self.writer, result, frames)
        board.log_gait_figure(self.writer, result["first_episode"], self.evaluator.gait_spec, frames)
        self.writer.add_scalar("eval/figure_s", time.perf_counter() - start, frames)
        if self.video_every and (frames // self.every) % self.video_every == 0:
            start, had_video = time.perf_counter(), not self.evaluator.no_video
            video = self.evaluator.video(actor)
            if video:
                board.log_video(self.writer, *video, frames)
                self.writer.add_scalar("eval/video_s", time.perf_counter() - start, frames)
            elif had_video:  # said once, on the console and in TensorBoard's text tab
                self.console.print(f"[yellow]pamrun: {self.evaluator.no_video}[/]", soft_wrap=True)
                self.writer.add_text("video/episode", self.evaluator.no_video, frames)

    def close(self) -> None:
        self.log.close()
        self.evaluator.close()


def resume(out: Path, learner, buffer) -> tuple[dict, set[str]]:
    """Learner, buffer and RNG states of the last checkpoint; forget what came after it. Returns
    the counters and the reward terms the buffer's transitions carry.

    Any piece that is missing or damaged stops the resume with one line naming the file."""
    files = RunFiles(out)
    try:
        counters, terms = checkpoints.load_last(files.checkpoints, learner, buffer)
    except checkpoints.CheckpointError as err:
        raise SystemExit(f"pamrun: cannot resume {out}: {err}. Restore the file, or start the run again "
                         "in a new directory.") from None
    directory.truncate_logs(out, counters)
    checkpoints.drop_agents_after(files.checkpoints, counters["episodes"])
    return counters, set(weighed_terms(directory.saved_config(out))) if terms is None else terms


def stopped_by(err: BaseException) -> tuple[str, Exception | None]:
    """The run.json status of a training stopped by ``err`` (``failed``: a crash to re-raise)."""
    if isinstance(err, KeyboardInterrupt):
        return "interrupted", None
    if isinstance(err, Terminated):
        return "terminated", None
    if isinstance(err, checkpoints.CheckpointError):  # a checkpoint could not be written (disk full)
        return "checkpoint_failed", err
    return "failed", None


class Clock:
    """Wall-clock seconds of training, carried over a resume."""

    def __init__(self, previous_s: float = 0.0):
        self.start = time.perf_counter() - previous_s

    def seconds(self) -> float:
        return time.perf_counter() - self.start


class EpisodeTracker:
    """Sums each collector trajectory's reward, length and unweighted reward terms (those named
    ``terms``) until it is done, with its first observation (for Q0), its distance and whether its
    physics blew up.

    Not TorchRL's ``RewardSum``/``StepCounter``: RewardSum sums in the reward's float32 (off by
    up to ~1e-3 over a 400-step return of ~400, which episodes.csv's 5 decimals show), and the
    first observation and physics flag need this per-trajectory state anyway."""

    def __init__(self, terms: list[str]):
        self.running: dict[int, dict] = {}
        self.terms = terms

    def add(self, batch) -> list[dict]:
        """The episodes this (flat) batch finishes."""
        finished = []
        traj = batch["collector", "traj_ids"].tolist()
        reward = batch["next", "reward"].reshape(-1).tolist()
        done = batch["next", "done"].reshape(-1).tolist()
        distance = batch["next", "distance"].reshape(-1).tolist()
        error = batch["next", "physics_error"].reshape(-1).tolist()
        features = {k: batch["next", FEATURES, k].reshape(-1).tolist() for k in self.terms}
        for i in range(len(traj)):
            ep = self.running.setdefault(traj[i], {"reward": 0.0, "length": 0, "obs0": batch["observation"][i],
                                                   "physics_error": False, "terms": dict.fromkeys(self.terms, 0.0)})
            ep["reward"] += reward[i]
            for k, values in features.items():
                ep["terms"][k] += values[i]
            ep["length"] += 1
            ep["physics_error"] |= bool(error[i])
            if done[i]:
                ep["distance_m"] = distance[i]
                finished.append(self.running.pop(traj[i]))
        return finished


def stop_reason(cfg: Config, log: EpisodeLog, elapsed_s: float) -> str | None:
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
