"""Pneumatic artificial muscle (PAM) physics: force law, regulator, dynamics, pairs (thesis §8.3).

A Festo DMSP-20-260N fluidic muscle is modelled, as in the thesis, by three parts:

* a **force law** F(x, P): the static contractile force [N] at contraction x [% of the
  260 mm nominal length] and pressure P [kPa] (Table 8.4's fifth-order polynomial, or a
  geometric model fitted to it: pamrun/physics/force_laws.py, imported here);
* a **pressure regulator** (Festo VPPM): command voltage [V] -> pressure [kPa], clipped to
  its 0.1-10 bar range, with an optional first-order lag, or the flow-limited valve
  (pamrun/physics/valve.py, the regulators' home, imported here);
* **dynamics** D x' + S x = Fce - FL (§8.3, first-order three-element model): x is the
  muscle's displacement [m] measured from its rest contraction, S(P) [N/m] a table per
  pressure band, D = tau * S, Fce = F(x, P) of this muscle and FL = F(x2, P2) of its
  antagonist. The signed force law is used inside the dynamics (a muscle past its
  zero-force contraction is pulled back); the force it applies to a joint is never
  negative (a muscle cannot push).

Everything works on arrays of shape (n_pairs, 2) so the 20 muscles of the robot step at
once. Force laws and dynamics are looked up by name in :data:`FORCE_LAWS`
(pamrun/physics/force_laws.py) and :data:`DYNAMICS`, so another law is one class, one registry entry
and its name in ``pamrun.config.robot.FORCE_LAW_NAMES`` away. Hysteresis
(``muscle.spring.hysteresis``, pamrun/physics/hysteresis.py) is a force H(path, P) taken off each
muscle's F (Fce - H, FL - H_L); its state lives in :attr:`FirstOrderPairDynamics.hysteresis`.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from pamrun.config.robot import MUSCLE_INNER_DIAMETER_M, SPRING_REFERENCE_LENGTH_M  # noqa: F401  (D0 per size)
from pamrun.physics.air import (  # noqa: F401  (the volume and air, also reachable from here)
    AIR_TEMPERATURE_K,
    ATMOSPHERE_KPA,
    MAX_CONTRACTION_PCT,
    NEUTRAL_BRAID_ANGLE_RAD,
    NORMAL_PRESSURE_KPA,
    NORMAL_TEMPERATURE_K,
    AirMeter,
    air_nl,
    muscle_volume_l,
)
from pamrun.physics.force_laws import (  # noqa: F401  (the force laws, also reachable from here)
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
from pamrun.physics.hysteresis import make_hysteresis
from pamrun.physics.valve import Regulator, make_regulator  # noqa: F401  (the regulator, also reachable from here)

if TYPE_CHECKING:
    from pamrun.config import MuscleConfig, PairConfig, SpringConfig, StepExperiment


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
    of every muscle (:class:`pamrun.physics.hysteresis.MaxwellSlip`), whose force H each muscle's F
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
    flow-limited valve, ``muscle.regulator.model=flow``: pamrun/physics/valve.py).
    """

    def __init__(self, cfg: MuscleConfig, n_pairs: int, force_scale: float | np.ndarray = 1.0,
                 muscles_per_side: float | np.ndarray = 1.0):
        # muscle.regulator.model: the lag (Regulator) or the flow-limited valve (pamrun/physics/valve.py)
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
    from scipy.optimize import least_squares  # heavy (~0.5 s): only pamrun muscle calibrate needs it

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
