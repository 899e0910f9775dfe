"""Saved agents and resume state on disk: what they hold, saving, finding and loading them safely.

An agent file (``checkpoints/agent_ep<N>_r<reward>.pt``, an evaluation's ``best.pt``) is a
``torch.save`` of plain data only: the actor's weights, the episode it was saved at, the
algorithm and the robot/task config sections it was trained with, so it can be evaluated
on its own. ``checkpoints/last.pt`` (the resume state) carries the same ``actor``,
``algo`` and ``config`` entries. Everything is read with ``torch.load(weights_only=True)``:
a file that tries to run code, a truncated file or one with the wrong shapes raises
:class:`CheckpointError` naming the file, never executes anything.

A training's checkpoint directory holds its threshold-saved agents (:func:`save_agent`,
the best ``train.keep_saved`` kept) and its resume state (:func:`save_last`,
:func:`load_last`): ``last.pt`` with the learner, counters and RNG states, and the replay
buffer in ``buffer/``.

torch is imported inside the functions that read or write tensors: finding, naming and checking
checkpoints (``pamrun eval``'s config check) does not wait seconds for it.
"""

from __future__ import annotations

import glob
import pickle
import random
import shutil
import warnings
import zlib
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pamrun.config import upgrade_saved_config
from pamrun.learning.curriculum import FEATURES
from pamrun.runs.directory import (
    AGENT_GLOB,
    BEST_EVAL,
    CHECKPOINTS,
    LAST,
    RunFiles,
    saved_config,
)
from pamrun.runs.files import atomic_save
from pamrun.task.reward import REWARD_KEYS
from pamrun.task.spec import EnvSpec

FORMAT = "pamrun-agent/1"


class CheckpointError(Exception):
    """A checkpoint that cannot be used; ``path`` names the file (or the pattern searched)."""

    def __init__(self, path: str | Path, message: str):
        self.path, self.message = str(path), message
        super().__init__(f"{path}: {message}")


@dataclass
class Agent:
    """An actor loaded from a checkpoint, with what it was trained on."""

    path: Path
    label: str  # "<run dir name>/<file stem>": unique and readable in tables
    actor_state: dict[str, Any]  # state_dict of pamrun.learning.networks.ThesisActor
    hidden_sizes: list[int]
    meta: dict[str, Any]  # training episode, frames, reward, ... at the time of saving
    config: dict[str, dict] | None  # its env as stored (pamrun.task.spec.EnvSpec.to_dict()), None if unknown
    algo: dict[str, Any] | None = None
    obs_size: int = 43  # the actor's input and output sizes
    action_size: int = 10

    @property
    def run_dir(self) -> Path | None:
        """The training run the file belongs to (``<run>/checkpoints/<file>``), if any."""
        return self.path.parent.parent if self.path.parent.name == CHECKPOINTS else None


def agent_record(actor_state: dict, cfg, meta: dict) -> dict:
    """The content of an agent file: weights, metadata and the run's algo and env config."""
    return {
        "format": FORMAT,
        "actor": actor_state,
        "meta": dict(meta),
        "algo": asdict(cfg.algo),
        "config": EnvSpec.from_config(cfg).to_dict(),
    }


def find_checkpoints(spec: str, include_last: bool = True) -> list[Path]:
    """Checkpoint files named by ``spec``: a file, a run directory, a folder of runs or a glob.

    A run directory gives its threshold-saved agents, its best agent by the evaluations
    during training (``checkpoints/best_eval.pt``) and, with ``include_last``, its final
    agent (``checkpoints/last.pt``). A folder holding several runs (a sweep) gives those
    of every run below it. Raises CheckpointError when nothing is found.
    """
    if not spec:
        raise CheckpointError("ckpt", "no checkpoint given: pass ckpt=<file, run directory or glob>")
    paths = [Path(p) for p in sorted(glob.glob(spec, recursive=True))] if glob.has_magic(spec) else [Path(spec)]
    if not glob.has_magic(spec) and not paths[0].exists():
        raise CheckpointError(spec, "no such file or directory")
    found: list[Path] = []
    for path in paths:
        found += [path] if path.is_file() else _in_directory(path, include_last)
    unique = list(dict.fromkeys(p.resolve() for p in found))
    if not unique:
        raise CheckpointError(spec, f"no checkpoints found (looked for {AGENT_GLOB}"
                                    f"{' and ' + LAST if include_last else ''} in run directories)")
    return unique


