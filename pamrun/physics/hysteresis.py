"""Muscle hysteresis, ``muscle.spring.hysteresis``: a Maxwell-slip friction element on each muscle.

The thesis (§13) asks for spring and damper behaviour that differs when a muscle inflates and
when it deflates. ``none`` (the default) keeps the thesis' single force-contraction curve.
``maxwell_slip`` (:class:`MaxwellSlip`) puts, in parallel with each muscle, N elasto-slide
elements: element i is a spring of stiffness k_i in series with a Coulomb slider of slip force
f_i, so its force k_i delta_i never exceeds f_i in size. Every element is driven by the
muscle's contraction; their summed force H = sum_i k_i delta_i is taken off the muscle's
contractile force:

    F_muscle = F(x, P) - H,    H = g(P) sum_i k_i delta_i,    |k_i delta_i| <= f_i,

k_i and f_i holding at a reference pressure and g(P) scaling both (below), so on contraction (H -> +sum f_i) the muscle pulls less than its static curve and on
extension (H -> -sum f_i) more: the force-contraction curve on contraction lies below the one
on extension and a cycle encloses a loop. Per cycle of amplitude A (in displacement), element
i dissipates the area of its parallelogram, 4 g f_i (A - f_i / k_i) when A > f_i / k_i (0 when
it never slips); the loop area is their sum. The law is rate-independent: only the path of the
contraction matters, not its speed.

Form and sources:

* the Maxwell-slip model (parallel elasto-slide elements): W. D. Iwan, "A distributed-element
  model for hysteresis and its steady-state dynamic response", J. Applied Mechanics 33(4),
  1966; F. Al-Bender, V. Lampaert, J. Swevers, "The generalized Maxwell-slip model: a novel
  model for friction simulation and compensation", IEEE Trans. Automatic Control 50(11), 2005;
* applied to a pneumatic artificial muscle's hysteresis: T. Vo-Minh, T. Tjahjowidodo, H. Ramon,
  H. Van Brussel, "A new approach to modeling hysteresis in a pneumatic artificial muscle using
  the Maxwell-slip model", IEEE/ASME Trans. Mechatronics 16(1), 2011. Their text was not at hand
  here: the form below (elements on the contraction, their force off the muscle's) is the model's
  own, and how pressure scales the elements is our choice (next paragraph), not taken from them.

Pressure: both k_i and f_i scale with g(P) = P / ``slip_reference_pressure_kpa`` (P the gauge
pressure, clipped to the force law's 0-800 kPa), so each element's break-away displacement
f_i / k_i is the same at every pressure and the loop's width grows in proportion to P, as a
friction pressed by the pressure would (C.-P. Chou, B. Hannaford, "Measurement and modeling of
McKibben pneumatic artificial muscles", IEEE Trans. Robotics and Automation 12(1), 1996, trace
a McKibben muscle's hysteresis to friction in its braid). Linear in P is our choice of the
simplest pressure dependence, not a fit.

Parameters (``SpringConfig.slip_*``, the one place their values live): no published hysteresis
measurement of the DMSP-20 (force against contraction at constant pressure) was available to
us, and none of the papers above could be read here for its numbers, so the values are
assumptions, not measurements: three elements of equal slip force, 2 sum f_i = 75 N at 6 bar
(5 % of the DMSP-20's rated 1500 N, the loop's full width between extension and contraction),
and break-away displacements f_i / k_i of 0.25, 0.78 and 2.1 mm of the 260 mm muscle (0.1, 0.3
and 0.8 % of contraction), so the loop's ends round off over about 1 % of contraction.
``pamrun muscle hysteresis`` draws the loop these give; replace them with a fit once the
DMSP's loop is measured. The parameters are the DMSP-20-260's, like the force law and the
spring table: another size scales H by its rated-force ratio with the force (force_scale),
and the elements are driven by contraction in % (their displacement is that of the 260 mm
muscle, ``M_PER_PCT`` per %), so another length has the same loop in % as S does.

Why not two spring tables (S for inflation, another for deflation, chosen by the sign of
dP/dt)? S exists only in the thesis coupling's dynamics (the kinematic coupling, the default
robot's, uses it only for the damper D = tau S), where the force law's slope (~36 kN/m) dwarfs
it (~100-1000 N/m): a second table would barely move anything. At constant pressure dP/dt = 0,
so it gives no loop in the force-contraction plane at all, where PAM hysteresis is measured,
and switching on the sign of dP/dt chatters as the regulator settles. The Maxwell-slip element
acts on the force itself, in every coupling, and has an analytic loop area to test against.

Numerics: each step moves every element exactly, delta_i <- clip(delta_i + dx, -f_i/k_i,
f_i/k_i) (the elasto-slide, or play, operator: exact for a monotone motion between steps). A
coupling that linearises the muscle force also needs dH/dx: each element adds k_i while it
sticks (|delta_i| < f_i / k_i) and 0 at its limit (it is taken to keep slipping the way it
went; a reversal is caught at the next step). Reset: every element at rest (delta = 0), the
muscle where the reset puts it.

Where it acts (pamrun/physics/muscle.py, pamrun/physics/actuation.py, pamrun/physics/kernels.py): the thesis coupling
(:class:`pamrun.physics.muscle.FirstOrderPairDynamics`) takes F - H for each muscle and its partner in
D x' + S x = Fce - FL and the elements' stiffness into its implicit step; the kinematic
coupling (numpy and the compiled kernel) takes F - H for each muscle's pull on the joint and
adds the elements' stiffness to the pair's. The state lives in
``pairs.dynamics.hysteresis`` (None for ``none``) whichever coupling steps it.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from pamrun.config.robot import SPRING_REFERENCE_LENGTH_M
from pamrun.physics.force_laws import FORCE_LAWS

if TYPE_CHECKING:
    from pamrun.config import MuscleConfig, SpringConfig

# Metres of displacement of the 260 mm reference muscle per % of contraction (the elements' unit).
M_PER_PCT = SPRING_REFERENCE_LENGTH_M / 100.0


class MaxwellSlip:
    """N elasto-slide elements on each muscle of n antagonistic pairs (module docstring).

    ``stiffness_n_per_m`` k_i and ``width_m`` f_i / k_i (N,) are the elements' constants at the
    reference pressure; state: ``slip_m`` (N, n, 2), each element's spring deflection [m of the
    reference muscle], and ``gain`` (n, 2), P / P_ref at the last :meth:`at_pressure`. Both are
    updated in place (the compiled kernel holds them).
    """

    def __init__(self, spring: SpringConfig, n_pairs: int, max_pressure_kpa: float):
        self.stiffness_n_per_m = np.asarray(spring.slip_stiffness_n_per_m, dtype=float)
        self.width_m = np.asarray(spring.slip_force_n, dtype=float) / self.stiffness_n_per_m
        self.reference_pressure_kpa = float(spring.slip_reference_pressure_kpa)
        self.max_pressure_kpa = float(max_pressure_kpa)  # the force law's clamp
        self.slip_m = np.zeros((len(self.stiffness_n_per_m), n_pairs, 2))
        self.gain = np.zeros((n_pairs, 2))
        self._width = self.width_m[:, None, None]
        self._stiffness = self.stiffness_n_per_m[:, None, None]

    def reset(self) -> None:
        """Every element at rest (no force)."""
        self.slip_m[:] = 0.0

    def at_pressure(self, pressure_kpa: np.ndarray) -> None:
        """The elements' scale g = P / P_ref at these pressures [kPa] (clipped to the force law's range)."""
        np.divide(np.clip(pressure_kpa, 0.0, self.max_pressure_kpa), self.reference_pressure_kpa, out=self.gain)

    def move(self, delta_pct: np.ndarray) -> None:
        """Drive every element by each muscle's contraction change ``delta_pct`` (n, 2) [%]."""
        np.clip(self.slip_m + delta_pct * M_PER_PCT, -self._width, self._width, out=self.slip_m)

    def force_n(self) -> np.ndarray:
        """H = g sum_i k_i delta_i [N], (n, 2): what the elements take off each muscle's pull."""
        return self.gain * (self._stiffness * self.slip_m).sum(axis=0)

    def stiffness_n_per_pct(self) -> np.ndarray:
        """dH/dx [N per % of contraction], (n, 2): g k_i M_PER_PCT of each element that sticks."""
        sticking = np.where(np.abs(self.slip_m) < self._width, self._stiffness, 0.0).sum(axis=0)
        return self.gain * sticking * M_PER_PCT


