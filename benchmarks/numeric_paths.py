"""The shipped agent's walk test on several numeric paths: the margins of tests/test_shipped_agent.py.

    python benchmarks/numeric_paths.py [--ckpt agents/walker_td3_seed0.pt] [--episodes 50]

A chaotic gait turns last-bit differences (another CPU, another muscle kernel) into other
episodes. This runs the agent's held-out episodes on each numeric path pamrun has (muscle
kernel numba or numpy x 1 or 2 evaluation workers) on two seed blocks (1000.., 2000..), and
prints and appends to benchmarks/results/shipped_agent_paths.jsonl: walk-test passes with
their 95 % Wilson interval, stand rate, median distance, and which episodes passed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from pamrun.config import Config, Perturbation
from pamrun.evaluation.episodes import aggregate, evaluate_agents
from pamrun.evaluation.evaluate import load_agents
from pamrun.task.criteria import walk_passed
from pamrun.task.spec import perturb

RESULTS = Path(__file__).parent / "results" / "shipped_agent_paths.jsonl"
ROOT = Path(__file__).resolve().parents[1]
PATHS = (("numba", 1, 1000), ("numba", 2, 1000), ("numpy", 1, 1000), ("numpy", 2, 1000), ("numba", 2, 2000),
         ("numpy", 2, 2000))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ckpt", default=str(ROOT / "agents" / "walker_td3_seed0.pt"))
    parser.add_argument("--episodes", type=int, default=50)
    args = parser.parse_args()
    cfg = Config()
    agents, kwargs, errors = load_agents(args.ckpt, cfg)
    assert not errors, errors
    stamp = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": platform.node(), "cpu_count": os.cpu_count(),
             "processor": platform.processor() or platform.machine(), "ckpt": args.ckpt, "episodes": args.episodes}
    with RESULTS.open("a") as fh:
        for kernel, workers, seed in PATHS:
            kw = perturb(kwargs[0], Perturbation(values={"muscle": {"kernel": kernel}}), "kernel")
            start = time.perf_counter()
            episodes = evaluate_agents(agents, [kw], args.episodes, seed, workers)[0]
            agg = aggregate(episodes, cfg.eval)
            row = {**stamp, "kernel": kernel, "workers": workers, "seed": seed,
                   "wall_s": round(time.perf_counter() - start, 2),
                   **{k: agg[k] for k in ("walk_passes", "walk_pass_ci_low", "walk_pass_ci_high", "stand_rate")},
                   "distance_median": float(np.median([e["distance_m"] for e in episodes])),
                   "passed": "".join("1" if walk_passed(e, cfg.eval) else "0" for e in episodes)}
            print(f"seeds {seed}.. {kernel:5} {workers} worker(s): {row['walk_passes']}/{args.episodes} "
                  f"({100 * row['walk_pass_ci_low']:.0f}-{100 * row['walk_pass_ci_high']:.0f} %), stand "
                  f"{row['stand_rate']:.0%}, median {row['distance_median']:.2f} m  {row['passed']}", flush=True)
            fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
