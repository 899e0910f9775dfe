"""``pamrun eval``: test saved agents in parallel, rank them and pick the best (thesis §10.3).

The episodes themselves (the agent's env, perturbations, workers, the walk test and the
aggregates) are :mod:`pamrun.evaluation.episodes`'s; this module ranks, writes and draws.

After training, the thesis tested every saved agent and showed the paths and muscle
pressures of the best. Here each agent runs ``eval.episodes`` (50) episodes with its
deterministic policy, episode k from seed ``eval.seed + k`` for every agent, spread over
``eval.workers`` processes; the results do not depend on the number of workers. Per
episode: return, forward distance, duration before a fall, fell, max |y|, mean forward
speed, the mean absolute change of the 20 commanded pressures per control step (the
thesis found its gait pulsing) and the gait and air metrics of :mod:`pamrun.evaluation.metrics`. An
episode passes the **walk test** of :func:`pamrun.task.criteria.walk_passed`; an agent's pass rate comes with its episode count and 95 % Wilson interval.

**Held-out seeds.** Evaluation during training selects ``best_eval.pt`` on the selection
block (seeds ``eval.selection_seed + k``); ``pamrun eval`` reports on ``eval.seed + k``
(from 1000), and ``leaderboard.json`` says whether the two blocks are disjoint
(``held_out``); when they are not, the console says so in red.

The evaluation directory holds ``episodes.jsonl`` (metrics and per-step x, y, z, joint
angles, velocities and torques, pressures, contractions, foot forces and positions and
actions of every episode), ``leaderboard.csv``/``.json`` (ranked by ``eval.rank_by``),
``best.pt`` with ``selection.json`` saying why, and the figures drawn from those files by
:mod:`pamrun.evaluation.figures` (``gait.png`` of the best agent among them); ``eval.render=true`` adds
``best_episode.mp4`` and ``best_episode_frames.png``.

**Suites.** ``eval.suite=robustness`` runs every agent under each perturbation of
``eval.suites.robustness`` (each a :class:`pamrun.config.Perturbation` of its own robot and
task, applied through the env's options) and writes ``robustness.csv``/``.json`` (agent x
perturbation: walk pass rate with its interval, stand rate, distance, ...),
``robustness_episodes.jsonl`` and ``robustness.png``.
"""

from __future__ import annotations

import copy
import csv
import json
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from pamrun.evaluation.episodes import (
    aggregate,
    env_kwargs,
    eval_env_options,
    evaluate_agents,
    gait_spec,
    make_policy,
    run_episode,
    torch_threads,
)
from pamrun.evaluation.metrics import GAIT_METRICS
from pamrun.learning.checkpoints import (
    ENV_SECTIONS,
    Agent,
    CheckpointError,
    check_fits,
    find_checkpoints,
    load_agent,
    unique_labels,
)
from pamrun.runs.directory import RunFiles
from pamrun.task.criteria import walk_passed
from pamrun.task.spec import perturb

LEADERBOARD_FIELDS = ("rank", "agent", "episodes", "walk_test", "walk_passes", "walk_pass_rate", "walk_pass_ci_low",
                      "walk_pass_ci_high", "stand_rate", "distance_mean", "distance_std", "distance_min",
                      "return_mean", "return_std", "duration_mean", "duration_std", "fall_rate", "physics_error_rate",
                      "max_abs_y_mean", "max_abs_y_max", "speed_mean", "speed_std", "pressure_change_mean", "pressure_change_std",
                      *(f"{m}_{s}" for m in GAIT_METRICS for s in ("mean", "std")),
                      "train_episode", "train_reward", "path")


# --------------------------------------------------------------------------- one episode




















# --------------------------------------------------------------------------- many episodes, many processes











# --------------------------------------------------------------------------- during training

