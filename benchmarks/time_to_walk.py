"""Time to stand and time to walk: ``pamrun train`` on a preset, for several seeds.

    python benchmarks/time_to_walk.py [--preset walk] [--seeds 0 1] [--minutes 120] [-- extra overrides]
    python benchmarks/time_to_walk.py --runs outputs/.../run_a outputs/.../run_b   # read finished runs
    python benchmarks/time_to_walk.py --runs ... --figure curves.png --no-record     # their curves only

Each seed is one ``pamrun train experiment=<preset> seed=<s> train.max_minutes=<minutes>``, one
after the other (a run uses the machine's cores). Its ``evals.csv`` (the evaluations during
training: ``pamrun eval``'s walk test on 10 episodes with 0.01 rad start noise) gives the
wall-clock time and the frames to two milestones:

* **stand**: every evaluation episode lasts the full 10 s (``stand_rate`` = 1);
* **walk**: the walk test passes (10 s, no fall, |y| <= 0.5 m, >= 7 m, in every episode);
* **gait**: the walk test passes and the episodes' means meet every one of the walk's targets
  (``pamrun.evaluation.targets``: a walk, not a run; evals.csv's ``walk_targets_met``).

The sized robot stands passively at zero command, so an untrained actor (whose outputs
start near 0) passes *stand* at the first evaluation. The row therefore also gives
**stand, learned**: the first evaluation after the actor's first update
(``train.actor_start_frames``, ``train.init_random_frames``) in which every episode stands
(``pamrun.task.criteria.stands_learned``: the milestone at which ``train.walk_kvx``'s curriculum
starts walking; the row gives its frames as ``walk_kvx_from_frames``).

The milestones and ``best_*`` come from the seeds the run selects its agents on (biased
upward for the agent they chose). What the row claims about the agent itself comes from
``held_out``: the run's ``best_eval.pt`` under ``pamrun eval``'s defaults, 50 episodes on
the held-out seeds (1000-1049), with the walk-test passes and their 95 % Wilson interval,
and the gait's means (``GAIT``: speed, pressure change, hop share, symmetry, stops, straight
swing knees, swing clearance, slip, air).
``--figure`` draws the runs' evaluations during training against wall-clock minutes.

It prints one row per seed and the median over seeds (a milestone not reached counts as
not reached, never as the budget), and appends one JSON line per seed to
benchmarks/results/time_to_walk.jsonl.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

RESULTS = Path(__file__).parent / "results" / "time_to_walk.jsonl"
# The held-out gait the row records beside the walk test (means over the 50 episodes)
GAIT = ("speed_mean", "pressure_change_mean", "hop_share_mean", "step_time_symmetry_mean",
        "step_length_symmetry_mean", "stop_share_gait_max_mean", "knee_swing_stop_share_mean", "swing_clearance_m_mean",
        "foot_slip_m_s_mean", "air_nl_per_m_mean", "step_frequency_hz_mean", "step_length_m_mean", "duty_factor_mean",
        "double_support_share_mean", "flight_share_mean", "knee_midstance_deg_mean", "knee_swing_peak_deg_mean",
        "cost_of_transport_mean", "walk_targets_met")


def milestones(run: Path) -> dict:
    """Wall time and frames to stand and to walk, and the best evaluation, from a run's files."""
    from pamrun.evaluation.targets import WALK_TARGETS
    from pamrun.runs.directory import RunFiles, read_evals, saved_config
    from pamrun.runs.files import read_json
    from pamrun.task.criteria import actor_learns_from, stands_learned

    rows = read_evals(run)
    info = read_json(RunFiles(run).run_json)
    out = {"run": str(run), "evaluations": len(rows), "status": info.get("status"), "frames": info.get("frames"),
           "wall_time_s": info.get("wall_time_s"), "command": info.get("command"), "git_commit": info.get("git_commit"),
           "walk_kvx_from_frames": info.get("walk_kvx_from_frames")}
    cfg = saved_config(run)
    learning = actor_learns_from(cfg)
    out["actor_learns_from_frames"] = learning
    for name, reached in (("stand", lambda r: float(r["stand_rate"]) >= 1.0),
                          ("stand_learned", lambda r: stands_learned(float(r["stand_rate"]), int(r["frames"]), cfg)),
                          ("walk", lambda r: float(r["walk_pass_rate"]) >= 1.0),
                          ("gait", lambda r: float(r["walk_pass_rate"]) >= 1.0
                           and int(r.get("walk_targets_met") or 0) == len(WALK_TARGETS))):
        first = next((r for r in rows if reached(r)), None)
        out[f"{name}_s"] = float(first["wall_time_s"]) if first else None
        out[f"{name}_frames"] = int(first["frames"]) if first else None
    for key in ("stand_rate", "walk_pass_rate", "distance_mean", "duration_mean"):
        out[f"best_{key}"] = max((float(r[key]) for r in rows), default=None)
    learned = [r for r in rows if int(r["frames"]) > learning]  # the untrained actor stands
    out["best_duration_mean_learned"] = max((float(r["duration_mean"]) for r in learned), default=None)
    out["held_out"] = held_out_evaluation(run)
    return out


