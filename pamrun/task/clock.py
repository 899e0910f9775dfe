"""The gait clock: its phase, which foot it swings, each foot's miss of it, and its period and
step length at a commanded speed (``docs/environment.md``, "Gait clock").

A stride of period T turns the phase phi once; the right foot's clock is phi, the left's
phi + 1/2; each foot swings for a share ``env.swing_share`` of its period, centred a quarter
period after its clock's zero (:func:`swing_weights`). ``reward.kgait``'s
feature is 1 - (1/2) sum_feet miss (:func:`followed`).
"""

from __future__ import annotations

import math

import numpy as np

from pamrun.config import EnvConfig


def phase(phase0: float, steps: int, control_dt_s: float, period_s: float) -> float:
    """The phase phi in [0, 1) after ``steps`` control steps from ``phase0``."""
    return (phase0 + steps * control_dt_s / period_s) % 1.0


def swing_weights(phase: float, swing_share: float) -> tuple[float, float]:
    """How much the clock swings the right and the left foot at this phase: 1 in swing, 0 in
    stance, smooth in between, s = (1 + tanh((sin 2 pi phi - cos pi sigma) / 0.1)) / 2."""
    edge = math.cos(math.pi * swing_share)
    return tuple(0.5 * (1.0 + math.tanh((math.sin(2 * math.pi * (phase + 0.5 * foot)) - edge) / 0.1))
                 for foot in (0, 1))


def both_down_weight(phase: float, swing_share: float) -> float:
    """How much the clock stands both feet at this phase, (1 - s_right)(1 - s_left): ~1 in its
    double-support windows (a share 1 - 2 ``swing_share`` of the period), ~0 while a foot swings."""
    right, left = swing_weights(phase, swing_share)
    return (1.0 - right) * (1.0 - left)


def since_lift_off(phase: float, foot: int, swing_share: float) -> float:
    """A foot's own clock psi in [0, 1): 0 at its lift-off, ``swing_share`` at its touchdown (the
    swing :func:`swing_weights` centres a quarter period after its clock's zero)."""
    return (phase + 0.5 * foot - 0.25 + 0.5 * swing_share) % 1.0


def in_early_stance(phase: float, foot: int, swing_share: float) -> bool:
    """Whether a foot's clock is in the first half of its stance, from its touchdown (psi = ``swing_share``)
    to halfway to its next lift-off (:func:`since_lift_off`)."""
    return swing_share <= since_lift_off(phase, foot, swing_share) < 0.5 * (1.0 + swing_share)


# How far, as a share of the period, a touchdown may fall from its foot's clock touchdown (psi = swing_share) and
# still be the clock's: the clock's double support at swing_share 0.4 (a foot landing within it lands between
# the other's touchdown and its lift-off, give or take that much).
TOUCHDOWN_WINDOW_SHARE = 0.1


def touchdown_offset(phase: float, foot: int, swing_share: float) -> float:
    """How far a foot's clock is past its touchdown (psi = ``swing_share``, :func:`since_lift_off`), as a
    share of the period in [-0.5, 0.5): + after it (a foot landing now lands late), - before it."""
    return (since_lift_off(phase, foot, swing_share) - swing_share + 0.5) % 1.0 - 0.5


def near_touchdown(phase: float, foot: int, swing_share: float) -> bool:
    """Whether a foot's clock is within :data:`TOUCHDOWN_WINDOW_SHARE` of the period of its touchdown, either side."""
    return abs(touchdown_offset(phase, foot, swing_share)) <= TOUCHDOWN_WINDOW_SHARE


def landing_reach_m(swing_share: float, step_length_m: float) -> float:
    """How far ahead of the torso [m] the clock's foot path (:func:`foot_path_m`) lands a foot: E / 2 =
    (1 - sigma) L*, half the distance the torso covers in a stance."""
    return (1.0 - swing_share) * step_length_m


