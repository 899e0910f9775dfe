"""Gait and air metrics on constructed motion (no MuJoCo): every expected number is worked
out by hand from the construction, not recomputed with pamrun's code."""

from __future__ import annotations

import math

import numpy as np
import pytest
from rich.console import Console

from pamrun.config import BodyConfig, EvalConfig, MuscleConfig
from pamrun.evaluation import figures
from pamrun.evaluation.episodes import aggregate
from pamrun.evaluation.metrics import (
    GAIT_METRICS,
    GaitSpec,
    contacts,
    episode_metrics,
    gait_cycle,
    touchdowns,
)
from pamrun.evaluation.tables import targets_table
from pamrun.evaluation.targets import WALK_TARGETS, met
from pamrun.physics.body import JOINTS
from pamrun.physics.muscle import air_nl, muscle_volume_l

DT = 0.025
L0, D0 = 0.26, 0.020  # a DMSP-20-260
V0_L = math.pi * D0**2 * L0 / 4 * 1000  # cylinder of the nominal state [litres] = 0.0816814...
LIMITS = np.tile([-0.5, 0.5], (10, 1))  # every joint: +-0.5 rad


def spec(**kw) -> GaitSpec:
    args = dict(dt_s=DT, joint_limits_rad=LIMITS, mass_kg=40.0, muscles_per_side=np.ones(10),
                nominal_length_m=L0, inner_diameter_m=D0, gravity_m_s2=9.81)
    return GaitSpec(**{**args, **kw})


def still(n: int, **arrays) -> dict:
    """n rows of a robot standing still on both feet, mid-range joints; ``arrays`` replace."""
    steps = {
        "t_s": np.arange(1, n + 1) * DT,
        "x_m": np.zeros(n), "y_m": np.zeros(n), "z_m": np.ones(n),
        "joint_angle_rad": np.zeros((n, 10)),
        "joint_velocity_rad_s": np.zeros((n, 10)),
        "joint_torque_nm": np.zeros((n, 10)),
        "pressure_kpa": np.full((n, 20), 300.0),
        "contraction_pct": np.full((n, 20), 9.0),
        "foot_force_n": np.full((n, 2), 200.0),
        "foot_xyz_m": np.zeros((n, 2, 3)),
    }
    steps.update(arrays)
    return steps


def walk(n: int, stride_rows: int, left_offset_rows: int, stance_rows: int, right_len_m: float,
         left_len_m: float) -> dict:
    """Right foot down for ``stance_rows`` from each row i with i % stride_rows == 0, the left
    from each i with (i - left_offset_rows) % stride_rows == 0; a foot lands (instantly)
    ``*_len_m`` ahead of the other and stays put while down."""
    down = np.zeros((n, 2), bool)
    i = np.arange(n)
    down[:, 0] = i % stride_rows < stance_rows
    down[:, 1] = (i - left_offset_rows) % stride_rows < stance_rows
    feet = np.zeros((n, 2, 3))
    x = [0.0, 0.0]
    for row in range(n):
        for foot, length in ((0, right_len_m), (1, left_len_m)):
            if row > 0 and down[row, foot] and not down[row - 1, foot]:
                x[foot] = x[1 - foot] + length
        feet[row, :, 0] = x
    return still(n, foot_force_n=np.where(down, 300.0, 0.0), foot_xyz_m=feet,
                 x_m=np.arange(n) * DT * 0.8)


# --------------------------------------------------------------------------- spec


def test_spec_from_configs():
    s = GaitSpec.from_configs(BodyConfig(), MuscleConfig(size="DMSP-20"), mass_kg=37.0, dt_s=DT)
    assert s.muscles_per_side.tolist() == [1, 1, 2, 2, 1] * 2  # JointCounts defaults
    assert s.inner_diameter_m == 0.020 and s.nominal_length_m == 0.30
    assert s.contact_threshold_n == pytest.approx(0.05 * 37.0 * 9.81)
    assert s.stop_margin_rad == pytest.approx(math.pi / 90)
    right_hip_roll, left_hip_roll = s.joint_limits_rad[1], s.joint_limits_rad[6]
    assert np.rad2deg(left_hip_roll) == pytest.approx([-22.5, 11.25])
    assert np.rad2deg(right_hip_roll) == pytest.approx([-11.25, 22.5])  # mirrored
    assert GaitSpec.from_configs(BodyConfig(), MuscleConfig(), 37.0, DT).inner_diameter_m == 0.040


# --------------------------------------------------------------------------- steps


def test_touchdown_reach_is_the_landing_foots_distance_ahead_of_the_torso():
    # the constructed walk covers 0.4 m per step in 20 rows at 0.8 m/s: at each touchdown the torso
    # is where the landing foot lands (a foot under the hip); 0.25 m further back, 0.25 m behind it
    steps = walk(200, 40, 20, 24, 0.4, 0.4)
    assert episode_metrics(steps, spec())["touchdown_reach_m"] == pytest.approx(0.0, abs=1e-9)
    steps["x_m"] = steps["x_m"] - 0.25
    assert episode_metrics(steps, spec())["touchdown_reach_m"] == pytest.approx(0.25, abs=1e-9)
    assert math.isnan(episode_metrics(still(100), spec())["touchdown_reach_m"])


