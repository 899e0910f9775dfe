"""How long the robot stays up with zero action, in each muscle coupling.

    python benchmarks/standing.py [--episodes 5]

Zero action holds every pair at V0 = 2.12 V (212 kPa in both muscles). Prints, per
coupling, the time until termination (fall) or the full 10 s, with the cause, over a few
seeds with small reset noise; results go to benchmarks/results/standing.jsonl.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from pamrun.env import PamWalkerEnv


def stand(coupling: str, seed: int, noise_rad: float) -> dict:
    env = PamWalkerEnv(muscle={"coupling": coupling}, env={"reset_noise_rad": noise_rad})
    env.reset(seed=seed)
    zero = np.zeros(10, dtype=np.float32)
    for step in range(1, env.max_steps + 1):
        _, _, terminated, truncated, info = env.step(zero)
        if terminated or truncated:
            break
    u = env
    pos = u.data.qpos
    cause = "stood 10 s" if truncated else (
        "physics error" if info["physics_error"] else
        "torso too low" if pos[2] < u.env_cfg.fall_height_ratio * u.z0 else
        "|y| > 0.5 m" if abs(pos[1]) > u.env_cfg.max_lateral_m else "tilt >= 45 deg"
    )
    return {"coupling": coupling, "seed": seed, "reset_noise_rad": noise_rad,
            "time_up_s": round(step * u.env_cfg.control_dt_s, 3), "cause": cause}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=5)
    args = parser.parse_args()
    rows = []
    for coupling in ("thesis", "kinematic"):
        runs = [stand(coupling, 0, 0.0)] + [stand(coupling, s, 0.02) for s in range(1, args.episodes)]
        rows += runs
        times = [r["time_up_s"] for r in runs]
        causes = sorted({r["cause"] for r in runs})
        print(f"{coupling:>9}: time up {times} s (nominal pose first, then 0.02 rad noise); {', '.join(causes)}")
    out = Path(__file__).parent / "results" / "standing.jsonl"
    out.parent.mkdir(exist_ok=True)
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
    with out.open("a") as fh:
        for r in rows:
            fh.write(json.dumps({"time": stamp, **r}) + "\n")


if __name__ == "__main__":
    main()
