"""``pamrun eval``: test saved agents in parallel, rank them and pick the best (thesis §10.3).

This module is the command; its parts are the evaluation package's modules: the agents and
their envs (:mod:`~pamrun.evaluation.agents`), the episodes, workers, walk test and aggregates
(:mod:`~pamrun.evaluation.episodes`), the ranking (:mod:`~pamrun.evaluation.ranking`), the files
and figures (:mod:`~pamrun.evaluation.results`), the console's tables
(:mod:`~pamrun.evaluation.tables`), the video (:mod:`~pamrun.evaluation.video`) and the suites
(:mod:`~pamrun.evaluation.suite`). The evaluations during training are
:mod:`pamrun.evaluation.evaluator`'s.

After training, the thesis tested every saved agent and showed the paths and muscle
pressures of the best. Here each agent runs ``eval.episodes`` (50) episodes with its
deterministic policy, episode k from seed ``eval.seed + k`` for every agent, spread over
``eval.workers`` processes; the results do not depend on the number of workers. Per
episode: return, forward distance, duration before a fall, fell, max |y|, mean forward
speed, the mean absolute change of the 20 commanded pressures per control step (the
thesis found its gait pulsing) and the gait and air metrics of :mod:`pamrun.evaluation.metrics`. An
episode passes the **walk test** of :func:`pamrun.task.criteria.walk_passed`; an agent's pass rate comes with its episode count and 95 % Wilson interval.

**Held-out seeds.** Evaluation during training selects ``best_eval.pt`` on the selection
block (seeds ``eval.selection_seed + k``); ``pamrun eval`` reports on ``eval.seed + k``
(from 1000), and ``leaderboard.json`` says whether the two blocks are disjoint
(``held_out``); when they are not, the console says so in red.

The evaluation directory holds ``episodes.jsonl`` (metrics and per-step x, y, z, joint
angles, velocities and torques, pressures, contractions, foot forces and positions and
actions of every episode), ``leaderboard.csv``/``.json`` (ranked by ``eval.rank_by``),
``best.pt`` with ``selection.json`` saying why, and the figures drawn from those files by
:mod:`pamrun.evaluation.figures` (``gait.png`` of the best agent among them); ``eval.render=true`` adds
``best_episode.mp4`` from ``eval.camera`` (:mod:`pamrun.task.camera`), ``best_episode_frames.png``
(8 frames 0.1 s apart mid-episode) and ``best_episode.gif`` (3 s of it).

**Suites.** ``eval.suite=robustness`` runs every agent under each perturbation of
``eval.suites.robustness`` (each a :class:`pamrun.config.Perturbation` of its own robot and
task, :meth:`pamrun.task.spec.EnvSpec.perturbed`) and writes ``robustness.csv``/``.json`` (agent x
perturbation: walk pass rate with its interval, stand rate, distance, ...),
``robustness_episodes.jsonl`` and ``robustness.png``.
"""

from __future__ import annotations

from pathlib import Path

from hydra.core.hydra_config import HydraConfig
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import OmegaConf

from pamrun.config import ENV_SECTIONS, ConfigError, to_object, without_hydra
from pamrun.evaluation.agents import run_all, start
from pamrun.evaluation.episodes import agent_env
from pamrun.evaluation.ranking import warn_if_not_held_out
from pamrun.evaluation.results import draw_figures, write_results
from pamrun.evaluation.suite import run_suite
from pamrun.evaluation.tables import gait_table, leaderboard_table, targets_table
from pamrun.learning.checkpoints import CheckpointError, find_checkpoints, load_agent
from pamrun.runs.files import run_dir
from pamrun.task.spec import EnvSpec, eval_env_options


