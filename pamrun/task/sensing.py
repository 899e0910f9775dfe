"""PamWalker-v0's arithmetic around MuJoCo in a control step, compiled (numba): the command and its
regulator voltages before it (:func:`command_voltages`), and what it reads of the state after it.

:func:`read_state` computes the torso's 12 values, the observation's sensed values and the
previous action (:mod:`pamrun.task.observation`'s layout; float64, then rounded once to
float32), the feet's ground forces and contact points, and whether the physics blew up. Every
value is the one Python computes from the same state, operation for operation: the same IEEE
operations in the same order, libm's ``atan2`` and ``asin`` (which Python's ``math`` calls too),
and ``min``/``max`` as Python's builtins treat NaN.

Compiled on first use and cached next to this file (``cache=True``).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def command_voltages(action, v0, swing, command, voltage):
    """The command: ``action`` (n,) clipped to [-1, 1] (NaN kept, as np.maximum then np.minimum) into
    ``command`` (float64), and each pair's regulator voltages V0 + dV a, V0 - dV a into ``voltage``
    (n, 2) [V] (``swing``: dV, -dV [V]), as :meth:`pamrun.physics.actuation.MuscleDrive.voltages_v`."""
    for k in range(action.shape[0]):
        a = np.float64(action[k])
        if a < -1.0:
            a = -1.0
        if a > 1.0:
            a = 1.0
        command[k] = a
        voltage[k, 0] = a * swing[0] + v0
        voltage[k, 1] = a * swing[1] + v0


@njit(cache=True)
def _torso(qpos, qvel, torso):
    """The torso's x, y, z, roll, pitch, yaw (extrinsic x-y-z, :func:`pamrun.task.observation.quat_to_euler`),
    vx, vy, vz, wx, wy, wz into ``torso`` (12,)."""
    w, x, y, z = qpos[3], qpos[4], qpos[5], qpos[6]
    sin_pitch = 2 * (w * y - z * x)
    if not sin_pitch < 1.0:  # min(1.0, s): NaN gives 1.0
        sin_pitch = 1.0
    if not sin_pitch > -1.0:  # max(-1.0, s)
        sin_pitch = -1.0
    torso[0], torso[1], torso[2] = qpos[0], qpos[1], qpos[2]
    torso[3] = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    torso[4] = math.asin(sin_pitch)
    torso[5] = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    for i in range(6):
        torso[6 + i] = qvel[i]


@njit(cache=True)
def _unstable(qpos, qvel, warning_number, unstable):
    """MuJoCo counted one of the ``unstable`` warnings, or a value of qpos or qvel is not finite."""
    for w in unstable:
        if warning_number[w] != 0:
            return True
    for values in (qpos, qvel):
        for value in values:
            if not math.isfinite(value):
                return True
    return False


@njit(cache=True)
def read_state(qpos, qvel, sensordata, geom_xpos, warning_number, unstable, foot_adr, toe_adr, sole_ids, qpos_idx,
               qvel_idx, weight_n, prev_action, torso, sensed, obs, soles):
    """Read the state after a step. In: MjData's ``qpos``, ``qvel``, ``sensordata``, ``geom_xpos`` and
    ``warning.number``; the warnings that mean a blow-up (``unstable``); the feet's touch sensors
    (``foot_adr``, right and left, and ``toe_adr``, empty without toes, added to them); the feet's
    contact point geoms ``sole_ids`` (2, k); the hinges in qpos and qvel; the weight [N]; the
    previous action. Out: ``torso`` (12,), ``sensed`` (33,) the observation's sensed values (float64),
    ``obs`` from index 0 the sensed values and the previous action (float32), ``soles`` (2, k, 3) [m].
    Returns (blown up, right foot's force [N], left foot's force [N])."""
    _torso(qpos, qvel, torso)
    right, left = sensordata[foot_adr[0]], sensordata[foot_adr[1]]
    if toe_adr.shape[0] == 2:
        right, left = right + sensordata[toe_adr[0]], left + sensordata[toe_adr[1]]
    for i in range(11):  # y, z, roll, pitch, yaw, velocity, angular velocity
        sensed[i] = torso[1 + i]
    n = qpos_idx.shape[0]
    for j in range(n):
        sensed[11 + j] = qpos[qpos_idx[j]]
        sensed[11 + n + j] = qvel[qvel_idx[j]]
    sensed[11 + 2 * n], sensed[12 + 2 * n] = right / weight_n, left / weight_n
    for i in range(sensed.shape[0]):
        obs[i] = sensed[i]
    for i in range(prev_action.shape[0]):
        obs[sensed.shape[0] + i] = prev_action[i]
    for foot in range(2):
        for k in range(sole_ids.shape[1]):
            for c in range(3):
                soles[foot, k, c] = geom_xpos[sole_ids[foot, k], c]
    return _unstable(qpos, qvel, warning_number, unstable), right, left
