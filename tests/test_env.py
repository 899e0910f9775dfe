"""PamWalker-v0: spaces, observation layout, reward, termination, seeding, API checks."""

from __future__ import annotations

import functools
import math
import pickle
from dataclasses import asdict

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import pamrun  # noqa: F401  (registers the env)
from pamrun.config import CAMERAS, ConfigError, RewardConfig
from pamrun.physics.body import JOINTS
from pamrun.task.env import PamWalkerEnv
from pamrun.task.observation import quat_to_euler
from tests.conftest import thesis_muscle


@pytest.fixture(scope="module")
def env():
    e = gym.make("pamrun/PamWalker-v0")
    yield e
    e.close()


def test_spaces_and_registration(env):
    assert env.observation_space.shape == (43,)
    assert env.action_space.shape == (10,)
    assert np.all(env.action_space.low == -1) and np.all(env.action_space.high == 1)
    assert env.unwrapped.max_steps == 400  # Tf / Ts = 10 s / 0.025 s


def test_check_env():
    e = PamWalkerEnv()
    check_env(e, skip_render_check=True)
    e.close()


def test_observation_layout_matches_state(env):
    obs, info = env.reset(seed=0)
    u = env.unwrapped
    d = u.data
    obs, *_ = env.step(np.full(10, 0.3, dtype=np.float32))
    assert obs[0] == pytest.approx(d.qpos[1], abs=1e-6)  # y
    assert obs[1] == pytest.approx(d.qpos[2], abs=1e-6)  # z
    roll, pitch, yaw = quat_to_euler(d.qpos[3:7])
    np.testing.assert_allclose(obs[2:5], [roll, pitch, yaw], atol=1e-6)
    np.testing.assert_allclose(obs[5:8], d.qvel[0:3], atol=1e-5)
    np.testing.assert_allclose(obs[8:11], d.qvel[3:6], atol=1e-5)
    np.testing.assert_allclose(obs[11:21], d.qpos[u.qpos_idx], atol=1e-6)
    np.testing.assert_allclose(obs[21:31], d.qvel[u.qvel_idx], atol=1e-4)
    np.testing.assert_allclose(obs[31:33], u.foot_forces_n() / u.weight_n, atol=1e-5)
    # The touch sensors agree with MuJoCo's contact forces summed per foot.
    contact = np.zeros(2)
    wrench = np.zeros(6)
    feet = [u.model.body(f).id for f in ("right_foot", "left_foot")]
    for i in range(d.ncon):
        body_id = u.model.geom_bodyid[d.contact[i].geom1 if d.contact[i].geom2 == 0 else d.contact[i].geom2]
        mujoco.mj_contactForce(u.model, d, i, wrench)
        contact[feet.index(body_id)] += wrench[0]
    np.testing.assert_allclose(u.foot_forces_n(), contact, rtol=0.2, atol=5.0)
    np.testing.assert_allclose(obs[33:43], 0.3, atol=1e-6)
    # Joint order is the documented one.
    names = [u.model.joint(int(j)).name for j in u.model.dof_jntid[u.qvel_idx]]
    assert names == list(JOINTS)
    # The named blocks are exactly these slices, in order, covering the whole observation.
    structure = u.observation_structure
    assert structure["joint_angle"] == slice(11, 21) and structure["previous_action"] == slice(33, 43)
    assert [s.start for s in structure.values()][1:] == [s.stop for s in structure.values()][:-1]
    assert list(structure.values())[-1].stop == obs.shape[0]


def test_standing_feet_carry_the_weight(env):
    env.reset(seed=0)
    obs = None
    for _ in range(4):
        obs, *_ = env.step(np.zeros(10, dtype=np.float32))
    assert obs[31] + obs[32] == pytest.approx(1.0, abs=0.25)