def foot_path_m(phase: float, swing_share: float, step_length_m: float) -> tuple[float, float]:
    """Where the clock wants the right and the left foot [m], forward of the torso, at this phase:
    each foot's sole moves back at a constant rate through its stance, from +E/2 at touchdown to
    -E/2 at lift-off, and forward through its swing, -E/2 cos(pi u) at the swing's share u; E =
    2 (1 - sigma) L*, the distance the torso covers in a stance at v* = 2 L* / T. At L* = 0
    (standing still) both feet are under the torso. Each foot's swing is where
    :func:`swing_weights` swings it, centred a quarter period after its clock's zero."""
    reach = landing_reach_m(swing_share, step_length_m)
    path = []
    for foot in (0, 1):
        psi = since_lift_off(phase, foot, swing_share)
        if psi < swing_share:
            path.append(-reach * math.cos(math.pi * psi / swing_share))
        else:
            path.append(reach * (1.0 - 2.0 * (psi - swing_share) / (1.0 - swing_share)))
    return path[0], path[1]


# Where in its swing a human knee bends most: about 60 deg at 73 % of the gait cycle, toe-off at ~62 %
# (Winter, Biomechanics and Motor Control of Human Movement, 4th ed. 2009, ch. 4): (73 - 62) / 38.
KNEE_PEAK_SWING_SHARE = 0.3
_KNEE_POWER = math.log(0.5) / math.log(KNEE_PEAK_SWING_SHARE)  # p: u^p = 1/2 at that share


def knee_path_rad(phase: float, swing_share: float, peak_rad: float) -> tuple[float, float]:
    """The knee flexion [rad] the clock wants of the right and the left leg at this phase: through
    its swing, peak sin^2(pi u^p) at the swing's share u, p = ln(1/2) / ln(:data:`KNEE_PEAK_SWING_SHARE`)
    so it bends most 0.3 into the swing; 0 in its stance. The knee bends quickly after lift-off and
    is straight again, and at rest, when its foot lands (a knee still extending at touchdown throws
    its foot forward onto the ground)."""
    path = []
    for foot in (0, 1):
        u = since_lift_off(phase, foot, swing_share) / swing_share
        path.append(peak_rad * math.sin(math.pi * u**_KNEE_POWER) ** 2 if u < 1.0 else 0.0)
    return path[0], path[1]


# The human hip through the swing (hip extension +): near 0 at toe-off (62 % of the gait cycle), flexed
# most, about 30 deg, at ~85 %, and back to about 25 deg at heel strike (Winter 2009, ch. 4; Perry, Gait
# Analysis, 1992): its peak (85 - 62) / 38 = 0.6 into the swing, 5/6 of it kept at touchdown.
HIP_PEAK_SWING_SHARE = 0.6
HIP_TOUCHDOWN_SHARE_OF_PEAK = 5.0 / 6.0


def hip_path_rad(phase: float, swing_share: float, peak_rad: float, scale: float) -> tuple[float | None, float | None]:
    """The hip pitch [rad] (extension +) the clock wants of the right and the left leg at this phase, or
    None where it wants none: through its swing, from 0 at lift-off, flexing smoothly (a half cosine) to
    -``scale`` x ``peak_rad`` :data:`HIP_PEAK_SWING_SHARE` into the swing, and back to
    :data:`HIP_TOUCHDOWN_SHARE_OF_PEAK` of it at touchdown (the thigh retracts before the foot lands);
    free through its stance. ``scale``: the episode's step length over ``env.step_length_m``."""
    peak, path = -scale * peak_rad, []
    for foot in (0, 1):
        u = since_lift_off(phase, foot, swing_share) / swing_share
        if u >= 1.0:
            path.append(None)
        elif u <= HIP_PEAK_SWING_SHARE:
            path.append(peak * 0.5 * (1.0 - math.cos(math.pi * u / HIP_PEAK_SWING_SHARE)))
        else:
            back = 0.5 * (1.0 - math.cos(math.pi * (u - HIP_PEAK_SWING_SHARE) / (1.0 - HIP_PEAK_SWING_SHARE)))
            path.append(peak * (1.0 - (1.0 - HIP_TOUCHDOWN_SHARE_OF_PEAK) * back))
    return path[0], path[1]



