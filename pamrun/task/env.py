"""PamWalker: the thesis' walking task as a Gymnasium environment (thesis §9).

The MuJoCo body of :mod:`pamrun.physics.body` driven by the 20 muscles of
:mod:`pamrun.physics.actuation`. Every constant is a keyword argument whose default is the
thesis value, so ``gymnasium.make("pamrun/PamWalker-v0", reward={"kz": 30})`` works
without Hydra; the Hydra groups ``body``, ``muscle``, ``reward`` and ``env`` map onto the
keyword arguments of the same names.

## Action space
``muscle.command=antagonistic`` (default, as the thesis): ``Box(-1, 1, (10,), float32)``,
one value a per joint, in ``pamrun.physics.body.JOINTS`` order (right leg then left, each hip
pitch, hip roll, knee, ankle pitch, ankle roll). The pair of that joint gets
V1 = V0 + dV a, V2 = V0 - dV a (§9.5; default V0 = dV = 3 V, i.e. 0.1-6 bar; thesis
2.12 +- 0.71 V). ``muscle.command=independent``: ``Box(-1, 1, (20,), float32)``, one value
per muscle, V = V0 + dV a, in the order (joint 0 muscle 1, joint 0 muscle 2, joint 1 ...).
With ``env.action_filter_alpha`` alpha < 1 the command applied is alpha a + (1 - alpha) a_prev,
a_prev the command applied in the step before (0 at reset): a first-order low-pass that
shrinks each pressure step by alpha (the observation's previous action is the applied command).
The action is held for one control step Ts = 0.025 s (``env.control_dt_s``). Within it
the muscle model steps every ``env.muscle_dt_s`` (5 ms) and MuJoCo every
``env.physics_dt_s`` (2.5 ms): between muscle steps MuJoCo applies each pair's torque
linearised at the last muscle step (torque, stiffness and damping through the actuators'
affine bias, see ``MuscleDrive.apply``), so a stiff pair acts at every physics step with no
Python per physics step.

## Observation space
``Box(-inf, inf, (33 + n_actions,), float32)``: 43 values (antagonistic) or 53 (independent),
one more with ``env.speed_command`` (the commanded speed), two more with a gait clock (last).
``env.observation_structure`` names each block as a slice (use it instead of indices):

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
| 33-42 (33-52) | ``previous_action`` | the previous action (10 or 20 values) | 1 |
| 43 (53) | ``speed_command`` | v*, the commanded speed (only with ``env.speed_command``) | m/s |
| last 2 | ``gait_clock`` | sin, cos of 2 pi phi, the gait clock's phase (only with ``env.gait_period_s``) | 1 |

## Commanded speed
``kspeed`` pays for walking near v*. v* is ``env.target_speed_m_s``, or, with
``env.speed_range_m_s = [low, high]``, drawn uniformly per episode at reset (training a policy
that walks at the speed it is told); ``env.speed_command`` appends v* to the observation so the
policy can be told. ``info["target_speed_m_s"]`` holds the episode's v*.

## Gait clock
With ``env.gait_period_s`` T > 0 a clock runs: phase phi = phi0 + t / T (mod 1), phi0 drawn
uniformly per episode at reset (so no phase is tied to the start, and a mirrored transition, whose
phase is shifted by half a period, is as likely as its original). The right foot's clock is phi, the
left's phi + 1/2: each foot swings in the first ``env.swing_share`` (sigma) of its period, smoothly,
with weight s = (1 + tanh((sin 2 pi phi - cos pi sigma) / 0.1)) / 2 (sin 2 pi phi > cos pi sigma for a
share sigma of the period), and stands on the ground the rest; with sigma < 1/2 both feet are down
between steps, as in walking. The observation ends with sin 2 pi phi, cos 2 pi phi (the policy's
clock). With ``env.gait_follows_speed`` the episode's period and ``kstep``'s step length follow its
commanded speed v*: T = gait_period_s sqrt(v0 / v*), L* = step_length_m sqrt(v* / v0), v0 =
2 step_length_m / gait_period_s (:func:`gait_at_speed`), so that v* = 2 L* / T (cadence and step
length each grow with the square root of speed, as in human walking).

``kgait`` pays for following the clock (Siekmann et al., "Sim-to-real learning of all common
bipedal gaits via periodic reward composition", ICRA 2021), less each foot's miss: its
ground force f (as a share of the robot's weight, at most 1) while it should swing, and while it
should stand the larger of its sole centre's horizontal speed u (m/s, at most 1) and its want of
load, 1 - min(2 f, 1) (a stance foot carries at least half the weight): feature
1 - (1/2) sum_feet [s max(f, c, k) + (1 - s) max(u, 1 - min(2 f, 1))], in [0, 1], with c the swing's
want of clearance, 1 - min(h / H, 1), h the height of the foot's lowest contact point above the floor
and H ``env.swing_clearance_m``, and k its want of knee bend, 1 - min(q / K, 1), q the leg's knee
flexion (0 straight, on its stop) and K ``env.swing_knee_deg`` (c = 0 with H = 0, k = 0 with K = 0,
the defaults); with ``env.stance_knee_deg`` S > 0 a standing leg's miss is also at least its bend's
share of S, min(q / S, 1) (:func:`foot_miss`). A walk in step with the
clock earns 1 a step, a two-footed hop about 0.6, standing still about 0.8. The want of load makes
a flight phase cost what it costs in a run: the first clocked walker (speed only) kept its
clock-stance feet off the ground 40 % of the time, a stiff-legged run (duty factor 0.42, 0.58 of
kgait's 1 earned). The feature is positive, as the alive bonus:
a clock charged as a penalty (-(1/2) sum ..., tried first) made a fall within a second cheaper
than a stumbling step: all six evaluations in the 70,000 frames after the pilot stood fell within 1.6 s.
The want of clearance asks a swing to lift its foot (the clocked walkers swung straight knees,
at their stop 99.8 % of the swing); at 5 cm the one run with it lifted its feet 15 cm by
bounding, its knees still straight: a foot can be lifted without bending a knee. The want of knee
bend asks the knee itself: at 20 deg the one run with it bent its swing knees (at their stop 1 %
of the swing, 70-75 deg at mid-swing; and bent 35-45 deg at touchdown: a crouch), in step with
the clock, and held every perturbation of the robustness suite better than the clocked walkers
without it.

## Reward (thesis Table 9.3, config group ``reward``)
r = kvx Vx - ky y^2 - kz (z - z0)^2 - kv sum(a_prev^2) + kt Ts / Tf - kda sum((a_prev - a_prev2)^2)
- kfall [fell] - kstop n_stop / n + kspeed exp(-((Vx - v*) / sigma)^2) - kslip slip - kair air
- kstep sum_touchdowns (s - L*)^2 / L* + kgait (1 - miss) (the gait clock's, above), with Vx the torso's forward velocity, y its lateral
deviation, z - z0 its height change since reset, a_prev the action applied in this step (the
"previous action" of the next observation) and a_prev2 the one before it (zero at reset).
The last eight terms are not the thesis' (their weights are 0 by default): ``kda`` penalises
changes of the command, for the smoother gait the thesis asked for; ``kfall`` is paid once,
on the step that ends the episode by a fall; ``kstop`` penalises the share n_stop / n of the
hip and ankle joints, and of the knees of legs whose foot is off the ground, within 2 deg of a
stop (:data:`pamrun.evaluation.metrics.STOP_MARGIN_DEG`; a knee in stance rests on its extension stop by
design, its lock; in swing it should bend); ``kspeed`` pays for walking near
``env.target_speed_m_s`` (v*, within ``env.speed_sigma_m_s``) rather than ever faster; ``kslip``
penalises slip: the horizontal speed [m/s] of each foot's ground point over a control step in
which the foot is on the ground at both ends, summed over the feet (:mod:`pamrun.evaluation.metrics`'s foot
slip, per step; a foot is on the ground above its ``CONTACT_WEIGHT_SHARE`` of the weight);
``kair`` penalises the supply air the muscles draw in the step [normal litres]
(:func:`pamrun.physics.muscle.air_nl`'s rule: a muscle draws while its P V grows; also
``info["air_nl"]``); ``kstep`` penalises each step whose length s misses ``env.step_length_m``
(L*): in a control step in which a foot touches down (it is on the ground and was not at the
step before), (s - L*)^2 / L* [m], with s its sole centre's forward distance ahead of the other
foot's (:mod:`pamrun.evaluation.metrics`'s touchdown and step length, per step). Convex in s, it costs a limp
more than even steps of the same stride (0.2 and 0.6 m: 0.2 m; 0.4 and 0.4 m: 0), and it costs
many short steps (0.15 m at 6.4 steps/s: 1.0 m per second) more than fewer long ones; ``kgait``
pays for the feet following the gait clock (above; it needs ``env.gait_period_s``).

Every term is a weight times an unweighted feature, and this is the formula's one home
(:meth:`PamWalkerEnv.reward_features`, :data:`REWARD_KEYS`, MyoSuite's style): the features are
Vx, -y^2, -(z - z0)^2, -sum(a_prev^2), Ts / Tf, -sum((a_prev - a_prev2)^2), -[fell],
-n_stop / n, exp(-((Vx - v*) / sigma)^2), -slip, -air, -sum (s - L*)^2 / L* and the clock's 1 - miss (0 without a clock), all 0 in a step
whose physics blew up. ``info["reward_terms"]`` holds the weighted terms under the key of
their weight (``kvx``: forward, ``ky``: lateral, ``kz``: height, ``kv``: effort, ``kt``: alive,
``kda``: command change, ``kfall``: fall, ``kstop``: joint stops, ``kspeed``: speed, ``kslip``: slip,
``kair``: air, ``kstep``: steps, ``kgait``: gait clock), so a term and the ``reward.<key>`` that scales it
share one name; ``info["reward_unweighted"]`` holds the features in ``REWARD_KEYS`` order and
``env.reward_weights`` the weights, so a learner can re-weight any term after the fact
(pamrun's training stores the features in its replay buffer: :mod:`pamrun.learning.curriculum`).

## Perturbations (``env`` group; ``pamrun eval eval.suite=robustness`` uses them)
``observation_noise_std`` adds Gaussian noise of that standard deviation (in each value's
own unit) to the 33 sensed observations, not to the previous action, from the env's seeded
generator. ``push_impulse_ns`` [x, y, z, world frame, N s] is applied to the torso as a
constant force from ``push_time_s`` for ``push_duration_s`` rounded to whole control steps
(at least one), force = impulse / (steps x Ts), so the impulse is exact.

## Episode end
Truncation after Tf = 10 s (400 steps). Termination by a fall (:func:`pamrun.task.criteria.fell`: the
torso below ``fall_height_ratio`` of its standing height, |y| > ``max_lateral_m``, |roll|,
|pitch| or |yaw| >= pi/4) or when the physics state is not finite (``info["physics_error"]``
is then True). The env truncates itself rather than through Gymnasium's ``TimeLimit``: it is
built directly (pamrun's evaluation, tests) as well as by ``gymnasium.make``, and its length
is a config value (``env.episode_s``).

## info
``x``, ``y``, ``z``, ``distance`` (x walked since reset) [m], ``reward_terms``, ``reward_unweighted``,
``pressure_kpa`` and ``contraction_pct`` (10, 2) of the 20 muscles, ``foot_force_n``
(right, left) [N], ``sole_xyz_m`` (2, 4, 3) the centres of each foot's four contact spheres
(front left, front right, back left, back right) [m], ``joint_torque_nm`` (10,)
the muscles' torque on each joint at the end of the step [N m], ``fell``, ``physics_error``.
"""

