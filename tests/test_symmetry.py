"""The walker's mirror symmetry (pamrun/task/symmetry.py): a reflection of a reflection is the
identity, and the physics agrees: from a mirrored state, mirrored commands give mirrored
observations."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from pamrun.task.env import PamWalkerEnv
from pamrun.task.symmetry import action_map, mirror_state, observation_map


@pytest.mark.parametrize("n_actions", [10, 20])
def test_mirror_maps_are_involutions(n_actions):
    for index, sign in (action_map(n_actions), observation_map(n_actions)):
        assert sorted(index) == list(range(len(index)))
        assert np.array_equal(index[index], np.arange(len(index)))
        assert np.array_equal(sign * sign[index], np.ones(len(index)))


@pytest.mark.parametrize("command", ["antagonistic", "independent"])
def test_mirrored_commands_from_a_mirrored_state_give_mirrored_observations(command):
    """Start a second robot in the first's mirror image (joint noise, a sideways velocity), drive
    it with the mirror image of the first's commands: its observations are the mirror images of
    the first's, to the contact solver's rounding, over 0.5 s of feet on the ground."""
    a, b = (PamWalkerEnv(muscle={"command": command}, env={"reset_noise_rad": 0.05}) for _ in range(2))
    a.reset(seed=3)
    b.reset(seed=3)
    a.data.qvel[1], a.data.qvel[3] = 0.2, 0.3  # sideways and rolling: nothing symmetric by accident
    mujoco.mj_forward(a.model, a.data)
    b.data.qpos[:], b.data.qvel[:] = mirror_state(a.data.qpos, a.data.qvel, a.qpos_idx, a.qvel_idx)
    mujoco.mj_forward(b.model, b.data)
    o_index, o_sign = observation_map(a.n_actions)
    a_index, a_sign = action_map(a.n_actions)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(20):
        action = rng.uniform(-0.5, 0.5, a.n_actions)
        obs_a, *_ = a.step(action)
        obs_b, *_ = b.step(action[a_index] * a_sign)
        worst = max(worst, float(np.max(np.abs(obs_b - obs_a[o_index] * o_sign))))
        assert abs(obs_a[0]) > 1e-4  # y moves: the test would see a wrong sign
    assert worst < 1e-3, worst
    a.close()
    b.close()


def test_a_mirrored_batch_holds_the_mirror_images(cfg):
    """train.mirror stores mirror_batch(batch): observations and actions reflected, rewards kept."""
    import torch

    from pamrun.task.symmetry import mirror_batch
    from pamrun.training.recipe import make_env

    env = make_env(cfg, seed=0)
    batch = env.rollout(30)
    env.close()
    mirrored = mirror_batch(batch, cfg.env)
    o_index, o_sign = observation_map(10)
    a_index, a_sign = action_map(10)
    assert torch.equal(mirrored["observation"], batch["observation"][:, o_index] * torch.as_tensor(o_sign).float())
    assert torch.equal(mirrored["next", "observation"][:, 0], -batch["next", "observation"][:, 0])  # y
    assert torch.equal(mirrored["action"], batch["action"][:, a_index] * torch.as_tensor(a_sign).float())
    assert torch.equal(mirrored["next", "reward"], batch["next", "reward"])
    assert torch.equal(mirror_batch(mirrored, cfg.env)["observation"], batch["observation"])
