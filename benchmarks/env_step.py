"""Environment steps per second vs bare MuJoCo stepping of the same model.

    python benchmarks/env_step.py [--seconds 5] [--repeats 5] [--presets sized thesis] [--models] [--clock] [--terms]
                                  [--terrain] [--lean-info] [--timer cpu]

Prints, per muscle preset, control steps/s of PamWalker-v0 with random actions and, in the same run, the
rate of bare ``mj_step`` on the same model with the same number of physics substeps
per control step and no muscle computation; their ratio is the muscle model's (and the
env's Python's) cost. The sized preset (kinematic coupling) is measured with both
``muscle.kernel=numba`` (the compiled muscle step, compiled or loaded from its cache before
timing) and ``numpy`` (the reference); the thesis coupling always uses numpy. ``--models``
measures the sized preset instead with each pneumatic model beyond the thesis' (``MODELS``:
the flow-limited valve, hysteresis, the Tondu-Lopez law, the toe) against today's, both
kernels, in the same run; ``--clock`` the sized preset with the gait clock and every kgait
demand on (``CLOCK``) against today's; ``--terms`` the sized preset (numba) with that clock and
every reward term computed, as training computes them (``ALL_TERMS``), against the clock with only
its weighted terms; ``--terrain`` the sized preset (numba) on each of the
robustness suite's terrains (``TERRAINS``, begun 0.3 m ahead, so that the robot, falling under
random actions, lands on them) against the flat floor.

Each measurement is repeated ``--repeats`` times, env and bare alternating so that a change
of machine load hits both; the median and the range (min-max) of the env rate, the bare
rate and their ratio (per env/bare pair) are printed and appended to
benchmarks/results/env_step.jsonl. ``--timer cpu`` times by this thread's CPU time instead of the
wall clock: on a machine shared with other work, a wall-clock rate counts the time others ran.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import mujoco
import numpy as np

from pamrun.config import MuscleConfig, preset
from pamrun.config.experiments import terrain_perturbations
from pamrun.task.env import PamWalkerEnv
from pamrun.task.reward import REWARD_KEYS

CLOCKS = {"wall": time.perf_counter, "cpu": time.thread_time}
clock = CLOCKS["wall"]  # main() sets --timer's


def env_rate(env: PamWalkerEnv, seconds: float, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1, 1, (1000, env.n_actions)).astype(np.float32)
    env.reset(seed=seed)
    steps, start = 0, clock()
    while clock() - start < seconds:
        _, _, terminated, truncated, _ = env.step(actions[steps % 1000])
        steps += 1
        if terminated or truncated:
            env.reset()
    return steps / (clock() - start)


def bare_rate(env: PamWalkerEnv, seconds: float) -> float:
    """Control steps/s of bare MuJoCo: n_substeps mj_step calls, constant ctrl, no muscles."""
    m, d = env.model, mujoco.MjData(env.model)
    d.qpos[:] = env._qpos0
    steps, start = 0, clock()
    while clock() - start < seconds:
        mujoco.mj_step(m, d, env.n_substeps)
        steps += 1
        if steps % 400 == 0:
            mujoco.mj_resetData(m, d)
            d.qpos[:] = env._qpos0
    return steps / (clock() - start)


def warm_up(env: PamWalkerEnv) -> float:
    """A few steps before timing (the numba kernel is compiled or loaded on its first call);
    returns their seconds."""
    start = time.perf_counter()
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.zeros(env.n_actions, dtype=np.float32))
    return time.perf_counter() - start


# The pneumatic models (the same as eval.suite=models), as env keyword-argument overrides.
MODELS = {
    "valve_flow": {"muscle": {"regulator": {"model": "flow"}}},
    "hysteresis": {"muscle": {"spring": {"hysteresis": "maxwell_slip"}}},
    "force_law": {"muscle": {"force_law": "tondu_lopez"}},
    "toe": {"body": {"toe": True}},
}
# The gait clock with every kgait demand on (experiment=walker's period and swing knee, a stance knee),
# the env's reward path the clock adds: --clock measures it against today's in the same run
CLOCK = {"env": {"gait_period_s": 0.8, "swing_clearance_m": 0.05, "swing_knee_deg": 20.0, "stance_knee_deg": 30.0}}

# Every reward term computed at any weight (training's env: pamrun.training.recipe.make_env), with the clock
ALL_TERMS = {**CLOCK, "features": REWARD_KEYS}

# The robustness suite's terrains (eval.perturbations), begun as near the start as the env allows
TERRAINS = {name: {"env": {**p.values["env"], "terrain_x_m": 0.3}} for name, p in terrain_perturbations().items()}


def merged(base: dict, over: dict) -> dict:
    return {k: merged(base.get(k, {}), v) if isinstance(v, dict) else v for k, v in over.items()} | {
        k: v for k, v in base.items() if k not in over}


def spread(values: list[float]) -> tuple[float, float, float]:
    return min(values), statistics.median(values), max(values)


def measure(name: str, kernel: str, seconds: float, repeats: int, model: str = "", lean_info: bool = False) -> dict:
    kwargs = merged({"muscle": {**preset("muscle", name), "kernel": kernel}}, {**MODELS, "clock": CLOCK, "all_terms": ALL_TERMS, **TERRAINS}.get(model, {}))
    env = PamWalkerEnv(**kwargs, lean_info=lean_info)
    used = "numba" if env.drive.compiled else "numpy"  # the thesis coupling is numpy only
    ready_s = warm_up(env)
    rates_env, rates_bare, ratios = [], [], []
    for _ in range(repeats):  # alternating, so that load drift hits both
        rates_env.append(env_rate(env, seconds))
        rates_bare.append(bare_rate(env, seconds))
        ratios.append(rates_env[-1] / rates_bare[-1])
    env.close()
    (e_lo, e_med, e_hi), (b_lo, b_med, b_hi) = spread(rates_env), spread(rates_bare)
    r_lo, r_med, r_hi = spread(ratios)
    label = f"{name}{' + ' + model if model else ''} ({env.muscle_cfg.coupling}, {used}{', lean info' * lean_info})"
    print(f"{label:>40}: env {e_med:7.1f} [{e_lo:7.1f}-{e_hi:7.1f}] control steps/s | bare MuJoCo {b_med:7.1f} "
          f"[{b_lo:7.1f}-{b_hi:7.1f}] ({env.n_substeps} x {env.model.opt.timestep * 1000:.1f} ms) | "
          f"ratio {r_med:.3f} [{r_lo:.3f}-{r_hi:.3f}]  (warm-up {ready_s:.2f} s)")
    return {
        "preset": name,
        "model": model or "today",
        "info": "lean" if lean_info else "full",
        "coupling": env.muscle_cfg.coupling,
        "kernel": used,
        "physics_dt_s": env.model.opt.timestep,
        "substeps": env.n_substeps,
        "seconds": seconds,
        "repeats": repeats,
        "env_steps_per_s": round(e_med, 1),  # medians; the spread below
        "bare_steps_per_s": round(b_med, 1),
        "ratio": round(r_med, 3),
        "env_steps_per_s_range": [round(e_lo, 1), round(e_hi, 1)],
        "bare_steps_per_s_range": [round(b_lo, 1), round(b_hi, 1)],
        "ratio_range": [round(r_lo, 3), round(r_hi, 3)],
        "warm_up_s": round(ready_s, 3),
        "timer": next(name for name, fn in CLOCKS.items() if fn is clock),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=5.0, help="length of one measurement")
    parser.add_argument("--repeats", type=int, default=5, help="measurements per rate (env and bare alternating)")
    parser.add_argument("--presets", nargs="+", default=["sized", "thesis"])
    parser.add_argument("--models", action="store_true", help="the sized preset with each pneumatic model")
    parser.add_argument("--clock", action="store_true", help="the sized preset with the gait clock and its demands")
    parser.add_argument("--terms", action="store_true",
                        help="the sized preset (numba) with the clock, every reward term against the weighted ones")
    parser.add_argument("--terrain", action="store_true", help="the sized preset (numba) on each terrain")
    parser.add_argument("--lean-info", action="store_true",
                        help="the env as training builds it: info holds only what training reads (lean_info=True)")
    parser.add_argument("--timer", choices=CLOCKS, default="wall",
                        help="wall clock, or this thread's CPU time (on a machine shared with other work)")
    args = parser.parse_args()
    global clock
    clock = CLOCKS[args.timer]
    print(f"median [min-max] of {args.repeats} x {args.seconds:g} s each")
    results = []
    for model in ("", *MODELS) if args.models else ("", "clock") if args.clock else ():
        for kernel in ("numba", "numpy"):
            results.append(measure("sized", kernel, args.seconds, args.repeats, model, args.lean_info))
    for model in ("clock", "all_terms") if args.terms else ():
        results.append(measure("sized", "numba", args.seconds, args.repeats, model, args.lean_info))
    for model in ("", *TERRAINS) if args.terrain else ():
        results.append(measure("sized", "numba", args.seconds, args.repeats, model, args.lean_info))
    for name in () if args.models or args.clock or args.terms or args.terrain else args.presets:
        coupling = preset("muscle", name).get("coupling", MuscleConfig().coupling)
        for kernel in (("numba", "numpy") if coupling == "kinematic" else ("numpy",)):
            results.append(measure(name, kernel, args.seconds, args.repeats, lean_info=args.lean_info))
    out = Path(__file__).parent / "results" / "env_step.jsonl"
    out.parent.mkdir(exist_ok=True)
    stamp = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": platform.node(), "cpu_count": os.cpu_count()}
    with out.open("a") as fh:
        for row in results:
            fh.write(json.dumps({**stamp, **row}) + "\n")


if __name__ == "__main__":
    main()
