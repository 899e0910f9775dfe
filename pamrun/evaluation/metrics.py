"""Gait and air metrics of one episode, from its per-step arrays (no simulator needed).

An episode's ``steps`` (see ``pamrun.evaluation.episodes.run_episode``) holds one row per control step:
``t_s``, torso ``x_m``, ``joint_angle_rad`` / ``joint_velocity_rad_s`` / ``joint_torque_nm``
(n, 10) in ``pamrun.physics.body.JOINTS`` order, ``pressure_kpa`` / ``contraction_pct`` (n, 20),
``foot_force_n`` (n, 2) and ``sole_xyz_m`` (n, 2, 4, 3), the centres of each foot's four
contact spheres (or ``foot_xyz_m`` (n, 2, 3), one point per foot), feet ordered right, left.
Lists (as read from episodes.jsonl) and arrays are both accepted.

Definitions (the manual of :func:`episode_metrics`):

* **contact**: a foot is in contact in a row when its normal force exceeds
  ``GaitSpec.contact_threshold_n``.
* **steady contact**: the contact with its flickers merged: a run of rows off the ground
  shorter than ``MIN_PHASE_S`` (two control steps) between two in contact counts as contact,
  and then a run in contact that short between two off the ground as off. A foot that
  bounces for one control step as it lands has landed once. The step events below, the
  swing clearance and the knee's phases read steady contact; the shares of rows (duty,
  double support, flight, slip, stops in swing) read the contact row by row.
* **touchdown**: a row where a foot is in steady contact and was not in the row before (a
  rising edge; a foot already down in the first row has not touched down). Every touchdown
  is a **step** of that foot.
* **step length**: forward (x) distance from the other foot's sole centre to the sole centre
  of the foot touching down, at the touchdown (negative for a step backwards).
* **touchdown reach**: forward (x) distance from the torso (``x_m``) to the sole centre of the foot
  touching down, at the touchdown, averaged over the steps (half the step length when the torso
  is midway between the feet as a foot lands; near 0, the foot lands under the hip).
* **step time**: time from the other foot's previous touchdown to this one (undefined for a
  step before the other foot has touched down).
* **step frequency**: steps per second over the span of the detected steps,
  (k - 1) / (t_last - t_first) for k touchdowns of either foot.
* **stride length**: forward (x) distance a foot moves from one of its touchdowns to its
  next, averaged over both feet (in a gallop the step lengths alternate in sign and their
  mean says little; the stride length is what each foot covers per cycle).
* **symmetry index** of a quantity: |L - R| / ((|L| + |R|) / 2) of its mean over the left
  foot's and the right foot's steps (0 = symmetric; left 0.3 s, right 0.5 s gives 0.5; 2 when
  the signs differ, e.g. one foot always landing behind the other).
* **hop share**: the share of the touchdowns that come within ``HOP_WINDOW_S`` of a touchdown
  of the other foot (both feet landing together: a hop or bound, not a step; a walk's
  footfalls alternate, 0; two-footed hopping, 1).
* **re-touch share**: the share of the touchdowns that follow a touchdown of the same foot,
  none of the other foot's between (a stance split by a lift of at least ``MIN_PHASE_S``, or a
  hop on one leg; a walk's footfalls alternate, 0). Step frequency counts each as a step.
* **duty factor**: the share of the rows in which a foot is in contact, averaged over both
  feet (over the whole episode: standing still is 1).
* **stop share** of a joint: the share of the rows in which its angle lies within
  ``stop_margin_rad`` of its lower or upper limit (or past it).
* **knee swing stop share**: the share of the rows in which a foot is off the ground and its
  knee lies within ``stop_margin_rad`` of a stop, pooled over both legs (the knee's stop share
  counts its lock in stance, by design; in swing a walker's knee bends). ``stop_share_gait_max``
  is the largest stop share counting the knees in swing only (the walker issue's target: no
  joint at a stop more than 30 % of the time but the knee's lock in stance).
* **swing clearance**: the highest a foot's lowest contact point rises in a swing (a run of
  rows off the ground between two rows on it), above that point's median height in the foot's
  rows in contact (the ground, less the contact spheres' radius), averaged over the swings of
  both feet. It measures the foot, not the knee: a bounding gait lifts its feet high on
  straight knees.
* **foot slip**: mean horizontal (x, y) speed of a foot's ground point between consecutive
  rows in which the foot is in contact in both, pooled over both feet. The ground point is
  the contact sphere lowest at the first of the two rows, followed to the second: a foot
  rolling over its heel or toe does not slip, and its ankle, which moves as it rolls, is not
  what touches the ground.
* **sole tilt**: the mean side-to-side tilt [deg] of a foot in contact
  (:func:`pamrun.task.measures.sole_tilt_rad`, its absolute value), over the rows in which it is,
  pooled over both feet (0: every foot on the ground flat across its width; a foot on its
  sole's edge grips by two corners, and pivots and slides).
* **double support share** and **flight share**: the share of the rows after the first
  ``SETTLE_S`` (the start from standing, left out of these and the knee's metrics) in which both
  feet are in contact, and in which neither is (a human walking at 1 m/s: about 20 % and 0; a
  run: none and its flight).
* **stance** and **swing** of a foot: a run of rows in contact, from a touchdown to the row
  before the lift-off, and a run of rows off the ground, from the lift-off to the row before
  the touchdown, in steady contact. Only complete phases count: not the one the episode starts
  or ends in.
* **knee flexion**: how far a knee is bent from straight, its extension stop (its lower
  limit), in degrees; 0 at the stop or past it.
* **knee at mid-stance**: the knee's flexion at the middle of a stance (linear between rows when
  the middle falls between two), averaged over the stances of both legs that begin after the
  first ``SETTLE_S`` (a human's, walking: nearly straight, under 15 deg).
* **knee swing peak**: the largest knee flexion in a swing, averaged over the swings of both
  legs that begin after the first ``SETTLE_S`` (a human's, walking: about 60 deg; the first
  step from standing swings lower).
* **knee at touchdown**: the knee's flexion in the row a foot touches down (the step table's
  touchdowns), averaged over those after the first ``SETTLE_S`` (a human's at heel strike: about
  5 deg; a knee still bent lands its foot under the knee, short of the hip's reach).
* **stance hip extension**: the largest hip pitch (extension +, the thigh behind the torso) in a
  stance, in degrees, averaged over the stances of both legs that begin after the first ``SETTLE_S``
  (a human's, walking: 10-20 deg as the other foot lands; a hip that stops extending under the body
  leaves the trailing leg there, and the step short).
* **hip at touchdown**: the hip's flexion (minus its pitch: + the thigh ahead of the torso) in the
  row a foot touches down, in degrees, averaged over the touchdowns after the first ``SETTLE_S`` (a
  human's at heel strike: about 25 deg; near 0, the foot lands under the hip and the step is short).
* **swing hip peak**: the largest hip flexion (minus its pitch) in a swing, averaged over the swings of
  both legs that begin after the first ``SETTLE_S`` (a human's: about 30 deg, some 5 more than at heel
  strike; far above the hip at touchdown, the leg swung ahead and was pulled back before it landed).
* **cost of transport** (mechanical): sum over rows and joints of |torque x velocity| x dt,
  divided by m g d with d = x_m[-1] - x_m[0], the torso's forward distance. Each row's power
  stands for the control step that ends at it, so the rows after the first are summed (the
  first row's step began before x_m[0]); constant power P at constant speed v gives
  P / (m g v). Negative work counts too (|.|): a muscle spends air to brake as well.
* **air**: the supply air the muscles draw, :func:`pamrun.physics.muscle.air_nl`, in normal
  litres, and per metre of d.

Every metric is a float, NaN where undefined (too few steps, d <= 0, ...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pamrun.physics.actuation import joint_limits_rad, muscle_counts
from pamrun.physics.body import GRAVITY, JOINTS
from pamrun.physics.muscle import MUSCLE_INNER_DIAMETER_M, air_nl
from pamrun.task.measures import (
    CONTACT_WEIGHT_SHARE,
    HIP_PITCHES,
    KNEES,
    STOP_MARGIN_DEG,
    at_stops,
    ground_point_shift_m,
    sole_tilt_rad,
    step_length,
    stop_bounds,
)

RIGHT, LEFT = 0, 1  # foot columns of foot_force_n / foot_xyz_m

GAIT_METRICS = (
    "step_count",
    "step_frequency_hz",
    "step_length_m",
    "touchdown_reach_m",
    "stride_length_m",
    "step_time_symmetry",
    "step_length_symmetry",
    "hop_share",
    "retouch_share",
    "duty_factor",
    *(f"stop_share_{joint}" for joint in JOINTS),
    "stop_share_max",
    "knee_swing_stop_share",
    "stop_share_gait_max",
    "swing_clearance_m",
    "foot_slip_m_s",
    "sole_tilt_deg",
    "torso_pitch_deg",
    "torso_sway_deg",
    "cost_of_transport",
    "air_nl",
    "air_nl_per_m",
    "double_support_share",
    "flight_share",
    "knee_midstance_deg",
    "knee_swing_peak_deg",
    "knee_touchdown_deg",
    "hip_extension_deg",
    "hip_touchdown_deg",
    "hip_swing_peak_deg",
)
HOP_WINDOW_S = 0.05  # two feet touching down this close together land as one (two control steps)
SETTLE_S = 1.0  # the support shares and the knee's phases leave out the episode's first second
MIN_PHASE_S = 0.05  # a stance or swing shorter than this (two control steps) is a flicker, not a phase


@dataclass(frozen=True, eq=False)
class GaitSpec:
    """What the metrics need to know about the robot.

    ``contact_threshold_n`` defaults to 5 % of the body weight (``CONTACT_WEIGHT_SHARE``): a
    foot in stance carries about half the weight or more, a swinging foot none, so the
    threshold sits far from both and moves a touchdown or lift-off by a control step at
    most; it is high enough that a foot grazing the ground (MuJoCo's soft contact reports a
    small force before the feet really touch) is not a step, and it scales with the robot.
    """

    dt_s: float  # control step [s]
    joint_limits_rad: np.ndarray  # (10, 2) [lower, upper] in JOINTS order
    mass_kg: float  # the robot's total mass
    muscles_per_side: np.ndarray  # (10,) muscles in parallel per direction of each joint
    nominal_length_m: float  # muscle nominal length L0
    inner_diameter_m: float  # muscle inner diameter D0
    gravity_m_s2: float = GRAVITY
    contact_threshold_n: float | None = None  # None: CONTACT_WEIGHT_SHARE of the weight
    stop_margin_rad: float = math.radians(STOP_MARGIN_DEG)

    def __post_init__(self) -> None:
        set_ = object.__setattr__  # frozen
        set_(self, "joint_limits_rad", np.asarray(self.joint_limits_rad, float).reshape(len(JOINTS), 2))
        set_(self, "muscles_per_side", np.broadcast_to(np.asarray(self.muscles_per_side, float), (len(JOINTS),)))
        if self.contact_threshold_n is None:
            set_(self, "contact_threshold_n", CONTACT_WEIGHT_SHARE * self.mass_kg * self.gravity_m_s2)

    @classmethod
    def from_configs(cls, body_cfg, muscle_cfg, mass_kg: float, dt_s: float, **overrides) -> GaitSpec:
        """The spec of a robot built from its BodyConfig and MuscleConfig (mass from the model)."""
        return cls(
            dt_s=dt_s,
            joint_limits_rad=joint_limits_rad(body_cfg),
            mass_kg=mass_kg,
            muscles_per_side=muscle_counts(muscle_cfg),
            nominal_length_m=muscle_cfg.nominal_length_m,
            inner_diameter_m=MUSCLE_INNER_DIAMETER_M[muscle_cfg.size],
            **overrides,
        )


def contacts(steps: dict, spec: GaitSpec | float) -> np.ndarray:
    """(n, 2) bool: right and left foot in contact per row (``spec`` or a threshold in N)."""
    threshold = spec.contact_threshold_n if isinstance(spec, GaitSpec) else float(spec)
    return np.asarray(steps["foot_force_n"], float).reshape(-1, 2) > threshold


def touchdowns(contact: np.ndarray) -> list[np.ndarray]:
    """Rows where each foot touches down (contact rising edges), [right, left]."""
    contact = np.asarray(contact, bool)
    rising = contact[1:] & ~contact[:-1]
    return [np.flatnonzero(rising[:, foot]) + 1 for foot in (RIGHT, LEFT)]


def sole_points(steps: dict) -> np.ndarray:
    """(n, 2, k, 3): each foot's contact points per row (k = 4 spheres, or 1 from foot_xyz_m)."""
    if "sole_xyz_m" in steps:
        points = np.asarray(steps["sole_xyz_m"], float)
        return points.reshape(len(points), 2, -1, 3)
    return np.asarray(steps["foot_xyz_m"], float).reshape(-1, 2, 1, 3)


