"""The gait clock (env.gait_period_s, reward.kgait): a phase the policy sees, drawn per episode,
that swings each foot in turn; kgait pays 1 a step less a foot's force while its clock swings it
and its speed while its clock stands it; the mirror image's clock is half a period on; a run trains with
it, mirrored, and its export says how to feed the clock."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from pamrun.config import ConfigError, to_object
from pamrun.task.clock import (
    HIP_PEAK_SWING_SHARE,
    PUSH_OFF_SHARE,
    STANCE_WANTS,
    SWING_WANTS,
    both_down_weight,
    foot_miss,
    foot_path_m,
    foot_wants,
    hip_path_rad,
    knee_path_rad,
    landing_reach_m,
    push_off_path_rad,
    since_lift_off,
    stance_hip_path_rad,
    swing_weights,
)
from pamrun.task.env import PamWalkerEnv
from pamrun.task.reward import TERMS, Transition
from pamrun.task.symmetry import action_map, mirror_state, observation_map
from tests.conftest import compose_config
from tests.test_train import TINY, train_here

CLOCK = {"gait_period_s": 0.8, "swing_share": 0.4}


def test_the_clock_swings_each_foot_in_turn_for_its_share():
    """Over a period each foot swings (weight > 1/2) for swing_share of it, the left half a period
    after the right, and both stand between (sigma < 1/2: double support)."""
    phases = np.arange(4000) / 4000
    weights = np.array([swing_weights(p, 0.4) for p in phases])
    assert np.mean(weights[:, 0] > 0.5) == pytest.approx(0.4, abs=0.002)
    assert np.mean(weights[:, 1] > 0.5) == pytest.approx(0.4, abs=0.002)
    assert np.allclose(weights[:2000, 0], weights[2000:, 1])  # the left foot: the right's, half a period on
    assert np.mean((weights[:, 0] < 0.5) & (weights[:, 1] < 0.5)) == pytest.approx(0.2, abs=0.002)
    assert not np.any((weights[:, 0] > 0.5) & (weights[:, 1] > 0.5))
    assert np.mean(np.array([swing_weights(p, 0.25) for p in phases])[:, 0] > 0.5) == pytest.approx(0.25, abs=0.002)


def test_the_policy_sees_the_clock_and_each_episode_draws_its_phase():
    """sin, cos of the phase end the observation; the phase turns by Ts / T a step from a start
    drawn per seed (reproducible); the start pose is the same as without a clock."""
    env = PamWalkerEnv(env={**CLOCK, "reset_noise_rad": 0.02})
    plain = PamWalkerEnv(env={"reset_noise_rad": 0.02}, features=["kgait"])
    assert env.observation_structure["gait_clock"] == slice(43, 45)
    assert env.observation_space.shape == (45,)
    starts = []
    for seed in range(6):
        obs, _ = env.reset(seed=seed)
        plain_obs, _ = plain.reset(seed=seed)
        assert np.array_equal(obs[:43], plain_obs)
        starts.append(env.gait_phase())
        assert obs[43:] == pytest.approx([math.sin(2 * math.pi * starts[-1]), math.cos(2 * math.pi * starts[-1])],
                                         abs=1e-6)
    assert len(set(starts)) == 6 and max(starts) - min(starts) > 0.3
    env.reset(seed=2)
    assert env.gait_phase() == starts[2]
    for k in range(1, 5):
        obs, *_ = env.step(np.zeros(10))
        phase = (starts[2] + k * 0.025 / 0.8) % 1
        assert obs[43:] == pytest.approx([math.sin(2 * math.pi * phase), math.cos(2 * math.pi * phase)], abs=1e-6)
    *_, info = plain.step(np.zeros(10))
    assert info["reward_unweighted"]["kgait"] == 0.0  # no clock, nothing to follow
    env.close()
    plain.close()


def test_kgait_charges_force_on_a_swinging_foot_and_nothing_when_both_should_stand():
    """The robot stands still on both feet: when the clock stands both, kgait's feature is ~1;
    when it swings one foot fully, it is 1 less half that foot's share of the weight; in info
    under kgait, weighted."""
    env = PamWalkerEnv(env=CLOCK, reward={"kgait": 2.0})
    env.reset(seed=0)
    both_stand, one_swings = [], []
    for _ in range(64):  # two periods
        _, _, fell, _, info = env.step(np.zeros(10))
        assert not fell
        feature = info["reward_unweighted"]["kgait"]
        assert info["reward_terms"]["kgait"] == pytest.approx(2.0 * feature)
        swing = swing_weights(env.gait_phase(), 0.4)
        if max(swing) < 0.01:
            both_stand.append(feature)
        for foot in (0, 1):
            if swing[foot] > 0.999:
                one_swings.append((feature, info["foot_force_n"][foot] / env.weight_n))
    assert both_stand and one_swings
    assert min(both_stand) > 0.99  # standing still: no speed to charge
    for feature, share in one_swings:
        assert share > 0.3  # it stands on both feet
        assert feature == pytest.approx(1 - 0.5 * min(share, 1.0), abs=0.01)
    env.close()


def test_kgait_charges_a_foot_that_moves_while_its_clock_stands_it():
    """Move the whole robot, feet and all, forward in a step where the clock stands both feet:
    kgait's feature falls below 1 by the feet's mean speed (each capped at 1 m/s)."""
    env = PamWalkerEnv(env=CLOCK, features=["kgait"])
    env.reset(seed=0)
    while max(swing_weights(env.gait_phase() + 0.025 / 0.8, 0.4)) > 0.01:  # to a step in double support
        env.step(np.zeros(10))
    env.data.qvel[0] = 0.4  # the torso (and with it the feet) moving forward
    _, _, _, _, info = env.step(np.zeros(10))
    feature = info["reward_unweighted"]["kgait"]
    assert 0.0 <= feature < 0.95
    env.close()


def test_the_mirror_image_runs_half_a_period_on():
    """A robot started in another's mirror image with its clock half a period on, driven by the
    mirrored commands, sees the mirrored observations (the clock's sin, cos negated) and is paid
    the same kgait."""
    a, b = (PamWalkerEnv(env={**CLOCK, "reset_noise_rad": 0.05}, reward={"kgait": 1.0}) for _ in range(2))
    a.reset(seed=3)
    b.reset(seed=3)
    b.episode.phase0 = (a.episode.phase0 + 0.5) % 1
    a.data.qvel[1] = 0.2
    mujoco.mj_forward(a.model, a.data)
    b.data.qpos[:], b.data.qvel[:] = mirror_state(a.data.qpos, a.data.qvel, a.qpos_idx, a.qvel_idx)
    mujoco.mj_forward(b.model, b.data)
    o_index, o_sign = observation_map(10, gait_clock=True)
    a_index, a_sign = action_map(10)
    assert sorted(o_index) == list(range(45)) and list(o_sign[-2:]) == [-1.0, -1.0]
    rng = np.random.default_rng(0)
    for k in range(20):
        action = rng.uniform(-0.5, 0.5, 10)
        obs_a, r_a, *_, info_a = a.step(action)
        obs_b, r_b, *_, info_b = b.step(action[a_index] * a_sign)
        assert np.max(np.abs(obs_b - obs_a[o_index] * o_sign)) < 1e-3
        if k:  # the first step's foot speed runs from b's own reset pose, not the mirrored one set after it
            assert info_b["reward_terms"]["kgait"] == pytest.approx(info_a["reward_terms"]["kgait"], abs=1e-3)
            assert info_b["reward_terms"]["kgait"] < 0.99
    a.close()
    b.close()


@pytest.mark.parametrize("override, key", [
    (["reward.kgait=1"], "reward.kgait"),  # a clock to follow that does not run
    (["+train.walk_weights.kgait=4"], "train.walk_weights.kgait"),
    (["env.gait_period_s=0.8", "env.swing_share=1"], "swing_share"),
    (["env.gait_period_s=-0.8"], "gait_period_s"),
    (["env.gait_follows_speed=true"], "gait_follows_speed"),  # no clock to scale
    (["env.swing_clearance_m=0.05"], "swing_clearance_m"),  # no clock to swing
    (["env.gait_period_s=0.8", "env.swing_clearance_m=-0.05"], "swing_clearance_m"),
    (["env.swing_knee_deg=20"], "swing_knee_deg"),  # no clock to swing
    (["env.gait_period_s=0.8", "env.swing_knee_deg=-20"], "swing_knee_deg"),
    (["env.stance_knee_deg=30"], "stance_knee_deg"),  # no clock to stand on
    (["env.gait_period_s=0.8", "env.stance_knee_deg=-30"], "stance_knee_deg"),
    (["env.gait_period_s=0.8", "env.gait_follows_speed=true", "env.target_speed_m_s=-0.5"], "target_speed_m_s"),
])
def test_impossible_gait_clocks_fail_naming_the_key(override, key):
    with pytest.raises(ConfigError, match=key):
        to_object(compose_config(*override))


def test_a_clocked_agent_trains_mirrored_evaluates_and_exports_its_clock(tmp_path):
    """A run with the clock (mirrored transitions included) saves agents of 45 inputs; pamrun
    eval runs them with their clock; the export's metadata names the clock's block and period."""
    from pamrun.evaluation.agents import load_agents
    from pamrun.evaluation.episodes import evaluate_agents
    from pamrun.evaluation.export import metadata

    run = tmp_path / "run"
    assert train_here(run, *TINY, "train.max_frames=400", "train.eval_every_frames=0", "train.mirror=true",
                      "env.gait_period_s=0.8", "reward.kgait=1") == "max_frames"
    cfg = to_object(compose_config("eval.episodes=2", "eval.episode_s=1", "eval.walk_duration_s=1"))
    agents, envs, errors = load_agents(str(run / "checkpoints" / "last.pt"), cfg)
    assert not errors and agents[0].obs_size == 45 and envs[0].env.gait_period_s == 0.8
    (episodes,) = evaluate_agents(agents, envs, 2, 1000, 1, keep_steps=False)
    assert len(episodes) == 2 and all(np.isfinite(e["distance_m"]) for e in episodes)
    meta = metadata(agents[0], "onnx")
    assert meta["observation_layout"]["gait_clock"] == [43, 45] and meta["gait_clock"]["period_s"] == 0.8
    assert meta["gait_clock"]["follows_speed"] is False and meta["gait_clock"]["step_length_m"] == 0.4


def test_kgait_charges_a_foot_off_the_ground_while_its_clock_stands_it():
    """Hold the robot still a few centimetres above the floor in double support: both feet are
    still but carry nothing, so each misses its stance fully and kgait's feature is ~0 (a flight
    phase costs what a run's does)."""
    env = PamWalkerEnv(env=CLOCK, features=["kgait"])
    env.reset(seed=0)
    while max(swing_weights(env.gait_phase() + 0.025 / 0.8, 0.4)) > 0.01:  # to a step in double support
        env.step(np.zeros(10))
    env.data.qpos[2] += 0.05
    env.data.qvel[:] = 0.0
    mujoco.mj_forward(env.model, env.data)
    _, _, _, _, info = env.step(np.zeros(10))
    assert max(info["foot_force_n"]) < 1.0  # in the air
    assert info["reward_unweighted"]["kgait"] < 0.05
    env.close()


def held_in_right_swing(env_overrides: dict, lift_m: float, knee_deg: float | None = None):
    """Step a clocked env (CLOCK plus env_overrides) to a step that swings the right foot fully,
    raise the robot lift_m, set its right knee to knee_deg (if given), still, and step once with
    zero action: kgait's feature, the step's info, and the right knee's angle after it [deg]."""
    env = PamWalkerEnv(env={**CLOCK, **env_overrides}, features=["kgait"])
    env.reset(seed=0)
    while swing_weights(env.gait_phase() + 0.025 / 0.8, 0.4)[0] < 0.999:  # to a step swinging the right foot
        env.step(np.zeros(10))
    knee = env.model.jnt_qposadr[mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_JOINT, "right_knee")]
    env.data.qpos[2] += lift_m
    if knee_deg is not None:
        env.data.qpos[knee] = math.radians(knee_deg)
    env.data.qvel[:] = 0.0
    mujoco.mj_forward(env.model, env.data)
    _, _, _, _, info = env.step(np.zeros(10))
    bent = math.degrees(env.data.qpos[knee])  # after the step, as kgait reads it
    env.close()
    return info["reward_unweighted"]["kgait"], info, bent


