"""The files of ``pamrun eval``: episodes.jsonl, the leaderboard, best.pt with selection.json,
and the figures (and video) drawn from them."""

from __future__ import annotations

import csv
import json
from dataclasses import asdict
from pathlib import Path

from pamrun.evaluation.episodes import aggregate, gait_spec
from pamrun.evaluation.metrics import GAIT_METRICS
from pamrun.evaluation.ranking import rank, selection_reason
from pamrun.evaluation.tracking import TRACKING_METRICS
from pamrun.learning.checkpoints import Agent, save_agent_copy
from pamrun.runs.directory import RunFiles
from pamrun.runs.files import write_json
from pamrun.task.criteria import walk_passed
from pamrun.task.spec import EnvSpec

LEADERBOARD_FIELDS = ("rank", "agent", "episodes", "walk_test", "walk_passes", "walk_pass_rate", "walk_pass_ci_low",
                      "walk_pass_ci_high", "stand_rate", "distance_mean", "distance_std", "distance_min",
                      "return_mean", "return_std", "duration_mean", "duration_std", "fall_rate", "physics_error_rate",
                      "max_abs_y_mean", "max_abs_y_max", "speed_mean", "speed_std", "pressure_change_mean", "pressure_change_std",
                      *(f"{m}_{s}" for m in (*GAIT_METRICS, *TRACKING_METRICS) for s in ("mean", "std")),
                      "train_episode", "train_reward", "path")


def write_results(out: Path, cfg, ckpt: str, agents: list[Agent], results: list[list[dict]], errors: list[dict],
                  workers: int, wall_s: float, is_held_out: bool = True) -> tuple[list[dict], Agent, dict]:
    """episodes.jsonl, the leaderboard, best.pt and selection.json; the ranking, best agent, selection."""
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
    write_leaderboard(out, ranked, errors, cfg, ckpt, workers, wall_s, is_held_out)
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


def write_leaderboard(out: Path, ranked: list[dict], errors: list[dict], cfg, ckpt: str, workers: int,
                      wall_s: float, is_held_out: bool = True) -> None:
    with (out / "leaderboard.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=LEADERBOARD_FIELDS, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(ranked)
    ecfg = cfg.eval
    (out / "leaderboard.json").write_text(json.dumps({
        "rank_by": list(ecfg.rank_by), "episodes": ecfg.episodes, "held_out": is_held_out,
        "seeds": list(range(ecfg.seed, ecfg.seed + ecfg.episodes)), "workers": workers, "wall_time_s": round(wall_s, 3),
        "ckpt": ckpt, "eval": asdict(ecfg), "agents": ranked, "errors": errors}, indent=2))


def draw_figures(out: Path, ecfg, agents: list[Agent], envs: list[EnvSpec], results: list[list[dict]], best: Agent,
                 console) -> list[str]:
    """Figures from the files just written (and the best agent's video); the names of all files."""
    # matplotlib and PyAV are imported where figures are drawn: pamrun eval imports this module
    # before it checks its config, and a config error need not wait for them (about a second).
    from pamrun.evaluation import figures
    from pamrun.evaluation.video import record_video, write_gif

    written = ["episodes.jsonl", "leaderboard.csv", "leaderboard.json", "best.pt", "selection.json"]
    if ecfg.save_steps:  # the per-step figures need the per-step data
        figures.trajectories(out / "episodes.jsonl", out / "leaderboard.json", out / "trajectories.png",
                           top_k=ecfg.top_k, lateral_m=ecfg.walk_lateral_m)
        figures.pressures(out / "episodes.jsonl", best.label, 0, out / "pressures.png")
        written += ["trajectories.png", "pressures.png"]
        gait = gait_spec(envs[agents.index(best)])
        figures.gait(figures.read_episodes_jsonl(out / "episodes.jsonl", {best.label}), gait.joint_limits_rad,
                   gait.contact_threshold_n, out / "gait.png")
        written.append("gait.png")
        best_env = envs[agents.index(best)].env
        if best_env.speed_command or best_env.speed_schedule:  # a commanded speed to follow
            figures.speed(figures.read_episodes_jsonl(out / "episodes.jsonl", {best.label}), out / "speed.png")
            written.append("speed.png")
    runs = list(dict.fromkeys(a.run_dir for a in agents if a.run_dir and RunFiles(a.run_dir).episodes.exists()))
    for run in runs:
        name = "training.png" if len(runs) == 1 else f"training_{run.name}.png"
        figures.training_curves(RunFiles(run).episodes, out / name)
        written.append(name)
    if ecfg.render:
        video = record_video(best, envs[agents.index(best)], ecfg.seed, ecfg.video_width, ecfg.video_height,
                             out / "best_episode.mp4", ecfg.camera)
        same = abs(video["distance_m"] - results[agents.index(best)][0]["distance_m"]) < 1e-9
        console.print(f"Video: {video['frames']} frames, {video['duration_s']:.2f} s"
                      + ("" if same else " [red](the replay differs from the evaluated episode)[/red]"))
        # the following camera keeps the robot mid-picture: the strip shows the middle of each frame;
        # the fixed one sees it only near its start: strip and GIF show the episode's first frames
        from_start = ecfg.camera == "fixed"
        figures.video_frames(out / "best_episode.mp4", out / "best_episode_frames.png",
                             width_share=0.6 if ecfg.camera == "follow" else 1.0, from_start=from_start)
        write_gif(out / "best_episode.mp4", out / "best_episode.gif", from_start=from_start)
        written += ["best_episode.mp4", "best_episode_frames.png", "best_episode.gif"]
    return written
