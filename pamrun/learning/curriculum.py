"""Curricula over the reward: the learner's weights change during training, the env's do not.

The env returns its reward's unweighted terms by weight key (``info["reward_unweighted"]``:
:mod:`pamrun.task.reward`), and training stores them in its replay buffer under
``("next", "reward_unweighted", <key>)`` (:class:`FeatureReader`). A :class:`Reweight` transform on
the buffer gives every sample, old or new, the reward of other weights:
r' = r + sum_k (w'_k - w_k) f_k, matched by key. Training's env computes every term, at any weight
(its ``features``: :data:`COMPUTED`), so that a later run from the buffer
(``train.init_from``) may weigh any term its pamrun knew. Transitions whose
physics blew up have all features 0, so they keep their reward (0). The env, its logs and
``pamrun eval`` keep the config's weights.

:class:`WalkCurriculum` (``train.walk_kvx``, ``train.walk_weights``): stand first, then walk.
Until the "stand, learned" milestone (:func:`pamrun.task.criteria.stands_learned`) the learner
optimises the env's reward; from it on, the forward weight is ``walk_kvx`` instead of
``reward.kvx``, and every weight in ``walk_weights`` replaces the env's. The stage is a
function of the run's evaluations (``evals.csv``), so a resumed run takes it up where it was.
A run from a trained agent (``train.init_from``) is at its last stage from its first frame: gait where
it has ``train.gait_weights``, walking otherwise.
``train.gait_weights`` adds a third stage, gait: from the walking stage's first evaluation in
which every episode passes the walk test (or, with ``train.gait_from_distance_m``, stands the
whole episode and covers that distance), its weights replace those of the walking stage (a
run that first learns to walk, however it can, then how: a flight or a crouch charged from the
start keeps it from learning to walk at all). In it, ``train.adapt_weights`` rise by
``train.adapt_factor`` after each evaluation that meets that milestone again, up to their caps,
and fall back after one that does not: the largest costs the walk bears.
"""

from __future__ import annotations

import torch
from tensordict import TensorDict
from torchrl.data import Composite, Unbounded
from torchrl.envs.gym_like import BaseInfoDictReader
from torchrl.envs.transforms import Transform

from pamrun.config import Config
from pamrun.task.criteria import stands_learned
from pamrun.task.reward import REWARD_KEYS

FEATURES = "reward_unweighted"  # the replay buffer's key (under "next") of the unweighted terms, by weight key
COMPUTED = REWARD_KEYS  # the terms training's env computes, at any weight (its features), and its buffer carries


def reweighted_terms(cfg: Config) -> tuple[str, ...]:
    """The terms the walking and gait stages may weigh (``train.walk_weights``, ``train.walk_kvx``,
    ``train.gait_weights``): a replay buffer this run takes must carry them."""
    t = cfg.train
    return tuple(k for k in REWARD_KEYS
                 if k in t.walk_weights or k in t.gait_weights or (k == "kvx" and t.walk_kvx is not None))


def weighed_terms(cfg: Config) -> tuple[str, ...]:
    """The terms the env's reward or a stage of the run ``cfg`` weighs, in ``REWARD_KEYS`` order:
    those a training episode's sums are kept for (TensorBoard's ``reward_terms/*``), and those a
    buffer carries that a pamrun filled before every term was computed (it holds 0 for the others)."""
    stages = set(reweighted_terms(cfg))
    return tuple(k for k in REWARD_KEYS if getattr(cfg.reward, k) != 0.0 or k in stages)


class FeatureReader(BaseInfoDictReader):
    """TorchRL's reader of the env's ``info["reward_unweighted"]`` (a dict by weight key) into a
    nested TensorDict, ``(FEATURES, key)``, float64 (``GymWrapper.set_info_dict_reader``)."""

    def __init__(self):
        terms = Composite({k: Unbounded((), dtype=torch.float64) for k in REWARD_KEYS}, shape=())
        self._info_spec = Composite({FEATURES: terms}, shape=())

    def __call__(self, info_dict, tensordict):
        features = info_dict[FEATURES]
        values = torch.tensor([features[k] for k in REWARD_KEYS], dtype=torch.float64).unbind(0)
        tensordict.set(FEATURES, TensorDict(dict(zip(REWARD_KEYS, values)), batch_size=()))
        return tensordict

    def reset(self) -> None:
        pass

    @property
    def info_spec(self) -> Composite:
        return self._info_spec


