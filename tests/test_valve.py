"""The flow-limited valve, ``muscle.regulator.model=flow`` (pamrun/physics/valve.py), against analytic numbers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pamrun.config import ConfigError, MuscleConfig, RegulatorConfig, to_object
from pamrun.physics.muscle import Regulator, muscle_volume_l
from pamrun.physics.valve import FlowRegulator, make_regulator, volume_cubic_l
from tests.conftest import compose_config

# The default robot's muscle: a DMSP-40 (40 mm inner diameter) of 300 mm.
LENGTH_M, DIAMETER_M = 0.30, 0.040
ATM_KPA = 101.325
# kPa litres of gas at 20 degC per normal litre (DIN 1343: 101.325 kPa, 0 degC), isothermal.
KPA_L_PER_NL = 101.325 * 293.15 / 273.15


def datasheet_conductance(b: float = 0.528) -> float:
    """C [Nl/(s kPa)] from the datasheet: 700 Nl/min from 6 to 5 bar gauge (ISO 6358, subsonic there)."""
    p1, p2 = 600.0 + ATM_KPA, 500.0 + ATM_KPA
    psi = math.sqrt(1.0 - ((p2 / p1 - b) / (1.0 - b)) ** 2)
    return 700.0 / 60.0 / (p1 * psi)


def valve(shape=(1, 2), count=1.0, pressure_kpa=0.0, **cfg) -> FlowRegulator:
    reg = FlowRegulator(RegulatorConfig(model="flow", **cfg), np.zeros(shape), LENGTH_M, DIAMETER_M, count)
    reg.reset(np.full(shape, pressure_kpa))
    return reg


def command(reg: Regulator, pressure_kpa: float) -> np.ndarray:
    return reg.voltage_for_pressure_v(np.full(reg.pressure_kpa.shape, pressure_kpa))


def test_volume_cubic_is_the_muscle_volume():
    c = np.linspace(-3.0, 30.0, 67)
    a0, a1, a2, a3 = volume_cubic_l(LENGTH_M, DIAMETER_M)
    cc = np.minimum(c, 25.0)
    np.testing.assert_allclose(a0 + a1 * cc + a2 * cc**2 + a3 * cc**3, muscle_volume_l(c, LENGTH_M, DIAMETER_M),
                               rtol=1e-12)
    assert a0 == pytest.approx(math.pi * DIAMETER_M**2 * LENGTH_M / 4 * 1000, rel=1e-12)  # V(0 %) = pi D0^2 L0 / 4


@pytest.mark.parametrize("count", [1, 2])
def test_initial_fill_and_exhaust_are_the_choked_flow_over_the_volume(count):
    """At 0 % contraction (V = pi D0^2 L0 / 4) the first 0.1 ms of a fill from 0 kPa (800 kPa supply:
    p_down / p_up = 0.11, choked) and of an exhaust from 600 kPa (0.14, choked) move at
    P_N (T / T_N) C p_up / V, with C from the datasheet's 700 Nl/min; the 50 ms lag alone would
    move twice as fast, so the valve sets the slope. Two muscles on one valve: half."""
    volume_l = count * math.pi * DIAMETER_M**2 * LENGTH_M / 4 * 1000
    c = datasheet_conductance()
    dt = 1e-4
    fill = valve(count=count)
    fill.step(command(fill, 600.0), dt, np.zeros((1, 2)))
    expected = KPA_L_PER_NL * c * (800.0 + ATM_KPA) / volume_l  # kPa/s
    assert fill.pressure_kpa[0, 0] / dt == pytest.approx(expected, rel=1e-9)
    assert expected * dt < 600.0 * (1 - math.exp(-dt / 0.05))  # flow-limited, not lag-limited
    assert expected == pytest.approx(6039.0 / count, rel=1e-3)  # about 6 bar in 0.1 s (one muscle)

    exhaust = valve(count=count, pressure_kpa=600.0)
    exhaust.step(command(exhaust, 10.0), dt, np.zeros((1, 2)))
    slope = (exhaust.pressure_kpa[0, 0] - 600.0) / dt
    assert slope == pytest.approx(-KPA_L_PER_NL * c * (600.0 + ATM_KPA) / volume_l, rel=1e-9)


def test_pressure_never_exceeds_the_supply_and_the_fill_slows_near_it():
    """A 10 bar command on a 700 kPa supply: the pressure creeps up to 700 kPa, never past it,
    even at 50 ms steps; the last 50 kPa take longer than the first 50 (subsonic ellipse)."""
    for dt in (0.05, 0.005, 0.0005):
        reg = valve(supply_pressure_kpa=700.0)
        high = command(reg, 1000.0)
        trace = [0.0]
        for _ in range(round(3.0 / dt)):
            reg.step(high, dt, np.full((1, 2), 9.0))
            trace.append(reg.pressure_kpa[0, 0])
        trace = np.asarray(trace)
        assert trace.max() <= 700.0 and trace[-1] > 699.0
        assert np.all(np.diff(trace) >= 0.0)
    t = np.arange(len(trace)) * dt  # the finest run
    first = np.interp(50.0, trace, t)
    last = np.interp(699.0, trace, t) - np.interp(649.0, trace, t)
    assert last > 2 * first


def test_gas_is_kept_through_a_volume_change():
    """Valve shut (the pressure at its target, no time passing): a muscle contracting from 0 to
    20 % keeps its gas, P_abs V constant."""
    reg = valve(pressure_kpa=300.0)
    hold = command(reg, 300.0)
    reg.step(hold, 0.0, np.zeros((1, 2)))
    reg.step(hold, 0.0, np.full((1, 2), 20.0))
    v0, v20 = muscle_volume_l(np.array([0.0, 20.0]), LENGTH_M, DIAMETER_M)
    np.testing.assert_allclose(reg.pressure_kpa, (300.0 + ATM_KPA) * v0 / v20 - ATM_KPA, rtol=1e-12)
    assert reg.pressure_kpa[0, 0] < 270.0  # the muscle grew by 22 %


def test_reservoir_gives_the_air_of_the_fills():
    """Mass balance: a 5 l tank (no compressor) filling 2 pairs (1 and 2 muscles per side) from
    300 to 600 kPa at 9 % loses P_res V_res = sum (Delta P) V; the compressor then refills it at
    its rate, up to the supply pressure."""
    reg = valve(shape=(2, 2), count=np.array([1.0, 2.0]), pressure_kpa=300.0, reservoir_volume_l=5.0,
                compressor_flow_nl_min=0.0)
    at, high = np.full((2, 2), 9.0), command(reg, 600.0)
    for _ in range(400):  # 2 s
        reg.step(high, 0.005, at)
    volume = muscle_volume_l(9.0, LENGTH_M, DIAMETER_M) * np.array([[1.0, 1.0], [2.0, 2.0]])
    drawn_kpa_l = ((reg.pressure_kpa - 300.0) * volume).sum()
    assert reg.reservoir_kpa[0] == pytest.approx(800.0 - drawn_kpa_l / 5.0, abs=1e-9)
    assert 800.0 - reg.reservoir_kpa[0] == pytest.approx(300.0 * 6 * volume[0, 0] / 5.0, rel=1e-6)  # 154 kPa

    refill = valve(pressure_kpa=300.0, reservoir_volume_l=10.0, compressor_flow_nl_min=200.0)
    refill.reservoir_kpa[0] = 500.0
    hold = command(refill, 300.0)
    for _ in range(100):  # 1 s, no fill
        refill.step(hold, 0.01, np.full((1, 2), 9.0))
    assert refill.reservoir_kpa[0] == pytest.approx(500.0 + 200.0 / 60.0 * KPA_L_PER_NL / 10.0, rel=1e-9)
    for _ in range(1000):
        refill.step(hold, 0.01, np.full((1, 2), 9.0))
    assert refill.reservoir_kpa[0] == 800.0  # the pressure switch


def test_a_small_tank_settles_where_the_gas_is_shared():
    """1 l at 800 kPa, no compressor, into two sides at 100 kPa commanded to 600 kPa: the fill stops
    where tank and muscles share their gas, P_eq = sum(P_abs V) / sum(V) (absolute)."""
    reg = valve(pressure_kpa=100.0, reservoir_volume_l=1.0, compressor_flow_nl_min=0.0)
    high = command(reg, 600.0)
    for _ in range(2000):
        reg.step(high, 0.001, np.full((1, 2), 9.0))
    v = muscle_volume_l(9.0, LENGTH_M, DIAMETER_M)
    equal = ((800.0 + ATM_KPA) * 1.0 + 2 * (100.0 + ATM_KPA) * v) / (1.0 + 2 * v) - ATM_KPA
    np.testing.assert_allclose(reg.pressure_kpa, equal, atol=0.5)
    assert reg.reservoir_kpa[0] == pytest.approx(equal, abs=0.5)
    # each step fills up to the tank's pressure at its start, which the fills then lower: the
    # explicit step may leave the muscles a fraction of a kPa above a tank this small
    assert reg.pressure_kpa.max() <= reg.reservoir_kpa[0] + 0.5


@pytest.mark.parametrize(("overrides", "key"), [
    ({"model": "valve"}, "model"),
    ({"nominal_flow_nl_min": 0.0}, "nominal_flow_nl_min"),
    ({"nominal_flow_nl_min": -700.0}, "nominal_flow_nl_min"),
    ({"supply_pressure_kpa": -1.0}, "supply_pressure_kpa"),
    ({"reservoir_volume_l": -2.0}, "reservoir_volume_l"),
    ({"compressor_flow_nl_min": -1.0}, "compressor_flow_nl_min"),
    ({"critical_pressure_ratio": 1.0}, "critical_pressure_ratio"),
])
def test_a_bad_valve_parameter_names_its_key(overrides, key):
    with pytest.raises(ConfigError) as err:
        RegulatorConfig(**overrides)
    assert err.value.key == key
    name, value = next(iter(overrides.items()))
    with pytest.raises(ConfigError) as err:
        to_object(compose_config(f"muscle.regulator.{name}={value}"))
    assert err.value.key == f"muscle.regulator.{key}"


def test_the_supply_must_reach_the_muscles_top_pressure():
    """The top pressure is the lower of the regulator's (10 bar) and the muscle's maximum (6 bar by
    default, 8 bar for muscle=thesis); only model=flow reads the supply."""
    with pytest.raises(ConfigError) as err:
        to_object(compose_config("muscle.regulator.model=flow", "muscle.regulator.supply_pressure_kpa=500"))
    assert err.value.key == "muscle.regulator.supply_pressure_kpa" and "600" in err.value.message
    assert to_object(compose_config("muscle.regulator.supply_pressure_kpa=500")).muscle.regulator.model == "lag"
    assert to_object(compose_config("muscle.regulator.model=flow", "muscle.regulator.supply_pressure_kpa=600"))
    with pytest.raises(ConfigError) as err:
        to_object(compose_config("muscle=thesis", "muscle.regulator.model=flow",
                                 "muscle.regulator.supply_pressure_kpa=700"))
    assert err.value.key == "muscle.regulator.supply_pressure_kpa"
    with pytest.raises(ConfigError) as err:  # a drive built without the root config checks it too
        make_regulator(MuscleConfig(regulator=RegulatorConfig(model="flow", supply_pressure_kpa=500.0)),
                       np.zeros((1, 2)))
    assert err.value.key == "regulator.supply_pressure_kpa"


def test_lag_is_the_default_and_untouched():
    """model=lag builds the plain Regulator (no valve state), and both kernels follow its closed form."""
    from pamrun.physics.kernels import P_MODEL
    from pamrun.task.env import PamWalkerEnv

    assert RegulatorConfig().model == "lag"
    assert type(make_regulator(MuscleConfig(), np.zeros((10, 2)))) is Regulator
    for kernel in ("numba", "numpy"):
        env = PamWalkerEnv(muscle={"kernel": kernel})
        assert type(env.drive.pairs.regulator) is Regulator
        if kernel == "numba":
            assert env.drive.coupling.compiled.params[P_MODEL] == 0.0
        env.reset(seed=0)
        for k in range(1, 4):
            env.step(np.ones(10, dtype=np.float32))
            np.testing.assert_allclose(env.drive.pressure_kpa[:, 0], 300 + 300 * (1 - np.exp(-0.025 * k / 0.05)),
                                       rtol=1e-12)


def _drives(**muscle):
    """The same robot's drive with the compiled kernel and with the numpy reference."""
    from pamrun.task.env import PamWalkerEnv

    envs = [PamWalkerEnv(muscle={**muscle, "kernel": k}) for k in ("numba", "numpy")]
    assert envs[0].drive.compiled and not envs[1].drive.compiled
    for e in envs:
        e.reset(seed=0)
    return envs


