"""Force laws (pamrun/physics/force_laws.py): ``muscle.force_law=tondu_lopez`` against its formula, its fit to
Table 8.4 and the measured DMSP-20-300, on every path (numpy, compiled kernel, env, CLI)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from pamrun.config import FORCE_LAW_NAMES, ConfigError, MuscleConfig, preset, to_object
from pamrun.config.robot import MUSCLE_INNER_DIAMETER_M
from pamrun.physics.force_laws import (
    FORCE_LAWS,
    MARTENS_BOBLAN_DMSP20_300,
    TONDU_LOPEZ_K,
    TONDU_LOPEZ_THETA0_DEG,
    ThesisPolynomial,
    TonduLopez,
    polynomial_fit_grid,
    zero_force_contraction_pct,
)
from tests.conftest import compose_config, run_pamrun

TL = {"force_law": "tondu_lopez"}


# --------------------------------------------------------------------------- the law


def test_law_is_chou_hannaford_with_tondu_lopez_k_computed_by_hand():
    """theta0 = 30 deg: a = 3 / tan^2 = 9 and b = 1 / sin^2 = 4; D0 = 20 mm; P = 400 kPa = 4e5 Pa."""
    law = TonduLopez(theta0_deg=30.0, k=1.25)
    pressure_force = math.pi * 0.020**2 / 4 * 400e3  # pi D0^2 P / 4 = 125.66 N
    assert law.signed_force_n(0.0, 400.0) == pytest.approx(pressure_force * (9 - 4), rel=1e-12)  # eps = 0: a - b
    # x = 20 %: eps = 0.2, (1 - 1.25 * 0.2)^2 = 0.5625
    assert law.signed_force_n(20.0, 400.0) == pytest.approx(pressure_force * (9 * 0.5625 - 4), rel=1e-12)
    # dF/dx [N per %] = pi D0^2 P / 4 * a * 2 (1 - k eps) (-k) / 100
    assert law.slope_n_per_pct(20.0, 400.0) == pytest.approx(pressure_force * 9 * 2 * 0.75 * -1.25 / 100, rel=1e-12)
    # zero force where a (1 - k eps)^2 = b: eps = (1 - 2/3) / 1.25, at every pressure
    assert law.zero_force_contraction_pct() == pytest.approx(100 / 3 / 1.25, rel=1e-12)
    for p in (100.0, 400.0, 800.0):
        assert zero_force_contraction_pct(p, law) == pytest.approx(100 / 3 / 1.25, abs=1e-9)
    assert law.signed_force_n(30.0, 400.0) < 0  # past it: pulled back, as the polynomial


def test_stored_law_at_zero_contraction_and_its_scaling():
    """The default parameters at eps = 0: F = pi D0^2 P / 4 (a - b), proportional to P, with the
    DMSP-20's 20 mm and the same pressure clamp as the polynomial."""
    law = TonduLopez()
    theta0 = math.radians(TONDU_LOPEZ_THETA0_DEG)
    a, b = 3 / math.tan(theta0) ** 2, 1 / math.sin(theta0) ** 2
    assert law.inner_diameter_m == MUSCLE_INNER_DIAMETER_M["DMSP-20"] == 0.020
    assert law.signed_force_n(0.0, 600.0) == pytest.approx(math.pi * 0.020**2 / 4 * 600e3 * (a - b), rel=1e-12)
    x = np.linspace(-3, 25, 8)
    np.testing.assert_allclose(law.signed_force_n(x, 600.0), 2 * law.signed_force_n(x, 300.0), rtol=1e-12)
    assert np.all(law.signed_force_n(x, 0.0) == 0.0)  # no passive force
    assert law.signed_force_n(5.0, 1000.0) == law.signed_force_n(5.0, 800.0)  # clamped to the fitted 800 kPa
    assert TonduLopez(600.0).signed_force_n(5.0, 700.0) == law.signed_force_n(5.0, 600.0)


def test_tondu_lopez_is_a_coefficient_matrix_the_kernel_reads():
    """Only x^0..2 P^1 are non-zero, so at_pressure / Horner (and the compiled kernel, which reads
    ``coefficients`` only) evaluate it; they agree with the closed formula everywhere."""
    law = TonduLopez()
    c = law.coefficients
    assert c.shape == (6, 6) and np.count_nonzero(c) == 3 and np.all(c[:3, 1] != 0)
    x, p = np.meshgrid(np.linspace(-3, 30, 34), np.linspace(0, 800, 17))
    theta0 = math.radians(TONDU_LOPEZ_THETA0_DEG)
    a, b = 3 / math.tan(theta0) ** 2, 1 / math.sin(theta0) ** 2
    closed = math.pi * 0.020**2 / 4 * p * 1e3 * (a * (1 - TONDU_LOPEZ_K * x / 100) ** 2 - b)
    np.testing.assert_allclose(law.signed_force_n(x, p), closed, rtol=1e-10, atol=1e-9)


