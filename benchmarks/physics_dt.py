"""Accuracy against speed of the MuJoCo time step (evidence for env.physics_dt_s).

    python benchmarks/physics_dt.py

Runs the same seeded episode (small random actions) at physics steps of 0.5, 1, 2.5 and
5 ms in each coupling and prints, per step size, the steps until the robot falls, the
largest torso-height difference from the 0.5 ms run over the first second, and the speed.
Results are appended to benchmarks/results/physics_dt.jsonl.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from pamrun.task.env import PamWalkerEnv


def episode(coupling: str, dt: float) -> tuple[np.ndarray, float]:
    env = PamWalkerEnv(muscle={"coupling": coupling}, env={"physics_dt_s": dt})
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    heights, start = [], time.perf_counter()
    for _ in range(env.max_steps):
        obs, _, terminated, truncated, _ = env.step((0.3 * rng.uniform(-1, 1, 10)).astype(np.float32))
        heights.append(obs[1])
        if terminated or truncated:
            break
    return np.array(heights), len(heights) / (time.perf_counter() - start)


def main() -> None:
    rows = []
    for coupling in ("thesis", "kinematic"):
        ref = None
        for dt in (0.0005, 0.001, 0.0025, 0.005):
            z, rate = episode(coupling, dt)
            ref = z if ref is None else ref
            n = min(len(ref), len(z), 40)
            row = {"coupling": coupling, "physics_dt_ms": dt * 1000, "steps_before_fall": len(z),
                   "max_dz_vs_0.5ms_mm": round(float(np.max(np.abs(z[:n] - ref[:n]))) * 1000, 2),
                   "control_steps_per_s": round(rate)}
            rows.append(row)
            print(row)
    out = Path(__file__).parent / "results" / "physics_dt.jsonl"
    out.parent.mkdir(exist_ok=True)
    with out.open("a") as fh:
        for row in rows:
            fh.write(json.dumps({"time": time.strftime("%Y-%m-%dT%H:%M:%S"), **row}) + "\n")


if __name__ == "__main__":
    main()
