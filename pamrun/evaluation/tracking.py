"""How well an episode follows its commanded speed v*, how still it stands where v* = 0, and how its
feet keep to the gait clock, from its per-step arrays (``t_s``, ``x_m``, ``y_m``, ``foot_force_n``,
``target_speed_m_s`` and ``clock_touchdown_offset``, as :func:`pamrun.evaluation.episodes.run_episode`
records them).

v* is piecewise constant (``env.speed_schedule``, drawn changes, or one speed for the episode);
each constant stretch is a *segment*, from the change (0 s for the first) to the next change or
the episode's end. After ``SETTLE_S`` of settling a segment is cut into ``WINDOW_S`` windows, a
leftover of at least ``MIN_WINDOW_S`` (more than a stride) a shorter window of its own (so a
2.5 s segment has one 1 s window); a window's error is its mean forward speed (its x travel over
its length) minus v*.

* ``speed_tracking_rms_m_s``: the RMS of the windows' errors over the episode, each weighted by
  its length (with whole windows only: the plain RMS) [m/s];
* ``stand_still_feet_down_share``: in the segments where v* = 0, after settling, the share of
  control steps with both feet on the ground (each carrying more than the contact threshold);
* ``stand_still_drift_m``: in the same stretches, the torso's horizontal displacement from the
  end of settling to the segment's end, summed over the segments [m].

How well the feet keep to the gait clock (``clock_touchdown_offset``, each foot's clock past its
touchdown per step, a share of the period in [-0.5, 0.5); NaN without a clock or while it stands still),
over the touchdowns after the first ``CLOCK_SETTLE_S`` at which the clock runs (rising edges of contact,
a foot's force above the threshold, row by row, as ``ktouch`` charges them):

* ``touchdown_clock_offset``: the median offset at those touchdowns (+: the feet land late; a foot
  cadence above the clock's drifts through every value);
* ``touchdown_on_clock_share``: the share of them within ``pamrun.task.clock.TOUCHDOWN_WINDOW_SHARE``
  (0.1 of the period) of the clock's touchdown, where ``ktouch`` does not charge them.

Each is NaN where it is undefined (no whole window; no v* = 0 segment outlasting its settling),
e.g. in an episode that falls before its first window ends.
"""

from __future__ import annotations

import math

import numpy as np

from pamrun.evaluation.metrics import contacts, touchdowns
from pamrun.task.clock import TOUCHDOWN_WINDOW_SHARE

SETTLE_S = 1.5  # after a change of v*, the time the robot is given to reach it [s]
WINDOW_S = 2.0  # the windows the mean speed is measured over [s]
MIN_WINDOW_S = 1.0  # a segment's leftover after its whole windows is a window when at least this long [s]
SMOOTH_S = 0.5  # the window of the measured speed the speed figure draws [s]
CLOCK_SETTLE_S = 1.0  # the clock metrics leave out the touchdowns of the start from standing [s]
TRACKING_METRICS = ("speed_tracking_rms_m_s", "stand_still_feet_down_share", "stand_still_drift_m",
                    "touchdown_clock_offset", "touchdown_on_clock_share")


def segments(command: np.ndarray, dt: float) -> list[tuple[float, float, float]]:
    """The stretches of constant v* as (start [s], end [s], v*): ``command[i]`` is v* at the
    time of step i, (i + 1) dt; a segment starts where v* changes (the first at 0 s) and ends
    where the next starts, the last at the episode's end."""
    n = len(command)
    if n == 0:
        return []
    starts = [0, *(np.flatnonzero(np.diff(command) != 0) + 1).tolist()]
    times = [0.0, *((i + 1) * dt for i in starts[1:]), n * dt]
    return [(times[k], times[k + 1], float(command[i])) for k, i in enumerate(starts)]


def _at(values: np.ndarray, t: float, dt: float) -> float:
    """A per-step array's value at time ``t`` (a multiple of ``dt`` >= dt)."""
    return float(values[max(round(t / dt), 1) - 1])


