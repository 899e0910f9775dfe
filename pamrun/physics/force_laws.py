"""Static force laws F(x, P) of a pneumatic muscle, ``muscle.force_law`` (thesis §8.3).

A force law is the contractile force [N] of one Festo DMSP-20 at contraction x [% of its
nominal length] and gauge pressure P [kPa]. Every law here is a polynomial in x and P held
as a 6 x 6 matrix ``coefficients[i, j]`` of x^i P^j (:class:`CoefficientLaw`), so that each
path that evaluates one works for all of them unchanged: the numpy hot paths (reduce to
a_i(P) at the current pressures, then Horner's rule in x), the compiled kernel
(pamrun/physics/kernels.py reads only ``coefficients`` and ``max_pressure_kpa``), the slopes, the
zero-force contraction and the pressure clamp.

* ``thesis_polynomial`` (:class:`ThesisPolynomial`, the default): the thesis' fifth-order
  fit, Table 8.4;
* ``tondu_lopez`` (:class:`TonduLopez`): Chou & Hannaford's geometric model with Tondu &
  Lopez's correction k, quadratic in x and proportional to P, fitted to Table 8.4.

Both are the DMSP-20's force; another size multiplies it by its rated-force ratio outside
the law (``MuscleConfig.force_scale``). Laws are looked up by name in :data:`FORCE_LAWS`,
whose names ``pamrun.config.robot.FORCE_LAW_NAMES`` lists (a test keeps the two in step).
"""

from __future__ import annotations

import numpy as np

from pamrun.config.robot import FITTED_SIZE, MUSCLE_INNER_DIAMETER_M

# F(x, P) = sum p_ij x^i P^j, x in %, P in kPa (thesis Table 8.4; LAR fit, R^2 = 0.9999,
# RMSE 5.875 N, fitted for -3 % <= x <= zero-force contraction and 0 <= P <= 800 kPa).
THESIS_COEFFICIENTS: dict[tuple[int, int], float] = {
    (0, 0): -0.002697,
    (1, 0): -93.8,
    (0, 1): 2.917,
    (2, 0): 13.05,
    (1, 1): -0.04264,
    (0, 2): -0.001793,
    (3, 0): -0.9395,
    (2, 1): -0.001597,
    (1, 2): -0.0001142,
    (0, 3): 4.694e-06,
    (4, 0): 0.03335,
    (3, 1): 6.106e-06,
    (2, 2): 2.699e-06,
    (1, 3): 1.25e-07,
    (0, 4): -5.675e-09,
    (5, 0): -0.0004611,
    (4, 1): 9.334e-07,
    (3, 2): -1.221e-08,
    (2, 3): -1.463e-09,
    (1, 4): -4.929e-11,
    (0, 5): 2.492e-12,
}
FITTED_PRESSURE_KPA = (0.0, 800.0)  # thesis §8.3: 0-8 bar in 0.5 bar steps
FITTED_PRESSURE_STEP_KPA = 50.0  # thesis §8.3: the fit's data, every 0.5 bar
FITTED_MIN_CONTRACTION_PCT = -3.0  # thesis §8.3: -7.8 mm of stroke

# Measured static force of a Festo DMSP-20-300 (M. Martens, I. Boblan, "Modeling the static
# force of a Festo pneumatic muscle actuator: a new approach and a comparison to existing
# models", Actuators 6(4), 33, 2017; as quoted in THESIS.md §8): (pressure [kPa],
# contraction [% of the 300 mm nominal length], force [N]). 0 N: slack at that contraction.
MARTENS_BOBLAN_DMSP20_300: tuple[tuple[float, float, float], ...] = (
    (600.0, 1.3, 1460.0), (600.0, 6.0, 1004.0), (600.0, 11.0, 715.0), (600.0, 17.0, 443.0), (600.0, 21.0, 188.0),
    (250.0, 1.3, 543.0), (250.0, 6.0, 245.0), (250.0, 11.0, 122.0), (250.0, 17.0, 0.0),
    (135.0, 1.3, 242.0), (135.0, 6.0, 0.0),
)

