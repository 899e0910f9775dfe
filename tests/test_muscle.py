"""The PAM model against the thesis' own numbers (§8.3 Table 8.4, §10.1)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from pamrun.config import MuscleConfig, PairConfig, RegulatorConfig, to_object
from pamrun.physics.muscle import (
    AntagonisticPairs,
    FirstOrderPairDynamics,
    Regulator,
    SpringTable,
    ThesisPolynomial,
    calibrate_spring,
    contractile_force,
    simulate_step,
    zero_force_contraction_pct,
)
from tests.conftest import thesis_muscle


def test_polynomial_spot_values():
    # THESIS.md §2: F(0 %, 600 kPa) ~ 1577 N (Festo rates ~1500 N at 6 bar).
    assert contractile_force(0.0, 600.0) == pytest.approx(1576.92, abs=0.05)
    # Zero-force contractions quoted by the thesis.
    assert zero_force_contraction_pct(176.4) == pytest.approx(14.06, abs=0.01)
    assert zero_force_contraction_pct(276.4) == pytest.approx(20.27, abs=0.01)
    assert zero_force_contraction_pct(800.0) == pytest.approx(28.13, abs=0.01)


def test_polynomial_is_vectorised_and_broadcasts():
    x = np.linspace(-3, 30, 7)
    p = np.array([[0.0], [400.0], [800.0]])
    f = contractile_force(x, p)
    assert f.shape == (3, 7)
    assert f[2, 0] == pytest.approx(contractile_force(-3.0, 800.0))


def test_force_is_never_negative():
    x, p = np.meshgrid(np.linspace(-10, 45, 200), np.linspace(-100, 1200, 120))
    f = contractile_force(x, p)
    assert np.all(f >= 0)
    # Past the zero-force contraction the muscle is slack: exactly zero, not negative.
    assert contractile_force(25.0, 276.4) == 0.0
    assert contractile_force(10.0, 276.4) > 0.0


def test_pressure_above_fitted_range_is_clamped():
    assert contractile_force(5.0, 1000.0) == pytest.approx(contractile_force(5.0, 800.0))


def test_regulator_clips_voltage_and_pressure():
    reg = Regulator(RegulatorConfig(), np.zeros(4))
    p = reg.target_pressure_kpa(np.array([-1.0, 0.0, 2.12, 12.0]))
    # 0-10 V -> 0.1-10 bar at 1 bar/V (thesis §8.3, §9.5).
    np.testing.assert_allclose(p, [10.0, 10.0, 212.0, 1000.0])
    # The antagonistic command range of §9.5 stays within ~1.4-3 bar.
    lo, hi = reg.target_pressure_kpa(np.array([2.12 - 0.71, 2.12 + 0.71]))
    assert 140 <= lo <= 142 and 282 <= hi <= 284


def test_regulator_lag_is_first_order():
    reg = Regulator(RegulatorConfig(lag_s=0.1), np.array([100.0]))
    for _ in range(100):  # 0.1 s in 1 ms steps: one time constant
        reg.step(np.array([3.0]), 0.001)
    assert reg.pressure_kpa[0] == pytest.approx(100 + 200 * (1 - np.exp(-1)), rel=1e-6)


def test_regulator_hold_target_and_reset():
    """The API a caller that computes the target itself uses (the compiled step): hold() tells a
    new command (a new array) and checks its shape, step() then follows ``target_kpa`` as written,
    reset() forgets the command; lag_factor is the exact first-order share 1 - exp(-dt / lag)."""
    reg = Regulator(RegulatorConfig(lag_s=0.1), np.full((2, 2), 100.0))
    voltage = np.full((2, 2), 3.0)
    assert reg.hold(voltage) and not reg.hold(voltage)
    voltage = voltage.copy()  # equal values, another array: a new command
    assert reg.hold(voltage)
    with pytest.raises(ValueError, match="shape"):
        reg.hold(np.zeros(3))
    reg.target_kpa[:] = 300.0  # as the kernel writes it
    assert reg.step(voltage, 0.1)  # the held command: its target is not recomputed
    np.testing.assert_allclose(reg.pressure_kpa, 100 + 200 * (1 - np.exp(-1)), rtol=1e-12)
    assert reg.lag_factor(0.1) == pytest.approx(1 - np.exp(-1), rel=1e-15)
    assert Regulator(RegulatorConfig(lag_s=0.0), np.zeros(2)).lag_factor(0.1) == 0.0
    reg.reset(np.full((2, 2), 50.0))
    assert reg.pressure_kpa.tolist() == [[50.0, 50.0]] * 2 and reg.hold(voltage)  # forgotten: new again


def test_spring_table_bands():
    spring = SpringTable(thesis_muscle().spring)
    assert spring.band(np.array([0.0, 99.9, 100.0, 276.4, 800.0, 950.0])).tolist() == [0, 0, 1, 2, 7, 7]


@pytest.mark.parametrize("name", ["plus_minus_1bar", "max_and_1bar"])
def test_step_responses_match_thesis(name):
    pair = PairConfig()
    exp = pair.experiments[name]
    final = simulate_step(thesis_muscle(), pair, exp)["contraction_pct"][-1]
    np.testing.assert_allclose(final, exp.thesis_final_pct, atol=0.5)


@pytest.mark.parametrize("dt_s", [0.005, 0.01])
def test_integration_stable_at_robot_step_sizes(dt_s):
    """At 5 ms (and 10 ms) the trajectory stays finite, monotone and close to a 0.1 ms reference."""
    pair = PairConfig(duration_s=1.5, step_time_s=0.5)
    exp = pair.experiments["max_and_1bar"]
    fine = simulate_step(thesis_muscle(), replace(pair, dt_s=0.0001), exp)
    coarse = simulate_step(thesis_muscle(), replace(pair, dt_s=dt_s), exp)
    c = coarse["contraction_pct"]
    assert np.all(np.isfinite(c))
    after = coarse["time_s"] > 0.5
    assert np.all(np.diff(c[after, 0]) >= -1e-9) and np.all(np.diff(c[after, 1]) <= 1e-9)  # no overshoot/ringing
    ref = np.stack([np.interp(coarse["time_s"], fine["time_s"], fine["contraction_pct"][:, i]) for i in range(2)], -1)
    late = coarse["time_s"] > 0.5 + 0.1
    assert np.max(np.abs(c[late] - ref[late])) < 0.05
    np.testing.assert_allclose(c[-1], exp.thesis_final_pct, atol=0.5)


def test_explicit_euler_would_diverge_at_5ms():
    """The reason for the implicit step: in the states the §10.1 experiments reach, a muscle's
    fast rate (g + S) / D, from pamrun's own force-law slope g and spring table, is far beyond
    explicit Euler's stability bound 2 / 5 ms, and pamrun's step still holds that state."""
    muscle, pair = thesis_muscle(), PairConfig()
    rates = []
    for exp in pair.experiments.values():
        sim = simulate_step(muscle, pair, exp)
        dynamics = FirstOrderPairDynamics(muscle, ThesisPolynomial(), 1)
        dynamics.set_contraction_pct(sim["contraction_pct"][-1])
        pressure = sim["pressure_kpa"][-1][None, :]
        dynamics.at_pressure(pressure)
        slope_n_per_m = -dynamics.law.slope_n_per_pct(dynamics.contraction_pct(), pressure) * dynamics.pct_per_m
        rates.append(float(((slope_n_per_m + dynamics.s) / dynamics.d).max()))
        before = dynamics.contraction_pct().copy()
        dynamics.step(pressure, 0.005)
        np.testing.assert_allclose(dynamics.contraction_pct(), before, atol=0.05)
    assert max(rates) * 0.005 > 2


def test_calibration_recovers_thesis_from_a_wrong_table():
    muscle = thesis_muscle()
    wrong = replace(muscle, spring=replace(muscle.spring, stiffness_n_per_m=[1000.0] * 8))
    pair = PairConfig(duration_s=1.5, dt_s=0.002)
    table, fitted = calibrate_spring(wrong, pair)
    assert fitted == [0, 1, 2, 7]
    assert all(s > 0 for s in table)
    tuned = replace(muscle, spring=replace(muscle.spring, stiffness_n_per_m=table))
    for exp in pair.experiments.values():
        final = simulate_step(tuned, pair, exp)["contraction_pct"][-1]
        np.testing.assert_allclose(final, exp.thesis_final_pct, atol=0.01)
    # The shipped table is what calibration produces.
    np.testing.assert_allclose(table, muscle.spring.stiffness_n_per_m, rtol=1e-3)


def test_pair_command_and_torque():
    pairs = AntagonisticPairs(thesis_muscle(), 3)
    pairs.reset(212.0, thesis_muscle().rest_contraction_pct)
    v = pairs.voltages_v(np.array([0.0, 1.0, -1.0]))
    np.testing.assert_allclose(v, [[2.12, 2.12], [2.83, 1.41], [1.41, 2.83]])
    pairs.step(v, 0.005)
    torque = pairs.torque_nm(np.full(3, 0.05))
    assert torque[0] == pytest.approx(0.0, abs=1e-9)
    assert torque[1] > 1.0 and torque[2] == pytest.approx(-torque[1])  # mirror-symmetric command
    for _ in range(100):
        pairs.step(v, 0.005)
        assert np.all(pairs.forces_n() >= 0)
    # Thesis coupling: once settled, both muscles sit near their zero-force contraction, so
    # the steady torque is only S * x * r: the thesis coupling cannot hold a joint against a load.
    assert abs(pairs.torque_nm(np.full(3, 0.05))[1]) < 0.5


# --------------------------------------------------------------------------- compiled kinematic step


def _drives(**muscle):
    """The same robot's drive with the compiled kernel and with the numpy reference, one model each."""
    from pamrun.task.env import PamWalkerEnv

    envs = [PamWalkerEnv(muscle={**muscle, "kernel": k}) for k in ("numba", "numpy")]
    assert envs[0].drive.compiled and not envs[1].drive.compiled  # two paths, really
    for e in envs:
        e.reset(seed=0)
    return envs