def test_reward_is_its_weights_times_unweighted_terms(env):
    """info holds each term unweighted (``reward_unweighted``) and weighted (``reward_terms``),
    both by weight key; the features are the state's quantities (Table 9.3's Vx, y^2,
    (z - z0)^2, sum(a^2), Ts / Tf) and the reward is the weights' sum over them, in
    RewardConfig's order; a term whose weight is 0 is not computed (its feature is 0)."""
    from pamrun.task.reward import REWARD_KEYS

    _, info0 = env.reset(seed=1)
    assert info0["reward_unweighted"] == dict.fromkeys(REWARD_KEYS, 0.0)  # reset: the same keys, zeros
    action = np.linspace(-1, 1, 10).astype(np.float32)
    _, reward, _, _, info = env.step(action)
    u = env.unwrapped
    f = info["reward_unweighted"]
    assert list(f) == list(info["reward_terms"]) == list(REWARD_KEYS)
    assert f["kvx"] == u.data.qvel[0] and f["ky"] == -u.data.qpos[1] ** 2
    assert f["kz"] == pytest.approx(-(u.data.qpos[2] - u.z0) ** 2, abs=1e-15)
    assert f["kv"] == pytest.approx(-np.sum(action.astype(float) ** 2)) and f["kt"] == pytest.approx(0.025 / 10)
    assert u.reward_weights == {k: getattr(RewardConfig(), k) for k in REWARD_KEYS}
    assert reward == sum(u.reward_weights[k] * f[k] for k in REWARD_KEYS)
    assert info["reward_terms"] == {k: w * f[k] for k, w in u.reward_weights.items()}
    assert info["reward_terms"]["kt"] == pytest.approx(0.0625)  # Table 9.3: kt Ts / Tf = 25 x 0.025 / 10
    assert f["kda"] == 0.0 and "air_nl" not in info  # weight 0: neither computed nor metered
    asked = PamWalkerEnv(features=["kda", "kair"])
    asked.reset(seed=1)
    asked.step(np.zeros(10))
    _, again, _, _, info = asked.step(action)
    assert info["reward_unweighted"]["kda"] == pytest.approx(-np.sum(action.astype(float) ** 2))
    assert info["reward_unweighted"]["kair"] == -info["air_nl"] < 0 and info["reward_terms"]["kda"] == 0.0
    with pytest.raises(ValueError, match="kspeeed"):
        PamWalkerEnv(features=["kspeeed"])


def test_command_change_and_fall_terms():
    """kda penalises the change of the command since the last step (from zero at reset); kfall is
    paid once, on the step that ends the episode by a fall, and never otherwise."""
    e = PamWalkerEnv(reward={"kda": 0.5, "kfall": 100.0})
    e.reset(seed=0)
    first, second = np.full(10, 0.2, np.float32), np.full(10, -0.3, np.float32)
    _, r1, _, _, info1 = e.step(first)
    _, r2, _, _, info2 = e.step(second)
    assert info1["reward_terms"]["kda"] == pytest.approx(-0.5 * 10 * 0.2**2, rel=1e-6)
    assert info2["reward_terms"]["kda"] == pytest.approx(-0.5 * 10 * 0.5**2, rel=1e-6)
    assert info1["reward_terms"]["kfall"] == 0.0 and sum(info2["reward_terms"].values()) == pytest.approx(r2)
    rng = np.random.default_rng(0)
    for _ in range(400):  # full-band random commands throw the robot over within a second
        _, reward, terminated, truncated, info = e.step(rng.choice([-1.0, 1.0], 10).astype(np.float32))
        if terminated or truncated:
            break
        assert info["reward_terms"]["kfall"] == 0.0
    assert terminated and info["fell"] and info["reward_terms"]["kfall"] == -100.0
    e.close()


def test_action_filter_low_passes_the_command():
    """env.action_filter_alpha = 0.5: the applied command moves half-way to each action (from 0
    at reset), the observation's previous action and kda see the applied command, the regulator
    targets its pressures; 1 applies the action as it is."""
    e = PamWalkerEnv(reward={"kda": 1.0}, env={"action_filter_alpha": 0.5})
    ref = PamWalkerEnv()
    structure = e.observation_structure["previous_action"]
    for env in (e, ref):
        env.reset(seed=0)
    ones = np.ones(10, np.float32)
    obs, _, _, _, info = e.step(ones)
    assert obs[structure] == pytest.approx(np.full(10, 0.5)) and info["reward_terms"]["kda"] == pytest.approx(-10 * 0.25)
    obs, _, _, _, info = e.step(ones)
    assert obs[structure] == pytest.approx(np.full(10, 0.75)) and info["reward_terms"]["kda"] == pytest.approx(-10 * 0.0625)
    ref.step(np.full(10, 0.5, np.float32))
    ref.step(np.full(10, 0.75, np.float32))  # the same commands, unfiltered: the same state to float rounding
    np.testing.assert_allclose(e.data.qpos, ref.data.qpos, atol=1e-9)
    np.testing.assert_allclose(e.drive.pressure_kpa, ref.drive.pressure_kpa, atol=1e-6)
    e.reset(seed=0)
    obs, *_ = e.step(ones)
    assert obs[structure] == pytest.approx(np.full(10, 0.5))  # reset starts the filter from 0 again
    for bad in (0.0, 1.5):
        with pytest.raises(ConfigError, match="action_filter_alpha"):
            PamWalkerEnv(env={"action_filter_alpha": bad})
    e.close()
    ref.close()


