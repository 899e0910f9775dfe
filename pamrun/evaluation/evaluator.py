"""The evaluations during training: ``pamrun eval``'s walk test run on the current actor, and
which of two evaluations ranks first (``best_eval.pt``)."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import torch

from pamrun.evaluation.episodes import aggregate, run_episode, torch_threads
from pamrun.evaluation.ranking import rank
from pamrun.task.criteria import walk_passed
from pamrun.task.spec import EnvSpec, eval_env_options


class TrainingEvaluator:
    """The walk test of ``pamrun eval`` run on the current actor during training.

    Every call runs ``cfg.train.eval_episodes`` deterministic episodes in one env of the
    run's robot and task, episode k from seed ``eval.selection_seed + k`` (the selection
    block, disjoint from ``pamrun eval``'s held-out ``eval.seed``) with the evaluation's start
    noise and episode length (:func:`pamrun.task.spec.eval_env_options`; the commanded speed
    stays the run's own), the same starts every time, in this process with one torch thread,
    and returns the aggregate (:func:`pamrun.evaluation.episodes.aggregate`) with its cost ``eval_s``.

    **Selection under perturbation** (``train.select_perturbations``): once a nominal episode
    passes, the call also runs ``train.select_episodes`` episodes (seeds ``eval.selection_seed
    + k``; a name's own count in ``train.select_episodes_of``) under each of those perturbations
    of the suite, and ``select_pass_rate`` is the walk pass rate over all the episodes it ran
    (without them: ``walk_pass_rate``). ``better`` ranks by it first, then by ``eval.rank_by``:
    among agents that all walk the nominal block, the one that holds under perturbation is kept.
    The nominal aggregate is unchanged (the curriculum reads it).
    Anchors: Stable-Baselines3's ``EvalCallback``, TorchRL's ``Evaluator``.
    """

    def __init__(self, cfg):
        self.ecfg, self.episodes = cfg.eval, cfg.train.eval_episodes
        t = cfg.train
        self.select_counts = [t.select_episodes_of.get(name, t.select_episodes) for name in t.select_perturbations]
        spec = EnvSpec.from_config(cfg).with_values(env=eval_env_options(cfg.eval, hold_speed=False))
        self.env = spec.make()
        self.perturbed = [spec.perturbed(cfg.eval.perturbations[name], f"eval.perturbations.{name}").make()
                          for name in t.select_perturbations]

    def __call__(self, actor) -> dict[str, Any]:
        start = time.perf_counter()

        def policy(obs: np.ndarray) -> np.ndarray:
            return actor(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0].numpy()

        def block(env, n: int) -> list[dict]:
            return [run_episode(policy, env, self.ecfg.selection_seed + k, keep_steps=False) for k in range(n)]

        with torch.no_grad(), torch_threads(1):
            episodes = block(self.env, self.episodes)
            result = aggregate(episodes, self.ecfg)
            if result["walk_passes"]:
                episodes += [e for env, n in zip(self.perturbed, self.select_counts) for e in block(env, n)]
        seeds = [self.ecfg.selection_seed, self.ecfg.selection_seed + self.episodes - 1]
        select = float(np.mean([walk_passed(e, self.ecfg) for e in episodes]))
        return {**result, "select_pass_rate": select, "seeds": seeds, "eval_s": time.perf_counter() - start}

    def better(self, new: dict, best: dict | None) -> bool:
        """Whether ``new`` ranks before ``best`` by ``eval.rank_by``, preceded by
        ``select_pass_rate`` when selecting under perturbation (ties keep the old one; a best
        saved before selection under perturbation existed counts its ``walk_pass_rate``)."""
        if best is None:
            return True
        best = {"select_pass_rate": best["walk_pass_rate"], **best, "agent": "0-best"}
        by = ["select_pass_rate"] * bool(self.perturbed) + list(self.ecfg.rank_by)
        ranked = rank([best, {**new, "agent": "1-new"}], by)
        return ranked[0]["agent"] == "1-new"

    def close(self) -> None:
        for env in (self.env, *self.perturbed):
            env.close()
