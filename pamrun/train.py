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
import json
import math
import os
import random
import shutil
import subprocess
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from pamrun.checkpoints import agent_record
from pamrun.config import Config, to_object, upgrade_saved_config
from pamrun.runtime import usable_cores

CSV_FIELDS = ("episode", "frames", "reward", "avg_reward", "q0", "length", "distance_m", "wall_time_s")


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
    env.set_info_dict_reader(default_info_dict_reader(["distance"]))
    return env


def make_collector(cfg: Config, policy, total_frames: int, start_random: int):
    from torchrl.collectors import Collector, MultiSyncCollector

    # auto_register_policy_transforms: adds the InitTracker the OU noise needs to restart per episode.
    kwargs = dict(frames_per_batch=cfg.train.frames_per_batch, total_frames=total_frames,
                  init_random_frames=start_random, auto_register_policy_transforms=True)
    if cfg.train.workers == 1:
        return Collector(functools.partial(make_env, cfg), policy, **kwargs)
    return MultiSyncCollector([functools.partial(make_env, cfg)] * cfg.train.workers, policy, **kwargs)


def seed_everything(seed: int) -> None:
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)


def atomic_save(obj, path: Path) -> None:
    """torch.save to a temporary file, then rename: a crash never leaves a torn file."""
    tmp = path.with_suffix(path.suffix + ".tmp")
    torch.save(obj, tmp)
    os.replace(tmp, path)


class EpisodeLog:
    """Per-episode rows in episodes.csv and TensorBoard, and the running average."""

    def __init__(self, out: Path, window: int, writer):
        self.path = out / "episodes.csv"
        new = not self.path.exists()
        history = [] if new else [float(r["reward"]) for r in csv.DictReader(self.path.open())]
        self.file = self.path.open("a", newline="")
        self.csv = csv.DictWriter(self.file, fieldnames=CSV_FIELDS)
        if new:
            self.csv.writeheader()
        self.rewards: list[float] = history
        self.window = window
        self.writer = writer
        self.best = max(self.rewards, default=-math.inf)

    def add(self, row: dict) -> dict:
        self.rewards.append(row["reward"])
        row["avg_reward"] = float(np.mean(self.rewards[-self.window:]))
        self.best = max(self.best, row["reward"])
        self.csv.writerow({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()})
        self.file.flush()  # a killed process loses no finished episode
        ep = row["episode"]
        for key in ("reward", "avg_reward", "q0", "length", "distance_m"):
            self.writer.add_scalar(f"episode/{key}", row[key], ep)
        return row

    def sync(self) -> None:
        """Make the rows durable before a checkpoint refers to them (machine loss)."""
        self.file.flush()
        os.fsync(self.file.fileno())

    def close(self) -> None:
        self.file.close()


