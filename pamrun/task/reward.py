"""The reward as named terms: r = sum_k w_k f_k over the weights of ``RewardConfig``, each
feature f_k one small function of the control step (:class:`Transition`), registered under
its weight's key (``reward.<key>`` on the command line).

A term returns its unweighted value; :class:`Reward` matches weights to terms by key, sums
weight x feature in ``RewardConfig``'s field order (float64), and computes only the terms whose
weight is not 0 or that a reader asks for (``features``): the others are 0. A step whose physics
blew up has every feature 0. Adding a term is one function here and one ``RewardConfig`` field;
:func:`check_terms` (and the tests) fail when a weight has no term or a term no weight. The
formulas: ``docs/environment.md``, "Reward".
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from pamrun.config import RewardConfig
from pamrun.task import clock
from pamrun.task.measures import (
    STOP_BAND_DEG,
    ground_point_shift_m,
    sole_tilt_rad,
    step_length,
    stop_nearness,
    stop_share,
)

REWARD_KEYS = tuple(f.name for f in fields(RewardConfig))  # the weights, in the summation order
_STOP_BAND_RAD = math.radians(STOP_BAND_DEG)


@dataclass(slots=True)
class Transition:
    """One control step as the terms read it: the env's constants, the state after the step, the
    commands, and each foot's contact points (2, k, 3) and ground contact before and after."""

    env: Any  # PamWalkerEnv: z0, env_cfg, stop bounds, ...
    episode: Any  # its per-episode state (v*, L*, the clock's phase)
    torso: tuple[float, ...]  # x, y, z, roll, pitch, yaw, vx, vy, vz, wx, wy, wz
    qpos: list[float]
    action: np.ndarray  # the command applied in this step
    previous: np.ndarray  # the one applied in the step before (0 after reset)
    soles_before: np.ndarray
    soles: np.ndarray
    contact_before: list[bool]
    contact: list[bool]
    forces_n: list[float]  # ground force under each foot after the step [N]
    fell: bool = False
    air_nl: float = 0.0  # supply air drawn in the step, when the env meters it


TERMS: dict[str, Callable[[Transition], float]] = {}


def term(key: str) -> Callable:
    """Register a function of a :class:`Transition` as the feature that ``reward.<key>`` weighs."""
    def register(fn: Callable[[Transition], float]) -> Callable[[Transition], float]:
        TERMS[key] = fn
        return fn
    return register


@term("kvx")
def forward(t: Transition) -> float:
    return t.torso[6]  # Vx [m/s]


@term("ky")
def lateral(t: Transition) -> float:
    return -(t.torso[1] ** 2)


@term("kz")
def height(t: Transition) -> float:
    """On terrain, the height above the ground under the torso (pamrun.physics.terrain.ground_height_m)."""
    z = t.torso[2] - t.env.ground_height_m(t.torso[0]) if t.env.on_terrain else t.torso[2]
    return -((z - t.env.z0) ** 2)


@term("kv")
def effort(t: Transition) -> float:
    return -float(np.add.reduce(t.action * t.action))  # = -np.sum(a**2), bit for bit


@term("kt")
def alive(t: Transition) -> float:
    return t.env.env_cfg.control_dt_s / t.env.env_cfg.episode_s


@term("kda")
def command_change(t: Transition) -> float:
    return -float(np.add.reduce((t.action - t.previous) ** 2))


@term("kfall")
def fall(t: Transition) -> float:
    return -float(t.fell)


@term("kstop")
def joint_stops(t: Transition) -> float:
    q = [t.qpos[adr] for adr in t.env.qpos_addresses]
    return -stop_share(q, t.env.stop_bounds, t.contact)


@term("knear")
def near_stops(t: Transition) -> float:
    """Minus each counted joint's nearness to its stop, summed: (1 - d / 10 deg)^2 within 10 deg of a
    limit (``measures.stop_nearness``). One ankle roll held at its stop costs 1 a step (kstop: 0.1)."""
    q = [t.qpos[adr] for adr in t.env.qpos_addresses]
    return -stop_nearness(q, t.env.joint_limits_rad, _STOP_BAND_RAD, t.contact)


