"""Muscle pairs on the robot's joints: action -> pressures -> forces -> joint torques.

Ten antagonistic pairs, one per hinge (``pamrun.body.JOINTS`` order). Muscle 1 of a pair
pulls the joint towards positive angles, muscle 2 towards negative ones; the policy's
action a in [-1, 1] sets V1 = V0 + 0.71 a, V2 = V0 - 0.71 a (thesis §9.5).

Two couplings of muscle and joint (``muscle.coupling``):

* ``thesis`` — as the thesis built it (§8.3): each muscle's contraction is its own dynamic
  state (D x' + S x = Fce - FL, :class:`pamrun.muscle.FirstOrderPairDynamics`) and the
  joint angle does not feed back into it; T = (F1 - F2) r.
* ``kinematic`` — physically consistent: each muscle's contraction follows the joint
  through its pulley, c1 = c_rest + 100 r theta / L0 and c2 = c_rest - 100 r theta / L0,
  so co-contraction stiffens the joint; the muscles' dampers (D = tau S) act on the joint
  velocity, T = (F1 - F2) r - (D1 + D2) r^2 theta'. Pressure follows the command through
  the regulator (and its lag, if set).

Pulley radii and rest contractions are not in the thesis. Both muscles of a pair sit at
``kinematic_rest_contraction_pct`` in the standing pose (a pre-tensioned pair: zero torque
at zero action), and each joint's radius is chosen so that its farthest limit takes a
muscle to ``kinematic_max_contraction_pct`` (the other to 2 c_rest - c_max >= 0):

    r_j = (c_max - c_rest) / 100 * L0 / max(|theta_lo|, |theta_hi|)

That keeps every contraction inside the force polynomial's fitted range. With the
defaults c_rest = 6.5 %, c_max = 13 % (the contraction near which F(c, 8 bar) * c, the
torque available at a limit, is largest), the same radii serve the thesis coupling.
"""

from __future__ import annotations

import numpy as np

from pamrun.config import BodyConfig, MuscleConfig
from pamrun.muscle import AntagonisticPairs

COUPLINGS = ("thesis", "kinematic")


def joint_limits_rad(body: BodyConfig) -> np.ndarray:
    """(10, 2) joint limits [rad], JOINTS order (right leg mirrors the roll joints, Table 8.3)."""
    from pamrun.body import LEG_JOINTS

    left = np.deg2rad([getattr(body, f"{j}_limits_deg") for j in LEG_JOINTS])
    right = left.copy()
    for k, name in enumerate(LEG_JOINTS):
        if name.endswith("roll"):
            right[k] = -left[k, ::-1]
    return np.concatenate([right, left])


def pulley_radii_m(muscle: MuscleConfig, body: BodyConfig) -> np.ndarray:
    """(10,) pulley radius of each joint [m] (see the module docstring for the rule)."""
    reach_rad = np.abs(joint_limits_rad(body)).max(axis=1)
    span_pct = muscle.kinematic_max_contraction_pct - muscle.kinematic_rest_contraction_pct
    return span_pct / 100.0 * muscle.nominal_length_m / reach_rad


class MuscleDrive:
    """All 20 muscles of the robot, stepped together with numpy."""

    def __init__(self, muscle: MuscleConfig, body: BodyConfig):
        if muscle.coupling not in COUPLINGS:
            raise ValueError(f"muscle.coupling: unknown {muscle.coupling!r}; known: {COUPLINGS}")
        self.cfg = muscle
        self.kinematic = muscle.coupling == "kinematic"
        self.radius_m = pulley_radii_m(muscle, body)
        self.pairs = AntagonisticPairs(muscle, len(self.radius_m))
        self.voltage_v = self.pairs.voltages_v(np.zeros(len(self.radius_m)))
        self._pct_per_rad = 100.0 * self.radius_m / muscle.nominal_length_m
        self._contraction = np.zeros((len(self.radius_m), 2))
        self._coef: np.ndarray | None = None

    def reset(self) -> None:
        """Both muscles of every pair at V0's pressure and their rest contraction."""
        v0_kpa = self.pairs.regulator.target_pressure_kpa(np.full((1, 2), self.cfg.v0_v))[0, 0]
        rest = self.cfg.kinematic_rest_contraction_pct if self.kinematic else self.cfg.rest_contraction_pct
        self.pairs.reset(v0_kpa, rest)
        self.voltage_v = self.pairs.voltages_v(np.zeros(len(self.radius_m)))
        self._contraction[:] = rest
        self._coef = None

    def set_action(self, action: np.ndarray) -> None:
        """Hold the regulator voltages for this action until the next call."""
        self.voltage_v = self.pairs.voltages_v(action)

    def set_voltages(self, voltage_v: np.ndarray) -> None:
        """Direct regulator voltages (n, 2), e.g. for open-loop pressure steps."""
        self.voltage_v = np.asarray(voltage_v, dtype=float)

    def torques_nm(self, angle_rad: np.ndarray, velocity_rad_s: np.ndarray, dt_s: float) -> np.ndarray:
        """Advance the muscles by dt_s and return the (10,) joint torques [N m]."""
        pairs = self.pairs
        changed = pairs.regulator.step(self.voltage_v, dt_s)
        if not self.kinematic:
            pairs.dynamics.step(pairs.pressure_kpa, dt_s, changed)
            self._contraction = pairs.dynamics.contraction_pct()
            return pairs.torque_nm(self.radius_m)
        if changed or self._coef is None:
            pressure = pairs.pressure_kpa
            self._coef = pairs.law.at_pressure(pressure)
            # Both muscles' dampers act on the joint: (D1 + D2) r^2 [N m s/rad].
            self._damping = self.cfg.tau_s * pairs.dynamics.spring(pressure).sum(axis=1) * self.radius_m**2
        shift = self._pct_per_rad * angle_rad
        c = self._contraction
        c[:, 0] = self.cfg.kinematic_rest_contraction_pct + shift
        c[:, 1] = self.cfg.kinematic_rest_contraction_pct - shift
        force = np.maximum(pairs.law.force_and_slope(self._coef, c)[0], 0.0)
        return (force[:, 0] - force[:, 1]) * self.radius_m - self._damping * velocity_rad_s

    @property
    def pressure_kpa(self) -> np.ndarray:
        return self.pairs.pressure_kpa

    @property
    def contraction_pct(self) -> np.ndarray:
        return self._contraction
