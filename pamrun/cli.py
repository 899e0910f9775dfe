"""The ``pamrun`` command: each sub-command is a Hydra application over ``conf/config.yaml``.

``pamrun <command> [<subcommand>] [key=value ...] [hydra flags]``: the words before the
first override pick the task; the rest goes to Hydra untouched, so ``--cfg job``,
``--help``, ``-m`` (multirun) and every override work the same for every command.
Adding a command is one entry in :data:`COMMANDS` (and, for its own checks, a
``check_config`` function in its module); :data:`CONFIG_NAMES` and :data:`READ_ONLY` say
when it composes another primary config or only reads a directory.
"""

from __future__ import annotations

import importlib
import logging
import os
import sys
from pathlib import Path
from typing import Any

import hydra
import yaml
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf

from pamrun.config import CONF_DIR, Config, ConfigError, register_configs, validate
from pamrun.config.docs import describe
from pamrun.runs import machine  # noqa: F401  (registers the config resolvers)
from pamrun.sweep.overrides import RUNTIME_KEYS, sweep_dir_for, swept_keys, task_overrides

# command words -> (module, function, one-line help). Functions take the composed DictConfig.
# A module may also define ``check_config(config)``: what its command needs beyond valid
# values (e.g. ``pamrun eval``: a checkpoint to read), checked before its directory exists.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "muscle step": ("pamrun.bench.muscle", "muscle_step", "step responses of one antagonistic pair vs thesis §10.1"),
    "muscle calibrate": ("pamrun.bench.muscle", "muscle_calibrate", "fit the spring table S(P) to the §10.1 step responses"),
    "muscle curves": ("pamrun.bench.muscle", "muscle_curves", "both force laws vs measured, and the surface (Figs 8.9, 8.10)"),
    "muscle valve": ("pamrun.bench.muscle", "muscle_valve", "regulator step 0 -> 600 kPa: model=lag vs model=flow, rise times"),
    "muscle hysteresis": ("pamrun.bench.muscle", "muscle_hysteresis", "a muscle cycled at one pressure: the loop, its area"),
    "body": ("pamrun.bench.robot", "generate_body", "generate the robot: robot.xml, body.json, robot.png (thesis §8.1-8.2)"),
    "openloop": ("pamrun.bench.robot", "openloop", "pressure steps on each joint, torso fixed (thesis §10.2)"),
    "capacity": ("pamrun.bench.robot", "check_capacity", "muscle torque and stiffness vs standing and walking demand, per joint"),
    "train": ("pamrun.training.recipe", "main", "train DDPG, TD3 or SAC on PamWalker-v0 with TorchRL (thesis §9)"),
    "eval": ("pamrun.evaluation.evaluate", "evaluate", "test saved agents in parallel, rank them, pick the best: ckpt=<path>"),
    "export": ("pamrun.evaluation.export", "export", "write an agent's policy as ONNX or TorchScript with its metadata: ckpt=<file>"),
    "sweep": ("pamrun.sweep.grid", "job", "trainings over a grid (-m a=1,2 b=x,y), each evaluated, summary at the end"),
    "sweep summarize": ("pamrun.sweep.grid", "summarize_command", "summary table and curves of a sweep: dir=<sweep dir>"),
    "sweep optuna": ("pamrun.sweep.search", "optuna_search", "Optuna search, each trial averaged over seeds (sweep.optuna)"),
    "plot training": ("pamrun.training.console", "plot_training", "redraw training.png of a run: dir=<run dir>"),
}
# Commands composed from another primary config than conf/config.yaml.
CONFIG_NAMES = {"sweep": "config_sweep"}
# Commands that only read a directory (dir=...): they write nothing of Hydra's there.
READ_ONLY = ("sweep summarize", "plot training")
# Config sections `pamrun <command> --help` documents (every key of them, with its doc).
ROBOT = ("muscle", "body")
TASK = ("seed", *ROBOT, "reward", "env")
HELP_SECTIONS: dict[str, tuple[str, ...]] = {
    "muscle step": ("muscle", "pair"), "muscle calibrate": ("muscle", "pair"), "muscle curves": ("muscle",),
    "muscle valve": ("muscle",), "muscle hysteresis": ("muscle",),
    "body": ("body",), "openloop": (*ROBOT, "env"), "capacity": ROBOT,
    "train": (*TASK, "algo", "train", "eval", "resume"), "eval": ("ckpt", "eval", *TASK),
    "export": ("ckpt", "format"),
    "sweep": ("sweep", *TASK, "algo", "train", "eval"), "sweep optuna": ("sweep", *TASK, "algo", "train", "eval"),
    "sweep summarize": ("dir", "sweep"), "plot training": ("dir",),
}


