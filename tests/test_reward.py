"""The reward as named terms (pamrun.task.reward), the per-step measures it shares with the gait
metrics (pamrun.task.measures), and replay buffers saved with the terms as one array."""

from __future__ import annotations

import math
from dataclasses import fields

import mujoco
import numpy as np
import pytest
import torch

from pamrun.config import BodyConfig, MuscleConfig, RewardConfig, as_config
from pamrun.evaluation.metrics import GaitSpec, foot_slip_m_s, knee_swing_stop_share, stop_shares
from pamrun.physics.actuation import muscle_counts
from pamrun.physics.body import JOINTS
from pamrun.task import reward as reward_mod
from pamrun.task.env import PamWalkerEnv
from pamrun.task.measures import (
    KNEES,
    at_stops,
    ground_point_shift_m,
    sole_tilt_rad,
    stop_bounds,
    stop_nearness,
    stop_share,
)
from pamrun.task.reward import REWARD_KEYS, TERMS, Reward, check_terms
from tests.test_train import TINY, train_here

LIMITS = np.tile([-0.5, 0.5], (len(JOINTS), 1))  # every joint: +-0.5 rad
BOUNDS = stop_bounds(LIMITS, 0.1)  # at a stop outside +-0.4 rad


def test_every_weight_has_a_term_and_every_term_a_weight():
    """The reward's terms are RewardConfig's weights, key for key, in its field order; a weight
    without a term, or a term without a weight, fails."""
    assert REWARD_KEYS == tuple(f.name for f in fields(RewardConfig)) and set(TERMS) == set(REWARD_KEYS)
    check_terms()
    with pytest.raises(ValueError, match=r"weights without a term: \['kjump'\]"):
        check_terms((*REWARD_KEYS, "kjump"))
    with pytest.raises(ValueError, match=rf"without a weight in RewardConfig: \['{REWARD_KEYS[-1]}'\]"):
        check_terms(REWARD_KEYS[:-1])


def test_reward_sums_weight_times_term_by_key_and_skips_unweighted_terms(monkeypatch):
    """Weights meet their terms by key, never by position; a term whose weight is 0 is not called
    (its feature is 0) unless a reader asks for it; a blown-up step's features are all 0."""
    called = []
    for key in REWARD_KEYS:
        monkeypatch.setitem(TERMS, key, lambda t, key=key: called.append(key) or float(REWARD_KEYS.index(key) + 1))
    weights = {k: 0.0 for k in REWARD_KEYS} | {"kz": 2.0, "kvx": 0.5}
    reward = Reward(RewardConfig(**weights), features=["kslip"])
    total, terms, features = reward(object())
    assert called == ["kvx", "kz", "kslip"] and reward.computed == ("kvx", "kz", "kslip")
    assert features == {k: 0.0 for k in REWARD_KEYS} | {"kvx": 1.0, "kz": 3.0, "kslip": 10.0}
    assert terms["kz"] == 6.0 and terms["kslip"] == 0.0 and total == 0.5 + 6.0
    assert Reward(RewardConfig(**weights))(None) == (0.0, dict.fromkeys(REWARD_KEYS, 0.0), dict.fromkeys(REWARD_KEYS, 0.0))
    with pytest.raises(ValueError, match="unknown reward features"):
        Reward(RewardConfig(), features=["kjump"])


def test_stop_share_counts_hips_ankles_and_swinging_knees():
    """kstop's share: hips and ankles within the margin of a stop, and the knee of a leg whose foot
    is off the ground (a knee in stance rests on its lock by design)."""
    q = np.full(len(JOINTS), 0.45)  # every joint past its upper bound
    assert at_stops(q, BOUNDS).all() and not at_stops(np.zeros(len(JOINTS)), BOUNDS).any()
    assert at_stops([[-0.4, 0.39] + [0.0] * 8], BOUNDS)[0, :2].tolist() == [True, False]  # on the bound counts
    assert stop_share(q, BOUNDS, [True, True]) == 1.0
    q[KNEES[0]] = 0.0
    assert stop_share(q, BOUNDS, [True, True]) == 1.0  # the mid-range knee is in stance: not counted
    q[0] = 0.0
    assert stop_share(q, BOUNDS, [True, True]) == pytest.approx(7 / 8)
    assert stop_share(q, BOUNDS, [True, False]) == pytest.approx(8 / 9)  # the left knee swings, at its stop
    assert stop_share(q, BOUNDS, [False, True]) == pytest.approx(7 / 9)  # the right knee swings, mid-range


