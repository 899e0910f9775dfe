"""An agent's env: the config sections that make its robot and task, and a perturbation of them."""

from __future__ import annotations

import copy
from dataclasses import asdict
from typing import Any


def _section_types() -> dict[str, type]:
    from pamrun.config import BodyConfig, EnvConfig, MuscleConfig, RewardConfig

    return {"body": BodyConfig, "muscle": MuscleConfig, "reward": RewardConfig, "env": EnvConfig}


SECTION_TYPES = _section_types()  # ENV_SECTIONS -> their dataclasses


def perturb(kwargs: dict[str, dict], perturbation, where: str, strength: float = 1.0) -> dict[str, dict]:
    """``kwargs`` (an agent's env sections) under ``perturbation``: its ``scale`` factors times
    the agent's values, then its ``values``; validated like any config. An unknown key, a
    factor on a non-number or an impossible result raises ConfigError naming
    ``<where>.scale|values.<section>.<key>``.

    ``strength`` s goes part of the way (or beyond, s > 1): a factor f becomes 1 + s (f - 1), a
    numeric value v the agent's v0 + s (v - v0) (elementwise for lists); other values are set
    as they are. s = 1 is the perturbation itself (training's domain randomisation draws s).
    Sections the perturbation does not touch are returned as the same objects."""
    from pamrun.config import ConfigError, flatten
    from pamrun.task.env import as_config

    out = dict(kwargs)  # sections are copied when first changed; the others stay the same objects
    changed, touched = {}, set()
    for kind in ("scale", "values"):
        for dotted, value in flatten(getattr(perturbation, kind)).items():
            key = f"{where}.{kind}.{dotted}"
            section, *path = dotted.split(".")
            if section not in touched:
                out[section], touched = copy.deepcopy(kwargs[section]), touched | {section}
            node = out[section]
            for name in path[:-1]:
                if not isinstance(node.get(name), dict):
                    raise ConfigError(key, f"unknown key: {section} has no section {name!r}")
                node = node[name]
            if path[-1] not in node:
                raise ConfigError(key, f"unknown key; known: {', '.join(sorted(node))}")
            old = node[path[-1]]
            if kind == "scale":
                numbers = old if isinstance(old, list) else [old]
                if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in numbers):
                    raise ConfigError(key, f"cannot scale {old!r}, which is not a number")
                value = value if strength == 1 else 1 + strength * (value - 1)
                value = [v * value for v in numbers] if isinstance(old, list) else type(old)(old * value)
            elif strength != 1:
                value = _partway(old, value, strength)
            node[path[-1]] = value
            changed[dotted] = key
    for section in sorted(touched):  # validated like any config (the others are as they were)
        try:
            out[section] = asdict(as_config(out[section], SECTION_TYPES[section]))
        except ConfigError as err:
            name = f"{section}.{err.key}"
            raise ConfigError(changed.get(name, f"{where} ({name})"), err.message) from None
        except Exception as err:  # OmegaConf: a value of the wrong type
            raise ConfigError(where, str(err).splitlines()[0]) from None
    return out


def _partway(old: Any, new: Any, strength: float) -> Any:
    """old + strength (new - old) for numbers and lists of numbers; ``new`` for anything else."""
    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new) and all(map(number, old + new)):
        return [o + strength * (n - o) for o, n in zip(old, new)]
    return type(old)(old + strength * (new - old)) if number(old) and number(new) else new
