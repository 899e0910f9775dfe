"""PamWalker-v0: the walking task as a Gymnasium environment (thesis §9).

The MuJoCo body of :mod:`pamrun.physics.body` driven by the 20 muscles of
:mod:`pamrun.physics.actuation`. Its keyword arguments ``body``, ``muscle``, ``reward`` and ``env``
take the config sections of the same names (dataclasses or partial dicts; defaults are the
thesis values), so ``gymnasium.make("pamrun/PamWalker-v0", reward={"kz": 30})`` works without
Hydra. The full manual, with every formula: ``docs/environment.md``.

## Action space
``Box(-1, 1, (10,))`` with ``muscle.command=antagonistic`` (default): one value a per joint
(``pamrun.physics.body.JOINTS`` order), its pair at V0 +- dV a. ``independent``: ``Box(-1, 1, (20,))``,
one value per muscle. With ``env.action_filter_alpha`` alpha < 1 the command applied is
alpha a + (1 - alpha) a_prev. It is held for one control step Ts (``env.control_dt_s``, 25 ms),
the muscles stepping every ``env.muscle_dt_s``, MuJoCo every ``env.physics_dt_s``.

## Observation space
``Box(-inf, inf, (33 + n_actions [+ 1] [+ 2],))``; ``env.observation_structure`` names each block's slice:

| index | ``observation_structure`` key | meaning | unit |
|---|---|---|---|
| 0 | ``torso_y`` | torso lateral position y | m |
| 1 | ``torso_z`` | torso height z | m |
| 2, 3, 4 | ``torso_rpy`` | torso roll, pitch, yaw | rad |
| 5, 6, 7 | ``torso_velocity`` | torso linear velocity vx, vy, vz (world frame) | m/s |
| 8, 9, 10 | ``torso_angular_velocity`` | torso angular velocity (torso frame) | rad/s |
| 11-20 | ``joint_angle`` | joint angles, JOINTS order | rad |
| 21-30 | ``joint_velocity`` | joint angular velocities, JOINTS order | rad/s |
| 31, 32 | ``foot_force`` | normal ground force under the right, left foot | robot weights (N / (m g)) |
| 33-42 (33-52) | ``previous_action`` | the command applied in the last step (10 or 20 values) | 1 |
| 43 (53) | ``speed_command`` | v*, the commanded speed (only with ``env.speed_command``) | m/s |
| last 2 | ``gait_clock`` | sin, cos of 2 pi phi, the gait clock's phase (only with ``env.gait_period_s``) | 1 |

## Reward
r = sum_k w_k f_k over ``RewardConfig``'s weights (:mod:`pamrun.task.reward`, one named term per
weight): ``kvx`` forward velocity, ``ky`` lateral deviation, ``kz`` height change, ``kv`` effort,
``kt`` alive, ``kda`` command change, ``kfall`` fall, ``kstop`` joints at a stop, ``kspeed``
speed near v*, ``kslip`` foot slip, ``kair`` supply air, ``kstep`` step length miss, ``kgait``
following the gait clock. Only the terms whose weight is not 0, and those named in the keyword
argument ``features`` (e.g. a curriculum's), are computed; the others are 0. Every feature is 0
in a step whose physics blew up.

## Commanded speed and gait clock
v* is ``env.target_speed_m_s``, or drawn per episode from ``env.speed_range_m_s`` (and again
``env.speed_changes`` times within it, 0 with chance ``env.speed_stop_share``), or piecewise
constant after ``env.speed_schedule``; a change applies from the control step nearest its time
on (its observation, reward and info). With ``env.speed_ramp_m_s2`` a changed command is not
taken at once: v* moves toward it by at most that many m/s a second (the stop from a walk then
takes a step, not a control step); info's ``target_speed_m_s`` is the command. With ``env.gait_period_s`` T > 0 a clock phi = phi0 + t / T (mod 1) runs, phi0
drawn per episode; the right foot swings in the first ``env.swing_share`` of each period, the
left half a period later (:mod:`pamrun.task.clock`). With ``env.gait_follows_speed`` T follows
v* (the phase runs on from where it was when v* changes) and at v* = 0 the clock stops, both
feet asked down.

## Perturbations
``env.observation_noise_std`` (Gaussian noise on the 33 sensed values), ``env.push_impulse_ns``
at ``env.push_time_s`` over ``env.push_duration_s`` (a constant force on the torso).

## Rendering
``render_mode="rgb_array"``: :meth:`render` returns a ``height`` x ``width`` RGB frame from the
camera named by the keyword argument ``camera`` (:mod:`pamrun.task.camera`): ``follow``
(default; side-on, following the torso), ``fixed`` (side-on, aimed where the robot starts) or
``three_quarter`` (the model's camera, front right).

## Episode end
Truncation after ``env.episode_s`` (10 s). Termination by a fall (:func:`pamrun.task.criteria.fell`)
or when the physics state is not finite (``info["physics_error"]``).

## info
``x``, ``y``, ``z``, ``distance`` [m], ``torso_rpy_rad`` (3,) (the torso's roll, pitch and yaw), ``reward_terms`` (weighted) and ``reward_unweighted``
(the features), each a dict by weight key, ``pressure_kpa``, ``contraction_pct`` (10, 2),
``foot_force_n`` (2,) [N], ``sole_xyz_m`` (2, 4, 3) [m], ``joint_torque_nm`` (10,) [N m],
``fell``, ``physics_error``, ``target_speed_m_s`` (the speed commanded now: v*, or where
``env.speed_ramp_m_s2`` ramps v*, the command it moves toward), and ``air_nl`` [normal litres] when the
reward computes ``kair``. With the keyword argument ``lean_info=True`` only ``distance``,
``physics_error``, ``reward_terms``, ``reward_unweighted`` (and ``air_nl``): what a training run
reads (``pamrun.training.recipe.make_env``'s info readers), without the cost of the rest.
"""

