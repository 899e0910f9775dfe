"""``pamrun eval``: test saved agents in parallel, rank them and pick the best (thesis §10.3).

After training, the thesis tested every saved agent and showed the paths and muscle
pressures of the best. Here each agent runs ``eval.episodes`` episodes with its
deterministic policy, episode k from seed ``eval.seed + k`` for every agent, spread over
``eval.workers`` processes; the results do not depend on the number of workers. Per
episode: return, forward distance, duration before a fall, fell, max |y|, mean forward
speed and the mean absolute change of the 20 commanded pressures per control step (the
thesis found its gait pulsing). An episode passes the **walk test** when it lasts
``eval.walk_duration_s`` without a fall, never leaves |y| <= ``eval.walk_lateral_m`` and ends
``eval.walk_distance_m`` forward; an agent passes when all its episodes do.

The evaluation directory holds ``episodes.jsonl`` (metrics and per-step x, y, z, joint
angles, pressures and actions of every episode), ``leaderboard.csv``/``.json`` (ranked by
``eval.rank_by``), ``best.pt`` with ``selection.json`` saying why, and the figures drawn
from those files by :mod:`pamrun.plots`; ``eval.render=true`` adds ``best_episode.mp4`` and ``best_episode_frames.png``.
"""

from __future__ import annotations

import contextlib
import csv
import json
import multiprocessing
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pamrun.checkpoints import (ENV_SECTIONS, Agent, CheckpointError, check_fits, find_checkpoints, load_agent,
                                unique_labels)

from pamrun.config import RANK_METRICS  # aggregates an agent can be ranked by (``eval.rank_by``)

LEADERBOARD_FIELDS = ("rank", "agent", "walk_test", "walk_pass_rate", "stand_rate", "distance_mean", "distance_std", "distance_min",
                      "return_mean", "return_std", "duration_mean", "duration_std", "fall_rate", "physics_error_rate",
                      "max_abs_y_mean", "max_abs_y_max", "speed_mean", "speed_std", "pressure_change_mean", "pressure_change_std",
                      "train_episode", "train_reward", "path")


# --------------------------------------------------------------------------- one episode


def make_policy(agent: Agent):
    """The agent's actor as a function observation -> action (no exploration noise)."""
    import torch

    from pamrun import agents as agents_mod
    net = agents_mod.ThesisActor(agent.obs_size, agent.action_size, tuple(agent.hidden_sizes), init_scale=1e-3)
    net.load_state_dict(agent.actor_state)
    net.eval()

    def policy(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0].numpy()

    return policy


def env_kwargs(agent: Agent, cfg) -> dict[str, dict]:
    """Keyword arguments of PamWalkerEnv for ``agent``: its own robot and task (or the command
    line's), with the evaluation's start noise and episode length. Validated here."""
    from pamrun.config import BodyConfig, EnvConfig, MuscleConfig, RewardConfig
    from pamrun.env import as_config

    own = agent.config if (cfg.eval.use_agent_env and agent.config) else {}
    sections = {k: dict(own.get(k) or asdict(getattr(cfg, k))) for k in ENV_SECTIONS}
    sections["env"].update(reset_noise_rad=cfg.eval.reset_noise_rad,
                           reset_velocity_noise=cfg.eval.reset_velocity_noise, episode_s=cfg.eval.episode_s)
    types = {"body": BodyConfig, "muscle": MuscleConfig, "reward": RewardConfig, "env": EnvConfig}
    return {k: asdict(as_config(v, types[k])) for k, v in sections.items()}