# The human hip through the stance (hip extension +): flexed about 25 deg at heel strike, extending
# steadily to its most, 10-20 deg, as the other foot lands (50 % of the gait cycle; Perry, Gait Analysis,
# 1992: 10 deg true, 20 deg apparent hyperextension in terminal stance; Winter 2009, ch. 4), and back near
# 0 at toe-off (62 %), where the swing's path (hip_path_rad) starts.
def stance_hip_path_rad(phase: float, swing_share: float, flexion_rad: float,
                        extension_rad: float) -> tuple[float | None, float | None]:
    """The hip pitch [rad] (extension +) the clock wants of the right and the left leg at this phase, or
    None where it wants none: through its stance, from ``-flexion_rad`` at touchdown, straight to
    ``+extension_rad`` as the other foot lands half a period later, and straight back to 0 at lift-off
    (at ``swing_share`` >= 0.5, no double support: along the first line to lift-off); free through its swing."""
    path = []
    for foot in (0, 1):
        s = since_lift_off(phase, foot, swing_share)
        if s < swing_share:
            path.append(None)
        elif s < swing_share + 0.5:
            path.append(-flexion_rad + (flexion_rad + extension_rad) * (s - swing_share) / 0.5)
        else:
            path.append(extension_rad * (1.0 - s) / (0.5 - swing_share))
    return path[0], path[1]

# The human ankle's push-off: from its most dorsiflexed (about 10 deg, at ~48 % of the gait cycle) it
# plantarflexes to about 20 deg at toe-off (~62 %) and is back near neutral by ~76 % (Winter, Biomechanics
# and Motor Control of Human Movement, 4th ed. 2009, ch. 4): about 0.14 of the period each way.
PUSH_OFF_SHARE = 0.14


def push_off_path_rad(phase: float, swing_share: float, peak_rad: float) -> tuple[float | None, float | None]:
    """The ankle plantarflexion [rad] the clock wants of the right and the left foot at this phase,
    or None where it wants none: over the last :data:`PUSH_OFF_SHARE` of a foot's period before its
    lift-off, peak sin^2(pi/2 w) (w from 0 to 1), and over the same share after it, peak cos^2(pi/2 w)
    back to 0; free through the rest of the stance and the swing (a foot's clock: :func:`since_lift_off`)."""
    path = []
    for foot in (0, 1):
        psi = since_lift_off(phase, foot, swing_share)
        if psi > 1.0 - PUSH_OFF_SHARE:
            path.append(peak_rad * math.sin(0.5 * math.pi * (psi - 1.0 + PUSH_OFF_SHARE) / PUSH_OFF_SHARE) ** 2)
        elif psi < PUSH_OFF_SHARE:
            path.append(peak_rad * math.cos(0.5 * math.pi * psi / PUSH_OFF_SHARE) ** 2)
        else:
            path.append(None)
    return path[0], path[1]


SWING_WANTS = ("swing_load", "swing_lift", "swing_knee")  # a swinging foot's wants, as misses
STANCE_WANTS = ("stance_speed", "stance_load", "stance_knee")  # ... and a standing one's


def foot_wants(share: float, speed_m_s: float, lift_m: float, knee_rad: float, env: EnvConfig) -> dict[str, float]:
    """One foot's miss of each of its wants, in [0, 1], by name (those whose env option is off left
    out): in swing, carrying (its ground force as a share of the weight), not lifted (its lowest
    point's height under ``env.swing_clearance_m``) and not bent (its knee's flexion, 0 straight,
    under ``env.swing_knee_deg``); in stance, moving (its sole's speed), not carrying (1 - 2 f)
    and bent (its knee's flexion as a share of ``env.stance_knee_deg``)."""
    wants = {"swing_load": min(share, 1.0), "stance_speed": min(speed_m_s, 1.0),
             "stance_load": 1.0 - min(2.0 * share, 1.0)}
    if env.swing_clearance_m:
        wants["swing_lift"] = 1.0 - min(max(lift_m, 0.0) / env.swing_clearance_m, 1.0)
    if env.swing_knee_deg:
        wants["swing_knee"] = 1.0 - min(max(knee_rad, 0.0) / math.radians(env.swing_knee_deg), 1.0)
    if env.stance_knee_deg:
        wants["stance_knee"] = min(max(knee_rad, 0.0) / math.radians(env.stance_knee_deg), 1.0)
    return wants


