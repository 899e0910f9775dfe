"""Episodes of saved agents: the agent's env, perturbed or not, one deterministic episode
with its per-step data and metrics, many episodes over worker processes, and what they add
up to (the walk and stand tests, the pass count with its 95 % Wilson interval, means and
spreads). Used by ``pamrun eval`` (:mod:`pamrun.evaluation.evaluate`) and by ``pamrun train``'s
evaluations (:mod:`pamrun.evaluation.evaluator`).

An episode's walk and stand tests are :mod:`pamrun.task.criteria`'s. Its gait and air metrics are :mod:`pamrun.evaluation.metrics`'s.
"""

from __future__ import annotations

import contextlib
import json
import math
import multiprocessing
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any, Callable

import numpy as np

from pamrun.evaluation.metrics import GAIT_METRICS, GaitSpec, episode_metrics
from pamrun.evaluation.targets import targets_met
from pamrun.evaluation.tracking import TRACKING_METRICS, tracking_metrics
from pamrun.learning.checkpoints import Agent
from pamrun.physics.body import build_model
from pamrun.task import clock
from pamrun.task.criteria import stood, walk_passed
from pamrun.task.spec import EnvSpec, eval_env_options

# --------------------------------------------------------------------------- the agent's env


def make_policy(agent: Agent):
    """The agent's actor as a function observation -> action (no exploration noise)."""
    # torch and TorchRL (pamrun.learning.networks) are imported where a policy runs: pamrun eval
    # imports this module before it checks its config, and a config error need not wait seconds for them.
    import torch

    from pamrun.learning import networks as agents_mod
    net = agents_mod.ThesisActor(agent.obs_size, agent.action_size, tuple(agent.hidden_sizes), init_scale=1e-3)
    net.load_state_dict(agent.actor_state)
    net.eval()

    def policy(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return net(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0].numpy()

    return policy


def agent_env(agent: Agent, cfg, changes: dict | None = None) -> EnvSpec:
    """The env ``agent`` is evaluated in: its own robot and task (with ``eval.use_agent_env``;
    a section it did not store, or all without, the command line's) with ``changes`` (section ->
    key -> value: the keys set on ``pamrun eval``'s command line), then the evaluation's start
    noise, episode length and held commanded speed. Validated here."""
    own = agent.config if cfg.eval.use_agent_env else None
    values = {name: dict(keys) for name, keys in (changes or {}).items()}
    values["env"] = {**values.get("env", {}), **eval_env_options(cfg.eval)}
    return EnvSpec.from_dict(own, base=EnvSpec.from_config(cfg), **values)


# What run_episode records per control step (pamrun.evaluation.metrics reads them): torso position and
# roll, pitch, yaw, joint
# angles, velocities and muscle torques (10), pressures and contractions of the 20 muscles, the
# feet's normal forces (2) and contact spheres' positions (2, 4, 3), the action, the commanded
# speed v*, and each foot's gait clock past its touchdown (2; pamrun.evaluation.tracking reads these two).
STEP_KEYS = ("x_m", "y_m", "z_m", "torso_rpy_rad", "joint_angle_rad", "joint_velocity_rad_s", "joint_torque_nm", "pressure_kpa",
             "contraction_pct", "foot_force_n", "sole_xyz_m", "action", "target_speed_m_s", "clock_touchdown_offset")


def clock_touchdown_offsets(env) -> list[float]:
    """Each foot's gait clock past its touchdown now, right and left, as a share of the period
    (:func:`pamrun.task.clock.touchdown_offset`, as ``ktouch`` reads it); NaN without a clock or while it
    stands still."""
    if not env.gait_clock or env.episode.clock_stopped:
        return [math.nan, math.nan]
    phase = env.gait_phase()
    return [clock.touchdown_offset(phase, foot, env.env_cfg.swing_share) for foot in (0, 1)]


def gait_spec(spec: EnvSpec) -> GaitSpec:
    """The gait metrics' view of the robot ``spec`` builds: its mass from the compiled body, no env."""
    mass_kg = float(build_model(spec.body, timestep_s=spec.env.physics_dt_s).body_subtreemass[0])
    return GaitSpec.from_configs(spec.body, spec.muscle, mass_kg, spec.env.control_dt_s)


def run_episode(policy: Callable, env, seed: int, frame_sink: Callable | None = None,
                keep_steps: bool = True) -> dict[str, Any]:
    """One deterministic episode: metrics and, with ``keep_steps``, its per-step arrays as lists
    (``frame_sink`` gets rendered frames)."""
    obs, info = env.reset(seed=seed)
    regulator, drive = env.drive.pairs.regulator, env.drive
    command = regulator.target_pressure_kpa(drive.voltage_v)
    steps = {k: [] for k in STEP_KEYS}
    qpos, qvel = env.qpos_idx, env.qvel_idx
    total, change, max_y, fell, physics_error = 0.0, 0.0, 0.0, False, False
    if frame_sink:
        frame_sink(env.render())
    while True:
        action = policy(obs)
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        new_command = regulator.target_pressure_kpa(drive.voltage_v)
        change += float(np.abs(new_command - command).mean())
        command = new_command
        max_y = max(max_y, abs(float(info["y"])))
        physics_error |= bool(info["physics_error"])
        for key, value in (("x_m", info["x"]), ("y_m", info["y"]), ("z_m", info["z"]),
                           ("torso_rpy_rad", info["torso_rpy_rad"]),
                           ("joint_angle_rad", env.data.qpos[qpos]), ("joint_velocity_rad_s", env.data.qvel[qvel]),
                           ("joint_torque_nm", info["joint_torque_nm"]), ("pressure_kpa", info["pressure_kpa"].ravel()),
                           ("contraction_pct", info["contraction_pct"].ravel()), ("foot_force_n", info["foot_force_n"]),
                           ("sole_xyz_m", info["sole_xyz_m"]), ("action", action),
                           ("target_speed_m_s", info["target_speed_m_s"]),
                           ("clock_touchdown_offset", clock_touchdown_offsets(env))):
            steps[key].append(value)
        if frame_sink:
            frame_sink(env.render())
        if terminated or truncated:
            fell = bool(terminated)
            break
    n = len(steps["x_m"])
    duration = n * env.env_cfg.control_dt_s
    distance = float(info["distance"])
    arrays = {"t_s": np.arange(1, n + 1) * env.env_cfg.control_dt_s,
              **{k: np.asarray(v, dtype=float) for k, v in steps.items()}}
    spec = GaitSpec.from_configs(env.body_cfg, env.muscle_cfg, env.mass_kg, env.env_cfg.control_dt_s)
    gait = episode_metrics(arrays, spec)
    gait.update(tracking_metrics(arrays, spec.contact_threshold_n, env.env_cfg.control_dt_s))
    out = {
        "seed": seed,
        "return": float(total),
        "distance_m": distance,
        "duration_s": duration,
        "fell": fell,
        "physics_error": physics_error,
        "max_abs_y_m": max_y,
        "speed_m_s": distance / duration,
        "pressure_change_kpa": change / n,
        **gait,
    }
    if keep_steps:  # rounded for the file (1e-6 of each unit); the metrics above use the full values
        out["steps"] = {k: np.round(v, 6).tolist() for k, v in arrays.items()}
    return out


_WORKER: dict[str, Any] = {}


def _init_worker(agents: list[Agent], specs: list[EnvSpec], seed: int, keep_steps: bool = True) -> None:
    """Per process: one thread for torch (identical results at any worker count), policies, envs."""
    import torch  # (as in make_policy)

    torch.set_num_threads(1)
    _WORKER.update(policies=[make_policy(a) for a in agents], specs=specs, seed=seed, envs={}, keep_steps=keep_steps)


def _run_task(task: tuple[int, int]) -> tuple[int, int, dict]:
    i, k = task
    spec = _WORKER["specs"][i]
    key = json.dumps(spec.to_dict(), sort_keys=True)  # agents of the same robot and task share an env
    if key not in _WORKER["envs"]:
        _WORKER["envs"][key] = spec.make()
    return i, k, run_episode(_WORKER["policies"][i], _WORKER["envs"][key], _WORKER["seed"] + k,
                             keep_steps=_WORKER["keep_steps"])


@contextlib.contextmanager
def torch_threads(n: int):
    import torch  # (as in make_policy)

    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def evaluate_agents(agents: list[Agent], specs: list[EnvSpec], episodes: int, seed: int, workers: int,
                    on_episode: Callable[[], None] | None = None, keep_steps: bool = True) -> list[list[dict]]:
    """Episode results per agent, ``[agent][episode]``, each in its env ``specs[agent]``, the same
    for any number of workers (``keep_steps=False``: metrics only, no per-step lists)."""
    import pamrun.learning.networks  # noqa: F401  (torch and TorchRL imported once here, inherited by forked workers)

    tasks = [(i, k) for i in range(len(agents)) for k in range(episodes)]
    results: list[list[dict | None]] = [[None] * episodes for _ in agents]
    if workers <= 1:
        with torch_threads(1):
            _init_worker(agents, specs, seed, keep_steps)
            try:
                for task in tasks:
                    i, k, res = _run_task(task)
                    results[i][k] = res
                    if on_episode:
                        on_episode()
            finally:
                for env in _WORKER["envs"].values():
                    env.close()
                _WORKER.clear()
        return results
    # fork: workers start in milliseconds and inherit the loaded agents (spawn where fork is absent).
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    pool = ProcessPoolExecutor(min(workers, len(tasks)), mp_context=multiprocessing.get_context(method),
                               initializer=_init_worker, initargs=(agents, specs, seed, keep_steps))
    try:
        for future in as_completed([pool.submit(_run_task, t) for t in tasks]):
            i, k, res = future.result()
            results[i][k] = res
            if on_episode:
                on_episode()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return results


# Per-episode metric -> name of its aggregates (<name>_mean, <name>_std).
AGGREGATED = {"return": "return", "distance_m": "distance", "duration_s": "duration", "speed_m_s": "speed",
              "max_abs_y_m": "max_abs_y", "pressure_change_kpa": "pressure_change"}


def wilson_interval(successes: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """The 95 % Wilson score interval of a proportion (E. B. Wilson, JASA 22, 1927): unlike
    p +- z sqrt(p(1-p)/n) it stays inside [0, 1] and is not empty at 0 or n successes
    (10 of 10 gives [0.72, 1], 41 of 50 gives [0.69, 0.90])."""
    if n <= 0:
        return float("nan"), float("nan")
    p, z2 = successes / n, z * z
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = z / (1 + z2 / n) * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    # at 0 or n successes the bound is exactly 0 or 1 (rounding would leave 1 - 2e-16, outside p)
    return (0.0 if successes == 0 else max(0.0, centre - half)), (1.0 if successes == n else min(1.0, centre + half))


def aggregate(episodes: list[dict], ecfg) -> dict[str, Any]:
    """Mean and spread (population std) of an agent's episodes, its extremes, its walk test
    (pass count, rate and 95 % Wilson interval; ``walk_test``: every episode passed), its
    stand rate (the share of episodes that last the test's duration) and the gait metrics'
    means and spreads over the episodes where they are defined (NaN where none is), and how many
    of the walk's targets those means meet (``walk_targets_met``, :mod:`pamrun.evaluation.targets`)."""
    passed = [walk_passed(e, ecfg) for e in episodes]
    low, high = wilson_interval(sum(passed), len(passed))
    out: dict[str, Any] = {"episodes": len(episodes), "walk_test": all(passed), "walk_passes": int(sum(passed)),
                           "walk_pass_rate": float(np.mean(passed)), "walk_pass_ci_low": low, "walk_pass_ci_high": high,
                           "stand_rate": float(np.mean([stood(e, ecfg) for e in episodes])),
                           "fall_rate": float(np.mean([e["fell"] for e in episodes])),
                           "physics_error_rate": float(np.mean([e.get("physics_error", False) for e in episodes]))}
    for key, name in AGGREGATED.items():
        values = np.array([e[key] for e in episodes], dtype=float)
        out[f"{name}_mean"], out[f"{name}_std"] = float(values.mean()), float(values.std())
        if name == "distance":
            out["distance_min"] = float(values.min())
        if name == "max_abs_y":
            out["max_abs_y_max"] = float(values.max())
    for name in (*GAIT_METRICS, *TRACKING_METRICS):
        values = np.array([e.get(name, np.nan) for e in episodes], dtype=float)
        values = values[np.isfinite(values)]
        out[f"{name}_mean"] = float(values.mean()) if len(values) else float("nan")
        out[f"{name}_std"] = float(values.std()) if len(values) else float("nan")
    out["walk_targets_met"] = targets_met(out)
    return out
