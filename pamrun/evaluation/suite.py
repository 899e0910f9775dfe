"""``pamrun eval eval.suite=NAME``: every agent under each perturbation of the suite, on the
same held-out seeds, into robustness.csv/.json, robustness_episodes.jsonl and robustness.png."""

from __future__ import annotations

import csv
import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

from pamrun.evaluation.agents import run_all, start
from pamrun.evaluation.episodes import aggregate
from pamrun.evaluation.ranking import warn_if_not_held_out
from pamrun.evaluation.tables import robustness_table
from pamrun.runs.files import write_json
from pamrun.task.criteria import walk_passed

ROBUSTNESS_FIELDS = ("agent", "perturbation", "note", "episodes", "walk_passes", "walk_pass_rate", "walk_pass_ci_low",
                     "walk_pass_ci_high", "stand_rate", "fall_rate", "physics_error_rate", "distance_mean", "distance_std",
                     "distance_min", "speed_mean", "max_abs_y_max", "pressure_change_mean", "stop_share_max_mean",
                     "foot_slip_m_s_mean", "cost_of_transport_mean", "air_nl_per_m_mean")


def run_suite(cfg, ckpt: str, out: Path, changes: dict | None = None, presets: Sequence[str] = ()) -> list[dict]:
    """``pamrun eval eval.suite=NAME``: every agent under each perturbation of the suite, on the
    same held-out seeds; writes robustness.csv/.json, robustness_episodes.jsonl and
    robustness.png; returns the rows (agent x perturbation). ``changes``, ``presets``: as :func:`start`'s."""
    from pamrun.evaluation import figures  # (as in pamrun.evaluation.results.draw_figures)

    ecfg = cfg.eval
    console, agents, envs, errors = start(cfg, ckpt, out, changes, presets)
    names = list(ecfg.suites[ecfg.suite])
    runs = [(agent, name, env.perturbed(ecfg.perturbations[name], f"eval.perturbations.{name}"))
            for agent, env in zip(agents, envs) for name in names]
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
        "suite": ecfg.suite, "ckpt": ckpt, "episodes": ecfg.episodes, "held_out": is_held_out,
        "seeds": [ecfg.seed, ecfg.seed + ecfg.episodes - 1], "workers": workers, "wall_time_s": round(wall, 3),
        "seconds_per_episode": round(wall / n_episodes, 4),
        "perturbations": {name: asdict(ecfg.perturbations[name]) for name in names},
        "agents": [a.label for a in agents], "rows": rows, "errors": errors})
    figures.robustness(out / "robustness.json", out / "robustness.png")
    console.print(robustness_table(rows, ecfg))
    console.print(f"Evaluated in {wall:.1f} s on {workers} worker(s) ({wall / n_episodes:.3f} s per episode). Wrote "
                  f"robustness.csv, robustness.json, robustness_episodes.jsonl, robustness.png in {out}", soft_wrap=True)
    return rows