# Tondu & Lopez's parameters for the DMSP-20, least-squares fitted once, offline, to Table 8.4's
# polynomial on its valid range (python benchmarks/fit_tondu_lopez.py, which writes the fit and
# its errors to benchmarks/results/tondu_lopez_fit.json; see TonduLopez for the choice of data).
# Model: C.-P. Chou, B. Hannaford, "Measurement and modeling of McKibben pneumatic artificial
# muscles", IEEE Trans. Robotics and Automation 12(1), 1996 (theta0); B. Tondu, P. Lopez,
# "Modeling and control of McKibben artificial muscle robot actuators", IEEE Control Systems
# Magazine 20(2), 2000 (k).
TONDU_LOPEZ_THETA0_DEG = 25.0325  # initial braid angle theta0 [deg] to the muscle's axis
TONDU_LOPEZ_K = 1.4219  # Tondu & Lopez's correction of the contraction, (1 - k eps)^2


class CoefficientLaw:
    """A force law F(x, P) = sum_ij c_ij x^i P^j [N], x [%], P [kPa], i, j <= 5, vectorised.

    Pressure is clamped to [0, ``max_pressure_kpa``] kPa; contraction is not clamped, and
    past the zero-force contraction the signed value turns negative (the callers clip it
    at 0 where a muscle pulls on a joint: a muscle cannot push).

    Hot paths first reduce F to a polynomial in x at the current pressures
    (:meth:`at_pressure`, once per pressure change) and then evaluate it by Horner's rule
    (:meth:`force_and_slope`, a dozen array operations), since pressure changes once per
    control step while contraction changes every physics step.
    """

    def __init__(self, coefficients: np.ndarray, max_pressure_kpa: float):
        self.max_pressure_kpa = max_pressure_kpa
        self.coefficients = np.array(coefficients, dtype=float)  # [i, j]: x^i P^j
        if self.coefficients.shape != (6, 6):
            raise ValueError(f"a force law has 6 x 6 coefficients, got {self.coefficients.shape}")

    def at_pressure(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """Coefficients a_i(P) [N / %^i], shape (6, *P.shape): F(x, P) = sum_i a_i x^i."""
        p = np.clip(np.asarray(pressure_kpa, float), 0.0, self.max_pressure_kpa)
        powers = p[None, ...] ** np.arange(6).reshape((6,) + (1,) * p.ndim)
        return np.tensordot(self.coefficients, powers, axes=(1, 0))

    @staticmethod
    def force_and_slope(coef: np.ndarray, contraction_pct: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Signed F [N] and dF/dx [N per %] at contraction x [%] by Horner's rule."""
        x = contraction_pct
        force = coef[5] * x + coef[4]
        slope = 5.0 * coef[5] * x + 4.0 * coef[4]
        for i in (3, 2, 1):
            force = force * x + coef[i]
            slope = slope * x + i * coef[i]
        return force * x + coef[0], slope

    def signed_force_n(self, contraction_pct: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        """Raw law value [N]; negative past the zero-force contraction."""
        x, p = np.broadcast_arrays(np.asarray(contraction_pct, float), np.asarray(pressure_kpa, float))
        return self.force_and_slope(self.at_pressure(p), x)[0]

    def slope_n_per_pct(self, contraction_pct: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        """dF/dx [N per % of contraction] (negative: force drops as the muscle shortens)."""
        x, p = np.broadcast_arrays(np.asarray(contraction_pct, float), np.asarray(pressure_kpa, float))
        return self.force_and_slope(self.at_pressure(p), x)[1]


class ThesisPolynomial(CoefficientLaw):
    """The thesis' fitted contractile force F(x, P) (Table 8.4), ``thesis_polynomial``.

    Pressure is clamped because the fifth-order terms diverge beyond 8 bar; below -3 % (a
    muscle stretched past its nominal length) the polynomial is extrapolated and keeps
    pulling harder. At 0 kPa it is the stretched rubber's passive force (427 N at -3 %).
    """

    def __init__(self, max_pressure_kpa: float = FITTED_PRESSURE_KPA[1]):
        coefficients = np.zeros((6, 6))
        for (i, j), value in THESIS_COEFFICIENTS.items():
            coefficients[i, j] = value
        super().__init__(coefficients, max_pressure_kpa)


def tondu_lopez_coefficients(theta0_deg: float, k: float, inner_diameter_m: float) -> np.ndarray:
    """Tondu & Lopez's F(x, P) as a 6 x 6 matrix of x^i P^j [N / (%^i kPa^j)].

    F = (pi D0^2 P / 4) (a (1 - k eps)^2 - b), a = 3 / tan^2(theta0), b = 1 / sin^2(theta0),
    eps = x / 100 and P in Pa (= 1000 P [kPa]): expanded in x, only the j = 1 column is not 0,
    c_01 = A (a - b), c_11 = -2 a k A / 100, c_21 = a k^2 A / 100^2 with A = 1000 pi D0^2 / 4.
    """
    theta0 = np.radians(theta0_deg)
    a, b = 3.0 / np.tan(theta0) ** 2, 1.0 / np.sin(theta0) ** 2
    area = 1000.0 * np.pi * inner_diameter_m**2 / 4.0  # N per kPa
    coefficients = np.zeros((6, 6))
    coefficients[0:3, 1] = area * np.array([a - b, -2.0 * a * k / 100.0, a * k**2 / 100.0**2])
    return coefficients


class TonduLopez(CoefficientLaw):
    """Chou & Hannaford's geometric model with Tondu & Lopez's correction k, ``tondu_lopez``.

    F = (pi D0^2 P / 4) (a (1 - k eps)^2 - b), a = 3 / tan^2(theta0), b = 1 / sin^2(theta0),
    eps = x / 100 the contraction as a fraction, P the gauge pressure in Pa (the methods
    take kPa like every law). D0 = 20 mm, the DMSP-20's inner diameter: the law is the
    fitted size's, and another size scales it by the rated-force ratio outside the law,
    exactly as the polynomial (the size's own D0 here as well would count it twice).

    theta0 and k (:data:`TONDU_LOPEZ_THETA0_DEG`, :data:`TONDU_LOPEZ_K`) are fitted to Table
    8.4's polynomial alone, on its valid range (-3 % to the zero-force contraction, 0-800
    kPa), and the measured DMSP-20-300 points (:data:`MARTENS_BOBLAN_DMSP20_300`) are left
    out as an independent check: the polynomial is the muscle the rest of pamrun is
    calibrated on (the spring table and §10.1's step responses, the default robot's sizing by
    ``pamrun capacity``), so the new law is the best two-parameter geometric stand-in for
    that muscle; the measured points
    are another muscle (300 mm long), only 11 of them, three at 0 N (slack: no force to
    fit), and fitting both sets at once would need an arbitrary weight between 11 points
    and ~3900. Fitting those points instead lowers their RMSE only from 141 to 122 N and
    raises the polynomial's from 118 to 146 N (benchmarks/results/tondu_lopez_fit.json).

    Errors (N; the polynomial's own misses of the measured points are 46 N RMSE): against
    the polynomial RMSE 118 N, max 428 N; against the measured points RMSE 141 N, worst
    251 N. Both come from the model's form, not the fit:

    * no passive force: at 0 kPa F is 0, while the stretched rubber pulls 427 N at -3 %
      (the polynomial's P = 0 terms); every pressure's largest error is at -3 %, the
      largest of all 428 N at 50 kPa;
    * one zero-force contraction for every pressure, eps* = (1 - sqrt(b / a)) / k (25.5 %),
      while the real muscle's grows with pressure (14 % at 176 kPa, 28 % at 800 kPa): at low
      pressure the law still pulls where the muscle is slack (251 N at 1.35 bar and 6 %,
      measured 0 N).

    Past eps* the signed force is negative (pulled back, as the polynomial) down to its
    minimum at eps = 1 / k (70 %), far beyond the DMSP's 25 % stroke. The fitted theta0 is an
    effective angle, not the braid of pamrun.physics.muscle.muscle_volume_l (39.7 deg at 0 %, from
    the 25 % stroke): with that braid and k = 1 the model gives 360 N at 0 % and 6 bar, a
    quarter of the DMSP-20's 1500 N rating.
    """

    def __init__(self, max_pressure_kpa: float = FITTED_PRESSURE_KPA[1], theta0_deg: float = TONDU_LOPEZ_THETA0_DEG,
                 k: float = TONDU_LOPEZ_K, inner_diameter_m: float = MUSCLE_INNER_DIAMETER_M[FITTED_SIZE]):
        self.theta0_deg, self.k, self.inner_diameter_m = theta0_deg, k, inner_diameter_m
        super().__init__(tondu_lopez_coefficients(theta0_deg, k, inner_diameter_m), max_pressure_kpa)

    def zero_force_contraction_pct(self) -> float:
        """eps* = (1 - sqrt(b / a)) / k [%]: where a (1 - k eps)^2 = b, the same at every pressure."""
        sqrt_b_over_a = 1.0 / (np.sqrt(3.0) * np.cos(np.radians(self.theta0_deg)))
        return float(100.0 * (1.0 - sqrt_b_over_a) / self.k)


FORCE_LAWS = {"thesis_polynomial": ThesisPolynomial, "tondu_lopez": TonduLopez}

_DEFAULT_LAW = ThesisPolynomial()


def contractile_force(contraction_pct, pressure_kpa):
    """Force [N] a DMSP-20 applies at a contraction [%] and pressure [kPa] (thesis Table 8.4).

    Vectorised over numpy arrays (broadcasting). Never negative: a muscle cannot push, so
    past the zero-force contraction the force is 0. Pressure is clamped to the fitted
    0-800 kPa; contraction below the fitted -3 % is extrapolated (see ThesisPolynomial).
    """
    force = _DEFAULT_LAW.signed_force_n(np.asarray(contraction_pct, float), np.asarray(pressure_kpa, float))
    return np.maximum(force, 0.0)


def zero_force_contraction_pct(pressure_kpa: float, law: CoefficientLaw = _DEFAULT_LAW) -> float:
    """Contraction [%] at which the muscle's force vanishes at a given pressure [kPa].

    Searched between -3 % and 45 %. A law with no passive force (TonduLopez) is 0 everywhere
    at 0 kPa, and then the answer is the search's start, -3 %.
    """
    from scipy.optimize import brentq  # heavy (~0.5 s): only the fits use it; the env imports this module

    return brentq(lambda x: law.signed_force_n(x, pressure_kpa), FITTED_MIN_CONTRACTION_PCT, 45.0)


def polynomial_fit_grid(step_pct: float = 0.1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Table 8.4's polynomial on its valid range, where another law is fitted and judged.

    Every ``step_pct`` [%] from -3 % to the zero-force contraction, at every fitted pressure
    (0-800 kPa in 50 kPa steps, the thesis' data): contraction [%], pressure [kPa] and the
    polynomial's force [N], flat arrays of one point each.
    """
    law = ThesisPolynomial()
    lo, hi = FITTED_PRESSURE_KPA
    x, p = [], []
    for pressure in np.arange(lo, hi + FITTED_PRESSURE_STEP_KPA / 2, FITTED_PRESSURE_STEP_KPA):
        top = zero_force_contraction_pct(pressure, law)
        points = np.arange(FITTED_MIN_CONTRACTION_PCT, top + 1e-9, step_pct)
        x.append(points)
        p.append(np.full_like(points, pressure))
    x_pct, p_kpa = np.concatenate(x), np.concatenate(p)
    return x_pct, p_kpa, law.signed_force_n(x_pct, p_kpa)
