"""The walker's left-right mirror symmetry: observations, actions and states reflected in the
sagittal (x-z) plane.

The robot is left/right symmetric (:mod:`pamrun.physics.body`): the right leg's roll joints mirror
the left's (``body.mirror_sign``: their limits and neutral angles are negated), its pitch
joints are the same. Reflecting y -> -y therefore maps

* the torso: y, roll, yaw, vy, and the torso-frame angular velocities wx, wz change sign;
  z, pitch, vx, vz, wy do not;
* the joints: each right-leg joint's angle and velocity become the left leg's, times the
  joint's ``mirror_sign`` product (-1 for roll joints, +1 for pitch joints), and back;
* the feet's forces: right <-> left;
* the gait clock (``env.gait_period_s``): the right foot's clock is the left's shifted by half a
  period, so the mirror image's phase is phi + 1/2: its sine and cosine change sign;
* the command (``muscle.command``): ``antagonistic`` actions follow their joint (a roll
  joint's action changes sign: its muscle 1 pulls the other way); ``independent`` actions
  (muscle 1 and 2 of each joint in a row) swap legs, and a roll joint's muscle 1 and 2 swap.

The reward is symmetric (its terms depend on y only through y^2, on the joints through
stop shares, on the feet through sums over both with the clock shifted), so a transition and its
mirror image pay the same: a replay buffer may hold
both (``train.mirror``).
"""

from __future__ import annotations

import numpy as np
import torch

from pamrun.physics.body import JOINTS, LEG_JOINTS, SIDES, mirror_sign

_TORSO_SIGNS = [-1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1]  # y, z, roll, pitch, yaw, vx, vy, vz, wx, wy, wz
SENSED = len(_TORSO_SIGNS) + 2 * len(JOINTS) + 2  # then the foot forces; the previous action follows (env.OBS_BASE)


def joint_map() -> tuple[np.ndarray, np.ndarray]:
    """(10,) index of each joint's mirror image, and the sign its angle takes there."""
    index = np.array([JOINTS.index(f"{SIDES[1 - SIDES.index(side)]}_{joint}")
                      for side in SIDES for joint in LEG_JOINTS])
    sign = np.array([mirror_sign("right", joint) for _ in SIDES for joint in LEG_JOINTS])
    return index, sign


def action_map(n_actions: int) -> tuple[np.ndarray, np.ndarray]:
    """The mirror image of an action a is a[index] * sign (``muscle.command`` by its size)."""
    index, sign = joint_map()
    n = len(JOINTS)
    if n_actions == n:  # antagonistic: one action per joint
        return index, sign.astype(float)
    if n_actions != 2 * n:
        raise ValueError(f"no mirror for {n_actions} actions")
    muscle1 = np.where(sign > 0, 2 * index, 2 * index + 1)  # (joint, muscle) pairs in a row; a roll joint's swap
    muscle2 = np.where(sign > 0, 2 * index + 1, 2 * index)
    return np.stack([muscle1, muscle2], axis=1).reshape(-1), np.ones(2 * n)


def observation_map(n_actions: int, speed_command: bool = False, gait_clock: bool = False
                    ) -> tuple[np.ndarray, np.ndarray]:
    """The mirror image of an observation o is o[index] * sign (the env's observation table; the
    commanded speed, with ``env.speed_command``, is its own mirror image; the gait clock's sine
    and cosine, last with ``env.gait_period_s``, change sign)."""
    j_index, j_sign = joint_map()
    a_index, a_sign = action_map(n_actions)
    n_torso, n = len(_TORSO_SIGNS), len(JOINTS)
    extra = np.arange(SENSED + n_actions, SENSED + n_actions + int(speed_command) + 2 * gait_clock)
    index = np.concatenate([np.arange(n_torso), n_torso + j_index, n_torso + n + j_index,
                            n_torso + 2 * n + np.array([1, 0]), SENSED + a_index, extra])
    sign = np.concatenate([_TORSO_SIGNS, j_sign, j_sign, [1.0, 1.0], a_sign, [1.0] * speed_command,
                           [-1.0, -1.0] * gait_clock])
    return index, sign.astype(float)


def mirror_state(qpos: np.ndarray, qvel: np.ndarray, qpos_idx: np.ndarray, qvel_idx: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A MuJoCo state (free-joint torso, then the hinges at ``qpos_idx``/``qvel_idx`` in JOINTS
    order) reflected in the x-z plane (other hinges, body.toe's toes, stay as they are)."""
    j_index, j_sign = joint_map()
    q, v = np.array(qpos, float), np.array(qvel, float)
    q[1] = -q[1]
    q[4], q[6] = -q[4], -q[6]  # quaternion (w, x, y, z): x and z change sign
    v[1], v[3], v[5] = -v[1], -v[3], -v[5]
    q[qpos_idx] = np.asarray(qpos)[qpos_idx][j_index] * j_sign
    v[qvel_idx] = np.asarray(qvel)[qvel_idx][j_index] * j_sign
    return q, v


def mirror_batch(batch, env):
    """A TorchRL batch of transitions reflected: observations, next observations and actions
    mirrored, everything else (rewards, their terms, done flags, ...) as it is. ``env`` (the
    run's EnvConfig) says which optional blocks the observation has."""
    n_actions = batch["action"].shape[-1]
    o_map = observation_map(n_actions, env.speed_command, env.gait_period_s > 0)
    o_index, o_sign = (torch.as_tensor(x) for x in o_map)
    a_index, a_sign = (torch.as_tensor(x) for x in action_map(n_actions))
    out = batch.clone()
    for key in ("observation", ("next", "observation")):
        obs = batch[key]
        out[key] = obs[..., o_index] * o_sign.to(obs.dtype)
    out["action"] = batch["action"][..., a_index] * a_sign.to(batch["action"].dtype)
    return out
