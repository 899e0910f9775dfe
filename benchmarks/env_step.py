"""Environment steps per second vs bare MuJoCo stepping of the same model.

    python benchmarks/env_step.py [--seconds 5] [--presets sized thesis]

Prints, per muscle preset, control steps/s of PamWalker-v0 with random actions and, in the same run, the
rate of bare ``mj_step`` on the same model with the same number of physics substeps
per control step and no muscle computation; their ratio is the muscle model's cost.
Results are appended to benchmarks/results/env_step.jsonl.
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import mujoco
import numpy as np

from pamrun.config import preset
from pamrun.env import PamWalkerEnv


def env_rate(env: PamWalkerEnv, seconds: float, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, (1000, env.n_actions)).astype(np.float32)
    env.reset(seed=seed)
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        _, _, terminated, truncated, _ = env.step(actions[steps % 1000])
        steps += 1
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def bare_rate(env: PamWalkerEnv, seconds: float) -> float:
    """Control steps/s of bare MuJoCo: n_substeps mj_step calls, constant ctrl, no muscles."""
    m, d = env.model, mujoco.MjData(env.model)
    d.qpos[:] = env._qpos0
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        mujoco.mj_step(m, d, env.n_substeps)
        steps += 1
        if steps % 400 == 0:
            mujoco.mj_resetData(m, d)
            d.qpos[:] = env._qpos0
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--presets", nargs="+", default=["sized", "thesis"])
    args = parser.parse_args()
    results = []
    for name in args.presets:
        env = PamWalkerEnv(muscle=preset("muscle", name))
        coupling = f"{name} ({env.muscle_cfg.coupling})"
        rate_env = env_rate(env, args.seconds)
        rate_bare = bare_rate(env, args.seconds)
        row = {
            "preset": name,
            "coupling": env.muscle_cfg.coupling,
            "physics_dt_s": env.model.opt.timestep,
            "substeps": env.n_substeps,
            "env_steps_per_s": round(rate_env, 1),
            "bare_steps_per_s": round(rate_bare, 1),
            "ratio": round(rate_env / rate_bare, 3),
        }
        results.append(row)
        print(
            f"{coupling:>18}: env {rate_env:8.1f} control steps/s | bare MuJoCo {rate_bare:8.1f} "
            f"({env.n_substeps} x {env.model.opt.timestep * 1000:.1f} ms) | ratio {rate_env / rate_bare:.2f}"
        )
        env.close()
    out = Path(__file__).parent / "results" / "env_step.jsonl"
    out.parent.mkdir(exist_ok=True)
    stamp = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": platform.node(), "cpu_count": __import__("os").cpu_count()}
    with out.open("a") as fh:
        for row in results:
            fh.write(json.dumps({**stamp, **row}) + "\n")


if __name__ == "__main__":
    main()
