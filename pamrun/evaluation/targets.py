"""The walk's targets: what a natural human-like walk at about 1 m/s measures, as bounds on the
means of an agent's episodes (:func:`pamrun.evaluation.episodes.aggregate`; the metrics:
:mod:`pamrun.evaluation.metrics`).

The bounds come from human walking at 0.8-1.4 m/s:
duty 61 % (Kirtley, Whittle & Jefferson 1985, J Biomed Eng 7:282), so about 20 % of the cycle
on both feet and none in the air; the knee near straight at mid-stance and about 60 deg at its
swing peak (the standard sagittal knee curve); 1.81 steps/s (Umberger & Martin 2007, J Exp Biol
210:3255); a symmetry index under 0.10 (Herzog et al. 1989, Med Sci Sports Exerc); a cost of
transport of about 0.3 for a human (the target allows twice it). The rest are pamrun's: a
foot that slips under 0.15 m/s, no joint at a stop more than 10 % of the time (knees in
swing), and under 30 kPa of pressure change per control step, against 50 kPa of the walker
the issue measured.
"""

from __future__ import annotations

import math

# the aggregate's key -> (lowest, highest) it may be; None: open
WALK_TARGETS: dict[str, tuple[float | None, float | None]] = {
    "flight_share_mean": (None, 0.02),
    "double_support_share_mean": (0.10, 0.30),
    "duty_factor_mean": (0.55, 0.68),
    "knee_midstance_deg_mean": (None, 15.0),
    "knee_swing_peak_deg_mean": (40.0, 70.0),
    "step_frequency_hz_mean": (1.5, 2.2),
    "step_length_m_mean": (0.45, None),
    "step_time_symmetry_mean": (None, 0.10),
    "step_length_symmetry_mean": (None, 0.10),
    "stop_share_gait_max_mean": (None, 0.10),
    "foot_slip_m_s_mean": (None, 0.15),
    "pressure_change_mean": (None, 30.0),
    "cost_of_transport_mean": (None, 0.6),
}


def met(key: str, value: float) -> bool:
    """Whether ``value`` of the aggregate's ``key`` lies within its target (NaN: not met)."""
    low, high = WALK_TARGETS[key]
    return math.isfinite(value) and (low is None or value >= low) and (high is None or value <= high)


def targets_met(result: dict) -> int:
    """How many of the :data:`WALK_TARGETS` an aggregate meets (a key it lacks: not met)."""
    return sum(met(key, float(result.get(key, math.nan))) for key in WALK_TARGETS)


def bounds_text(key: str) -> str:
    """A target as text: '0.55-0.68', '<= 0.02', '>= 0.45'."""
    low, high = WALK_TARGETS[key]
    if low is not None and high is not None:
        return f"{low:g}-{high:g}"
    return f"<= {high:g}" if low is None else f">= {low:g}"
