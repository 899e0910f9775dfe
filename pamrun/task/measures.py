"""Per-step measures of the gait that the reward and the evaluation's gait metrics share: when a
foot is on the ground, when a joint is at its stop, how far a foot's ground point slides, and a
step's length, how far a foot on the ground is tilted onto its sole's edge. Each works on one
step's values or, where it says so, on rows of them."""

from __future__ import annotations

import numpy as np

from pamrun.physics.body import JOINTS, SIDES, SOLE_CORNERS

STOP_MARGIN_DEG = 2.0  # a joint 'at its stop': within this of a limit (reward.kstop and the gait metrics)
# reward.knear charges a joint from this far inside a limit on: far enough to give the policy a gradient
# before STOP_MARGIN_DEG counts it at the stop (pamrun's choice: 5 x the margin)
STOP_BAND_DEG = 10.0
# A foot carrying less than this share of the body weight is taken as off the ground.
CONTACT_WEIGHT_SHARE = 0.05
KNEES = [JOINTS.index(f"{side}_knee") for side in SIDES]  # each leg's knee column, in foot order (right, left)
HIP_PITCHES = [JOINTS.index(f"{side}_hip_pitch") for side in SIDES]  # ... its hip's pitch (extension +)
ANKLE_PITCHES = [JOINTS.index(f"{side}_ankle_pitch") for side in SIDES]  # ... and its ankle's pitch (plantarflexion +)
_LEFT_EDGE = [i for i, (_, edge) in enumerate(SOLE_CORNERS) if edge == "left"]  # a sole's corners on its left edge
_RIGHT_EDGE = [i for i, (_, edge) in enumerate(SOLE_CORNERS) if edge == "right"]


def stop_bounds(limits_rad, margin_rad: float) -> np.ndarray:
    """(10, 2): the angles below and above which each joint is at a stop, its limits moved
    ``margin_rad`` inward."""
    return np.asarray(limits_rad, float) + [margin_rad, -margin_rad]


def at_stops(q, bounds: np.ndarray) -> np.ndarray:
    """Which joints are at a stop: q (..., 10) [rad] on or past ``bounds`` (:func:`stop_bounds`)."""
    q = np.asarray(q, float)
    return (q <= bounds[:, 0]) | (q >= bounds[:, 1])


def stop_share(q, bounds: np.ndarray, contact) -> float:
    """Share of the hip and ankle joints, and of the knees of legs whose foot is off the ground,
    at a stop (``reward.kstop``'s; a knee in stance rests on its stop by design, its lock)."""
    at = at_stops(q, bounds).tolist()
    counted = _counted_joints(len(at), contact)
    return sum(at[j] for j in counted) / len(counted)


def _counted_joints(n_joints: int, contact) -> list[int]:
    """The joints a stop measure counts: the hips and ankles, and the knees of legs whose foot is off
    the ground (a knee in stance rests on its extension stop by design, its lock)."""
    return [j for j in range(n_joints) if j not in KNEES] + [k for k, down in zip(KNEES, contact) if not down]


def stop_nearness(q, limits_rad, band_rad: float, contact) -> float:
    """Sum over the joints :func:`stop_share` counts of (1 - d / band)^2 for d < band, d [rad] the
    distance from q to the nearer limit (1 on or past it, 0 from ``band_rad`` inside on): each joint
    charged on its own (``reward.knear``'s), not as a share of ten. Plain floats: one control step's
    10 joints cost less in Python than in numpy."""
    total = 0.0
    for j in _counted_joints(len(q), contact):
        lo, hi = limits_rad[j]
        d = min(q[j] - lo, hi - q[j])
        if d < band_rad:
            total += 1.0 if d <= 0.0 else (1.0 - d / band_rad) ** 2
    return total


def ground_point_shift_m(before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """(..., 2, 2): how far [m] each foot's ground point moved in x and y between two rows of
    contact points (..., 2, k, 3). The ground point is the point lowest in ``before``, followed to
    ``after``: a foot rolling over its heel or toe does not slide (the slip of ``reward.kslip`` and
    of the gait metrics: its length over the time between the rows)."""
    lowest = np.argmin(before[..., 2], axis=-1)[..., None, None]
    start = np.take_along_axis(before, lowest, axis=-2)[..., 0, :2]
    end = np.take_along_axis(after, lowest, axis=-2)[..., 0, :2]
    return end - start


def step_length(soles: np.ndarray, foot: int) -> float:
    """A step's length [m] as ``foot`` touches down: its sole centre's forward (x) distance ahead
    of the other foot's; ``soles`` (2, k, 3), each foot's contact points (the one definition:
    the gait metrics' and reward.kstep's)."""
    return float(soles[foot, :, 0].mean() - soles[1 - foot, :, 0].mean())


def sole_tilt_rad(soles) -> np.ndarray:
    """(..., 2): each foot's side-to-side tilt [rad], positive with its left edge the higher: the
    angle from the horizontal of the line from the mean of its right-edge contact points to the
    mean of its left-edge ones; ``soles`` (..., 2, 4, 3) in ``SOLE_CORNERS`` order. A sole flat
    on level ground gives 0, whatever its heading or its pitch (a foot rolling heel to toe)."""
    soles = np.asarray(soles, float)
    across = soles[..., _LEFT_EDGE, :].mean(axis=-2) - soles[..., _RIGHT_EDGE, :].mean(axis=-2)
    return np.arctan2(across[..., 2], np.hypot(across[..., 0], across[..., 1]))
