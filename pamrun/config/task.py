"""Schemas of the walking task: reward weights (thesis Table 9.3), timing and termination (§9)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Any

from pamrun.config.checks import _non_negative, _positive, _require

# The config sections that make an agent's env, its robot (body, muscle) and its task (reward,
# env): what an agent file stores (pamrun.task.spec.EnvSpec) and what a perturbation may change.
ENV_SECTIONS = ("body", "muscle", "reward", "env")
# The terrain's keys (pamrun.physics.terrain): at most one of them set at a time.
TERRAIN_KEYS = frozenset({"env.slope_deg", "env.step_height_m", "env.rough_height_m"})
# --------------------------------------------------------------------------- task


@dataclass
class RewardConfig:
    """Per-step reward weights (thesis Table 9.3).

    r = kvx Vx - ky y^2 - kz (z - z0)^2 - kv sum(a_prev^2) + kt Ts / Tf
          - kda sum((a_prev - a_prev2)^2) - kfall [fell] - kstop n_stop / n
          + kspeed exp(-((Vx - v*) / sigma)^2) - kslip slip - kair air - kstep steps
          + kgait (1 - clock miss) - kflight [no foot down] - kflat tilt - kland landing
          - kupright (roll^2 + pitch^2) + ktrack exp(-((Vx - v*) / sigma_track)^2)
          - kdouble w_both [a foot up] + kplace (1 - path miss) + kknee (1 - knee miss)
          + kpush (1 - push-off miss) + khip (1 - hip miss) - klift n_lifts
          - ktouch n_touchdowns - klevel swing tilt - knear nearness to stops
          + kextend (1 - stance hip miss) - kreach landing reach miss (the last twenty-four: 0 in the thesis)
    """

    kvx: float = 1.0  # weight of the forward velocity Vx [per m/s]
    ky: float = 4.0  # weight of the squared lateral deviation y^2 [per m^2]
    kz: float = 60.0  # weight of the squared height change (z - z0)^2 [per m^2]
    kv: float = 0.02  # weight of the action effort sum(a^2)
    kt: float = 25.0  # alive bonus per episode (kt Ts / Tf per step)
    # Beyond Table 9.3 (0 = the thesis' reward):
    kda: float = 0.0  # weight of the squared command change sum((a - a_prev)^2), for a smoother gait
    kfall: float = 0.0  # penalty paid once, on the step an episode ends by a fall
    kstop: float = 0.0  # weight of the share of hip and ankle joints, and swinging legs' knees, within 2 deg of a stop
    kspeed: float = 0.0  # weight of the speed tracking exp(-((Vx - env.target_speed_m_s) / env.speed_sigma_m_s)^2)
    kslip: float = 0.0  # weight of the feet's slip: summed horizontal speed [m/s] of the feet in stance
    kair: float = 0.0  # weight of the supply air the muscles draw in a control step [normal litres]
    kstep: float = 0.0  # weight of the steps' miss, sum over touchdowns of (s - env.step_length_m)^2 / env.step_length_m [m]
    # weight of the feet following the gait clock, 1 - their miss (needs env.gait_period_s > 0):
    # the miss is force on a foot the clock swings; speed, or want of load, of a foot it stands on (pamrun.task.env, "Gait clock")
    kgait: float = 0.0
    kflight: float = 0.0  # penalty per control step that ends with neither foot on the ground (a walk has no flight)
    # weight of the feet's side-to-side tilt: summed |tilt| [rad] of the feet on the ground at the step's
    # end (a foot on its sole's edge grips by two corners, and pivots and slides)
    kflat: float = 0.0
    # weight of the landing feet's speed: summed horizontal speed [m/s] over the step of the feet that touch
    # down in it (a foot landing still moving forward skids on into its stance)
    kland: float = 0.0
    # weight of the torso's squared tilt from upright, roll^2 + pitch^2 [rad^2] (a walker's trunk stays
    # within a few degrees of upright)
    kupright: float = 0.0
    # weight of kspeed's pay with a narrower sigma, exp(-((Vx - v*) / env.track_sigma_m_s)^2): for a later
    # stage (train.gait_weights), once the wide one has started a walk (a narrow one alone pays a march nothing)
    ktrack: float = 0.0
    # weight of a foot off the ground while the gait clock stands both feet down: w_both [a foot up], w_both
    # = (1 - s_right)(1 - s_left) the clock's both-feet-down weight (1 while it stands still), 0 without a clock
    kdouble: float = 0.0
    # weight of the feet following the gait clock's foot path, 1 - (1/2) sum_feet min(((x_foot - x_torso - x*) / (L0 / 2))^2, 1),
    # x* from +E/2 at touchdown back to -E/2 at lift-off (E = 2 (1 - swing_share) L*), L0 = env.step_length_m; 0 without a clock
    kplace: float = 0.0
    # weight of the knees following the gait clock's knee path, 1 - (1/2) sum_legs min(((k - k*) / (k_peak / 2))^2, 1):
    # k* = k_peak sin^2(pi u^p) through a leg's swing (u its share, peaking at u = 0.3; k_peak = env.knee_path_peak_deg),
    # 0 in its stance, so a swinging knee is straight, and at rest, when its foot lands; 0 without a clock
    kknee: float = 0.0
    # weight of the ankles following the gait clock's push-off, 1 - (1/2) sum_feet min(((a - a*) / (a_peak / 2))^2, 1):
    # a* a plantarflexion rising to a_peak = env.push_off_peak_deg at a foot's lift-off over the last 0.14 of its period
    # and back to 0 over the next 0.14; the ankle free otherwise (and while the clock stands still); 0 without a clock
    kpush: float = 0.0
    # weight of the swinging hips following the gait clock's hip path, 1 - (1/2) sum_swinging min(((h - h*) / (h_peak / 2))^2, 1):
    # h* from 0 at lift-off to a flexion h_peak = env.hip_path_peak_deg x L* / env.step_length_m 0.6 into the swing,
    # 5/6 of it at touchdown; a hip in stance free (and while the clock stands still); 0 without a clock
    khip: float = 0.0
    # weight of the feet leaving the ground in the first half of the gait clock's stance (any foot while it
    # stands still), one per lift: a stance split by a bounce after its landing; 0 without a clock
    klift: float = 0.0
    # weight of the feet touching the ground more than 0.1 of the period from the gait clock's touchdown (any foot
    # while it stands still), one per touchdown: a split stance's second landing, a swing cut short; 0 without a clock
    ktouch: float = 0.0
    # weight of the summed side-to-side tilt [rad] of the feet off the ground (kflat's, for the swinging feet):
    # a swinging foot rolled onto its edge lands on it
    klevel: float = 0.0
    # weight of the joints' nearness to their stops, sum over the joints kstop counts of (1 - d / 10 deg)^2 within
    # 10 deg of a limit (d the distance to it): each joint charged on its own, from before it reaches its stop
    knear: float = 0.0
    # weight of the stance hips following the gait clock's stance hip path, 1 - (1/2) sum_stance min(((h - h*) / (h_peak / 2))^2, 1):
    # h* from khip's touchdown flexion (5/6 h_peak) straight to an extension env.hip_extension_deg x L* / env.step_length_m
    # as the other foot lands, and back to 0 at lift-off; a swinging hip free (and while the clock stands still); 0 without a clock
    kextend: float = 0.0
    # weight of the landing feet's miss of the clock's landing reach, sum over touchdowns of (r - R*)^2 / L* [m]:
    # r the sole's distance ahead of the torso, R* = (1 - env.swing_share) L* (kplace's foot path at touchdown); 0 without a clock
    kreach: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            _require(math.isfinite(getattr(self, f.name)), f.name, "must be finite")


@dataclass
class EnvConfig:
    """Timing, termination and reset of the walking task (thesis §9, §7 of THESIS.md)."""

    control_dt_s: float = 0.025  # Ts of the MathWorks example the thesis adapted
    episode_s: float = 10.0  # Tf (§9)
    # MuJoCo timestep: the largest that keeps the joint-limit constraint resolved
    # (MuJoCo needs its time constant >= 2 steps) with the muscle update a multiple of it.
    physics_dt_s: float = 0.0025
    # Muscle model update; its torque is held over muscle_dt_s / physics_dt_s MuJoCo steps.
    muscle_dt_s: float = 0.005
    fall_height_ratio: float = 0.6  # fall when torso z < ratio * standing torso z
    max_lateral_m: float = 0.5  # |y| band (§9.5 trajectories)
    max_tilt_rad: float = math.pi / 4  # |roll|, |pitch|, |yaw| limit (example's check)
    target_speed_m_s: float = 1.0  # v*: the speed reward.kspeed pays most for (the thesis' agents walked 0.6-1.1 m/s)
    speed_sigma_m_s: float = 0.5  # sigma: how fast reward.kspeed's pay falls off around v*
    track_sigma_m_s: float = 0.25  # reward.ktrack's sigma: at 0.25, 0.8 m/s told 1.0 earns 53 % of the top (kspeed: 85 %)
    # L*: the step length reward.kstep asks for (pamrun's choice: 2.5 steps/s at 1 m/s, against the
    # short, quick steps an agent takes when only its speed pays)
    step_length_m: float = 0.4
    speed_command: bool = False  # the observation ends with v*, the commanded speed [m/s]: the policy is told it
    # [low, high]: v* drawn uniformly per episode (to train a commanded speed; needs speed_command);
    # [] = v* is target_speed_m_s (pamrun eval eval.speed_m_s=V sets it). 0 (standing) is a speed
    speed_range_m_s: list[float] = field(default_factory=list)
    # [[time_s, speed_m_s], ...]: v* piecewise constant within the episode, from 0 s, times increasing
    # and inside episode_s, rounded to control steps (pamrun eval eval.speed_schedule sets it); [] = off
    # (typed Any: OmegaConf does not convert the numbers of nested lists; checked and made floats here)
    speed_schedule: list[Any] = field(default_factory=list)
    # v* drawn again from speed_range_m_s this many times per episode, at times drawn uniformly in it
    speed_changes: int = 0
    # chance that a v* drawn from speed_range_m_s (at reset or a change) is 0 instead: learning to stop
    speed_stop_share: float = 0.0
    # How fast v* moves to a changed command [m/s^2]: within an episode, the v* the policy is told, the
    # reward pays and the clock follows moves toward each new command by at most this much a second (a
    # stop from 1.2 m/s at 2 takes 0.6 s: one step); an episode starts at its command. 0 = at once
    speed_ramp_m_s2: float = 0.0
    # The command applied is alpha a + (1 - alpha) a_prev: a first-order low-pass of the policy's
    # action a (a_prev the last applied command, 0 at reset), for smaller pressure steps; 1 = off
    action_filter_alpha: float = 1.0
    # Gait clock (pamrun.task.env, "Gait clock"; Siekmann et al., ICRA 2021): a phase that turns once per
    # stride of this period [s], the right foot's swing in its first swing_share, the left's half a
    # period later; the observation ends with the phase's sine and cosine, reward.kgait pays for
    # following it. 0 = no clock. pamrun's choice for the period: 2.5 steps/s, which at
    # step_length_m (0.4 m) is 1 m/s
    gait_period_s: float = 0.0
    swing_share: float = 0.4  # share of the period a foot swings; < 0.5 leaves both feet down between steps
    # Height [m] reward.kgait wants a swinging foot's lowest point to reach, its miss the shortfall's
    # share (pamrun.task.env, "Gait clock"); 0 = off (only force on the swinging foot is charged)
    swing_clearance_m: float = 0.0
    # Knee flexion [deg] reward.kgait wants of a swinging leg, its miss the shortfall's share
    # (pamrun.task.env, "Gait clock"); 0 = off. env.stance_knee_deg asks the stance knee
    swing_knee_deg: float = 0.0
    # Knee flexion [deg] at which reward.kgait charges a leg the clock stands on fully, its miss
    # the bend's share (pamrun.task.env, "Gait clock"): asks stance toward the knee's lock; 0 = off
    stance_knee_deg: float = 0.0
    # Peak knee flexion [deg] of reward.kknee's knee path, 0.3 into the swing: about 60 deg in human walking
    # (Winter, Biomechanics and Motor Control of Human Movement, 4th ed. 2009; the 40-70 deg)
    knee_path_peak_deg: float = 60.0
    # Ankle plantarflexion [deg] reward.kpush wants at a foot's lift-off: about 20 deg in human walking
    # (Winter, Biomechanics and Motor Control of Human Movement, 4th ed. 2009)
    push_off_peak_deg: float = 20.0
    # Hip flexion [deg] reward.khip wants of a swinging leg at its most, at env.step_length_m (scaled by the
    # episode's step length): about 30 deg in human walking (Winter 2009; Perry, Gait Analysis, 1992)
    hip_path_peak_deg: float = 30.0
    # Hip extension [deg] reward.kextend wants of a stance leg at its most, as the other foot lands, at
    # env.step_length_m (scaled as hip_path_peak_deg): 10-20 deg in human walking (Perry, Gait Analysis, 1992)
    hip_extension_deg: float = 15.0
    # The clock's period and reward.kstep's step length follow the episode's commanded speed v*,
    # each as its square root, so v* = 2 L* / T at every v* (pamrun's choice, after human walking;
    # the rule: pamrun.task.env, "Gait clock", gait_at_speed); at v* = 0 the clock stops, both feet asked down
    gait_follows_speed: bool = False
    reset_noise_rad: float = 0.0  # uniform noise on joint angles at reset
    reset_velocity_noise: float = 0.0  # uniform noise on joint velocities [rad/s]
    # Perturbations (pamrun eval's robustness suite uses them; a user can train under them too):
    observation_noise_std: float = 0.0  # Gaussian noise on the 33 sensed observations (not the previous action), in their units
    push_impulse_ns: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])  # impulse on the torso, world x, y, z [N s]
    push_time_s: float = 5.0  # when the push starts [s from reset]
    push_duration_s: float = 0.1  # how long it lasts [s], rounded to whole control steps (at least one)
    # Terrain (pamrun.physics.terrain; at most one of the three; all 0 = the flat floor): the robot
    # starts on flat ground and the terrain begins terrain_x_m ahead, across the path.
    slope_deg: float = 0.0  # a slope [deg], + uphill in the walking direction (+x); |slope| <= 15
    step_height_m: float = 0.0  # a step across the path [m], + up, - down; |height| <= 0.1
    rough_height_m: float = 0.0  # uneven ground, each point within +-this [m] (buried spheres on a 10 cm grid, fixed per model); <= 0.05
    terrain_x_m: float = 1.0  # where the terrain begins [m ahead of the start]; >= 0.3, clear of the feet

    def __post_init__(self) -> None:
        _positive(self, "control_dt_s", "episode_s", "physics_dt_s", "max_lateral_m", "max_tilt_rad", "speed_sigma_m_s",
                  "track_sigma_m_s", "step_length_m")
        _non_negative(self, "reset_noise_rad", "reset_velocity_noise", "observation_noise_std", "push_time_s")
        _positive(self, "push_duration_s")
        _require(math.isfinite(self.target_speed_m_s), "target_speed_m_s", "must be finite")
        _non_negative(self, "gait_period_s")
        _require(0 < self.swing_share < 1, "swing_share", f"must lie in (0, 1), got {self.swing_share}")
        _require(0 < self.knee_path_peak_deg <= 120, "knee_path_peak_deg",
                 f"must lie in (0, 120], got {self.knee_path_peak_deg}")
        _require(0 < self.push_off_peak_deg <= 45, "push_off_peak_deg",
                 f"must lie in (0, 45], got {self.push_off_peak_deg}")
        _require(0 < self.hip_path_peak_deg <= 45, "hip_path_peak_deg",
                 f"must lie in (0, 45], got {self.hip_path_peak_deg}")
        _require(0 <= self.hip_extension_deg <= 45, "hip_extension_deg",
                 f"must lie in [0, 45], got {self.hip_extension_deg}")
        for name in ("swing_clearance_m", "swing_knee_deg", "stance_knee_deg"):
            _non_negative(self, name)
            _require(not getattr(self, name) or self.gait_period_s > 0, name,
                     "needs a gait clock (env.gait_period_s > 0, e.g. 0.8)")
        _require(not self.gait_follows_speed or self.gait_period_s > 0, "gait_follows_speed",
                 "needs a gait clock (env.gait_period_s > 0, e.g. 0.8)")
        _require(not self.gait_follows_speed or self.target_speed_m_s >= 0, "target_speed_m_s",
                 f"must be >= 0 with env.gait_follows_speed, got {self.target_speed_m_s}")
        _require(0 < self.action_filter_alpha <= 1, "action_filter_alpha",
                 f"must lie in (0, 1] (1 = no filter), got {self.action_filter_alpha}")
        r = list(self.speed_range_m_s)
        _require(not r or (len(r) == 2 and all(math.isfinite(v) for v in r) and 0 <= r[0] <= r[1]), "speed_range_m_s",
                 f"must be [] or [low, high] with 0 <= low <= high in m/s, got {r}")
        _require(not r or self.speed_command, "speed_range_m_s",
                 "needs env.speed_command=true: a policy asked for a drawn speed must be told it")
        self._check_speed_changes()
        _require(len(self.push_impulse_ns) == 3 and all(math.isfinite(v) for v in self.push_impulse_ns),
                 "push_impulse_ns", f"must be three finite values [x, y, z] in N s, got {list(self.push_impulse_ns)}")
        if any(self.push_impulse_ns):
            _require(self.push_time_s + self.push_duration_s <= self.episode_s + 1e-9, "push_time_s",
                     f"the push ({self.push_time_s} s + {self.push_duration_s} s) must end within the episode "
                     f"({self.episode_s} s)")
        self._check_terrain()
        _require(0 < self.fall_height_ratio < 1, "fall_height_ratio", "must lie in (0, 1)")
        _positive(self, "muscle_dt_s")
        for key, big, small in (
            ("muscle_dt_s", self.control_dt_s, self.muscle_dt_s),
            ("physics_dt_s", self.muscle_dt_s, self.physics_dt_s),
        ):
            ratio = big / small
            _require(
                abs(ratio - round(ratio)) < 1e-6 and round(ratio) >= 1,
                key,
                f"must divide {'control_dt_s' if key == 'muscle_dt_s' else 'muscle_dt_s'} ({big}) a whole number "
                f"of times, got {small}",
            )
        _require(self.episode_s >= self.control_dt_s, "episode_s", "must be >= control_dt_s")

    def _check_terrain(self) -> None:
        for name, limit in (("slope_deg", 15.0), ("step_height_m", 0.1)):
            value = getattr(self, name)
            _require(math.isfinite(value) and abs(value) <= limit, name, f"must lie in [-{limit}, {limit}], got {value}")
        _require(math.isfinite(self.rough_height_m) and 0 <= self.rough_height_m <= 0.05, "rough_height_m",
                 f"must lie in [0, 0.05] m, got {self.rough_height_m}")
        _require(math.isfinite(self.terrain_x_m) and self.terrain_x_m >= 0.3, "terrain_x_m",
                 f"must be >= 0.3 m (the feet stand within it), got {self.terrain_x_m}")
        chosen = [name for name in ("slope_deg", "step_height_m", "rough_height_m") if getattr(self, name)]
        _require(len(chosen) <= 1, chosen[-1] if chosen else "slope_deg",
                 f"one terrain at a time, got {' and '.join(chosen)}")

    def _check_speed_changes(self) -> None:
        """The speed schedule and the drawn speed changes (each failure names its key)."""
        self.speed_schedule = check_speed_schedule(self.speed_schedule, self.episode_s, "speed_schedule",
                                                   "env.episode_s")
        _require(not self.speed_schedule or not self.speed_range_m_s, "speed_schedule",
                 "sets v* itself: leave env.speed_range_m_s empty")
        _require(self.speed_changes >= 0, "speed_changes", f"must be >= 0, got {self.speed_changes}")
        _require(0 <= self.speed_stop_share <= 1, "speed_stop_share", f"must lie in [0, 1], got {self.speed_stop_share}")
        _require(math.isfinite(self.speed_ramp_m_s2) and self.speed_ramp_m_s2 >= 0, "speed_ramp_m_s2",
                 f"must be >= 0 (0 = at once), got {self.speed_ramp_m_s2}")
        for name in ("speed_changes", "speed_stop_share"):
            _require(not getattr(self, name) or self.speed_range_m_s, name,
                     "draws from env.speed_range_m_s: set it, e.g. [0, 1.2]")


def check_speed_schedule(schedule: list, episode_s: float, key: str, episode_key: str) -> list[list[float]]:
    """``schedule`` as floats, checked: [] or [[time_s, speed_m_s], ...], first time 0, times
    increasing and before ``episode_s`` (named ``episode_key``), speeds finite and >= 0;
    ConfigError naming ``key``."""
    entries = [list(e) if isinstance(e, (list, tuple)) else e for e in schedule]
    for i, entry in enumerate(entries):
        _require(isinstance(entry, list) and len(entry) == 2
                 and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in entry),
                 key, f"entry {i} must be [time_s, speed_m_s] (two finite numbers), got {entry}")
        _require(entry[1] >= 0, key, f"entry {i}: speed must be >= 0 m/s, got {entry[1]}")
    times = [e[0] for e in entries]
    _require(not times or times[0] == 0, key, f"must start at time 0 s, got {times[:1]}")
    _require(all(a < b for a, b in zip(times, times[1:])), key, f"times must increase, got {times}")
    _require(not times or times[-1] < episode_s, key,
             f"time {times[-1] if times else 0} s is not inside the episode ({episode_key} = {episode_s} s)")
    return [[float(t), float(v)] for t, v in entries]