class TrainingEvaluator:
    """The walk test of ``pamrun eval`` run on the current actor during training.

    Every call runs ``cfg.train.eval_episodes`` deterministic episodes in one env of the
    run's robot and task, episode k from seed ``eval.selection_seed + k`` (the selection
    block, disjoint from ``pamrun eval``'s held-out ``eval.seed``) with ``eval.reset_noise_rad``
    start noise (the same starts every time, as ``pamrun eval``), in this process with one
    torch thread, and returns the aggregate (:func:`aggregate`) with its cost ``eval_s``.

    **Selection under perturbation** (``train.select_perturbations``): once a nominal episode
    passes, the call also runs ``train.select_episodes`` episodes (seeds ``eval.selection_seed
    + k``; a name's own count in ``train.select_episodes_of``) under each of those perturbations
    of the suite, and ``select_pass_rate`` is the walk pass rate over all the episodes it ran
    (without them: ``walk_pass_rate``). ``better`` ranks by it first, then by ``eval.rank_by``:
    among agents that all walk the nominal block, the one that holds under perturbation is kept.
    The nominal aggregate is unchanged (the curriculum reads it).
    Anchors: Stable-Baselines3's ``EvalCallback``, TorchRL's ``Evaluator``.
    """

    def __init__(self, cfg):
        from pamrun.task.env import PamWalkerEnv

        self.ecfg, self.episodes = cfg.eval, cfg.train.eval_episodes
        t = cfg.train
        self.select_counts = [t.select_episodes_of.get(name, t.select_episodes) for name in t.select_perturbations]
        sections = {k: asdict(getattr(cfg, k)) for k in ENV_SECTIONS}
        sections["env"].update(reset_noise_rad=cfg.eval.reset_noise_rad,
                               reset_velocity_noise=cfg.eval.reset_velocity_noise, episode_s=cfg.eval.episode_s)
        self.env = PamWalkerEnv(**sections)
        self.perturbed = [PamWalkerEnv(**perturb(sections, cfg.eval.perturbations[name],
                                                 f"eval.perturbations.{name}"))
                          for name in cfg.train.select_perturbations]

    def __call__(self, actor) -> dict[str, Any]:
        import torch

        start = time.perf_counter()

        def policy(obs: np.ndarray) -> np.ndarray:
            return actor(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0].numpy()

        def block(env, n: int) -> list[dict]:
            return [run_episode(policy, env, self.ecfg.selection_seed + k, keep_steps=False) for k in range(n)]

        with torch.no_grad(), torch_threads(1):
            episodes = block(self.env, self.episodes)
            result = aggregate(episodes, self.ecfg)
            if result["walk_passes"]:
                episodes += [e for env, n in zip(self.perturbed, self.select_counts) for e in block(env, n)]
        seeds = [self.ecfg.selection_seed, self.ecfg.selection_seed + self.episodes - 1]
        select = float(np.mean([walk_passed(e, self.ecfg) for e in episodes]))
        return {**result, "select_pass_rate": select, "seeds": seeds, "eval_s": time.perf_counter() - start}

    def better(self, new: dict, best: dict | None) -> bool:
        """Whether ``new`` ranks before ``best`` by ``eval.rank_by``, preceded by
        ``select_pass_rate`` when selecting under perturbation (ties keep the old one; a best
        saved before selection under perturbation existed counts its ``walk_pass_rate``)."""
        if best is None:
            return True
        best = {"select_pass_rate": best["walk_pass_rate"], **best, "agent": "0-best"}
        by = ["select_pass_rate"] * bool(self.perturbed) + list(self.ecfg.rank_by)
        ranked = rank([best, {**new, "agent": "1-new"}], by)
        return ranked[0]["agent"] == "1-new"

    def close(self) -> None:
        for env in (self.env, *self.perturbed):
            env.close()


# --------------------------------------------------------------------------- metrics and ranking


def pass_text(row: dict) -> str:
    """'41/50 (69-90 %)': passes of episodes with the 95 % Wilson interval."""
    return (f"{row['walk_passes']}/{row['episodes']} ({100 * row['walk_pass_ci_low']:.0f}-"
            f"{100 * row['walk_pass_ci_high']:.0f} %)")


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
    from pamrun.task.env import PamWalkerEnv

    env = PamWalkerEnv(**kwargs, render_mode="rgb_array", width=width, height=height)
    writer = VideoWriter(path, 1.0 / env.env_cfg.control_dt_s, width, height)
    try:
        with torch_threads(1):
            result = run_episode(make_policy(agent), env, seed, frame_sink=writer.add)
    finally:
        writer.close()
        env.close()
    result["frames"] = writer.frames
    return result


# --------------------------------------------------------------------------- the command


