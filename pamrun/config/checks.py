"""Value checks shared by the config dataclasses: each failure names its key."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

CONF_DIR = Path(__file__).resolve().parent.parent.parent / "conf"


class ConfigError(ValueError):
    """An impossible configuration value; ``key`` is its full dotted path."""

    def __init__(self, key: str, message: str):
        self.key, self.message = key, message
        super().__init__(f"{key}: {message}")


def _require(ok: bool, key: str, message: str) -> None:
    if not ok:
        raise ConfigError(key, message)


def _positive(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        _require(math.isfinite(value) and value > 0, name, f"must be > 0, got {value}")


def _non_negative(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        _require(math.isfinite(value) and value >= 0, name, f"must be >= 0, got {value}")