def test_gait_metrics_stop_shares_use_the_same_bounds():
    """The gait metrics count a joint at its stop where kstop does: per joint over rows, and the
    knees in swing."""
    spec = GaitSpec(dt_s=0.025, joint_limits_rad=LIMITS, mass_kg=10.0, muscles_per_side=1, nominal_length_m=0.2,
                    inner_diameter_m=0.02, stop_margin_rad=0.1)
    q = np.zeros((4, len(JOINTS)))
    q[:2, 0], q[1:, KNEES[1]] = 0.45, -0.41
    assert stop_shares(q, spec)[[0, 1, KNEES[1]]].tolist() == [0.5, 0.0, 0.75]
    contact = np.array([[True, True], [True, False], [False, False], [True, True]])
    assert knee_swing_stop_share(q, contact, spec) == pytest.approx(2 / 3)  # left swings in rows 1, 2; right in 2


def _feet(lowest_z: float = 0.0) -> np.ndarray:
    """(2, 4, 3): four contact points per foot, the first the lowest."""
    soles = np.zeros((2, 4, 3))
    soles[:, :, 0] = [0.0, 0.1, 0.0, 0.1]
    soles[:, :, 2] = [lowest_z, 0.01, 0.01, 0.01]
    return soles


def test_ground_point_shift_follows_the_lowest_point():
    """A foot's slip is how far the point lowest before the step slides: a foot rolling (its
    other points moving) does not slip; one sliding 3 cm sideways and 4 cm forward slips 5 cm."""
    before, after = _feet(), _feet()
    after[0, 1:, 2] += 0.05  # the right foot rolls over its lowest point
    after[1, :, :2] += [0.04, 0.03]  # the left foot slides
    shift = ground_point_shift_m(before, after)
    assert shift.shape == (2, 2) and shift[0].tolist() == [0.0, 0.0]
    assert np.linalg.norm(shift[1]) == pytest.approx(0.05)
    rows = {"t_s": [0.0, 0.5], "sole_xyz_m": [before, after]}
    assert foot_slip_m_s(rows, np.ones((2, 2), bool)) == pytest.approx((0.0 + 0.1) / 2)  # per foot, averaged
    t = reward_mod.Transition(env=type("E", (), {"env_cfg": type("C", (), {"control_dt_s": 0.5})})(), episode=None,
                              torso=(), qpos=[], action=np.zeros(1), previous=np.zeros(1), soles_before=before,
                              soles=after, contact_before=[True, True], contact=[True, True], forces_n=[1.0, 1.0])
    assert reward_mod.slip(t) == pytest.approx(-0.1)  # summed over the feet
    t.contact_before = [True, False]  # the left foot touched down: no slip
    assert reward_mod.slip(t) == 0.0


def test_muscle_counts_are_physics_one_definition():
    """The gait metrics' (and the env's air meter's) muscles per joint are physics.actuation's."""
    muscle = as_config({"count": {"knee": 2}}, MuscleConfig)
    expected = [getattr(muscle.count, name.split("_", 1)[1]) for name in JOINTS]
    assert muscle_counts(muscle).tolist() == expected and muscle_counts(muscle)[KNEES].tolist() == [2.0, 2.0]
    spec = GaitSpec.from_configs(BodyConfig(), muscle, 30.0, 0.025)
    assert spec.muscles_per_side.tolist() == muscle_counts(muscle).tolist()