def step_table(steps: dict, contact: np.ndarray) -> list[tuple[int, int, float, float]]:
    """Every step as (row, foot, step length [m], step time [s] or NaN), in time order."""
    t = np.asarray(steps["t_s"], float)
    points = sole_points(steps)
    events = sorted((int(row), foot) for foot, rows in enumerate(touchdowns(contact)) for row in rows)
    last = [None, None]  # row of each foot's previous touchdown
    out = []
    for row, foot in events:
        other = 1 - foot
        length = step_length(points[row], foot)
        time = t[row] - t[last[other]] if last[other] is not None else math.nan
        out.append((row, foot, float(length), float(time)))
        last[foot] = row
    return out


def hop_share(steps: dict, contact: np.ndarray) -> float:
    """Share of the touchdowns within ``HOP_WINDOW_S`` of a touchdown of the other foot (NaN
    without touchdowns)."""
    t = np.asarray(steps["t_s"], float)
    times = [t[rows] for rows in touchdowns(contact)]
    if not sum(map(len, times)):
        return math.nan
    gaps = [np.abs(own[:, None] - other[None, :]).min(axis=1, initial=np.inf)  # to the other foot's nearest
            for own, other in ((times[0], times[1]), (times[1], times[0]))]
    together = sum(int(np.count_nonzero(gap <= HOP_WINDOW_S + 1e-9)) for gap in gaps)
    return together / sum(map(len, times))


