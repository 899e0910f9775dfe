"""The ``pamrun`` command: each sub-command is a Hydra application over ``conf/config.yaml``.

``pamrun <command> [<subcommand>] [key=value ...] [hydra flags]``: the words before the
first override pick the task; the rest goes to Hydra untouched, so ``--cfg job``,
``--help``, ``-m`` (multirun) and every override work the same for every command.
Adding a command is one entry in :data:`COMMANDS`.
"""

from __future__ import annotations

import importlib
import logging
import os
import sys

from pamrun.config import CONF_DIR

# command words -> (module, function, one-line help). Functions take the composed DictConfig.
COMMANDS: dict[str, tuple[str, str, str]] = {
    "muscle step": ("pamrun.lab", "muscle_step", "step responses of one antagonistic pair vs thesis §10.1"),
    "muscle calibrate": ("pamrun.lab", "muscle_calibrate", "fit the spring table S(P) to the §10.1 step responses"),
    "muscle curves": ("pamrun.lab", "muscle_curves", "force-contraction curves and surface (Figs 8.9, 8.10)"),
    "body": ("pamrun.lab", "body", "generate the robot: robot.xml, body.json, robot.png (thesis §8.1-8.2)"),
    "openloop": ("pamrun.lab", "openloop", "pressure steps on each joint, torso fixed (thesis §10.2)"),
    "capacity": ("pamrun.lab", "capacity", "muscle torque and stiffness vs standing and walking demand, per joint"),
    "train": ("pamrun.train", "train", "train DDPG or TD3 on PamWalker-v0 with TorchRL (thesis §9)"),
    "eval": ("pamrun.evaluate", "evaluate", "test saved agents in parallel, rank them, pick the best: ckpt=<path>"),
    "sweep": ("pamrun.sweep", "job", "trainings over a grid (-m a=1,2 b=x,y), each evaluated, summary at the end"),
    "sweep summarize": ("pamrun.sweep", "summarize_command", "summary table and curves of a sweep: dir=<sweep dir>"),
    "sweep optuna": ("pamrun.search", "optuna_search", "Optuna search, each trial averaged over seeds (sweep.optuna)"),
    "plot training": ("pamrun.train", "plot_training", "redraw training.png of a run: dir=<run dir>"),
}
# Commands composed from another primary config than conf/config.yaml.
CONFIG_NAMES = {"sweep": "sweep"}
# Commands that only read a directory (dir=...): they write nothing of Hydra's there.
READ_ONLY = ("sweep summarize", "plot training")


def usage() -> str:
    width = max(len(c) for c in COMMANDS)
    lines = [
        "usage: pamrun <command> [key=value ...] [--cfg job] [--help] [-m]",
        "",
        "commands:",
        *(f"  {name:<{width}}  {text}" for name, (_, _, text) in COMMANDS.items()),
        "",
        "Each command is a Hydra app: `pamrun <command> --help` lists its config groups,",
        "`pamrun <command> --cfg job` prints the composed config.",
    ]
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
    run_hydra_app(name, rest)


def run_hydra_app(name: str, args: list[str]) -> None:
    """Run the command's task function as a Hydra app with ``args`` as its command line."""
    import hydra

    from pamrun.config import register_configs

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
        from pamrun.sweep import sweep_dir_for

        folder = sweep_dir_for(args, kind="optuna")  # the same command resumes the same study
        print(f"Study directory: {folder}")
        args = [*args, f"hydra.run.dir={folder}"]
    if name in READ_ONLY:
        folder = [a.split("=", 1)[1] for a in args if a.startswith("dir=")]
        if folder and not any(a.startswith("hydra.run.dir=") for a in args):
            args = [*args, f"hydra.run.dir={folder[-1]}", "hydra.output_subdir=null", "hydra/job_logging=stdout"]
    # argparse takes one run of overrides: flags (and their values) first, then every key=value.
    overrides = [a for a in args if "=" in a and not a.startswith("-")]
    flags = [a for a in args if a not in overrides]
    sys.argv = [f"pamrun {name}", *flags, f"hydra.job.name={job_name}", *overrides]
    config_name = CONFIG_NAMES.get(name, "config")
    app = hydra.main(config_path=str(CONF_DIR), config_name=config_name, version_base="1.3")(task)
    app()


def sweep_args(args: list[str]) -> list[str]:
    """A sweep is always a multirun, in a folder named by its command line (see pamrun.sweep)."""
    from pamrun.sweep import RUNTIME_KEYS, swept_keys, sweep_dir_for

    informational = {"--cfg", "-c", "--info", "-i", "--help", "-h", "--hydra-help"} & set(args)
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


if __name__ == "__main__":
    main()
