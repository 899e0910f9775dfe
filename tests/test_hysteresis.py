"""Muscle hysteresis, ``muscle.spring.hysteresis`` (pamrun/physics/hysteresis.py), against analytic numbers.

An elasto-slide element (stiffness k, slip force f) cycled through +- A (A > f / k) encloses a
parallelogram of area 4 f (A - f / k): the energy it dissipates per cycle. N elements: the sum.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from pamrun.config import BodyConfig, ConfigError, MuscleConfig, RegulatorConfig, SpringConfig, to_object
from pamrun.config.robot import HYSTERESIS_LAWS
from pamrun.physics.actuation import MuscleDrive
from pamrun.physics.hysteresis import (
    HYSTERESIS,
    M_PER_PCT,
    MaxwellSlip,
    hysteresis_loop,
    loop_area_j,
)
from pamrun.physics.muscle import AntagonisticPairs
from tests.conftest import compose_config, run_pamrun, thesis_muscle

SLIP = {"hysteresis": "maxwell_slip"}


def _cycle_pct(amplitude_pct: float, steps_per_cycle: int, cycles: int = 2) -> np.ndarray:
    """A sinusoidal contraction change, +- amplitude [%] about 0, ``cycles`` times (extremes sampled)."""
    return amplitude_pct * np.sin(2 * np.pi * np.arange(cycles * steps_per_cycle + 1) / steps_per_cycle)


def _analytic_j(spring: SpringConfig, gain: float, amplitude_m: float) -> float:
    """sum_i 4 f_i g (A - f_i / k_i) [J]: what the elements dissipate per cycle of +- A (all slip)."""
    elements = list(zip(spring.slip_stiffness_n_per_m, spring.slip_force_n))
    assert all(amplitude_m > f / k for k, f in elements)
    return sum(4 * f * gain * (amplitude_m - f / k) for k, f in elements)


def _element_loop_j(spring: SpringConfig, amplitude_m: float, steps: int = 4000) -> float:
    """Energy [J] the elements of ``spring`` dissipate over the second of two cycles of +- amplitude_m
    [m of the reference muscle] at their reference pressure (g = 1): the closed integral of H dx."""
    slip = MaxwellSlip(spring, 1, 800.0)
    slip.at_pressure(np.full((1, 2), spring.slip_reference_pressure_kpa))
    path_pct = _cycle_pct(amplitude_m / M_PER_PCT, steps)
    held = np.empty(len(path_pct))
    previous = path_pct[0]
    for k, c in enumerate(path_pct):
        slip.move(np.full((1, 2), c - previous))
        previous = c
        held[k] = slip.force_n()[0, 0]
    second = slice(steps, None)
    # loop_area_j integrates -F dx over x = c / 100 L0: the elements' force H is -F, L0 the reference 0.26 m
    return loop_area_j(path_pct[second], -held[second], 0.26)


def test_law_names_are_the_registry():
    assert tuple(HYSTERESIS) == HYSTERESIS_LAWS == ("none", "maxwell_slip")
    assert SpringConfig().hysteresis == "none" and MuscleConfig().spring.hysteresis == "none"


@pytest.mark.parametrize(("k_n_per_m", "f_n", "amplitude_m"), [(20000.0, 10.0, 0.003), (5000.0, 30.0, 0.008)])
def test_one_element_dissipates_4f_times_a_minus_f_over_k(k_n_per_m, f_n, amplitude_m):
    spring = SpringConfig(hysteresis="maxwell_slip", slip_stiffness_n_per_m=[k_n_per_m], slip_force_n=[f_n])
    expected = 4 * f_n * (amplitude_m - f_n / k_n_per_m)
    assert _element_loop_j(spring, amplitude_m) == pytest.approx(expected, rel=2e-3)


def test_an_element_that_never_slips_dissipates_nothing():
    spring = SpringConfig(hysteresis="maxwell_slip", slip_stiffness_n_per_m=[1000.0], slip_force_n=[10.0])
    assert abs(_element_loop_j(spring, 0.005)) < 1e-12  # A = 5 mm < f / k = 10 mm


def test_n_elements_dissipate_the_sum():
    spring = SpringConfig(hysteresis="maxwell_slip")  # the default three elements
    amplitude_m = 0.004
    each = [4 * f * (amplitude_m - f / k) for k, f in zip(spring.slip_stiffness_n_per_m, spring.slip_force_n)]
    assert len(each) == 3 and all(e > 0 for e in each)
    assert _element_loop_j(spring, amplitude_m) == pytest.approx(sum(each), rel=2e-3)


def test_bench_loop_area_is_analytic_with_slip_and_zero_with_none():
    """pamrun muscle hysteresis' numbers: the force law's own curve encloses nothing; the elements
    enclose sum 4 f_i g (A - f_i / k_i), scaled by the size's force ratio and L0 / 0.26 m."""
    thesis = MuscleConfig(size="DMSP-20", nominal_length_m=0.26)
    results = hysteresis_loop(thesis, pressures_kpa=(300.0, 600.0), amplitude_pct=5.0, steps_per_cycle=2000)
    spring = thesis.spring
    for case in results["cases"]:
        gain = case["pressure_kpa"] / spring.slip_reference_pressure_kpa
        a_m = 5.0 / 100 * 0.26
        expected = _analytic_j(spring, gain, a_m)
        assert case["analytic_area_j"] == pytest.approx(expected, rel=1e-12)
        assert case["area_slip_j"] == pytest.approx(expected, rel=2e-3)
        assert abs(case["area_none_j"]) < 1e-9
    # another size and length: x4 the force (DMSP-40), 300 / 260 the stroke
    big = hysteresis_loop(MuscleConfig(), pressures_kpa=(600.0,), steps_per_cycle=2000)["cases"][0]
    assert big["area_slip_j"] == pytest.approx(4 * 0.30 / 0.26 * results["cases"][1]["area_slip_j"], rel=1e-9)