def tracking_rms(x_m: np.ndarray, command: np.ndarray, dt: float) -> float:
    """``speed_tracking_rms_m_s`` (module docstring) of forward positions ``x_m`` under ``command``."""
    errors, lengths = [], []
    for start, end, speed in segments(command, dt):
        w0 = start + SETTLE_S
        while end - w0 >= MIN_WINDOW_S - 1e-9:
            length = min(WINDOW_S, end - w0)
            errors.append((_at(x_m, w0 + length, dt) - _at(x_m, w0, dt)) / length - speed)
            lengths.append(length)
            w0 += length
    return math.sqrt(float(np.average(np.square(errors), weights=lengths))) if errors else float("nan")


def stand_still(arrays: dict, contact_threshold_n: float, dt: float) -> tuple[float, float]:
    """``stand_still_feet_down_share`` and ``stand_still_drift_m`` (module docstring)."""
    t, down, drift = arrays["t_s"], [], 0.0
    both = contacts(arrays, contact_threshold_n).all(axis=1)
    for start, end, speed in segments(arrays["target_speed_m_s"], dt):
        settled = (t >= start + SETTLE_S - 1e-9) & (t <= end + 1e-9)
        if speed != 0 or not settled.any():
            continue
        first, last = np.flatnonzero(settled)[[0, -1]]
        down.append(both[settled])
        drift += math.hypot(arrays["x_m"][last] - arrays["x_m"][first], arrays["y_m"][last] - arrays["y_m"][first])
    if not down:
        return float("nan"), float("nan")
    return float(np.concatenate(down).mean()), float(drift)


def clock_keeping(arrays: dict, contact_threshold_n: float) -> tuple[float, float]:
    """``touchdown_clock_offset`` and ``touchdown_on_clock_share`` (module docstring); NaN without a
    touchdown on a running clock (or without the per-step offsets, an older episode's)."""
    if "clock_touchdown_offset" not in arrays:
        return float("nan"), float("nan")
    offsets = np.asarray(arrays["clock_touchdown_offset"], float).reshape(-1, 2)
    late = np.asarray(arrays["t_s"], float) > CLOCK_SETTLE_S + 1e-9
    at = np.concatenate([offsets[rows[late[rows]], foot]
                         for foot, rows in enumerate(touchdowns(contacts(arrays, contact_threshold_n)))])
    at = at[np.isfinite(at)]
    if not len(at):
        return float("nan"), float("nan")
    return float(np.median(at)), float(np.mean(np.abs(at) <= TOUCHDOWN_WINDOW_SHARE))


def tracking_metrics(arrays: dict, contact_threshold_n: float, dt: float) -> dict[str, float]:
    """:data:`TRACKING_METRICS` of one episode's per-step arrays (module docstring)."""
    share, drift = stand_still(arrays, contact_threshold_n, dt)
    offset, on_clock = clock_keeping(arrays, contact_threshold_n)
    return {"speed_tracking_rms_m_s": tracking_rms(np.asarray(arrays["x_m"]), np.asarray(arrays["target_speed_m_s"]), dt),
            "stand_still_feet_down_share": share, "stand_still_drift_m": drift,
            "touchdown_clock_offset": offset, "touchdown_on_clock_share": on_clock}


def smoothed_speed(t_s: np.ndarray, x_m: np.ndarray, window_s: float = SMOOTH_S) -> tuple[np.ndarray, np.ndarray]:
    """The forward speed over ``window_s`` windows centred on each step that has one: times [s]
    and speeds [m/s] (what the speed figure draws)."""
    t_s, x_m = np.asarray(t_s, float), np.asarray(x_m, float)
    if len(t_s) < 2:
        return np.zeros(0), np.zeros(0)
    half = max(1, round(window_s / (2 * (t_s[1] - t_s[0]))))
    if len(t_s) <= 2 * half:
        return np.zeros(0), np.zeros(0)
    return t_s[half:-half], (x_m[2 * half:] - x_m[:-2 * half]) / (t_s[2 * half:] - t_s[:-2 * half])
