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


# The recipe a test's config builds on unless it names one: experiment=walk, the plain stand-then-walk
# recipe. `pamrun train`'s default (experiment=gait) adds randomised episodes, mirroring, selection
# under perturbation and two more curriculum stages, which the tests of those features ask for by name.
TEST_RECIPE = "experiment=walk"


def compose_config(*overrides: str, recipe: str | None = TEST_RECIPE):
    """The DictConfig `pamrun <cmd> overrides...` would get (no hydra node), on ``recipe`` unless an
    override names an experiment (``recipe=None``: pamrun's own default)."""
    if recipe and not any(o.lstrip("+~").startswith("experiment=") for o in overrides):
        overrides = (recipe, *overrides)
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