def command_line_changes(config, overrides: list[str]) -> tuple[dict, list[str]]:
    """The keys of the sections an agent file stores (:data:`pamrun.config.ENV_SECTIONS`: its robot
    and task) set on ``pamrun eval``'s command line (``overrides``: Hydra's task overrides; section ->
    nested dict of their composed values in ``config``), and the presets chosen there (a group of the
    same name, or ``experiment=``) that an agent's own env does not take; both empty with
    ``eval.use_agent_env=false``, where the command line's robot and task are the env."""
    if not config.eval.use_agent_env:
        return {}, []
    changes: dict[str, dict] = {}
    presets = []
    for override in OverridesParser.create().parse_overrides(overrides):
        key = override.key_or_group
        section, _, rest = key.partition(".")
        if not rest:
            if section in (*ENV_SECTIONS, "experiment"):
                presets.append(f"{key}={override.value()}")
            continue
        if section not in ENV_SECTIONS or override.is_delete():
            continue
        *path, name = rest.split(".")
        node = changes.setdefault(section, {})
        value = config[section]
        for part in path:
            node, value = node.setdefault(part, {}), value[part]
        value = value[name]
        node[name] = OmegaConf.to_container(value) if OmegaConf.is_config(value) else value
    return changes, presets


def check_config(config) -> None:
    """``ckpt`` must name at least one usable checkpoint, in whose own env the command line's keys
    (:func:`command_line_changes`) are valid (run by pamrun.cli before any directory exists)."""
    changes, _ = command_line_changes(config, list(config.hydra.overrides.task) if "hydra" in config else [])
    cfg = to_object(without_hydra(config))
    if cfg.eval.suite:  # every perturbation of the suite applied to the command line's robot and task
        base = EnvSpec.from_config(cfg).with_values(env=eval_env_options(cfg.eval))
        for name in cfg.eval.suites[cfg.eval.suite]:
            base.perturbed(cfg.eval.perturbations[name], f"eval.perturbations.{name}")
    try:
        paths = find_checkpoints(cfg.ckpt, cfg.eval.include_last)
    except CheckpointError as err:
        raise ConfigError("ckpt", str(err)) from None
    errors = []
    for path in paths:  # at least one must load, or the evaluation would write only its failure
        try:
            agent = load_agent(path)
        except CheckpointError as err:
            errors.append(err)
            continue
        agent_env(agent, cfg, changes)  # ConfigError naming the key a change makes impossible there
        return
    raise ConfigError("ckpt", f"none of its {len(paths)} checkpoint(s) is usable; the first: {errors[0]}")


def evaluate(dcfg) -> None:
    """The Hydra task of ``pamrun eval``."""
    changes, presets = command_line_changes(dcfg, list(HydraConfig.get().overrides.task))
    cfg = to_object(dcfg)
    if cfg.eval.suite:
        run_suite(cfg, cfg.ckpt, run_dir(), changes, presets)
    else:
        run_evaluation(cfg, cfg.ckpt, run_dir(), changes, presets)


def run_evaluation(cfg, ckpt: str, out: Path, changes: dict | None = None, presets: list[str] = ()) -> dict:
    """Evaluate the agents named by ``ckpt`` into ``out``; the selection (selection.json's content).
    ``changes`` and ``presets``: :func:`command_line_changes`'s."""
    console, agents, envs, errors = start(cfg, ckpt, out, changes, presets)
    is_held_out = warn_if_not_held_out(agents, cfg, console)
    results, workers, wall = run_all(agents, envs, cfg.eval, console)
    ranked, best, selection = write_results(out, cfg, ckpt, agents, results, errors, workers, wall, is_held_out)
    written = draw_figures(out, cfg.eval, agents, envs, results, best, console)
    console.print(leaderboard_table(ranked, cfg.eval))
    console.print(gait_table(ranked))
    console.print(targets_table(next(row for row in ranked if row["agent"] == best.label)))
    console.print(f"Best: [bold]{best.label}[/bold] -> {out / 'best.pt'}\n{selection['reason']}", soft_wrap=True)
    if errors:
        console.print(f"[red]{len(errors)} checkpoint(s) skipped[/red] (listed in leaderboard.json)")
    console.print(f"Evaluated in {wall:.1f} s on {workers} worker(s). Wrote {', '.join(written)}", soft_wrap=True)
    return selection
