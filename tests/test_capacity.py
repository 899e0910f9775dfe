"""A robot that can stand and walk: sizing options, capacity against demand, standing, open loop."""

from __future__ import annotations

import json
from dataclasses import replace

import mujoco
import numpy as np
import pytest

from pamrun.config import (
    LEG_JOINTS,
    BodyConfig,
    ConfigError,
    JointCounts,
    MuscleConfig,
    upgrade_saved_config,
)
from pamrun.physics.actuation import MuscleDrive
from pamrun.physics.capacity import (
    _BELOW,
    REQUIRED_MARGIN,
    WALKING_PEAK_NM_PER_KG,
    WALKING_RANGE_DEG,
    analyse,
)
from pamrun.task.env import PamWalkerEnv
from pamrun.task.observation import space_sizes
from tests.conftest import run_pamrun, thesis_muscle


@pytest.fixture(scope="module")
def default_capacity():
    return analyse(MuscleConfig(), BodyConfig())


def test_walking_tables_name_every_leg_joint():
    """The demand tables are keyed by LEG_JOINTS, in its order; each joint's first word is a group."""
    assert tuple(WALKING_PEAK_NM_PER_KG) == LEG_JOINTS == tuple(WALKING_RANGE_DEG)
    assert {joint.split("_")[0] for joint in LEG_JOINTS} == set(_BELOW)


def test_default_covers_walking_demand_with_margin(default_capacity):
    joints = default_capacity["joints"]
    assert set(joints) == {"hip_pitch", "hip_roll", "knee", "ankle_pitch", "ankle_roll"}
    for name, r in joints.items():
        assert r["walking_margin"] >= REQUIRED_MARGIN, name
        # the margin is the weakest envelope point over the walking range, both directions
        angle = np.asarray(r["angle_deg"])
        lo, hi = r["walking_range_deg"]
        inside = (angle >= lo - 1e-6) & (angle <= hi + 1e-6)
        band = r["envelope"]["band"]
        weakest = min(np.min(np.asarray(band["plus_nm"])[inside]), -np.max(np.asarray(band["minus_nm"])[inside]))
        assert r["walking_margin"] == pytest.approx(weakest / r["walking_demand_nm"], rel=1e-3)
    assert default_capacity["robot_mass_kg"] == pytest.approx(37.12, abs=0.01)
    assert joints["ankle_pitch"]["walking_demand_nm"] == pytest.approx(1.5 * 37.12, rel=1e-3)
    assert default_capacity["verdict"] == {"walking_margin_ok": True, "ankle_stiffness_ok": True,
                                           "min_walking_margin": min(r["walking_margin"] for r in joints.values())}


def test_default_ankle_stiffness_exceeds_m_g_h_per_ankle(default_capacity):
    ankle = default_capacity["joints"]["ankle_pitch"]
    # everything but the feet, its centre of mass ~0.64 m above the ankle axes, over two ankles
    assert 110 < ankle["gravity_stiffness_nm_per_rad"] < 125
    assert ankle["stiffness_zero_action_nm_per_rad"] >= ankle["gravity_stiffness_nm_per_rad"]
    levels = ankle["stiffness_nm_per_rad"]
    assert list(levels) == ["100", "200", "300", "400", "600"]
    assert all(b > a for a, b in zip(list(levels.values())[1:], list(levels.values())[2:]))  # co-contraction stiffens


def test_air_per_gait_cycle_at_the_walking_demand(default_capacity):
    """Each direction's pressure gives the joint's walking peak at mid-range against the band's
    low pressure, and the air is one fill of each muscle from that low pressure to it, at
    constant volume (kinematic: the contraction follows the angle only): V (p - p_low) in
    normal litres, 2 legs x muscles per direction; the joints sum to the robot's total."""
    from pamrun.physics.capacity import _static_torque_nm
    from pamrun.physics.muscle import MUSCLE_INNER_DIAMETER_M, muscle_volume_l

    m, body = MuscleConfig(), BodyConfig()
    drive = MuscleDrive(m, body)
    low = default_capacity["band_kpa"][1]
    total = 0.0
    for name, r in default_capacity["joints"].items():
        j = 5 + LEG_JOINTS.index(name)  # the left leg's joint (JOINTS: right leg first)
        mid = np.radians([0.5 * sum(WALKING_RANGE_DEG[name])])
        p_plus, p_minus = r["walking_pressures_kpa"]
        assert low < p_plus <= m.max_pressure_kpa and low < p_minus <= m.max_pressure_kpa
        assert _static_torque_nm(drive, j, mid, p_plus, low)[0] == pytest.approx(r["walking_demand_nm"], rel=1e-3)
        assert -_static_torque_nm(drive, j, mid, low, p_minus)[0] == pytest.approx(r["walking_demand_nm"], rel=1e-3)
        angles = np.zeros((1, 10))
        angles[0, j] = mid[0]
        c1, c2 = drive.coupling.static_contraction_pct(angles, np.full((1, 10, 2), low))[0, j]
        v1, v2 = (muscle_volume_l(c, m.nominal_length_m, MUSCLE_INNER_DIAMETER_M[m.size]) for c in (c1, c2))
        litres = (v1 * (p_plus - low) + v2 * (p_minus - low)) / 101.325 * 273.15 / 293.15
        assert r["air_per_cycle_nl"] == pytest.approx(2 * r["muscles_per_direction"] * litres, abs=1e-3)
        total += r["air_per_cycle_nl"]
    assert default_capacity["air_per_cycle_nl"] == pytest.approx(total, abs=1e-3)
    assert 10 < total < 50  # tens of normal litres per cycle (the pilot walker measured ~25 per stride)


