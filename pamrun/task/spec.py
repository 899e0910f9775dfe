"""An agent's env: the four config sections that make its robot and task (:class:`EnvSpec`),
what an evaluation sets of every agent's task (:func:`eval_env_options`), and a perturbation
of it (:meth:`EnvSpec.perturbed`)."""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import asdict, dataclass, field
from typing import Any, get_type_hints

from omegaconf import OmegaConf

from pamrun.config import (
    ENV_SECTIONS,
    BodyConfig,
    ConfigError,
    EnvConfig,
    MuscleConfig,
    RewardConfig,
    flatten,
    to_object,
    upgrade_saved_config,
)
from pamrun.task.env import PamWalkerEnv

# env keys that change only which speed commands the episodes see and how v* moves between them: a
# transition carries its own v* (in its observation, and in its reward's terms), so a replay buffer
# gathered under other values is still this task's.
COMMAND_DRAWS = ("env.speed_range_m_s", "env.speed_changes", "env.speed_stop_share", "env.speed_ramp_m_s2")


@dataclass(frozen=True)
class EnvSpec:
    """The robot and task an agent acts in: its typed, validated ``body``, ``muscle``, ``reward``
    and ``env`` sections (:data:`pamrun.config.ENV_SECTIONS`), the keyword arguments of
    PamWalker-v0 (not gymnasium's registration ``EnvSpec``, which a gym env holds as ``env.spec``).

    A spec comes from a run's config (:meth:`from_config`) or from an agent file's ``config``
    entry (:meth:`from_dict`), which is :meth:`to_dict`: the sections as plain dicts. It is
    never changed in place: :meth:`with_values` and :meth:`perturbed` give a new spec, validated
    like any config, whose untouched sections are the same objects. :meth:`make` builds its env.
    """

    body: BodyConfig = field(default_factory=BodyConfig)
    muscle: MuscleConfig = field(default_factory=MuscleConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    env: EnvConfig = field(default_factory=EnvConfig)

    @classmethod
    def from_config(cls, cfg) -> EnvSpec:
        """The sections of ``cfg`` (a :class:`pamrun.config.Config`, validated), as the spec's own
        copies: a later change of ``cfg`` does not reach the spec."""
        return cls(**{name: copy.deepcopy(getattr(cfg, name)) for name in ENV_SECTIONS})

    @classmethod
    def from_dict(cls, data: dict | None, base: EnvSpec | None = None, **values: dict) -> EnvSpec:
        """The spec an agent file's ``config`` entry describes, in any pamrun's key names
        (:func:`pamrun.config.upgrade_saved_config`): each section it holds merged over that
        section's defaults, each it lacks (or all, for None) ``base``'s, else the defaults; then
        ``values`` (section -> key -> value) set. Validated once, after ``values``: ConfigError
        names ``<section>.<key>``; OmegaConf's errors name an unknown key or a wrong type."""
        data = upgrade_saved_config(dict(data or {}))
        sections = {name: data.get(name) or (getattr(base, name) if base else {}) for name in ENV_SECTIONS}
        return _validated(cls, sections, values)

    def to_dict(self) -> dict[str, dict]:
        """The sections as plain dicts: an agent file's ``config`` entry."""
        return {name: asdict(section) for name, section in self.sections().items()}

    def changes_to(self, other: EnvSpec) -> list[str]:
        """``key old -> new`` for each key of the sections in which ``other`` differs from this spec."""
        ours, theirs = flatten(self.to_dict()), flatten(other.to_dict())
        return [f"{k} {ours.get(k)} -> {theirs[k]}" for k in sorted(theirs) if ours.get(k) != theirs[k]]

    def transition_changes_to(self, other: EnvSpec) -> list[str]:
        """:meth:`changes_to` less :data:`COMMAND_DRAWS`: the changes that make a transition gathered
        in this spec's env another task's in ``other``'s (a replay buffer that may not be reused)."""
        return [c for c in self.changes_to(other) if c.split(" ", 1)[0] not in COMMAND_DRAWS]

    def sections(self) -> dict[str, Any]:
        """Section name -> its dataclass: PamWalker-v0's keyword arguments."""
        return {name: getattr(self, name) for name in ENV_SECTIONS}

    def make(self, **render_kwargs) -> PamWalkerEnv:
        """PamWalker-v0 of this robot and task (``render_kwargs``: render_mode, width, height, camera)."""
        return PamWalkerEnv(**self.sections(), **render_kwargs)

    def with_values(self, **values: dict) -> EnvSpec:
        """This spec with ``values`` (section -> key -> value) set; a new spec, validated
        (ConfigError names ``<section>.<key>``)."""
        typed = {}
        for name, changes in values.items():
            try:
                typed[name] = _validated(SECTION_TYPES[name], getattr(self, name), changes)
            except ConfigError as err:
                raise ConfigError(f"{name}.{err.key}", err.message) from None
        return dataclasses.replace(self, **typed)

    def perturbed(self, perturbation, where: str, strength: float = 1.0) -> EnvSpec:
        """This robot and task under ``perturbation`` (a :class:`pamrun.config.Perturbation`):
        its ``scale`` factors times the spec's values, then its ``values``; validated like any
        config. An unknown key, a factor on a non-number or an impossible result raises
        ConfigError naming ``<where>.scale|values.<section>.<key>``.

        ``strength`` s goes part of the way (or beyond, s > 1): a factor f becomes 1 + s (f - 1),
        a numeric value v the spec's v0 + s (v - v0) (elementwise for lists); other values are
        set as they are. s = 1 is the perturbation itself (training's domain randomisation draws
        s). Always a new spec; the sections the perturbation leaves alone are the same objects."""
        changed: dict[str, dict] = {}  # section -> its dict, copied when first touched
        keys: dict[str, str] = {}  # dotted key -> its name in the perturbation
        for kind in ("scale", "values"):
            for dotted, value in flatten(getattr(perturbation, kind)).items():
                keys[dotted] = key = f"{where}.{kind}.{dotted}"
                section, *path = dotted.split(".")
                if section not in changed:
                    changed[section] = asdict(getattr(self, section))
                _change(changed[section], section, path, key, value, kind == "scale", strength)
        typed = {}
        for section in sorted(changed):
            try:
                typed[section] = _validated(SECTION_TYPES[section], changed[section])
            except ConfigError as err:
                name = f"{section}.{err.key}"
                raise ConfigError(keys.get(name, f"{where} ({name})"), err.message) from None
            except Exception as err:  # OmegaConf: a value of the wrong type
                raise ConfigError(where, str(err).splitlines()[0]) from None
        return dataclasses.replace(self, **typed)


SECTION_TYPES: dict[str, type] = get_type_hints(EnvSpec)  # section name -> its dataclass


def eval_env_options(ecfg) -> dict:
    """What an evaluation sets of every agent's task (``eval``: a
    :class:`pamrun.config.EvalConfig`), in ``pamrun eval`` and in the selection evaluations during
    training alike: its start noise and episode length, and a commanded speed held for the whole
    episode (``eval.speed_m_s``), or a schedule of them (``eval.speed_schedule``), else the
    agent's own v* (``env.target_speed_m_s``), and how fast v* follows a change
    (``eval.speed_ramp_m_s2``, else the agent's own), never a drawn range or drawn changes: the walk
    test is defined at one speed, so a run that trains over drawn speeds is selected at it."""
    options = {"reset_noise_rad": ecfg.reset_noise_rad, "reset_velocity_noise": ecfg.reset_velocity_noise,
               "episode_s": ecfg.episode_s}
    speed = {} if ecfg.speed_m_s is None else {"target_speed_m_s": ecfg.speed_m_s, "speed_schedule": []}
    if ecfg.speed_schedule:
        speed = {"speed_schedule": [list(e) for e in ecfg.speed_schedule]}
    if ecfg.speed_ramp_m_s2 is not None:
        speed["speed_ramp_m_s2"] = ecfg.speed_ramp_m_s2
    return {**options, "speed_range_m_s": [], "speed_changes": 0, "speed_stop_share": 0.0, **speed}


def _validated(cls: type, *layers: Any) -> Any:
    """A ``cls`` from ``layers`` (dicts or dataclasses) merged in order over its defaults through
    OmegaConf (an unknown key or a wrong type fails naming it), then validated
    (:func:`pamrun.config.to_object`: ConfigError names the key)."""
    return to_object(OmegaConf.merge(OmegaConf.structured(cls), *layers))


def _change(node: dict, section: str, path: list[str], key: str, value: Any, scale: bool, strength: float) -> None:
    """Set (or, with ``scale``, multiply) ``node``'s value at ``path``, ``strength`` of the way;
    ConfigError naming ``key`` where there is no such value or it cannot be scaled."""
    for name in path[:-1]:
        if not isinstance(node.get(name), dict):
            raise ConfigError(key, f"unknown key: {section} has no section {name!r}")
        node = node[name]
    if path[-1] not in node:
        raise ConfigError(key, f"unknown key; known: {', '.join(sorted(node))}")
    old = node[path[-1]]
    if scale:
        numbers = old if isinstance(old, list) else [old]
        if not all(_number(v) for v in numbers):
            raise ConfigError(key, f"cannot scale {old!r}, which is not a number")
        value = value if strength == 1 else 1 + strength * (value - 1)
        value = [v * value for v in numbers] if isinstance(old, list) else type(old)(old * value)
    elif strength != 1:
        value = _partway(old, value, strength)
    node[path[-1]] = value


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _partway(old: Any, new: Any, strength: float) -> Any:
    """old + strength (new - old) for numbers and lists of numbers; ``new`` for anything else."""
    if isinstance(old, list) and isinstance(new, list) and len(old) == len(new) and all(map(_number, old + new)):
        return [o + strength * (n - o) for o, n in zip(old, new)]
    return type(old)(old + strength * (new - old)) if _number(old) and _number(new) else new