# Laws by name; pamrun.config.robot.HYSTERESIS_LAWS lists the names (a test keeps the two in step).
HYSTERESIS = {"none": None, "maxwell_slip": MaxwellSlip}


def make_hysteresis(spring: SpringConfig, n_pairs: int, max_pressure_kpa: float) -> MaxwellSlip | None:
    """The law ``spring.hysteresis`` names for n pairs, or None for ``none``."""
    law = HYSTERESIS[spring.hysteresis]
    return None if law is None else law(spring, n_pairs, max_pressure_kpa)


# --------------------------------------------------------------------------- the loop


def loop_area_j(contraction_pct: np.ndarray, force_n: np.ndarray, nominal_length_m: float) -> float:
    """Energy [J] a closed force-contraction path dissipates, -closed integral of F dx (trapezoids),
    x = contraction [%] / 100 * L0 [m]: positive when extension pulls harder than contraction."""
    x_m = np.asarray(contraction_pct, float) / 100.0 * nominal_length_m
    force = np.asarray(force_n, float)
    return float(-np.sum(0.5 * (force[1:] + force[:-1]) * np.diff(x_m)))


def analytic_loop_area_j(spring: SpringConfig, pressure_kpa: float, amplitude_pct: float,
                         max_pressure_kpa: float) -> float:
    """sum_i 4 f_i g (A - f_i / k_i) [J] for the DMSP-20-260 (0 for an element that never slips)
    under a contraction cycle of +- ``amplitude_pct`` [%] at ``pressure_kpa`` [kPa]."""
    gain = min(max(pressure_kpa, 0.0), max_pressure_kpa) / spring.slip_reference_pressure_kpa
    amplitude_m = amplitude_pct * M_PER_PCT
    return float(sum(4.0 * f * gain * max(amplitude_m - f / k, 0.0)
                     for k, f in zip(spring.slip_stiffness_n_per_m, spring.slip_force_n)))