class Reweight(Transform):
    """A replay-buffer transform (``buffer.append_transform``): the sampled ``("next", "reward")``
    re-weighted to ``weights`` from the env's ``base`` weights (both by key). With equal weights
    it leaves samples untouched."""

    def __init__(self, base: dict[str, float]):
        super().__init__()
        self.base = {k: float(base[k]) for k in REWARD_KEYS}
        self.delta = dict.fromkeys(REWARD_KEYS, 0.0)
        self.carried = set(COMPUTED)  # the terms every sample carries (fewer in a buffer an older run filled)

    def set_weights(self, weights: dict[str, float]) -> None:
        self.delta = {k: float(weights[k]) - w for k, w in self.base.items()}

    @property
    def weights(self) -> dict[str, float]:
        """The weights, by key, the samples are summed with now."""
        return {k: w + self.delta[k] for k, w in self.base.items()}

    def forward(self, tensordict):
        changed = [k for k, d in self.delta.items() if d != 0.0]
        if changed:
            nxt = tensordict["next"]
            reward, features = nxt["reward"], nxt[FEATURES]
            for k in changed:  # one term at a time, in REWARD_KEYS order: the reward stays in its own dtype
                reward += self.delta[k] * features[k].unsqueeze(-1).to(reward.dtype)
        return tensordict