def test_mirrored_gait_is_symmetric_with_the_constructed_frequency_and_length():
    # stride 40 rows = 1 s, left half a stride later: a step every 0.5 s, 0.4 m long
    m = episode_metrics(walk(200, 40, 20, 24, 0.4, 0.4), spec())
    assert set(m) == set(GAIT_METRICS)
    assert m["step_count"] == 9  # right lands at rows 40, 80, 120, 160; left at 20, 60, ..., 180
    assert m["step_frequency_hz"] == pytest.approx(2.0, abs=1e-9)
    assert m["step_length_m"] == pytest.approx(0.4, abs=1e-12)
    assert m["stride_length_m"] == pytest.approx(0.8, abs=1e-12)  # each foot moves two steps per stride
    assert m["step_time_symmetry"] == pytest.approx(0.0, abs=1e-9)
    assert m["step_length_symmetry"] == pytest.approx(0.0, abs=1e-9)
    assert m["duty_factor"] == pytest.approx(0.6, abs=1e-12)  # 24 of every 40 rows, both feet
    assert m["foot_slip_m_s"] == 0.0  # planted while down


def test_asymmetric_gait_gives_the_constructed_index():
    # stride 32 rows = 0.8 s: left lands 12 rows (0.3 s) after the right, right 20 rows (0.5 s)
    # after the left; right steps 0.5 m, left 0.3 m -> both indices |0.3 - 0.5| / 0.4 = 0.5
    m = episode_metrics(walk(320, 32, 12, 22, 0.5, 0.3), spec())
    assert m["step_time_symmetry"] == pytest.approx(0.5, abs=1e-9)
    assert m["step_length_symmetry"] == pytest.approx(0.5, abs=1e-9)
    assert m["step_length_m"] == pytest.approx((9 * 0.5 + 10 * 0.3) / 19)  # 9 right, 10 left steps
    assert m["step_frequency_hz"] == pytest.approx(18 / ((300 - 12) * DT))  # 19 steps, rows 12..300
    assert m["duty_factor"] == pytest.approx(22 / 32)


def test_a_gallop_is_maximally_asymmetric_in_step_length():
    """The left foot always lands 0.26 m behind the right, the right 0.3 m ahead of the left:
    signed step lengths +0.3 and -0.26, symmetry index 2 (the signs differ), stride 0.04 m."""
    n, stride = 200, 20
    i = np.arange(n)
    down = np.stack([i % stride < 4, (i - 5) % stride < 4], axis=1)
    cycles = i // stride
    right_x = 0.04 * cycles + 0.3  # the right foot lands 0.3 m ahead of the left ...
    left_x = 0.04 * np.where(i % stride >= 5, cycles, cycles - 1) + 0.04  # ... which lands 0.26 m behind it
    feet = np.zeros((n, 2, 3))
    feet[:, 0, 0], feet[:, 1, 0] = right_x, left_x
    m = episode_metrics(still(n, foot_force_n=np.where(down, 300.0, 0.0), foot_xyz_m=feet), spec())
    assert m["step_length_symmetry"] == pytest.approx(2.0)
    assert m["stride_length_m"] == pytest.approx(0.04)