from __future__ import annotations

import math
import operator
import os
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import gymnasium as gym
import numpy as np

# Rendering headless: MuJoCo reads MUJOCO_GL when it is first imported, so it is set before.
os.environ.setdefault("MUJOCO_GL", "egl")
import mujoco

from pamrun.config import BodyConfig, EnvConfig, MuscleConfig, RewardConfig, as_config
from pamrun.config.robot import MUSCLE_INNER_DIAMETER_M
from pamrun.physics import body as body_mod
from pamrun.physics.actuation import MuscleDrive, joint_limits_rad, muscle_counts
from pamrun.physics.muscle import AirMeter
from pamrun.physics.terrain import ground_height_m, has_terrain
from pamrun.task import clock
from pamrun.task.camera import Camera
from pamrun.task.clock import gait_at_speed
from pamrun.task.criteria import fell as fell_rule
from pamrun.task.measures import ANKLE_PITCHES, CONTACT_WEIGHT_SHARE, HIP_PITCHES, KNEES, STOP_MARGIN_DEG, stop_bounds
from pamrun.task.observation import (
    N_JOINTS,
    OBS_BASE,
    obs_size,
    observation_structure,
    quat_to_euler,
)
from pamrun.task.reward import REWARD_KEYS, Reward, Transition

_INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)
# What one step reads of the state (PamWalkerEnv._state): qpos, qvel, and the torso's 12 values.
_State = tuple[list[float], list[float], tuple[float, ...]]