@term("kspeed")
def speed(t: Transition) -> float:
    return math.exp(-(((t.torso[6] - t.episode.target_speed_m_s) / t.env.env_cfg.speed_sigma_m_s) ** 2))


@term("ktrack")
def narrow_speed(t: Transition) -> float:
    """kspeed's pay at ``env.track_sigma_m_s``: a narrower bell around v*."""
    return math.exp(-(((t.torso[6] - t.episode.target_speed_m_s) / t.env.env_cfg.track_sigma_m_s) ** 2))


def _ground_point_speeds(t: Transition, before: bool) -> float:
    """The summed horizontal speed [m/s] over the step of the ground points of the feet on the ground
    at its end and, at its start, on it (``before``) or off it."""
    shift, total = ground_point_shift_m(t.soles_before, t.soles).tolist(), 0.0
    for foot in (0, 1):
        if t.contact[foot] and t.contact_before[foot] == before:
            total += math.hypot(*shift[foot]) / t.env.env_cfg.control_dt_s
    return total


@term("kslip")
def slip(t: Transition) -> float:
    """Minus the summed horizontal speed of the feet on the ground at both ends of the step [m/s]."""
    return -_ground_point_speeds(t, before=True)


@term("kland")
def landing(t: Transition) -> float:
    """Minus the summed horizontal speed over the step of the feet that touch down in it [m/s]: a
    foot that lands still moving forward skids (kslip charges the steps after)."""
    return -_ground_point_speeds(t, before=False)


@term("kair")
def air(t: Transition) -> float:
    return -t.air_nl


@term("kstep")
def step_miss(t: Transition) -> float:
    """Minus sum over the feet touching down in the step of (s - L*)^2 / L* [m] (at L* = 0, standing:
    s^2 / ``env.step_length_m``)."""
    target, miss = t.episode.step_length_m, 0.0
    scale = target or t.env.env_cfg.step_length_m
    for foot in (0, 1):
        if t.contact[foot] and not t.contact_before[foot]:
            miss += (step_length(t.soles, foot) - target) ** 2 / scale
    return -miss


def _soles_ahead_m(t: Transition) -> list[float]:
    """Each sole centre's forward distance [m] from the torso, right and left (kplace's and kreach's r)."""
    return (t.soles[:, :, 0].mean(axis=1) - t.torso[0]).tolist()


@term("kreach")
def landing_reach(t: Transition) -> float:
    """Minus sum over the feet touching down in the step of (r - R*)^2 / L* [m]: r the sole centre's
    distance ahead of the torso, R* where the clock's foot path lands a foot
    (pamrun.task.clock.landing_reach_m, (1 - swing_share) L*; at L* = 0, standing: r^2 /
    ``env.step_length_m``); 0 without a clock. A foot that lands under the torso makes its step
    behind the body, with the trailing leg (kstep charges the step, not where it is made)."""
    env = t.env
    landing = [foot for foot in (0, 1) if t.contact[foot] and not t.contact_before[foot]]
    if not env.gait_clock or not landing:
        return 0.0
    length = t.episode.step_length_m
    target, scale = clock.landing_reach_m(env.env_cfg.swing_share, length), length or env.env_cfg.step_length_m
    ahead = _soles_ahead_m(t)
    return -sum((ahead[foot] - target) ** 2 / scale for foot in landing)


@term("kgait")
def gait_clock(t: Transition) -> float:
    """1 - the feet's miss of the gait clock (0 without a clock); on terrain a swinging foot's lift
    counts from the ground under it."""
    env = t.env
    if not env.gait_clock:
        return 0.0
    shares = [f / env.weight_n for f in t.forces_n]
    knees = [t.qpos[adr] for adr in env.knee_addresses]
    ground = [env.ground_height_m(float(x)) for x in t.soles[:, :, 0].mean(axis=1)] if env.on_terrain else None
    return clock.followed(t.episode.phase(env.env_cfg), t.soles_before, t.soles, shares, knees, env.sole_radius_m,
                          env.env_cfg, t.episode.clock_stopped, ground)


