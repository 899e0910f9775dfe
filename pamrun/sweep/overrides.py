"""A sweep's command line: its config overrides, which of them sweep, and the folder it is named by.

Light on purpose (Hydra's override parser only): ``pamrun.cli`` imports it to name a sweep's
folder before the sweep's own modules load.
"""

from __future__ import annotations

import hashlib

from hydra.core.override_parser.overrides_parser import OverridesParser


def task_overrides(args: list[str]) -> list[str]:
    """The config overrides of a command line (no flags, nothing of Hydra's own)."""
    return [a for a in args if "=" in a and not a.startswith(("hydra.", "hydra/", "-", "+hydra", "~hydra"))]


def swept_keys(args: list[str]) -> tuple[list[str], list[str]]:
    """Keys of the overrides that sweep (``a=1,2``, ``range(...)``, ...) and of those that do not."""
    parsed = OverridesParser.create().parse_overrides(task_overrides(args))
    swept = [o.key_or_group for o in parsed if o.is_sweep_override()]
    return swept, [o.key_or_group for o in parsed if not o.is_sweep_override()]


# How a sweep runs, not what it computes: left out of its folder's name, so changing them resumes it.
RUNTIME_KEYS = ("sweep.jobs", "sweep.optuna.trials", "eval.workers", "train.threads")


def sweep_dir_for(args: list[str], kind: str = "sweep") -> str:
    """``multirun/<kind>-<swept keys>-<hash>``: the same command line always gets the same folder
    (whatever the order of its overrides, the launcher or :data:`RUNTIME_KEYS`)."""
    identity = sorted(a for a in task_overrides(args) if a.lstrip("+~").split("=", 1)[0] not in RUNTIME_KEYS)
    digest = hashlib.sha1("\n".join(identity).encode()).hexdigest()[:8]
    name = "-".join(sorted(swept_keys(args)[0]))[:60] or "single"
    return f"multirun/{kind}-{name}-{digest}" if kind == "sweep" else f"multirun/{kind}-{digest}"
