"""Shared fixtures: composed configs through Hydra's compose API, as the CLI builds them."""

from __future__ import annotations

import os

import pytest
from hydra import compose, initialize_config_dir

from pamrun.config import CONF_DIR, Config, register_configs, to_object

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