@pytest.mark.parametrize("regulator", [{"model": "flow"}, {"model": "flow", "lag_s": 0.0},
                                       {"model": "flow", "reservoir_volume_l": 3.0, "supply_pressure_kpa": 650.0}])
def test_compiled_valve_matches_numpy_step_by_step(regulator):
    """Voltages past both clips, new and held commands, angles out to the limits (volumes change),
    a dt of 0: the compiled valve's every output is the numpy reference's to float rounding."""
    fast, ref = _drives(regulator=regulator)
    assert isinstance(fast.drive.pairs.regulator, FlowRegulator)
    outputs = {"ctrl": lambda e: e.data.ctrl, "bias": lambda e: e.model.actuator_biasprm[:, :3],
               "regulator": lambda e: e.drive.pairs.regulator.pressure_kpa,
               "volume": lambda e: e.drive.pairs.regulator.volume_l,
               "reservoir": lambda e: e.drive.pairs.regulator.reservoir_kpa,
               "contraction": lambda e: e.drive.contraction_pct}
    rng = np.random.default_rng(5)
    lo, hi = ref.model.jnt_range[ref.model.dof_jntid[ref.qvel_idx]].T
    pressures = []
    for k in range(80):
        if k % 16 == 0:  # a new command every 80 ms, held in between
            voltage = rng.uniform(-2.0, 12.0, (10, 2))
        angle = rng.uniform(lo - 0.05, hi + 0.05)
        dt = 0.0 if k % 7 == 3 else 0.005
        for e in (fast, ref):
            e.drive.set_voltages(voltage)
            e.data.qpos[e.qpos_idx] = angle
            e.drive.apply(e.model, e.data, e.qpos_idx, e.qvel_idx, dt)
        for name, get in outputs.items():
            np.testing.assert_allclose(get(fast), get(ref), rtol=1e-12, atol=1e-9, err_msg=f"{name}, step {k}")
        pressures.append(ref.drive.pairs.regulator.pressure_kpa.copy())
    pressures = np.asarray(pressures)
    assert pressures.max() > 500 and pressures.min() < 150  # it filled and exhausted
    if regulator.get("reservoir_volume_l"):
        assert ref.drive.pairs.regulator.reservoir_kpa[0] < 650.0  # the tank sagged
    fast.reset(seed=0)
    assert fast.drive.pairs.regulator.reservoir_kpa[0] == regulator.get("supply_pressure_kpa", 800.0)