@pytest.mark.slow
def test_a_checkpoint_with_the_terms_as_one_array_resumes(tmp_path):
    """A resume state saved when the buffer held the reward's terms as one (n, 13) array (pamrun
    before the terms had names) resumes: each column becomes the term of its key."""
    from tensordict import TensorDict
    from torchrl.data import LazyTensorStorage, TensorDictReplayBuffer

    from pamrun.learning.checkpoints import ARRAY_TERMS, file_fingerprints
    from pamrun.learning.curriculum import FEATURES
    from pamrun.runs.directory import LAST, saved_config

    run = tmp_path / "run"
    assert train_here(run, *TINY, "train.max_frames=400", "train.eval_every_frames=0") == "max_frames"
    state = torch.load(run / "checkpoints" / LAST, weights_only=True)
    folder = run / "checkpoints" / state["buffer"]["dir"]
    size = saved_config(run).train.buffer_size
    buffer = TensorDictReplayBuffer(storage=LazyTensorStorage(size))
    buffer.loads(folder)
    named = buffer.storage._storage.get(("next", FEATURES))
    columns = torch.stack([named[k] for k in ARRAY_TERMS], dim=-1)  # the old writer's layout
    buffer.storage._storage.del_(("next", FEATURES))
    buffer.storage._storage.set(("next", FEATURES), columns)
    buffer.dumps(folder)
    state["buffer"]["files"] = file_fingerprints(folder)
    torch.save(state, run / "checkpoints" / LAST)

    assert train_here(run, f"resume={run}", "train.max_frames=600") == "max_frames"
    resumed = TensorDictReplayBuffer(storage=LazyTensorStorage(size))
    state = torch.load(run / "checkpoints" / LAST, weights_only=True)
    resumed.loads(run / "checkpoints" / state["buffer"]["dir"])
    terms = resumed.storage._storage.get(("next", FEATURES))
    assert isinstance(terms, TensorDict) and set(terms.keys()) == set(REWARD_KEYS)
    n = len(buffer)
    for i, key in enumerate(ARRAY_TERMS):
        assert torch.equal(terms[key][:n], columns[:n, i]), key
    assert math.isclose(float(terms["kt"][n - 1]), 0.025 / 10) or float(terms["kt"][n - 1]) == 0.0


def test_flight_term_charges_a_step_with_no_foot_down():
    """reward.kflight: 0 while the robot stands on its feet, -1 a step once it is lifted clear of
    the floor (the env's own contact rule), weighted into the reward."""
    import gymnasium as gym

    env = gym.make("pamrun/PamWalker-v0", reward={"kflight": 2.0}).unwrapped
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape)
    _, r_stand, *_, info = env.step(zero)
    assert info["reward_unweighted"]["kflight"] == 0.0
    env.data.qpos[2] += 0.5  # the free joint's height: both feet 0.5 m up
    env.data.qvel[:] = 0.0
    _, r_air, *_, info = env.step(zero)
    assert info["reward_unweighted"]["kflight"] == -1.0 and info["reward_terms"]["kflight"] == -2.0
    env.close()


def test_flat_term_charges_the_feet_on_the_ground_for_standing_on_an_edge():
    """reward.kflat: near 0 for the robot standing on its soles; with the robot lifted so the
    spheres of one edge of each sole are 2 cm above those of the other, the feet's contact (the
    env's) decides which tilts count: none in the air."""
    import gymnasium as gym

    env = gym.make("pamrun/PamWalker-v0", reward={"kflat": 2.0}).unwrapped
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape)
    _, _, *_, info = env.step(zero)
    standing = info["reward_unweighted"]["kflat"]
    assert -math.radians(1.0) < standing <= 0.0 and info["reward_terms"]["kflat"] == 2.0 * standing
    env.data.qpos[2] += 0.5  # both feet 0.5 m up: no foot on the ground, whatever its tilt
    env.data.qvel[:] = 0.0
    _, _, *_, info = env.step(zero)
    assert info["reward_unweighted"]["kflat"] == 0.0
    env.close()


