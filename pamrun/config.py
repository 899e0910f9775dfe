"""Typed configuration of pamrun (Hydra structured configs).

Every dataclass here is the schema of one config group under ``conf/``; its defaults are
the thesis values, each with the section it comes from (``../shared/THESIS.md``). YAML
files in ``conf/`` select and override them. Hydra rejects unknown keys and wrong types
while composing; :func:`validate` then checks values (a negative height, tau <= 0, a
pressure table that is not monotone) and raises :class:`ConfigError` naming the full
key, before any run directory is created (see :class:`ValidateConfig`).
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hydra.core.config_store import ConfigStore
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

CONF_DIR = Path(__file__).resolve().parent.parent / "conf"


class ConfigError(ValueError):
    """An impossible configuration value; ``key`` is its full dotted path."""

    def __init__(self, key: str, message: str):
        self.key, self.message = key, message
        super().__init__(f"{key}: {message}")


def _require(ok: bool, key: str, message: str) -> None:
    if not ok:
        raise ConfigError(key, message)


def _positive(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        _require(math.isfinite(value) and value > 0, name, f"must be > 0, got {value}")


def _non_negative(obj: Any, *names: str) -> None:
    for name in names:
        value = getattr(obj, name)
        _require(math.isfinite(value) and value >= 0, name, f"must be >= 0, got {value}")


# --------------------------------------------------------------------------- muscle


@dataclass
class RegulatorConfig:
    """Festo VPPM-8L-L-1-G14-0L10H proportional pressure regulator (thesis §8.3).

    Input 0-10 V, output 0.1-10 bar. The thesis calls the relation linear and, with
    V0 = 2.12 V +- 0.71 V, quotes pressures of "about 1.4 to 3 bar" (§9.5): that is
    1 bar per volt, which we take. Its dynamics are not modelled in the thesis;
    ``lag_s`` adds an optional first-order lag (0 = ideal regulator, the thesis).
    """

    gain_kpa_per_v: float = 100.0
    min_voltage_v: float = 0.0
    max_voltage_v: float = 10.0
    min_pressure_kpa: float = 10.0  # 0.1 bar
    max_pressure_kpa: float = 1000.0  # 10 bar
    lag_s: float = 0.0

    def __post_init__(self) -> None:
        _positive(self, "gain_kpa_per_v", "max_voltage_v", "max_pressure_kpa")
        _non_negative(self, "min_voltage_v", "min_pressure_kpa", "lag_s")
        _require(self.min_voltage_v < self.max_voltage_v, "max_voltage_v", "must exceed min_voltage_v")
        _require(self.min_pressure_kpa < self.max_pressure_kpa, "max_pressure_kpa", "must exceed min_pressure_kpa")


SPRING_FILE = CONF_DIR / "muscle" / "spring" / "calibrated.yaml"


def _calibrated_spring() -> dict[str, list[float]]:
    """The table written by ``pamrun muscle calibrate``: the one source of default S(P)."""
    data = _read_spring_file(SPRING_FILE.stat().st_mtime_ns)
    return {k: list(v) for k, v in data.items()}  # fresh lists: dataclass fields are mutable


@functools.lru_cache(maxsize=4)
def _read_spring_file(mtime_ns: int) -> dict[str, tuple[float, ...]]:
    """Parsed once per file version (keyed by mtime, so a new calibration is picked up)."""
    import yaml

    data = yaml.safe_load(SPRING_FILE.read_text())
    return {k: tuple(float(v) for v in data[k]) for k in ("band_edges_kpa", "stiffness_n_per_m")}


@dataclass
class SpringConfig:
    """Spring coefficient S(P) of the muscle, piecewise constant in pressure bands.

    The thesis used 1-bar bands from 0 to 8 bar and tuned the values by hand without
    publishing them (§8.3); ``pamrun muscle calibrate`` fits them to the step responses
    of §10.1 and writes ``conf/muscle/spring/calibrated.yaml``. Band k covers
    ``[band_edges_kpa[k], band_edges_kpa[k+1])``; pressures past the last edge use the
    last band. ``hysteresis`` names the law that chooses between inflation and deflation
    tables (only ``none`` so far: one table for both, as in the thesis).
    """

    band_edges_kpa: list[float] = field(default_factory=lambda: _calibrated_spring()["band_edges_kpa"])
    stiffness_n_per_m: list[float] = field(default_factory=lambda: _calibrated_spring()["stiffness_n_per_m"])
    hysteresis: str = "none"

    def __post_init__(self) -> None:
        edges, values = self.band_edges_kpa, self.stiffness_n_per_m
        _require(len(edges) >= 2, "band_edges_kpa", "needs at least two edges")
        _require(
            all(b > a for a, b in zip(edges, edges[1:])),
            "band_edges_kpa",
            f"must be strictly increasing in pressure, got {list(edges)}",
        )
        _require(edges[0] >= 0, "band_edges_kpa", f"pressures must be >= 0 kPa, got {edges[0]}")
        _require(
            len(values) == len(edges) - 1,
            "stiffness_n_per_m",
            f"needs one value per band: {len(edges) - 1} bands, got {len(values)} values",
        )
        _require(
            all(math.isfinite(v) and v > 0 for v in values),
            "stiffness_n_per_m",
            f"every value must be > 0 N/m, got {list(values)}",
        )
        _require(self.hysteresis in ("none",), "hysteresis", f"unknown law {self.hysteresis!r}; known: none")


@dataclass
class MuscleConfig:
    """One Festo DMSP-20-260N fluidic muscle and its antagonistic command (thesis §8.3, §9.5)."""

    force_law: str = "thesis_polynomial"  # F(x, P) of Table 8.4
    dynamics: str = "first_order"  # D x' + S x = Fce - FL (§8.3)
    nominal_length_m: float = 0.26  # DMSP-20-260N: 260 mm nominal length
    max_pressure_kpa: float = 800.0  # top of the polynomial's fitted range (§8.3): 8 bar
    tau_s: float = 0.3  # D = tau * S (§8.3)
    rest_contraction_pct: float = 14.06  # zero-force contraction at 176.4 kPa (§10.1)
    v0_v: float = 2.12  # common command voltage V0 (§9.5)
    dv_max_v: float = 0.71  # |dV| <= 0.71 V (§9.5)
    # Muscle-joint coupling (see pamrun/actuation.py): "thesis" (contraction is a dynamic
    # state, the thesis' Simulink model) or "kinematic" (contraction follows the joint).
    coupling: str = "thesis"
    # Not in the thesis: pre-tension and stroke of each pair (pulley radii follow from them).
    kinematic_rest_contraction_pct: float = 6.5
    kinematic_max_contraction_pct: float = 13.0
    regulator: RegulatorConfig = field(default_factory=RegulatorConfig)
    spring: SpringConfig = field(default_factory=SpringConfig)

    def __post_init__(self) -> None:
        from pamrun.muscle import DYNAMICS, FORCE_LAWS  # the registries live with the physics

        _require(self.force_law in FORCE_LAWS, "force_law", f"unknown {self.force_law!r}; known: {sorted(FORCE_LAWS)}")
        _require(self.dynamics in DYNAMICS, "dynamics", f"unknown {self.dynamics!r}; known: {sorted(DYNAMICS)}")
        _positive(self, "nominal_length_m", "max_pressure_kpa", "tau_s", "v0_v")
        _non_negative(self, "dv_max_v")
        _require(-3.0 <= self.rest_contraction_pct < 30.0, "rest_contraction_pct", "must lie in [-3, 30) %")
        _require(self.coupling in ("thesis", "kinematic"), "coupling", f"unknown {self.coupling!r}; known: thesis, kinematic")
        _require(
            0.0 <= 2 * self.kinematic_rest_contraction_pct - self.kinematic_max_contraction_pct
            and self.kinematic_rest_contraction_pct < self.kinematic_max_contraction_pct <= 28.0,
            "kinematic_max_contraction_pct",
            "must exceed kinematic_rest_contraction_pct, be <= 28 % and <= twice the rest contraction "
            "(so the antagonist never stretches below 0 %)",
        )
        _require(self.dv_max_v <= self.v0_v, "dv_max_v", f"must be <= v0_v ({self.v0_v} V): a voltage cannot go negative")


# --------------------------------------------------------------------------- body


@dataclass
class BodyConfig:
    """Body generated from height and mass by anthropometric ratios (thesis §8.1-8.2).

    Joint limits are degrees from the standing pose, for the left leg (Table 8.3); the
    right leg mirrors the roll joints. What the thesis leaves open (pelvis block, hip
    width, contact overlap) is documented field by field.
    """

    height_m: float = 1.80  # Table 8.2 reference
    mass_kg: float = 80.0  # Table 8.2 reference
    # Pelvis/torso block: not in the thesis. Ratios of H and M, see pamrun/body.py for the source.
    pelvis_mass_ratio: float = 0.142
    pelvis_width_ratio: float = 0.191
    pelvis_depth_ratio: float = 0.1
    pelvis_height_ratio: float = 0.1
    hip_width_ratio: float = 0.1  # lateral distance between the two hip joint centres / H
    # Foot-ground contact (§8.1): stiffness = robot weight / overlap, damping = stiffness / 10.
    contact_overlap_m: float = 0.001
    contact_damping_ratio: float = 0.1  # damping [N s/m] = ratio * stiffness [N/m]
    friction_static: float = 0.5
    friction_dynamic: float = 0.6
    friction_critical_velocity_m_s: float = 0.10
    # Joints (Table 8.2)
    joint_stiffness_nm_per_rad: float = 0.0
    joint_damping_nms_per_rad: float = 1.0
    # Joint limits: the thesis' Simscape stop is a spring-damper (1e4 N m/rad, 10 N m s/rad,
    # Table 8.2). MuJoCo's soft limit cannot be one (see pamrun/body.py); we use its own stiff,
    # critically damped stop: time constant [s] and damping ratio of the constraint.
    joint_limit_timeconst_s: float = 0.01
    joint_limit_dampratio: float = 1.0
    # Left-leg limits, degrees from the standing pose (Table 8.3)
    hip_pitch_limits_deg: list[float] = field(default_factory=lambda: [-45.0, 45.0])
    hip_roll_limits_deg: list[float] = field(default_factory=lambda: [-22.5, 11.25])
    knee_limits_deg: list[float] = field(default_factory=lambda: [0.0, 90.0])
    ankle_pitch_limits_deg: list[float] = field(default_factory=lambda: [-45.0, 45.0])
    ankle_roll_limits_deg: list[float] = field(default_factory=lambda: [-25.0, 35.0])

    def __post_init__(self) -> None:
        _positive(
            self,
            "height_m",
            "mass_kg",
            "pelvis_mass_ratio",
            "pelvis_width_ratio",
            "pelvis_depth_ratio",
            "pelvis_height_ratio",
            "hip_width_ratio",
            "contact_overlap_m",
            "contact_damping_ratio",
            "friction_critical_velocity_m_s",
        )
        _non_negative(
            self,
            "friction_static",
            "friction_dynamic",
            "joint_stiffness_nm_per_rad",
            "joint_damping_nms_per_rad",
        )
        _positive(self, "joint_limit_timeconst_s", "joint_limit_dampratio")
        _require(0.5 <= self.height_m <= 3.0, "height_m", f"must lie in [0.5, 3.0] m, got {self.height_m}")
        for name in ("hip_pitch", "hip_roll", "knee", "ankle_pitch", "ankle_roll"):
            key = f"{name}_limits_deg"
            lo_hi = getattr(self, key)
            _require(
                len(lo_hi) == 2 and lo_hi[0] < lo_hi[1],
                key,
                f"must be [lower, upper] with lower < upper, got {list(lo_hi)}",
            )


# --------------------------------------------------------------------------- task


@dataclass
class RewardConfig:
    """Per-step reward weights (thesis Table 9.3).

    r = kvx Vx - ky y^2 - kz (z - z0)^2 - kv sum(a_prev^2) + kt Ts / Tf
    """

    kvx: float = 1.0
    ky: float = 4.0
    kz: float = 60.0
    kv: float = 0.02
    kt: float = 25.0

    def __post_init__(self) -> None:
        for name in ("kvx", "ky", "kz", "kv", "kt"):
            _require(math.isfinite(getattr(self, name)), name, "must be finite")


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
    reset_noise_rad: float = 0.0  # uniform noise on joint angles at reset
    reset_velocity_noise: float = 0.0  # uniform noise on joint velocities [rad/s]

    def __post_init__(self) -> None:
        _positive(self, "control_dt_s", "episode_s", "physics_dt_s", "max_lateral_m", "max_tilt_rad")
        _non_negative(self, "reset_noise_rad", "reset_velocity_noise")
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


# --------------------------------------------------------------------------- learning


@dataclass
class AlgoConfig:
    """DDPG (the thesis, Table 9.4) or TD3 (its proposed next step, §13)."""

    name: str = "ddpg"
    gamma: float = 0.99  # discount (Table 9.4)
    batch_size: int = 128  # Table 9.4
    target_smoothing: float = 1e-3  # soft target update tau (Table 9.4)
    # The thesis prints actor 1e-3 / critic 1e-4, the reverse of the MathWorks example it
    # adapted (actor 1e-4, critic 1e-3): we keep the thesis' values (THESIS.md §7).
    actor_lr: float = 1e-3
    critic_lr: float = 1e-4
    hidden_sizes: list[int] = field(default_factory=lambda: [400, 300])  # Tables 9.1, 9.2
    output_init_scale: float = 3e-3
    loss_function: str = "l2"
    # Exploration: variance 0.5 decaying by 1e-5 per step (Table 9.4).
    noise_variance: float = 0.5
    noise_decay: float = 1e-5
    noise_variance_min: float = 0.01
    ou_theta: float = 0.15  # OU mean attraction (not in the thesis; TorchRL's default)
    ou_dt_s: float = 0.025  # OU time step = the control step Ts
    # TD3 only (Fujimoto et al. 2018 defaults)
    policy_noise: float = 0.2
    noise_clip: float = 0.5
    actor_update_every: int = 2  # delayed actor updates (1 for DDPG)
    grad_clip: float = 1.0  # gradient threshold of the MathWorks example

    def __post_init__(self) -> None:
        _require(self.name in ("ddpg", "td3"), "name", f"unknown algorithm {self.name!r}; known: ddpg, td3")
        _require(0 < self.gamma <= 1, "gamma", f"must lie in (0, 1], got {self.gamma}")
        _require(self.batch_size >= 1, "batch_size", f"must be >= 1, got {self.batch_size}")
        _require(0 < self.target_smoothing <= 1, "target_smoothing", "must lie in (0, 1]")
        _positive(self, "actor_lr", "critic_lr", "output_init_scale", "ou_dt_s", "grad_clip")
        _non_negative(self, "noise_variance", "noise_decay", "noise_variance_min", "ou_theta", "policy_noise",
                      "noise_clip")
        _require(len(self.hidden_sizes) == 2 and min(self.hidden_sizes) > 0, "hidden_sizes",
                 f"needs two positive layer sizes, got {list(self.hidden_sizes)}")
        _require(self.actor_update_every >= 1, "actor_update_every", "must be >= 1")
        _require(self.loss_function in ("l1", "l2", "smooth_l1"), "loss_function", "must be l1, l2 or smooth_l1")


@dataclass
class TrainConfig:
    """Budget, stop criteria, saving and parallelism of ``pamrun train`` (thesis §9.5, Table 9.4)."""

    max_episodes: int = 5000  # Table 9.4
    max_frames: int = 2_000_000
    max_minutes: float = 0.0  # wall-clock limit; 0 = none
    target_avg_reward: float = 0.0  # stop when the windowed average reaches it; 0 = off
    avg_window: int = 100  # episodes in the average (MATLAB's ScoreAveragingWindowLength)
    save_threshold: float = 250.0  # save every agent whose episode reward reaches it (§9.5)
    keep_saved: int = 10  # keep the best this many threshold saves
    workers: int = 1  # collector processes (the thesis used 8)
    threads: int = 0  # torch threads of the learner; 0 = the cores the collectors leave free
    frames_per_batch: int = 200
    init_random_frames: int = 2000  # uniform random actions before learning starts
    updates_per_frame: float = 1.0
    buffer_size: int = 1_000_000  # the MathWorks example's ExperienceBufferLength
    checkpoint_every_frames: int = 20_000

    def __post_init__(self) -> None:
        for name in ("max_episodes", "max_frames", "avg_window", "keep_saved", "workers", "frames_per_batch",
                     "buffer_size", "checkpoint_every_frames"):
            _require(getattr(self, name) >= 1, name, f"must be >= 1, got {getattr(self, name)}")
        _non_negative(self, "max_minutes", "updates_per_frame")
        _require(self.init_random_frames >= 0, "init_random_frames", "must be >= 0")
        _require(self.threads >= 0, "threads", f"must be >= 0 (0 = automatic), got {self.threads}")


@dataclass
class EvalConfig:
    """``pamrun eval``: how saved agents are tested and ranked (thesis §10.3).

    Every agent runs ``episodes`` episodes with its deterministic policy (no exploration
    noise), episode k from seed ``seed + k`` for every agent, so the comparison is fair.
    The start pose gets uniform joint-angle noise of ``reset_noise_rad`` (not in the
    thesis, which tested from the nominal pose: with 0 every episode is the same). Each
    agent acts in the robot and task it was trained on (the config stored with it) unless
    ``use_agent_env`` is false; then the command line's groups apply.
    """

    episodes: int = 10
    workers: int = 0  # evaluation processes; 0 = one per CPU core
    seed: int = 0
    reset_noise_rad: float = 0.01
    reset_velocity_noise: float = 0.0
    episode_s: float = 10.0  # Tf (§9)
    # Walk test (§10.3): walk walk_duration_s without falling, never leaving |y| <= walk_lateral_m.
    walk_duration_s: float = 10.0
    walk_lateral_m: float = 0.5
    # Leaderboard order: aggregate names, best first; a leading '-' ranks that one ascending.
    rank_by: list[str] = field(default_factory=lambda: ["walk_pass_rate", "distance_mean"])
    include_last: bool = True  # a run directory's final agent (checkpoints/last.pt) competes too
    use_agent_env: bool = True
    top_k: int = 5  # agents drawn in trajectories.png
    save_steps: bool = True  # per-step data in episodes.jsonl
    render: bool = False  # mp4 of the best agent's first episode
    video_width: int = 640
    video_height: int = 480

    def __post_init__(self) -> None:
        from pamrun.evaluate import RANK_METRICS

        for name in ("episodes", "top_k"):
            _require(getattr(self, name) >= 1, name, f"must be >= 1, got {getattr(self, name)}")
        _require(self.workers >= 0, "workers", f"must be >= 0 (0 = one per core), got {self.workers}")
        _require(self.seed >= 0, "seed", f"must be >= 0, got {self.seed}")
        _non_negative(self, "reset_noise_rad", "reset_velocity_noise")
        _positive(self, "episode_s", "walk_duration_s", "walk_lateral_m")
        _require(self.walk_duration_s <= self.episode_s + 1e-9, "walk_duration_s",
                 f"must be <= episode_s ({self.episode_s} s): an episode ends before the test could pass")
        _require(len(self.rank_by) >= 1, "rank_by", "needs at least one metric")
        for name in self.rank_by:
            _require(name.lstrip("-") in RANK_METRICS, "rank_by",
                     f"unknown metric {name!r}; known: {', '.join(RANK_METRICS)} (prefix '-' for ascending)")
        for name in ("video_width", "video_height"):
            value = getattr(self, name)
            _require(16 <= value <= 1280 and value % 2 == 0, name, f"must be even and in [16, 1280], got {value}")


# Per-job results a sweep summarises and Optuna can optimise (see pamrun/sweep.py).
JOB_METRICS = ("final_avg_reward", "best_distance_m", "walk_pass_rate", "frames_to_first_save")


@dataclass
class OptunaConfig:
    """``pamrun sweep optuna``: hyperparameter search whose objective averages seeds.

    ``params`` maps a Hydra override key to its search space: ``float:LOW:HIGH``,
    ``log:LOW:HIGH`` (log-uniform), ``int:LOW:HIGH`` or ``choice:A,B,...`` (a config group
    such as ``algo`` takes ``choice:ddpg,td3``). Each trial is a ``pamrun sweep -m`` over
    ``seeds``; its value is the mean of ``sweep.metric`` over them. The study lives in
    ``study.db`` (SQLite) in the study directory, so the same command resumes it.
    """

    trials: int = 10
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])
    params: dict[str, str] = field(default_factory=dict)
    sampler_seed: int = 0

    def __post_init__(self) -> None:
        _require(self.trials >= 1, "trials", f"must be >= 1, got {self.trials}")
        _require(len(self.seeds) >= 1 and min(self.seeds) >= 0, "seeds", "needs one or more seeds >= 0")
        for key, spec in self.params.items():
            kind, _, rest = str(spec).partition(":")
            ok = kind == "choice" and rest != ""
            if kind in ("float", "log", "int"):
                try:
                    low, high = (float(v) for v in rest.split(":"))
                    ok = low < high and (kind != "log" or low > 0)
                except ValueError:
                    ok = False
            _require(ok, f"params.{key}",
                     f"must be float:LOW:HIGH, log:LOW:HIGH (LOW > 0), int:LOW:HIGH or choice:A,B,..., got {spec!r}")


@dataclass
class SweepConfig:
    """``pamrun sweep``: several trainings side by side, each evaluated, and their summary."""

    jobs: int = 0  # trainings at once on this machine; 0 = the cores / each job's train.workers
    # Overrides that repeat a setting rather than define one: the summary groups over them.
    group_exclude: list[str] = field(default_factory=lambda: ["seed"])
    metric: str = "best_distance_m"  # what "better" means in the verdict and for Optuna (comparable across rewards)
    direction: str = "maximize"
    optuna: OptunaConfig = field(default_factory=OptunaConfig)

    def __post_init__(self) -> None:
        _require(self.jobs >= 0, "jobs", f"must be >= 0 (0 = automatic), got {self.jobs}")
        _require(self.metric in JOB_METRICS, "metric", f"unknown {self.metric!r}; known: {', '.join(JOB_METRICS)}")
        _require(self.direction in ("maximize", "minimize"), "direction", "must be maximize or minimize")


# --------------------------------------------------------------------------- experiments


@dataclass
class StepExperiment:
    """A pressure step on one antagonistic pair and the thesis' final contractions (§10.1)."""

    label: str = ""
    pressure1_kpa: float = 276.4
    pressure2_kpa: float = 76.4
    thesis_final_pct: list[float] = field(default_factory=lambda: [20.22, 3.44])

    def __post_init__(self) -> None:
        _non_negative(self, "pressure1_kpa", "pressure2_kpa")
        _require(len(self.thesis_final_pct) == 2, "thesis_final_pct", "needs one value per muscle (2)")