def test_thesis_model_is_too_weak_and_has_no_stiffness():
    cap = analyse(thesis_muscle(), BodyConfig())
    assert cap["coupling"] == "thesis" and cap["band_kpa"] == [283.0, 141.0]
    for r in cap["joints"].values():
        assert r["walking_margin"] < 0.5
        assert abs(r["stiffness_zero_action_nm_per_rad"]) < 1e-9
        plus = np.asarray(r["envelope"]["band"]["plus_nm"])
        assert np.ptp(plus) < 1e-9  # the burst does not depend on the angle
    assert not cap["verdict"]["walking_margin_ok"] and not cap["verdict"]["ankle_stiffness_ok"]


def test_size_and_count_scale_the_torque():
    body = BodyConfig()
    angle = np.zeros((1, 10))
    pressure = np.broadcast_to([600.0, 10.0], (1, 10, 2))
    one = MuscleConfig(size="DMSP-20", count=JointCounts(1, 1, 1, 1, 1))
    base = MuscleDrive(one, body).static_torque_nm(angle, pressure)
    np.testing.assert_allclose(MuscleDrive(replace(one, size="DMSP-40"), body).static_torque_nm(angle, pressure),
                               4 * base)
    np.testing.assert_allclose(MuscleDrive(replace(one, size="DMSP-10"), body).static_torque_nm(angle, pressure),
                               0.42 * base)
    two_knees = MuscleDrive(replace(one, count=JointCounts(knee=2)), body).static_torque_nm(angle, pressure)
    knees = [2, 7]
    np.testing.assert_allclose(two_knees[0, knees], 2 * base[0, knees])
    # a longer muscle gets a proportionally larger automatic radius: more torque at the same %
    longer = MuscleDrive(replace(one, nominal_length_m=2 * one.nominal_length_m), body)
    np.testing.assert_allclose(longer.radius_m, 2 * MuscleDrive(one, body).radius_m)


def test_automatic_radius_stretches_to_the_minimum_and_no_further():
    muscle, body = MuscleConfig(), BodyConfig()
    drive = MuscleDrive(muscle, body)
    limits = np.deg2rad([[-45, 45], [-11.25, 22.5], [0, 90], [-45, 45], [-35, 25]])  # right leg
    neutral = np.deg2rad([0, 0, -5, 0, 0])
    for k in range(5):
        for angle in limits[k]:
            stretched = muscle.kinematic_rest_contraction_pct - abs(100 * drive.radius_m[k] * (angle - neutral[k])
                                                                   / muscle.nominal_length_m)
            assert stretched >= muscle.min_contraction_pct - 1e-9
    # the knee's farthest limit (90 deg flexion, 95 from neutral) is exactly at the minimum
    assert 9.0 - 100 * drive.radius_m[2] * np.deg2rad(95) / 0.30 == pytest.approx(-1.0)
    with pytest.raises(ConfigError, match="radius_mm.knee.*at most 18.1 mm"):
        MuscleDrive(replace(muscle, radius_mm=replace(muscle.radius_mm, knee=25.0)), body)
    smaller = MuscleDrive(replace(muscle, radius_mm=replace(muscle.radius_mm, knee=15.0)), body)
    assert smaller.radius_m[2] == pytest.approx(0.015)


def test_cli_refuses_an_over_stretching_radius_before_writing(tmp_path):
    proc = run_pamrun("capacity", "muscle.radius_mm.ankle_pitch=60", f"hydra.run.dir={tmp_path / 'x'}")
    assert proc.returncode != 0
    assert "muscle.radius_mm.ankle_pitch" in proc.stderr and "at most" in proc.stderr
    assert not (tmp_path / "x").exists()


