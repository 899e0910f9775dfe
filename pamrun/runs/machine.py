"""What a running pamrun process needs to know about its machine and its signals, and the
config resolvers.

Kept apart from :mod:`pamrun.config` (plain data, the bottom layer) because it asks the
operating system. Importing it registers the resolvers that ``conf/config_sweep.yaml`` and the
local launcher use (``pamrun.cli`` and ``pamrun.sweep.grid`` import it, so sweep jobs composed
in worker processes have them too).
"""

from __future__ import annotations

import contextlib
import os
import signal

from omegaconf import OmegaConf


def usable_cores() -> int:
    """Cores this process may run on (a SLURM allocation or container limit, not the whole node)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def parallel_jobs(jobs: int, workers_per_job: int) -> int:
    """Sweep jobs to run side by side: ``jobs``, or (0) the cores each job's workers leave."""
    return int(jobs) if int(jobs) > 0 else max(1, usable_cores() // max(1, int(workers_per_job)))


class Terminated(Exception):
    """SIGTERM (a scheduler's time limit, ``kill``): stop like Ctrl-C, with a final checkpoint."""


def _terminate(signum, frame) -> None:
    raise Terminated()


@contextlib.contextmanager
def stop_signals():
    """SIGTERM raises :class:`Terminated` and SIGINT KeyboardInterrupt inside, even when whatever
    started pamrun ignored SIGINT (a script's `cmd &`, some CI runners: Python then keeps SIG_IGN
    and the run would train on to its budget)."""
    previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _terminate),
                signal.SIGINT: signal.signal(signal.SIGINT, signal.default_int_handler)}
    try:
        yield
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


OmegaConf.register_new_resolver("pamrun_jobs", parallel_jobs, replace=True)
OmegaConf.register_new_resolver("pamrun_job_dir", lambda name: name or "default", replace=True)