from __future__ import annotations

import math
import operator
import os
from dataclasses import asdict, is_dataclass
from typing import Any

import gymnasium as gym
import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")
import mujoco  # noqa: E402
from omegaconf import OmegaConf  # noqa: E402

from pamrun.config import BodyConfig, EnvConfig, MuscleConfig, RewardConfig, to_object  # noqa: E402
from pamrun.config.robot import LEG_JOINTS, MUSCLE_INNER_DIAMETER_M  # noqa: E402
from pamrun.physics import body as body_mod  # noqa: E402
from pamrun.physics.actuation import MuscleDrive, joint_limits_rad, n_actions  # noqa: E402
from pamrun.physics.muscle import AirMeter  # noqa: E402
from pamrun.task.criteria import fell as fell_rule  # noqa: E402
from pamrun.task.measures import CONTACT_WEIGHT_SHARE, STOP_MARGIN_DEG, step_length  # noqa: E402

N_JOINTS = len(body_mod.JOINTS)  # the hinges, pamrun.config.LEG_JOINTS on each side
# Observation blocks in order, with their sizes (the table above); the previous action follows.
_OBS_BLOCKS = (("torso_y", 1), ("torso_z", 1), ("torso_rpy", 3), ("torso_velocity", 3), ("torso_angular_velocity", 3),
               ("joint_angle", N_JOINTS), ("joint_velocity", N_JOINTS), ("foot_force", 2))