def test_reward_weights_are_keyword_arguments():
    e = gym.make("pamrun/PamWalker-v0", reward={"kv": 1.0, "kt": 0.0})
    e.reset(seed=0)
    _, _, _, _, info = e.step(np.ones(10, dtype=np.float32))
    assert info["reward_terms"]["kv"] == pytest.approx(-10.0)
    assert info["reward_terms"]["kt"] == 0.0
    e.close()


def test_bad_keyword_values_fail_with_the_key():
    with pytest.raises(ConfigError, match="height_m"):
        PamWalkerEnv(body={"height_m": -1.0})
    with pytest.raises(Exception, match="kzz"):
        PamWalkerEnv(reward={"kzz": 1.0})


def _set_torso(env, **kw):
    u = env.unwrapped
    if "y" in kw:
        u.data.qpos[1] = kw["y"]
    if "z" in kw:
        u.data.qpos[2] = kw["z"]
    if "roll" in kw:
        r = kw["roll"]
        u.data.qpos[3:7] = [math.cos(r / 2), math.sin(r / 2), 0, 0]


@pytest.mark.parametrize(
    "case", [{"y": 0.6}, {"y": -0.6}, {"roll": math.pi / 3}, {"z_ratio": 0.3}],
)
def test_termination_cases(env, case):
    env.reset(seed=0)
    u = env.unwrapped
    if "z_ratio" in case:
        case = {"z": u.z0 * case["z_ratio"]}
    _set_torso(env, **case)
    assert u._fell()


def test_non_finite_physics_ends_the_episode_cleanly(env):
    env.reset(seed=0)
    u = env.unwrapped
    u.data.qvel[:] = np.nan
    obs, reward, terminated, truncated, info = env.step(np.zeros(10, dtype=np.float32))
    assert terminated and not truncated
    assert info["physics_error"]
    assert np.all(np.isfinite(obs)) and np.isfinite(reward)


def test_truncation_after_tf():
    e = PamWalkerEnv(env={"episode_s": 0.1})
    e.reset(seed=0)
    for k in range(4):
        _, _, terminated, truncated, _ = e.step(np.zeros(10, dtype=np.float32))
    assert truncated and not terminated


def test_seeding_is_reproducible():
    def rollout(seed):
        e = PamWalkerEnv(env={"reset_noise_rad": 0.05, "reset_velocity_noise": 0.1})
        obs, _ = e.reset(seed=seed)
        rng = np.random.default_rng(seed)
        out = [obs]
        for _ in range(20):
            obs, *_ = e.step(rng.uniform(-1, 1, 10).astype(np.float32))
            out.append(obs)
        return np.array(out)

    np.testing.assert_array_equal(rollout(3), rollout(3))
    assert not np.array_equal(rollout(3)[0], rollout(4)[0])


@pytest.mark.parametrize("coupling", ["thesis", "kinematic"])
def test_info_has_muscle_state(coupling):
    e = PamWalkerEnv(muscle={**asdict(thesis_muscle()), "coupling": coupling})
    e.reset(seed=0)
    _, _, _, _, info = e.step(np.ones(10, dtype=np.float32))
    assert info["pressure_kpa"].shape == (10, 2) and info["contraction_pct"].shape == (10, 2)
    # a = +1: V1 = 2.83 V -> 283 kPa, V2 = 1.41 V -> 141 kPa (thesis §9.5)
    np.testing.assert_allclose(info["pressure_kpa"][0], [283.0, 141.0])
    for key in ("x", "y", "z", "distance", "foot_force_n", "fell", "physics_error"):
        assert key in info


