"""The evaluations during training: ``pamrun eval``'s walk test run on the current actor, which
of two evaluations ranks first (``best_eval.pt``), and a short video of an evaluation's first
episode (for TensorBoard: :mod:`pamrun.evaluation.board`)."""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
import torch

from pamrun.evaluation.episodes import aggregate, run_episode, torch_threads
from pamrun.evaluation.metrics import GaitSpec
from pamrun.evaluation.ranking import rank
from pamrun.task.criteria import kept_command, walk_passed
from pamrun.task.spec import EnvSpec, eval_env_options

VIDEO_S = 4.0  # seconds of the episode a video shows (from its start)
VIDEO_STRIDE = 2  # a video frame every this many control steps
VIDEO_SIZE = (320, 240)  # width, height of a video frame [px]


def as_policy(actor):
    """``actor`` (a torch module) as a function observation -> action."""

    def policy(obs: np.ndarray) -> np.ndarray:
        return actor(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0].numpy()

    return policy


class TrainingEvaluator:
    """The walk test of ``pamrun eval`` run on the current actor during training.

    Every call runs ``cfg.train.eval_episodes`` deterministic episodes in one env of the
    run's robot and task, episode k from seed ``eval.selection_seed + k`` (the selection
    block, disjoint from ``pamrun eval``'s held-out ``eval.seed``) with the evaluation's start
    noise, episode length and commanded speed (:func:`pamrun.task.spec.eval_env_options`: a run
    that trains over drawn speeds is selected at ``eval.speed_m_s``, else its own v*), the same
    starts every time, in this process with one torch thread, and returns the aggregate
    (:func:`pamrun.evaluation.episodes.aggregate`) with its cost ``eval_s`` and its first episode
    with its per-step arrays (``first_episode``; the gait figure's).

    **Selection under perturbation** (``train.select_perturbations``): once a nominal episode
    passes, the call also runs ``train.select_episodes`` episodes (seeds ``eval.selection_seed
    + k``; a name's own count in ``train.select_episodes_of``) under each of those perturbations
    of the suite, and ``select_pass_rate`` is the walk pass rate over all the episodes it ran
    (without them: ``walk_pass_rate``). ``better`` ranks by it first, then by ``eval.rank_by``:
    among agents that all walk the nominal block, the one that holds under perturbation is kept.
    **Selection on a speed schedule** (``train.select_schedule``): in the same case it also runs
    ``train.select_schedule_episodes`` episodes (the same seeds) on that schedule, each counted in
    ``select_pass_rate`` as passed when it kept to it (:func:`pamrun.task.criteria.kept_command`: no
    fall, standing still where told 0 m/s); ``select_schedule_rate`` is their share (NaN when none ran).
    The nominal aggregate is unchanged (the curriculum reads it).
    Anchors: Stable-Baselines3's ``EvalCallback``, TorchRL's ``Evaluator``.

    **Video** (``train.eval_video_every`` > 0): :meth:`video` replays the first episode in an env
    of its own that renders offscreen, made at the first video. On a machine that cannot render,
    :meth:`video` returns None and ``no_video`` says why (the run goes on without videos).
    """

    def __init__(self, cfg):
        self.ecfg, self.episodes = cfg.eval, cfg.train.eval_episodes
        t = cfg.train
        self.select_counts = [t.select_episodes_of.get(name, t.select_episodes) for name in t.select_perturbations]
        self.spec = EnvSpec.from_config(cfg).with_values(env=eval_env_options(cfg.eval))
        self.env = self.spec.make()
        self.gait_spec = GaitSpec.from_configs(self.env.body_cfg, self.env.muscle_cfg, self.env.mass_kg,
                                               self.env.env_cfg.control_dt_s)
        self.perturbed = [self.spec.perturbed(cfg.eval.perturbations[name], f"eval.perturbations.{name}").make()
                          for name in t.select_perturbations]
        self.scheduled = (self.spec.with_values(env={"speed_schedule": t.select_schedule}).make()
                          if t.select_schedule else None)
        self.schedule_episodes = t.select_schedule_episodes
        self.camera, self.no_video = None, ""

    def __call__(self, actor) -> dict[str, Any]:
        start = time.perf_counter()
        policy = as_policy(actor)

        def block(env, n: int, keep_first: bool = False) -> list[dict]:
            return [run_episode(policy, env, self.ecfg.selection_seed + k, keep_steps=keep_first and k == 0)
                    for k in range(n)]

        with torch.no_grad(), torch_threads(1):
            episodes = block(self.env, self.episodes, keep_first=True)
            result = aggregate(episodes, self.ecfg)
            scheduled = []
            if result["walk_passes"]:
                episodes += [e for env, n in zip(self.perturbed, self.select_counts) for e in block(env, n)]
                scheduled = block(self.scheduled, self.schedule_episodes) if self.scheduled else []
        seeds = [self.ecfg.selection_seed, self.ecfg.selection_seed + self.episodes - 1]
        kept = [kept_command(e, self.ecfg) for e in scheduled]
        select = float(np.mean([walk_passed(e, self.ecfg) for e in episodes] + kept))
        return {**result, "select_pass_rate": select, "select_schedule_rate": float(np.mean(kept)) if kept else math.nan,
                "seeds": seeds, "first_episode": episodes[0], "eval_s": time.perf_counter() - start}

    def open_camera(self):
        """The env :meth:`video` renders in, checked by rendering its first frame; None, with
        ``no_video`` saying why, where this machine cannot render."""
        env = self.spec.make(render_mode="rgb_array", width=VIDEO_SIZE[0], height=VIDEO_SIZE[1])
        try:
            env.reset(seed=self.ecfg.selection_seed)
            env.render()
        except Exception as err:  # no OpenGL to render with (MUJOCO_GL names the backend, egl by default)
            env.close()
            self.no_video = (f"no videos in TensorBoard: offscreen rendering failed ({type(err).__name__}: {err}); "
                             "set MUJOCO_GL to a backend this machine has (egl, osmesa), or train.eval_video_every=0")
            return None
        return env

    def video(self, actor) -> tuple[list[np.ndarray], float] | None:
        """The first ``VIDEO_S`` seconds of the first episode (its seed, hence the same episode),
        rendered every ``VIDEO_STRIDE``-th control step and at its end; the frames and their
        rate (frames/s). None where this machine cannot render (``no_video``)."""
        if self.camera is None and not self.no_video:
            self.camera = self.open_camera()
        if self.camera is None:
            return None
        env, policy = self.camera, as_policy(actor)
        dt = env.env_cfg.control_dt_s
        with torch.no_grad(), torch_threads(1):
            obs, _ = env.reset(seed=self.ecfg.selection_seed)
            frames = [env.render()]
            for i in range(1, round(VIDEO_S / dt) + 1):
                obs, _, terminated, truncated, _ = env.step(policy(obs))
                if i % VIDEO_STRIDE == 0 or terminated or truncated:
                    frames.append(env.render())
                if terminated or truncated:
                    break
        return frames, 1.0 / (VIDEO_STRIDE * dt)

    def better(self, new: dict, best: dict | None) -> bool:
        """Whether ``new`` ranks before ``best`` by ``eval.rank_by``, preceded by
        ``select_pass_rate`` when selecting under perturbation (ties keep the old one; a best
        saved before selection under perturbation existed counts its ``walk_pass_rate``)."""
        if best is None:
            return True
        best = {"select_pass_rate": best["walk_pass_rate"], **best, "agent": "0-best"}
        by = ["select_pass_rate"] * bool(self.perturbed or self.scheduled) + list(self.ecfg.rank_by)
        ranked = rank([best, {**new, "agent": "1-new"}], by)
        return ranked[0]["agent"] == "1-new"

    def close(self) -> None:
        for env in (self.env, *self.perturbed, *[e for e in (self.scheduled, self.camera) if e]):
            env.close()
