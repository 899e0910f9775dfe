"""Pneumatic artificial muscle (PAM) physics: force law, regulator, dynamics, pairs (thesis §8.3).

A Festo DMSP-20-260N fluidic muscle is modelled, as in the thesis, by three parts:

* a **force law** F(x, P): the static contractile force [N] at contraction x [% of the
  260 mm nominal length] and pressure P [kPa] (Table 8.4's fifth-order polynomial, or a
  geometric model fitted to it: pamrun/force_laws.py, imported here);
* a **pressure regulator** (Festo VPPM): command voltage [V] -> pressure [kPa], clipped to
  its 0.1-10 bar range, with an optional first-order lag;
* **dynamics** D x' + S x = Fce - FL (§8.3, first-order three-element model): x is the
  muscle's displacement [m] measured from its rest contraction, S(P) [N/m] a table per
  pressure band, D = tau * S, Fce = F(x, P) of this muscle and FL = F(x2, P2) of its
  antagonist. The signed force law is used inside the dynamics (a muscle past its
  zero-force contraction is pulled back); the force it applies to a joint is never
  negative (a muscle cannot push).

Everything works on arrays of shape (n_pairs, 2) so the 20 muscles of the robot step at
once. Force laws and dynamics are looked up by name in :data:`FORCE_LAWS`
(pamrun/force_laws.py) and :data:`DYNAMICS`, so another law is one class, one registry entry
and its name in ``pamrun.config.robot.FORCE_LAW_NAMES`` away. Hysteresis
(``muscle.spring.hysteresis``, pamrun/hysteresis.py) is a force H(path, P) taken off each
muscle's F (Fce - H, FL - H_L); its state lives in :attr:`FirstOrderPairDynamics.hysteresis`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from pamrun.config.robot import MUSCLE_INNER_DIAMETER_M, SPRING_REFERENCE_LENGTH_M  # noqa: F401  (D0 per size)
from pamrun.force_laws import (  # noqa: F401  (the force laws, also reachable from here)
    FITTED_MIN_CONTRACTION_PCT,
    FITTED_PRESSURE_KPA,
    FORCE_LAWS,
    THESIS_COEFFICIENTS,
    CoefficientLaw,
    ThesisPolynomial,
    TonduLopez,
    contractile_force,
    zero_force_contraction_pct,
)
from pamrun.hysteresis import make_hysteresis

if TYPE_CHECKING:
    from pamrun.config import MuscleConfig, PairConfig, RegulatorConfig, SpringConfig, StepExperiment


class Regulator:
    """VPPM proportional pressure regulator: voltage [V] -> pressure [kPa] (thesis §8.3).

    Linear (``gain_kpa_per_v``), input clipped to its voltage range and output to its
    pressure range (0.1-10 bar). With ``lag_s`` > 0 the pressure follows the target
    through an exactly discretised first-order lag; with 0 it is reached at once.

    State: ``pressure_kpa`` (the output), :attr:`target_kpa` (where it is heading) and the
    command held (a voltage array; a new array is a new command). :meth:`step` advances all
    three; a caller that computes the target and the lag itself (the compiled muscle step,
    :class:`pamrun.kernels.CompiledStep`) takes the command with :meth:`hold` and updates
    ``pressure_kpa`` and ``target_kpa`` in place.
    """

    def __init__(self, cfg: RegulatorConfig, initial_pressure_kpa: np.ndarray):
        self.cfg = cfg
        self.pressure_kpa = np.array(initial_pressure_kpa, dtype=float)
        self._voltage: np.ndarray | None = None
        self._target = self.pressure_kpa.copy()

    def reset(self, pressure_kpa: np.ndarray) -> None:
        """Output at ``pressure_kpa`` [kPa] (a new array) and no command held: the next is new."""
        self.pressure_kpa = np.array(pressure_kpa, dtype=float)
        self._voltage = None

    @property
    def target_kpa(self) -> np.ndarray:
        """Pressure [kPa] the output is heading to: the held command's, clipped (see :meth:`hold`)."""
        return self._target

    def target_pressure_kpa(self, voltage_v: np.ndarray) -> np.ndarray:
        c = self.cfg
        voltage_v = np.clip(voltage_v, c.min_voltage_v, c.max_voltage_v)
        return np.clip(c.gain_kpa_per_v * voltage_v, c.min_pressure_kpa, c.max_pressure_kpa)

    def voltage_for_pressure_v(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """Inverse of the linear map (for experiments that are specified in pressure)."""
        return np.asarray(pressure_kpa, float) / self.cfg.gain_kpa_per_v

    def lag_factor(self, dt_s: float) -> float:
        """Share of the gap to the target the pressure closes in dt_s: 1 - exp(-dt_s / lag_s) (0 if no lag)."""
        lag = self.cfg.lag_s
        return float(-np.expm1(-dt_s / lag)) if lag > 0 else 0.0

    def hold(self, voltage_v: np.ndarray) -> bool:
        """Take ``voltage_v`` (the output's shape) [V] as the command, without computing its target.

        Returns whether it is a new command (another array than the one held), whose target
        the caller then writes into :attr:`target_kpa` in place, as :meth:`step` would
        compute it.
        """
        if voltage_v is self._voltage:
            return False
        if np.shape(voltage_v) != self.pressure_kpa.shape:
            raise ValueError(f"regulator voltages must have shape {self.pressure_kpa.shape}, "
                             f"got {np.shape(voltage_v)}")
        self._voltage = voltage_v
        if not isinstance(self._target, np.ndarray) or self._target.shape != self.pressure_kpa.shape:
            self._target = np.zeros(self.pressure_kpa.shape)
        return True

    def step(self, voltage_v: np.ndarray, dt_s: float, contraction_pct: np.ndarray | None = None) -> bool:
        """Advance by dt_s holding ``voltage_v``; return whether the pressure changed.

        The target is recomputed only when a new voltage array is passed (callers hold
        one array per command), so an ideal regulator costs nothing per physics step.
        ``contraction_pct`` is not read: the lag does not depend on the muscles' volume (the
        flow-limited valve, :class:`pamrun.valve.FlowRegulator`, does).
        """
        if voltage_v is not self._voltage:
            self._voltage = voltage_v
            self._target = self.target_pressure_kpa(voltage_v)
            if self.cfg.lag_s == 0:
                self.pressure_kpa = self._target.copy()
                return True
        if self.cfg.lag_s > 0:
            self.pressure_kpa += (self._target - self.pressure_kpa) * self.lag_factor(dt_s)
            return True
        return False


class SpringTable:
    """Spring coefficient S(P) [N/m], piecewise constant over pressure bands (thesis §8.3)."""

    def __init__(self, cfg: SpringConfig):
        self.edges_kpa = np.asarray(cfg.band_edges_kpa, dtype=float)
        self.values_n_per_m = np.asarray(cfg.stiffness_n_per_m, dtype=float)

    def band(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """Index of the band holding each pressure (last band beyond the last edge)."""
        idx = np.searchsorted(self.edges_kpa, pressure_kpa, side="right") - 1
        return np.clip(idx, 0, len(self.values_n_per_m) - 1)

    def __call__(self, pressure_kpa: np.ndarray) -> np.ndarray:
        return self.values_n_per_m[self.band(pressure_kpa)]


class FirstOrderPairDynamics:
    """D x' + S x = Fce - FL for antagonistic pairs, with FL the partner's force (§8.3).

    State: displacement ``x`` [m] of each muscle from its rest contraction, shape (n, 2).
    The system is stiff: |dF/dx| is ~36 kN/m while S is a few hundred N/m, so explicit
    Euler diverges above ~2 ms. Each step is linearly implicit (Rosenbrock-Euler) on the
    full 2x2 Jacobian of each pair, solved in closed form: A-stable at any step size and
    exact at equilibrium, so a robot simulation can step it at 5 ms or more.

    ``hysteresis`` (``muscle.spring.hysteresis``; None for ``none``): the Maxwell-slip elements
    of every muscle (:class:`pamrun.hysteresis.MaxwellSlip`), whose force H each muscle's F
    loses, here and in the kinematic coupling, which keeps its state here too.
    """

    def __init__(self, cfg: MuscleConfig, law: CoefficientLaw, n_pairs: int):
        self.law = law
        self.spring = SpringTable(cfg.spring)
        self.tau_s = cfg.tau_s
        self.rest_pct = cfg.rest_contraction_pct
        self.pct_per_m = 100.0 / cfg.nominal_length_m
        # S is tabulated for the 260 mm muscle the thesis calibrated; a muscle of another
        # length is that spring in series, S * L_ref / L0, so its response in % is the same.
        # (A size's force scale multiplies F and S alike and cancels here.)
        self.length_scale = SPRING_REFERENCE_LENGTH_M / cfg.nominal_length_m
        self.x_m = np.zeros((n_pairs, 2))
        self.force_n = np.zeros((n_pairs, 2))
        self.hysteresis = make_hysteresis(cfg.spring, n_pairs, law.max_pressure_kpa)
        self._pressure: np.ndarray | None = None
        self._dt = 0.0

    def contraction_pct(self) -> np.ndarray:
        return self.rest_pct + self.pct_per_m * self.x_m

    def set_contraction_pct(self, contraction_pct: np.ndarray) -> None:
        self.x_m = (np.broadcast_to(contraction_pct, self.x_m.shape) - self.rest_pct) / self.pct_per_m

    def reset(self, contraction_pct: np.ndarray) -> None:
        """Muscles at ``contraction_pct`` [%], hysteresis elements at rest; what depends on pressure
        is recomputed at the next step."""
        self.set_contraction_pct(contraction_pct)
        self._pressure = None
        if self.hysteresis is not None:
            self.hysteresis.reset()

    def at_pressure(self, pressure_kpa: np.ndarray) -> None:
        """Cache what depends on pressure only: force coefficients, S, D = tau S (and the hysteresis' scale)."""
        self._pressure = pressure_kpa
        self._coef = self.law.at_pressure(pressure_kpa)
        self.s = self.spring(pressure_kpa) * self.length_scale
        self.d = self.tau_s * self.s
        if self.hysteresis is not None:
            self.hysteresis.at_pressure(pressure_kpa)

    def coefficients(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """The force law's coefficients a_i(P) [N / %^i] at the last step's pressures, or at
        ``pressure_kpa`` [kPa] when there was no step since a reset."""
        if self._pressure is None:
            self.at_pressure(pressure_kpa)
        return self._coef

    def step(self, pressure_kpa: np.ndarray, dt_s: float, pressure_changed: bool = True) -> np.ndarray:
        """Advance by dt_s at the given muscle pressures [kPa]; return contractions [%].

        Also leaves ``self.force_n``, the signed force at the new state, linearised like
        the step itself (F + dF/dx dx), so callers need not evaluate the polynomial again.
        """
        if pressure_changed or self._pressure is None or dt_s != self._dt:
            self.at_pressure(pressure_kpa)
            self._dt = dt_s
            self._h = dt_s / self.d
            self._h_s = self._h * self.s
        x, h = self.x_m, self._h
        force, slope = self.law.force_and_slope(self._coef, self.rest_pct + self.pct_per_m * x)
        slope *= self.pct_per_m  # dF/dx [N/m]
        if self.hysteresis is not None:  # F - H, and dH/dx of the sticking elements in the Jacobian
            raw_force, raw_slope = force, slope
            force = force - self.hysteresis.force_n()
            slope = slope - self.hysteresis.stiffness_n_per_pct() * self.pct_per_m
        b = h * (force - force[:, ::-1]) - self._h_s * x  # dt * x' [m]
        # (I - dt J) dx = b, dt J = h * [[g1 - S1, -g2], [-g1, g2 - S2]] per pair; Cramer's rule.
        diag = 1.0 + self._h_s - h * slope
        off = h * slope[:, ::-1]
        det = diag[:, 0] * diag[:, 1] - off[:, 0] * off[:, 1]
        dx = (diag[:, ::-1] * b - off * b[:, ::-1]) / det[:, None]
        x += dx
        if self.hysteresis is None:
            self.force_n = force + slope * dx
        else:  # the elements moved exactly (slipping or not): F + dF/dx dx - H at the new state
            self.hysteresis.move(self.pct_per_m * dx)
            self.force_n = raw_force + raw_slope * dx - self.hysteresis.force_n()
        return self.contraction_pct()


DYNAMICS = {"first_order": FirstOrderPairDynamics}


class AntagonisticPairs:
    """n antagonistic muscle pairs: command -> regulator -> dynamics -> force -> torque.

    Command of thesis §9.5: V1 = V0 + dV, V2 = V0 - dV with dV = dv_max * a, a in [-1, 1].
    Joint torque T = k (F1 - F2) r [N m] with forces never negative, where ``force_scale``
    k = muscles in parallel x the size's force ratio (1 for one DMSP-20, the thesis).
    ``muscles_per_side`` (n,): the muscles in parallel, which one regulator fills (read by the
    flow-limited valve, ``muscle.regulator.model=flow``: pamrun/valve.py).
    """

    def __init__(self, cfg: MuscleConfig, n_pairs: int, force_scale: float | np.ndarray = 1.0,
                 muscles_per_side: float | np.ndarray = 1.0):
        # muscle.regulator.model: the lag (Regulator) or the flow-limited valve
        from pamrun.valve import make_regulator

        self.cfg = cfg
        self.n_pairs = n_pairs
        self.force_scale = np.broadcast_to(np.asarray(force_scale, float), (n_pairs,)).copy()
        self.law = FORCE_LAWS[cfg.force_law](cfg.max_pressure_kpa)
        initial_kpa = np.full((n_pairs, 2), cfg.v0_v * cfg.regulator.gain_kpa_per_v)
        self.regulator = make_regulator(cfg, initial_kpa, np.broadcast_to(muscles_per_side, (n_pairs,)))
        self.dynamics = DYNAMICS[cfg.dynamics](cfg, self.law, n_pairs)
        self._pressure = np.zeros((n_pairs, 2))

    def reset(self, pressure_kpa: float | np.ndarray, contraction_pct: float | np.ndarray) -> None:
        """Every muscle at ``pressure_kpa`` [kPa] and ``contraction_pct`` [%], at rest, no command held."""
        self.regulator.reset(np.broadcast_to(pressure_kpa, (self.n_pairs, 2)))
        self.dynamics.reset(contraction_pct)

    def voltages_v(self, action: np.ndarray) -> np.ndarray:
        """(n,) actions in [-1, 1] -> (n, 2) regulator voltages V0 +- dv_max * a."""
        dv = self.cfg.dv_max_v * np.clip(action, -1.0, 1.0)
        return self.cfg.v0_v + np.stack([dv, -dv], axis=-1)

    @property
    def pressure_kpa(self) -> np.ndarray:
        """Pressure inside each muscle [kPa] (the regulator's output, capped at the muscle's max)."""
        return np.minimum(self.regulator.pressure_kpa, self.cfg.max_pressure_kpa, out=self._pressure)

    def contraction_pct(self) -> np.ndarray:
        return self.dynamics.contraction_pct()

    def step(self, voltage_v: np.ndarray, dt_s: float) -> None:
        changed = self.regulator.step(voltage_v, dt_s, self.dynamics.contraction_pct())
        self.dynamics.step(self.pressure_kpa, dt_s, changed)

    def forces_n(self) -> np.ndarray:
        """Force of one muscle of each side [N], (n, 2), never negative (before ``force_scale``)."""
        coef = self.dynamics.coefficients(self.pressure_kpa)
        force = self.law.force_and_slope(coef, self.contraction_pct())[0]
        if self.dynamics.hysteresis is not None:
            force = force - self.dynamics.hysteresis.force_n()
        return np.maximum(force, 0.0)

    def torque_nm(self, radius_m: np.ndarray) -> np.ndarray:
        """Joint torque [N m] after the last step: (F1 - F2) r, forces never negative."""
        force = np.maximum(self.dynamics.force_n, 0.0)
        return (force[:, 0] - force[:, 1]) * (self.force_scale * radius_m)


# --------------------------------------------------------------------------- experiments


def simulate_step(muscle: MuscleConfig, pair: PairConfig, experiment: StepExperiment) -> dict[str, np.ndarray]:
    """One pair from the §10.1 initial state, pressure step at ``pair.step_time_s``.

    The pressures are commanded as regulator voltages. Returns time [s], pressures [kPa]
    and contractions [%], each (T, 2) for muscle 1 and muscle 2.
    """
    pairs = AntagonisticPairs(muscle, 1)
    pairs.reset(pair.initial_pressure_kpa, pair.initial_contraction_pct)
    v_before = pairs.regulator.voltage_for_pressure_v([[pair.initial_pressure_kpa] * 2])
    v_after = pairs.regulator.voltage_for_pressure_v([[experiment.pressure1_kpa, experiment.pressure2_kpa]])
    n = int(round(pair.duration_s / pair.dt_s))
    time_s = np.arange(n + 1) * pair.dt_s
    pressure = np.empty((n + 1, 2))
    contraction = np.empty((n + 1, 2))
    pressure[0], contraction[0] = pairs.pressure_kpa[0], pairs.contraction_pct()[0]
    for k in range(1, n + 1):
        pairs.step(v_after if time_s[k] > pair.step_time_s else v_before, pair.dt_s)
        pressure[k], contraction[k] = pairs.pressure_kpa[0], pairs.contraction_pct()[0]
    return {"time_s": time_s, "pressure_kpa": pressure, "contraction_pct": contraction}


def calibrate_spring(muscle: MuscleConfig, pair: PairConfig) -> tuple[list[float], list[int]]:
    """Fit the spring table S(P) so the §10.1 step responses end at the thesis' values.

    Each muscle of each experiment settles in one pressure band; those bands are fitted
    (least squares on the simulated final contractions, in log S so S stays positive,
    started from the closed-form steady state). Bands no experiment reaches are
    interpolated linearly in pressure between fitted band centres (flat beyond them).
    Returns the table [N/m] and the indices of the fitted bands.
    """
    from dataclasses import replace

    from scipy.optimize import least_squares

    law = FORCE_LAWS[muscle.force_law](muscle.max_pressure_kpa)
    spring = SpringTable(muscle.spring)
    pct_per_m = 100.0 / SPRING_REFERENCE_LENGTH_M  # the table is for the reference length
    rest = muscle.rest_contraction_pct

    guesses: dict[int, list[float]] = {}
    for exp in pair.experiments.values():
        p = np.minimum([exp.pressure1_kpa, exp.pressure2_kpa], muscle.max_pressure_kpa)
        c = np.asarray(exp.thesis_final_pct, float)
        force = law.signed_force_n(c, p)
        for i in range(2):
            x = (c[i] - rest) / pct_per_m
            guesses.setdefault(int(spring.band(p[i])), []).append((force[i] - force[1 - i]) / x)
    bands = sorted(guesses)
    start = np.log([np.mean(guesses[b]) for b in bands])

    def table(log_s: np.ndarray) -> list[float]:
        centres = 0.5 * (spring.edges_kpa[:-1] + spring.edges_kpa[1:])
        return list(np.interp(centres, centres[bands], np.exp(log_s)))

    def residuals(log_s: np.ndarray) -> np.ndarray:
        trial = replace(muscle, spring=replace(muscle.spring, stiffness_n_per_m=table(log_s)))
        out = []
        for exp in pair.experiments.values():
            final = simulate_step(trial, pair, exp)["contraction_pct"][-1]
            out.extend(final - np.asarray(exp.thesis_final_pct))
        return np.asarray(out)

    fit = least_squares(residuals, start, x_scale=1.0, xtol=1e-10, ftol=1e-10)
    return [float(round(v, 3)) for v in table(fit.x)], bands


# --------------------------------------------------------------------------- volume and air

# Largest contraction: about 25 % of the nominal length (Festo DMSP catalogue; THESIS.md §8).
MAX_CONTRACTION_PCT = 25.0
# Braid angle at which a McKibben muscle stops contracting, arccos(1/sqrt(3)) = 54.7 deg
# (Chou & Hannaford 1996: the pressure force vanishes there).
NEUTRAL_BRAID_ANGLE_RAD = float(np.arccos(1.0 / np.sqrt(3.0)))
# Normal litres (DIN 1343 normal conditions): 101.325 kPa and 0 degC.
NORMAL_PRESSURE_KPA = 101.325
NORMAL_TEMPERATURE_K = 273.15
# The air in the muscles: room temperature, 20 degC (ISO 8778's standard reference atmosphere).
AIR_TEMPERATURE_K = 293.15
# Pressures in pamrun are gauge; absolute = gauge + the ambient, taken as the standard atmosphere.
ATMOSPHERE_KPA = 101.325


class AirMeter:
    """The volume, gas and supply air of a robot's muscles (:func:`muscle_volume_l`,
    :func:`air_nl`), its geometry's constants computed once: the env meters every control
    step with it (``info["air_nl"]``, ``reward.kair``).

    ``muscles_per_side``: muscles in parallel per direction of each of the 10 joints (one
    value, or (10,)); arrays of 20 values are the (10, 2) pairs raveled.
    """

    def __init__(self, nominal_length_m: float, inner_diameter_m: float, muscles_per_side=1,
                 temperature_k: float = AIR_TEMPERATURE_K):
        l0 = self.nominal_length_m = float(nominal_length_m)
        b = (1.0 - MAX_CONTRACTION_PCT / 100.0) * l0 / math.cos(NEUTRAL_BRAID_ANGLE_RAD)  # fibre length [m]
        turns = b * math.sqrt(1.0 - (l0 / b) ** 2) / (math.pi * inner_diameter_m)
        self._b2, self._litres = b * b, 1000.0 / (4.0 * math.pi * turns**2)  # m^3 -> litres
        count = np.asarray(muscles_per_side, float)
        self.count = np.repeat(count, 2) if count.ndim else count  # both muscles of a joint
        self.nl_per_kpa_l = NORMAL_TEMPERATURE_K / (NORMAL_PRESSURE_KPA * temperature_k)

    def volume_l(self, contraction_pct) -> np.ndarray:
        length = (1.0 - np.minimum(contraction_pct, MAX_CONTRACTION_PCT) / 100.0) * self.nominal_length_m
        return length * (self._b2 - length * length) * self._litres

    def gas_kpa_l(self, pressure_kpa, contraction_pct) -> np.ndarray:
        """Each muscle's gas amount P V [kPa litres], P absolute (gauge + 101.325 kPa)."""
        return (np.asarray(pressure_kpa, float) + ATMOSPHERE_KPA) * self.volume_l(contraction_pct)

    def drawn_nl(self, gas_before_kpa_l, gas_after_kpa_l) -> float:
        """Supply air [normal litres] drawn between two gas states: each muscle's growth of
        P V, none where it falls (it exhausts to the atmosphere), times its count."""
        drawn = np.maximum(np.subtract(gas_after_kpa_l, gas_before_kpa_l), 0.0) * self.count
        return float(drawn.sum() * self.nl_per_kpa_l)


def muscle_volume_l(contraction_pct, nominal_length_m: float, inner_diameter_m: float) -> np.ndarray:
    """Inner volume [litres] of one muscle at a contraction [% of nominal length], vectorised.

    Chou & Hannaford's geometric model (C.-P. Chou, B. Hannaford, "Measurement and modeling
    of McKibben pneumatic artificial muscles", IEEE Trans. Robotics and Automation 12(1),
    1996): the muscle is a cylinder inside a braid of fibres of length b wound n turns
    around it, at braid angle theta to the axis, so

        L = b cos(theta),   D = b sin(theta) / (n pi),   V = pi D^2 L / 4 = L (b^2 - L^2) / (4 pi n^2).

    b and n are fixed by two facts: the muscle contracts until the braid reaches its neutral
    angle 54.7 deg (cos = 1/sqrt(3)) at ``MAX_CONTRACTION_PCT`` (25 %), so
    b = sqrt(3) (1 - 0.25) L0; and at 0 % it has its nominal length L0 and inner diameter
    D0, so n = b sin(theta0) / (pi D0) with cos(theta0) = L0 / b. Then V(0 %) = pi D0^2 L0 / 4
    exactly, and V grows with contraction up to its maximum at 25 % (27/22 of V(0 %)).
    Contraction past 25 % is clipped to 25 % (the braid cannot pass its neutral angle); a
    stretched muscle (negative contraction) has a smaller volume.

    The rubber wall is ignored (a thin-walled braid): its thickness fills part of the
    cylinder, so the model slightly over-estimates the volume, and with it the air.
    """
    return AirMeter(nominal_length_m, inner_diameter_m).volume_l(np.asarray(contraction_pct, float))


def air_nl(pressure_kpa, contraction_pct, nominal_length_m: float, inner_diameter_m: float,
           muscles_per_side=1, temperature_k: float = AIR_TEMPERATURE_K) -> float:
    """Supply air [normal litres] the muscles draw over a series of states.

    ``pressure_kpa`` (gauge) and ``contraction_pct`` are (n, 20) arrays, one row per
    step, muscles ordered as the (10, 2) pairs raveled; ``muscles_per_side`` is the number of
    muscles in parallel per direction of each of the 10 joints (one value, or (10,)): each
    of them draws the same air as the muscle it doubles. Between consecutive rows a muscle
    holding the gas amount P V (absolute pressure P = gauge + 101.325 kPa, volume V from
    :func:`muscle_volume_l`) draws air only while P V grows (being filled, or contracting at
    constant pressure); when it falls the muscle exhausts to the atmosphere and draws none:

        air_nl = sum_steps sum_muscles count * max(0, Delta(P V)) / P_N * T_N / T

    with P_N = 101.325 kPa and T_N = 273.15 K (DIN 1343 normal litres). The fill is
    isothermal and the air an ideal gas at ``temperature_k``, by default room temperature
    (20 degC): a muscle filled from p1 to p2 at constant volume V draws
    V (p2 - p1) / 101.325 * 273.15 / 293.15 Nl (0.93 V (p2 - p1) / 101.325). Only changes
    between the rows count: the fill before the first row is not included.
    """
    meter = AirMeter(nominal_length_m, inner_diameter_m, muscles_per_side, temperature_k)
    gas = meter.gas_kpa_l(pressure_kpa, np.asarray(contraction_pct, float))
    return meter.drawn_nl(gas[:-1], gas[1:])