@pytest.mark.parametrize("camera", CAMERAS)
def test_render_rgb_array(camera):
    e = PamWalkerEnv(render_mode="rgb_array", width=160, height=120, camera=camera)
    e.reset(seed=0)
    frame = e.render()
    assert frame.shape == (120, 160, 3) and frame.std() > 5
    e.close()


def _legs_in(frame: np.ndarray) -> tuple[float, float]:
    """Where the robot's legs are in ``frame``: their mean column and the rows they span, each as a
    share of the frame's width or height (the legs are orange, red well above blue; floor and sky
    are grey and blue)."""
    rgb = frame.astype(int)
    rows, columns = np.nonzero(rgb[..., 0] > rgb[..., 2] + 40)
    if len(rows) == 0:
        return float("nan"), 0.0
    return float(columns.mean() / frame.shape[1]), float((rows.max() - rows.min() + 1) / frame.shape[0])


def test_follow_camera_keeps_the_robot_centred_and_the_fixed_one_stays():
    """The torso 1 m forward (qpos): the following camera keeps the legs mid-picture and as tall;
    the fixed one sees them move right (side-on, forward is to the right)."""
    seen = {}
    for camera in ("follow", "fixed"):
        e = PamWalkerEnv(render_mode="rgb_array", width=160, height=120, camera=camera)
        e.reset(seed=0)
        start = _legs_in(e.render())
        e.data.qpos[0] += 1.0
        mujoco.mj_forward(e.model, e.data)
        seen[camera] = start, _legs_in(e.render())
        e.close()
    (column, tall), (moved_column, moved_tall) = seen["follow"]
    assert abs(column - 0.5) < 0.05 and abs(moved_column - 0.5) < 0.05
    assert tall > 0.4 and abs(moved_tall - tall) < 0.05  # the legs fill a good part of the picture, then as much
    (column, tall), (moved_column, _) = seen["fixed"]
    assert abs(column - seen["follow"][0][0]) < 0.01 and abs(tall - seen["follow"][0][1]) < 0.01  # the same start
    assert moved_column > 0.75


def test_an_env_with_a_camera_pickles():
    e = PamWalkerEnv(render_mode="rgb_array", width=160, height=120)
    e.reset(seed=0)
    copy = pickle.loads(pickle.dumps(e))
    assert copy.camera.name == "follow" and copy.render().shape == (120, 160, 3)
    copy.close()
    e.close()


def test_unknown_camera_fails():
    with pytest.raises(ValueError, match="camera must be one of follow, fixed, three_quarter"):
        PamWalkerEnv(camera="overhead")


def test_gymnasium_vector_env():
    envs = gym.make_vec("pamrun/PamWalker-v0", num_envs=2, vectorization_mode="sync")
    obs, _ = envs.reset(seed=0)
    assert obs.shape == (2, 43)
    obs, rew, term, trunc, _ = envs.step(np.zeros((2, 10), dtype=np.float32))
    assert rew.shape == (2,)
    envs.close()


def test_torchrl_gymenv_and_parallel_env():
    from torchrl.envs import GymEnv, ParallelEnv
    from torchrl.envs.utils import check_env_specs

    env = GymEnv("pamrun/PamWalker-v0")
    check_env_specs(env)
    td = env.rollout(5)
    assert td["observation"].shape == (5, 43)
    env.close()
    # "module:id" makes each worker process import pamrun (and so register the env) first.
    penv = ParallelEnv(2, functools.partial(GymEnv, "pamrun:pamrun/PamWalker-v0"))
    td = penv.rollout(3)
    assert td["observation"].shape == (2, 3, 43)
    penv.close()


