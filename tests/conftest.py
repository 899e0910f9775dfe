"""Shared fixtures: composed configs through Hydra's compose API, as the CLI builds them."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from hydra import compose, initialize_config_dir

from pamrun.config import CONF_DIR, Config, register_configs, to_object
from pamrun.runs import machine  # noqa: F401  (registers the resolvers conf/config_sweep.yaml uses, as pamrun.cli does)

os.environ.setdefault("MUJOCO_GL", "egl")
register_configs()


def compose_config(*overrides: str):
    """The DictConfig `pamrun <cmd> overrides...` would get (no hydra node)."""
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        return compose("config", overrides=list(overrides))


@pytest.fixture
def cfg() -> Config:
    """The default configuration as validated dataclasses."""
    return to_object(compose_config())


def thesis_muscle():
    """The thesis' muscle model (``muscle=thesis``) as a validated MuscleConfig."""
    return to_object(compose_config("muscle=thesis")).muscle


def run_pamrun(*args: str, cwd=None) -> subprocess.CompletedProcess:
    """The ``pamrun`` command line in a fresh interpreter, output captured."""
    return subprocess.run(
        [sys.executable, "-m", "pamrun.cli", *args], capture_output=True, text=True, cwd=cwd, timeout=300
    )