def test_pamrun_capacity_writes_table_json_and_figure(tmp_path):
    out = tmp_path / "cap"
    proc = run_pamrun("capacity", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr
    data = json.loads((out / "capacity.json").read_text())
    assert data["verdict"]["walking_margin_ok"] and data["muscle"]["size"] == "DMSP-40"
    assert (out / "capacity.png").stat().st_size > 20_000
    assert "ankle_pitch" in proc.stdout and "covered with margin >= 1.5: yes" in " ".join(proc.stdout.split())
    assert f"about {data['air_per_cycle_nl']:.1f} normal litres per gait cycle" in " ".join(proc.stdout.split())
    proc = run_pamrun("capacity", "muscle=thesis", f"hydra.run.dir={tmp_path / 'thesis'}")
    assert proc.returncode == 0, proc.stderr
    assert "burst" in proc.stdout and "no (weakest" in " ".join(proc.stdout.split())


def test_linearised_actuation_matches_the_muscle_torque():
    """What MuJoCo applies at a later physics step equals the pair's own torque there (to
    first order), so the drive's linearisation is the muscle model, not an approximation of it."""
    env = PamWalkerEnv()
    env.reset(seed=0)
    m, d, drive = env.model, env.data, env.drive
    drive.set_action(np.linspace(-0.8, 0.8, 10))
    for _ in range(20):  # let the regulator lag settle a little, then freeze it
        drive.apply(m, d, env.qpos_idx, env.qvel_idx, 0.005)
    drive.apply(m, d, env.qpos_idx, env.qvel_idx, 0.005)
    d.qpos[env.qpos_idx] += np.deg2rad(0.3)  # a later physics step, 0.3 deg on
    d.qvel[env.qvel_idx] = 0.2
    mujoco.mj_forward(m, d)
    own = drive.torques_nm(d.qpos[env.qpos_idx], d.qvel[env.qvel_idx], 0.0)
    np.testing.assert_allclose(d.actuator_force, own, rtol=2e-3, atol=0.05)
    assert np.abs(own).max() > 50


def test_independent_command_sets_co_contraction():
    env = PamWalkerEnv(muscle={"command": "independent"})
    assert env.action_space.shape == (20,) and env.observation_space.shape == (53,)
    assert space_sizes({"command": "independent"}) == (53, 20) and space_sizes() == (43, 10)
    obs, _ = env.reset(seed=0)
    action = np.zeros(20, dtype=np.float32)
    action[6:8] = 1.0  # both muscles of the right knee to the top of the band
    for _ in range(12):  # 0.3 s: six regulator time constants
        obs, *_ = env.step(action)
    np.testing.assert_allclose(env.drive.pressure_kpa[3], [600.0, 600.0], rtol=1e-2)
    np.testing.assert_allclose(env.drive.pressure_kpa[0], [300.0, 300.0], rtol=1e-6)
    np.testing.assert_allclose(obs[33:], action)


def test_regulator_lag_delays_the_pressure():
    env = PamWalkerEnv()
    env.reset(seed=0)
    env.step(np.ones(10, dtype=np.float32))  # one control step, 25 ms, of a 50 ms lag
    expected = 300 + 300 * (1 - np.exp(-0.025 / 0.05))
    assert env.drive.pressure_kpa[0, 0] == pytest.approx(expected, rel=1e-6)


@pytest.mark.parametrize("seed, noise", [(0, 0.0), (3, 0.02)])
def test_default_robot_stands_ten_seconds_with_zero_action(seed, noise):
    env = PamWalkerEnv(env={"reset_noise_rad": noise})
    env.reset(seed=seed)
    for _ in range(env.max_steps):
        _, _, terminated, truncated, info = env.step(np.zeros(10, dtype=np.float32))
        assert not terminated
    assert truncated and abs(info["x"]) < 0.1 and info["z"] > 0.95 * env.z0


def test_thesis_robot_falls_with_zero_action():
    env = PamWalkerEnv(muscle=thesis_muscle())
    env.reset(seed=0)
    for step in range(env.max_steps):
        _, _, terminated, _, _ = env.step(np.zeros(10, dtype=np.float32))
        if terminated:
            break
    assert terminated and step < 120


def test_openloop_default_reaches_all_nine_limits(tmp_path):
    out = tmp_path / "ol"
    proc = run_pamrun("openloop", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr
    moves = json.loads((out / "openloop.json").read_text())["movements"]
    errors = {name: r["error_deg"] for name, r in moves.items()}
    assert all(abs(e) <= 2.0 for e in errors.values()), errors


def test_configs_saved_before_sizing_keep_their_robot():
    old = {"muscle": {"v0_v": 2.12, "dv_max_v": 0.71, "coupling": "kinematic", "nominal_length_m": 0.26,
                      "max_pressure_kpa": 800.0, "kinematic_rest_contraction_pct": 6.5,
                      "kinematic_max_contraction_pct": 13.0, "regulator": {"lag_s": 0.0}}}
    muscle = MuscleConfig(**{k: v for k, v in upgrade_saved_config(old)["muscle"].items()
                             if k not in ("count", "regulator", "neutral_deg")})
    upgraded = upgrade_saved_config(old)["muscle"]
    assert upgraded["size"] == "DMSP-20" and upgraded["command"] == "antagonistic"
    assert upgraded["min_contraction_pct"] == 0.0 and "kinematic_max_contraction_pct" not in upgraded
    assert set(upgraded["count"].values()) == {1} and set(upgraded["neutral_deg"].values()) == {0.0}
    env = PamWalkerEnv(muscle=upgraded)
    np.testing.assert_allclose(env.drive.radius_m[:5], [0.0215, 0.0430, 0.0108, 0.0215, 0.0277], atol=1e-4)
    assert muscle.force_scale == 1.0