@dataclass
class PairConfig:
    """Antagonistic-pair experiments of thesis §10.1 (``pamrun muscle step|calibrate``)."""

    initial_pressure_kpa: float = 176.4  # 1.764 bar (§10.1)
    initial_contraction_pct: float = 14.06  # §10.1
    step_time_s: float = 0.5
    duration_s: float = 4.0
    dt_s: float = 0.001
    tolerance_pct: float = 0.5  # acceptance: every final contraction within 0.5 points
    experiments: dict[str, StepExperiment] = field(
        default_factory=lambda: {
            "plus_minus_1bar": StepExperiment("+1/-1 bar (Fig 10.5)", 276.4, 76.4, [20.22, 3.44]),
            "max_and_1bar": StepExperiment("max/1 bar (Fig 10.4)", 800.0, 100.0, [28.12, 6.28]),
        }
    )
    # `pamrun muscle calibrate` also writes conf/muscle/spring/calibrated.yaml (the default table).
    calibrate_write_conf: bool = True

    def __post_init__(self) -> None:
        _positive(self, "initial_pressure_kpa", "duration_s", "dt_s", "tolerance_pct")
        _non_negative(self, "step_time_s")
        _require(self.step_time_s < self.duration_s, "step_time_s", "must be < duration_s")
        _require(self.dt_s <= 0.01, "dt_s", f"must be <= 0.01 s, got {self.dt_s}")