def held_out_evaluation(run: Path) -> dict | None:
    """The run's best_eval.pt on pamrun eval's held-out seeds (its defaults), or None."""
    from pamrun.config import Config
    from pamrun.evaluation.agents import load_agents
    from pamrun.evaluation.episodes import aggregate, evaluate_agents
    from pamrun.evaluation.ranking import held_out
    from pamrun.runs.directory import RunFiles
    from pamrun.runs.machine import usable_cores

    best = RunFiles(run).best_eval
    if not best.exists():
        return None
    cfg = Config()
    agents, kwargs, _ = load_agents(str(best), cfg)
    episodes = evaluate_agents(agents, kwargs, cfg.eval.episodes, cfg.eval.seed, usable_cores())[0]
    agg = aggregate(episodes, cfg.eval)
    return {"seeds": [cfg.eval.seed, cfg.eval.seed + cfg.eval.episodes - 1], "held_out": held_out(agents, cfg),
            **{k: agg[k] for k in ("episodes", "walk_passes", "walk_pass_rate", "walk_pass_ci_low",
                                   "walk_pass_ci_high", "stand_rate", "distance_mean", "distance_std", *GAIT)}}


def train(preset: str, seed: int, minutes: float, extra: list[str], root: Path) -> Path:
    run = root / f"{preset}-seed{seed}"
    cmd = [sys.executable, "-m", "pamrun.cli", "train", f"experiment={preset}", f"seed={seed}",
           f"train.max_minutes={minutes}", *extra, f"hydra.run.dir={run}"]
    print("$", " ".join(cmd[2:]), flush=True)
    with (root / f"{preset}-seed{seed}.log").open("w") as log:
        subprocess.run(cmd, stdout=log, stderr=subprocess.STDOUT, check=False)
    return run


def figure(runs: list[Path], png: Path) -> Path:
    """Each run's evaluations during training against wall-clock minutes: the walk-test pass rate
    on its 10 selection episodes, and the mean pressure change per control step."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from pamrun.runs.directory import read_evals

    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    for run in runs:
        rows = read_evals(run)
        minutes = [float(r["wall_time_s"]) / 60 for r in rows]
        top.plot(minutes, [float(r["walk_pass_rate"]) for r in rows], ".-", label=Path(run).name)
        bottom.plot(minutes, [float(r["pressure_change_mean"]) for r in rows], ".-", label=Path(run).name)
    top.set_ylabel("walk-test pass rate\n(10 selection episodes)")
    bottom.set_ylabel("pressure change (kPa/step)")
    bottom.axhline(50, color="k", lw=0.8, ls=":", label="target: 50")
    bottom.set_xlabel("wall-clock minutes")
    top.set_title("Evaluations during training")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    plt.close(fig)
    return png


def fmt(seconds: float | None, frames: int | None) -> str:
    return "not reached" if seconds is None else f"{seconds / 60:6.1f} min, {frames:>8,} frames"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="gait", help="experiment=<preset> (gait: pamrun train's default)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1])
    parser.add_argument("--minutes", type=float, default=120.0, help="wall-clock budget per seed")
    parser.add_argument("--root", type=Path, default=Path("outputs/time_to_walk"))
    parser.add_argument("--runs", type=Path, nargs="+", help="summarise these finished runs instead of training")
    parser.add_argument("--device", default=f"{os.cpu_count()}-core CPU ({platform.machine()})",
                        help="what the runs ran on, for the record")
    parser.add_argument("--note", default="", help="a label stored with each row (e.g. 'recipe search')")
    parser.add_argument("--figure", type=Path, help="draw the runs' evaluation curves into this PNG")
    parser.add_argument("--no-record", action="store_true", help="with --runs and --figure: only the figure")
    parser.add_argument("extra", nargs="*", help="more overrides for pamrun train (after --)")
    args = parser.parse_args()
    if args.runs:
        runs = args.runs
    else:
        args.root.mkdir(parents=True, exist_ok=True)
        runs = [train(args.preset, s, args.minutes, args.extra, args.root) for s in args.seeds]
    if args.figure:
        print(f"wrote {figure(runs, args.figure)}")
        if args.no_record:
            return
    from pamrun.evaluation.targets import WALK_TARGETS

    results = [milestones(r) for r in runs]
    stamp = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "device": args.device, "cpu_count": os.cpu_count(),
             "note": args.note}
    print(f"{'run':<16} {'stand':>28} {'stand, learned':>28} {'walk':>28} {'gait targets':>28} "
          f"{'best_eval.pt, held out':>48} {'frames':>8}")
    for r in results:
        h = r["held_out"]
        agent = "n/a" if h is None else (f"{h['walk_passes']}/{h['episodes']} ({100 * h['walk_pass_ci_low']:.0f}-"
                                         f"{100 * h['walk_pass_ci_high']:.0f} %), {h['distance_mean']:.2f} m, "
                                         f"targets {h['walk_targets_met']}/{len(WALK_TARGETS)}")
        print(f"{Path(r['run']).name:<16} {fmt(r['stand_s'], r['stand_frames']):>28} "
              f"{fmt(r['stand_learned_s'], r['stand_learned_frames']):>28} {fmt(r['walk_s'], r['walk_frames']):>28} "
              f"{fmt(r['gait_s'], r['gait_frames']):>28} {agent:>48} {r['frames'] or 0:>8}")
    for name in ("stand", "stand_learned", "walk", "gait"):
        reached = [r[f"{name}_s"] for r in results if r[f"{name}_s"] is not None]
        median = f"{statistics.median(reached) / 60:.1f} min" if len(reached) == len(results) else "not every seed"
        print(f"{name}: reached by {len(reached)}/{len(results)} seeds; median {median}")
    RESULTS.parent.mkdir(exist_ok=True)
    with RESULTS.open("a") as fh:
        for r in results:
            fh.write(json.dumps({**stamp, **r}) + "\n")


if __name__ == "__main__":
    main()