def _episode_record(steps: int = 200, **muscle) -> dict[str, np.ndarray]:
    """Observations, rewards, pressures and contractions of ``steps`` control steps with fixed
    random actions (reset after a fall, which is deterministic without reset noise)."""
    e = PamWalkerEnv(muscle=muscle)
    actions = np.random.default_rng(7).uniform(-1, 1, (steps, e.n_actions)).astype(np.float32)
    out = {"obs": [], "reward": [], "pressure": [], "contraction": [], "end": []}
    obs, info = e.reset(seed=0)
    for action in actions:
        obs, reward, terminated, truncated, info = e.step(action)
        for key, value in (("obs", obs), ("reward", reward), ("pressure", info["pressure_kpa"]),
                           ("contraction", info["contraction_pct"]), ("end", terminated or truncated)):
            out[key].append(value)
        if terminated or truncated:
            e.reset()
    compiled = e.drive.compiled
    e.close()
    return {"compiled": compiled, **{k: np.array(v, dtype=float) for k, v in out.items()}}


@pytest.mark.parametrize("muscle", [{}, {"command": "independent"}, {"regulator": {"lag_s": 0.0}}],
                         ids=["default", "independent", "no_lag"])
def test_compiled_muscle_kernel_matches_numpy_reference(muscle):
    """muscle.kernel=numba (the default) and numpy run the same episodes to float rounding."""
    fast, ref = _episode_record(**muscle, kernel="numba"), _episode_record(**muscle, kernel="numpy")
    assert fast.pop("compiled") and not ref.pop("compiled")
    for key in ref:
        np.testing.assert_allclose(fast[key], ref[key], rtol=1e-9, atol=1e-9, err_msg=key)
    # a real test: the pressures move (lag and clips at work) and the robot moves
    assert np.ptp(ref["pressure"]) > 300 and np.ptp(ref["obs"][:, 11:21]) > 0.3


@pytest.mark.parametrize("toe", [False, True])
def test_compiled_reading_is_the_python_one(toe):
    """task/sensing.read_state's torso, observation and feet are Python's values from the same state."""
    u = PamWalkerEnv(body={"toe": toe})
    u.reset(seed=2)
    rng = np.random.default_rng(3)
    for _ in range(40):
        u.step(rng.uniform(-1, 1, u.n_actions).astype(np.float32))
    error, forces, soles, torso, obs = u._sense()
    q, v, python_torso = u._state()
    assert not error and torso == list(python_torso)
    assert forces == u.foot_forces_n().tolist()
    assert np.array_equal(soles, u.data.geom_xpos[u._sole_ids].reshape(2, -1, 3))
    sensed = [*python_torso[1:12], *(q[a] for a in u.qpos_idx), *(v[a] for a in u.qvel_idx),
              *(f / u.weight_n for f in forces), *u.episode.prev_action.tolist()]
    assert np.array_equal(obs, np.array(sensed, dtype=np.float32))


def test_compiled_command_is_the_drives_voltages():
    """sensing.command_voltages clips and maps to voltages as the env's numpy path and MuscleDrive do."""
    from pamrun.task.sensing import command_voltages

    u = PamWalkerEnv()
    action = np.array([-3.0, -1.0, -0.0, 0.0, 0.3, 1.0, 2.5, np.nan, np.inf, -np.inf])
    for dtype in (np.float32, np.float64):
        command, voltage = np.empty(10), np.empty((10, 2))
        command_voltages(action.astype(dtype), u.muscle_cfg.v0_v, u._swing_v, command, voltage)
        reference = np.minimum(np.maximum(action.astype(dtype), -1.0, dtype=float), 1.0)
        assert np.array_equal(command, reference, equal_nan=True)
        assert np.array_equal(voltage, u.drive.voltages_v(action.astype(dtype)), equal_nan=True)


def test_lean_info_is_the_full_infos_training_keys():
    """lean_info=True: info holds what training reads, with the full info's values."""
    full, lean = PamWalkerEnv(), PamWalkerEnv(lean_info=True)
    keys = ["distance", "physics_error", "reward_terms", "reward_unweighted"]
    outs = [full.reset(seed=4), lean.reset(seed=4)]
    rng = np.random.default_rng(4)
    for step in range(30):
        assert list(outs[1][-1]) == keys
        for k in keys:
            assert outs[1][-1][k] == outs[0][-1][k] and type(outs[1][-1][k]) is type(outs[0][-1][k])
        assert np.array_equal(outs[0][0], outs[1][0])
        action = rng.uniform(-1, 1, 10).astype(np.float32)
        outs = [full.step(action), lean.step(action)]
    assert gym.make("pamrun/PamWalker-v0", lean_info=True).unwrapped.lean_info