def _in_directory(path: Path, include_last: bool) -> list[Path]:
    folders = [path / CHECKPOINTS, path] if (path / CHECKPOINTS).is_dir() else [path]
    for folder in folders:
        files = sorted(folder.glob(AGENT_GLOB)) + [folder / BEST_EVAL] * (folder / BEST_EVAL).exists() \
            + ([folder / LAST] if include_last and (folder / LAST).exists() else [])
        if files:
            return files
    # A folder of runs (a sweep): every run below it.
    runs = sorted({p.parent.parent for p in path.glob(f"**/checkpoints/{LAST}")}
                  | {p.parent.parent for p in path.glob(f"**/checkpoints/{AGENT_GLOB}")})
    return [f for run in runs for f in _in_directory(run, include_last)]


def load_agent(path: str | Path, obs_size: int | None = None, action_size: int | None = None) -> Agent:
    """Read an agent without executing code; check it fits an env with these sizes (if given)."""
    import torch  # here, not at the top: finding and naming checkpoints does not wait for torch (seconds)

    path = Path(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # torch's note on foreign pickle protocols
            data = torch.load(path, map_location="cpu", weights_only=True)
    except FileNotFoundError:
        raise CheckpointError(path, "no such file") from None
    except pickle.UnpicklingError:
        raise CheckpointError(path, "refused by the safe loader: not tensors and plain data in torch's format "
                                    "(e.g. a pickle that would run code); nothing was executed") from None
    except Exception as err:  # truncated or corrupt zip, not a torch file at all
        first = str(err).strip().splitlines()[0][:120] if str(err).strip() else ""
        raise CheckpointError(path, f"truncated or corrupt, not a complete torch checkpoint "
                                    f"({type(err).__name__}: {first})") from None
    if not isinstance(data, dict) or not isinstance(data.get("actor"), dict):
        raise CheckpointError(path, "holds no actor weights (not an agent file or last.pt written by pamrun)")
    state = data["actor"]
    shapes = {k: tuple(v.shape) for k, v in state.items() if isinstance(v, torch.Tensor)}
    needed = ("net.0.weight", "net.2.weight", "net.4.weight")
    if any(k not in shapes or len(shapes[k]) != 2 for k in needed):
        raise CheckpointError(path, f"actor weights do not have the thesis actor's layers {list(needed)}")
    (h0, n_obs), (h1, _), (n_act, _) = (shapes[k] for k in needed)
    _check_sizes(path, n_obs, n_act, obs_size, action_size)
    if not all(bool(torch.isfinite(v).all()) for v in state.values() if isinstance(v, torch.Tensor)):
        raise CheckpointError(path, "actor weights are not finite (NaN or inf)")
    meta = dict(data.get("meta") or {})
    if "counters" in data:  # last.pt
        meta.setdefault("frames", data["counters"].get("frames"))
        meta.setdefault("episode", data["counters"].get("episodes"))
    config = data.get("config")
    if config is None:
        config = _run_config(path)
    if config is not None:
        config = upgrade_saved_config(config)
    return Agent(path=path, label=label_of(path), actor_state=state, hidden_sizes=[h0, h1], meta=meta,
                 config=config, algo=data.get("algo"), obs_size=n_obs, action_size=n_act)


def _check_sizes(path: Path, n_obs: int, n_act: int, obs_size: int | None, action_size: int | None) -> None:
    if obs_size is not None and n_obs != obs_size:
        raise CheckpointError(path, f"actor takes {n_obs} observations, PamWalker-v0 gives {obs_size}: "
                                    "trained with an incompatible observation layout")
    if action_size is not None and n_act != action_size:
        raise CheckpointError(path, f"actor gives {n_act} actions, PamWalker-v0 takes {action_size}")


def check_fits(agent: Agent, obs_size: int, action_size: int) -> None:
    """Raise CheckpointError unless the agent's actor fits an env with these sizes."""
    _check_sizes(agent.path, agent.obs_size, agent.action_size, obs_size, action_size)


def save_agent_copy(agent: Agent, path: Path, **extra_meta) -> Path:
    """Write ``agent`` as a stand-alone agent file (e.g. an evaluation's ``best.pt``), atomically."""
    record = {"format": FORMAT, "actor": agent.actor_state, "meta": {**agent.meta, **extra_meta},
              "algo": agent.algo, "config": agent.config}
    return atomic_save(record, path)


def _run_config(path: Path) -> dict[str, dict] | None:
    """The env (EnvSpec.to_dict()) of the run a checkpoint sits in (``<run>/pamrun_config.yaml``), if there."""
    run = path.parent.parent
    if path.parent.name != CHECKPOINTS or not RunFiles(run).config.exists():
        return None
    return EnvSpec.from_config(saved_config(run)).to_dict()


def label_of(path: Path) -> str:
    """``<run dir name>/<stem>`` for files in a run's checkpoints/, else ``<folder>/<stem>``."""
    owner = path.parent.parent if path.parent.name == CHECKPOINTS else path.parent
    return f"{owner.name}/{path.stem}"


def unique_labels(agents: list[Agent]) -> None:
    """Make labels unique in place (two runs of the same name in different folders)."""
    seen: dict[str, int] = {}
    for agent in agents:
        n = seen.get(agent.label, 0)
        seen[agent.label] = n + 1
        if n:
            agent.label = f"{agent.label}#{n + 1}"


# --------------------------------------------------------------------------- a training's checkpoints


def save_agent_record(path: Path, actor_state: dict, cfg, meta: dict) -> Path:
    """Write an agent file (weights, ``meta``, the run's algo and env config), atomically."""
    return atomic_save(agent_record(actor_state, cfg, meta), path)


def save_agent(ckpt_dir: Path, actor_state: dict, row: dict, cfg, saved: list, keep: int) -> list:
    """Save an actor with its episode's reward in name and metadata; keep the best ``keep``.

    ``saved`` is the (reward, path) list of the agents on disk, best first; returns it updated."""
    path = ckpt_dir / f"agent_ep{row['episode']:06d}_r{row['reward']:.1f}.pt"
    meta = {k: row[k] for k in ("episode", "frames", "reward", "distance_m", "q0")}
    save_agent_record(path, actor_state, cfg, meta)
    saved = sorted(saved + [(row["reward"], path)], key=lambda t: -t[0])
    for _, old in saved[keep:]:
        old.unlink(missing_ok=True)
    return saved[:keep]


def scan_saved(ckpt_dir: Path) -> list[tuple[float, Path]]:
    """Threshold-saved agents already on disk, best first."""
    import torch  # heavy: imported where a tensor is read or written (module docstring)

    found = [(torch.load(p, weights_only=True)["meta"]["reward"], p) for p in ckpt_dir.glob(AGENT_GLOB)]
    return sorted(found, key=lambda t: -t[0])


def drop_agents_after(ckpt_dir: Path, episodes: int) -> None:
    """Delete agents saved after episode ``episodes`` (a resume runs those episodes again)."""
    for agent in ckpt_dir.glob(AGENT_GLOB):
        if int(agent.name.split("_")[1][2:]) > episodes:
            agent.unlink()


def save_last(ckpt_dir: Path, cfg, learner, buffer, counters: dict, terms) -> None:
    """Everything a resume needs, and the final actor as an agent (``pamrun eval`` reads it).

    The replay buffer goes first, into its own ``buffer-<frames>/`` folder; then ``last.pt``,
    atomically, naming that folder with the size and CRC-32 of each of its files and the
    buffer's length; then older buffer folders go. A crash at any moment leaves a
    ``last.pt`` whose buffer is complete on disk, and ``terms``, the reward terms its transitions
    carry (the others are stored as 0). Plain data only: loadable with ``weights_only=True``."""


    needed = _checkpoint_bytes(learner, buffer)
    free = shutil.disk_usage(ckpt_dir).free
    if free < needed:  # a memory-mapped dump onto a full disk dies of SIGBUS, with no message
        raise CheckpointError(ckpt_dir, f"not enough disk space for a checkpoint: about {needed / 1e6:.0f} MB "
                                        f"needed, {free / 1e6:.0f} MB free (any previous checkpoint is kept); "
                                        "free some space or lower train.buffer_size")
    name = f"buffer-{counters['frames']:010d}"
    tmp = ckpt_dir / (name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    buffer.dumps(tmp)
    shutil.rmtree(ckpt_dir / name, ignore_errors=True)
    tmp.rename(ckpt_dir / name)
    actor = agent_record(learner.policy_state(), cfg,
                         {"frames": counters["frames"], "episode": counters["episodes"]})
    atomic_save({**actor, **learner.state_dict(), "counters": dict(counters), "rng": rng_states(),
                 "buffer": {"dir": name, "length": len(buffer), "files": file_fingerprints(ckpt_dir / name),
                            "terms": sorted(terms)}},
                ckpt_dir / LAST)
    for old in ckpt_dir.glob("buffer*"):
        if old.name != name:
            shutil.rmtree(old, ignore_errors=True)


def _checkpoint_bytes(learner, buffer) -> int:
    """What a checkpoint writes, roughly: the buffer's storage (its full capacity, as TorchRL
    dumps it), three copies of every parameter (weights, two Adam moments) and 16 MB to spare."""
    storage = getattr(buffer.storage, "_storage", None)
    data = 0 if storage is None else sum(t.numel() * t.element_size() for t in storage.values(True, True))
    params = sum(p.numel() * p.element_size() for p in learner.parameters())
    return int(data + 3 * params + 16e6)


def file_fingerprints(folder: Path) -> dict[str, list[int]]:
    """Relative path -> [size, CRC-32] of every file below ``folder``."""

    out = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        crc = 0
        with path.open("rb") as fh:
            while chunk := fh.read(1 << 22):
                crc = zlib.crc32(chunk, crc)
        out[str(path.relative_to(folder))] = [path.stat().st_size, crc]
    return out


def saved_counters(ckpt_dir: Path) -> dict | None:
    """The counters of the last checkpoint on disk (None without one)."""
    import torch  # heavy: imported where a tensor is read or written (module docstring)

    path = ckpt_dir / LAST
    return dict(torch.load(path, weights_only=True)["counters"]) if path.exists() else None


def load_last(ckpt_dir: Path, learner, buffer) -> tuple[dict, set[str] | None]:
    """Restore the learner, the replay buffer and the RNG states; return the counters and the
    reward terms the buffer's transitions carry (None: a ``last.pt`` that did not record them).

    Every piece is checked first: ``last.pt`` must load, and each buffer file must have the
    size and checksum the checkpoint recorded, so a resume never trains on a truncated or
    zero-filled buffer. A failure raises :class:`CheckpointError` naming the file."""

    import torch  # heavy: imported where a tensor is read or written (module docstring)

    last = ckpt_dir / LAST
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            state = torch.load(last, map_location="cpu", weights_only=True)
        counters = dict(state["counters"])
        learner.load_state_dict(state, counters["updates"])
    except Exception as err:  # truncated, not a torch file, or not pamrun's resume state
        first = (str(err).strip().splitlines() or [""])[0][:120]
        raise CheckpointError(last, f"unreadable resume state ({type(err).__name__}: {first})") from None
    set_rng_states(state["rng"])
    load_buffer(ckpt_dir, state.get("buffer"), buffer)
    terms = (state.get("buffer") or {}).get("terms")
    return counters, None if terms is None else set(terms)


def check_buffer_sizes(ckpt_dir: Path, record: dict) -> Path:
    """The folder of the replay buffer a ``last.pt`` in ``ckpt_dir`` names (``record``: its
    ``"buffer"`` entry), each of its files there with the size it recorded (no checksums: quick);
    :class:`CheckpointError` naming the first file missing or of another size."""
    folder = ckpt_dir / record["dir"]
    for rel, (size, _) in record["files"].items():
        path = folder / rel
        if not path.is_file():
            raise CheckpointError(path, "replay buffer file missing")
        if path.stat().st_size != size:
            raise CheckpointError(path, f"replay buffer file truncated or grown: {path.stat().st_size} bytes, "
                                        f"the checkpoint wrote {size}")
    return folder


def load_buffer(ckpt_dir: Path, record: dict | None, buffer) -> None:
    """The replay buffer a ``last.pt`` in ``ckpt_dir`` names (``record``: its ``"buffer"`` entry),
    each file checked against the size and checksum it recorded; :class:`CheckpointError` naming the file."""
    if record is None:  # written by pamrun before buffer fingerprints: no check possible
        folder = next((ckpt_dir / n for n in ("buffer", "buffer.old") if (ckpt_dir / n).exists()), None)
        if folder is None:
            raise CheckpointError(ckpt_dir / "buffer", "no replay buffer beside last.pt")
    else:
        folder = check_buffer_sizes(ckpt_dir, record)
        found = file_fingerprints(folder)
        for rel, (size, crc) in record["files"].items():
            if found[rel][1] != crc:
                raise CheckpointError(folder / rel, "replay buffer file changed since the checkpoint (checksum)")
    try:
        buffer.loads(folder)
    except Exception as err:
        first = (str(err).strip().splitlines() or [""])[0][:120]
        raise CheckpointError(folder, f"replay buffer unreadable ({type(err).__name__}: {first})") from None
    if record is not None and len(buffer) != record["length"]:
        raise CheckpointError(folder, f"replay buffer holds {len(buffer)} transitions, "
                                      f"the checkpoint {record['length']}")
    check_reward_terms(buffer, folder)


# The reward terms' order in the replay buffers pamrun saved before it stored them by name (one
# (n, 13) array of features under ("next", "reward_unweighted")): RewardConfig's field order then.
ARRAY_TERMS = ("kvx", "ky", "kz", "kv", "kt", "kda", "kfall", "kstop", "kspeed", "kslip", "kair", "kstep", "kgait")


def check_reward_terms(buffer, folder: Path) -> None:
    """The replay buffer's transitions carry every reward term of this pamrun by weight key
    (``pamrun.task.reward.REWARD_KEYS``, under ``("next", FEATURES)``). A buffer saved with the
    terms as one array (:data:`ARRAY_TERMS` order) is converted in place. A term added to pamrun
    after the buffer was saved is stored as 0: a resume keeps the run's own config, in which that
    term's weight is its default 0 and no curriculum weights it, so nothing reads it."""
    import torch  # torch and TorchRL: heavy, imported where used (as everywhere in this module)
    from tensordict import TensorDict

    storage = buffer.storage._storage if len(buffer) else None
    stored = None if storage is None else storage.get(("next", FEATURES), None)
    if isinstance(stored, torch.Tensor):
        if stored.shape[-1] != len(ARRAY_TERMS):
            raise CheckpointError(folder, f"replay buffer stores {stored.shape[-1]} reward terms, not the "
                                          f"{len(ARRAY_TERMS)} of the array format ({', '.join(ARRAY_TERMS)})")
        named = {k: stored[..., i].contiguous() for i, k in enumerate(ARRAY_TERMS)}
        storage.del_(("next", FEATURES))
        storage.set(("next", FEATURES), stored := TensorDict(named, batch_size=stored.shape[:-1]))
    for key in [] if stored is None else [k for k in REWARD_KEYS if k not in stored]:
        storage.set(("next", FEATURES, key), torch.zeros_like(stored[ARRAY_TERMS[0]]))


def rng_states() -> dict:
    """Torch, numpy and Python RNG states as tensors, lists and numbers (weights_only-safe)."""

    import torch  # heavy: imported where a tensor is read or written (module docstring)

    np_state = np.random.get_state(legacy=False)
    np_state["state"]["key"] = np_state["state"]["key"].tolist()
    return {"torch": torch.get_rng_state(), "numpy": np_state, "python": random.getstate()}


def set_rng_states(rng: dict) -> None:

    import torch  # heavy: imported where a tensor is read or written (module docstring)

    torch.set_rng_state(rng["torch"])
    np_state = dict(rng["numpy"])
    np_state["state"] = {**np_state["state"], "key": np.asarray(np_state["state"]["key"], dtype=np.uint32)}
    np.random.set_state(np_state)
    random.setstate(tuple(tuple(x) if isinstance(x, list) else x for x in rng["python"]))
