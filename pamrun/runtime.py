"""What a running pamrun process needs to know about its machine, and the config resolvers.

Kept apart from :mod:`pamrun.config` (plain data, the bottom layer) because it asks the
operating system. Importing it registers the resolvers that ``conf/sweep.yaml`` and the
local launcher use (``pamrun.cli`` and ``pamrun.sweep`` import it, so sweep jobs composed
in worker processes have them too).
"""

from __future__ import annotations

import os

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


OmegaConf.register_new_resolver("pamrun_jobs", parallel_jobs, replace=True)
OmegaConf.register_new_resolver("pamrun_job_dir", lambda name: name or "default", replace=True)