# The unit of each block (the table above), for readers outside pamrun (pamrun export's metadata).
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


REWARD_KEYS = tuple(RewardConfig.__dataclass_fields__)  # one reward term per weight, same key


def space_sizes(muscle: MuscleConfig | dict | None = None, env: EnvConfig | dict | None = None) -> tuple[int, int]:
    """(observations, actions) of the env for this muscle and env config, without building it."""
    n, env = n_actions(as_config(muscle, MuscleConfig)), as_config(env, EnvConfig)
    return _obs_size(observation_structure(n, env.speed_command, env.gait_period_s > 0)), n


def _obs_size(structure: dict[str, slice]) -> int:
    """The observation's length: where its last block ends."""
    return max(s.stop for s in structure.values())
_INSTABILITY_WARNINGS = (
    mujoco.mjtWarning.mjWARN_BADQPOS,
    mujoco.mjtWarning.mjWARN_BADQVEL,
    mujoco.mjtWarning.mjWARN_BADQACC,
)
# What one step reads of the state (PamWalkerEnv._state): qpos, qvel, and the torso's 12 values.
_State = tuple[list[float], list[float], tuple[float, ...]]
_unstable_counts = operator.itemgetter(*(int(w) for w in _INSTABILITY_WARNINGS))  # from warning.number