class WalkCurriculum:
    """``train.walk_kvx``'s and ``train.walk_weights``' stages, stand then walk, and
    ``train.gait_weights``' third, gait, on a :class:`Reweight` of the learner's replay buffer."""

    def __init__(self, cfg: Config):
        self.cfg, self.kvx, self.stage = cfg, cfg.train.walk_kvx, "stand"
        self.weights = {**{k: getattr(cfg.reward, k) for k in REWARD_KEYS}, **cfg.train.walk_weights,
                        **({"kvx": self.kvx} if self.kvx is not None else {})}  # the walking stage's
        self.gait_weights = {**self.weights, **cfg.train.gait_weights}  # the gait stage's (adapted: _adapt)
        self.adapted_from = {k: self.gait_weights[k] for k in cfg.train.adapt_weights}
        self.since: int | None = None  # frames of the evaluation that started the walking stage
        self.gait_since: int | None = None  # ... and the gait stage
        self.transform = Reweight({k: getattr(cfg.reward, k) for k in REWARD_KEYS})
        if self.active and cfg.train.init_from:  # a trained agent's run is at its last stage from its first frame
            self._start("walk", 0)
            if cfg.train.gait_weights:
                self._start("gait", 0)

    @property
    def walking(self) -> bool:
        """At the walking stage or past it."""
        return self.stage != "stand"

    def replay(self, rows: list[dict]) -> None:
        """Take up the stage a resumed run was in, from its evals.csv rows."""
        for row in rows:
            self.observe(float(row["stand_rate"]), int(row["frames"]), float(row.get("walk_pass_rate") or 0.0),
                         float(row.get("distance_min") or 0.0))

    def observe(self, stand_rate: float, frames: int, walk_pass_rate: float = 0.0, distance_min: float = 0.0) -> bool:
        """Take an evaluation into account; True when it starts a stage: walking at the "stand,
        learned" milestone, gait (with ``train.gait_weights``) at the walking stage's first
        evaluation that meets :meth:`gait_milestone`."""
        if self.stage == "stand" and self.active and stands_learned(stand_rate, frames, self.cfg):
            return self._start("walk", frames)
        if self.stage == "walk" and self.cfg.train.gait_weights and self.gait_milestone(stand_rate, walk_pass_rate,
                                                                                         distance_min):
            return self._start("gait", frames)
        if self.stage == "gait" and self.cfg.train.adapt_weights:
            self._adapt(self.gait_milestone(stand_rate, walk_pass_rate, distance_min))
        return False

    def gait_milestone(self, stand_rate: float, walk_pass_rate: float, distance_min: float) -> bool:
        """Every episode passes the walk test, or with ``train.gait_from_distance_m`` every episode
        lasts the full episode and its shortest covers that distance."""
        metres = self.cfg.train.gait_from_distance_m
        if metres is None:
            return walk_pass_rate >= 1.0
        return stand_rate >= 1.0 and distance_min >= metres

    def _adapt(self, holds: bool) -> None:
        """``train.adapt_weights``: each one times ``train.adapt_factor`` (up to its cap) after an
        evaluation that meets the gait stage's milestone (:meth:`gait_milestone`: every episode
        passes, or stands and covers ``train.gait_from_distance_m``), divided by it (down to the gait
        stage's own) after one that does not."""
        factor = self.cfg.train.adapt_factor
        for key, cap in self.cfg.train.adapt_weights.items():
            weight = self.gait_weights[key]
            self.gait_weights[key] = min(weight * factor, cap) if holds else max(weight / factor, self.adapted_from[key])
        self.transform.set_weights(self.gait_weights)

    def _describe_adapt(self) -> str:
        if not self.cfg.train.adapt_weights:
            return ""
        caps = ", ".join(f"{k} {self.adapted_from[k]:g} up to {cap:g}" for k, cap in self.cfg.train.adapt_weights.items())
        return (f" While every evaluation meets the gait stage's milestone, these rise x{self.cfg.train.adapt_factor:g} an evaluation, "
                f"and fall back when one fails (train.adapt_weights): {caps}; TensorBoard curriculum/*.")

    def adapted(self) -> dict[str, float]:
        """``train.adapt_weights``' keys and their weights now."""
        return {key: self.gait_weights[key] for key in self.cfg.train.adapt_weights}

    def _start(self, stage: str, frames: int) -> bool:
        self.stage = stage
        if stage == "walk":
            self.since = frames
            self.transform.set_weights(self.weights)
        else:
            self.gait_since = frames
            self.transform.set_weights(self.gait_weights)
        return True

    @property
    def active(self) -> bool:
        return self.kvx is not None or bool(self.cfg.train.walk_weights)

    def changed(self) -> dict[str, float]:
        """The current stage's weights that differ from the env's."""
        weights = self.gait_weights if self.stage == "gait" else self.weights
        return {k: w for k, w in weights.items() if w != getattr(self.cfg.reward, k)}

    def describe(self) -> str:
        changed = ", ".join(f"{k} {getattr(self.cfg.reward, k):g} -> {w:g}" for k, w in self.changed().items())
        if self.stage == "gait":
            metres = self.cfg.train.gait_from_distance_m
            when = ("first passed the walk test" if metres is None else
                    f"first stood the whole episode and covered {metres:g} m (train.gait_from_distance_m)")
            when = ("from the first frame, a trained agent's run (train.init_from)" if self.cfg.train.init_from else
                    f"since {self.gait_since} frames, when every evaluation episode {when}")
            return (f"Gait stage of the curriculum {when}: the learner's weights {changed} (train.gait_weights over "
                    f"train.walk_weights; the env keeps reward.*).{self._describe_adapt()}")
        why = ("from the first frame, a trained agent's run (train.init_from)" if self.cfg.train.init_from else
               f"since {self.since} frames, when it first stood in every evaluation episode")
        beta = self.cfg.train.walk_noise_beta
        noise = ("" if beta is None else f" Exploration noise 1/f^{self.cfg.algo.noise_beta:g} -> "
                 f"1/f^{beta:g} (train.walk_noise_beta).")
        return (f"Walking stage of the curriculum {why}: the learner's weights {changed} "
                f"(train.walk_kvx = {self.kvx}, train.walk_weights; the env keeps reward.*).{noise}")
