"""Domain randomisation during training (``train.randomize``): the robustness suite's
perturbations, drawn per episode.

Each episode, with probability ``train.randomize_prob``, the robot and task carry
``train.randomize_count`` distinct perturbations named in ``train.randomize`` (defined in
``eval.perturbations``, the suite's own: mass, friction, regulator lag, top pressure,
observation and start noise, pushes), drawn uniformly or, with ``train.randomize_weights``, in
proportion to their weights (1 for a name it leaves out; drawn without replacement, so a name
of weight w among n of weight 1 comes first with chance w / (w + n)), each at its own
strength s drawn uniformly in [0, ``train.randomize_reach``] (or the name's own
``train.randomize_reaches``) of the way from the run's own config to it
(:meth:`pamrun.task.spec.EnvSpec.perturbed`: a factor f becomes 1 + s (f - 1); s > 1 goes beyond the
suite's size, for a margin). Factors compose (mass x1.1 and x0.9 both drawn: their product);
two perturbations that set the same value (the pushes) are never drawn together. A push comes at a time drawn uniformly between 1 s
and 1 s before the episode's end, so a policy cannot learn when it comes. Otherwise the
episode is the run's nominal robot and task. The draws come from the env's own seeded
generator, so a run stays reproducible.

The env is rebuilt for a perturbed episode (the suite's mechanism, so training and testing
perturb alike); the nominal one is kept and reused.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from pamrun.config import Config, ConfigError, flatten
from pamrun.config.task import TERRAIN_KEYS
from pamrun.task.env import PamWalkerEnv
from pamrun.task.spec import EnvSpec

PUSH_MARGIN_S = 1.0  # a randomised push starts at least this long after the start and before the end


class RandomizedWalker(gym.Env):
    """PamWalker-v0 whose robot and task are redrawn at every reset (module docstring)."""

    metadata = PamWalkerEnv.metadata

    def __init__(self, spec: EnvSpec, perturbations: dict[str, Any], prob: float, reach: float,
                 count: int = 1, weights: dict[str, float] | None = None, reaches: dict[str, float] | None = None,
                 options: dict[str, Any] | None = None):
        self.options = dict(options or {})  # PamWalkerEnv's keyword arguments beyond the spec (features, lean_info)
        self.nominal_spec, self.perturbations, self.prob, self.count = spec, perturbations, prob, count
        self.reach = {n: (reaches or {}).get(n, reach) for n in perturbations}  # each name's reach
        self.names = sorted(perturbations)
        w = np.array([(weights or {}).get(n, 1.0) for n in self.names])
        self.p = w / w.sum() if weights else None  # draw probabilities in names order (None: uniform)
        self.nominal = self.env = spec.make(**self.options)
        self.action_space, self.observation_space = self.env.action_space, self.env.observation_space
        self.drawn: tuple[tuple[str, float], ...] = ()  # this episode's perturbations and strengths

    @classmethod
    def from_config(cls, spec: EnvSpec, cfg: Config, options: dict[str, Any] | None = None) -> RandomizedWalker:
        """The env ``cfg.train``'s randomisation settings describe, around the robot and task ``spec``."""
        t = cfg.train
        return cls(spec, {n: cfg.eval.perturbations[n] for n in t.randomize}, t.randomize_prob, t.randomize_reach,
                   t.randomize_count, t.randomize_weights, t.randomize_reaches, options)

    def draw(self) -> EnvSpec:
        """This episode's robot and task (and ``self.drawn``)."""
        rng = self.np_random
        self.drawn = ()
        if not self.names or rng.random() >= self.prob:
            return self.nominal_spec
        spec, taken = self.nominal_spec, set()
        n = len(self.names)
        order = rng.permutation(n) if self.p is None else rng.choice(n, size=n, replace=False, p=self.p)
        for k in order.tolist():
            name = self.names[k]
            sets = set(flatten(self.perturbations[name].values))
            sets |= TERRAIN_KEYS if sets & TERRAIN_KEYS else set()  # one terrain at a time (env.slope_deg's check)
            if len(self.drawn) == self.count or sets & taken:
                continue
            strength = float(rng.uniform(0.0, self.reach[name]))
            spec = spec.perturbed(self.perturbations[name], f"train.randomize.{name}", strength)
            self.drawn, taken = (*self.drawn, (name, strength)), taken | sets
        env = spec.env
        if any(env.push_impulse_ns):  # drawn whenever the task pushes; it applies where a draw changed the task
            latest = env.episode_s - PUSH_MARGIN_S - env.push_duration_s
            push_time_s = float(rng.uniform(PUSH_MARGIN_S, max(PUSH_MARGIN_S, latest)))
            if env is not self.nominal_spec.env:
                spec = spec.with_values(env={"push_time_s": push_time_s})
        return spec

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        spec = self.draw()
        new = self.nominal if spec is self.nominal_spec else spec.make(**self.options)
        if self.env is not self.nominal and self.env is not new:
            self.env.close()
        self.env = new
        return self.env.reset(seed=int(self.np_random.integers(2**31)), options=options)

    def step(self, action):
        return self.env.step(action)

    def close(self):
        if self.env is not self.nominal:
            self.env.close()
        self.nominal.close()


def check(cfg: Config) -> None:
    """Every perturbation ``train.randomize`` names applies to the run's robot and task, at its
    full reach too (friction x0.7 at reach 4 would be negative): a ConfigError naming the key
    otherwise, before the run writes anything (its names are checked against
    ``eval.perturbations`` with the config)."""
    spec, t = EnvSpec.from_config(cfg), cfg.train
    for name in t.randomize:
        spec.perturbed(cfg.eval.perturbations[name], f"eval.perturbations.{name}")
        reach = t.randomize_reaches.get(name, t.randomize_reach)
        try:
            spec.perturbed(cfg.eval.perturbations[name], f"eval.perturbations.{name}", reach)
        except ConfigError as e:
            key = f"train.randomize_reaches.{name}" if name in t.randomize_reaches else "train.randomize_reach"
            raise ConfigError(key, f"{name} at strength {reach:g} is impossible: {e}") from None