def check_config(config) -> None:
    """``ckpt`` must name at least one usable checkpoint (run by pamrun.cli before any directory exists)."""
    from pamrun.config import ConfigError, to_object

    if config.eval.suite:  # every perturbation of the suite applied to the command line's robot and task
        from omegaconf import open_dict, read_write

        config = copy.deepcopy(config)
        with read_write(config), open_dict(config):
            config.pop("hydra", None)  # (its interpolations resolve only inside a Hydra job)
        cfg = to_object(config)
        base = {k: asdict(getattr(cfg, k)) for k in ENV_SECTIONS}
        base["env"].update(eval_env_options(cfg.eval))
        for name in cfg.eval.suites[cfg.eval.suite]:
            perturb(base, cfg.eval.perturbations[name], f"eval.perturbations.{name}")
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
    from pamrun.task.env import space_sizes

    loaded, kwargs, errors = [], [], []
    for path in find_checkpoints(spec, cfg.eval.include_last):
        try:
            agent = load_agent(path)
            kw = env_kwargs(agent, cfg)
            check_fits(agent, *space_sizes(kw["muscle"], kw["env"]))
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
    from pamrun.runs.files import run_dir

    cfg = to_object(dcfg)
    if cfg.eval.suite:
        run_suite(cfg, cfg.ckpt, run_dir())
    else:
        run_evaluation(cfg, cfg.ckpt, run_dir())


def selection_block(agent: Agent, cfg) -> range:
    """The seeds ``agent`` was selected on: those its best_eval record names, else (an agent
    saved before the record) ``eval.selection_seed`` onwards for its evaluation's episodes."""
    record = agent.meta.get("eval") or {}
    if "seeds" in record:
        return range(int(record["seeds"][0]), int(record["seeds"][1]) + 1)
    return range(cfg.eval.selection_seed,
                 cfg.eval.selection_seed + int(record.get("episodes") or cfg.train.eval_episodes))


def held_out(agents: list[Agent], cfg) -> bool:
    """Whether the evaluation's seeds miss every agent's selection block."""
    seeds = set(range(cfg.eval.seed, cfg.eval.seed + cfg.eval.episodes))
    return not any(seeds & set(selection_block(a, cfg)) for a in agents)


def warn_if_not_held_out(agents: list[Agent], cfg, console) -> bool:
    ok = held_out(agents, cfg)
    if not ok:
        console.print(f"[red]Seeds {cfg.eval.seed}..{cfg.eval.seed + cfg.eval.episodes - 1} overlap the seeds an "
                      f"agent was selected on: these numbers are biased (use eval.seed >= 1000)[/red]", soft_wrap=True)
    return ok


def start(cfg, spec: str, out: Path) -> tuple[Any, list[Agent], list[dict], list[dict]]:
    """A console, ``out`` made, and the usable agents of ``spec`` with their env kwargs and the
    unusable files (named on the console); exits when none is usable."""
    from pamrun.runs.files import console as make_console

    console = make_console()
    out.mkdir(parents=True, exist_ok=True)
    agents, kwargs, errors = load_agents(spec, cfg)
    for err in errors:
        console.print(f"[red]skipped[/red] {err['path']}: {err['error']}", soft_wrap=True)
    if not agents:
        raise SystemExit(f"pamrun: no usable checkpoint in {spec} ({len(errors)} unreadable; see above)")
    return console, agents, kwargs, errors


def run_evaluation(cfg, spec: str, out: Path) -> dict:
    """Evaluate the agents named by ``spec`` into ``out``; the selection (selection.json's content)."""
    console, agents, kwargs, errors = start(cfg, spec, out)
    is_held_out = warn_if_not_held_out(agents, cfg, console)
    results, workers, wall = run_all(agents, kwargs, cfg.eval, console)
    ranked, best, selection = write_results(out, cfg, spec, agents, results, errors, workers, wall, is_held_out)
    written = draw_figures(out, cfg.eval, agents, kwargs, results, best, console)
    console.print(leaderboard_table(ranked, cfg.eval))
    console.print(gait_table(ranked))
    console.print(f"Best: [bold]{best.label}[/bold] -> {out / 'best.pt'}\n{selection['reason']}", soft_wrap=True)
    if errors:
        console.print(f"[red]{len(errors)} checkpoint(s) skipped[/red] (listed in leaderboard.json)")
    console.print(f"Evaluated in {wall:.1f} s on {workers} worker(s). Wrote {', '.join(written)}", soft_wrap=True)
    return selection


ROBUSTNESS_FIELDS = ("agent", "perturbation", "note", "episodes", "walk_passes", "walk_pass_rate", "walk_pass_ci_low",
                     "walk_pass_ci_high", "stand_rate", "fall_rate", "physics_error_rate", "distance_mean", "distance_std",
                     "distance_min", "speed_mean", "max_abs_y_max", "pressure_change_mean", "stop_share_max_mean",
                     "foot_slip_m_s_mean", "cost_of_transport_mean", "air_nl_per_m_mean")


