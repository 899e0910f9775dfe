"""How long the robot stands with zero action, for each muscle preset.

    python benchmarks/standing.py [--seeds 10] [--presets sized thesis]

Zero action holds every pair at V0 (``muscle=sized``: 300 kPa in both muscles, a fixed
co-contraction; ``muscle=thesis``: 212 kPa). Per preset: one episode from the nominal
pose, then ``--seeds`` episodes with 0.02 rad uniform reset noise on every joint. Prints
the time up (10 s = the full episode) and the cause of each fall; appends every episode
to benchmarks/results/standing.jsonl.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from pamrun.config import preset
from pamrun.task.env import PamWalkerEnv


def stand(muscle: dict, seed: int, noise_rad: float) -> dict:
    env = PamWalkerEnv(muscle=muscle, env={"reset_noise_rad": noise_rad})
    env.reset(seed=seed)
    zero = np.zeros(env.n_actions, dtype=np.float32)
    for step in range(1, env.max_steps + 1):
        _, _, terminated, truncated, info = env.step(zero)
        if terminated or truncated:
            break
    pos, cfg = env.data.qpos, env.env_cfg
    cause = "stood 10 s" if truncated else (
        "physics error" if info["physics_error"] else
        "torso too low" if pos[2] < cfg.fall_height_ratio * env.z0 else
        "|y| > 0.5 m" if abs(pos[1]) > cfg.max_lateral_m else "tilt >= 45 deg"
    )
    return {"seed": seed, "reset_noise_rad": noise_rad, "time_up_s": round(step * cfg.control_dt_s, 3),
            "cause": cause, "final_x_m": round(float(pos[0]), 4)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--presets", nargs="+", default=["sized", "thesis"])
    args = parser.parse_args()
    out = Path(__file__).parent / "results" / "standing.jsonl"
    out.parent.mkdir(exist_ok=True)
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
    for name in args.presets:
        muscle = preset("muscle", name)
        runs = [stand(muscle, 0, 0.0)] + [stand(muscle, s, 0.02) for s in range(1, args.seeds + 1)]
        noisy = [r["time_up_s"] for r in runs[1:]]
        causes = sorted({r["cause"] for r in runs})
        print(f"muscle={name:<7} nominal pose {runs[0]['time_up_s']:5.2f} s | 0.02 rad noise, {len(noisy)} seeds: "
              f"min {min(noisy):.2f} s, median {np.median(noisy):.2f} s, {sum(t >= 10 for t in noisy)}/{len(noisy)} "
              f"stand 10 s | {', '.join(causes)}")
        with out.open("a") as fh:
            for r in runs:
                fh.write(json.dumps({"time": stamp, "preset": name, **r}) + "\n")


if __name__ == "__main__":
    main()
