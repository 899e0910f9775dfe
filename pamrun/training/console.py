"""What ``pamrun train`` prints: the header table, the summary table, and how a run that did
not finish its budget says so (the next command, and its exit code)."""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path

import numpy as np
from rich.table import Table

from pamrun.config import Config
from pamrun.evaluation import figures
from pamrun.learning import checkpoints
from pamrun.runs.directory import RunFiles

# Exit codes of a run stopped by a signal (after its final checkpoint), as a shell reports them.
STOPPED_EXIT = {"interrupted": 130, "terminated": 143}


def header_table(cfg: Config, out: Path):
    table = Table(title="pamrun train", show_header=False)
    a, t = cfg.algo, cfg.train
    for key, value in (
        ("algorithm", f"{a.name}: actor lr {a.actor_lr:g}, critic lr {a.critic_lr:g}, batch {a.batch_size}, "
                      f"gamma {a.gamma}, tau {a.target_smoothing:g}, "
                      + (f"initial alpha {a.init_alpha:g}" if a.name == "sac" else f"noise var {a.noise_variance:g}")),
        ("robot", f"H {cfg.body.height_m} m, M {cfg.body.mass_kg} kg, coupling {cfg.muscle.coupling}"),
        ("reward", ", ".join(f"{k} {w:g}" for k, w in asdict(cfg.reward).items())  # every weight
                   + (f"; kvx {t.walk_kvx:g} once it stands (train.walk_kvx)" if t.walk_kvx is not None else "")
                   + "".join(f"; {k} {w:g} once it stands" for k, w in t.walk_weights.items())
                   + "".join(f"; {k} {w:g} once every episode "
                             + ("walks" if t.gait_from_distance_m is None else f"stands and covers {t.gait_from_distance_m:g} m")
                             for k, w in t.gait_weights.items())),
        ("randomised", (f"{t.randomize_prob:.0%} of episodes, {t.randomize_count} of: "
                        + ", ".join(n + (f" x{t.randomize_weights[n]:g}" if n in t.randomize_weights else "")
                                    + (f" to {t.randomize_reaches[n]:g}" if n in t.randomize_reaches else "")
                                    for n in t.randomize)
                        + f" (strength 0-{t.randomize_reach:g})"
                        if t.randomize else "no")),
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


def summary_table(run_info: dict, log, saved: list, out: Path):
    table = Table(title=f"Training finished: {run_info['status']}", show_header=False)
    files = RunFiles(out)
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
        ("episodes", str(files.episodes)),
        ("curves", str(files.training_png) + (f", {files.evals_png.name}" if files.evals.exists() else "")),
        ("checkpoints", str(files.checkpoints)),
        ("TensorBoard", f"tensorboard --logdir {files.tensorboard}"),
    ]
    for key, value in rows:
        table.add_row(key, value)
    return table


def best_eval_text(out: Path) -> str:
    path = RunFiles(out).best_eval
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


def end_of_run(console, out: Path, status: str | None, failure: Exception | None, log) -> None:
    """How a run that did not finish its budget says so: the next command, and its exit code."""
    if status in STOPPED_EXIT:
        console.print(f"Stopped ({status}) with a final checkpoint. Continue with: pamrun train resume={out}",
                      soft_wrap=True)
        raise SystemExit(STOPPED_EXIT[status])
    if failure is not None:
        again = f"pamrun train resume={out}" if RunFiles(out).last.exists() else \
            "the same command (no checkpoint yet: it starts clean)"
        raise SystemExit(f"pamrun: training stopped: {failure}. Then continue with: {again}")
    if status == "physics_unstable":
        console.print(f"[red]Stopped: the physics blew up in {sum(log.flagged[-100:])} of the last "
                      f"{len(log.flagged[-100:])} episodes.[/red] The robot is unstable in MuJoCo at this setting: "
                      "check body.mass_kg and body.height_m, the muscles' strength (muscle.size, muscle.count, "
                      "muscle.max_pressure_kpa) against them, and env.physics_dt_s.")
        raise SystemExit(1)


def plot_training(dcfg) -> None:
    """``pamrun plot training dir=<run dir>``: redraw training.png from episodes.csv."""
    files = RunFiles(dcfg.dir)
    if not files.episodes.exists():
        raise SystemExit(f"pamrun: no episodes.csv in {files.out}")
    print(f"Wrote {figures.training_curves(files.episodes, files.training_png)}")
