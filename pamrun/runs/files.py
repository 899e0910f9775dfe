"""Run directories and their files: where a command writes, atomic writes, JSON, progress.

A leaf: it imports no other pamrun module, so every command can use it.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from importlib.metadata import version
from pathlib import Path
from typing import Any, Callable

from hydra.core.hydra_config import HydraConfig
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress

# Outside a terminal (a log file, a pipe, CI) the console is this wide, so that no table cuts a
# cell with "…" and no path is broken: rich draws a table only as wide as its content.
LOG_WIDTH = 400


def console():
    """The console a command prints to: a terminal's own width, or LOG_WIDTH outside one."""
    terminal = Console()
    return terminal if terminal.is_terminal else Console(width=LOG_WIDTH)


def run_dir() -> Path:
    """The Hydra run directory of this job (created by Hydra), announced on the console."""
    path = Path(HydraConfig.get().runtime.output_dir)
    Console().print(f"Run directory: [bold]{path}[/bold]")
    return path


def atomic_write(path: Path, write: Callable[[Path], Any]) -> Path:
    """``write(tmp)`` to a temporary file beside ``path``, then rename it over ``path``:
    a crash at any moment leaves the old file or the new one, never a torn one."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    write(tmp)
    os.replace(tmp, path)
    return path


def atomic_save(obj: Any, path: Path) -> Path:
    """``torch.save`` through :func:`atomic_write`."""
    import torch  # heavy (~1 s): only checkpoints need it, and every command imports this module

    return atomic_write(path, lambda tmp: torch.save(obj, tmp))


def write_json(path: Path, data: Any) -> Path:
    """Indented JSON through :func:`atomic_write`."""
    return atomic_write(path, lambda tmp: tmp.write_text(json.dumps(data, indent=2)))


def read_json(path: Path) -> dict[str, Any]:
    """A JSON file a run or job left (run.json, job.json, ...), or {} if it is not there yet."""
    path = Path(path)
    return json.loads(path.read_text()) if path.exists() else {}


def git_commit(here: Path | None = None) -> str | None:
    """The commit of the pamrun checkout that runs (or of ``here``), if it is a git checkout;
    ``-dirty`` appended when its tracked files differ from that commit (the run's code is
    then not the commit's)."""
    here = here or Path(__file__).parent
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True,
                                cwd=here).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True, check=True, cwd=here).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
    return commit + ("-dirty" if dirty else "")


def package_versions() -> dict[str, str]:
    return {name: version(name) for name in ("pamrun", "torch", "torchrl", "tensordict", "mujoco", "gymnasium",
                                             "numpy", "hydra-core")}


class Progress:
    """A rich progress bar with ETA on a terminal; a plain line every ~10 s otherwise (CI, files)."""

    def __init__(self, console, total: int, done: int, unit: str = "frames"):
        self.console = console
        self.unit = unit
        self.bar = None
        self.last_line = 0.0
        if console.is_terminal and os.environ.get("PAMRUN_PROGRESS") != "lines":  # sweep jobs share a terminal
            self.bar = RichProgress(TextColumn(unit), BarColumn(), MofNCompleteColumn(),
                                    TextColumn("{task.fields[info]}"), TimeElapsedColumn(), TextColumn("ETA"),
                                    TimeRemainingColumn(), console=console)
            self.task = self.bar.add_task(unit, total=total, completed=done, info="")

    def update(self, done: int, info: str) -> None:
        if self.bar is not None:
            if not self.bar.live.is_started:  # started on first use: worker processes fork before its thread
                self.bar.start()
            self.bar.update(self.task, completed=done, info=info)
        elif time.monotonic() - self.last_line > 10:
            self.last_line = time.monotonic()
            self.console.print(f"{self.unit} {done}  {info}", soft_wrap=True)

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()