def test_kgait_charges_a_swinging_foot_that_does_not_lift_to_the_clearance():
    """Hold the robot still 5 cm above the floor while the clock swings its right foot fully.
    With env.swing_clearance_m = 0.1 the right foot misses the half of the clearance it lacks;
    with 0.03 (reached) or 0 (off) it misses nothing: it carries no weight. On the floor, a
    clearance makes the swinging foot miss fully, whatever it carries."""
    def held(clearance: float, lift_m: float):
        kgait, info, _ = held_in_right_swing({"swing_clearance_m": clearance}, lift_m)
        return kgait, info

    off, info = held(0.0, 0.05)
    assert max(info["foot_force_n"]) < 1.0  # in the air
    assert off == pytest.approx(0.5, abs=0.01)  # the left foot carries nothing while it should stand
    assert held(0.03, 0.05)[0] == pytest.approx(off, abs=1e-9)
    lacking, _ = held(0.1, 0.05)  # lifted ~0.05 (less the fall in one step) of 0.1
    assert lacking == pytest.approx(off - 0.5 * 0.5, abs=0.03)
    plain, info = held(0.0, 0.0)
    scuffing, _ = held(0.05, 0.0)
    share = info["foot_force_n"][0] / (info["foot_force_n"].sum())
    assert 0.2 < share < 0.8  # on both feet: the swinging one carries
    assert plain - scuffing == pytest.approx(0.5 * (1 - share), abs=0.05)  # its miss: 1, not its load