def retouch_share(table: list[tuple[int, int, float, float]]) -> float:
    """Share of the touchdowns of a :func:`step_table` (after the first) that follow one of the same
    foot (NaN with fewer than two touchdowns)."""
    feet = [foot for _, foot, _, _ in table]
    if len(feet) < 2:
        return math.nan
    return sum(a == b for a, b in zip(feet[:-1], feet[1:])) / (len(feet) - 1)


def symmetry_index(right: float, left: float) -> float:
    """|L - R| / mean(|L|, |R|); NaN when either is undefined or both are 0.

    For positive L and R this is |L - R| / mean(L, R). The magnitudes keep it in [0, 2] when
    the signs differ: a gallop whose left foot always lands behind the right has step
    lengths +0.3 m and -0.26 m, an index of 2 (the most asymmetric), not 28."""
    mean = 0.5 * (abs(left) + abs(right))
    return abs(left - right) / mean if np.isfinite(mean) and mean != 0 else math.nan


def _mean(values) -> float:
    values = [v for v in values if np.isfinite(v)]
    return float(np.mean(values)) if values else math.nan


def stop_shares(joint_angle_rad, spec: GaitSpec) -> np.ndarray:
    """(10,) share of the rows each joint lies within ``stop_margin_rad`` of a limit."""
    q = np.asarray(joint_angle_rad, float).reshape(-1, len(JOINTS))
    at_stop = at_stops(q, stop_bounds(spec.joint_limits_rad, spec.stop_margin_rad))
    return at_stop.mean(axis=0) if len(q) else np.full(len(JOINTS), math.nan)