def train(dcfg: DictConfig) -> None:
    """The Hydra task of ``pamrun train``."""
    from rich.console import Console
    from torch.utils.tensorboard import SummaryWriter
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    from pamrun import agents
    from pamrun.env import space_sizes
    from pamrun.lab import run_dir

    console = Console()
    cfg: Config = to_object(dcfg)
    out = run_dir()
    ckpt_dir = out / "checkpoints"
    resuming = bool(cfg.resume)
    if resuming:
        cfg = load_run_config(out)
        console.print(f"Resuming {out} with its own config ({cfg.algo.name}); command-line values are ignored.")
    else:
        if (ckpt_dir / "last.pt").exists():
            raise SystemExit(f"pamrun: {out} already holds a training run; continue it with resume={out}")
        (out / "pamrun_config.yaml").write_text(OmegaConf.to_yaml(OmegaConf.structured(cfg)))
    ckpt_dir.mkdir(exist_ok=True)
    seed_everything(cfg.seed)
    torch.set_num_threads(cfg.train.threads or max(1, usable_cores() - cfg.train.workers + 1))

    probe = make_env(cfg)
    action_spec = probe.action_spec_unbatched
    probe.close()
    obs_size, act_size = space_sizes(cfg.muscle)
    actor = agents.make_actor(cfg.algo, obs_size, act_size)
    critic = agents.make_critic(cfg.algo, obs_size, act_size)
    explore = agents.make_exploration(cfg.algo, actor, action_spec)
    loss, updater, _ = agents.make_loss(cfg.algo, actor, critic, action_spec)
    critic_loss_fn, actor_loss_fn = agents.loss_parts(loss)
    actor_params = list(loss.actor_network_params.flatten_keys().values())
    critic_net_params = loss.value_network_params if cfg.algo.name == "ddpg" else loss.qvalue_network_params
    critic_params = list(critic_net_params.flatten_keys().values())
    actor_opt = torch.optim.Adam(actor_params, lr=cfg.algo.actor_lr)
    critic_opt = torch.optim.Adam(critic_params, lr=cfg.algo.critic_lr)
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(cfg.train.buffer_size), batch_size=cfg.algo.batch_size)

    frames = episodes = updates = 0
    previous_s = 0.0
    if resuming:
        state = torch.load(ckpt_dir / "last.pt", weights_only=True)
        loss.load_state_dict(state["loss"])
        actor_opt.load_state_dict(state["actor_opt"])
        critic_opt.load_state_dict(state["critic_opt"])
        frames, episodes, updates = (state["counters"][k] for k in ("frames", "episodes", "updates"))
        previous_s = state["counters"].get("wall_time_s", 0.0)
        set_rng_states(state["rng"])
        load_buffer(buffer, ckpt_dir)
        truncate_after(out, ckpt_dir, episodes)
        if frames >= cfg.train.max_frames or episodes >= cfg.train.max_episodes:
            console.print(f"{out} already finished its budget ({frames} frames, {episodes} episodes): nothing to do.")
            return
    agents.set_noise_scale(explore, agents.noise_scale(cfg.algo, frames))

    writer = SummaryWriter(str(out / "tensorboard"))
    log = EpisodeLog(out, cfg.train.avg_window, writer)
    run_info = json.loads((out / "run.json").read_text()) if resuming else {
        "command": " ".join(["pamrun", "train", *HydraConfig.get().overrides.task]),
        "git_commit": git_commit(), "versions": package_versions(), "seed": cfg.seed, "algo": cfg.algo.name,
        "start": time.strftime("%Y-%m-%dT%H:%M:%S")}
    run_info["status"] = "running"
    if resuming:
        run_info.setdefault("resumed", []).append({"at": time.strftime("%Y-%m-%dT%H:%M:%S"), "frames": frames})
    (out / "run.json").write_text(json.dumps(run_info, indent=2))

    saved = scan_saved(ckpt_dir)
    running: dict[int, dict] = {}
    collector = make_collector(cfg, explore, cfg.train.max_frames - frames,
                               max(0, cfg.train.init_random_frames - frames))
    collector.set_seed(cfg.seed + frames)
    start = time.perf_counter() - previous_s
    update_budget = 0.0
    status = "max_frames"
    console.print(header_table(cfg, out))
    progress = Progress(console, cfg.train.max_frames, frames)
    try:
        for batch in collector:
            batch = batch.reshape(-1)
            n = batch.numel()
            frames += n
            buffer.extend(batch)
            # ---- episodes finished in this batch
            finished = []
            traj = batch["collector", "traj_ids"].tolist()
            reward = batch["next", "reward"].reshape(-1).tolist()
            done = batch["next", "done"].reshape(-1).tolist()
            distance = batch["next", "distance"].reshape(-1).tolist()
            for i in range(n):
                ep = running.setdefault(traj[i], {"reward": 0.0, "length": 0, "obs0": batch["observation"][i]})
                ep["reward"] += reward[i]
                ep["length"] += 1
                if done[i]:
                    ep["distance_m"] = distance[i]
                    finished.append(running.pop(traj[i]))
            if finished:
                with torch.no_grad():
                    obs0 = torch.stack([e["obs0"] for e in finished])
                    q0 = critic.module(obs0, actor.module(obs0)).reshape(-1).tolist()
                for e, q in zip(finished, q0):
                    episodes += 1
                    row = log.add({"episode": episodes, "frames": frames, "reward": e["reward"], "avg_reward": 0.0,
                                   "q0": q, "length": e["length"], "distance_m": e["distance_m"],
                                   "wall_time_s": round(time.perf_counter() - start, 3)})
                    if e["reward"] >= cfg.train.save_threshold:
                        saved = save_agent(ckpt_dir, actor, row, cfg, saved)
            # ---- gradient updates
            learn_frames = frames - max(cfg.train.init_random_frames, frames - n)  # frames past the random phase
            if learn_frames > 0:
                update_budget += learn_frames * cfg.train.updates_per_frame
                while update_budget >= 1:
                    update_budget -= 1
                    sample = buffer.sample()
                    # Critic and actor losses separately (as TorchRL's sota scripts): computing
                    # only what each step needs is ~1.5x faster than the full loss forward.
                    critic_loss = critic_loss_fn(sample)[0]
                    critic_opt.zero_grad()
                    critic_loss.backward()
                    torch.nn.utils.clip_grad_norm_(critic_params, cfg.algo.grad_clip)
                    critic_opt.step()
                    if updates % cfg.algo.actor_update_every == 0:
                        actor_loss = actor_loss_fn(sample)[0]
                        actor_opt.zero_grad()
                        actor_loss.backward()
                        torch.nn.utils.clip_grad_norm_(actor_params, cfg.algo.grad_clip)
                        actor_opt.step()
                        updater.step()
                    updates += 1
                    if updates % 50 == 0:
                        writer.add_scalar("loss/actor", actor_loss.item(), updates)
                        writer.add_scalar("loss/critic", critic_loss.item(), updates)
                collector.update_policy_weights_()
            scale = agents.noise_scale(cfg.algo, frames)
            agents.set_noise_scale(explore, scale)
            elapsed = time.perf_counter() - start
            writer.add_scalar("throughput/frames_per_s", frames / elapsed, frames)
            writer.add_scalar("throughput/updates_per_s", updates / elapsed, frames)
            writer.add_scalar("exploration/noise_std", math.sqrt(cfg.algo.noise_variance) * scale, frames)
            avg = float(np.mean(log.rewards[-cfg.train.avg_window:])) if log.rewards else float("nan")
            progress.update(frames, f"episodes {episodes}  avg {avg:.2f}  best {log.best:.2f}  "
                                    f"{frames / elapsed:.0f} frames/s  {updates / elapsed:.1f} updates/s")
            if frames % cfg.train.checkpoint_every_frames < n:
                log.sync()
                save_last(ckpt_dir, cfg, actor, loss, actor_opt, critic_opt, buffer, frames, episodes, updates, elapsed)
            if episodes >= cfg.train.max_episodes:
                status = "max_episodes"
                break
            if cfg.train.max_minutes and elapsed > 60 * cfg.train.max_minutes:
                status = "max_minutes"
                break
            if cfg.train.target_avg_reward and len(log.rewards) >= cfg.train.avg_window and \
                    np.mean(log.rewards[-cfg.train.avg_window:]) >= cfg.train.target_avg_reward:
                status = "target_avg_reward"
                break
    except KeyboardInterrupt:
        status = "interrupted"
    finally:
        progress.stop()
        collector.shutdown()
        log.sync()
        save_last(ckpt_dir, cfg, actor, loss, actor_opt, critic_opt, buffer, frames, episodes, updates,
                  time.perf_counter() - start)
        log.close()
        writer.close()
        run_info.update(status=status, end=time.strftime("%Y-%m-%dT%H:%M:%S"), frames=frames, episodes=episodes,
                        wall_time_s=round(time.perf_counter() - start, 3),
                        updates=updates, best_reward=log.best if episodes else None,
                        saved_agents=[str(p.name) for _, p in saved])
        (out / "run.json").write_text(json.dumps(run_info, indent=2))
    from pamrun import plots

    plots.training_curves(out / "episodes.csv", out / "training.png")
    console.print(summary_table(run_info, log, saved, out))