# --------------------------------------------------------------------------- the fit

# The stored constants' errors (python benchmarks/fit_tondu_lopez.py, benchmarks/results/
# tondu_lopez_fit.json): RMSE 118.3 N and max 428.3 N against the polynomial's 3885 grid points,
# RMSE 141.0 N and worst 251.2 N against the 11 measured points. The bounds leave 1-3 % for
# platforms' float differences; the max cannot fall below 427 N for any theta0 and k (the
# polynomial's passive force at -3 %, 0 kPa, where this law is 0), so a few newtons is all the
# margin there is.
MAX_GRID_RMSE_N = 120.0
MAX_GRID_ERROR_N = 430.0
MAX_MEASURED_RMSE_N = 145.0
MAX_MEASURED_ERROR_N = 255.0


def test_fit_errors_against_table_8_4_polynomial():
    x, p, f = polynomial_fit_grid()
    assert x.size > 3000 and x.min() == -3.0 and p.max() == 800.0
    error = TonduLopez().signed_force_n(x, p) - f
    assert np.sqrt(np.mean(error**2)) < MAX_GRID_RMSE_N
    assert np.abs(error).max() < MAX_GRID_ERROR_N
    assert x[np.argmax(np.abs(error))] == -3.0  # the missing passive force, as documented
    assert ThesisPolynomial().signed_force_n(-3.0, 0.0) == pytest.approx(427, abs=1)


def test_fit_errors_against_the_measured_dmsp_20_300():
    p, x, f = np.asarray(MARTENS_BOBLAN_DMSP20_300, float).T
    error = np.maximum(TonduLopez().signed_force_n(x, p), 0.0) - f
    assert np.sqrt(np.mean(error**2)) < MAX_MEASURED_RMSE_N and np.abs(error).max() < MAX_MEASURED_ERROR_N
    # the worst point is a slack one: 1.35 bar at 6 %, where the muscle's zero-force contraction lies
    assert (p[np.argmax(np.abs(error))], x[np.argmax(np.abs(error))], f[np.argmax(np.abs(error))]) == (135, 6, 0)
    # the polynomial (the default law) stays the closer one
    poly = np.maximum(ThesisPolynomial().signed_force_n(x, p), 0.0) - f
    assert np.sqrt(np.mean(poly**2)) < 50


def test_stored_constants_are_the_least_squares_fit():
    """Refitting (the script's own function) gives the stored constants to their rounding."""
    from benchmarks.fit_tondu_lopez import ROUNDING, fit, grid_residuals

    grid = polynomial_fit_grid()
    theta0, k = fit(lambda law: grid_residuals(law, grid))
    assert theta0 == pytest.approx(TONDU_LOPEZ_THETA0_DEG, abs=ROUNDING)
    assert k == pytest.approx(TONDU_LOPEZ_K, abs=ROUNDING)


# --------------------------------------------------------------------------- config


def test_registry_names_and_the_default_is_unchanged():
    assert set(FORCE_LAWS) == set(FORCE_LAW_NAMES) == {"thesis_polynomial", "tondu_lopez"}
    assert MuscleConfig().force_law == "thesis_polynomial"
    assert to_object(compose_config()).muscle.force_law == "thesis_polynomial"
    assert to_object(compose_config("muscle.force_law=tondu_lopez")).muscle.force_law == "tondu_lopez"


def test_unknown_law_fails_naming_force_law():
    with pytest.raises(ConfigError) as err:
        MuscleConfig(force_law="hill")
    assert err.value.key == "force_law" and "thesis_polynomial, tondu_lopez" in str(err.value)
    with pytest.raises(ConfigError) as err:
        to_object(compose_config("muscle.force_law=hill"))
    assert err.value.key == "muscle.force_law"


# --------------------------------------------------------------------------- every path


def _drives(**muscle):
    """The default robot's drive with the compiled kernel and with the numpy reference."""
    from pamrun.task.env import PamWalkerEnv

    envs = [PamWalkerEnv(muscle={**muscle, "kernel": k}) for k in ("numba", "numpy")]
    assert envs[0].drive.compiled and not envs[1].drive.compiled
    for e in envs:
        e.reset(seed=0)
    return envs