def test_kgait_charges_a_swinging_leg_whose_knee_does_not_bend_to_the_demand():
    """Hold the robot 5 cm above the floor while the clock swings its right foot fully, its right
    knee set to a bend. With env.swing_knee_deg = 0 (off) the swinging foot misses nothing (it
    carries no weight); with 20 deg a straight knee misses fully and a knee bent past 20 deg
    nothing; with 40 deg a knee at q deg misses 1 - q / 40."""
    def held(knee_deg: float, bend_deg: float) -> tuple[float, float]:
        kgait, info, bent = held_in_right_swing({"swing_knee_deg": knee_deg}, 0.05, bend_deg)
        assert max(info["foot_force_n"]) < 1.0  # in the air
        return kgait, bent

    off, _ = held(0.0, 0.0)
    assert off == pytest.approx(0.5, abs=0.01)  # the left foot carries nothing while it should stand
    assert held(0.0, 30.0)[0] == pytest.approx(off, abs=1e-6)
    assert held(20.0, 0.0)[0] == pytest.approx(off - 0.5, abs=0.01)  # straight: the swing misses fully
    bent_past, bent = held(20.0, 30.0)
    assert bent > 20 and bent_past == pytest.approx(off, abs=1e-6)
    part, bent = held(40.0, 30.0)
    assert 0 < bent < 40 and part == pytest.approx(off - 0.5 * (1 - bent / 40), abs=1e-3)


def test_a_foot_misses_the_larger_of_its_wants_and_a_bent_stance_knee_is_one():
    """foot_miss, kgait's per-foot miss: in stance the larger of its sole speed, its want of load
    and, with env.stance_knee_deg S, its knee's bend as a share of S; in swing the larger of its
    load and, with env.swing_knee_deg K, its want of bend; in between, the two weighted."""
    off = to_object(compose_config("env.gait_period_s=0.8")).env
    knees = to_object(compose_config("env.gait_period_s=0.8", "env.stance_knee_deg=30", "env.swing_knee_deg=20")).env
    rad = math.radians
    assert foot_miss(0.0, 0.5, 0.0, 0.0, rad(45), off) == 0.0  # S off: a loaded, still stance misses nothing
    assert foot_miss(0.0, 0.5, 0.0, 0.0, rad(15), knees) == pytest.approx(0.5)
    assert foot_miss(0.0, 0.5, 0.0, 0.0, rad(45), knees) == 1.0
    assert foot_miss(0.0, 0.5, 0.0, 0.0, rad(-1), knees) == 0.0  # straight, on its stop
    assert foot_miss(0.0, 0.5, 0.3, 0.0, rad(6), knees) == pytest.approx(0.3)  # speed 0.3 > bend 0.2
    assert foot_miss(0.0, 0.1, 0.0, 0.0, rad(6), knees) == pytest.approx(0.8)  # want of load 0.8
    assert foot_miss(1.0, 0.0, 0.0, 0.05, rad(45), knees) == 0.0  # swinging: the stance demand is off
    assert foot_miss(1.0, 0.0, 0.0, 0.05, rad(10), knees) == pytest.approx(0.5)  # half the swing bend
    assert foot_miss(0.5, 0.0, 0.0, 0.05, rad(10), knees) == pytest.approx(0.5 * 0.5 + 0.5 * 1.0)


def test_a_foots_wants_are_named_and_only_those_its_options_ask_for():
    """foot_wants, what reward_anatomy splits kgait's miss by: the wants of a foot whose env options
    are off are left out, each miss is in [0, 1], and foot_miss is the larger in each phase."""
    off = to_object(compose_config("env.gait_period_s=0.8")).env
    every = to_object(compose_config("env.gait_period_s=0.8", "env.stance_knee_deg=30", "env.swing_knee_deg=20",
                                     "env.swing_clearance_m=0.05")).env
    assert set(foot_wants(0.3, 0.2, 0.01, 0.1, off)) == {"swing_load", "stance_speed", "stance_load"}
    wants = foot_wants(0.3, 0.2, 0.01, math.radians(10), every)
    assert set(wants) == set(SWING_WANTS) | set(STANCE_WANTS)
    assert wants == pytest.approx({"swing_load": 0.3, "swing_lift": 0.8, "swing_knee": 0.5,
                                   "stance_speed": 0.2, "stance_load": 0.4, "stance_knee": 1 / 3})
    assert foot_miss(0.25, 0.3, 0.2, 0.01, math.radians(10), every) == pytest.approx(0.25 * 0.8 + 0.75 * 0.4)
    assert all(0.0 <= w <= 1.0 for w in foot_wants(3.0, 5.0, -1.0, math.radians(120), every).values())


def test_kgait_charges_bent_knees_on_the_ground_only_where_the_clock_stands_them():
    """The same crouch (both knees commanded to bend, feet on the ground) under three values of
    env.stance_knee_deg: off and 10^9 deg (a bend's share < 1e-7) pay the same kgait; 1 deg (any
    bend misses fully) pays less on each step with knees bent past it, by at most the stances'
    half of the feature."""
    def crouch(stance_knee_deg: float) -> tuple[list[float], list[float], list[float]]:
        env = PamWalkerEnv(env={**CLOCK, "stance_knee_deg": stance_knee_deg}, features=["kgait"])
        env.reset(seed=0)
        action = np.zeros(10)
        action[[2, 7]] = 0.5  # right_knee, left_knee
        kgait, stance, bent = [], [], []
        for _ in range(6):
            _, _, _, _, info = env.step(action)
            kgait.append(info["reward_unweighted"]["kgait"])
            stance.append(sum(1.0 - s for s in swing_weights(env.gait_phase(), 0.4)))
            bent.append(min(math.degrees(env.data.qpos[a]) for a in env.knee_addresses))
        env.close()
        return kgait, stance, bent

    off, stance, bent = crouch(0.0)
    assert crouch(1e9)[0] == pytest.approx(off, abs=1e-6)
    full = crouch(1.0)[0]
    assert max(bent) > 30
    for k_off, k_full, share, q in zip(off, full, stance, bent):
        assert k_full <= k_off + 1e-12 and k_off - k_full <= 0.5 * share + 1e-9
        if q > 1.0 and share > 0.5:
            assert k_full < k_off - 0.05