class Progress:
    """A rich progress bar with ETA on a terminal; a plain line every ~10 s otherwise (CI, files)."""

    def __init__(self, console, total: int, done: int, unit: str = "frames"):
        self.console = console
        self.unit = unit
        self.bar = None
        self.last_line = 0.0
        if console.is_terminal and os.environ.get("PAMRUN_PROGRESS") != "lines":  # sweep jobs share a terminal
            from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
            from rich.progress import Progress as RichProgress

            self.bar = RichProgress(TextColumn(unit), BarColumn(), MofNCompleteColumn(),
                                    TextColumn("{task.fields[info]}"), TimeElapsedColumn(), TextColumn("ETA"),
                                    TimeRemainingColumn(), console=console)
            self.task = self.bar.add_task(unit, total=total, completed=done, info="")

    def update(self, done: int, info: str) -> None:
        if self.bar is not None:
            if not self.bar.live.is_started:  # started on first use: worker processes fork before its thread
                self.bar.start()
            self.bar.update(self.task, completed=done, info=info)
        elif time.monotonic() - self.last_line > 10:
            self.last_line = time.monotonic()
            self.console.print(f"{self.unit} {done}  {info}", soft_wrap=True)

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()


def header_table(cfg: Config, out: Path):
    from rich.table import Table

    table = Table(title="pamrun train", show_header=False)
    a, t = cfg.algo, cfg.train
    for key, value in (
        ("algorithm", f"{a.name}: actor lr {a.actor_lr:g}, critic lr {a.critic_lr:g}, batch {a.batch_size}, "
                      f"gamma {a.gamma}, tau {a.target_smoothing:g}, noise var {a.noise_variance:g}"),
        ("robot", f"H {cfg.body.height_m} m, M {cfg.body.mass_kg} kg, coupling {cfg.muscle.coupling}"),
        ("reward", f"kvx {cfg.reward.kvx}, ky {cfg.reward.ky}, kz {cfg.reward.kz}, kv {cfg.reward.kv}, "
                   f"kt {cfg.reward.kt}"),
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
        ("episodes", str(out / "episodes.csv")),
        ("curves", str(out / "training.png")),
        ("checkpoints", str(out / "checkpoints")),
        ("TensorBoard", f"tensorboard --logdir {out / 'tensorboard'}"),
    ]
    for key, value in rows:
        table.add_row(key, value)
    return table