# --------------------------------------------------------------------------- root


@dataclass
class Config:
    """The composed configuration of every pamrun command."""

    seed: int = 0
    muscle: MuscleConfig = field(default_factory=MuscleConfig)
    body: BodyConfig = field(default_factory=BodyConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    resume: str = ""  # a run directory to continue from its last checkpoint
    dir: str = ""  # a run directory, for commands that read one (pamrun plot training)
    ckpt: str = ""  # pamrun eval: a checkpoint, a run directory, a folder of runs or a glob
    eval: EvalConfig = field(default_factory=EvalConfig)
    sweep: SweepConfig = field(default_factory=SweepConfig)
    pair: PairConfig = field(default_factory=PairConfig)

    def __post_init__(self) -> None:
        _require(self.seed >= 0, "seed", f"must be >= 0, got {self.seed}")


# Keys renamed since a config could have been saved with a run: old section.key -> new key.
RENAMED_KEYS = {"reward": {"k_vx": "kvx", "k_y": "ky", "k_z": "kz", "k_v": "kv", "k_t": "kt"}}


def upgrade_saved_config(data: dict) -> dict:
    """A config saved by an older pamrun (a run's pamrun_config.yaml, an agent file) with
    today's key names, so old runs can still be resumed and evaluated."""
    data = dict(data)
    for section, renames in RENAMED_KEYS.items():
        if isinstance(data.get(section), dict):
            data[section] = {renames.get(k, k): v for k, v in data[section].items()}
    return data


def register_configs() -> None:
    """Register the root schema; every group's YAML is merged into its typed field."""
    ConfigStore.instance().store(name="pamrun_schema", node=Config)


def parallel_jobs(jobs: int, workers_per_job: int) -> int:
    """Sweep jobs to run side by side: ``jobs``, or (0) the cores each job's workers leave."""
    return int(jobs) if int(jobs) > 0 else max(1, usable_cores() // max(1, int(workers_per_job)))


def usable_cores() -> int:
    """Cores this process may run on (a SLURM allocation or container limit, not the whole node)."""
    import os

    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# Used by conf/sweep.yaml (registered on import: sweep jobs compose their config in worker processes).
OmegaConf.register_new_resolver("pamrun_jobs", parallel_jobs, replace=True)
OmegaConf.register_new_resolver("pamrun_job_dir", lambda name: name or "default", replace=True)


def validate(cfg: DictConfig, path: str = "") -> None:
    """Check every value of a composed config; raise ConfigError with the full key.

    Children are checked before their parent so the error names the deepest key. The
    ``hydra`` node (present in callbacks) is left out.
    """
    if "hydra" in cfg:
        cfg = copy.deepcopy(cfg)
        with read_write(cfg), open_dict(cfg):
            cfg.pop("hydra")
    for key in cfg.keys():
        child = cfg._get_node(key)
        if isinstance(child, DictConfig) and OmegaConf.get_type(child) not in (dict, None):
            validate(child, f"{path}{key}.")
        elif isinstance(child, DictConfig):  # a dict of dataclasses, e.g. pair.experiments
            for name in child.keys():
                sub = child._get_node(name)
                if isinstance(sub, DictConfig):
                    validate(sub, f"{path}{key}.{name}.")
    if OmegaConf.get_type(cfg) in (dict, None):
        return
    try:
        OmegaConf.to_object(cfg)
    except ConfigError as err:
        raise ConfigError(path + err.key, err.message) from None


def to_object(cfg: DictConfig) -> Any:
    """Validated dataclass instance of a composed config (or of one of its sections)."""
    validate(cfg)
    return OmegaConf.to_object(cfg)


class ValidateConfig(Callback):
    """Hydra callback: validate values before Hydra creates the run directory."""

    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        _validate_or_exit(config)

    def on_job_start(self, config: DictConfig, **kwargs: Any) -> None:
        # Multirun jobs are composed inside the launcher; a bad one fails alone. A sweep job
        # validates inside its task instead, so the failure is recorded and the others go on.
        if OmegaConf.select(config, "hydra.job.name", default="") != "sweep":
            _validate_or_exit(config)


def _validate_or_exit(config: DictConfig) -> None:
    try:
        validate(config)
        check_command(config)
    except ConfigError as err:
        raise SystemExit(f"pamrun: invalid configuration: {err}") from None


def check_command(config: DictConfig) -> None:
    """What one command needs beyond valid values, checked before its directory exists.

    ``pamrun eval``: ``ckpt`` must name at least one checkpoint file.
    """
    job = OmegaConf.select(config, "hydra.job.name", default="")
    if job == "eval":
        from pamrun.checkpoints import CheckpointError, find_checkpoints

        try:
            find_checkpoints(config.ckpt, config.eval.include_last)
        except CheckpointError as err:
            raise ConfigError("ckpt", str(err)) from None
