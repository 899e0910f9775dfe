"""Cost of ``pamrun eval eval.suite=robustness``: seconds per agent x perturbation x episode.

    python benchmarks/robustness_cost.py [--ckpt agents/walker_td3_seed0.pt] [--episodes 50] [--workers 2] [--out DIR]

Runs the suite (every perturbation of ``eval.suites.robustness``) through
``pamrun.evaluation.evaluate.run_suite`` and, in the same process as the baseline, the plain
evaluation of the same agents (``run_evaluation``, the nominal episodes with per-step
data and figures) on the same seeds. Prints and appends to
benchmarks/results/robustness_cost.jsonl: wall time, episodes, seconds per episode of
each, and their ratio (suite / plain per episode). Per-episode cost depends on how long
the agent stays up: a fall ends an episode early.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

from hydra import compose, initialize_config_dir

from pamrun.config import CONF_DIR, register_configs, to_object
from pamrun.evaluation.evaluate import run_evaluation, run_suite
from pamrun.runs import machine  # noqa: F401  (the resolvers conf/ uses)

RESULTS = Path(__file__).parent / "results" / "robustness_cost.jsonl"
ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ckpt", default=str(ROOT / "agents" / "walker_td3_seed0.pt"))
    parser.add_argument("--episodes", type=int, default=50)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", type=Path, help="keep both evaluations' files here (default: a temporary folder)")
    args = parser.parse_args()
    register_configs()
    overrides = [f"eval.episodes={args.episodes}", f"eval.workers={args.workers}"]
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = to_object(compose("config", overrides=[*overrides, "eval.suite=robustness"]))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = args.out or tmp
        start = time.perf_counter()
        run_evaluation(cfg, args.ckpt, Path(tmp) / "plain")
        plain_s = time.perf_counter() - start
        plain_episodes = len((Path(tmp) / "plain" / "episodes.jsonl").read_text().splitlines())
        start = time.perf_counter()
        rows = run_suite(cfg, args.ckpt, Path(tmp) / "suite")
        suite_s = time.perf_counter() - start
    suite_episodes = len(rows) * args.episodes
    result = {
        "time": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": platform.node(), "cpu_count": os.cpu_count(),
        "processor": platform.processor() or platform.machine(), "ckpt": args.ckpt, "workers": args.workers,
        "episodes_per_cell": args.episodes, "perturbations": len(rows) // max(1, len({r["agent"] for r in rows})),
        "agents": len({r["agent"] for r in rows}),
        "suite_wall_s": round(suite_s, 2), "suite_episodes": suite_episodes,
        "suite_s_per_episode": round(suite_s / suite_episodes, 4),
        "plain_wall_s": round(plain_s, 2), "plain_episodes": plain_episodes,
        "plain_s_per_episode": round(plain_s / plain_episodes, 4),
        "ratio_suite_to_plain_per_episode": round((suite_s / suite_episodes) / (plain_s / plain_episodes), 3),
        "walk_pass_rate": {r["perturbation"]: r["walk_pass_rate"] for r in rows},
    }
    print(json.dumps(result, indent=2))
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    with RESULTS.open("a") as fh:
        fh.write(json.dumps(result) + "\n")


if __name__ == "__main__":
    main()