@term("kflight")
def flight(t: Transition) -> float:
    """-1 when the step ends with neither foot on the ground (each foot's force at most 5 % of the weight)."""
    return -float(not any(t.contact))


@term("kdouble")
def double_support(t: Transition) -> float:
    """Minus the clock's both-feet-down weight (pamrun.task.clock.both_down_weight; 1 while it stands
    still) when the step ends with a foot off the ground: its double support kept (0 without a clock).
    kgait charges each foot's largest miss, so a trailing foot whose knee already bends past
    env.stance_knee_deg pays nothing more for lifting early."""
    env = t.env
    if not env.gait_clock or all(t.contact):
        return 0.0
    if t.episode.clock_stopped:
        return -1.0
    return -clock.both_down_weight(t.episode.phase(env.env_cfg), env.env_cfg.swing_share)


@term("kplace")
def foot_placement(t: Transition) -> float:
    """1 - the feet's mean squared miss of the clock's foot path (pamrun.task.clock.foot_path_m: each
    sole's forward distance from the torso, from +E/2 at touchdown back to -E/2 at lift-off and forward
    again in swing), in units of half ``env.step_length_m``, each foot's capped at 1 (0 without a clock):
    a swing that lands its foot under the hip, not ahead of it, takes short steps at the clock's cadence.
    A pay, as kgait's: a cost this large would make ending the episode cheaper than walking."""
    env = t.env
    if not env.gait_clock:
        return 0.0
    stopped = t.episode.clock_stopped
    path = (0.0, 0.0) if stopped else clock.foot_path_m(t.episode.phase(env.env_cfg), env.env_cfg.swing_share,
                                                        t.episode.step_length_m)
    scale = 0.5 * env.env_cfg.step_length_m
    ahead = _soles_ahead_m(t)
    return 1.0 - 0.5 * sum(min(((a - p) / scale) ** 2, 1.0) for a, p in zip(ahead, path))


@term("kknee")
def knee_path(t: Transition) -> float:
    """1 - the knees' mean squared miss of the clock's knee path (pamrun.task.clock.knee_path_rad: a
    bend that peaks at ``env.knee_path_peak_deg`` 0.3 into the swing and is 0, at rest, at touchdown and in stance),
    in units of half that peak, each capped at 1 (0 without a clock). A swing that still bends its
    knee when the foot lands puts the foot down under the knee, not ahead of the hip. A pay, as kplace's."""
    env = t.env
    if not env.gait_clock:
        return 0.0
    cfg = env.env_cfg
    peak = math.radians(cfg.knee_path_peak_deg)
    wanted = (0.0, 0.0) if t.episode.clock_stopped else clock.knee_path_rad(t.episode.phase(cfg), cfg.swing_share, peak)
    return _joint_path_pay(t.qpos, env.knee_addresses, wanted, 0.5 * peak)


def _joint_path_pay(qpos: list[float], addresses: list[int], wanted, scale_rad: float) -> float:
    """1 - (1/2) sum over the right and left joint at ``addresses`` of min(((q - q*) / scale)^2, 1), a joint
    whose wanted q* is None missing nothing: the joint-path terms' feature."""
    return 1.0 - 0.5 * sum(min(((qpos[adr] - w) / scale_rad) ** 2, 1.0) for adr, w in zip(addresses, wanted) if w is not None)