def test_none_builds_no_elements_and_its_forces_are_the_force_law():
    """hysteresis=none: no element state, and every path's force is the force law's (clipped at 0)."""
    rng = np.random.default_rng(1)
    for kernel in ("numpy", "numba"):
        drive = MuscleDrive(MuscleConfig(kernel=kernel, regulator=RegulatorConfig(lag_s=0.0)), BodyConfig())
        drive.reset()
        assert drive.pairs.dynamics.hysteresis is None and drive.coupling.hysteresis is None
        for _ in range(5):
            drive.set_voltages(rng.uniform(0.5, 6.0, (10, 2)))
            angle = drive.coupling.neutral + rng.uniform(-0.3, 0.3, 10)
            torque = drive.torques_nm(angle, np.zeros(10), 0.005)
            force = np.maximum(drive.pairs.law.signed_force_n(drive.contraction_pct, drive.pressure_kpa), 0.0)
            np.testing.assert_allclose(torque, (force[:, 0] - force[:, 1]) * drive.coupling.lever, rtol=1e-12)
    pairs = AntagonisticPairs(thesis_muscle(), 2)
    pairs.reset(176.4, thesis_muscle().rest_contraction_pct)
    assert pairs.dynamics.hysteresis is None
    for _ in range(20):
        pairs.step(np.array([[2.8, 1.4], [1.4, 2.8]]), 0.005)
        force = np.maximum(pairs.law.signed_force_n(pairs.contraction_pct(), pairs.pressure_kpa), 0.0)
        np.testing.assert_array_equal(pairs.forces_n(), force)


@pytest.mark.parametrize("kernel", ["numpy", "numba"])
def test_kinematic_coupling_dissipates_the_analytic_energy_per_cycle(kernel):
    """Each joint cycled +- 3 % of contraction about its neutral angle at constant pressure: the
    work the pair's torque does on it over a cycle is minus both muscles' element dissipation,
    -closed integral of T dtheta = k r / (100 r / L0) / M_PER_PCT (E1 + E2), E = sum 4 f g (A - f/k)."""
    muscle = MuscleConfig(kernel=kernel, regulator=RegulatorConfig(lag_s=0.0), spring=SpringConfig(**SLIP))
    drive = MuscleDrive(muscle, BodyConfig())
    drive.reset()
    drive.set_voltages(np.full((10, 2), 4.0))  # 400 kPa in every muscle: all taut over the cycle
    coupling, steps = drive.coupling, 800
    amplitude_rad = 3.0 / coupling.pct_per_rad
    path = coupling.neutral + np.outer(np.sin(2 * np.pi * np.arange(2 * steps + 1) / steps), amplitude_rad)
    torque = np.array([drive.torques_nm(angle, np.zeros(10), 0.005) for angle in path])
    second = slice(steps, None)
    work_j = np.sum(0.5 * (torque[second][1:] + torque[second][:-1]) * np.diff(path[second], axis=0), axis=0)
    spring, gain, a_m = muscle.spring, 400.0 / muscle.spring.slip_reference_pressure_kpa, 3.0 * M_PER_PCT
    expected = coupling.lever / coupling.pct_per_rad / M_PER_PCT * 2 * _analytic_j(spring, gain, a_m)
    np.testing.assert_allclose(-work_j, expected, rtol=3e-3)