@dataclass
class Episode:
    """What changes within an episode; ``reset`` replaces it."""

    target_speed_m_s: float  # v*: the speed the task asks now (observed, paid, clocked)
    command_m_s: float  # the speed commanded now, which v* moves toward (v* at reset)
    gait_period_s: float  # T at v*
    step_length_m: float  # L* at v*
    prev_action: np.ndarray  # the command applied in the last step (0 at reset)
    phase0: float = 0.0  # the gait clock's phase at reset
    steps: int = 0  # control steps since reset
    x0: float = 0.0  # torso x at reset [m]
    soles: np.ndarray | None = None  # the feet's contact points (2, k, 3) after the last step
    contact: list[bool] = field(default_factory=lambda: [False, False])  # the feet on the ground then
    gas: np.ndarray | None = None  # the muscles' gas P V [kPa l] then (when the env meters air)
    changes: list[tuple[int, float]] = field(default_factory=list)  # the commands to come: (control step, speed)
    clock_step0: int = 0  # the control step the clock runs at its period from (phase0 its phase then)

    def phase(self, env: EnvConfig) -> float:
        """The gait clock's phase phi in [0, 1) now."""
        return clock.phase(self.phase0, self.steps - self.clock_step0, env.control_dt_s, self.gait_period_s)

    @property
    def clock_stopped(self) -> bool:
        """Whether the clock stands still, both feet asked down (v* = 0 with ``env.gait_follows_speed``)."""
        return math.isinf(self.gait_period_s)

    def speed_changes_now(self) -> bool:
        """Whether v* changes in this step: a command falls due, or v* is still on its way to one."""
        return bool(self.changes and self.changes[0][0] <= self.steps) or self.target_speed_m_s != self.command_m_s

    def change_speed(self, env: EnvConfig) -> None:
        """Take the commands due by this step and move v* toward the last (at most
        ``env.speed_ramp_m_s2`` x Ts, or at once at 0); the clock goes on from its phase now."""
        while self.changes and self.changes[0][0] <= self.steps:
            _, self.command_m_s = self.changes.pop(0)
        gap, most = self.command_m_s - self.target_speed_m_s, env.speed_ramp_m_s2 * env.control_dt_s
        if most and abs(gap) > most:
            self.target_speed_m_s += math.copysign(most, gap)
        else:
            self.target_speed_m_s = self.command_m_s
        if env.gait_period_s > 0:
            self.phase0, self.clock_step0 = self.phase(env), self.steps
        self.gait_period_s, self.step_length_m = gait_at_speed(env, self.target_speed_m_s)


class PamWalkerEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 40}

    def __init__(
        self,
        body: BodyConfig | dict | None = None,
        muscle: MuscleConfig | dict | None = None,
        reward: RewardConfig | dict | None = None,
        env: EnvConfig | dict | None = None,
        render_mode: str | None = None,
        width: int = 480,
        height: int = 360,
        features: Iterable[str] = (),
        lean_info: bool = False,
        camera: str = "follow",
    ):
        self.body_cfg, self.muscle_cfg = as_config(body, BodyConfig), as_config(muscle, MuscleConfig)
        self.reward_cfg, self.env_cfg = as_config(reward, RewardConfig), as_config(env, EnvConfig)
        self.reward = Reward(self.reward_cfg, features)
        self.reward_weights = self.reward.weights  # by key
        self.lean_info = lean_info  # info: only what training reads (module docstring, "info")
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode, self.width, self.height = render_mode, width, height
        self._renderer: mujoco.Renderer | None = None
        cfg = self.env_cfg
        self._build_physics(cfg)
        self.camera = Camera(camera, self.model, self.body_cfg.height_m)  # what render() draws from
        self.drive = MuscleDrive(self.muscle_cfg, self.body_cfg)
        self.n_actions = self.drive.n_actions
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.n_actions,), np.float32)
        self.speed_command, self.gait_clock = cfg.speed_command, cfg.gait_period_s > 0
        self.observation_structure = observation_structure(self.n_actions, self.speed_command, self.gait_clock)
        size = obs_size(self.observation_structure)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self._read_model()
        self._sensing(size)
        self._push_steps, self._push_force_n = self._push()
        # info["air_nl"] and kair's feature: metered only when the reward computes kair
        self.air_meter = AirMeter(self.muscle_cfg.nominal_length_m, MUSCLE_INNER_DIAMETER_M[self.muscle_cfg.size],
                                  muscle_counts(self.muscle_cfg)) if "kair" in self.reward.computed else None
        self.episode = self._new_episode(cfg.target_speed_m_s)

    def _build_physics(self, cfg: EnvConfig) -> None:
        """The MuJoCo model and data, the views of its arrays read every step, and the step counts."""
        self.model = body_mod.build_model(self.body_cfg, timestep_s=cfg.physics_dt_s, env=cfg)
        self.on_terrain = has_terrain(cfg)  # the fall check measures the torso's height from the ground
        self.data = d = mujoco.MjData(self.model)
        # views read every step (MjData's memory never moves)
        self._qpos, self._qvel, self._sensordata, self._geom_xpos = d.qpos, d.qvel, d.sensordata, d.geom_xpos
        self._qfrc_actuator, self._warning_number = d.qfrc_actuator, d.warning.number
        self.n_muscle_steps = int(round(cfg.control_dt_s / cfg.muscle_dt_s))
        self.n_physics_per_muscle = int(round(cfg.muscle_dt_s / cfg.physics_dt_s))
        self.n_substeps = self.n_muscle_steps * self.n_physics_per_muscle  # MuJoCo steps per control step
        self.max_steps = int(round(cfg.episode_s / cfg.control_dt_s))

    def _read_model(self) -> None:
        """The model's addresses and constants the steps read (as Python numbers where read every step)."""
        m = self.model
        self.qpos_idx, self.qvel_idx = body_mod.joint_addresses(m)  # the hinges in qpos, qvel (JOINTS order)
        self.qpos_addresses = self.qpos_idx.tolist()
        self.knee_addresses = [self.qpos_addresses[k] for k in KNEES]  # right, left
        self.ankle_addresses = [self.qpos_addresses[a] for a in ANKLE_PITCHES]  # right, left
        self.hip_addresses = [self.qpos_addresses[h] for h in HIP_PITCHES]  # right, left
        self._torso_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body_mod.TORSO)
        self._sole_ids = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{side}_contact_{end}_{edge}")
                                   for side in body_mod.SIDES for end, edge in body_mod.SOLE_CORNERS])
        self._sole_ids_by_foot = self._sole_ids.reshape(2, -1)
        self.sole_radius_m = float(m.geom_size[self._sole_ids, 0].max())  # kgait's clearance: sphere bottom
        sensor = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, s) for s in body_mod.FOOT_SENSORS]
        self._foot_sensor_adr = np.array(m.sensor_adr[sensor])
        toes = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, s) for s in body_mod.TOE_SENSORS]
        self._toe_sensor_adr = m.sensor_adr[toes] if min(toes) >= 0 else None  # body.toe: added to the feet
        # the touch sensors of the right, left foot (and toe) in sensordata as a list
        self._foot_sensors = operator.itemgetter(*self._foot_sensor_adr.tolist())
        self._toe_sensors = None if self._toe_sensor_adr is None else operator.itemgetter(*self._toe_sensor_adr.tolist())
        self.mass_kg = float(m.body_subtreemass[0])  # the whole robot
        self.weight_n = float(m.body_subtreemass[0] * -m.opt.gravity[2])
        self.contact_n = CONTACT_WEIGHT_SHARE * self.weight_n  # a foot carrying more is on the ground
        # [low, high] of each joint in JOINTS order, as floats (reward.knear's per-step sum reads them)
        self.joint_limits_rad = np.asarray(joint_limits_rad(self.body_cfg), float).tolist()
        self.stop_bounds = stop_bounds(self.joint_limits_rad, math.radians(STOP_MARGIN_DEG))
        key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "stand")
        self._qpos0 = m.key_qpos[key].copy() if key >= 0 else m.qpos0.copy()
        self.z0 = float(self._qpos0[2])

    def _sensing(self, obs_size: int) -> None:
        """What :func:`pamrun.task.sensing.read_state` reads and writes besides MjData's arrays."""
        from pamrun.task.sensing import command_voltages, read_state  # numba: compiled on first use, then cached

        self._read_state, self._command_voltages = read_state, command_voltages
        # the command's voltages compiled: one per pair (antagonistic), no low-pass
        self._voltages_compiled = self.n_actions == len(self.drive.radius_m) and self.env_cfg.action_filter_alpha >= 1.0
        self._swing_v = np.array([self.muscle_cfg.dv_max_v, -self.muscle_cfg.dv_max_v])  # dV, -dV
        self._unstable = np.array([int(w) for w in _INSTABILITY_WARNINGS], dtype=np.intp)
        self._foot_adr = self._foot_sensor_adr.astype(np.intp)
        self._toe_adr = np.zeros(0, np.intp) if self._toe_sensor_adr is None else self._toe_sensor_adr.astype(np.intp)
        self._sole_adr = self._sole_ids_by_foot.astype(np.intp)
        self._hinge_adr = self.qpos_idx.astype(np.intp), self.qvel_idx.astype(np.intp)
        self._torso_values, self._sensed = np.zeros(12), np.zeros(OBS_BASE)
        self._obs_size, self._commands_at = obs_size, OBS_BASE + self.n_actions

    def _push(self) -> tuple[range, np.ndarray | None]:
        """The control steps k (1-based: the step that starts at (k - 1) Ts) the torso is pushed in, and the force."""
        cfg = self.env_cfg
        if not any(cfg.push_impulse_ns):
            return range(0), None
        n_push = max(1, int(round(cfg.push_duration_s / cfg.control_dt_s)))
        first = int(round(cfg.push_time_s / cfg.control_dt_s)) + 1
        return range(first, first + n_push), np.asarray(cfg.push_impulse_ns, float) / (n_push * cfg.control_dt_s)

    def _new_episode(self, speed_m_s: float, phase0: float = 0.0, changes: list | None = None) -> Episode:
        return Episode(speed_m_s, speed_m_s, *gait_at_speed(self.env_cfg, speed_m_s), np.zeros(self.n_actions), phase0,
                       changes=changes or [])

    def _speed_plan(self, speed_m_s: float) -> tuple[float, list[tuple[int, float]]]:
        """v* at reset and its changes [(control step, v*)]: ``env.speed_schedule``'s, else
        ``speed_m_s`` and, with ``env.speed_changes``/``env.speed_stop_share``, drawn ones (drawn
        after the start pose and the clock's phase, which they leave as they were)."""
        cfg, rng = self.env_cfg, self.np_random
        to_step = lambda t: max(1, round(t / cfg.control_dt_s))  # noqa: E731  (a change applies after a step)
        if cfg.speed_schedule:
            (_, first), *rest = cfg.speed_schedule
            return float(first), [(to_step(t), float(v)) for t, v in rest]
        if not (cfg.speed_changes or cfg.speed_stop_share):
            return speed_m_s, []
        times = np.sort(rng.uniform(0.0, cfg.episode_s, cfg.speed_changes)).tolist()
        speeds = [speed_m_s, *rng.uniform(*cfg.speed_range_m_s, cfg.speed_changes).tolist()]
        if cfg.speed_stop_share:
            speeds = [0.0 if stop else v for v, stop in zip(speeds, rng.uniform(size=len(speeds)) < cfg.speed_stop_share)]
        return speeds[0], [(to_step(t), v) for t, v in zip(times, speeds[1:])]

    # Per-episode values, read-only (the episode's state is ``self.episode``).
    target_speed_m_s = property(lambda self: self.episode.target_speed_m_s, doc="v*, this episode's [m/s]")
    gait_period_s = property(lambda self: self.episode.gait_period_s, doc="T, this episode's [s]")
    step_length_m = property(lambda self: self.episode.step_length_m, doc="L*, this episode's [m]")

    def gait_phase(self) -> float:
        """The gait clock's phase phi in [0, 1) now."""
        return self.episode.phase(self.env_cfg)

    # ------------------------------------------------------------------ gym API

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        d, cfg = self.data, self.env_cfg
        mujoco.mj_resetData(self.model, d)
        self.model.actuator_biasprm[:] = 0.0  # the last episode's linearised muscles (MuscleDrive.apply)
        d.qpos[:] = self._qpos0
        if cfg.reset_noise_rad > 0:
            d.qpos[self.qpos_idx] += self.np_random.uniform(-cfg.reset_noise_rad, cfg.reset_noise_rad, N_JOINTS)
        if cfg.reset_velocity_noise > 0:
            noise = cfg.reset_velocity_noise
            d.qvel[self.qvel_idx] = self.np_random.uniform(-noise, noise, N_JOINTS)
        d.xfrc_applied[:] = 0.0
        mujoco.mj_forward(self.model, d)
        self.drive.reset()
        # v*, then the clock's phase, each after the start noise: a seed's start pose depends on neither
        speed = float(self.np_random.uniform(*cfg.speed_range_m_s)) if cfg.speed_range_m_s else cfg.target_speed_m_s
        phase0 = float(self.np_random.uniform()) if self.gait_clock else 0.0
        speed, changes = self._speed_plan(speed)
        ep = self.episode = self._new_episode(speed, phase0, changes)
        ep.x0 = float(d.qpos[0])
        _, forces, ep.soles, torso, obs = self._sense()
        ep.contact = self._contact(forces)
        info = self._info(False, forces, self._fell(torso), torso)
        if self.air_meter is not None:
            ep.gas, info["air_nl"] = self._gas(), np.float64(0.0)
        info["reward_terms"] = dict.fromkeys(REWARD_KEYS, 0.0)  # as after a step, so info's keys never change
        info["reward_unweighted"] = dict.fromkeys(REWARD_KEYS, 0.0)
        return obs, info

    def step(self, action):
        action, voltage = self._command(action)
        ep = self.episode
        self._advance(action, voltage)
        ep.steps += 1
        if ep.speed_changes_now():  # v* changes from this step's observation and reward on
            ep.change_speed(self.env_cfg)
        previous, ep.prev_action = ep.prev_action, action
        # MuJoCo resets the state itself when it meets NaN/Inf, so its warnings count too.
        physics_error, forces, soles, torso, obs = self._sense()
        contact = self._contact(forces)
        t = Transition(self, ep, torso, self._qpos.tolist(), action, previous, ep.soles, soles, ep.contact, contact,
                       forces)
        ep.soles, ep.contact = soles, contact
        if self.air_meter is not None:
            gas = self._gas()
            t.air_nl, ep.gas = self.air_meter.drawn_nl(ep.gas, gas), gas
        if physics_error:
            obs = np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0)
        t.fell = fell = physics_error or self._fell(torso)
        reward, terms, features = self.reward(None if physics_error else t)
        truncated = ep.steps >= self.max_steps and not fell
        info = self._info(physics_error, forces, fell, torso)
        if self.air_meter is not None:
            info["air_nl"] = np.float64(t.air_nl)  # supply air drawn in this step [normal litres]
        info["reward_terms"], info["reward_unweighted"] = terms, features
        return obs, reward, fell, truncated, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
        self.camera.update_scene(self._renderer, self.data)
        return self._renderer.render()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------ pieces

    def _command(self, action) -> tuple[np.ndarray, np.ndarray | None]:
        """The command applied: the action clipped to [-1, 1], low-passed with ``env.action_filter_alpha`` < 1;
        and its regulator voltages, where :func:`pamrun.task.sensing.command_voltages` computes them (else None)."""
        if self._voltages_compiled and type(action) is np.ndarray and action.shape == self.action_space.shape \
                and action.dtype in (np.float32, np.float64):
            command, voltage = np.empty(self.n_actions), np.empty((self.n_actions, 2))
            self._command_voltages(action, self.muscle_cfg.v0_v, self._swing_v, command, voltage)
            return command, voltage
        # np.clip(action, -1, 1) as two ufuncs (np.clip's Python wrapper costs more than both).
        action = np.maximum(action, -1.0, dtype=np.float64)
        if action.shape != self.action_space.shape:
            action = action.reshape(self.n_actions)
        np.minimum(action, 1.0, out=action)
        alpha = self.env_cfg.action_filter_alpha
        if alpha < 1.0:
            action = alpha * action + (1.0 - alpha) * self.episode.prev_action
        return action, None

    def _advance(self, action: np.ndarray, voltage: np.ndarray | None) -> None:
        """One control step of the muscles and MuJoCo under ``action`` (its ``voltage`` if computed) and
        the push, if in it."""
        d = self.data
        if voltage is None:
            self.drive.set_action(action, clipped=self.env_cfg.action_filter_alpha >= 1.0)  # _command's clip
        else:
            self.drive.set_voltages(voltage)
        if self._push_steps:
            d.xfrc_applied[self._torso_id, :3] = self._push_force_n if self.episode.steps + 1 in self._push_steps else 0.0
        self.drive.advance(self.model, d, self.qpos_idx, self.qvel_idx, self.env_cfg.muscle_dt_s, self.n_muscle_steps,
                           self.n_physics_per_muscle)  # apply, mj_step, ...

    def _state(self) -> _State:
        """qpos and qvel as Python lists, and from them the torso's (x, y, z, roll, pitch, yaw,
        vx, vy, vz, wx, wy, wz): read once per step for the observation, reward, fall check
        and info (Python floats: cheaper than numpy scalars, and the same values)."""
        q, v = self._qpos.tolist(), self._qvel.tolist()
        return q, v, (*q[0:3], *quat_to_euler(q[3:7]), *v[0:6])

    def foot_forces_n(self) -> np.ndarray:
        """Normal ground force [N] under the right and left foot (MuJoCo touch sensors; with
        ``body.toe`` each foot's sum of its sole's and its toe's). Sensors are evaluated inside
        ``mj_step`` before integration, so the value lags the state by one physics step."""
        return np.array(self._foot_forces())

    def _foot_forces(self) -> list[float]:
        """:meth:`foot_forces_n` as a list (the same sums, as Python floats)."""
        sensed = self._sensordata.tolist()
        right, left = self._foot_sensors(sensed)
        if self._toe_sensors is not None:  # body.toe: the toe's touch sensor, under the same foot
            right_toe, left_toe = self._toe_sensors(sensed)
            return [right + right_toe, left + left_toe]
        return [right, left]

    def _contact(self, foot_force_n: list[float]) -> list[bool]:
        """Which feet are on the ground under these forces [N]."""
        right, left = foot_force_n
        return [right > self.contact_n, left > self.contact_n]

    def _gas(self) -> np.ndarray:
        """The muscles' gas P V [kPa l] now (the air meter's)."""
        return self.air_meter.gas_kpa_l(self.drive.pressure_kpa.ravel(), self.drive.contraction_pct.ravel())

    def _sense(self) -> tuple[bool, list[float], np.ndarray, list[float], np.ndarray]:
        """What a step reads of the state now (:func:`pamrun.task.sensing.read_state`): whether the
        physics blew up, the feet's forces [N], their contact points (2, 4, 3) [m], the torso's 12
        values (x, y, z, roll, pitch, yaw, vx, vy, vz, wx, wy, wz) and the observation."""
        ep = self.episode
        obs, soles = np.empty(self._obs_size, np.float32), np.empty(self._sole_adr.shape + (3,))
        error, right, left = self._read_state(
            self._qpos, self._qvel, self._sensordata, self._geom_xpos, self._warning_number, self._unstable,
            self._foot_adr, self._toe_adr, self._sole_adr, *self._hinge_adr, self.weight_n, ep.prev_action,
            self._torso_values, self._sensed, obs, soles)
        if self.env_cfg.observation_noise_std > 0:  # rounded once to float32, as the noiseless values
            obs[:OBS_BASE] = self._sensed + self.np_random.normal(0.0, self.env_cfg.observation_noise_std, OBS_BASE)
        command = [ep.target_speed_m_s] if self.speed_command else []
        if self.gait_clock:
            angle = 2 * math.pi * ep.phase(self.env_cfg)
            command += [math.sin(angle), math.cos(angle)]
        if command:
            obs[self._commands_at:] = command
        return error, [right, left], soles, self._torso_values.tolist(), obs

    def _fell(self, torso: list[float] | None = None) -> bool:
        """Whether the robot has fallen (:func:`pamrun.task.criteria.fell`) with the torso's 12 values
        ``torso``; on terrain, its height above the ground under it (:func:`pamrun.physics.terrain.ground_height_m`)."""
        torso = self._state()[2] if torso is None else torso
        if self.on_terrain:
            torso = [*torso[:2], torso[2] - self.ground_height_m(torso[0]), *torso[3:]]
        return fell_rule(torso, self.z0, self.env_cfg)

    def ground_height_m(self, x: float) -> float:
        """The ground's height [m] at ``x`` along the path (:func:`pamrun.physics.terrain.ground_height_m`)."""
        return ground_height_m(self.env_cfg, x)

    def _info(self, physics_error: bool, foot_force_n: list[float], fell: bool, torso: list[float]) -> dict[str, Any]:
        """info without the reward's dicts (and ``air_nl``); numpy scalars: TorchRL's info readers need .dtype."""
        x, y, z = torso[:3]
        distance = np.float64(x - self.episode.x0)
        if self.lean_info:
            return {"distance": distance, "physics_error": np.bool_(physics_error)}
        return {
            "x": np.float64(x),
            "y": np.float64(y),
            "z": np.float64(z),
            "torso_rpy_rad": np.array(torso[3:6]),
            "distance": distance,
            "pressure_kpa": self.drive.pressure_kpa.copy(),
            "contraction_pct": self.drive.contraction_pct.copy(),
            "foot_force_n": np.array(foot_force_n),
            "sole_xyz_m": self.episode.soles,  # (2, 4, 3), this step's
            "joint_torque_nm": self._qfrc_actuator[self.qvel_idx],
            "fell": bool(fell),
            "physics_error": np.bool_(physics_error),
            "target_speed_m_s": np.float64(self.episode.command_m_s),  # the command now (v* ramps to it)
        }