def test_level_term_charges_a_swinging_foot_rolled_at_its_ankle():
    """reward.klevel in real steps: on the ground it pays 0 (the tilt is kflat's); the robot held 0.3 m
    up pays minus its soles' summed tilt at the step's end, weighted in info, and more with its right
    ankle rolled 0.5 rad at the step's start than with its ankles at rest."""
    import gymnasium as gym

    env = gym.make("pamrun/PamWalker-v0", reward={"klevel": 2.0, "kflat": 1.0}).unwrapped
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape)
    *_, info = env.step(zero)
    assert info["reward_unweighted"]["klevel"] == 0.0
    roll = env.model.jnt_qposadr[mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_JOINT, "right_ankle_roll")]
    paid = []
    for rolled in (0.0, -0.5):
        env.reset(seed=0)
        env.data.qpos[2] += 0.3
        env.data.qpos[roll] = rolled
        env.data.qvel[:] = 0.0
        mujoco.mj_forward(env.model, env.data)
        *_, info = env.step(zero)
        assert info["reward_unweighted"]["kflat"] == 0.0
        tilt = sole_tilt_rad(env.episode.soles)
        assert info["reward_unweighted"]["klevel"] == pytest.approx(-np.abs(tilt).sum())
        assert info["reward_terms"]["klevel"] == 2.0 * info["reward_unweighted"]["klevel"]
        paid.append(info["reward_unweighted"]["klevel"])
    assert paid[0] == pytest.approx(0.0, abs=0.01) and paid[1] < -0.02
    env.close()


def test_stop_nearness_charges_each_joint_from_its_band_on():
    """measures.stop_nearness on joint angles set by hand (limits +-0.5 rad, band 0.2 rad): a joint on
    its limit or past it counts 1, one 0.1 rad inside 0.25, one at the band's edge or further in 0;
    each joint counts on its own (two at a stop: 2), and a knee counts only with its foot off the
    ground. In a real env step, reward.knear is the nearness of the env's own limits, 10 deg."""
    q = np.zeros(len(JOINTS))
    assert stop_nearness(q, LIMITS, 0.2, [True, True]) == 0.0
    ankle_roll, hip_roll = JOINTS.index("right_ankle_roll"), JOINTS.index("left_hip_roll")
    q[ankle_roll] = -0.5
    assert stop_nearness(q, LIMITS, 0.2, [True, True]) == pytest.approx(1.0)
    q[ankle_roll] = -0.7
    assert stop_nearness(q, LIMITS, 0.2, [True, True]) == pytest.approx(1.0)
    q[hip_roll] = 0.4
    assert stop_nearness(q, LIMITS, 0.2, [True, True]) == pytest.approx(1.25)
    q[hip_roll] = 0.3
    assert stop_nearness(q, LIMITS, 0.2, [True, True]) == pytest.approx(1.0)
    q[KNEES[0]] = 0.5  # the right knee on its stop: charged only in swing
    assert stop_nearness(q, LIMITS, 0.2, [True, True]) == pytest.approx(1.0)
    assert stop_nearness(q, LIMITS, 0.2, [False, True]) == pytest.approx(2.0)
    assert stop_share(q, stop_bounds(LIMITS, 0.1), [False, True]) == pytest.approx(2 / 9)  # kstop's share: thin

    env = PamWalkerEnv(reward={"knear": 3.0})
    env.reset(seed=0)
    roll = env.qpos_addresses[ankle_roll]
    low = env.joint_limits_rad[ankle_roll][0]
    for offset_deg, expected in ((0.0, 1.0), (5.0, 0.25), (12.0, 0.0)):
        env.data.qpos[roll] = low + math.radians(offset_deg)
        t = reward_mod.Transition(env=env, episode=None, torso=(), qpos=env.data.qpos.tolist(), action=np.zeros(1),
                                  previous=np.zeros(1), soles_before=None, soles=None, contact_before=[True, True],
                                  contact=[True, True], forces_n=[400.0, 400.0])
        others = stop_nearness([env.data.qpos[a] for a in env.qpos_addresses], env.joint_limits_rad, math.radians(10),
                               [True, True]) - expected
        assert reward_mod.TERMS["knear"](t) == pytest.approx(-expected - others)
        assert others == pytest.approx(0.0, abs=1e-9)  # the standing pose is clear of every band
    _, _, _, _, info = env.step(np.zeros(10))
    assert info["reward_terms"]["knear"] == pytest.approx(3.0 * info["reward_unweighted"]["knear"])
    env.close()