def usage() -> str:
    width = max(len(c) for c in COMMANDS)
    lines = [
        "usage: pamrun <command> [key=value ...] [--cfg job] [--help] [-m]",
        "",
        "commands:",
        *(f"  {name:<{width}}  {text}" for name, (_, _, text) in COMMANDS.items()),
        "",
        "Each command is a Hydra app: `pamrun <command> --help` lists its config groups and",
        "documents every key it uses; `pamrun <command> --cfg job` prints the composed config.",
    ]
    return "\n".join(lines)


def command_help(name: str) -> str:
    """`pamrun <command> --help`: its config groups and options, and every key it uses with its doc."""
    chosen = {}
    for entry in yaml.safe_load((CONF_DIR / "config.yaml").read_text())["defaults"]:
        if isinstance(entry, dict):
            chosen.update({k: v for k, v in entry.items() if "/" not in k and not k.startswith("override")})
    sections = HELP_SECTIONS.get(name, tuple(chosen))
    lines = [f"pamrun {name}: {COMMANDS[name][2]}", "",
             f"usage: pamrun {name} [group=option ...] [key=value ...] [--cfg job] [-m]", "",
             "Config groups (group=option, * marks the default):"]
    for group, default in chosen.items():
        if group in sections:
            options = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))
            lines.append(f"  {group:<8} " + ", ".join(f"{o}*" if o == default else o for o in options))
    if name.startswith("sweep") and name != "sweep summarize":
        launchers = sorted(p.stem for p in (CONF_DIR / "hydra" / "launcher").glob("*.yaml"))
        lines.append("  hydra/launcher " + ", ".join(f"{o}*" if o == "local" else o for o in launchers))
    lines += ["", "Config keys (key = default  # what it is; override with key=value):"]
    for key, value, doc in describe(Config):
        if key.split(".")[0] in sections:
            lines.append(f"  {key} = {value!r}" + (f"  # {doc}" if doc else ""))
    lines += ["", f"Hydra's own flags: pamrun {name} --hydra-help"]
    return "\n".join(lines)


def split_command(argv: list[str]) -> tuple[str | None, list[str]]:
    """Longest run of leading words that names a command, and the remaining arguments."""
    for n in (2, 1):
        name = " ".join(argv[:n])
        if len(argv) >= n and name in COMMANDS:
            return name, argv[n:]
    return None, argv


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    name, rest = split_command(argv)
    if name is None:
        if argv and argv[0] not in ("-h", "--help"):
            print(f"pamrun: unknown command {' '.join(argv[:2])!r}\n", file=sys.stderr)
            print(usage(), file=sys.stderr)
            raise SystemExit(2)
        print(usage())
        return
    if "--help" in rest or "-h" in rest:
        print(command_help(name))
        return
    run_hydra_app(name, rest)


def run_hydra_app(name: str, args: list[str]) -> None:
    """Run the command's task function as a Hydra app with ``args`` as its command line."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    logging.getLogger("OpenGL").setLevel(logging.WARNING)  # PyOpenGL's import chatter
    register_configs()
    module, func, _ = COMMANDS[name]
    task = getattr(importlib.import_module(module), func)
    job_name = name.replace(" ", "_")
    resume = [a.split("=", 1)[1] for a in args if a.startswith("resume=")]
    if resume:  # continue in the run's own directory; keep its original .hydra/ untouched
        args = [*args, f"hydra.run.dir={resume[-1]}", "hydra.output_subdir=.hydra-resume"]
    if name == "sweep":
        args = sweep_args(args)
    if name == "sweep optuna" and not any(a.startswith("hydra.run.dir=") for a in args):
        folder = sweep_dir_for(args, kind="optuna")  # the same command resumes the same study
        print(f"Study directory: {folder}")
        args = [*args, f"hydra.run.dir={folder}"]
    if name in READ_ONLY:
        folder = [a.split("=", 1)[1] for a in args if a.startswith("dir=")]
        if folder and not any(a.startswith("hydra.run.dir=") for a in args):
            args = [*args, f"hydra.run.dir={folder[-1]}", "hydra.output_subdir=null", "hydra/job_logging=stdout"]
    # argparse takes one run of overrides: flags (and their values) first, then every key=value.
    overrides = [a for a in args if "=" in a and not a.startswith("-")]
    check_no_empty_dicts(overrides)
    flags = [a for a in args if a not in overrides]
    sys.argv = [f"pamrun {name}", *flags, f"hydra.job.name={job_name}", *overrides]
    config_name = CONFIG_NAMES.get(name, "config")
    app = hydra.main(config_path=str(CONF_DIR), config_name=config_name, version_base="1.3")(task)
    app()


def sweep_args(args: list[str]) -> list[str]:
    """A sweep is always a multirun, in a folder named by its command line (pamrun.sweep.overrides)."""
    informational = {"--cfg", "-c", "--info", "-i", "--help", "-h", "--hydra-help"} & set(args)
    check_group_options(args)
    if not informational and not {"-m", "--multirun"} & set(args):
        args = ["-m", *args]
    if not any(a.startswith("hydra.sweep.dir=") for a in args):
        folder = sweep_dir_for(args)
        if not informational:
            print(f"Sweep directory: {folder}")
        args = [*args, f"hydra.sweep.dir={folder}"]
    # Job folders are named by the swept overrides only (the rest is the same for all jobs).
    fixed = swept_keys(args)[1] + list(RUNTIME_KEYS)
    return [*args, f"hydra.job.config.override_dirname.exclude_keys=[{','.join(fixed)}]"]


def check_no_empty_dicts(overrides: list[str]) -> None:
    """``key={}`` changes nothing (Hydra merges a dict given on the command line into the preset's), so
    it fails, naming the key, rather than leave a preset's entries in place unsaid."""
    for override in overrides:
        key, _, value = override.partition("=")
        if value.replace(" ", "") == "{}":
            raise SystemExit(f"pamrun: invalid configuration: {key.lstrip('+~')}={{}} would change nothing: "
                             f"Hydra merges a dict given on the command line into the preset's; "
                             f"set its entries one by one ({key.lstrip('+~')}.<name>=<value>)")


def check_group_options(args: list[str]) -> None:
    """Every option named for a config group (``algo=ppo,td3``) must exist, before Hydra
    creates a sweep folder for jobs that could never compose."""
    for override in OverridesParser.create().parse_overrides(task_overrides(args)):
        group = override.key_or_group
        if "." in group or not (CONF_DIR / group).is_dir():
            continue
        values = override.sweep_string_iterator() if override.is_sweep_override() else [override.value()]
        known = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))
        for value in values:
            if str(value) not in known:
                raise SystemExit(f"pamrun: invalid configuration: {group}: no option {value!r}; "
                                 f"known: {', '.join(known)}")


def _check_writable(run_dir: str | None) -> None:
    """The run directory (or the nearest folder that exists above it) must take new files."""
    if not run_dir:
        return
    path = Path(run_dir).resolve()
    while not path.exists():
        path = path.parent
    if not path.is_dir():
        raise ConfigError("hydra.run.dir", f"{path} is a file, not a folder")
    if not os.access(path, os.W_OK | os.X_OK):
        raise ConfigError("hydra.run.dir", f"{path} is not writable")


class ValidateConfig(Callback):
    """Hydra callback (``conf/config.yaml``): validate values before Hydra creates the run directory."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        _validate_or_exit(config)

    def on_job_start(self, config: DictConfig, **kwargs: Any) -> None:
        # Multirun jobs are composed inside the launcher; a bad one fails alone. A sweep job
        # validates inside its task instead, so the failure is recorded and the others go on.
        if OmegaConf.select(config, "hydra.job.name", default="") != "sweep":
            _validate_or_exit(config)


def _validate_or_exit(config: DictConfig) -> None:
    try:
        validate(config)
        _check_writable(OmegaConf.select(config, "hydra.run.dir", default=None))
        name = OmegaConf.select(config, "hydra.job.name", default="").replace("_", " ")
        if name in COMMANDS:
            check = getattr(importlib.import_module(COMMANDS[name][0]), "check_config", None)
            if check is not None:
                check(config)
    except ConfigError as err:
        raise SystemExit(f"pamrun: invalid configuration: {err}") from None


if __name__ == "__main__":
    main()