def _envs(**muscle):
    """The same robot with hysteresis, stepped by the compiled kernel and by the numpy reference."""
    from pamrun.task.env import PamWalkerEnv

    envs = [PamWalkerEnv(muscle={"spring": SLIP, **muscle, "kernel": k}) for k in ("numba", "numpy")]
    assert envs[0].drive.compiled and not envs[1].drive.compiled
    for e in envs:
        e.reset(seed=0)
    return envs


@pytest.mark.parametrize("regulator", [{"lag_s": 0.05}, {"lag_s": 0.0}, {"model": "flow"}])
def test_compiled_kernel_matches_numpy_with_hysteresis(regulator):
    """Random commands (past the clips), angles out to the limits (slack muscles), dt 0 now and
    then: every output and the elements' state agree to float rounding; then whole env steps."""
    fast, ref = _envs(regulator=regulator)
    outputs = {"ctrl": lambda e: e.data.ctrl, "bias": lambda e: e.model.actuator_biasprm[:, :3],
               "pressure": lambda e: e.drive.pressure_kpa, "contraction": lambda e: e.drive.contraction_pct,
               "slip": lambda e: e.drive.coupling.hysteresis.slip_m, "gain": lambda e: e.drive.coupling.hysteresis.gain}
    rng = np.random.default_rng(7)
    lo, hi = ref.model.jnt_range[ref.model.dof_jntid[ref.qvel_idx]].T
    slipping, sticking = 0, 0
    for k in range(80):
        if k % 4 == 0:
            voltage = rng.uniform(-2.0, 12.0, (10, 2))
        near = ref.data.qpos[ref.qpos_idx] + rng.normal(0, 0.01, 10)  # small moves: elements stick
        angle = rng.uniform(lo - 0.05, hi + 0.05) if k % 3 == 0 else near
        dt = 0.0 if k % 7 == 3 else 0.005
        for e in (fast, ref):
            e.drive.set_voltages(voltage)
            e.data.qpos[e.qpos_idx] = angle
            e.drive.apply(e.model, e.data, e.qpos_idx, e.qvel_idx, dt)
        for name, get in outputs.items():
            np.testing.assert_allclose(get(fast), get(ref), rtol=1e-12, atol=1e-9, err_msg=f"{name}, step {k}")
        h = ref.drive.coupling.hysteresis
        at_limit = np.abs(h.slip_m) == h.width_m[:, None, None]
        slipping, sticking = slipping + int(at_limit.sum()), sticking + int((~at_limit).sum())
    assert slipping > 0 and sticking > 0  # both regimes were crossed
    rng = np.random.default_rng(8)
    for _ in range(20):  # env steps: the compiled multi-step advance against the numpy loop
        action = rng.uniform(-1, 1, fast.n_actions).astype(np.float32)
        obs_fast, obs_ref = fast.step(action)[0], ref.step(action)[0]
        np.testing.assert_allclose(obs_fast, obs_ref, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(outputs["slip"](fast), outputs["slip"](ref), rtol=1e-9, atol=1e-12)


def test_elements_reset_with_the_muscle():
    """After a reset every element is at rest, whichever coupling and kernel (the kernel writes the
    numpy state in place, so the same array is reset)."""
    fast, ref = _envs()
    for e in (fast, ref):
        for _ in range(5):
            e.step(np.ones(e.n_actions, dtype=np.float32))
        h = e.drive.coupling.hysteresis
        assert h is e.drive.pairs.dynamics.hysteresis and np.abs(h.slip_m).max() > 0
        e.reset(seed=1)
        assert not h.slip_m.any()
    assert fast.drive.coupling.compiled.slip is fast.drive.coupling.hysteresis.slip_m
    thesis = to_object(compose_config("muscle=thesis", "muscle.spring.hysteresis=maxwell_slip")).muscle
    pairs = AntagonisticPairs(thesis, 1)
    pairs.reset(176.4, 14.06)
    for _ in range(10):
        pairs.step(np.array([[2.8, 1.4]]), 0.005)
    assert pairs.dynamics.hysteresis.slip_m.any()
    pairs.reset(176.4, 14.06)
    assert not pairs.dynamics.hysteresis.slip_m.any()


def test_thesis_coupling_settles_where_the_forces_with_hysteresis_balance():
    """Thesis coupling, a §10.1 step with hysteresis: it settles (short of the frictionless end,
    the elements holding it) where S x = (F1 - H1) - (F2 - H2) for each muscle, x' = 0."""
    cfg = to_object(compose_config("muscle=thesis", "muscle.spring.hysteresis=maxwell_slip"))
    muscle, exp = cfg.muscle, cfg.pair.experiments["plus_minus_1bar"]
    pairs = AntagonisticPairs(muscle, 1)
    pairs.reset(cfg.pair.initial_pressure_kpa, cfg.pair.initial_contraction_pct)
    voltage = pairs.regulator.voltage_for_pressure_v(np.array([[exp.pressure1_kpa, exp.pressure2_kpa]]))
    for _ in range(600):
        pairs.step(voltage, 0.005)
    dyn = pairs.dynamics
    net = pairs.law.signed_force_n(pairs.contraction_pct(), pairs.pressure_kpa) - dyn.hysteresis.force_n()
    np.testing.assert_allclose(dyn.s * dyn.x_m, net - net[:, ::-1], atol=1e-6)
    assert np.abs(dyn.hysteresis.force_n()).min() > 1.0  # the elements hold a force
    final = pairs.contraction_pct()[0]
    assert abs(final[0] - exp.thesis_final_pct[0]) > 0.05  # not the frictionless end (20.22 %)...
    assert abs(final[0] - exp.thesis_final_pct[0]) < 1.0  # ...but near it


@pytest.mark.parametrize(("key", "value"), [
    ("hysteresis", "two_tables"),
    ("slip_stiffness_n_per_m", [-50000.0, 16000.0, 6000.0]),
    ("slip_stiffness_n_per_m", [0.0, 16000.0, 6000.0]),
    ("slip_force_n", [12.5, -1.0, 12.5]),
    ("slip_force_n", [12.5, 12.5]),
    ("slip_reference_pressure_kpa", 0.0),
])
def test_a_bad_hysteresis_parameter_names_its_key(key, value):
    with pytest.raises(ConfigError) as err:
        SpringConfig(**{key: value})
    assert err.value.key == key
    if key == "hysteresis":
        assert "none, maxwell_slip" in err.value.message
    text = json.dumps(value).replace('"', "")
    with pytest.raises(ConfigError) as err:
        to_object(compose_config(f"muscle.spring.{key}={text}"))
    assert err.value.key == f"muscle.spring.{key}"


@pytest.mark.parametrize(("seed", "noise", "kernel"), [(0, 0.0, "numba"), (3, 0.02, "numba"), (0, 0.0, "numpy")])
def test_default_robot_stands_ten_seconds_with_hysteresis(seed, noise, kernel):
    """As the zero-action stand of tests/test_capacity.py, with the Maxwell-slip elements on."""
    from pamrun.task.env import PamWalkerEnv

    env = PamWalkerEnv(muscle={"kernel": kernel, "spring": SLIP}, env={"reset_noise_rad": noise})
    env.reset(seed=seed)
    for _ in range(round(10.0 / env.env_cfg.control_dt_s)):
        _, _, terminated, _, info = env.step(np.zeros(env.n_actions, dtype=np.float32))
        assert not terminated
    assert abs(info["x"]) < 0.1 and info["z"] > 0.95 * env.z0
    assert np.abs(env.drive.coupling.hysteresis.force_n()).max() > 1.0  # the elements did act


def test_pamrun_muscle_hysteresis_writes_the_loop_and_its_area(tmp_path):
    run_dir = tmp_path / "hysteresis"
    proc = run_pamrun("muscle", "hysteresis", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    data = json.loads((run_dir / "hysteresis_loop.json").read_text())
    assert [c["pressure_kpa"] for c in data["cases"]] == [300.0, 600.0]
    for case in data["cases"]:
        assert case["area_slip_j"] == pytest.approx(case["analytic_area_j"], rel=2e-3) and case["area_slip_j"] > 1.0
    assert (run_dir / "hysteresis_loop.png").stat().st_size > 10_000
    assert "Wrote hysteresis_loop.json, hysteresis_loop.png" in proc.stdout