@term("khip")
def hip_path(t: Transition) -> float:
    """1 - the swinging hips' mean squared miss of the clock's hip path (pamrun.task.clock.hip_path_rad: a
    flexion to ``env.hip_path_peak_deg`` x L*/``env.step_length_m`` 0.6 into the swing, 5/6 of it kept at
    touchdown), in units of half that peak, each capped at 1; a hip in stance misses nothing (0 without a
    clock; 1 while it stands still). A swing whose thigh flexes little and retracts early lands its foot
    under the hip: the step is short whatever the foot's path asks. A pay, as kknee's."""
    env, cfg = t.env, t.env.env_cfg
    if not env.gait_clock or t.episode.clock_stopped:
        return float(env.gait_clock)
    scale, peak = _hip_scale_and_peak(t)
    wanted = clock.hip_path_rad(t.episode.phase(cfg), cfg.swing_share, peak, scale)
    return _joint_path_pay(t.qpos, env.hip_addresses, wanted, 0.5 * peak * scale)


def _hip_scale_and_peak(t: Transition) -> tuple[float, float]:
    """The episode's step length over ``env.step_length_m``, and ``env.hip_path_peak_deg`` [rad]: the hip paths' scales."""
    cfg = t.env.env_cfg
    return t.episode.step_length_m / cfg.step_length_m, math.radians(cfg.hip_path_peak_deg)


@term("kextend")
def stance_hip_path(t: Transition) -> float:
    """1 - the stance hips' mean squared miss of the clock's stance hip path (pamrun.task.clock.stance_hip_path_rad:
    from khip's touchdown flexion, 5/6 of its peak, extending to ``env.hip_extension_deg`` x L*/``env.step_length_m``
    as the other foot lands, and back to 0 at lift-off), in units of half khip's peak, each capped at 1; a hip in
    swing misses nothing (0 without a clock; 1 while it stands still). A step made by both legs: the landed leg
    ahead of the body, the stance leg extending behind it. A pay, as khip's."""
    env, cfg = t.env, t.env.env_cfg
    if not env.gait_clock or t.episode.clock_stopped:
        return float(env.gait_clock)
    scale, peak = _hip_scale_and_peak(t)
    wanted = clock.stance_hip_path_rad(t.episode.phase(cfg), cfg.swing_share,
                                       scale * peak * clock.HIP_TOUCHDOWN_SHARE_OF_PEAK,
                                       scale * math.radians(cfg.hip_extension_deg))
    return _joint_path_pay(t.qpos, env.hip_addresses, wanted, 0.5 * peak * scale)


@term("kpush")
def push_off(t: Transition) -> float:
    """1 - the ankles' mean squared miss of the clock's push-off (pamrun.task.clock.push_off_path_rad: a
    plantarflexion rising to ``env.push_off_peak_deg`` at a foot's lift-off and back to 0 after it), in
    units of half that peak, each capped at 1; an ankle the clock leaves free misses nothing (0 without a
    clock; 1 while it stands still). A stance ankle that stays loose to lift-off leaves the trailing foot
    behind, dorsiflexed, and the step short. A pay, as kknee's."""
    env, cfg = t.env, t.env.env_cfg
    if not env.gait_clock or t.episode.clock_stopped:
        return float(env.gait_clock)
    peak = math.radians(cfg.push_off_peak_deg)
    wanted = clock.push_off_path_rad(t.episode.phase(cfg), cfg.swing_share, peak)
    return _joint_path_pay(t.qpos, env.ankle_addresses, wanted, 0.5 * peak)


@term("klift")
def early_lift(t: Transition) -> float:
    """Minus the number of feet that leave the ground in the step in the first half of their clock's
    stance (pamrun.task.clock.in_early_stance; any foot while it stands still): a stance split by a
    bounce after its landing (0 without a clock). Each lift is charged once, as kland charges each
    landing; a foot lifting late in its stance, before its swing, is kdouble's."""
    return _charged_contact_changes(t, landing=False, charged=clock.in_early_stance)


@term("ktouch")
def off_clock_touchdown(t: Transition) -> float:
    """Minus the number of feet that touch the ground in the step more than 0.1 of the period from
    their clock's touchdown (pamrun.task.clock.near_touchdown; any foot while it stands still): the
    second landing of a split stance, a foot that lifted and touched again before its swing or bounced
    after its landing, and a swing cut short or dragged on (0 without a clock). Each touchdown is
    charged once, as klift charges each lift."""
    return _charged_contact_changes(t, landing=True, charged=lambda *at: not clock.near_touchdown(*at))


