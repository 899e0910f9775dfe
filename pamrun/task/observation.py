"""The observation's layout: its blocks in order, their sizes and units, and the torso's angles.

The table of every block is in the env's docstring (:mod:`pamrun.task.env`) and in
``docs/environment.md``; :func:`observation_structure` names each block's slice.
"""

from __future__ import annotations

import math

from pamrun.config import EnvConfig, MuscleConfig, as_config
from pamrun.physics import body as body_mod
from pamrun.physics.actuation import n_actions

N_JOINTS = len(body_mod.JOINTS)  # the hinges, pamrun.config.LEG_JOINTS on each side
# The sensed blocks in order, with their sizes; the previous action follows, then the commands.
_OBS_BLOCKS = (("torso_y", 1), ("torso_z", 1), ("torso_rpy", 3), ("torso_velocity", 3), ("torso_angular_velocity", 3),
               ("joint_angle", N_JOINTS), ("joint_velocity", N_JOINTS), ("foot_force", 2))
# The unit of each block, for readers outside pamrun (pamrun export's metadata).
OBSERVATION_UNITS = {
    "torso_y": "m", "torso_z": "m", "torso_rpy": "rad", "torso_velocity": "m/s",
    "torso_angular_velocity": "rad/s", "joint_angle": "rad", "joint_velocity": "rad/s",
    "foot_force": "robot weights (N / (m g))", "previous_action": "1", "speed_command": "m/s", "gait_clock": "1",
}
OBS_BASE = sum(n for _, n in _OBS_BLOCKS)  # 33: observations before the previous action
OBS_SIZE = OBS_BASE + N_JOINTS  # with the antagonistic command (the default and the thesis)


def observation_structure(n_actions: int = N_JOINTS, speed_command: bool = False, gait_clock: bool = False
                          ) -> dict[str, slice]:
    """Each observation block's slice, for an env taking ``n_actions`` actions (and told the
    commanded speed, ``env.speed_command``, and the gait clock, ``env.gait_period_s`` > 0)."""
    out, start = {}, 0
    for name, size in (*_OBS_BLOCKS, ("previous_action", n_actions), ("speed_command", int(speed_command)),
                       ("gait_clock", 2 * gait_clock)):
        if not size:
            continue
        out[name] = slice(start, start + size)
        start += size
    return out


def obs_size(structure: dict[str, slice]) -> int:
    """The observation's length: where its last block ends."""
    return max(s.stop for s in structure.values())


def space_sizes(muscle: MuscleConfig | dict | None = None, env: EnvConfig | dict | None = None) -> tuple[int, int]:
    """(observations, actions) of the env for this muscle and env config, without building it."""
    n, env = n_actions(as_config(muscle, MuscleConfig)), as_config(env, EnvConfig)
    return obs_size(observation_structure(n, env.speed_command, env.gait_period_s > 0)), n


def quat_to_euler(quat_wxyz) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] (extrinsic x-y-z) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = quat_wxyz
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw
