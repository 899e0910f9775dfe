"""``pamrun export``: a saved agent's policy as a file that runs without pamrun.

``pamrun export ckpt=<agent file> [format=onnx|torchscript]`` writes the agent's actor,
the deterministic policy observation -> action of :class:`pamrun.learning.networks.ThesisActor`
(no exploration noise), to the run directory:

* ``format=onnx`` (default): ``actor.onnx``, input ``observation`` (batch, obs_size)
  float32, output ``action`` (batch, action_size) float32, the batch dimension dynamic.
  Needs the ``onnx`` package (``pip install "pamrun[export]"``); run it with ONNX Runtime.
* ``format=torchscript``: ``actor.pt`` (``torch.jit.load``), same input and output.

Both files carry the same metadata as ``export.json`` beside them: in ONNX the model's
``metadata_props`` key ``pamrun``, in TorchScript the extra file ``pamrun.json``, each a
JSON object with

* ``observation_layout``: each block of the observation as ``[start, stop]``
  (:func:`pamrun.task.observation.observation_structure`) and ``observation_units`` its unit;
* ``action``: a in [-1, 1], one per joint in ``pamrun.physics.body.JOINTS`` order (``names``), or
  one per muscle with ``muscle.command=independent``; the voltages V = V0 +- dV a
  (``v0_v``, ``dv_max_v``, ``voltage``), the regulator's ``gain_kpa_per_v`` and the clipping
  that turn them into pressures (``pressure``), and its time constant ``regulator_lag_s``;
  all from the agent's own muscle config, not the command line's;
* ``action_filter`` and ``gait_clock``: the low-pass the robot applies to the action, and the
  clock it feeds the policy (``env.action_filter_alpha``, ``env.gait_period_s``; pamrun.task.env);
* ``control_dt_s``: the action is held for this long (one control step);
* ``checkpoint``: the source file, its label and meta (episode, frames, reward, ...);
* ``pamrun_version``.

``ckpt`` must name one agent file (an agent_ep*.pt, best_eval.pt, last.pt or an evaluation's
best.pt): a directory, a glob or an unusable file is refused before the run directory exists.
"""

from __future__ import annotations

import glob
import importlib.util
import io
import json
import warnings
from importlib.metadata import version as package_version
from pathlib import Path
from typing import Any

import torch

import pamrun
from pamrun.config import ConfigError, EnvConfig, MuscleConfig, as_config, to_object
from pamrun.learning.checkpoints import Agent, CheckpointError, load_agent
from pamrun.learning.networks import ThesisActor
from pamrun.physics.body import JOINTS
from pamrun.runs.files import atomic_write, run_dir, write_json
from pamrun.task.observation import OBSERVATION_UNITS, observation_structure

FILE_NAMES = {"onnx": "actor.onnx", "torchscript": "actor.pt"}
METADATA_KEY = "pamrun"  # ONNX metadata_props key
EXTRA_FILE = "pamrun.json"  # TorchScript extra file
ONNX_MISSING = 'ONNX export needs the onnx package: pip install "pamrun[export]"'


def check_config(config) -> None:
    """``ckpt`` must be one usable agent file, and ONNX needs onnx (run by pamrun.cli before
    the run directory exists)."""
    if config.format == "onnx" and importlib.util.find_spec("onnx") is None:
        raise ConfigError("format", ONNX_MISSING)
    spec = str(config.ckpt)
    if not spec:
        raise ConfigError("ckpt", "no checkpoint given: pass ckpt=<agent file>")
    if glob.has_magic(spec) or Path(spec).is_dir():
        raise ConfigError("ckpt", f"{spec}: name one agent file, not a directory or a glob")
    try:
        agent = load_agent(spec)
    except CheckpointError as err:
        raise ConfigError("ckpt", str(err)) from None
    if not agent.config:
        raise ConfigError("ckpt", f"{spec}: holds no robot config, so the action's scaling is unknown")


def export(dcfg) -> None:
    """The Hydra task of ``pamrun export``."""
    cfg = to_object(dcfg)
    agent = load_agent(cfg.ckpt)
    out = run_dir()
    out.mkdir(parents=True, exist_ok=True)
    meta = metadata(agent, cfg.format)
    path = out / FILE_NAMES[cfg.format]
    if cfg.format == "onnx":
        write_onnx(actor_of(agent), agent.obs_size, path, meta)
    else:
        write_torchscript(actor_of(agent), path, meta)
    write_json(out / "export.json", {"file": path.name, **meta})
    print(f"Exported {agent.label} ({cfg.format}, {agent.obs_size} observations -> {agent.action_size} actions) "
          f"to {path}; metadata in {out / 'export.json'}")


def actor_of(agent: Agent):
    """The agent's actor network in eval mode (as pamrun.evaluation.episodes.make_policy builds it)."""
    net = ThesisActor(agent.obs_size, agent.action_size, tuple(agent.hidden_sizes), init_scale=1e-3)
    net.load_state_dict(agent.actor_state)
    return net.eval()


def metadata(agent: Agent, file_format: str) -> dict[str, Any]:
    """What the exported file says about its input and output (see the module docstring)."""
    env = as_config(agent.config.get("env"), EnvConfig)
    layout = observation_structure(agent.action_size, env.speed_command, env.gait_period_s > 0)
    return {
        "format": file_format,
        "input": "observation", "output": "action",
        "observation_size": agent.obs_size, "action_size": agent.action_size,
        "observation_layout": {name: [s.start, s.stop] for name, s in layout.items()},
        "observation_units": {name: OBSERVATION_UNITS[name] for name in layout},
        "action": action_scaling(as_config(agent.config.get("muscle"), MuscleConfig)),
        "action_filter": {"alpha": env.action_filter_alpha,
                          "rule": "command = alpha * action + (1 - alpha) * previous command (0 at start); "
                                  "the observation's previous_action is the command"},
        "gait_clock": {"period_s": env.gait_period_s, "swing_share": env.swing_share,
                       "follows_speed": env.gait_follows_speed,
                       "rule": "gait_clock = sin, cos of 2 pi phase; phase = phase0 + t / period (mod 1), "
                               "any phase0; period = period_s, or with follows_speed period_s * sqrt(v0 / v*), "
                               "v0 = 2 step_length_m / period_s, v* the commanded speed; period_s 0 = no clock",
                       "step_length_m": env.step_length_m},
        "control_dt_s": env.control_dt_s,
        "checkpoint": {"path": str(agent.path.resolve()), "label": agent.label,
                       "meta": json.loads(json.dumps(agent.meta, default=str))},
        "pamrun_version": pamrun_version(),
    }


def action_scaling(muscle: MuscleConfig) -> dict[str, Any]:
    """How an action a in [-1, 1] becomes command voltages and muscle pressures."""
    reg = muscle.regulator
    if muscle.command == "independent":
        names = [f"{joint}.muscle{m}" for joint in JOINTS for m in (1, 2)]
        voltage = "V = v0_v + dv_max_v * a, per muscle"
    else:
        names = list(JOINTS)
        voltage = "V1 = v0_v + dv_max_v * a, V2 = v0_v - dv_max_v * a (the joint's muscles 1 and 2)"
    return {
        "range": [-1.0, 1.0], "command": muscle.command, "names": names,
        "v0_v": muscle.v0_v, "dv_max_v": muscle.dv_max_v, "voltage": voltage,
        "gain_kpa_per_v": reg.gain_kpa_per_v,
        "voltage_range_v": [reg.min_voltage_v, reg.max_voltage_v],
        "pressure_range_kpa": [reg.min_pressure_kpa, reg.max_pressure_kpa],
        "muscle_max_pressure_kpa": muscle.max_pressure_kpa,
        "pressure": ("P_kpa = min(clip(gain_kpa_per_v * clip(V, *voltage_range_v), *pressure_range_kpa), "
                     "muscle_max_pressure_kpa)"),
        "regulator_lag_s": reg.lag_s,
    }


def pamrun_version() -> str:
    version = getattr(pamrun, "__version__", None)
    if version is None:
        version = package_version("pamrun")
    return version


def write_onnx(net, obs_size: int, path: Path, meta: dict) -> Path:
    """``net`` as ONNX (legacy TorchScript-based exporter), batch dimension dynamic, ``meta``
    in metadata_props."""
    try:
        import onnx  # optional: only pamrun export format=onnx needs it (pip install "pamrun[export]")
    except ImportError:
        raise SystemExit(f"pamrun: {ONNX_MISSING}") from None
    buffer = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # "legacy TorchScript-based ONNX export"
        torch.onnx.export(net, (torch.zeros(1, obs_size),), buffer, input_names=["observation"],
                          output_names=["action"], dynamo=False,
                          dynamic_axes={"observation": {0: "batch"}, "action": {0: "batch"}})
    model = onnx.load_from_string(buffer.getvalue())
    onnx.helper.set_model_props(model, {METADATA_KEY: json.dumps(meta)})
    onnx.checker.check_model(model)
    return atomic_write(path, lambda tmp: onnx.save(model, str(tmp)))


def write_torchscript(net, path: Path, meta: dict) -> Path:
    """``net`` scripted, saved with ``meta`` as the extra file ``pamrun.json``."""
    scripted = torch.jit.script(net)
    return atomic_write(path, lambda tmp: torch.jit.save(scripted, str(tmp),
                                                          _extra_files={EXTRA_FILE: json.dumps(meta)}))


def read_metadata(path: str | Path) -> dict[str, Any]:
    """The metadata of an exported file (actor.onnx or actor.pt)."""
    path = Path(path)
    if path.suffix == ".onnx":
        import onnx  # optional: an ONNX file's metadata (pip install "pamrun[export]")

        props = {p.key: p.value for p in onnx.load(str(path)).metadata_props}
        return json.loads(props[METADATA_KEY])
    extra = {EXTRA_FILE: ""}
    torch.jit.load(str(path), _extra_files=extra)
    return json.loads(extra[EXTRA_FILE])