def save_agent(ckpt_dir: Path, actor, row: dict, cfg: Config, saved: list) -> list:
    """Save the actor with its episode's reward in name and metadata; keep the best ``keep_saved``."""
    path = ckpt_dir / f"agent_ep{row['episode']:06d}_r{row['reward']:.1f}.pt"
    meta = {k: row[k] for k in ("episode", "frames", "reward", "distance_m", "q0")}
    atomic_save(agent_record(actor.module.state_dict(), cfg, meta), path)
    saved = sorted(saved + [(row["reward"], path)], key=lambda t: -t[0])
    for _, old in saved[cfg.train.keep_saved:]:
        old.unlink(missing_ok=True)
    return saved[: cfg.train.keep_saved]


def save_last(ckpt_dir: Path, cfg: Config, actor, loss, actor_opt, critic_opt, buffer, frames: int, episodes: int,
              updates: int, wall_time_s: float) -> None:
    """Everything a resume needs, and the final actor as an agent (``pamrun eval`` reads it).

    The buffer goes first, through a directory swap, then ``last.pt`` atomically, so a
    crash at any moment leaves a loadable pair. Plain data only: loadable with
    ``weights_only=True``."""
    tmp, live, old = ckpt_dir / "buffer.tmp", ckpt_dir / "buffer", ckpt_dir / "buffer.old"
    shutil.rmtree(tmp, ignore_errors=True)
    buffer.dumps(tmp)
    shutil.rmtree(old, ignore_errors=True)
    if live.exists():
        os.replace(live, old)
    os.replace(tmp, live)
    shutil.rmtree(old, ignore_errors=True)
    counters = {"frames": frames, "episodes": episodes, "updates": updates, "wall_time_s": wall_time_s}
    atomic_save(
        {**agent_record(actor.module.state_dict(), cfg, {"frames": frames, "episode": episodes}),
         "loss": loss.state_dict(), "actor_opt": actor_opt.state_dict(), "critic_opt": critic_opt.state_dict(),
         "counters": counters, "rng": rng_states()},
        ckpt_dir / "last.pt",
    )


