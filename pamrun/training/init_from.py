"""A new run from a trained agent (``train.init_from``): what it takes of the agent's file, its
networks and, from a run's ``last.pt``, the replay buffer, and the checks made before the run
directory exists (``docs/commands.md``, "Fine-tuning")."""

from __future__ import annotations

from pathlib import Path

import torch

from pamrun.config import Config, ConfigError
from pamrun.learning import checkpoints, networks
from pamrun.learning.curriculum import reweighted_terms, weighed_terms
from pamrun.runs import directory
from pamrun.runs.directory import RunFiles
from pamrun.task.observation import space_sizes
from pamrun.task.reward import REWARD_KEYS
from pamrun.task.spec import EnvSpec


def check_start(cfg: Config) -> None:
    """``train.init_from`` is an agent pamrun can read, for this env's sizes and ``algo.hidden_sizes``;
    the replay buffer this run would take from it is whole, as far as file sizes tell."""
    path = cfg.train.init_from
    try:
        agent = checkpoints.load_agent(path, *space_sizes(cfg.muscle, cfg.env))
        record, _ = _buffer_to_take(cfg, Path(path), torch.load(path, map_location="cpu", weights_only=True))
        if record is not None:
            checkpoints.check_buffer_sizes(Path(path).parent, record)
    except checkpoints.CheckpointError as err:
        raise ConfigError("train.init_from", str(err)) from None
    if agent.hidden_sizes != list(cfg.algo.hidden_sizes):
        raise ConfigError("train.init_from", f"{path}: its actor's hidden layers are {agent.hidden_sizes}, "
                                             f"algo.hidden_sizes {list(cfg.algo.hidden_sizes)}")


def start_from(cfg: Config, learner: networks.Learner, buffer, console) -> set[str] | None:
    """A new run's networks from the trained agent in ``train.init_from``, and the replay buffer
    :func:`_buffer_to_take` says it takes, re-weighted to this run's rewards like any sample;
    returns the reward terms that buffer's transitions carry (None: no buffer taken)."""
    path = Path(cfg.train.init_from)
    state = torch.load(path, map_location="cpu", weights_only=True)
    try:
        took = learner.start_from(state)
    except (RuntimeError, KeyError) as err:  # another algorithm's critics, or other critic sizes
        first = (str(err).strip().splitlines() or [""])[0][:160]
        raise SystemExit(f"pamrun: train.init_from: {path}: its networks do not fit algo.* ({first})") from None
    record, why_not = _buffer_to_take(cfg, path, state)
    if record is None:
        took += f"; not its replay buffer, {why_not}" if why_not else ""
        terms = None
    else:
        terms = carried_terms(path, record, state.get("config") or {})
        try:
            checkpoints.load_buffer(path.parent, record, buffer)
        except checkpoints.CheckpointError as err:
            raise SystemExit(f"pamrun: train.init_from: {err}") from None
        took += f", and its {len(buffer)} replayed transitions"
    console.print(f"Starting from {took} of {path}.", soft_wrap=True)
    return terms


def _buffer_to_take(cfg: Config, path: Path, state: dict) -> tuple[dict | None, str]:
    """The ``"buffer"`` record of the resume state ``state`` (``train.init_from``, at ``path``)
    whose transitions this run takes, or None and why not ("" for an agent file, which has none).
    It takes them when the env's weights (``reward.*``) and transitions are the same, they carry
    every term this run's stages weigh, they fit ``train.buffer_size``, and their folder lies
    beside the file (a ``last.pt`` copied alone starts with an empty buffer)."""
    record, config = state.get("buffer"), state.get("config") or {}
    if record is None:
        return None, ""
    differ = EnvSpec.from_dict(config).transition_changes_to(EnvSpec.from_config(cfg))  # its env is not ours
    computed = carried_terms(path, record, config)
    uncarried = [k for k in reweighted_terms(cfg) if k not in computed]
    if differ:
        return None, f"gathered in another env or summed with other weights ({', '.join(differ)})"
    if uncarried:
        return None, (f"whose transitions do not carry terms this run's stages weigh ({', '.join(uncarried)}: "
                      f"its run, by an earlier pamrun, did not compute them)")
    if record["length"] > cfg.train.buffer_size:
        return None, f"of {record['length']} transitions (train.buffer_size {cfg.train.buffer_size})"
    if not (path.parent / record["dir"]).is_dir():
        return None, f"whose folder {record['dir']} is not beside it"
    return record, ""


def carried_terms(path: Path, record: dict, config: dict) -> set[str]:
    """The reward terms the transitions of the buffer a ``last.pt`` at ``path`` names carry: as
    its ``record`` says, or for one saved before it recorded them, those its run's config computed
    (outside its run directory, those of weight not 0 in its ``config``)."""
    if "terms" in record:
        return set(record["terms"])
    run = path.parent.parent
    if RunFiles(run).config.exists():
        return set(weighed_terms(directory.saved_config(run)))
    return {k for k in REWARD_KEYS if (config.get("reward") or {}).get(k, 0.0) != 0.0}