def _stands(seconds: float, seed: int = 0, noise: float = 0.0, **regulator) -> None:
    from pamrun.task.env import PamWalkerEnv

    env = PamWalkerEnv(muscle={"regulator": {"model": "flow", **regulator}}, env={"reset_noise_rad": noise})
    assert isinstance(env.drive.pairs.regulator, FlowRegulator)
    env.reset(seed=seed)
    steps = round(seconds / env.env_cfg.control_dt_s)
    for _ in range(steps):
        _, _, terminated, truncated, info = env.step(np.zeros(env.n_actions, dtype=np.float32))
        assert not terminated
    assert abs(info["x"]) < 0.1 and info["z"] > 0.95 * env.z0
    np.testing.assert_allclose(env.drive.pressure_kpa, 300.0, atol=5.0)  # V0's 300 kPa, held
    return truncated


@pytest.mark.parametrize(("seed", "noise", "regulator"), [(0, 0.0, {}), (3, 0.02, {}),
                                                          (0, 0.0, {"reservoir_volume_l": 2.0})])
def test_default_robot_stands_ten_seconds_under_flow(seed, noise, regulator):
    """As tests/test_capacity.py's zero-action stand (under a second with the compiled kernel),
    with the ideal supply and with a 2 l tank."""
    assert _stands(10.0, seed, noise, **regulator)  # the episode ran out standing


def test_valve_bench_reports_flow_slower_than_lag():
    """pamrun muscle valve's numbers: the lag's 10-90 % rise is 2.2 lag_s whatever the volume; the
    valve's is longer, and longer for a bigger volume (20 % vs 0 %, two muscles vs one)."""
    from pamrun.bench.muscle import valve_step_responses

    results = valve_step_responses(MuscleConfig(), duration_s=0.4, dt_s=0.001)
    lag = [c for c in results["cases"] if c["model"] == "lag"]
    flow = {(c["contraction_pct"], c["muscles_per_side"]): c for c in results["cases"] if c["model"] == "flow"}
    assert len(lag) == 1 and lag[0]["rise_10_90_s"] == pytest.approx(0.05 * math.log(9), abs=1e-3)
    assert lag[0]["rise_10_90_s"] < flow[0.0, 1]["rise_10_90_s"] < flow[20.0, 1]["rise_10_90_s"]
    assert flow[0.0, 1]["rise_10_90_s"] < flow[0.0, 2]["rise_10_90_s"]
    assert all(c["t95_s"] is not None for c in results["cases"])