def hysteresis_loop(muscle: MuscleConfig, pressures_kpa=(300.0, 600.0), center_pct: float = 9.0,
                    amplitude_pct: float = 5.0, steps_per_cycle: int = 400) -> dict:
    """One muscle of ``muscle``'s size and length at constant pressure, its contraction cycled
    sinusoidally, center +- amplitude [%], twice: the force [N] against contraction [%] without
    hysteresis (``none``) and with ``maxwell_slip`` (``muscle.spring``'s elements), and the loop
    area [J] of the second cycle (the first starts with the elements at rest), simulated and
    analytic (sum_i 4 f_i (A - f_i / k_i), scaled to this muscle's size and length)."""
    law = FORCE_LAWS[muscle.force_law](muscle.max_pressure_kpa)
    spring = replace(muscle.spring, hysteresis="maxwell_slip")
    phase = 2.0 * np.pi * np.arange(2 * steps_per_cycle + 1) / steps_per_cycle
    contraction = center_pct + amplitude_pct * np.sin(phase)
    second = slice(steps_per_cycle, None)
    # one muscle of this size and length: its force scales by the rated-force ratio, its stroke by L0
    scale = muscle.force_scale
    to_muscle = scale * muscle.nominal_length_m / SPRING_REFERENCE_LENGTH_M
    cases = []
    for pressure in pressures_kpa:
        static = scale * np.maximum(law.signed_force_n(contraction, pressure), 0.0)
        slip = MaxwellSlip(spring, 1, law.max_pressure_kpa)
        slip.at_pressure(np.full((1, 2), pressure))
        with_slip = np.empty_like(contraction)
        previous = contraction[0]
        for k, c in enumerate(contraction):
            slip.move(np.full((1, 2), c - previous))
            previous = c
            with_slip[k] = scale * max(law.signed_force_n(c, pressure) - slip.force_n()[0, 0], 0.0)
        cases.append({
            "pressure_kpa": float(pressure),
            "force_none_n": static.round(3).tolist(), "force_slip_n": with_slip.round(3).tolist(),
            "area_none_j": loop_area_j(contraction[second], static[second], muscle.nominal_length_m),
            "area_slip_j": loop_area_j(contraction[second], with_slip[second], muscle.nominal_length_m),
            "analytic_area_j": to_muscle * analytic_loop_area_j(spring, pressure, amplitude_pct, law.max_pressure_kpa),
        })
    return {"size": muscle.size, "nominal_length_m": muscle.nominal_length_m, "force_law": muscle.force_law,
            "center_pct": center_pct, "amplitude_pct": amplitude_pct, "steps_per_cycle": steps_per_cycle,
            "slip_stiffness_n_per_m": list(spring.slip_stiffness_n_per_m), "slip_force_n": list(spring.slip_force_n),
            "slip_reference_pressure_kpa": spring.slip_reference_pressure_kpa,
            "contraction_pct": contraction.round(6).tolist(), "cases": cases}