def run_suite(cfg, spec: str, out: Path) -> list[dict]:
    """``pamrun eval eval.suite=NAME``: every agent under each perturbation of the suite, on the
    same held-out seeds; writes robustness.csv/.json, robustness_episodes.jsonl and
    robustness.png; returns the rows (agent x perturbation)."""
    from pamrun.evaluation import figures
    from pamrun.runs.files import write_json

    ecfg = cfg.eval
    console, agents, kwargs, errors = start(cfg, spec, out)
    names = list(ecfg.suites[ecfg.suite])
    runs = [(agent, name, perturb(kw, ecfg.perturbations[name], f"eval.perturbations.{name}"))
            for agent, kw in zip(agents, kwargs) for name in names]
    is_held_out = warn_if_not_held_out(agents, cfg, console)
    results, workers, wall = run_all([r[0] for r in runs], [r[2] for r in runs], ecfg, console, keep_steps=False,
                                     what=f"runs ({len(agents)} agent(s) x {len(names)} perturbation(s))")
    rows = []
    with (out / "robustness_episodes.jsonl").open("w") as fh:
        for (agent, name, _), episodes in zip(runs, results):
            for k, episode in enumerate(episodes):
                record = {"agent": agent.label, "perturbation": name, "episode": k,
                          **episode,
                          "walk_pass": walk_passed(episode, ecfg)}
                fh.write(json.dumps(record) + "\n")
            row = {"agent": agent.label, "perturbation": name, "note": ecfg.perturbations[name].note,
                   **aggregate(episodes, ecfg)}
            rows.append({key: row[key] for key in ROBUSTNESS_FIELDS})
    with (out / "robustness.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=ROBUSTNESS_FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    n_episodes = len(runs) * ecfg.episodes
    write_json(out / "robustness.json", {
        "suite": ecfg.suite, "ckpt": spec, "episodes": ecfg.episodes, "held_out": is_held_out,
        "seeds": [ecfg.seed, ecfg.seed + ecfg.episodes - 1], "workers": workers, "wall_time_s": round(wall, 3),
        "seconds_per_episode": round(wall / n_episodes, 4),
        "perturbations": {name: asdict(ecfg.perturbations[name]) for name in names},
        "agents": [a.label for a in agents], "rows": rows, "errors": errors})
    figures.robustness(out / "robustness.json", out / "robustness.png")
    console.print(robustness_table(rows, ecfg))
    console.print(f"Evaluated in {wall:.1f} s on {workers} worker(s) ({wall / n_episodes:.3f} s per episode). Wrote "
                  f"robustness.csv, robustness.json, robustness_episodes.jsonl, robustness.png in {out}", soft_wrap=True)
    return rows


def robustness_table(rows: list[dict], ecfg):
    from rich.table import Table

    table = Table(title=f"Robustness ({ecfg.episodes} episodes per cell, seeds {ecfg.seed}.."
                        f"{ecfg.seed + ecfg.episodes - 1}; walk test with its 95 % Wilson interval)")
    for col in ("agent", "perturbation", "what", "walk test (95 % CI)", "stands", "distance (m)", "blow-ups"):
        table.add_column(col, justify="left" if col in ("agent", "perturbation", "what") else "right",
                         no_wrap=col != "agent", overflow="fold")
    for row in rows:
        table.add_row(row["agent"], row["perturbation"], row["note"], pass_text(row), f"{row['stand_rate']:.0%}",
                      f"{row['distance_mean']:.2f} ± {row['distance_std']:.2f}", f"{row['physics_error_rate']:.0%}")
    return table


def run_all(agents: list[Agent], kwargs: list[dict], ecfg, console, what: str = "agent(s)", keep_steps: bool = True
            ) -> tuple[list[list[dict]], int, float]:
    """Every agent's episodes, on ``eval.workers`` processes with a progress display."""
    from pamrun.runs.files import Progress
    from pamrun.runs.machine import usable_cores

    workers = min(ecfg.workers or usable_cores(), len(agents) * ecfg.episodes)
    import pamrun.learning.networks  # noqa: F401  (imported before the clock starts)

    console.print(f"Evaluating {len(agents)} {what} x {ecfg.episodes} episode(s), seeds {ecfg.seed}.."
                  f"{ecfg.seed + ecfg.episodes - 1}, on {workers} worker(s)")
    start = time.perf_counter()
    progress = Progress(console, len(agents) * ecfg.episodes, 0, unit="episodes")
    done = [0]

    def tick() -> None:
        done[0] += 1
        progress.update(done[0], f"of {len(agents) * ecfg.episodes}")

    try:
        results = evaluate_agents(agents, kwargs, ecfg.episodes, ecfg.seed, workers, on_episode=tick,
                                  keep_steps=keep_steps)
    except KeyboardInterrupt:
        raise SystemExit("pamrun: evaluation interrupted; no results written (checkpoints are untouched)") from None
    finally:
        progress.stop()
    return results, workers, time.perf_counter() - start


def write_results(out: Path, cfg, spec: str, agents: list[Agent], results: list[list[dict]], errors: list[dict],
                  workers: int, wall_s: float, is_held_out: bool = True) -> tuple[list[dict], Agent, dict]:
    """episodes.jsonl, the leaderboard, best.pt and selection.json; the ranking, best agent, selection."""
    from pamrun.learning.checkpoints import save_agent_copy
    from pamrun.runs.files import write_json

    ecfg = cfg.eval
    with (out / "episodes.jsonl").open("w") as fh:
        for agent, episodes in zip(agents, results):
            for k, episode in enumerate(episodes):
                record = {"agent": agent.label, "episode": k, **episode, "walk_pass": walk_passed(episode, ecfg)}
                if not ecfg.save_steps:
                    record.pop("steps")
                fh.write(json.dumps(record) + "\n")
    rows = [{"agent": agent.label, "path": str(agent.path), "train_episode": agent.meta.get("episode"),
             "train_reward": agent.meta.get("reward"), **aggregate(episodes, ecfg)}
            for agent, episodes in zip(agents, results)]
    ranked = rank(rows, list(ecfg.rank_by))
    write_leaderboard(out, ranked, errors, cfg, spec, workers, wall_s, is_held_out)
    best_row = ranked[0]
    best = next(a for a in agents if a.label == best_row["agent"])
    summary = {k: best_row[k] for k in ("walk_test", "walk_pass_rate", "walk_passes", "episodes", "walk_pass_ci_low",
                                        "walk_pass_ci_high", "distance_mean", "return_mean")}
    summary["seeds"], summary["held_out"] = [ecfg.seed, ecfg.seed + ecfg.episodes - 1], is_held_out
    save_agent_copy(best, out / "best.pt", source=str(best.path), evaluation=summary)
    selection = {"best": best.label, "source": str(best.path), "file": "best.pt", "rank_by": list(ecfg.rank_by),
                 "reason": selection_reason(ranked, list(ecfg.rank_by)), "walk_test": best_row["walk_test"],
                 "metrics": {k: best_row[k] for k in LEADERBOARD_FIELDS if k not in ("rank", "agent", "path")},
                 "runner_up": ranked[1]["agent"] if len(ranked) > 1 else None, "agents": len(ranked),
                 "held_out": is_held_out,
                 "skipped": errors}
    write_json(out / "selection.json", selection)
    return ranked, best, selection


def draw_figures(out: Path, ecfg, agents: list[Agent], kwargs: list[dict], results: list[list[dict]], best: Agent,
                 console) -> list[str]:
    """Figures from the files just written (and the best agent's video); the names of all files."""
    from pamrun.evaluation import figures

    written = ["episodes.jsonl", "leaderboard.csv", "leaderboard.json", "best.pt", "selection.json"]
    if ecfg.save_steps:  # the per-step figures need the per-step data
        figures.trajectories(out / "episodes.jsonl", out / "leaderboard.json", out / "trajectories.png",
                           top_k=ecfg.top_k, lateral_m=ecfg.walk_lateral_m)
        figures.pressures(out / "episodes.jsonl", best.label, 0, out / "pressures.png")
        written += ["trajectories.png", "pressures.png"]
        spec = gait_spec(kwargs[agents.index(best)])
        figures.gait(figures.read_episodes_jsonl(out / "episodes.jsonl", {best.label}), spec.joint_limits_rad,
                   spec.contact_threshold_n, out / "gait.png")
        written.append("gait.png")
    runs = list(dict.fromkeys(a.run_dir for a in agents if a.run_dir and RunFiles(a.run_dir).episodes.exists()))
    for run in runs:
        name = "training.png" if len(runs) == 1 else f"training_{run.name}.png"
        figures.training_curves(RunFiles(run).episodes, out / name)
        written.append(name)
    if ecfg.render:
        video = record_video(best, kwargs[agents.index(best)], ecfg.seed, ecfg.video_width, ecfg.video_height,
                             out / "best_episode.mp4")
        same = abs(video["distance_m"] - results[agents.index(best)][0]["distance_m"]) < 1e-9
        console.print(f"Video: {video['frames']} frames, {video['duration_s']:.2f} s"
                      + ("" if same else " [red](the replay differs from the evaluated episode)[/red]"))
        figures.video_frames(out / "best_episode.mp4", out / "best_episode_frames.png")
        written += ["best_episode.mp4", "best_episode_frames.png"]
    return written


def write_leaderboard(out: Path, ranked: list[dict], errors: list[dict], cfg, spec: str, workers: int,
                      wall_s: float, is_held_out: bool = True) -> None:
    with (out / "leaderboard.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=LEADERBOARD_FIELDS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(ranked)
    ecfg = cfg.eval
    (out / "leaderboard.json").write_text(json.dumps({
        "rank_by": list(ecfg.rank_by), "episodes": ecfg.episodes, "held_out": is_held_out,
        "seeds": list(range(ecfg.seed, ecfg.seed + ecfg.episodes)), "workers": workers, "wall_time_s": round(wall_s, 3),
        "ckpt": spec, "eval": asdict(ecfg), "agents": ranked, "errors": errors}, indent=2))


def leaderboard_table(ranked: list[dict], ecfg, limit: int = 20):
    from rich.table import Table

    table = Table(title=f"Leaderboard ({ecfg.episodes} episodes each, seeds {ecfg.seed}..{ecfg.seed + ecfg.episodes - 1}; "
                        f"ranked by {', '.join(ecfg.rank_by)})")
    for col in ("#", "agent", "walk test (95 % CI)", "distance (m)", "min (m)", "return", "time (s)", "falls",
                "max |y| (m)", "dP (kPa/step)"):
        table.add_column(col, justify="left" if col == "agent" else "right", no_wrap=col != "agent", overflow="fold")
    for row in ranked[:limit]:
        verdict = f"[green]{pass_text(row)}[/green]" if row["walk_test"] else pass_text(row)
        table.add_row(str(row["rank"]), row["agent"], verdict,
                      f"{row['distance_mean']:.2f} ± {row['distance_std']:.2f}", f"{row['distance_min']:.2f}",
                      f"{row['return_mean']:.1f} ± {row['return_std']:.1f}", f"{row['duration_mean']:.2f}",
                      f"{row['fall_rate']:.0%}", f"{row['max_abs_y_max']:.3f}", f"{row['pressure_change_mean']:.1f}")
    if len(ranked) > limit:
        table.caption = f"{len(ranked) - limit} more in leaderboard.csv"
    return table


def gait_table(ranked: list[dict], limit: int = 20):
    """The gait metrics' means (and spreads) per agent (pamrun.evaluation.metrics defines them)."""
    from rich.table import Table

    table = Table(title="Gait (means ± std over episodes; 'hops': touchdowns with both feet together; 'at a stop': "
                        "the joint most often within 2° of a stop, knees only in swing)")
    for col in ("#", "agent", "speed (m/s)", "steps/s", "stride (m)", "symmetry time/length", "hops", "duty",
                "at a stop", "clearance (m)", "slip (m/s)", "CoT", "air (NL/m)"):
        table.add_column(col, justify="left" if col == "agent" else "right", no_wrap=col != "agent", overflow="fold")

    def pm(row: dict, name: str, fmt: str = ".2f") -> str:
        return f"{row[f'{name}_mean']:{fmt}} ± {row[f'{name}_std']:{fmt}}"

    for row in ranked[:limit]:
        table.add_row(str(row["rank"]), row["agent"], pm(row, "speed"), pm(row, "step_frequency_hz"),
                      pm(row, "stride_length_m"),
                      f"{row['step_time_symmetry_mean']:.2f} / {row['step_length_symmetry_mean']:.2f}",
                      f"{row['hop_share_mean']:.0%}", f"{row['duty_factor_mean']:.2f}", f"{row['stop_share_gait_max_mean']:.0%}",
                      pm(row, "swing_clearance_m", ".3f"), pm(row, "foot_slip_m_s"),
                      pm(row, "cost_of_transport"), pm(row, "air_nl_per_m", ".1f"))
    return table
