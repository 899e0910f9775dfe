"""Per-step measures of the gait that the reward and the evaluation's gait metrics share:
when a foot is on the ground, when a joint is at its stop, and a step's length."""

from __future__ import annotations

import numpy as np

STOP_MARGIN_DEG = 2.0  # a joint 'at its stop': within this of a limit (reward.kstop and the gait metrics)
# A foot carrying less than this share of the body weight is taken as off the ground.
CONTACT_WEIGHT_SHARE = 0.05


def step_length(soles: np.ndarray, foot: int) -> float:
    """A step's length [m] as ``foot`` touches down: its sole centre's forward (x) distance ahead
    of the other foot's; ``soles`` (2, k, 3), each foot's contact points (the one definition:
    the gait metrics' and reward.kstep's)."""
    return float(soles[foot, :, 0].mean() - soles[1 - foot, :, 0].mean())