def _charged_contact_changes(t: Transition, landing: bool, charged) -> float:
    """Minus the number of feet that land in the step (``landing``; else lift) where ``charged(phase, foot,
    swing_share)`` holds, or at all while the clock stands still; 0 without a clock: klift's and ktouch's count."""
    env = t.env
    if not env.gait_clock:
        return 0.0
    stopped, phase = t.episode.clock_stopped, t.episode.phase(env.env_cfg)
    changed = [after != before and after == landing for before, after in zip(t.contact_before, t.contact)]
    return -float(sum(c and (stopped or charged(phase, f, env.env_cfg.swing_share)) for f, c in enumerate(changed)))


@term("kflat")
def sole_edge(t: Transition) -> float:
    """Minus the summed side-to-side tilt [rad] of the feet on the ground at the step's end: a foot
    standing on its sole's edge, not flat (pamrun.task.measures.sole_tilt_rad)."""
    tilt = sole_tilt_rad(t.soles).tolist()
    return -sum(abs(a) for a, down in zip(tilt, t.contact) if down)


@term("klevel")
def swing_sole_tilt(t: Transition) -> float:
    """Minus the summed side-to-side tilt [rad] of the feet off the ground at the step's end: a
    swinging foot rolled towards its ankle's stop, which lands on its sole's edge (kflat's tilt,
    pamrun.task.measures.sole_tilt_rad, for the feet kflat leaves out)."""
    tilt = sole_tilt_rad(t.soles).tolist()
    return -sum(abs(a) for a, down in zip(tilt, t.contact) if not down)


@term("kupright")
def upright(t: Transition) -> float:
    """Minus the torso's squared tilt from upright, roll^2 + pitch^2 [rad^2]; its heading (yaw) is free."""
    return -(t.torso[3] ** 2 + t.torso[4] ** 2)


def check_terms(keys: Iterable[str] = REWARD_KEYS) -> None:
    """Every weight has a term and every term a weight; ValueError naming the odd ones out."""
    keys = tuple(keys)
    unweighted, missing = sorted(set(TERMS) - set(keys)), [k for k in keys if k not in TERMS]
    if unweighted or missing:
        raise ValueError(f"reward terms without a weight in RewardConfig: {unweighted}; "
                         f"weights without a term: {missing}")


check_terms()


class Reward:
    """The weights of a ``RewardConfig`` and the terms they need (plus ``features``, computed at
    any weight for a reader that re-weights them, e.g. a training curriculum)."""

    def __init__(self, cfg: RewardConfig, features: Iterable[str] = ()):
        features = tuple(features)
        unknown = sorted(set(features) - set(REWARD_KEYS))
        if unknown:
            raise ValueError(f"unknown reward features {unknown}; known: {', '.join(REWARD_KEYS)}")
        self.weights = {k: float(getattr(cfg, k)) for k in REWARD_KEYS}
        self.computed = tuple(k for k in REWARD_KEYS if self.weights[k] or k in features)
        self._terms = [(k, TERMS[k], self.weights[k]) for k in self.computed]
        self._zeros = dict.fromkeys(REWARD_KEYS, 0.0)
        self._zero_terms = {k: w * 0.0 for k, w in self.weights.items()}  # each weight x a feature of 0

    def __call__(self, t: Transition | None) -> tuple[float, dict[str, float], dict[str, float]]:
        """The reward, its weighted terms and its features, both by key (``t`` None: a step whose
        physics blew up, every feature 0)."""
        features, terms = self._zeros.copy(), self._zero_terms.copy()
        if t is not None:
            for key, feature, weight in self._terms:
                features[key] = value = feature(t)
                terms[key] = weight * value
        return float(sum(terms.values())), terms, features