def test_the_clock_and_the_step_length_follow_the_commanded_speed():
    """With env.gait_follows_speed each episode's clock period T and kstep's step length L*
    follow its drawn v*: v* = 2 L* / T (one step per half period at that speed), the cadence and
    the step length each grow as the square root of v*, and the phase turns at the episode's
    T. A fixed v* (pamrun eval's eval.speed_m_s) sets them the same way."""
    env = PamWalkerEnv(env={**CLOCK, "gait_follows_speed": True, "speed_command": True, "speed_range_m_s": [0.5, 1.2]})
    speeds = []
    for seed in range(6):
        env.reset(seed=seed)
        v, start = env.target_speed_m_s, env.gait_phase()
        env.step(np.zeros(10))
        period = 0.025 / ((env.gait_phase() - start) % 1)  # as the phase turns
        assert period == pytest.approx(env.gait_period_s, rel=1e-9)
        assert 2 * env.step_length_m / period == pytest.approx(v, rel=1e-9)
        assert period * math.sqrt(v) == pytest.approx(0.8, rel=1e-9)  # 0.8 s at v0 = 2 * 0.4 / 0.8 = 1 m/s
        speeds.append(v)
    assert max(speeds) - min(speeds) > 0.2
    slow = PamWalkerEnv(env={**CLOCK, "gait_follows_speed": True, "target_speed_m_s": 0.5})
    slow.reset(seed=0)
    assert slow.gait_period_s == pytest.approx(0.8 * math.sqrt(2)) and slow.step_length_m == pytest.approx(0.4 / math.sqrt(2))
    assert PamWalkerEnv(env={**CLOCK, "target_speed_m_s": 0.5}).gait_period_s == 0.8  # without it: the fixed clock
    env.close()
    slow.close()


def test_both_down_weight_marks_the_clocks_double_support():
    """(1 - s_right)(1 - s_left) is ~1 for the 1 - 2 sigma of the period where neither foot swings
    and ~0 while one does."""
    phases = np.arange(4000) / 4000
    for share in (0.4, 0.3):
        weights = np.array([both_down_weight(p, share) for p in phases])
        swings = np.array([swing_weights(p, share) for p in phases])
        assert np.mean(weights > 0.5) == pytest.approx(1 - 2 * share, abs=0.003)
        assert weights[(swings > 0.99).any(axis=1)].max() < 0.01
        assert weights[(swings < 0.01).all(axis=1)].min() > 0.98


def test_kdouble_charges_a_foot_up_while_the_clock_stands_both():
    """On both feet, kdouble's feature is 0 at every phase. Lifted clear of the floor, it is minus
    the clock's both-feet-down weight: ~-1 in its double support, ~0 while it swings a foot; -1
    with the clock stopped (v* = 0); 0 without a clock. In info under kdouble, weighted."""
    env = PamWalkerEnv(env=CLOCK, reward={"kdouble": 3.0})
    env.reset(seed=0)
    for _ in range(64):  # two periods on both feet
        _, _, fell, _, info = env.step(np.zeros(10))
        assert not fell and min(info["foot_force_n"]) > 0.05 * env.weight_n
        assert info["reward_unweighted"]["kdouble"] == 0.0
    seen = {"double": [], "swing": []}
    for _ in range(32):  # one period, held in the air
        env.data.qpos[2] += 0.3
        env.data.qvel[:] = 0.0
        mujoco.mj_forward(env.model, env.data)
        _, _, _, _, info = env.step(np.zeros(10))
        env.data.qpos[2] -= 0.3
        assert max(info["foot_force_n"]) < 0.05 * env.weight_n
        weight = both_down_weight(env.gait_phase(), 0.4)
        feature = info["reward_unweighted"]["kdouble"]
        assert feature == pytest.approx(-weight, abs=1e-9)
        assert info["reward_terms"]["kdouble"] == pytest.approx(3.0 * feature)
        seen.setdefault("double" if weight > 0.98 else "swing" if weight < 0.01 else "edge", []).append(feature)
    assert seen["double"] and seen["swing"]
    env.close()
    stopped = PamWalkerEnv(env={**CLOCK, "gait_follows_speed": True, "target_speed_m_s": 0.0}, reward={"kdouble": 1.0})
    stopped.reset(seed=0)
    assert stopped.episode.clock_stopped
    stopped.data.qpos[2] += 0.3
    mujoco.mj_forward(stopped.model, stopped.data)
    *_, info = stopped.step(np.zeros(10))
    assert info["reward_unweighted"]["kdouble"] == -1.0
    stopped.close()
    plain = PamWalkerEnv(reward={"kdouble": 1.0})
    plain.reset(seed=0)
    plain.data.qpos[2] += 0.3
    mujoco.mj_forward(plain.model, plain.data)
    *_, info = plain.step(np.zeros(10))
    assert info["reward_unweighted"]["kdouble"] == 0.0
    plain.close()


def _transition(env, before: tuple[bool, bool] = (True, True), after: tuple[bool, bool] = (True, True)) -> Transition:
    """A control step as the terms read it, from the env's present state, its feet on the ground
    ``before`` and ``after`` it as given."""
    _, forces, soles, torso, _ = env._sense()
    return Transition(env, env.episode, torso, env.data.qpos.tolist(), np.zeros(10), np.zeros(10), soles, soles,
                      list(before), list(after), forces)


def _contacts(env, before: list[bool], after: list[bool], key: str = "klift") -> float:
    """``key``'s feature for a step whose feet were on the ground ``before`` it and are ``after`` it."""
    return TERMS[key](_transition(env, before, after))