def as_config(value: Any, cls: type) -> Any:
    """A dataclass of type ``cls`` from None, a dataclass, or a (nested, partial) dict.

    Dicts are merged over the defaults through OmegaConf, so unknown keys and wrong types
    fail with the key named, then values are validated (pamrun.config.ConfigError).
    """
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if is_dataclass(value):
        value = asdict(value)
    merged = OmegaConf.merge(OmegaConf.structured(cls), OmegaConf.create(dict(value)))
    return to_object(merged)


def _all_finite(*values: list[float]) -> bool:
    """Every value finite. A finite sum proves it (NaN and inf propagate through a sum); only a
    non-finite sum, which may be overflow, needs the value-by-value check."""
    return math.isfinite(sum(map(sum, values))) or all(math.isfinite(x) for v in values for x in v)


def swing_weights(phase: float, swing_share: float) -> tuple[float, float]:
    """How much the gait clock swings the right and the left foot at this phase (module
    docstring, "Gait clock"): 1 in swing, 0 in stance, smooth in between."""
    edge = math.cos(math.pi * swing_share)
    return tuple(0.5 * (1.0 + math.tanh((math.sin(2 * math.pi * (phase + 0.5 * foot)) - edge) / 0.1))
                 for foot in (0, 1))


def foot_miss(swing: float, share: float, speed_m_s: float, lift_m: float, knee_rad: float, env: EnvConfig) -> float:
    """One foot's miss of the gait clock, in [0, 1] (module docstring, "Gait clock"): swing weight
    s, ground force as a share of the weight, sole speed, lowest point's height above the floor and
    the leg's knee flexion (0 straight)."""
    stance = max(min(speed_m_s, 1.0), 1.0 - min(2.0 * share, 1.0))  # moving, or not carrying
    swing_miss = min(share, 1.0)  # carrying
    if env.swing_clearance_m:  # not lifted
        swing_miss = max(swing_miss, 1.0 - min(max(lift_m, 0.0) / env.swing_clearance_m, 1.0))
    if env.swing_knee_deg:  # not bent
        swing_miss = max(swing_miss, 1.0 - min(max(knee_rad, 0.0) / math.radians(env.swing_knee_deg), 1.0))
    if env.stance_knee_deg:  # bent while it should carry
        stance = max(stance, min(max(knee_rad, 0.0) / math.radians(env.stance_knee_deg), 1.0))
    return swing * swing_miss + (1.0 - swing) * stance


def gait_at_speed(env: EnvConfig, speed_m_s: float) -> tuple[float, float]:
    """The gait clock's period T [s] and kstep's step length L* [m] at commanded speed v*
    (``env.gait_follows_speed``; otherwise ``env.gait_period_s``, ``env.step_length_m``)."""
    if not env.gait_follows_speed:
        return env.gait_period_s, env.step_length_m
    ratio = math.sqrt(speed_m_s * env.gait_period_s / (2 * env.step_length_m))  # sqrt(v* / v0)
    return env.gait_period_s / ratio, env.step_length_m * ratio