def foot_miss(swing: float, share: float, speed_m_s: float, lift_m: float, knee_rad: float, env: EnvConfig) -> float:
    """One foot's miss of the clock, in [0, 1], at swing weight s: s times the largest of its swing
    wants' misses plus (1 - s) times the largest of its stance wants' (:func:`foot_wants`)."""
    return miss_of(swing, foot_wants(share, speed_m_s, lift_m, knee_rad, env))


def miss_of(swing: float, wants: dict[str, float]) -> float:
    """A foot's miss at swing weight s from its wants' misses (:func:`foot_wants`): s times the
    largest swing miss plus (1 - s) times the largest stance miss."""
    return (swing * max(wants[k] for k in SWING_WANTS if k in wants)
            + (1.0 - swing) * max(wants[k] for k in STANCE_WANTS if k in wants))


def foot_motion(soles_before: np.ndarray, soles: np.ndarray, sole_radius_m: float, control_dt_s: float,
                ground_m: list[float] | None = None) -> tuple[list[float], list[float]]:
    """Each foot's sole speed [m/s] over a control step (its contact points' mean, horizontal) and
    its lowest point's height [m] above the floor (``ground_m``: the ground under it) after it."""
    moved = (soles[:, :, :2].mean(axis=1) - soles_before[:, :, :2].mean(axis=1)).tolist()
    lifts = (soles[:, :, 2].min(axis=1) - sole_radius_m).tolist()
    if ground_m is not None:
        lifts = [lift - ground for lift, ground in zip(lifts, ground_m)]
    return [math.hypot(*m) / control_dt_s for m in moved], lifts


def followed(phase: float, soles_before: np.ndarray, soles: np.ndarray, shares: list[float], knees: list[float],
             sole_radius_m: float, env: EnvConfig, stopped: bool = False,
             ground_m: list[float] | None = None) -> float:
    """1 - (1/2) sum_feet miss over one control step (``reward.kgait``'s feature): the feet's
    contact points (2, k, 3) before and after it, their ground forces as shares of the weight
    and the legs' knee flexions after it (``stopped``: the clock stands still, both feet asked
    down; ``ground_m``: the ground's height under each foot, on terrain; None: the floor, 0)."""
    speeds, lifts = foot_motion(soles_before, soles, sole_radius_m, env.control_dt_s, ground_m)
    gait = 0.0
    for foot, swing in enumerate((0.0, 0.0) if stopped else swing_weights(phase, env.swing_share)):
        gait -= 0.5 * foot_miss(swing, shares[foot], speeds[foot], lifts[foot], knees[foot], env)
    return gait + 1.0


def gait_at_speed(env: EnvConfig, speed_m_s: float) -> tuple[float, float]:
    """The clock's period T [s] and kstep's step length L* [m] at commanded speed v*
    (``env.gait_follows_speed``: T = T0 sqrt(v0 / v*), L* = L0 sqrt(v* / v0), v0 = 2 L0 / T0;
    at v* = 0 the clock stops, T infinite, L* 0; otherwise ``env.gait_period_s``, ``env.step_length_m``)."""
    if not env.gait_follows_speed:
        return env.gait_period_s, env.step_length_m
    if speed_m_s <= 0:
        return math.inf, 0.0
    ratio = math.sqrt(speed_m_s * env.gait_period_s / (2 * env.step_length_m))  # sqrt(v* / v0)
    return env.gait_period_s / ratio, env.step_length_m * ratio