def test_klift_charges_a_foot_leaving_the_ground_early_in_its_stance():
    """A foot that leaves the ground costs 1 in the first half of its clock's stance (from its touchdown,
    psi = sigma, to psi = (1 + sigma) / 2) and nothing elsewhere, its swing and late stance included;
    staying down, staying up or landing costs nothing; the left's half is the right's half a period on;
    while the clock stands still every lift costs 1; without a clock 0. In a real step, the robot lifted
    off the floor early in the right foot's stance, the left's clock swinging it, pays -1, weighted in info."""
    env = PamWalkerEnv(env=CLOCK, reward={"klift": 3.0})
    env.reset(seed=0)
    sigma = env.env_cfg.swing_share
    seen = set()
    for phase0 in np.linspace(0.0, 1.0, 80, endpoint=False):
        env.episode.phase0 = float(phase0)
        phase = env.episode.phase(env.env_cfg)
        early = [sigma <= since_lift_off(phase, f, sigma) < 0.5 * (1 + sigma) for f in (0, 1)]
        assert early[1] == (sigma <= since_lift_off(phase + 0.5, 0, sigma) < 0.5 * (1 + sigma))
        assert not all(early)
        seen.add(tuple(early))
        assert _contacts(env, [True, True], [False, True]) == -float(early[0])
        assert _contacts(env, [True, True], [True, False]) == -float(early[1])
        assert _contacts(env, [True, True], [False, False]) == -float(sum(early))
        for before, after in (([True, True], [True, True]), ([False, False], [False, False]),
                              ([False, False], [True, True]), ([False, True], [True, True])):
            assert _contacts(env, before, after) == 0.0
    assert seen == {(True, False), (False, True), (False, False)}
    dt_share = env.env_cfg.control_dt_s / env.env_cfg.gait_period_s
    env.episode.phase0 = 0.6 - 4 * dt_share  # after 5 steps: the right foot 0.1 into its stance's first half
    for _ in range(4):
        _, _, fell, _, info = env.step(np.zeros(10))
    assert min(info["foot_force_n"]) > 0.05 * env.weight_n and info["reward_unweighted"]["klift"] == 0.0
    env.data.qpos[2] += 0.3
    env.data.qvel[:] = 0.0
    mujoco.mj_forward(env.model, env.data)
    *_, info = env.step(np.zeros(10))
    phase = env.gait_phase()
    assert sigma < since_lift_off(phase, 0, sigma) < 0.5 * (1 + sigma) and max(info["foot_force_n"]) < 0.05 * env.weight_n
    assert info["reward_unweighted"]["klift"] == -1.0 and info["reward_terms"]["klift"] == pytest.approx(-3.0)
    env.close()
    stopped = PamWalkerEnv(env={**CLOCK, "gait_follows_speed": True, "target_speed_m_s": 0.0}, reward={"klift": 1.0})
    stopped.reset(seed=0)
    assert stopped.episode.clock_stopped
    assert _contacts(stopped, [True, True], [False, False]) == -2.0
    assert _contacts(stopped, [True, True], [True, True]) == 0.0
    stopped.close()
    plain = PamWalkerEnv(reward={"klift": 1.0})
    plain.reset(seed=0)
    assert _contacts(plain, [True, True], [False, False]) == 0.0
    plain.close()


def test_ktouch_charges_a_foot_landing_off_its_clocks_touchdown():
    """A foot that touches the ground costs 1 unless its clock is within 0.1 of the period of its
    touchdown (psi = sigma), either side; staying down, staying up and lifting cost nothing; the left's
    window is the right's half a period on; while the clock stands still every touchdown costs 1;
    without a clock 0. In a real step, the robot dropped onto the floor late in the right foot's
    stance, from 0.3 m up, pays -2 (both feet), weighted in info."""
    env = PamWalkerEnv(env=CLOCK, reward={"ktouch": 2.0})
    env.reset(seed=0)
    sigma = env.env_cfg.swing_share
    seen = set()
    for phase0 in np.linspace(0.0, 1.0, 80, endpoint=False):
        env.episode.phase0 = float(phase0)
        phase = env.episode.phase(env.env_cfg)
        off = [not sigma - 0.1 - 1e-9 <= since_lift_off(phase, f, sigma) <= sigma + 0.1 + 1e-9 for f in (0, 1)]
        assert off[1] == (not sigma - 0.1 - 1e-9 <= since_lift_off(phase + 0.5, 0, sigma) <= sigma + 0.1 + 1e-9)
        seen.add(tuple(off))
        assert _contacts(env, [False, True], [True, True], "ktouch") == -float(off[0])
        assert _contacts(env, [True, False], [True, True], "ktouch") == -float(off[1])
        assert _contacts(env, [False, False], [True, True], "ktouch") == -float(sum(off))
        for before, after in (([True, True], [True, True]), ([False, False], [False, False]),
                              ([True, True], [False, False]), ([True, False], [False, False])):
            assert _contacts(env, before, after, "ktouch") == 0.0
    assert seen == {(True, False), (False, True), (True, True)}
    dt_share = env.env_cfg.control_dt_s / env.env_cfg.gait_period_s
    env.episode.phase0 = 0.72 - 4 * dt_share  # after 5 steps: the right foot about 0.7 into its own clock, the left 0.2
    env.data.qpos[2] += 0.3
    mujoco.mj_forward(env.model, env.data)
    for _ in range(4):
        *_, info = env.step(np.zeros(10))
    assert max(info["foot_force_n"]) < 0.05 * env.weight_n and info["reward_unweighted"]["ktouch"] == 0.0
    env.data.qpos[2] -= 0.3
    env.data.qvel[:] = 0.0
    mujoco.mj_forward(env.model, env.data)
    *_, info = env.step(np.zeros(10))
    phase = env.gait_phase()
    assert 0.6 < since_lift_off(phase, 0, sigma) < 0.8 and 0.1 < since_lift_off(phase, 1, sigma) < sigma - 0.1
    assert min(info["foot_force_n"]) > 0.05 * env.weight_n
    assert info["reward_unweighted"]["ktouch"] == -2.0 and info["reward_terms"]["ktouch"] == pytest.approx(-4.0)
    env.close()
    stopped = PamWalkerEnv(env={**CLOCK, "gait_follows_speed": True, "target_speed_m_s": 0.0}, reward={"ktouch": 1.0})
    stopped.reset(seed=0)
    assert stopped.episode.clock_stopped
    assert _contacts(stopped, [False, False], [True, True], "ktouch") == -2.0
    assert _contacts(stopped, [True, True], [True, True], "ktouch") == 0.0
    stopped.close()
    plain = PamWalkerEnv(reward={"ktouch": 1.0})
    plain.reset(seed=0)
    assert _contacts(plain, [False, False], [True, True], "ktouch") == 0.0
    plain.close()