def test_sole_tilt_of_known_corners():
    """pamrun.task.measures.sole_tilt_rad on corners laid out by hand: a 0.1 m wide sole with its
    left edge 0.1 m x tan(0.2) higher tilts +0.2 rad, the mirror image -0.2, a flat one 0."""
    rise = 0.1 * math.tan(0.2)
    foot = np.array([[0.1, 0.05, rise], [0.1, -0.05, 0.0], [-0.1, 0.05, rise], [-0.1, -0.05, 0.0]])
    mirrored = foot.copy()
    mirrored[:, 2] = rise - foot[:, 2]
    flat = foot.copy()
    flat[:, 2] = 0.3
    assert sole_tilt_rad(np.stack([foot, mirrored])) == pytest.approx([0.2, -0.2])
    assert sole_tilt_rad(np.stack([flat, flat])) == pytest.approx([0.0, 0.0], abs=1e-12)
    t = reward_mod.Transition(env=None, episode=None, torso=(), qpos=[], action=np.zeros(1), previous=np.zeros(1),
                              soles_before=np.stack([foot, mirrored]), soles=np.stack([foot, mirrored]),
                              contact_before=[True, True], contact=[True, False], forces_n=[300.0, 0.0])
    assert reward_mod.TERMS["kflat"](t) == pytest.approx(-0.2)
    t.contact = [True, True]
    assert reward_mod.TERMS["kflat"](t) == pytest.approx(-0.4)
    assert reward_mod.TERMS["klevel"](t) == 0.0
    t.contact = [False, True]
    assert reward_mod.TERMS["kflat"](t) == pytest.approx(-0.2) and reward_mod.TERMS["klevel"](t) == pytest.approx(-0.2)
    t.contact = [False, False]
    assert reward_mod.TERMS["kflat"](t) == 0.0 and reward_mod.TERMS["klevel"](t) == pytest.approx(-0.4)
    t.soles = np.stack([flat, flat])
    assert reward_mod.TERMS["klevel"](t) == pytest.approx(0.0, abs=1e-12)


def test_landing_term_charges_the_feet_that_touch_down_and_slip_those_already_down():
    """reward.kland: the horizontal speed over the step of a foot that lands in it (off the ground at
    its start, on it at its end); kslip the same for a foot on the ground at both ends; a foot in the
    air at the end counts in neither."""
    from types import SimpleNamespace

    env = SimpleNamespace(env_cfg=SimpleNamespace(control_dt_s=0.025))
    before = np.zeros((2, 4, 3))
    after = before.copy()
    after[0, :, 0] += 0.02  # the right foot moves 2 cm forward in the step: 0.8 m/s
    after[1, :, 1] += 0.01  # the left 1 cm sideways: 0.4 m/s

    def step(contact_before, contact):
        t = reward_mod.Transition(env=env, episode=None, torso=(), qpos=[], action=np.zeros(1), previous=np.zeros(1),
                                  soles_before=before, soles=after, contact_before=contact_before, contact=contact,
                                  forces_n=[0.0, 0.0])
        return reward_mod.TERMS["kland"](t), reward_mod.TERMS["kslip"](t)

    assert step([False, True], [True, True]) == pytest.approx((-0.8, -0.4))  # right lands, left slides
    assert step([True, False], [True, True]) == pytest.approx((-0.4, -0.8))  # left lands, right slides
    assert step([False, False], [False, True]) == pytest.approx((-0.4, 0.0))
    assert step([True, True], [False, False]) == (0.0, 0.0)  # both lift off


def test_a_robot_dropped_moving_forward_is_charged_for_its_landing():
    """In the env: standing, no foot lands (kland 0); lifted 2 cm and thrown forward at 1 m/s, its
    feet land in one step, moving, and that step alone is charged."""
    import gymnasium as gym

    env = gym.make("pamrun/PamWalker-v0", reward={"kland": 1.0}).unwrapped
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape)
    env.step(zero)  # the reset pose has no contact force yet: the feet 'land' in the first step, settling
    _, _, *_, info = env.step(zero)
    assert info["reward_unweighted"]["kland"] == 0.0
    env.data.qpos[2] += 0.02
    env.data.qvel[:] = 0.0
    env.data.qvel[0] = 1.0  # the free joint's forward velocity
    landings = []
    for _ in range(8):
        _, _, *_, info = env.step(zero)
        landings.append(info["reward_unweighted"]["kland"])
    env.close()
    charged = [v for v in landings if v != 0.0]
    assert 1 <= len(charged) <= 2 and min(charged) < -0.5, landings