def knee_swing_stop_share(joint_angle_rad, contact: np.ndarray, spec: GaitSpec) -> float:
    """Share of the rows with a foot off the ground in which that leg's knee is at a stop, pooled
    over both legs (a knee in stance rests on its stop by design, its lock; in swing it bends)."""
    q = np.asarray(joint_angle_rad, float).reshape(-1, len(JOINTS))
    at_stop = at_stops(q, stop_bounds(spec.joint_limits_rad, spec.stop_margin_rad))[:, KNEES]  # foot order
    swing = ~contact[: len(q)]
    return float(at_stop[swing].mean()) if swing.any() else math.nan


def swing_clearance_m(steps: dict, contact: np.ndarray) -> float:
    """Mean over complete swings of both feet of the peak height [m] of the foot's lowest contact
    point above its median height in contact (module docstring); NaN without a complete swing."""
    lowest = sole_points(steps)[..., 2].min(axis=2)  # (n, 2)
    peaks = []
    for foot, lands in enumerate(touchdowns(contact)):
        down = contact[:, foot]
        lifts = np.flatnonzero(down[:-1] & ~down[1:]) + 1  # first row off the ground
        ground = float(np.median(lowest[down, foot])) if len(lands) else 0.0  # unused without a touchdown
        for start, k in zip(lifts, np.searchsorted(lands, lifts)):  # k: the touchdown that ends it
            if k < len(lands):  # it lands again: a complete swing
                peaks.append(float(lowest[start:lands[k], foot].max()) - ground)
    return _mean(peaks)