def test_foot_path_moves_each_foot_back_in_stance_and_forward_in_swing():
    """The clock's foot path: a foot moves forward of the torso while swing_weights swings it and back
    while it stands, from +E/2 at touchdown to -E/2 at lift-off (E = 2 (1 - sigma) L*), without a jump,
    the feet L* apart at each touchdown;
    the left foot's path is the right's half a period later; at L* = 0 both are 0."""
    phases = np.arange(4000) / 4000
    for share, step in ((0.4, 0.625), (0.3, 0.4)):
        path = np.array([foot_path_m(p, share, step) for p in phases])
        swings = np.array([swing_weights(p, share) for p in phases])
        reach = (1 - share) * step
        assert path.max() == pytest.approx(reach, rel=1e-3) and path.min() == pytest.approx(-reach, rel=1e-3)
        assert np.abs(np.diff(path, axis=0)).max() < 4 * reach / (4000 * min(share, 1 - share))  # no jump
        moved = np.diff(path, axis=0, append=path[:1])
        for foot in (0, 1):
            assert (moved[swings[:, foot] > 0.99, foot] > 0).all()  # forward in swing
            assert (moved[swings[:, foot] < 0.01, foot] < 0).all()  # back in stance
            landing = np.flatnonzero((swings[:-1, foot] > 0.5) & (swings[1:, foot] <= 0.5))
            assert path[landing, foot] == pytest.approx([reach], abs=0.01)  # lands ahead, the other behind:
            assert path[landing, foot] - path[landing, 1 - foot] == pytest.approx([step], abs=0.01)  # a step of L*
        np.testing.assert_allclose(path[:, 1], np.roll(path[:, 0], -2000), atol=1e-9)
        assert foot_path_m(0.3, share, 0.0) == (0.0, 0.0)


def test_kplace_charges_the_feet_miss_of_the_clocks_path():
    """Standing still on both feet under the torso while the clock runs, kplace's feature is ~1 where
    the path has both feet under the torso (one at mid-swing, the other at mid-stance) and 0 where it
    wants them a step apart (each miss capped at 1); with the clock stopped it stays near 1, and is 0
    without a clock. In info under kplace, weighted."""
    env = PamWalkerEnv(env={**CLOCK, "step_length_m": 0.625}, reward={"kplace": 2.0})
    env.reset(seed=0)
    features = []
    for _ in range(64):
        _, _, fell, _, info = env.step(np.zeros(10))
        assert not fell
        features.append(info["reward_unweighted"]["kplace"])
        assert info["reward_terms"]["kplace"] == pytest.approx(2.0 * features[-1])
    assert max(features) > 0.95 and min(features) == pytest.approx(0.0, abs=0.02)
    env.close()
    stopped = PamWalkerEnv(env={**CLOCK, "gait_follows_speed": True, "target_speed_m_s": 0.0}, reward={"kplace": 1.0})
    stopped.reset(seed=0)
    still = [stopped.step(np.zeros(10))[-1]["reward_unweighted"]["kplace"] for _ in range(32)]
    assert 0.85 < min(still) < 1.0 and max(still) - min(still) < 0.05  # the soles' centres a few cm ahead of the torso
    stopped.close()
    plain = PamWalkerEnv(reward={"kplace": 1.0})
    plain.reset(seed=0)
    *_, info = plain.step(np.zeros(10))
    assert info["reward_unweighted"]["kplace"] == 0.0
    plain.close()


def test_the_knee_path_bends_a_swinging_knee_and_lands_it_straight():
    """Each knee's path is 0 through its stance and at its lift-off and touchdown, rises to its peak
    0.3 into the swing and falls from it, and the left's is the right's half a period later."""
    share, peak = 0.4, math.radians(60)
    lift_off = 0.25 - share / 2  # the right foot's (the clock centres its swing at phase 1/4)
    paths = np.array([knee_path_rad(p, share, peak) for p in np.arange(0, 1, 0.001)])
    assert (paths >= 0).all() and paths.max() == pytest.approx(peak, rel=1e-4)
    assert (paths[:, 0] > 1e-9).mean() == pytest.approx(share, abs=0.002)  # bent only while it swings
    assert knee_path_rad(lift_off, share, peak)[0] == 0.0
    assert knee_path_rad(lift_off + share - 1e-9, share, peak)[0] == pytest.approx(0.0, abs=1e-6)  # touchdown
    assert knee_path_rad(lift_off + share + 0.01, share, peak)[0] == 0.0
    assert knee_path_rad(lift_off + 0.3 * share, share, peak)[0] == pytest.approx(peak)
    swing = [knee_path_rad(lift_off + u * share, share, peak)[0] for u in np.arange(0.0, 1.0, 0.05)]
    top = int(np.argmax(swing))
    assert np.all(np.diff(swing[:top + 1]) > 0) and np.all(np.diff(swing[top:]) < 0)
    for u in (0.1, 0.5, 0.8):
        assert knee_path_rad(lift_off + u * share + 0.5, share, peak)[1] == pytest.approx(
            knee_path_rad(lift_off + u * share, share, peak)[0])
    late = [knee_path_rad(lift_off + u * share, share, peak)[0] for u in (0.98, 0.99, 0.999)]
    assert late[0] < 0.01 * peak and late[1] - late[2] < late[0] - late[1]  # at rest as it lands


def _posed(env, key: str, addresses, angles_rad) -> float:
    """Term ``key``'s feature with the joints at qpos ``addresses`` (right, left) at ``angles_rad``, the
    rest of the pose at reset."""
    d = env.data
    d.qpos[addresses] = angles_rad
    mujoco.mj_forward(env.model, d)
    return TERMS[key](_transition(env))


def _knees_posed(env, knees_rad) -> float:
    return _posed(env, "kknee", env.knee_addresses, knees_rad)


def test_kknee_pays_the_knees_on_the_clocks_knee_path():
    """Knees posed on the clock's path pay 1; a swinging knee held straight at its peak, a full
    miss (more than half the peak), pays 1/2; a knee bent a quarter of the peak off its path costs
    1/8; standing still at the stopped clock pays ~1; without a clock 0. In info under kknee, weighted."""
    env = PamWalkerEnv(env={**CLOCK, "knee_path_peak_deg": 60.0}, reward={"kknee": 3.0})
    env.reset(seed=0)
    env.episode.phase0 = 0.05 + 0.3 * 0.4  # the right knee's peak, 0.3 into its swing; the left in stance
    wanted = knee_path_rad(env.episode.phase(env.env_cfg), env.env_cfg.swing_share, math.radians(60))
    assert wanted[0] == pytest.approx(math.radians(60)) and wanted[1] == 0.0
    assert _knees_posed(env, wanted) == pytest.approx(1.0)
    assert _knees_posed(env, [0.0, 0.0]) == pytest.approx(0.5)
    assert _knees_posed(env, [wanted[0] - math.radians(15), 0.0]) == pytest.approx(1.0 - 0.5 * 0.25)
    *_, info = env.step(np.zeros(10))
    assert 0.0 <= info["reward_unweighted"]["kknee"] <= 1.0
    assert info["reward_terms"]["kknee"] == pytest.approx(3.0 * info["reward_unweighted"]["kknee"])
    env.close()
    stopped, plain = _stopped_and_clockless("kknee", 16)
    assert min(stopped) > 0.95 and plain == 0.0


