"""Schemas of what runs around training: evaluation (thesis §10.3), sweeps and Optuna,
and the antagonistic-pair bench experiments (§10.1)."""

from __future__ import annotations

from dataclasses import dataclass, field

from pamrun.config.checks import _non_negative, _positive, _require


# Aggregates an agent can be ranked by (``eval.rank_by``; pamrun/evaluate.py computes them);
# larger is better unless prefixed '-'.
RANK_METRICS = ("walk_pass_rate", "stand_rate", "distance_mean", "distance_min", "return_mean", "duration_mean", "speed_mean",
                "fall_rate", "max_abs_y_mean", "max_abs_y_max", "pressure_change_mean")


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

    episodes: int = 10  # deterministic episodes per agent
    workers: int = 0  # evaluation processes; 0 = one per CPU core
    seed: int = 0  # episode k starts from seed + k, the same for every agent
    reset_noise_rad: float = 0.01  # uniform start-pose noise on the joint angles (0 = the thesis' nominal pose)
    reset_velocity_noise: float = 0.0  # uniform start noise on the joint velocities [rad/s]
    episode_s: float = 10.0  # Tf (§9)
    # Walk test (§10.3): walk walk_duration_s without falling, never leaving |y| <= walk_lateral_m,
    # ending at least walk_distance_m forward.
    walk_duration_s: float = 10.0
    walk_lateral_m: float = 0.5  # ... never leaving |y| <= this (thesis Fig. 10.25)
    walk_distance_m: float = 7.0  # ... and at least this far forward (thesis abstract: 7-11 m in 10 s)
    # Leaderboard order: aggregate names, best first; a leading '-' ranks that one ascending. Standing
    # ranks before distance: an agent that stands 10 s beats one that lunges 10 cm and falls.
    rank_by: list[str] = field(default_factory=lambda: ["walk_pass_rate", "stand_rate", "distance_mean"])
    include_last: bool = True  # a run directory's final agent (checkpoints/last.pt) competes too
    use_agent_env: bool = True
    top_k: int = 5  # agents drawn in trajectories.png
    save_steps: bool = True  # per-step data in episodes.jsonl
    render: bool = False  # mp4 of the best agent's first episode
    video_width: int = 640
    video_height: int = 480

    def __post_init__(self) -> None:
        for name in ("episodes", "top_k"):
            _require(getattr(self, name) >= 1, name, f"must be >= 1, got {getattr(self, name)}")
        _require(self.workers >= 0, "workers", f"must be >= 0 (0 = one per core), got {self.workers}")
        _require(self.seed >= 0, "seed", f"must be >= 0, got {self.seed}")
        _non_negative(self, "reset_noise_rad", "reset_velocity_noise", "walk_distance_m")
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

    trials: int = 10  # trials to run (raise it to run more in the same study)
    seeds: list[int] = field(default_factory=lambda: [0, 1, 2])  # seeds each trial is averaged over
    params: dict[str, str] = field(default_factory=dict)  # key -> float:LO:HI, log:LO:HI, int:LO:HI or choice:A,B
    sampler_seed: int = 0  # seed of Optuna's TPE sampler

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


# --------------------------------------------------------------------------- bench experiments (§10.1)


@dataclass
class StepExperiment:
    """A pressure step on one antagonistic pair and the thesis' final contractions (§10.1)."""

    label: str = ""  # name in tables and figures
    pressure1_kpa: float = 276.4  # muscle 1 after the step [kPa]
    pressure2_kpa: float = 76.4  # muscle 2 after the step [kPa]
    thesis_final_pct: list[float] = field(default_factory=lambda: [20.22, 3.44])  # the thesis' final contractions [%]

    def __post_init__(self) -> None:
        _non_negative(self, "pressure1_kpa", "pressure2_kpa")
        _require(len(self.thesis_final_pct) == 2, "thesis_final_pct", "needs one value per muscle (2)")


@dataclass
class PairConfig:
    """Antagonistic-pair experiments of thesis §10.1 (``pamrun muscle step|calibrate``)."""

    initial_pressure_kpa: float = 176.4  # 1.764 bar (§10.1)
    initial_contraction_pct: float = 14.06  # §10.1
    step_time_s: float = 0.5  # when the pressures step [s]
    duration_s: float = 4.0  # length of each experiment [s]
    dt_s: float = 0.001  # integration step of the pair [s]
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
