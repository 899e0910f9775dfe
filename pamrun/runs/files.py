"""Run directories and their files: where a command writes, atomic writes, JSON, progress.

A leaf: it imports no other pamrun module, so every command can use it.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import time
from importlib.metadata import version
from pathlib import Path
from typing import Any, Callable

from hydra.core.hydra_config import HydraConfig
from rich.console import Console
from rich.progress import BarColumn, TextColumn
from rich.progress import Progress as RichProgress
from rich.table import Column

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


def duration(seconds: float | None) -> str:
    """'1h02m', '5m03s', '42s': a duration as a progress line shows it; '?' when unknown."""
    if seconds is None or not math.isfinite(seconds):
        return "?"
    s = max(0, round(seconds))
    if s >= 3600:
        return f"{s // 3600}h{s % 3600 // 60:02d}m"
    return f"{s // 60}m{s % 60:02d}s" if s >= 60 else f"{s}s"


class Progress:
    """A progress bar on a terminal; outside one (CI, a file, a pipe) or with
    ``PAMRUN_PROGRESS=lines`` (sweep jobs share a terminal) a plain line every ``every_s`` seconds.

    :meth:`update` counts ``done`` of ``total`` ``unit`` with the time remaining at the rate since
    the start; :meth:`show` takes the fraction and the line from the caller (training's budgets).
    ``clock``: seconds, monotonic (tests pass their own)."""

    def __init__(self, console, total: int, done: int = 0, unit: str = "frames", every_s: float = 10.0,
                 clock: Callable[[], float] = time.monotonic):
        self.console, self.total, self.unit, self.every_s, self.clock = console, total, unit, every_s, clock
        self.start = (clock(), done)
        self.bar, self.last_line, self.pending = None, -math.inf, ""
        if console.is_terminal and os.environ.get("PAMRUN_PROGRESS") != "lines":
            text = TextColumn("{task.fields[text]}", markup=False, table_column=Column(overflow="fold"))
            self.bar = RichProgress(BarColumn(bar_width=30), text, console=console)  # long text: on more lines
            self.task = self.bar.add_task(unit, total=1.0, completed=done / total if total else 0.0, text="")

    def update(self, done: int, info: str = "") -> None:
        """``done`` of the total, with ``info`` after the time remaining."""
        fraction = done / self.total if self.total else 1.0
        (t0, done0), now = self.start, self.clock()
        rate = (done - done0) / (now - t0) if done > done0 and now > t0 else None
        eta = (self.total - done) / rate if rate else None
        self.show(fraction, f"{self.unit} {done}/{self.total} ({fraction:.1%})  eta {duration(eta)}  {info}".rstrip())

    def show(self, fraction: float, text: str, now: bool = False) -> None:
        """The bar at ``fraction`` with ``text``; or ``text`` as a line if ``every_s`` have passed
        since the last (at once with ``now``)."""
        if self.bar is not None:
            if not self.bar.live.is_started:  # started on first use: worker processes fork before its thread
                self.bar.start()
            self.bar.update(self.task, completed=min(fraction, 1.0), text=text)
        elif now or self.clock() - self.last_line >= self.every_s:
            self.last_line, self.pending = self.clock(), ""
            self.console.print(text, soft_wrap=True, markup=False, highlight=False)
        else:
            self.pending = text

    def stop(self) -> None:
        """The bar stopped; outside a terminal, the latest line if it was not printed."""
        if self.bar is not None:
            self.bar.stop()
        elif self.pending:
            self.console.print(self.pending, soft_wrap=True, markup=False, highlight=False)
            self.pending = ""