def _stopped_and_clockless(key: str, steps: int) -> tuple[list[float], float]:
    """Term ``key``'s features over ``steps`` zero-action steps with the clock stopped (v* = 0), and its
    first without a clock."""
    stopped = PamWalkerEnv(env={**CLOCK, "gait_follows_speed": True, "target_speed_m_s": 0.0}, reward={key: 1.0})
    stopped.reset(seed=0)
    features = [stopped.step(np.zeros(10))[-1]["reward_unweighted"][key] for _ in range(steps)]
    stopped.close()
    plain = PamWalkerEnv(reward={key: 1.0})
    plain.reset(seed=0)
    feature = plain.step(np.zeros(10))[-1]["reward_unweighted"][key]
    plain.close()
    return features, feature


def test_the_stance_hip_path_extends_the_stance_leg_behind_the_body():
    """Through a leg's stance its hip is wanted from the touchdown flexion at touchdown, straight to the
    extension as the other foot lands, and back to 0 at lift-off; free (None) in its swing; the left's
    is the right's half a period later."""
    share, flexion, extension = 0.4, math.radians(25), math.radians(15)
    lift_off = 0.25 - share / 2
    stance = [stance_hip_path_rad(lift_off + share + w * (1 - share), share, flexion, extension)[0]
              for w in np.linspace(0.0, 0.999, 300)]
    top = int(np.argmax(stance))
    assert stance[0] == pytest.approx(-flexion) and max(stance) == pytest.approx(extension, rel=1e-2)
    assert top / 299 == pytest.approx(0.5 / (1 - share), abs=0.01)  # the other foot lands half a period on
    assert np.all(np.diff(stance[:top + 1]) > 0) and np.all(np.diff(stance[top:]) < 0)
    assert stance[-1] == pytest.approx(0.0, abs=5e-3)
    assert stance_hip_path_rad(lift_off + 0.5 * share, share, flexion, extension)[0] is None
    for w in (0.1, 0.9):
        at = lift_off + share + w * (1 - share)
        assert stance_hip_path_rad(at + 0.5, share, flexion, extension)[1] == pytest.approx(
            stance_hip_path_rad(at, share, flexion, extension)[0])


def test_kextend_pays_the_stance_hips_on_the_clocks_stance_path():
    """As the left foot lands, the right hip extended as asked pays 1, held at 0 (a full miss) 1/2, a
    quarter of h_peak off 1 - 1/8; the left, just landed, is wanted at khip's touchdown flexion. Stopped
    clock: 1; no clock: 0."""
    env = PamWalkerEnv(env={**CLOCK, "hip_path_peak_deg": 30.0, "hip_extension_deg": 15.0}, reward={"kextend": 2.0})
    env.reset(seed=0)
    env.episode.phase0 = 0.05 + 0.5 + 0.4 - 1.0  # the left's touchdown, half a period after the right's
    wanted = stance_hip_path_rad(env.episode.phase(env.env_cfg), 0.4, math.radians(25), math.radians(15))
    assert wanted == pytest.approx((math.radians(15), -math.radians(25)))
    assert _posed(env, "kextend", env.hip_addresses, list(wanted)) == pytest.approx(1.0)
    assert _posed(env, "kextend", env.hip_addresses, [0.0, wanted[1]]) == pytest.approx(0.5)
    assert _posed(env, "kextend", env.hip_addresses, [wanted[0] - math.radians(7.5), wanted[1]]) == pytest.approx(
        1.0 - 0.5 * 0.25)
    *_, info = env.step(np.zeros(10))
    assert info["reward_terms"]["kextend"] == pytest.approx(2.0 * info["reward_unweighted"]["kextend"])
    env.close()
    stopped, plain = _stopped_and_clockless("kextend", 8)
    assert stopped == [1.0] * 8 and plain == 0.0


def _landing(env, ahead_m: tuple[float, float], before: tuple[bool, bool], after: tuple[bool, bool]) -> float:
    """kreach's feature with each sole's centre ``ahead_m`` of the torso, its feet down ``before`` and ``after``."""
    t = _transition(env, before, after)
    soles = t.soles.copy()
    for foot, ahead in enumerate(ahead_m):
        soles[foot, :, 0] += t.torso[0] + ahead - soles[foot, :, 0].mean()
    t.soles = soles
    return TERMS["kreach"](t)


def test_kreach_charges_each_landing_foots_miss_of_the_clocks_reach():
    """R* = (1 - 0.4) x 0.4 m = 0.24 m: a foot landing there costs 0, one landing 0.04 m ahead of the
    torso (0.2 m short) 0.2^2 / 0.4 = 0.1, two such 0.2; a foot that was down already, or lifts, costs
    nothing. Standing still (L* = 0) a landing costs r^2 / env.step_length_m; without a clock, 0."""
    env = PamWalkerEnv(env={**CLOCK, "step_length_m": 0.4}, reward={"kreach": 2.0})
    env.reset(seed=0)
    assert landing_reach_m(0.4, 0.4) == pytest.approx(0.24)
    assert _landing(env, (0.24, -0.3), (False, True), (True, True)) == pytest.approx(0.0, abs=1e-12)
    assert _landing(env, (0.04, -0.3), (False, True), (True, True)) == pytest.approx(-0.1)
    assert _landing(env, (0.04, 0.04), (False, False), (True, True)) == pytest.approx(-0.2)
    assert _landing(env, (0.04, -0.3), (True, True), (True, True)) == 0.0
    assert _landing(env, (0.04, -0.3), (True, True), (False, True)) == 0.0
    env.close()
    still = PamWalkerEnv(env={**CLOCK, "step_length_m": 0.4, "gait_follows_speed": True, "target_speed_m_s": 0.0})
    still.reset(seed=0)
    assert _landing(still, (0.1, 0.0), (False, True), (True, True)) == pytest.approx(-0.1 ** 2 / 0.4)
    still.close()
    plain = PamWalkerEnv()
    plain.reset(seed=0)
    assert _landing(plain, (0.04, -0.3), (False, True), (True, True)) == 0.0
    plain.close()


@pytest.mark.parametrize("key, bad", [("knee_path_peak_deg", 0.0), ("knee_path_peak_deg", -10.0),
                                      ("knee_path_peak_deg", 150.0), ("push_off_peak_deg", 0.0),
                                      ("push_off_peak_deg", -5.0), ("push_off_peak_deg", 60.0),
                                      ("hip_path_peak_deg", 0.0), ("hip_path_peak_deg", 50.0),
                                      ("hip_extension_deg", -5.0), ("hip_extension_deg", 50.0)])
def test_bad_path_peak_fails_naming_the_key(key, bad):
    with pytest.raises(ConfigError, match=key):
        PamWalkerEnv(env={**CLOCK, key: bad})