def test_hop_share_tells_hops_from_steps():
    """Feet landing in the same row or one row apart (25 ms) are a hop; three rows (75 ms) or half
    a stride apart, steps; hops in alternate 40-row blocks: the touchdowns in those blocks."""
    assert episode_metrics(walk(200, 40, 20, 24, 0.4, 0.4), spec())["hop_share"] == 0.0
    assert episode_metrics(walk(200, 40, 0, 24, 0.0, 0.0), spec())["hop_share"] == 1.0
    # one row apart: 8 of 9 (the left's touchdown at row 1 has no partner: the right starts down)
    assert episode_metrics(walk(200, 40, 1, 24, 0.0, 0.0), spec())["hop_share"] == pytest.approx(8 / 9)
    assert episode_metrics(walk(200, 40, 3, 24, 0.0, 0.0), spec())["hop_share"] == 0.0  # 75 ms apart
    n, i = 160, np.arange(160)
    down = np.stack([i % 20 < 8, np.where(i // 40 % 2 == 0, i % 20, (i - 10) % 20) < 8], axis=1)
    m = episode_metrics(still(n, foot_force_n=np.where(down, 300.0, 0.0)), spec())
    assert m["hop_share"] == pytest.approx(6 / 14)  # together at rows 20, 80 and 100 (both feet)
    assert math.isnan(episode_metrics(still(20), spec())["hop_share"])  # no touchdown


def test_retouch_share_counts_split_stances():
    """Alternating feet: 0. The right stance split by a 3-row (75 ms) lift in each 40-row stride: the
    right foot touches down twice running in 3 of the 10 pairs of touchdowns (its first touchdown
    is row 11: it starts down). A 1-row flicker is no lift: 0."""
    assert episode_metrics(walk(200, 40, 20, 24, 0.4, 0.4), spec())["retouch_share"] == 0.0
    i = np.arange(160)

    def split(lift_rows: int) -> float:
        right = (i % 40 < 24) & ~((i % 40 >= 8) & (i % 40 < 8 + lift_rows))
        left = (i - 20) % 40 < 24
        down = np.stack([right, left], axis=1)
        return episode_metrics(still(160, foot_force_n=np.where(down, 300.0, 0.0)), spec())["retouch_share"]

    assert split(3) == pytest.approx(3 / 10)
    assert split(1) == 0.0
    assert math.isnan(episode_metrics(still(20), spec())["retouch_share"])


def test_touchdowns_are_rising_edges_only():
    force = np.array([[300, 0], [300, 0], [0, 300], [300, 300], [300, 0], [0, 0], [300, 300]], float)
    down = contacts({"foot_force_n": force}, spec(contact_threshold_n=10.0))
    right, left = touchdowns(down)
    assert right.tolist() == [3, 6] and left.tolist() == [2, 6]  # row 0 is no touchdown


def test_contact_threshold_defaults_to_five_percent_of_weight():
    s = spec()
    assert s.contact_threshold_n == pytest.approx(0.05 * 40 * 9.81)  # 19.62 N
    down = contacts({"foot_force_n": [[19.0, 20.0]]}, s)
    assert down.tolist() == [[False, True]]


def test_too_few_steps_give_nan_not_an_error():
    m = episode_metrics(still(10), spec())  # both feet down throughout: no touchdown
    assert m["step_count"] == 0
    for key in ("step_frequency_hz", "step_length_m", "stride_length_m", "step_time_symmetry", "step_length_symmetry",
                "cost_of_transport", "air_nl_per_m"):
        assert math.isnan(m[key]), key
    assert m["duty_factor"] == 1.0 and m["air_nl"] == 0.0
    one = walk(30, 40, 20, 10, 0.4, 0.4)  # a single touchdown, of the left foot at row 20
    m = episode_metrics(one, spec())
    assert m["step_count"] == 1 and m["step_length_m"] == pytest.approx(0.4)
    assert math.isnan(m["step_frequency_hz"]) and math.isnan(m["step_time_symmetry"])
    assert all(math.isnan(v) for v in episode_metrics(still(0), spec()).values())


# --------------------------------------------------------------------------- stops


def test_stop_shares():
    n = 40
    q = np.zeros((n, 10))
    q[:, 2] = -0.5  # right knee held at its lower stop
    q[:, 3] = 0.5 + 0.01  # right ankle pitch pressed 0.6 deg past its upper stop
    q[:, 4] = 0.5 - math.radians(1.0)  # within the 2 deg margin
    q[:, 6] = 0.5 - math.radians(3.0)  # outside it
    q[::2, 7] = 0.5  # left knee at the stop every other row
    m = episode_metrics(still(n, joint_angle_rad=q), spec())
    expected = {"right_knee": 1.0, "right_ankle_pitch": 1.0, "right_ankle_roll": 1.0, "left_knee": 0.5}
    for joint in JOINTS:
        assert m[f"stop_share_{joint}"] == expected.get(joint, 0.0), joint
    assert m["stop_share_max"] == 1.0


def test_knee_stop_counts_in_swing_only():
    """A knee locked at its stop in stance is by design; straight in swing it counts: the right
    knee straight throughout, the left bent in swing: knee swing stop share = the right foot's
    swing rows over all swing rows; the gait maximum ignores the knees' stance rows."""
    steps = walk(60, 20, 10, 12, 0.4, 0.4)
    down = steps["foot_force_n"] > 0
    q = np.zeros((60, 10))
    q[:, 2] = -0.5  # right knee on its stop, stance and swing
    q[:, 7] = np.where(down[:, 1], -0.5, -0.2)  # left knee on its stop in stance, bent in swing
    q[:, 0] = np.where(np.arange(60) < 15, 0.5, 0.0)  # right hip pitch at a stop in 15 of 60 rows
    steps["joint_angle_rad"] = q
    m = episode_metrics(steps, spec())
    swing = ~down
    assert m["knee_swing_stop_share"] == pytest.approx(swing[:, 0].sum() / swing.sum())
    assert m["stop_share_right_knee"] == 1.0 and m["stop_share_max"] == 1.0
    assert m["stop_share_gait_max"] == pytest.approx(max(0.25, m["knee_swing_stop_share"]))
    assert 0.25 < m["stop_share_gait_max"] < 1.0


def test_swing_clearance_is_the_mean_peak_lift_of_complete_swings():
    """The right foot lifts 0.06 m at the top of each swing, the left 0.02 m; the ground sits
    at 0.03 m (the contact spheres' centres): clearance is the mean of the peaks above it, and a
    swing the episode ends in does not count."""
    steps = walk(70, 20, 10, 12, 0.4, 0.4)  # the last rows cut a swing short
    down = steps["foot_force_n"] > 0
    feet = steps["foot_xyz_m"].copy()
    feet[..., 2] = 0.03
    for foot, peak in ((0, 0.06), (1, 0.02)):
        rows = np.flatnonzero(~down[:, foot])
        feet[rows, foot, 2] += peak * np.sin(np.pi * ((rows % 20) / 20))  # under the peak in the swing's rows
        feet[rows[rows % 20 == 16] if foot == 0 else rows[(rows - 10) % 20 == 16], foot, 2] = 0.03 + peak
    feet[66:, 1, 2] = 0.5  # the left foot's last swing (rows 62-69) never lands: not counted
    steps["foot_xyz_m"] = feet
    m = episode_metrics(steps, spec())
    assert m["swing_clearance_m"] == pytest.approx(0.04, abs=1e-9)
    assert math.isnan(episode_metrics(still(10), spec())["swing_clearance_m"])


# --------------------------------------------------------------------------- slip


def test_foot_slip():
    n = 20
    t = np.arange(1, n + 1) * DT
    sliding = np.zeros((n, 2, 3))
    sliding[:, 0, 0] = 0.3 * t  # right foot slides at 0.3 m/s in x, left planted
    sliding[:, 1, 0] = 0.3 * t  # ... and the left as well
    assert episode_metrics(still(n, foot_xyz_m=sliding), spec())["foot_slip_m_s"] == pytest.approx(0.3)
    diagonal = np.zeros((n, 2, 3))
    diagonal[:, :, 0], diagonal[:, :, 1] = (0.3 * t)[:, None], (0.4 * t)[:, None]
    diagonal[:, :, 2] = (5.0 * t)[:, None]  # vertical motion is no slip
    assert episode_metrics(still(n, foot_xyz_m=diagonal), spec())["foot_slip_m_s"] == pytest.approx(0.5)
    assert episode_metrics(still(n), spec())["foot_slip_m_s"] == 0.0  # planted
    swinging = np.zeros((n, 2, 3))
    swinging[:, 1, 0] = 1.0 * t  # the left foot moves, but in the air
    force = np.tile([300.0, 0.0], (n, 1))
    m = episode_metrics(still(n, foot_xyz_m=swinging, foot_force_n=force), spec())
    assert m["foot_slip_m_s"] == 0.0


# --------------------------------------------------------------------------- cost of transport


def test_cost_of_transport():
    n = 41
    torque, velocity = np.zeros((n, 10)), np.zeros((n, 10))
    torque[:, 0], velocity[:, 0] = 10.0, 2.0  # 20 W
    torque[:, 6], velocity[:, 6] = -5.0, 2.0  # -10 W of braking counts as 10 W
    x = 0.5 * np.arange(n) * DT  # 0.5 m/s: 0.5 m over the 40 control steps
    m = episode_metrics(still(n, joint_torque_nm=torque, joint_velocity_rad_s=velocity, x_m=x), spec())
    assert m["cost_of_transport"] == pytest.approx(30.0 / (40.0 * 9.81 * 0.5))  # P / (m g v) = 0.15291
    backwards = still(n, joint_torque_nm=torque, joint_velocity_rad_s=velocity, x_m=-x)
    assert math.isnan(episode_metrics(backwards, spec())["cost_of_transport"])


# --------------------------------------------------------------------------- volume and air


def test_volume_model():
    assert muscle_volume_l(0.0, L0, D0) == pytest.approx(V0_L, rel=1e-12)
    assert muscle_volume_l(0.0, 0.30, 0.040) == pytest.approx(math.pi * 0.04**2 * 0.30 / 4 * 1000, rel=1e-12)
    # b = sqrt(3) 0.75 L0 -> V / V0 = (1 - e) (1.6875 - (1 - e)^2) / 0.6875; at e = 0.25: 27/22
    assert muscle_volume_l(25.0, L0, D0) == pytest.approx(V0_L * 27 / 22, rel=1e-12)
    assert muscle_volume_l(10.0, L0, D0) == pytest.approx(V0_L * 0.9 * (1.6875 - 0.81) / 0.6875, rel=1e-12)
    c = np.linspace(-3.0, 25.0, 57)
    v = muscle_volume_l(c, L0, D0)
    assert v.shape == c.shape and np.all(np.diff(v) > 0)  # grows with contraction up to 25 %
    assert muscle_volume_l(30.0, L0, D0) == pytest.approx(V0_L * 27 / 22)  # clipped at the stroke


def test_air_of_a_known_fill():
    p = np.full((2, 20), 100.0)
    p[1, 0] = 500.0  # muscle 1 of joint 0 filled from 100 to 500 kPa at 0 % contraction
    c = np.zeros((2, 20))
    expected = V0_L * 400.0 / 101.325 * 273.15 / 293.15  # 0.3005 Nl: air at 20 degC, in DIN 1343 normal litres
    assert air_nl(p, c, L0, D0) == pytest.approx(expected, rel=1e-12)
    assert air_nl(p, c, L0, D0, temperature_k=273.15) == pytest.approx(V0_L * 400.0 / 101.325, rel=1e-12)
    assert air_nl(p[::-1], c, L0, D0) == 0.0  # exhausting draws nothing
    counts = np.ones(10)
    counts[0] = 3  # three muscles in parallel on joint 0
    assert air_nl(p, c, L0, D0, counts) == pytest.approx(3 * expected, rel=1e-12)
    cycle = np.full((4, 20), 100.0)
    cycle[:, 5] = [100.0, 500.0, 100.0, 500.0]  # fill, exhaust, fill: two fills
    assert air_nl(cycle, np.zeros((4, 20)), L0, D0) == pytest.approx(2 * expected, rel=1e-12)
    # contracting 0 -> 25 % at a constant 200 kPa gauge draws (200 + 101.325) kPa x (27/22 - 1) V0
    c2 = np.zeros((2, 20))
    c2[1, 3] = 25.0
    drawn = air_nl(np.full((2, 20), 200.0), c2, L0, D0)
    assert drawn == pytest.approx(301.325 * V0_L * 5 / 22 / 101.325 * 273.15 / 293.15, rel=1e-12)


def test_air_in_the_episode_metrics():
    n = 41
    p = np.full((n, 20), 100.0)
    p[20:, 0] = 500.0
    x = 0.5 * np.arange(n) * DT  # 0.5 m walked
    counts = np.full(10, 2.0)
    m = episode_metrics(still(n, pressure_kpa=p, contraction_pct=np.zeros((n, 20)), x_m=x),
                        spec(muscles_per_side=counts))
    assert m["air_nl"] == pytest.approx(2 * V0_L * 400.0 / 101.325 * 273.15 / 293.15)
    assert m["air_nl_per_m"] == pytest.approx(m["air_nl"] / 0.5)


# --------------------------------------------------------------------------- cycle and figure


def test_gait_cycle_resamples_each_stride():
    values = np.concatenate([np.linspace(0, 1, 11), np.linspace(1, 3, 21)[1:]])  # rows 0..30
    grid, strides = gait_cycle(values[:, None], [0, 10, 30], points=5)
    assert grid.tolist() == [0, 25, 50, 75, 100]
    assert strides.shape == (2, 5, 1)
    assert strides[0, :, 0] == pytest.approx([0, 0.25, 0.5, 0.75, 1.0])
    assert strides[1, :, 0] == pytest.approx([1, 1.5, 2, 2.5, 3])
    assert gait_cycle(values[:, None], [4])[1].shape == (0, 101, 1)


def test_gait_figure(tmp_path):
    walking = {"agent": "a", "episode": 0, "seed": 1, "steps": walk(200, 40, 20, 24, 0.4, 0.4)}
    fallen = {"agent": "a", "episode": 1, "seed": 2, "steps": still(10)}  # fell at 0.25 s: no touchdown
    lifted = {"agent": "a", "episode": 2, "seed": 3, "steps": still(10, foot_force_n=np.zeros((10, 2)))}
    listed = {"agent": "a", "episode": 3, "seed": 4,  # as read from episodes.jsonl
              "steps": {k: np.asarray(v).tolist() for k, v in walking["steps"].items()}}
    for name, episodes in (("walk", [walking, fallen, listed]), ("fallen", [fallen]), ("lifted", [lifted])):
        png = figures.gait(episodes, LIMITS, 20.0, tmp_path / f"{name}.png")
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 10_000, name


def test_a_foot_rolling_over_its_toe_does_not_slip_but_a_sliding_toe_does():
    """Four sole points: the foot pitches up about its front edge (the heel rises and moves),
    so its centre moves but the point on the ground does not; then the same roll while the
    toe slides at 0.3 m/s."""
    n, length = 20, 0.25
    angle = np.linspace(0.0, 0.8, n)  # heel lifted from 0 to 0.8 rad
    soles = np.zeros((n, 2, 4, 3))
    for foot in (0, 1):
        soles[:, foot, :2, 0] = length  # front points: at x = length, on the ground
        soles[:, foot, 2:, 0] = (length - length * np.cos(angle))[:, None]  # back points swing up and forward
        soles[:, foot, 2:, 2] = (length * np.sin(angle))[:, None]
    steps = still(n)
    steps.pop("foot_xyz_m")
    assert episode_metrics({**steps, "sole_xyz_m": soles}, spec())["foot_slip_m_s"] == pytest.approx(0.0, abs=1e-12)
    sliding = soles.copy()
    sliding[..., 0] += (0.3 * np.arange(n) * DT)[:, None, None]
    assert episode_metrics({**steps, "sole_xyz_m": sliding}, spec())["foot_slip_m_s"] == pytest.approx(0.3)


def tilted_soles(n: int, roll_rad: float, heading_rad: float = 0.0, pitch_rad: float = 0.0) -> np.ndarray:
    """(n, 2, 4, 3) sole corners (front left, front right, back left, back right) of two 0.25 x 0.1 m
    feet, each pitched ``pitch_rad`` about its lateral axis (toe down: rolling heel to toe), that axis
    then tilted ``roll_rad`` from the horizontal (left edge up), and the foot turned ``heading_rad``
    about the vertical."""
    corners = np.array([[0.125, 0.05, 0.0], [0.125, -0.05, 0.0], [-0.125, 0.05, 0.0], [-0.125, -0.05, 0.0]])
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    roll = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    c, s = math.cos(pitch_rad), math.sin(pitch_rad)
    pitch = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    c, s = math.cos(heading_rad), math.sin(heading_rad)
    yaw = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    foot = corners @ (yaw @ roll @ pitch).T
    return np.broadcast_to(foot, (n, 2, 4, 3)).copy()


def test_torso_pitch_is_its_mean_after_the_first_second():
    """torso_pitch_deg: the torso's pitch averaged over the rows after the first second (the start
    left out), in degrees; NaN for an episode recorded without the torso's orientation."""
    n = 80  # 2 s
    rpy = np.zeros((n, 3))
    rpy[:, 1] = np.where(np.arange(1, n + 1) * DT > 1.0 + 1e-9, math.radians(10.0), math.radians(40.0))
    rpy[:, 0], rpy[:, 2] = 0.3, -1.0  # roll and heading do not count
    assert episode_metrics(still(n, torso_rpy_rad=rpy), spec())["torso_pitch_deg"] == pytest.approx(10.0)
    assert math.isnan(episode_metrics(still(n), spec())["torso_pitch_deg"])


def test_torso_sway_is_how_far_its_roll_rocks_after_the_first_second():
    """torso_sway_deg: a torso rolling +-7 deg at a step's rhythm reads 7 deg (half its 5-95 % range),
    whatever its mean lean; the first second and a still torso read nothing; NaN without the torso's
    orientation."""
    n = 200  # 5 s
    t = np.arange(1, n + 1) * DT
    rpy = np.zeros((n, 3))
    rpy[:, 0] = np.where(t > 1.0 + 1e-9, math.radians(7.0) * np.sign(np.sin(2 * math.pi * 0.8 * t)), math.radians(30.0))
    rpy[:, 1] = math.radians(5.0)
    assert episode_metrics(still(n, torso_rpy_rad=rpy), spec())["torso_sway_deg"] == pytest.approx(7.0)
    rpy[:, 0] = math.radians(3.0)
    assert episode_metrics(still(n, torso_rpy_rad=rpy), spec())["torso_sway_deg"] == pytest.approx(0.0)
    assert math.isnan(episode_metrics(still(n), spec())["torso_sway_deg"])


def test_sole_tilt_is_the_side_to_side_angle_of_a_foot_on_the_ground():
    """A sole rolled 10 deg onto its edge reads 10 deg whatever its heading and its pitch (a foot
    rolling heel to toe is not on its edge); flat, 0; a tilted foot off the ground is not counted;
    one point per foot has no tilt to give."""
    n = 20
    steps = still(n)
    steps.pop("foot_xyz_m")
    flat = {**steps, "sole_xyz_m": tilted_soles(n, 0.0, heading_rad=0.7, pitch_rad=0.3)}
    assert episode_metrics(flat, spec())["sole_tilt_deg"] == pytest.approx(0.0, abs=1e-9)
    on_edge = {**steps, "sole_xyz_m": tilted_soles(n, math.radians(-10.0), heading_rad=0.7, pitch_rad=0.3)}
    assert episode_metrics(on_edge, spec())["sole_tilt_deg"] == pytest.approx(10.0)
    soles = tilted_soles(n, 0.0)
    soles[:, 1] = tilted_soles(n, math.radians(30.0))[:, 1]  # the left foot tilted 30 deg, but in the air
    lifted = {**steps, "sole_xyz_m": soles, "foot_force_n": np.tile([300.0, 0.0], (n, 1))}
    assert episode_metrics(lifted, spec())["sole_tilt_deg"] == pytest.approx(0.0, abs=1e-9)
    assert math.isnan(episode_metrics(still(n), spec())["sole_tilt_deg"])


# --------------------------------------------------------------------------- support and knee phases

KNEE_LIMITS = LIMITS.copy()
KNEE_LIMITS[[2, 7]] = [0.0, math.pi / 2]  # the knees: straight at their lower stop, 90 deg at the upper


def bent_knees(down: np.ndarray, stance_deg: tuple[float, float], swing_deg: tuple[float, float]) -> np.ndarray:
    """Joint angles (n, 10) [rad]: in the k-th row of each run of a foot's rows in contact (off the
    ground) of length r, its knee bends stance_deg (swing_deg) of the foot x sin(pi (k + 1) / (r + 1)),
    the full value in the middle row of an odd run."""
    q = np.zeros((len(down), 10))
    for foot, knee in ((0, 2), (1, 7)):
        start = 0
        for row in range(1, len(down) + 1):
            if row == len(down) or down[row, foot] != down[start, foot]:
                peak = (stance_deg if down[start, foot] else swing_deg)[foot]
                r = row - start
                q[start:row, knee] = np.radians(peak) * np.sin(np.pi * (np.arange(r) + 1) / (r + 1))
                start = row
    return q


def test_double_support_and_flight_are_shares_of_the_time_after_the_first_second():
    # stride 40 rows, each foot down 24 of them, the left half a stride after the right: both down
    # in rows 0-3 and 20-23 of each stride, 8 of 40 = 20 %, never both off
    m = episode_metrics(walk(200, 40, 20, 24, 0.4, 0.4), spec())
    assert m["double_support_share"] == pytest.approx(0.2, abs=1e-12)
    assert m["flight_share"] == 0.0
    # each foot down 18 of 40 rows: both off in rows 18-19 and 38-39, 4 of 40 = 10 %
    running = walk(200, 40, 20, 18, 0.4, 0.4)
    m = episode_metrics(running, spec())
    assert m["double_support_share"] == 0.0 and m["flight_share"] == pytest.approx(0.1, abs=1e-12)
    running["foot_force_n"][:40] = 300.0  # standing through the first second (rows 0-39): not counted
    assert episode_metrics(running, spec())["flight_share"] == pytest.approx(0.1, abs=1e-12)
    running["foot_force_n"][:41] = 300.0  # ... but the row ending at 1.025 s is
    assert episode_metrics(running, spec())["double_support_share"] == pytest.approx(1 / 160, abs=1e-12)
    for key in ("double_support_share", "flight_share"):
        assert math.isnan(episode_metrics(still(40), spec())[key])  # 1 s long: nothing after the first second
    assert episode_metrics(still(41), spec())["double_support_share"] == 1.0


def test_knee_at_mid_stance_and_its_peak_in_swing():
    """Stances of 23 rows and swings of 17: the right knee straight in stance, the left bent 10
    deg at mid-stance; both peak at 60 deg in swing. The phases the episode starts or ends in
    (bent 30 and 90 deg here) and those beginning in its first second (a swing peaking at 30
    deg) do not count."""
    steps = walk(210, 40, 20, 23, 0.4, 0.4)  # ends in a right stance (rows 200-209) and a left swing (203-209)
    down = steps["foot_force_n"] > 0
    q = bent_knees(down, stance_deg=(0.0, 10.0), swing_deg=(60.0, 60.0))
    q[:23, 2] = q[200:, 2] = np.radians(30.0)  # the right foot's first and last stances: no touchdown, no lift-off
    q[203:, 7] = np.radians(90.0)  # the left foot's last swing: no touchdown
    q[3:20, 7] *= 0.5  # the left foot's first swing (rows 3-19), in the first second
    steps["joint_angle_rad"] = q
    m = episode_metrics(steps, spec(joint_limits_rad=KNEE_LIMITS))
    # right stances from rows 40, 80, 120, 160 (0 deg), left from 60, ..., 180 (10 deg; the one from
    # row 20 begins at 0.525 s): (4 x 0 + 4 x 10) / 8
    assert m["knee_midstance_deg"] == pytest.approx(5.0, abs=1e-9)
    assert m["knee_swing_peak_deg"] == pytest.approx(60.0, abs=1e-9)
    q[:, [2, 7]] = np.where(down, np.radians(-3.0), q[:, [2, 7]])  # stance knees pressed past their stop
    assert episode_metrics(steps, spec(joint_limits_rad=KNEE_LIMITS))["knee_midstance_deg"] == 0.0
    # the flexion counts from the stop: with the knee's stop at -0.5 rad, -3 deg is 25.6 deg bent
    assert episode_metrics(steps, spec())["knee_midstance_deg"] == pytest.approx(math.degrees(0.5) - 3.0, abs=1e-9)


def test_stance_hip_extension_and_hip_at_touchdown():
    """Each stance's hip extends from -25 deg at its touchdown straight to +15 deg at its lift-off (the
    right hip 15, the left 5 at their most): the metric is (4 x 15 + 4 x 5) / 8 = 10 over the stances
    that begin after the first second. The swings' hips, extended 30 deg, do not count, nor does the
    right's first stance (no touchdown) held at 40."""
    steps = walk(210, 40, 20, 23, 0.4, 0.4)
    down = steps["foot_force_n"] > 0
    q = np.zeros((len(down), 10))
    for foot, hip, top in ((0, 0, 15.0), (1, 5, 5.0)):
        start = 0
        for row in range(1, len(down) + 1):
            if row == len(down) or down[row, foot] != down[start, foot]:
                ramp = np.linspace(-25.0, top, row - start)
                q[start:row, hip] = np.radians(ramp if down[start, foot] else np.full(row - start, 30.0))
                start = row
    q[:23, 0] = np.radians(40.0)
    steps["joint_angle_rad"] = q
    m = episode_metrics(steps, spec())
    assert m["hip_extension_deg"] == pytest.approx(10.0, abs=1e-9)
    assert m["hip_touchdown_deg"] == pytest.approx(25.0, abs=1e-9)  # each landing row: -25 deg of pitch, 25 of flexion
    assert math.isnan(episode_metrics(still(100), spec())["hip_extension_deg"])


def test_swing_hip_peak_reads_each_swings_largest_flexion():
    """Each swing's hip flexes on a half sine to 35 deg (right) and 25 deg (left) in its middle row and is
    back to 0 as the foot lands: the swing peak is (4 x 35 + 4 x 25) / 8 = 30 over the swings that begin
    after the first second, while the hip at touchdown reads 0 (the leg pulled back before it landed).
    The first second's swings, flexed twice as far, do not count; nor do the stances, flexed 40 deg after
    their touchdown row."""
    steps = walk(210, 40, 20, 23, 0.4, 0.4)
    down = steps["foot_force_n"] > 0
    swing_flexion = bent_knees(down, stance_deg=(0.0, 0.0), swing_deg=(35.0, 25.0))[:, [2, 7]]
    swing_flexion[:40] *= 2.0
    q = np.zeros((len(down), 10))
    q[:, [0, 5]] = -swing_flexion  # flexion is minus the pitch
    after_landing = down & np.vstack([down[:1], down[:-1]])
    q[:, [0, 5]] -= np.radians(40.0) * after_landing  # the stances flexed 40 deg past their touchdown row
    steps["joint_angle_rad"] = q
    m = episode_metrics(steps, spec())
    assert m["hip_swing_peak_deg"] == pytest.approx(30.0, abs=1e-9)
    assert m["hip_touchdown_deg"] == pytest.approx(0.0, abs=1e-9)
    assert math.isnan(episode_metrics(still(100), spec())["hip_swing_peak_deg"])


def test_knee_at_touchdown_reads_the_landing_row():
    """Each foot lands with its knee bent 30 deg in its touchdown row only, straight in the rest of
    its stance: the knee at touchdown is 30, at mid-stance 0. Bent 30 deg in the first second's
    touchdowns alone, none counts: 0. Without steps, NaN."""
    steps = walk(210, 40, 20, 23, 0.4, 0.4)
    down = steps["foot_force_n"] > 0
    q = bent_knees(down, stance_deg=(0.0, 0.0), swing_deg=(60.0, 60.0))
    landing = np.zeros_like(down)
    landing[1:] = down[1:] & ~down[:-1]
    late = steps["t_s"] > 1.0 + 1e-9
    for foot, knee in ((0, 2), (1, 7)):
        q[landing[:, foot], knee] = np.radians(30.0)
    steps["joint_angle_rad"] = q
    m = episode_metrics(steps, spec(joint_limits_rad=KNEE_LIMITS))
    assert m["knee_touchdown_deg"] == pytest.approx(30.0, abs=1e-9) and m["knee_midstance_deg"] == 0.0
    for foot, knee in ((0, 2), (1, 7)):
        q[landing[:, foot] & late, knee] = 0.0
    assert episode_metrics(steps, spec(joint_limits_rad=KNEE_LIMITS))["knee_touchdown_deg"] == 0.0
    assert math.isnan(episode_metrics(still(100), spec())["knee_touchdown_deg"])


def test_a_contact_flicker_of_one_row_is_no_phase():
    """A foot that lifts for one row in a stance and touches down for one row in a swing keeps
    one stance and one swing: the metrics of the clean motion. Split, the stance would add a
    swing peaking at 0 deg, the swing a one-row stance bent 39 deg and a swing peaking 30 deg."""
    steps = walk(210, 40, 20, 23, 0.4, 0.4)
    down = steps["foot_force_n"] > 0
    steps["joint_angle_rad"] = bent_knees(down, stance_deg=(0.0, 10.0), swing_deg=(60.0, 60.0))
    clean = episode_metrics(steps, spec(joint_limits_rad=KNEE_LIMITS))
    flicker = down.copy()
    flicker[85, 0] = False  # the right foot's stance of rows 80-102 lifts for a row
    flicker[106, 0] = True  # its swing of rows 103-119 touches down for a row
    steps["foot_force_n"] = np.where(flicker, 300.0, 0.0)
    m = episode_metrics(steps, spec(joint_limits_rad=KNEE_LIMITS))
    assert m["knee_midstance_deg"] == pytest.approx(clean["knee_midstance_deg"], abs=1e-9)
    assert m["knee_swing_peak_deg"] == pytest.approx(clean["knee_swing_peak_deg"], abs=1e-9)


def test_a_foot_that_bounces_as_it_lands_takes_one_step():
    """The right foot lands, lifts for one row and lands again at each of its touchdowns (and
    one stance lifts for a row mid-way): the steps, their cadence and lengths, the strides and
    the hops are the clean motion's (9 steps at 2 steps/s). Counted row by row the bounces would
    be 13 more steps at over 3 steps/s; the duty, read row by row, does see the rows off."""
    steps = walk(200, 40, 20, 24, 0.4, 0.4)
    clean = episode_metrics(steps, spec())
    down = steps["foot_force_n"] > 0
    for row in (41, 81, 121, 161, 90):
        down[row, 0] = False
    steps["foot_force_n"] = np.where(down, 300.0, 0.0)
    m = episode_metrics(steps, spec())
    assert m["step_count"] == clean["step_count"] == 9
    for key in ("step_frequency_hz", "step_length_m", "stride_length_m", "step_time_symmetry",
                "step_length_symmetry", "hop_share"):
        assert m[key] == pytest.approx(clean[key], abs=1e-9), key
    assert m["step_frequency_hz"] == pytest.approx(2.0, abs=1e-9)
    assert m["duty_factor"] == pytest.approx(clean["duty_factor"] - 5 / 400, abs=1e-12)


def test_no_complete_phase_gives_nan():
    lifted = still(100, foot_force_n=np.tile([300.0, 0.0], (100, 1)))  # one foot up the whole episode
    for steps in (still(100), lifted):
        m = episode_metrics(steps, spec(joint_limits_rad=KNEE_LIMITS))
        assert math.isnan(m["knee_midstance_deg"]) and math.isnan(m["knee_swing_peak_deg"])
    assert episode_metrics(lifted, spec())["flight_share"] == 0.0


# --------------------------------------------------------------------------- the walk's targets


def _agent(steps: dict, **record) -> dict:
    """The aggregate of 3 copies of one constructed episode, as pamrun eval ranks an agent."""
    episode = {"fell": False, "duration_s": 10.0, "max_abs_y_m": 0.0, "distance_m": 8.0, "return": 0.0,
               "speed_m_s": 0.8, "pressure_change_kpa": 20.0, **record, **episode_metrics(steps, spec(
                   joint_limits_rad=KNEE_LIMITS))}
    return {"agent": "constructed", **aggregate([episode] * 3, EvalConfig())}


def test_a_constructed_human_walk_meets_every_walk_target_and_a_run_misses_its_own():
    """A stride of 44 rows (1.1 s), each foot down 27 of them and landing 0.55 m ahead of the
    other: duty 27/44 = 0.61, both feet down 2 x 5/44 = 23 %, 1.82 steps/s, the stance knee
    straight and the swing knee at 60 deg meets all 13 targets. The running schedule (each foot
    down 18 of 40 rows, 0.4 m steps) misses exactly flight, both feet down, duty and step length;
    20 kPa more of pressure change per step misses that target too."""
    walk_ = walk(400, 44, 22, 27, 0.55, 0.55)
    walk_["joint_angle_rad"] = bent_knees(walk_["foot_force_n"] > 0, (0.0, 0.0), (60.0, 60.0))
    agent = _agent(walk_)
    assert agent["duty_factor_mean"] == pytest.approx(27 / 44, abs=0.01)
    assert agent["walk_targets_met"] == len(WALK_TARGETS) == 13
    run = walk(400, 40, 20, 18, 0.4, 0.4)
    run["joint_angle_rad"] = bent_knees(run["foot_force_n"] > 0, (0.0, 0.0), (60.0, 60.0))
    missed = {key for key in WALK_TARGETS if not met(key, _agent(run)[key])}
    assert missed == {"flight_share_mean", "double_support_share_mean", "duty_factor_mean", "step_length_m_mean"}
    assert _agent(walk_, pressure_change_kpa=40.0)["walk_targets_met"] == 12
    console = Console(width=120, record=True)
    console.print(targets_table(agent))
    assert "13 of 13 met" in console.export_text() and "missed" not in console.export_text()