def run_episode(policy: Callable, env, seed: int, frame_sink: Callable | None = None) -> dict[str, Any]:
    """One deterministic episode: metrics and per-step arrays (``frame_sink`` gets rendered frames)."""
    obs, info = env.reset(seed=seed)
    regulator, drive = env.drive.pairs.regulator, env.drive
    command = regulator.target_pressure_kpa(drive.voltage_v)
    steps = {k: [] for k in ("x_m", "y_m", "z_m", "joint_angle_rad", "pressure_kpa", "action")}
    angles = env.observation_structure["joint_angle"]
    total, change, max_y, fell, physics_error = 0.0, 0.0, 0.0, False, False
    if frame_sink:
        frame_sink(env.render())
    while True:
        action = policy(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        new_command = regulator.target_pressure_kpa(drive.voltage_v)
        change += float(np.abs(new_command - command).mean())
        command = new_command
        max_y = max(max_y, abs(float(info["y"])))
        physics_error |= bool(info["physics_error"])
        for key, value in (("x_m", info["x"]), ("y_m", info["y"]), ("z_m", info["z"]),
                           ("joint_angle_rad", obs[angles]), ("pressure_kpa", info["pressure_kpa"].ravel()),
                           ("action", action)):
            steps[key].append(value)
        if frame_sink:
            frame_sink(env.render())
        if terminated or truncated:
            fell = bool(terminated)
            break
    n = len(steps["x_m"])
    duration = n * env.env_cfg.control_dt_s
    distance = float(info["distance"])
    return {
        "seed": seed,
        "return": float(total),
        "distance_m": distance,
        "duration_s": duration,
        "fell": fell,
        "physics_error": physics_error,
        "max_abs_y_m": max_y,
        "speed_m_s": distance / duration,
        "pressure_change_kpa": change / n,
        "steps": {"t_s": (np.arange(1, n + 1) * env.env_cfg.control_dt_s).tolist(),
                  **{k: np.asarray(v, dtype=float).tolist() for k, v in steps.items()}},
    }


# --------------------------------------------------------------------------- many episodes, many processes

_WORKER: dict[str, Any] = {}


def _init_worker(agents: list[Agent], kwargs: list[dict], seed: int) -> None:
    """Per process: one thread for torch (identical results at any worker count), policies, envs."""
    import torch

    torch.set_num_threads(1)
    _WORKER.update(policies=[make_policy(a) for a in agents], kwargs=kwargs, seed=seed, envs={})


def _run_task(task: tuple[int, int]) -> tuple[int, int, dict]:
    from pamrun.env import PamWalkerEnv

    i, k = task
    key = json.dumps(_WORKER["kwargs"][i], sort_keys=True)
    if key not in _WORKER["envs"]:
        _WORKER["envs"][key] = PamWalkerEnv(**_WORKER["kwargs"][i])
    return i, k, run_episode(_WORKER["policies"][i], _WORKER["envs"][key], _WORKER["seed"] + k)


@contextlib.contextmanager
def _torch_threads(n: int):
    import torch

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def evaluate_agents(agents: list[Agent], kwargs: list[dict], episodes: int, seed: int, workers: int,
                    on_episode: Callable[[], None] | None = None) -> list[list[dict]]:
    """Episode results per agent, ``[agent][episode]``, the same for any number of workers."""
    import pamrun.agents  # noqa: F401  (torch and TorchRL imported once here, inherited by forked workers)

    tasks = [(i, k) for i in range(len(agents)) for k in range(episodes)]
    results: list[list[dict | None]] = [[None] * episodes for _ in agents]
    if workers <= 1:
        with _torch_threads(1):
            _init_worker(agents, kwargs, seed)
            try:
                for task in tasks:
                    i, k, res = _run_task(task)
                    results[i][k] = res
                    if on_episode:
                        on_episode()
            finally:
                for env in _WORKER["envs"].values():
                    env.close()
                _WORKER.clear()
        return results
    # fork: workers start in milliseconds and inherit the loaded agents (spawn where fork is absent).
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    pool = ProcessPoolExecutor(min(workers, len(tasks)), mp_context=multiprocessing.get_context(method),
                               initializer=_init_worker, initargs=(agents, kwargs, seed))
    try:
        for future in as_completed([pool.submit(_run_task, t) for t in tasks]):
            i, k, res = future.result()
            results[i][k] = res
            if on_episode:
                on_episode()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return results


# --------------------------------------------------------------------------- during training

EVALS_FIELDS = ("frames", "episodes", "wall_time_s", "eval_s", "walk_pass_rate", "stand_rate", "fall_rate",
                "distance_mean", "distance_min", "duration_mean", "max_abs_y_max", "return_mean",
                "pressure_change_mean", "best")


class TrainingEvaluator:
    """The walk test of ``pamrun eval`` run on the current actor during training.

    Every call runs ``cfg.train.eval_episodes`` deterministic episodes in one env of the
    run's robot and task, episode k from seed ``eval.seed + k`` with ``eval.reset_noise_rad``
    start noise (the same starts every time, as ``pamrun eval``), in this process with one
    torch thread, and returns the aggregate (:func:`aggregate`) with its cost ``eval_s``.
    Anchors: Stable-Baselines3's ``EvalCallback``, TorchRL's ``Evaluator``.
    """

    def __init__(self, cfg):
        from pamrun.env import PamWalkerEnv

        self.ecfg, self.episodes = cfg.eval, cfg.train.eval_episodes
        sections = {k: asdict(getattr(cfg, k)) for k in ENV_SECTIONS}
        sections["env"].update(reset_noise_rad=cfg.eval.reset_noise_rad,
                               reset_velocity_noise=cfg.eval.reset_velocity_noise, episode_s=cfg.eval.episode_s)
        self.env = PamWalkerEnv(**sections)

    def __call__(self, actor) -> dict[str, Any]:
        import torch

        start = time.perf_counter()

        def policy(obs: np.ndarray) -> np.ndarray:
            return actor(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0].numpy()

        with torch.no_grad(), _torch_threads(1):
            episodes = [run_episode(policy, self.env, self.ecfg.seed + k) for k in range(self.episodes)]
        return {**aggregate(episodes, self.ecfg), "eval_s": time.perf_counter() - start}

    def better(self, new: dict, best: dict | None) -> bool:
        """Whether ``new`` ranks before ``best`` by ``eval.rank_by`` (ties keep the old one)."""
        if best is None:
            return True
        ranked = rank([{**best, "agent": "0-best"}, {**new, "agent": "1-new"}], self.ecfg.rank_by)
        return ranked[0]["agent"] == "1-new"

    def close(self) -> None:
        self.env.close()


# --------------------------------------------------------------------------- metrics and ranking


def walk_passed(episode: dict, ecfg) -> bool:
    """The walk test of one episode (thesis §10.3 and its abstract): ``ecfg.walk_duration_s``
    without a fall, never leaving |y| <= ``ecfg.walk_lateral_m``, at least
    ``ecfg.walk_distance_m`` forward, and no physics blow-up (whose distances mean nothing)."""
    return (stood(episode, ecfg) and episode["max_abs_y_m"] <= ecfg.walk_lateral_m
            and episode["distance_m"] >= ecfg.walk_distance_m)


def stood(episode: dict, ecfg) -> bool:
    """The episode lasted ``ecfg.walk_duration_s`` without a fall or a physics blow-up."""
    return (not episode["fell"] and not episode.get("physics_error", False)
            and episode["duration_s"] >= ecfg.walk_duration_s - 1e-9)


# Per-episode metric -> name of its aggregates (<name>_mean, <name>_std).
AGGREGATED = {"return": "return", "distance_m": "distance", "duration_s": "duration", "speed_m_s": "speed",
              "max_abs_y_m": "max_abs_y", "pressure_change_kpa": "pressure_change"}


def aggregate(episodes: list[dict], ecfg) -> dict[str, Any]:
    """Mean and spread (population std) of an agent's episodes, its extremes, its walk test
    and its stand rate (the share of episodes that last the test's duration)."""
    passed = [walk_passed(e, ecfg) for e in episodes]
    out: dict[str, Any] = {"episodes": len(episodes), "walk_test": all(passed),
                           "walk_pass_rate": float(np.mean(passed)),
                           "stand_rate": float(np.mean([stood(e, ecfg) for e in episodes])),
                           "fall_rate": float(np.mean([e["fell"] for e in episodes])),
                           "physics_error_rate": float(np.mean([e.get("physics_error", False) for e in episodes]))}
    for key, name in AGGREGATED.items():
        values = np.array([e[key] for e in episodes], dtype=float)
        out[f"{name}_mean"], out[f"{name}_std"] = float(values.mean()), float(values.std())
        if name == "distance":
            out["distance_min"] = float(values.min())
        if name == "max_abs_y":
            out["max_abs_y_max"] = float(values.max())
    return out


def rank(rows: list[dict], rank_by: list[str]) -> list[dict]:
    """Rows sorted best first by ``rank_by`` (descending; '-name' ascending), ties by label.
    Each row gets its 1-based ``rank``; a NaN ranks last, and so does an agent any of whose
    episodes blew up in the physics (its numbers mean nothing)."""
    def key(row: dict) -> tuple:
        out = [row.get("physics_error_rate", 0.0) > 0]
        for name in rank_by:
            value = float(row[name.lstrip("-")])
            value = value if name.startswith("-") else -value
            out.append(np.inf if np.isnan(value) else value)
        return (*out, row["agent"])

    ranked = sorted(rows, key=key)
    for n, row in enumerate(ranked, 1):
        row["rank"] = n
    return ranked


def selection_reason(ranked: list[dict], rank_by: list[str]) -> str:
    """Why the first row won, in words."""
    best = ranked[0]
    by = ", then ".join(f"{n.lstrip('-')} = {best[n.lstrip('-')]:.4g}" + (" (lower is better)" if n[0] == "-" else "")
                        for n in rank_by)
    text = f"{best['agent']} ranks first of {len(ranked)} by {by}"
    if len(ranked) > 1:
        second = ranked[1]
        diff = next((n.lstrip("-") for n in rank_by if second[n.lstrip("-")] != best[n.lstrip("-")]), None)
        text += (f"; runner-up {second['agent']} has {diff} = {second[diff]:.4g}" if diff
                 else f"; tied with {second['agent']} on every criterion, first by name")
    return text + "."


# --------------------------------------------------------------------------- video


class VideoWriter:
    """H.264 mp4 from RGB frames (PyAV), streamed to disk frame by frame."""

    def __init__(self, path: Path, fps: float, width: int, height: int):
        import av

        self.container = av.open(str(path), mode="w")
        self.stream = self.container.add_stream("libx264", rate=int(round(fps)))
        self.stream.width, self.stream.height, self.stream.pix_fmt = width, height, "yuv420p"
        self.frames = 0

    def add(self, frame: np.ndarray) -> None:
        import av

        for packet in self.stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
            self.container.mux(packet)
        self.frames += 1

    def close(self) -> None:
        for packet in self.stream.encode():
            self.container.mux(packet)
        self.container.close()


def record_video(agent: Agent, kwargs: dict, seed: int, width: int, height: int, path: Path) -> dict:
    """Re-run one episode with offscreen rendering from the tracking camera; the episode's metrics."""
    from pamrun.env import PamWalkerEnv

    env = PamWalkerEnv(**kwargs, render_mode="rgb_array", width=width, height=height)
    writer = VideoWriter(path, 1.0 / env.env_cfg.control_dt_s, width, height)
    try:
        with _torch_threads(1):
            result = run_episode(make_policy(agent), env, seed, frame_sink=writer.add)
    finally:
        writer.close()
        env.close()
    result["frames"] = writer.frames
    return result


# --------------------------------------------------------------------------- the command


def check_config(config) -> None:
    """``ckpt`` must name at least one usable checkpoint (run by pamrun.cli before any directory exists)."""
    from pamrun.config import ConfigError

    try:
        paths = find_checkpoints(config.ckpt, config.eval.include_last)
    except CheckpointError as err:
        raise ConfigError("ckpt", str(err)) from None
    errors = []
    for path in paths:  # at least one must load, or the evaluation would write only its failure
        try:
            load_agent(path)
            return
        except CheckpointError as err:
            errors.append(err)
    raise ConfigError("ckpt", f"none of its {len(paths)} checkpoint(s) is usable; the first: {errors[0]}")


def load_agents(spec: str, cfg) -> tuple[list[Agent], list[dict], list[dict]]:
    """Agents named by ``spec`` with their env kwargs, and one error row per unusable file."""
    from omegaconf.errors import OmegaConfBaseException

    from pamrun.config import ConfigError
    from pamrun.env import space_sizes

    loaded, kwargs, errors = [], [], []
    for path in find_checkpoints(spec, cfg.eval.include_last):
        try:
            agent = load_agent(path)
            kw = env_kwargs(agent, cfg)
            check_fits(agent, *space_sizes(kw["muscle"]))
        except CheckpointError as err:
            errors.append({"path": err.path, "error": err.message})
            continue
        except (ConfigError, ValueError, OmegaConfBaseException) as err:
            errors.append({"path": str(path), "error": f"its stored config is not valid here: {err}".splitlines()[0]})
            continue
        loaded.append(agent)
        kwargs.append(kw)
    unique_labels(loaded)
    return loaded, kwargs, errors


def evaluate(dcfg) -> None:
    """The Hydra task of ``pamrun eval``."""
    from pamrun.config import to_object
    from pamrun.runio import run_dir

    cfg = to_object(dcfg)
    run_evaluation(cfg, cfg.ckpt, run_dir())


def run_evaluation(cfg, spec: str, out: Path) -> dict:
    """Evaluate the agents named by ``spec`` into ``out``; the selection (selection.json's content)."""
    from rich.console import Console

    console = Console() if Console().is_terminal else Console(width=160)  # logs keep whole rows
    out.mkdir(parents=True, exist_ok=True)
    agents, kwargs, errors = load_agents(spec, cfg)
    for err in errors:
        console.print(f"[red]skipped[/red] {err['path']}: {err['error']}", soft_wrap=True)
    if not agents:
        raise SystemExit(f"pamrun: no usable checkpoint in {spec} ({len(errors)} unreadable; see above)")
    results, workers, wall = run_all(agents, kwargs, cfg.eval, console)
    ranked, best, selection = write_results(out, cfg, spec, agents, results, errors, workers, wall)
    written = draw_figures(out, cfg.eval, agents, kwargs, results, best, console)
    console.print(leaderboard_table(ranked, cfg.eval))
    console.print(f"Best: [bold]{best.label}[/bold] -> {out / 'best.pt'}\n{selection['reason']}", soft_wrap=True)
    if errors:
        console.print(f"[red]{len(errors)} checkpoint(s) skipped[/red] (listed in leaderboard.json)")
    console.print(f"Evaluated in {wall:.1f} s on {workers} worker(s). Wrote {', '.join(written)}", soft_wrap=True)
    return selection


def run_all(agents: list[Agent], kwargs: list[dict], ecfg, console) -> tuple[list[list[dict]], int, float]:
    """Every agent's episodes, on ``eval.workers`` processes with a progress display."""
    from pamrun.runio import Progress
    from pamrun.runtime import usable_cores

    workers = min(ecfg.workers or usable_cores(), len(agents) * ecfg.episodes)
    import pamrun.agents  # noqa: F401  (imported before the clock starts)

    console.print(f"Evaluating {len(agents)} agent(s) x {ecfg.episodes} episode(s), seeds {ecfg.seed}.."
                  f"{ecfg.seed + ecfg.episodes - 1}, on {workers} worker(s)")
    start = time.perf_counter()
    progress = Progress(console, len(agents) * ecfg.episodes, 0, unit="episodes")
    done = [0]

    def tick() -> None:
        done[0] += 1
        progress.update(done[0], f"of {len(agents) * ecfg.episodes}")

    try:
        results = evaluate_agents(agents, kwargs, ecfg.episodes, ecfg.seed, workers, on_episode=tick)
    except KeyboardInterrupt:
        raise SystemExit("pamrun: evaluation interrupted; no results written (checkpoints are untouched)") from None
    finally:
        progress.stop()
    return results, workers, time.perf_counter() - start


def write_results(out: Path, cfg, spec: str, agents: list[Agent], results: list[list[dict]], errors: list[dict],
                  workers: int, wall_s: float) -> tuple[list[dict], Agent, dict]:
    """episodes.jsonl, the leaderboard, best.pt and selection.json; the ranking, best agent, selection."""
    from pamrun.checkpoints import save_agent_copy
    from pamrun.runio import write_json

    ecfg = cfg.eval
    with (out / "episodes.jsonl").open("w") as fh:
        for agent, episodes in zip(agents, results):
            for k, episode in enumerate(episodes):
                fh.write(json.dumps({"agent": agent.label, "episode": k, **episode,
                                     "walk_pass": walk_passed(episode, ecfg)})
                         + "\n")
    rows = [{"agent": agent.label, "path": str(agent.path), "train_episode": agent.meta.get("episode"),
             "train_reward": agent.meta.get("reward"), **aggregate(episodes, ecfg)}
            for agent, episodes in zip(agents, results)]
    ranked = rank(rows, list(ecfg.rank_by))
    write_leaderboard(out, ranked, errors, cfg, spec, workers, wall_s)
    best_row = ranked[0]
    best = next(a for a in agents if a.label == best_row["agent"])
    summary = {k: best_row[k] for k in ("walk_test", "walk_pass_rate", "distance_mean", "return_mean")}
    save_agent_copy(best, out / "best.pt", source=str(best.path), evaluation=summary)
    selection = {"best": best.label, "source": str(best.path), "file": "best.pt", "rank_by": list(ecfg.rank_by),
                 "reason": selection_reason(ranked, list(ecfg.rank_by)), "walk_test": best_row["walk_test"],
                 "metrics": {k: best_row[k] for k in LEADERBOARD_FIELDS if k not in ("rank", "agent", "path")},
                 "runner_up": ranked[1]["agent"] if len(ranked) > 1 else None, "agents": len(ranked),
                 "skipped": errors}
    write_json(out / "selection.json", selection)
    return ranked, best, selection


def draw_figures(out: Path, ecfg, agents: list[Agent], kwargs: list[dict], results: list[list[dict]], best: Agent,
                 console) -> list[str]:
    """Figures from the files just written (and the best agent's video); the names of all files."""
    from pamrun import plots

    written = ["episodes.jsonl", "leaderboard.csv", "leaderboard.json", "best.pt", "selection.json"]
    plots.trajectories(out / "episodes.jsonl", out / "leaderboard.json", out / "trajectories.png",
                       top_k=ecfg.top_k, lateral_m=ecfg.walk_lateral_m)
    plots.pressures(out / "episodes.jsonl", best.label, 0, out / "pressures.png")
    written += ["trajectories.png", "pressures.png"]
    runs = list(dict.fromkeys(a.run_dir for a in agents if a.run_dir and (a.run_dir / "episodes.csv").exists()))
    for run in runs:
        name = "training.png" if len(runs) == 1 else f"training_{run.name}.png"
        plots.training_curves(run / "episodes.csv", out / name)
        written.append(name)
    if ecfg.render:
        video = record_video(best, kwargs[agents.index(best)], ecfg.seed, ecfg.video_width, ecfg.video_height,
                             out / "best_episode.mp4")
        same = abs(video["distance_m"] - results[agents.index(best)][0]["distance_m"]) < 1e-9
        console.print(f"Video: {video['frames']} frames, {video['duration_s']:.2f} s"
                      + ("" if same else " [red](the replay differs from the evaluated episode)[/red]"))
        plots.video_frames(out / "best_episode.mp4", out / "best_episode_frames.png")
        written += ["best_episode.mp4", "best_episode_frames.png"]
    return written


def write_leaderboard(out: Path, ranked: list[dict], errors: list[dict], cfg, spec: str, workers: int,
                      wall_s: float) -> None:
    with (out / "leaderboard.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=LEADERBOARD_FIELDS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(ranked)
    ecfg = cfg.eval
    (out / "leaderboard.json").write_text(json.dumps({
        "rank_by": list(ecfg.rank_by), "episodes": ecfg.episodes,
        "seeds": list(range(ecfg.seed, ecfg.seed + ecfg.episodes)), "workers": workers, "wall_time_s": round(wall_s, 3),
        "ckpt": spec, "eval": asdict(ecfg), "agents": ranked, "errors": errors}, indent=2))


def leaderboard_table(ranked: list[dict], ecfg, limit: int = 20):
    from rich.table import Table

    table = Table(title=f"Leaderboard ({ecfg.episodes} episodes each; ranked by {', '.join(ecfg.rank_by)})")
    for col in ("#", "agent", "walk test", "distance (m)", "min (m)", "return", "time (s)", "falls", "max |y| (m)",
                "dP (kPa/step)"):
        table.add_column(col, justify="left" if col == "agent" else "right", no_wrap=True)
    for row in ranked[:limit]:
        verdict = "[green]pass[/green]" if row["walk_test"] else f"{row['walk_pass_rate']:.0%}"
        table.add_row(str(row["rank"]), row["agent"], verdict,
                      f"{row['distance_mean']:.2f} ± {row['distance_std']:.2f}", f"{row['distance_min']:.2f}",
                      f"{row['return_mean']:.1f} ± {row['return_std']:.1f}", f"{row['duration_mean']:.2f}",
                      f"{row['fall_rate']:.0%}", f"{row['max_abs_y_max']:.3f}", f"{row['pressure_change_mean']:.1f}")
    if len(ranked) > limit:
        table.caption = f"{len(ranked) - limit} more in leaderboard.csv"
    return table