def test_the_push_off_plantarflexes_the_ankle_to_its_peak_at_lift_off():
    """Each ankle is wanted over the last PUSH_OFF_SHARE of its period before lift-off, rising to the
    peak at lift-off, and over the same share after it, falling back to 0; free (None) through the rest;
    the left's is the right's half a period later."""
    share, peak = 0.4, math.radians(20)
    lift_off = 0.25 - share / 2  # the right foot's
    assert push_off_path_rad(lift_off, share, peak)[0] == pytest.approx(peak)
    wanted = [push_off_path_rad(p, share, peak)[0] for p in np.arange(0, 1, 0.001)]
    assert np.mean([w is not None for w in wanted]) == pytest.approx(2 * PUSH_OFF_SHARE, abs=0.002)
    rising = [push_off_path_rad(lift_off - PUSH_OFF_SHARE + d, share, peak)[0] for d in np.linspace(0.005, PUSH_OFF_SHARE - 0.005, 14)]
    falling = [push_off_path_rad(lift_off + d, share, peak)[0] for d in np.linspace(0.0, PUSH_OFF_SHARE - 0.005, 14)]
    assert np.all(np.diff(rising) > 0) and np.all(np.diff(falling) < 0)
    assert rising[0] < 0.01 * peak and falling[-1] < 0.01 * peak
    assert push_off_path_rad(lift_off + share, share, peak)[0] is None  # touchdown: free
    assert push_off_path_rad(lift_off - 0.3, share, peak)[0] is None  # mid-stance: free
    for d in (-0.05, 0.02, 0.1):
        assert push_off_path_rad(lift_off + d + 0.5, share, peak)[1] == pytest.approx(push_off_path_rad(lift_off + d, share, peak)[0])


def _ankles_posed(env, ankles_rad) -> float:
    return _posed(env, "kpush", env.ankle_addresses, ankles_rad)


def test_kpush_pays_the_ankles_on_the_clocks_push_off():
    """At the right foot's lift-off, its ankle plantarflexed to the peak pays 1, held neutral (a full miss)
    1/2, a quarter of the peak short 1 - 1/8; the left ankle, free in its swing, changes nothing. With the
    clock stopped it pays 1; without a clock 0. In info under kpush, weighted."""
    env = PamWalkerEnv(env={**CLOCK, "push_off_peak_deg": 20.0}, reward={"kpush": 3.0})
    env.reset(seed=0)
    env.episode.phase0 = 0.05  # the right foot's lift-off (0.25 - 0.4 / 2); the left mid-stance, free
    wanted = push_off_path_rad(env.episode.phase(env.env_cfg), env.env_cfg.swing_share, math.radians(20))
    assert wanted[0] == pytest.approx(math.radians(20)) and wanted[1] is None
    assert _ankles_posed(env, [wanted[0], 0.0]) == pytest.approx(1.0)
    assert _ankles_posed(env, [wanted[0], -0.5]) == pytest.approx(1.0)
    assert _ankles_posed(env, [0.0, 0.0]) == pytest.approx(0.5)
    assert _ankles_posed(env, [wanted[0] - math.radians(5), 0.0]) == pytest.approx(1.0 - 0.5 * 0.25)
    *_, info = env.step(np.zeros(10))
    assert 0.0 <= info["reward_unweighted"]["kpush"] <= 1.0
    assert info["reward_terms"]["kpush"] == pytest.approx(3.0 * info["reward_unweighted"]["kpush"])
    env.close()
    stopped, plain = _stopped_and_clockless("kpush", 8)
    assert stopped == [1.0] * 8 and plain == 0.0


def test_the_hip_path_flexes_a_swinging_thigh_and_retracts_it_before_touchdown():
    """Through a leg's swing its hip is wanted from 0 at lift-off to the scaled peak flexion (negative)
    0.6 into the swing, back to 5/6 of it at touchdown; free (None) in its stance; scaled by the step's
    share; the left's is the right's half a period later."""
    share, peak = 0.4, math.radians(30)
    lift_off = 0.25 - share / 2
    swing = [hip_path_rad(lift_off + u * share, share, peak, 1.0)[0] for u in np.linspace(0.0, 0.999, 200)]
    top = int(np.argmin(swing))
    assert swing[0] == pytest.approx(0.0, abs=1e-9) and min(swing) == pytest.approx(-peak, rel=1e-3)
    assert top / 199 == pytest.approx(HIP_PEAK_SWING_SHARE, abs=0.01)
    assert np.all(np.diff(swing[:top + 1]) < 0) and np.all(np.diff(swing[top:]) > 0)
    assert swing[-1] == pytest.approx(-peak * 5 / 6, rel=1e-3)
    assert hip_path_rad(lift_off + 0.6 * share, share, peak, 0.5)[0] == pytest.approx(-0.5 * peak)
    assert hip_path_rad(lift_off + share + 0.1, share, peak, 1.0)[0] is None
    for u in (0.2, 0.7):
        assert hip_path_rad(lift_off + u * share + 0.5, share, peak, 1.0)[1] == pytest.approx(
            hip_path_rad(lift_off + u * share, share, peak, 1.0)[0])


def test_khip_pays_the_swinging_hips_on_the_clocks_hip_path():
    """At the right leg's peak flexion, its hip on the path pays 1, held straight (a full miss) 1/2,
    a quarter of the peak off 1 - 1/8; the left hip, in stance, changes nothing. Stopped clock: 1; no clock: 0."""
    env = PamWalkerEnv(env={**CLOCK, "hip_path_peak_deg": 30.0}, reward={"khip": 2.0})
    env.reset(seed=0)
    env.episode.phase0 = 0.05 + 0.6 * 0.4  # 0.6 into the right leg's swing; the left in stance
    assert env.episode.step_length_m == pytest.approx(env.env_cfg.step_length_m)
    wanted = hip_path_rad(env.episode.phase(env.env_cfg), env.env_cfg.swing_share, math.radians(30), 1.0)
    assert wanted[0] == pytest.approx(-math.radians(30)) and wanted[1] is None
    assert _posed(env, "khip", env.hip_addresses, [wanted[0], 0.0]) == pytest.approx(1.0)
    assert _posed(env, "khip", env.hip_addresses, [wanted[0], 0.3]) == pytest.approx(1.0)
    assert _posed(env, "khip", env.hip_addresses, [0.0, 0.0]) == pytest.approx(0.5)
    assert _posed(env, "khip", env.hip_addresses, [wanted[0] + math.radians(7.5), 0.0]) == pytest.approx(1.0 - 0.5 * 0.25)
    *_, info = env.step(np.zeros(10))
    assert info["reward_terms"]["khip"] == pytest.approx(2.0 * info["reward_unweighted"]["khip"])
    env.close()
    stopped, plain = _stopped_and_clockless("khip", 8)
    assert stopped == [1.0] * 8 and plain == 0.0