def test_compiled_kernel_gives_the_numpy_forces_with_tondu_lopez():
    """Random commands past the clips and angles past the limits: the compiled step's law,
    per-muscle forces, MuJoCo inputs (torque, stiffness, damping) and pressures are the numpy
    reference's to float rounding."""
    fast, ref = _drives(**TL)
    law = ref.drive.pairs.law
    assert isinstance(law, TonduLopez) and isinstance(fast.drive.pairs.law, TonduLopez)
    np.testing.assert_array_equal(fast.drive.coupling.compiled.law, law.coefficients)
    rng = np.random.default_rng(5)
    lo, hi = ref.model.jnt_range[ref.model.dof_jntid[ref.qvel_idx]].T
    lowest, highest, most = np.inf, -np.inf, -np.inf
    for k in range(40):
        if k % 4 == 0:
            voltage = rng.uniform(-2.0, 12.0, (10, 2))
        angle = rng.uniform(lo - 0.05, hi + 0.05)
        for e in (fast, ref):
            e.drive.set_voltages(voltage)
            e.data.qpos[e.qpos_idx] = angle
            e.drive.apply(e.model, e.data, e.qpos_idx, e.qvel_idx, 0.005)
        forces = [np.maximum(law.force_and_slope(coef, e.drive.contraction_pct)[0], 0.0)
                  for coef, e in ((fast.drive.coupling.compiled.coef, fast), (ref.drive.coupling.coef, ref))]
        np.testing.assert_allclose(forces[0], forces[1], rtol=1e-12, atol=1e-9, err_msg=f"forces, step {k}")
        for name, get in (("ctrl", lambda e: e.data.ctrl), ("bias", lambda e: e.model.actuator_biasprm[:, :3]),
                          ("pressure", lambda e: e.drive.pressure_kpa)):
            np.testing.assert_allclose(get(fast), get(ref), rtol=1e-12, atol=1e-9, err_msg=f"{name}, step {k}")
        lowest, highest = min(lowest, ref.drive.pressure_kpa.min()), max(highest, ref.drive.pressure_kpa.max())
        most = max(most, ref.drive.contraction_pct.max())
    assert lowest < 200 and highest == 600.0  # low pressures and the muscle's cap
    # No muscle goes slack here, unlike with the polynomial: the default robot's contractions stay
    # below about 20 %, and this law's zero-force contraction is 25.5 % at every pressure (the
    # polynomial's is 14 % at 176 kPa). The kernel's slack branch is tests/test_muscle.py's.
    assert most < TonduLopez().zero_force_contraction_pct()


def test_env_builds_steps_and_the_default_robot_stands_2_s():
    """muscle.force_law=tondu_lopez on the default robot: zero action holds it up for 2 s (it
    stands the full 10 s, as with the polynomial: checked when the law was added)."""
    from pamrun.task.env import PamWalkerEnv

    env = PamWalkerEnv(muscle=TL)
    assert isinstance(env.drive.pairs.law, TonduLopez)
    obs, _ = env.reset(seed=0)
    zero = np.zeros(env.n_actions, dtype=np.float32)
    for _ in range(int(round(2.0 / env.env_cfg.control_dt_s))):
        obs, _, terminated, truncated, _ = env.step(zero)
        assert not (terminated or truncated)
    assert np.all(np.isfinite(obs)) and env.data.qpos[2] > 0.9 * env.z0
    env.close()


def test_thesis_coupling_steps_with_tondu_lopez():
    """The dynamics path (muscle=thesis: FirstOrderPairDynamics) takes the law too."""
    from pamrun.task.env import PamWalkerEnv

    env = PamWalkerEnv(muscle={**preset("muscle", "thesis"), **TL})
    assert isinstance(env.drive.pairs.law, TonduLopez)
    env.reset(seed=0)
    for _ in range(10):
        obs, *_ = env.step(np.full(env.n_actions, 0.5, dtype=np.float32))
    assert np.all(np.isfinite(obs)) and np.all(np.isfinite(env.drive.contraction_pct))
    env.close()


def test_muscle_curves_draws_both_laws_and_the_measured_points(tmp_path):
    run_dir = tmp_path / "curves"
    proc = run_pamrun("muscle", "curves", "muscle.force_law=tondu_lopez", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    data = json.loads((run_dir / "force_curves.json").read_text())
    assert data["force_law"] == "tondu_lopez"
    assert set(data["curves_n"]) == set(data["measured_curves_n"]) == set(FORCE_LAW_NAMES)
    assert len(data["measured"]["points"]) == len(MARTENS_BOBLAN_DMSP20_300)
    assert data["measured_pressures_kpa"] == [135.0, 250.0, 600.0]
    for name in ("force_curves.png", "force_surface.png"):
        assert (run_dir / name).stat().st_size > 10_000
    assert "tondu_lopez: RMSE 141 N" in proc.stdout