def foot_slip_m_s(steps: dict, contact: np.ndarray) -> float:
    """Mean horizontal speed [m/s] of the feet between consecutive rows in contact at both ends."""
    t = np.asarray(steps["t_s"], float)
    points = sole_points(steps)  # (n, 2, k, 3)
    both = contact[1:] & contact[:-1]  # (n - 1, 2)
    speed = np.linalg.norm(ground_point_shift_m(points[:-1], points[1:]), axis=-1) / np.diff(t)[:, None]
    return float(speed[both].mean()) if both.any() else math.nan


def sole_tilt_deg(steps: dict, contact: np.ndarray) -> float:
    """Mean |side-to-side tilt| [deg] of the feet over the rows each is in contact (NaN without
    such a row, or without the four contact points per foot it is measured on)."""
    points = sole_points(steps)
    if points.shape[2] != 4 or not contact.any():
        return math.nan
    return float(np.degrees(np.abs(sole_tilt_rad(points))[contact]).mean())


def torso_lean_and_sway_deg(steps: dict) -> tuple[float, float]:
    """After the first ``SETTLE_S``: the torso's mean pitch [deg], + leaning forward, and how far it
    rocks side to side [deg], half the range between the 5th and 95th percentiles of its roll (a
    torso rolling +-7 deg each step reads about 7; a push's single lurch barely counts). NaN, NaN
    without such a row, or for an episode recorded without the torso's orientation."""
    late = np.asarray(steps["t_s"], float) > SETTLE_S + 1e-9
    if "torso_rpy_rad" not in steps or not late.any():
        return math.nan, math.nan
    roll, pitch = np.degrees(np.asarray(steps["torso_rpy_rad"], float).reshape(-1, 3)[late, :2]).T
    return float(pitch.mean()), float(np.subtract(*np.percentile(roll, [95, 5])) / 2)


def support_shares(steps: dict, contact: np.ndarray) -> tuple[float, float]:
    """Shares of the rows after the first ``SETTLE_S`` with both feet in contact and with neither
    (NaN, NaN when the episode is no longer)."""
    late = contact[np.asarray(steps["t_s"], float) > SETTLE_S + 1e-9]
    if not len(late):
        return math.nan, math.nan
    return float(late.all(axis=1).mean()), float((~late.any(axis=1)).mean())


def steady(contact: np.ndarray, dt_s: float) -> np.ndarray:
    """(n, 2) steady contact: ``contact`` with each foot's flickers shorter than ``MIN_PHASE_S``
    merged into the runs around them, off-ground runs first (module docstring)."""
    min_rows = max(1, round(MIN_PHASE_S / dt_s))
    out = np.asarray(contact, bool).copy()
    for foot in range(out.shape[1]):
        column = out[:, foot]
        for value in (False, True):
            for run_value, a, b in runs(column)[1:-1]:
                if run_value == value and b - a < min_rows:
                    column[a:b] = not value
    return out


