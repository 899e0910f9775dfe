"""The agents an evaluation names, loaded with the env each is evaluated in, and their episodes
run over ``eval.workers`` processes with a progress display."""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from omegaconf.errors import OmegaConfBaseException

from pamrun.config import ConfigError, flatten
from pamrun.evaluation.episodes import agent_env, evaluate_agents
from pamrun.learning.checkpoints import Agent, CheckpointError, check_fits, find_checkpoints, load_agent, unique_labels
from pamrun.runs.files import Progress
from pamrun.runs.files import console as make_console
from pamrun.runs.machine import usable_cores
from pamrun.task.observation import space_sizes
from pamrun.task.spec import EnvSpec


def load_agents(spec: str, cfg, changes: dict | None = None) -> tuple[list[Agent], list[EnvSpec], list[dict]]:
    """Agents named by ``spec`` with the env each is evaluated in (:func:`agent_env`, with ``changes``),
    and one error row per unusable file."""
    loaded, envs, errors = [], [], []
    for path in find_checkpoints(spec, cfg.eval.include_last):
        try:
            agent = load_agent(path)
            env = agent_env(agent, cfg, changes)
            check_fits(agent, *space_sizes(env.muscle, env.env))
        except CheckpointError as err:
            errors.append({"path": err.path, "error": err.message})
            continue
        except (ConfigError, ValueError, OmegaConfBaseException) as err:
            errors.append({"path": str(path), "error": f"its stored config is not valid here: {err}".splitlines()[0]})
            continue
        loaded.append(agent)
        envs.append(env)
    unique_labels(loaded)
    return loaded, envs, errors


def start(cfg, spec: str, out: Path, changes: dict | None = None,
          presets: Sequence[str] = ()) -> tuple[Any, list[Agent], list[EnvSpec], list[dict]]:
    """A console, ``out`` made, and the usable agents of ``spec`` with their envs and the unusable
    files (named on the console); exits when none is usable. ``changes``: the command line's keys,
    set in each agent's own env (:func:`agent_env`); ``presets``: the command line's choices of
    whole robots and tasks, which an agent's own env does not take (both said on the console)."""
    console = make_console()
    out.mkdir(parents=True, exist_ok=True)
    agents, envs, errors = load_agents(spec, cfg, changes)
    if changes:
        said = ", ".join(f"{k}={v}" for k, v in flatten(changes).items())
        console.print(f"Each agent in its own robot and task, with {said} (eval.use_agent_env)", soft_wrap=True)
    if presets:
        console.print(f"[yellow]note[/yellow] {', '.join(presets)} chose a robot or task that no agent runs in: each "
                      f"runs in its own (eval.use_agent_env=true), with only the keys set one by one changed; "
                      f"eval.use_agent_env=false runs every agent in the command line's", soft_wrap=True)
    for err in errors:
        console.print(f"[red]skipped[/red] {err['path']}: {err['error']}", soft_wrap=True)
    if not agents:
        raise SystemExit(f"pamrun: no usable checkpoint in {spec} ({len(errors)} unreadable; see above)")
    asked = "eval.speed_schedule" if cfg.eval.speed_schedule else "eval.speed_m_s" if cfg.eval.speed_m_s is not None else ""
    for agent, env in zip(agents, envs):
        if asked and not env.env.speed_command:
            console.print(f"[yellow]note[/yellow] {agent.label} is not told the commanded speed (its env.speed_command is "
                          f"false): {asked} is only what its speed tracking is measured against", soft_wrap=True)
    return console, agents, envs, errors


def run_all(agents: list[Agent], envs: list[EnvSpec], ecfg, console, what: str = "agent(s)", keep_steps: bool = True
            ) -> tuple[list[list[dict]], int, float]:
    """Every agent's episodes in its env, on ``eval.workers`` processes with a progress display."""
    workers = min(ecfg.workers or usable_cores(), len(agents) * ecfg.episodes)
    # torch and TorchRL, imported before the clock starts (here, not at the top: pamrun eval imports
    # this module before it checks its config, and a config error need not wait seconds for them)
    import pamrun.learning.networks  # noqa: F401

    console.print(f"Evaluating {len(agents)} {what} x {ecfg.episodes} episode(s), seeds {ecfg.seed}.."
                  f"{ecfg.seed + ecfg.episodes - 1}, on {workers} worker(s)")
    start = time.perf_counter()
    progress = Progress(console, len(agents) * ecfg.episodes, 0, unit="episodes")
    done = [0]

    def tick() -> None:
        done[0] += 1
        progress.update(done[0])

    try:
        results = evaluate_agents(agents, envs, ecfg.episodes, ecfg.seed, workers, on_episode=tick,
                                  keep_steps=keep_steps)
    except KeyboardInterrupt:
        raise SystemExit("pamrun: evaluation interrupted; no results written (checkpoints are untouched)") from None
    finally:
        progress.stop()
    return results, workers, time.perf_counter() - start