def rng_states() -> dict:
    """Torch, numpy and Python RNG states as tensors, lists and numbers (weights_only-safe)."""
    np_state = np.random.get_state(legacy=False)
    np_state["state"]["key"] = np_state["state"]["key"].tolist()
    return {"torch": torch.get_rng_state(), "numpy": np_state, "python": random.getstate()}


def set_rng_states(rng: dict) -> None:
    torch.set_rng_state(rng["torch"])
    np_state = dict(rng["numpy"])
    np_state["state"] = {**np_state["state"], "key": np.asarray(np_state["state"]["key"], dtype=np.uint32)}
    np.random.set_state(np_state)
    random.setstate(tuple(tuple(x) if isinstance(x, list) else x for x in rng["python"]))


def load_buffer(buffer, ckpt_dir: Path) -> None:
    """The replay buffer of the last checkpoint (or of the one before, mid-swap)."""
    for name in ("buffer", "buffer.old"):
        if (ckpt_dir / name).exists():
            buffer.loads(ckpt_dir / name)
            return
    raise SystemExit(f"pamrun: no replay buffer in {ckpt_dir}: cannot resume")


def truncate_after(out: Path, ckpt_dir: Path, episodes: int) -> None:
    """Forget what was logged after the last checkpoint: those episodes will be run again."""
    path = out / "episodes.csv"
    if path.exists():
        rows = list(csv.DictReader(path.open()))
        kept = [r for r in rows if int(r["episode"]) <= episodes]
        with path.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=CSV_FIELDS)
            w.writeheader()
            w.writerows(kept)
    for agent in ckpt_dir.glob("agent_ep*.pt"):
        if int(agent.name.split("_")[1][2:]) > episodes:
            agent.unlink()


def scan_saved(ckpt_dir: Path) -> list[tuple[float, Path]]:
    """Threshold-saved agents already on disk, best first."""
    found = [(torch.load(p, weights_only=True)["meta"]["reward"], p) for p in ckpt_dir.glob("agent_ep*.pt")]
    return sorted(found, key=lambda t: -t[0])


def load_run_config(out: Path) -> Config:
    path = out / "pamrun_config.yaml"
    if not (out / "checkpoints" / "last.pt").exists() or not path.exists():
        raise SystemExit(f"pamrun: {out} holds no training run to resume (no checkpoints/last.pt)")
    saved = upgrade_saved_config(OmegaConf.to_container(OmegaConf.load(path)))
    return to_object(OmegaConf.merge(OmegaConf.structured(Config), saved))


def git_commit() -> str | None:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True,
                              cwd=Path(__file__).parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def package_versions() -> dict[str, str]:
    from importlib.metadata import version

    return {name: version(name) for name in ("pamrun", "torch", "torchrl", "tensordict", "mujoco", "gymnasium",
                                             "numpy", "hydra-core")}


def plot_training(dcfg: DictConfig) -> None:
    """``pamrun plot training dir=<run dir>``: redraw training.png from episodes.csv."""
    from pamrun import plots

    run = Path(dcfg.dir)
    if not (run / "episodes.csv").exists():
        raise SystemExit(f"pamrun: no episodes.csv in {run}")
    path = plots.training_curves(run / "episodes.csv", run / "training.png")
    print(f"Wrote {path}")