def test_upright_term_charges_the_torsos_tilt_and_not_its_heading():
    """reward.kupright: -(roll^2 + pitch^2) of the torso after the step, read from the env's own torso
    values; near 0 standing upright, -(0.2^2) with the robot lifted and pitched 0.2 rad, and the same
    turned 1 rad about the vertical."""
    import gymnasium as gym

    env = gym.make("pamrun/PamWalker-v0", reward={"kupright": 3.0}).unwrapped
    env.reset(seed=0)
    zero = np.zeros(env.action_space.shape)
    _, _, *_, info = env.step(zero)
    standing = info["reward_unweighted"]["kupright"]
    assert -math.radians(2.0) ** 2 < standing <= 0.0 and info["reward_terms"]["kupright"] == 3.0 * standing

    def tilted(yaw: float) -> dict:
        env.reset(seed=0)
        half_pitch, half_yaw = 0.1, yaw / 2  # a quaternion turning 0.2 rad about y, then yaw about z
        qy = np.array([math.cos(half_pitch), 0.0, math.sin(half_pitch), 0.0])
        qz = np.array([math.cos(half_yaw), 0.0, 0.0, math.sin(half_yaw)])
        quat = np.empty(4)
        mujoco.mju_mulQuat(quat, qz, qy)
        env.data.qpos[2] += 1.0  # in the air, so that the tilt holds over the step
        env.data.qpos[3:7] = quat
        env.data.qvel[:] = 0.0
        return env.step(zero)[4]

    info = tilted(0.0)
    assert info["reward_unweighted"]["kupright"] == pytest.approx(-0.2 ** 2, abs=2e-3)
    # + pitch leans forward: the torso's up axis tips toward +x, and info reports it (torso_pitch_deg's)
    torso = mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_BODY, "torso")
    assert env.data.xmat[torso].reshape(3, 3)[0, 2] > 0.15
    assert info["torso_rpy_rad"][1] == pytest.approx(0.2, abs=2e-3)
    turned = tilted(1.0)["reward_unweighted"]["kupright"]
    assert turned == pytest.approx(tilted(0.0)["reward_unweighted"]["kupright"], abs=1e-6)
    env.close()


def test_track_term_pays_kspeeds_bell_at_its_own_narrower_sigma():
    """reward.ktrack: exp(-((Vx - v*) / env.track_sigma_m_s)^2) of the torso's forward speed after the
    step. Lifted and moving at 0.8 m/s when told 1.0, it earns about half of its top at sigma 0.25 (kspeed,
    at sigma 0.5: 85 %); at the same sigma the two terms are the same."""
    def step_at(vx: float, sigma: float) -> tuple[float, dict]:
        env = PamWalkerEnv(env={"target_speed_m_s": 1.0, "track_sigma_m_s": sigma}, features=["kspeed", "ktrack"])
        env.reset(seed=0)
        env.data.qpos[2] += 1.0  # in the air: nothing slows it in one step
        env.data.qvel[:] = 0.0
        env.data.qvel[0] = vx
        info = env.step(np.zeros(env.action_space.shape))[4]
        speed = float(env.data.qvel[0])
        env.close()
        return speed, info["reward_unweighted"]

    speed, f = step_at(0.8, 0.25)
    assert speed == pytest.approx(0.8, abs=0.01)
    assert f["ktrack"] == pytest.approx(math.exp(-((speed - 1.0) / 0.25) ** 2), rel=1e-6)
    assert 0.45 < f["ktrack"] < 0.6 < 0.8 < f["kspeed"] < 0.9
    _, same = step_at(0.8, 0.5)
    assert same["ktrack"] == same["kspeed"]