def quat_to_euler(quat_wxyz: np.ndarray) -> tuple[float, float, float]:
    """Roll, pitch, yaw [rad] (extrinsic x-y-z) of a unit quaternion (w, x, y, z)."""
    w, x, y, z = quat_wxyz
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


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
    ):
        self.body_cfg = as_config(body, BodyConfig)
        self.muscle_cfg = as_config(muscle, MuscleConfig)
        self.reward_cfg = as_config(reward, RewardConfig)
        self.reward_weights = np.array([getattr(self.reward_cfg, k) for k in REWARD_KEYS])  # REWARD_KEYS order
        self.env_cfg = as_config(env, EnvConfig)
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self.width, self.height = width, height

        self.model = body_mod.build_model(self.body_cfg, timestep_s=self.env_cfg.physics_dt_s)
        self.data = mujoco.MjData(self.model)
        self.n_muscle_steps = int(round(self.env_cfg.control_dt_s / self.env_cfg.muscle_dt_s))
        self.n_physics_per_muscle = int(round(self.env_cfg.muscle_dt_s / self.env_cfg.physics_dt_s))
        self.n_substeps = self.n_muscle_steps * self.n_physics_per_muscle  # MuJoCo steps per control step
        self.max_steps = int(round(self.env_cfg.episode_s / self.env_cfg.control_dt_s))
        self.drive = MuscleDrive(self.muscle_cfg, self.body_cfg)

        m = self.model
        self.qpos_idx, self.qvel_idx = body_mod.joint_addresses(m)  # the hinges in qpos, qvel (JOINTS order)
        self._torso_id = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, body_mod.TORSO)
        self._sole_ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, f"{side}_contact_{end}_{edge}")
                          for side in body_mod.SIDES for end in ("front", "back") for edge in ("left", "right")]
        self._foot_sensor_adr = np.array(
            [m.sensor_adr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, s)] for s in body_mod.FOOT_SENSORS]
        )
        toes = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SENSOR, s) for s in body_mod.TOE_SENSORS]
        self._toe_sensor_adr = m.sensor_adr[toes] if min(toes) >= 0 else None  # body.toe: added to the feet
        self.mass_kg = float(m.body_subtreemass[0])  # the whole robot
        self.weight_n = float(m.body_subtreemass[0] * -m.opt.gravity[2])

        key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "stand")
        self._qpos0 = m.key_qpos[key].copy() if key >= 0 else m.qpos0.copy()
        self.z0 = float(self._qpos0[2])

        self.n_actions = self.drive.n_actions
        self.action_space = gym.spaces.Box(-1.0, 1.0, (self.n_actions,), np.float32)
        self.speed_command = self.env_cfg.speed_command
        self.gait_clock = self.env_cfg.gait_period_s > 0
        self._phase0 = 0.0  # the gait clock's phase at reset (drawn per episode)
        self.observation_structure = observation_structure(self.n_actions, self.speed_command, self.gait_clock)
        size = _obs_size(self.observation_structure)
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (size,), np.float32)
        self.target_speed_m_s = self.env_cfg.target_speed_m_s  # v*, this episode's (env.speed_range_m_s)
        self.gait_period_s, self.step_length_m = gait_at_speed(self.env_cfg, self.target_speed_m_s)  # T, L* at v*
        self._prev_action = np.zeros(self.n_actions)
        self._joint_angles = operator.itemgetter(*self.qpos_idx.tolist())  # from qpos as a list
        margin = math.radians(STOP_MARGIN_DEG)
        self._stops_rad = joint_limits_rad(self.body_cfg) + [margin, -margin]  # 'at a stop' below / above these
        # (qpos address, lower, upper) of each hip and ankle joint, and of each knee with its foot's
        # column in foot_forces_n (right, left), as Python floats: read every step
        limits = [(int(adr), float(lo), float(hi), name) for adr, (lo, hi), name in
                  zip(self.qpos_idx, self._stops_rad, body_mod.JOINTS)]
        self._stop_checks = [(adr, lo, hi) for adr, lo, hi, name in limits if "knee" not in name]
        self._knee_checks = [(adr, lo, hi, body_mod.SIDES.index(name.split("_")[0]))
                             for adr, lo, hi, name in limits if "knee" in name]
        self._knee_adr = [adr for adr, _, _, _ in sorted(self._knee_checks, key=lambda k: k[3])]  # kgait's: right, left
        self._sole_radius_m = float(m.geom_size[self._sole_ids, 0].max())  # kgait's clearance: sphere bottom
        self.contact_n = CONTACT_WEIGHT_SHARE * self.weight_n  # a foot carrying more is on the ground
        mc = self.muscle_cfg  # info["air_nl"] and kair's feature
        self.air_meter = AirMeter(mc.nominal_length_m, MUSCLE_INNER_DIAMETER_M[mc.size],
                                  [getattr(mc.count, j) for _ in body_mod.SIDES for j in LEG_JOINTS])
        self._gas, self._air_nl = None, 0.0  # the muscles' gas P V [kPa l] after the last step, this step's air
        self._soles, self._contact = None, [False, False]  # the feet's spheres and ground contact after the last step
        # this step's slip [m/s], steps' miss [m] and gait clock's 1 - miss (kslip's, kstep's and kgait's features)
        self._slip, self._step, self._gait = 0.0, 0.0, 0.0
        self._joint_velocities = operator.itemgetter(*self.qvel_idx.tolist())
        self._steps = 0
        self._x0 = 0.0
        cfg = self.env_cfg
        self._push_steps = range(0)  # control steps k (1-based, the step that starts at (k - 1) Ts) pushed
        if any(cfg.push_impulse_ns):
            n_push = max(1, int(round(cfg.push_duration_s / cfg.control_dt_s)))
            first = int(round(cfg.push_time_s / cfg.control_dt_s)) + 1
            self._push_steps = range(first, first + n_push)
            self._push_force_n = np.asarray(cfg.push_impulse_ns, float) / (n_push * cfg.control_dt_s)
        self._renderer: mujoco.Renderer | None = None

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
        if cfg.speed_range_m_s:  # after the start noise: a seed's start pose does not depend on it
            self.target_speed_m_s = float(self.np_random.uniform(*cfg.speed_range_m_s))
        if self.gait_clock:  # after the start noise and v*, for the same reason
            self._phase0 = float(self.np_random.uniform())
        self.gait_period_s, self.step_length_m = gait_at_speed(cfg, self.target_speed_m_s)  # this episode's
        self._prev_action = np.zeros(self.n_actions)
        self._steps = 0
        self._x0 = float(d.qpos[0])
        feet, state = self.foot_forces_n(), self._state()
        self._update_feet(feet)
        self._update_air()
        info = self._info(False, feet, self._fell(state), state)
        info["reward_terms"] = dict.fromkeys(REWARD_KEYS, 0.0)  # as after a step, so info's keys never change
        info["reward_unweighted"] = np.zeros(len(REWARD_KEYS))
        return self._observation(feet, state), info

    def step(self, action):
        # np.clip(action, -1, 1) as two ufuncs (np.clip's Python wrapper costs more than both).
        action = np.maximum(np.asarray(action, dtype=np.float64).reshape(self.n_actions), -1.0)
        np.minimum(action, 1.0, out=action)
        alpha = self.env_cfg.action_filter_alpha
        if alpha < 1.0:  # the low-pass (module docstring, "Action space")
            action = alpha * action + (1.0 - alpha) * self._prev_action
        m, d, drive = self.model, self.data, self.drive
        dt, nstep = self.env_cfg.muscle_dt_s, self.n_physics_per_muscle
        drive.set_action(action)
        if self._push_steps:
            d.xfrc_applied[self._torso_id, :3] = self._push_force_n if self._steps + 1 in self._push_steps else 0.0
        drive.advance(m, d, self.qpos_idx, self.qvel_idx, dt, self.n_muscle_steps, nstep)  # apply, mj_step, ...
        self._steps += 1
        previous, self._prev_action = self._prev_action, action

        # MuJoCo resets the state itself when it meets NaN/Inf, so count its warnings too.
        state = self._state()
        unstable = sum(_unstable_counts(d.warning.number.tolist()))
        physics_error = unstable > 0 or not _all_finite(state[0], state[1])
        feet = self.foot_forces_n()
        self._update_feet(feet)
        self._update_air()
        obs = self._observation(feet, state)
        if physics_error:
            obs = np.nan_to_num(obs, nan=0.0, posinf=0.0, neginf=0.0)
        fell = physics_error or self._fell(state)
        reward, terms, features = self._reward(action, physics_error, state, previous, fell)
        truncated = self._steps >= self.max_steps and not fell
        info = self._info(physics_error, feet, fell, state)
        info["reward_terms"] = terms
        info["reward_unweighted"] = np.array(features)
        return obs, reward, fell, truncated, info

    def render(self):
        if self.render_mode != "rgb_array":
            return None
        if self._renderer is None:
            self._renderer = mujoco.Renderer(self.model, self.height, self.width)
        self._renderer.update_scene(self.data, camera=body_mod.CAMERA)
        return self._renderer.render()

    def close(self):
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    # ------------------------------------------------------------------ pieces

    def _state(self) -> _State:
        """qpos and qvel as Python lists, and from them the torso's (x, y, z, roll, pitch, yaw,
        vx, vy, vz, wx, wy, wz): read once per step for the observation, reward, fall check
        and info (Python floats: cheaper than numpy scalars, and the same values)."""
        d = self.data
        q, v = d.qpos.tolist(), d.qvel.tolist()
        return q, v, (*q[0:3], *quat_to_euler(q[3:7]), *v[0:6])

    def foot_forces_n(self) -> np.ndarray:
        """Normal ground force [N] under the right and left foot (MuJoCo touch sensors; with
        ``body.toe`` each foot's sum of its sole's and its toe's).

        Sensors are evaluated inside ``mj_step`` before integration, so the value lags the
        state by one physics step (1 ms).
        """
        forces = self.data.sensordata[self._foot_sensor_adr]  # fancy indexing: a copy
        if self._toe_sensor_adr is not None:  # body.toe: the toe's touch sensor, under the same foot
            forces += self.data.sensordata[self._toe_sensor_adr]
        return forces

    def _observation(self, foot_force_n: np.ndarray, state: _State | None = None) -> np.ndarray:
        q, v, (_, y, z, roll, pitch, yaw, *velocity) = self._state() if state is None else state
        right, left = foot_force_n.tolist()
        sensed = [y, z, roll, pitch, yaw, *velocity, *self._joint_angles(q), *self._joint_velocities(v),
                  right / self.weight_n, left / self.weight_n]
        if self.env_cfg.observation_noise_std > 0:
            sensed = (np.asarray(sensed) + self.np_random.normal(0.0, self.env_cfg.observation_noise_std, OBS_BASE)).tolist()
        # float64 values rounded once to float32, as np.concatenate(...).astype(np.float32) would
        command = [self.target_speed_m_s] if self.speed_command else []
        if self.gait_clock:
            angle = 2 * math.pi * self.gait_phase()
            command += [math.sin(angle), math.cos(angle)]
        return np.array([*sensed, *self._prev_action.tolist(), *command], dtype=np.float32)

    def gait_phase(self) -> float:
        """The gait clock's phase phi in [0, 1) now (module docstring, "Gait clock")."""
        return (self._phase0 + self._steps * self.env_cfg.control_dt_s / self.gait_period_s) % 1.0

    def reward_features(self, action: np.ndarray, previous: np.ndarray | None, fell: bool,
                        state: _State | None = None) -> list[float]:
        """The reward's unweighted features in ``REWARD_KEYS`` order (module docstring, "Reward")."""
        cfg = self.env_cfg
        state = self._state() if state is None else state
        _, y, z, _, _, _, vx, *_ = state[2]
        return [vx, -(y**2), -((z - self.z0) ** 2),
                -float(np.add.reduce(action * action)),  # = np.sum(action**2), bit for bit
                cfg.control_dt_s / cfg.episode_s,
                -float(np.add.reduce((action - (action if previous is None else previous)) ** 2)),
                -float(fell),
                -self.stop_share(state[0]),
                math.exp(-(((vx - self.target_speed_m_s) / cfg.speed_sigma_m_s) ** 2)),
                -self._slip,
                -self._air_nl,
                -self._step,
                self._gait]

    def stop_share(self, qpos: list[float]) -> float:
        """Share of the hip and ankle joints, and of the knees of legs whose foot is off the ground
        (after the step), within gait.STOP_MARGIN_DEG of a stop (``kstop``'s term; a knee in
        stance rests on its extension stop by design: its lock)."""
        n, joints = sum(not lo < qpos[adr] < hi for adr, lo, hi in self._stop_checks), len(self._stop_checks)
        for adr, lo, hi, foot in self._knee_checks:
            if not self._contact[foot]:
                n, joints = n + (not lo < qpos[adr] < hi), joints + 1
        return n / joints

    def _update_air(self) -> None:
        """This step's supply air [normal litres] (``kair``'s feature, ``info["air_nl"]``): the
        air meter's between the muscles' gas before and after the step (0 at reset)."""
        drive = self.drive
        gas = self.air_meter.gas_kpa_l(drive.pressure_kpa.ravel(), drive.contraction_pct.ravel())
        self._air_nl = 0.0 if self._gas is None or self._steps == 0 else self.air_meter.drawn_nl(self._gas, gas)
        self._gas = gas

    def _update_feet(self, foot_force_n: np.ndarray) -> None:
        """This step's slip, steps and gait clock's 1 - miss (``kslip``'s, ``kstep``'s and ``kgait``'s
        features, module docstring) from the feet's ground points then and now, and the feet on
        the ground now (for the next step and ``stop_share``)."""
        soles = self.data.geom_xpos[self._sole_ids].reshape(2, -1, 3)  # fancy indexing: a copy
        forces = foot_force_n.tolist()
        contact = [f > self.contact_n for f in forces]
        slip = step = gait = 0.0
        if self._soles is not None and self._steps > 0:
            for foot in (0, 1):
                if contact[foot] and self._contact[foot]:
                    lowest = int(np.argmin(self._soles[foot, :, 2]))
                    dx, dy = (soles[foot, lowest, :2] - self._soles[foot, lowest, :2]).tolist()
                    slip += math.hypot(dx, dy) / self.env_cfg.control_dt_s
                elif contact[foot]:  # a touchdown
                    s = step_length(soles, foot)
                    step += (s - self.step_length_m) ** 2 / self.step_length_m
            if self.gait_clock:
                moved = (soles[:, :, :2].mean(axis=1) - self._soles[:, :, :2].mean(axis=1)).tolist()
                lifts = (soles[:, :, 2].min(axis=1) - self._sole_radius_m).tolist()
                knees = self.data.qpos[self._knee_adr].tolist()
                for foot, swing in enumerate(swing_weights(self.gait_phase(), self.env_cfg.swing_share)):
                    speed = math.hypot(*moved[foot]) / self.env_cfg.control_dt_s
                    gait -= 0.5 * foot_miss(swing, forces[foot] / self.weight_n, speed, lifts[foot], knees[foot],
                                            self.env_cfg)
                gait += 1.0  # 1 - the miss: paid, as the alive bonus (module docstring)
        self._soles, self._contact, self._slip, self._step, self._gait = soles, contact, slip, step, gait

    def _reward(self, action: np.ndarray, physics_error: bool, state: _State | None = None,
                previous: np.ndarray | None = None, fell: bool = False) -> tuple[float, dict[str, float], list[float]]:
        """The reward, its weighted terms by weight name, and its unweighted features."""
        features = [0.0] * len(REWARD_KEYS) if physics_error else self.reward_features(action, previous, fell, state)
        terms = {k: w * f for k, w, f in zip(REWARD_KEYS, self.reward_weights.tolist(), features)}
        return float(sum(terms.values())), terms, features

    def _fell(self, state: _State | None = None) -> bool:
        return fell_rule((self._state() if state is None else state)[2], self.z0, self.env_cfg)

    def _info(self, physics_error: bool, foot_force_n: np.ndarray, fell: bool, state: _State | None = None
              ) -> dict[str, Any]:
        torso = (self._state() if state is None else state)[2]
        x, y, z = np.float64(torso[0]), np.float64(torso[1]), np.float64(torso[2])  # TorchRL's info readers need .dtype
        return {
            "x": x,
            "y": y,
            "z": z,
            "distance": np.float64(x - self._x0),
            "pressure_kpa": self.drive.pressure_kpa.copy(),
            "contraction_pct": self.drive.contraction_pct.copy(),
            "foot_force_n": foot_force_n,
            "sole_xyz_m": self._soles,  # (2, 4, 3), this step's (_update_feet)
            "joint_torque_nm": self.data.qfrc_actuator[self.qvel_idx],
            "fell": bool(fell),
            "physics_error": np.bool_(physics_error),  # numpy: TorchRL's info reader needs a dtype
            "target_speed_m_s": np.float64(self.target_speed_m_s),  # v*, this episode's
            "air_nl": np.float64(self._air_nl),  # supply air drawn in this step [normal litres]
        }