@pytest.mark.parametrize("lag_s", [0.05, 0.0])
def test_compiled_muscle_step_matches_numpy_step_by_step(lag_s):
    """Voltages past both clips (0-10 V, and pressures above the muscle's 600 kPa), new and held
    commands, angles out to the limits (slack muscles), a dt of 0: the kernel's every output
    is the reference's to float rounding."""
    fast, ref = _drives(regulator={"lag_s": lag_s})
    outputs = {"ctrl": lambda e: e.data.ctrl, "bias": lambda e: e.model.actuator_biasprm[:, :3],
               "pressure": lambda e: e.drive.pressure_kpa, "contraction": lambda e: e.drive.contraction_pct,
               "regulator": lambda e: e.drive.pairs.regulator.pressure_kpa}
    rng = np.random.default_rng(3)
    lo, hi = ref.model.jnt_range[ref.model.dof_jntid[ref.qvel_idx]].T
    slack, lowest, highest = 0, np.inf, -np.inf
    for k in range(60):
        if k % 4 == 0:  # a new command every fourth step, held in between
            voltage = rng.uniform(-2.0, 12.0, (10, 2))
        angle = rng.uniform(lo - 0.05, hi + 0.05)
        dt = 0.0 if k % 7 == 3 else 0.005
        for e in (fast, ref):
            e.drive.set_voltages(voltage)
            e.data.qpos[e.qpos_idx] = angle
            e.drive.apply(e.model, e.data, e.qpos_idx, e.qvel_idx, dt)
        for name, get in outputs.items():
            np.testing.assert_allclose(get(fast), get(ref), rtol=1e-12, atol=1e-9, err_msg=f"{name}, step {k}")
        velocity = rng.uniform(-2, 2, 10)
        np.testing.assert_allclose(fast.drive.torques_nm(angle, velocity, 0.0),
                                   ref.drive.torques_nm(angle, velocity, 0.0), rtol=1e-12, atol=1e-9)
        force = ref.drive.pairs.law.force_and_slope(ref.drive.coupling.coef, ref.drive.contraction_pct)[0]
        slack += int((force <= 0).sum())
        pressure = ref.drive.pairs.regulator.pressure_kpa
        lowest, highest = min(lowest, pressure.min()), max(highest, pressure.max())
    assert highest > 650 and lowest < 200  # past the muscle's 600 kPa (the force law's clamp), and low
    if lag_s == 0:
        assert (lowest, highest) == (10.0, 1000.0)  # the regulator's own clips
    assert slack > 0  # and some muscles went slack


def test_kernel_must_be_known():
    from pamrun.config import ConfigError
    from tests.conftest import compose_config

    assert MuscleConfig().kernel == "numba"
    with pytest.raises(ConfigError) as err:
        MuscleConfig(kernel="foo")
    assert err.value.key == "kernel" and "numba, numpy" in str(err.value)
    with pytest.raises(ConfigError) as err:
        to_object(compose_config("muscle.kernel=foo"))
    assert err.value.key == "muscle.kernel"