def runs(column: np.ndarray) -> list[tuple[bool, int, int]]:
    """The runs of equal values of a bool column, as (value, first row, end row), in row order."""
    bounds = [0, *(np.flatnonzero(np.diff(column.astype(int))) + 1).tolist(), len(column)]
    return [(bool(column[a]), a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def phases(column: np.ndarray) -> list[tuple[bool, int, int]]:
    """A foot's complete stances (True) and swings (False) as (value, first row, end row): its
    steady contact column's runs but the first and the last."""
    return runs(np.asarray(column, bool))[1:-1]


def knee_flexion_deg(joint_angle_rad, spec: GaitSpec) -> np.ndarray:
    """(n, 2): each leg's knee flexion [deg] per row, right and left (0 at its stop or past it)."""
    q = np.asarray(joint_angle_rad, float).reshape(-1, len(JOINTS))[:, KNEES]
    return np.degrees(np.maximum(q - spec.joint_limits_rad[KNEES, 0], 0.0))


def hip_pitch_deg(joint_angle_rad) -> np.ndarray:
    """(n, 2): each leg's hip pitch [deg] per row, right and left (extension +, the thigh behind the torso)."""
    return np.degrees(np.asarray(joint_angle_rad, float).reshape(-1, len(JOINTS))[:, HIP_PITCHES])


def leg_phases_deg(steps: dict, contact: np.ndarray, spec: GaitSpec) -> tuple[float, float, float, float]:
    """The knee's flexion [deg] at mid-stance and its peak in swing, and the hip's largest extension in
    stance and largest flexion in swing [deg], each averaged over the complete phases of both legs that begin after the first
    ``SETTLE_S`` (NaN without one); ``contact``: steady."""
    flexion = knee_flexion_deg(steps["joint_angle_rad"], spec)
    hips = hip_pitch_deg(steps["joint_angle_rad"])
    late = np.asarray(steps["t_s"], float) > SETTLE_S + 1e-9
    rows = np.arange(len(flexion))
    mid, peak, extension, hip_peak = [], [], [], []
    for foot in (RIGHT, LEFT):
        for down, a, b in phases(contact[: len(flexion), foot]):
            if not late[a]:
                continue
            if down:
                mid.append(float(np.interp(0.5 * (a + b - 1), rows, flexion[:, foot])))
                extension.append(float(hips[a:b, foot].max()))
            else:
                peak.append(float(flexion[a:b, foot].max()))
                hip_peak.append(float(-hips[a:b, foot].min()))
    return _mean(mid), _mean(peak), _mean(extension), _mean(hip_peak)


def touchdown_flexions_deg(steps: dict, table: list, spec: GaitSpec) -> tuple[float, float]:
    """The knee's flexion and the hip's (minus its pitch) [deg] in the rows of the step table's touchdowns
    after the first ``SETTLE_S``, each averaged (NaN without one)."""
    flexion, t = knee_flexion_deg(steps["joint_angle_rad"], spec), np.asarray(steps["t_s"], float)
    hips = -hip_pitch_deg(steps["joint_angle_rad"])
    landings = [(row, foot) for row, foot, _, _ in table if t[row] > SETTLE_S + 1e-9]
    return _mean([flexion[row, foot] for row, foot in landings]), _mean([hips[row, foot] for row, foot in landings])


def gait_cycle(values, starts, points: int = 101) -> tuple[np.ndarray, np.ndarray]:
    """Values over the gait cycle: each stride (row ``starts[k]`` to ``starts[k + 1]``)
    resampled linearly onto 0-100 % in ``points`` points.

    ``values`` is (n, ...) per row; returns the percent grid (points,) and the strides
    (len(starts) - 1, points, ...), an empty first axis when there is no full stride.
    """
    values = np.asarray(values, float)
    flat = values.reshape(len(values), -1)
    grid = np.linspace(0.0, 100.0, points)
    strides = []
    for a, b in zip(starts[:-1], starts[1:]):
        percent = np.linspace(0.0, 100.0, b - a + 1)
        strides.append(np.stack([np.interp(grid, percent, col) for col in flat[a:b + 1].T], axis=-1))
    shape = (len(strides), points) + values.shape[1:]
    return grid, np.asarray(strides).reshape(shape)


def episode_metrics(steps: dict, spec: GaitSpec) -> dict[str, float]:
    """The metrics of :data:`GAIT_METRICS` for one episode (definitions: module docstring)."""
    nan = math.nan
    out = dict.fromkeys(GAIT_METRICS, nan)
    x = np.asarray(steps["x_m"], float)
    n = len(x)
    if n == 0:
        return out
    contact = contacts(steps, spec)
    events = steady(contact, spec.dt_s)  # for steps and phases; the row shares read contact

    table = step_table(steps, events)
    out["step_count"] = float(len(table))
    if len(table) >= 2:
        t = np.asarray(steps["t_s"], float)
        span = t[table[-1][0]] - t[table[0][0]]
        out["step_frequency_hz"] = (len(table) - 1) / span if span > 0 else nan
    per_foot = {foot: [s for s in table if s[1] == foot] for foot in (RIGHT, LEFT)}
    feet_x = sole_points(steps)[..., 0].mean(axis=2)
    if table:
        out["step_length_m"] = _mean([length for _, _, length, _ in table])
        out["touchdown_reach_m"] = _mean([feet_x[row, foot] - x[row] for row, foot, _, _ in table])
    out["stride_length_m"] = _mean([d for foot, rows in enumerate(touchdowns(events))
                                    for d in np.diff(feet_x[rows, foot])])
    out["step_time_symmetry"] = symmetry_index(*(_mean([s[3] for s in per_foot[f]]) for f in (RIGHT, LEFT)))
    out["step_length_symmetry"] = symmetry_index(*(_mean([s[2] for s in per_foot[f]]) for f in (RIGHT, LEFT)))
    out["hop_share"] = hop_share(steps, events)
    out["retouch_share"] = retouch_share(table)
    out["duty_factor"] = float(contact.mean())

    shares = stop_shares(steps["joint_angle_rad"], spec)
    for joint, share in zip(JOINTS, shares):
        out[f"stop_share_{joint}"] = float(share)
    out["stop_share_max"] = float(np.max(shares))
    out["knee_swing_stop_share"] = knee_swing_stop_share(steps["joint_angle_rad"], contact, spec)
    out["stop_share_gait_max"] = float(np.nanmax([*(sh for j, sh in zip(JOINTS, shares) if "knee" not in j),
                                                  out["knee_swing_stop_share"]]))

    out["swing_clearance_m"] = swing_clearance_m(steps, events)
    out["foot_slip_m_s"] = foot_slip_m_s(steps, contact)
    out["sole_tilt_deg"] = sole_tilt_deg(steps, contact)
    out["torso_pitch_deg"], out["torso_sway_deg"] = torso_lean_and_sway_deg(steps)
    out["double_support_share"], out["flight_share"] = support_shares(steps, contact)
    (out["knee_midstance_deg"], out["knee_swing_peak_deg"], out["hip_extension_deg"],
     out["hip_swing_peak_deg"]) = leg_phases_deg(steps, events, spec)
    out["knee_touchdown_deg"], out["hip_touchdown_deg"] = touchdown_flexions_deg(steps, table, spec)

    distance = float(x[-1] - x[0])
    power = np.abs(np.asarray(steps["joint_torque_nm"], float) * np.asarray(steps["joint_velocity_rad_s"], float))
    work = float(power.reshape(n, -1)[1:].sum() * spec.dt_s)
    air = air_nl(np.asarray(steps["pressure_kpa"], float).reshape(n, -1),
                 np.asarray(steps["contraction_pct"], float).reshape(n, -1),
                 spec.nominal_length_m, spec.inner_diameter_m, spec.muscles_per_side)
    out["air_nl"] = air
    if distance > 0:
        out["cost_of_transport"] = work / (spec.mass_kg * spec.gravity_m_s2 * distance)
        out["air_nl_per_m"] = air / distance
    return out
