"""Schemas of what runs around training: evaluation (thesis §10.3), sweeps and Optuna,
and the antagonistic-pair bench experiments (§10.1)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Optional

from pamrun.config.checks import ConfigError, _non_negative, _positive, _require
from pamrun.config.task import ENV_SECTIONS, check_speed_schedule

# Aggregates an agent can be ranked by (``eval.rank_by``; pamrun.evaluation.episodes.aggregate computes them);
# larger is better unless prefixed '-'.
RANK_METRICS = ("walk_pass_rate", "walk_pass_ci_low", "stand_rate", "distance_mean", "distance_min", "return_mean", "duration_mean", "speed_mean",
                "fall_rate", "max_abs_y_mean", "max_abs_y_max", "pressure_change_mean", "walk_targets_met")
# The cameras an episode is rendered from (``eval.camera``; PamWalker-v0's ``camera``, pamrun.task.camera).
CAMERAS = ("follow", "fixed", "three_quarter")


@dataclass
class Perturbation:
    """One named change of the robot or task an agent is tested under (``pamrun eval eval.suite=...``).

    Both fields mirror the config sections, e.g. ``scale: {body: {mass_kg: 1.1}}`` multiplies
    the agent's own body mass by 1.1 and ``values: {env: {reset_noise_rad: 0.05}}`` sets a
    value. They are applied to the agent's stored config after the evaluation's own start
    noise and episode length, through the same options a user has (the ``body``, ``muscle``,
    ``reward`` and ``env`` keys of PamWalker-v0), then validated like any config: an unknown
    key or an impossible result (negative friction, a push after the episode) fails naming it.
    """

    note: str = ""  # what it stands for, in words (the robustness table shows it)
    scale: dict[str, Any] = field(default_factory=dict)  # section -> key -> factor on the agent's value
    values: dict[str, Any] = field(default_factory=dict)  # section -> key -> value

    def __post_init__(self) -> None:
        for kind in ("scale", "values"):
            for section, keys in getattr(self, kind).items():
                _require(section in ENV_SECTIONS, f"{kind}.{section}",
                         f"unknown section; a perturbation changes {', '.join(ENV_SECTIONS)}")
                _require(isinstance(keys, dict) and len(keys) > 0, f"{kind}.{section}",
                         "must map keys of that section to values, e.g. {mass_kg: 1.1}")
        for dotted, factor in flatten(self.scale).items():
            _require(isinstance(factor, (int, float)) and not isinstance(factor, bool) and math.isfinite(factor)
                     and factor >= 0, f"scale.{dotted}", f"must be a finite factor >= 0, got {factor!r}")


def flatten(tree: dict, prefix: str = "") -> dict[str, Any]:
    """{'env': {'push': {'a': 1}}} -> {'env.push.a': 1} (lists are values)."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, dict):
            out.update(flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def _robustness_perturbations() -> dict[str, Perturbation]:
    """The robustness suite's perturbations: what a real PAM robot differs from its model by.

    Sizes chosen where the thesis is silent: +-10 % mass (cables, valves, a battery), foot
    friction x0.7 / x1.3 (floor and sole materials), the regulator twice as slow (Festo quotes
    its proportional regulators at 50-100 ms, pamrun.config.regulator.RegulatorConfig), 10 % less
    top pressure (a sagging supply), sensor noise, a 5x larger start noise, and a 10 N s push
    (100 N for 0.1 s) at 5 s forward, backward and sideways; and the ground
    (:func:`terrain_perturbations`)."""
    push = {"push_time_s": 5.0, "push_duration_s": 0.1}
    return {
        "nominal": Perturbation("the evaluation as is"),
        "mass_heavy": Perturbation("body mass +10 %", scale={"body": {"mass_kg": 1.1}}),
        "mass_light": Perturbation("body mass -10 %", scale={"body": {"mass_kg": 0.9}}),
        "friction_low": Perturbation("foot friction x0.7", scale={"body": {"friction_static": 0.7}}),
        "friction_high": Perturbation("foot friction x1.3", scale={"body": {"friction_static": 1.3}}),
        "lag_x2": Perturbation("regulator lag x2", scale={"muscle": {"regulator": {"lag_s": 2.0}}}),
        "top_pressure_low": Perturbation("top pressure -10 %", scale={"muscle": {"max_pressure_kpa": 0.9}}),
        "obs_noise": Perturbation("observation noise sigma 0.02", values={"env": {"observation_noise_std": 0.02}}),
        "start_noise": Perturbation("start noise 0.05 rad", values={"env": {"reset_noise_rad": 0.05}}),
        "push_forward": Perturbation("push 10 N s forward at 5 s",
                                     values={"env": {**push, "push_impulse_ns": [10.0, 0.0, 0.0]}}),
        "push_backward": Perturbation("push 10 N s backward at 5 s",
                                      values={"env": {**push, "push_impulse_ns": [-10.0, 0.0, 0.0]}}),
        "push_sideways": Perturbation("push 10 N s sideways at 5 s",
                                      values={"env": {**push, "push_impulse_ns": [0.0, 10.0, 0.0]}}),
        **terrain_perturbations(),
    }


def terrain_perturbations() -> dict[str, Perturbation]:
    """Ground other than the flat floor, from 1 m ahead of the start (``env.terrain_x_m``;
    pamrun.physics.terrain): a 3 deg slope up and down (a wheelchair ramp's is at most ~4.8 deg),
    a 2 cm step up (a doorsill), and uneven ground within +-1 cm."""
    return {
        "slope_up": Perturbation("slope 3 deg up", values={"env": {"slope_deg": 3.0}}),
        "slope_down": Perturbation("slope 3 deg down", values={"env": {"slope_deg": -3.0}}),
        "step_up": Perturbation("step 2 cm up", values={"env": {"step_height_m": 0.02}}),
        "uneven": Perturbation("uneven ground +-1 cm", values={"env": {"rough_height_m": 0.01}}),
    }


def _model_perturbations() -> dict[str, Perturbation]:
    """The models suite (``eval.suite=models``): the agent's robot under each pneumatic model
    beyond the thesis', so a policy's transfer between models is measured. Each is the model's
    option as it ships (pamrun/physics/valve.py, pamrun/physics/hysteresis.py, pamrun/physics/force_laws.py, body.toe)."""
    return {
        "nominal": Perturbation("the evaluation as is"),
        "valve_flow": Perturbation("flow-limited valve (muscle.regulator.model=flow)",
                                   values={"muscle": {"regulator": {"model": "flow"}}}),
        "hysteresis": Perturbation("Maxwell-slip hysteresis (muscle.spring.hysteresis=maxwell_slip)",
                                   values={"muscle": {"spring": {"hysteresis": "maxwell_slip"}}}),
        "force_law": Perturbation("Tondu-Lopez force law (muscle.force_law=tondu_lopez)",
                                  values={"muscle": {"force_law": "tondu_lopez"}}),
        "toe": Perturbation("passive toes (body.toe=true)", values={"body": {"toe": True}}),
    }


@dataclass
class EvalConfig:
    """``pamrun eval``: how saved agents are tested and ranked (thesis §10.3).

    Every agent runs ``episodes`` episodes with its deterministic policy (no exploration
    noise), episode k from seed ``seed + k`` for every agent, so the comparison is fair.
    The start pose gets uniform joint-angle noise of ``reset_noise_rad`` (not in the
    thesis, which tested from the nominal pose: with 0 every episode is the same). Each
    agent acts in the robot and task it was trained on (the config stored with it), with the
    ``body``, ``muscle``, ``reward`` and ``env`` keys set on ``pamrun eval``'s command line changed
    (:func:`pamrun.evaluation.evaluate.command_line_changes`), unless ``use_agent_env`` is false;
    then the command line's groups apply.

    **Two seed blocks.** Evaluation during training selects agents (``best_eval.pt``) on
    seeds ``selection_seed + k``, k < ``train.eval_episodes``; ``pamrun eval`` reports on
    the held-out block ``seed + k``, k < ``episodes``. A report on seeds that overlap the
    selection block is marked ``held_out: false`` and warned about.

    **Suites.** ``suite=robustness`` runs every agent under each perturbation named in
    ``suites.robustness`` (defined in ``perturbations``; add your own with
    ``+eval.perturbations.NAME.values.env.KEY=...`` and list it in the suite). ``suite=terrain``
    runs the nominal evaluation and the robustness suite's four terrain entries alone.
    """

    episodes: int = 50  # deterministic held-out episodes per agent (>= 50 wherever a claim is made)
    workers: int = 0  # evaluation processes; 0 = one per CPU core
    seed: int = 1000  # held-out block: episode k starts from seed + k, the same for every agent
    selection_seed: int = 0  # evaluation during training selects agents on seeds selection_seed + k
    reset_noise_rad: float = 0.01  # uniform start-pose noise on the joint angles (0 = the thesis' nominal pose)
    reset_velocity_noise: float = 0.0  # uniform start noise on the joint velocities [rad/s]
    episode_s: float = 10.0  # Tf (§9)
    # v* [m/s], the speed an agent trained with env.speed_command is told, held the whole episode
    # (sets env.target_speed_m_s; an agent's drawn speed range is not used here). None = its own.
    speed_m_s: Optional[float] = None
    # [[time_s, speed_m_s], ...]: v* piecewise constant within each episode, e.g. [[0,0],[2.5,0.6],[5,1.2]]
    # (sets env.speed_schedule; an agent without env.speed_command is not told it, only measured
    # against it: pamrun.evaluation.tracking). [] = off (typed Any, as env.speed_schedule)
    speed_schedule: list[Any] = field(default_factory=list)
    # How fast v* moves to a changed command [m/s^2] (sets env.speed_ramp_m_s2; 0 = at once). None = its own
    speed_ramp_m_s2: Optional[float] = None
    # Walk test (§10.3): walk walk_duration_s without falling, never leaving |y| <= walk_lateral_m,
    # ending at least walk_distance_m forward.
    walk_duration_s: float = 10.0
    walk_lateral_m: float = 0.5  # ... never leaving |y| <= this (thesis Fig. 10.25)
    walk_distance_m: float = 7.0  # ... and at least this far forward (thesis abstract: 7-11 m in 10 s)
    # Leaderboard order: aggregate names, best first; a leading '-' ranks that one ascending. Standing
    # ranks before distance: an agent that stands 10 s beats one that lunges 10 cm and falls.
    rank_by: list[str] = field(default_factory=lambda: ["walk_pass_rate", "stand_rate", "distance_mean"])
    include_last: bool = True  # a run directory's final agent (checkpoints/last.pt) competes too
    use_agent_env: bool = True  # each agent in its own robot and task (+ the command line's keys); false: the command line's
    top_k: int = 5  # agents drawn in trajectories.png
    save_steps: bool = True  # per-step data in episodes.jsonl
    render: bool = False  # the best agent's first episode: mp4, a strip of its frames, a GIF
    # the video's camera (pamrun.task.camera): follow (side-on, following the torso), fixed (side-on,
    # aimed where the robot starts) or three_quarter (front right, keeping its offset from the centre of mass)
    camera: str = "follow"
    video_width: int = 640
    video_height: int = 480
    suite: str = ""  # "" = one evaluation; a name in suites: every agent under each of its perturbations
    suites: dict[str, list[str]] = field(default_factory=lambda: {  # suite -> its perturbations' names
        "robustness": list(_robustness_perturbations()), "models": list(_model_perturbations()),
        "terrain": ["nominal", *terrain_perturbations()]})
    # Typed Any, not Perturbation, so that `+eval.perturbations.NAME.values.env.KEY=...` can add one
    # on the command line; __post_init__ makes each a Perturbation.
    perturbations: dict[str, Any] = field(default_factory=lambda: {
        k: asdict(v) for k, v in {**_robustness_perturbations(), **_model_perturbations()}.items()
    })  # name -> a Perturbation (note, scale, values)

    def __post_init__(self) -> None:
        for name in ("episodes", "top_k"):
            _require(getattr(self, name) >= 1, name, f"must be >= 1, got {getattr(self, name)}")
        _require(self.workers >= 0, "workers", f"must be >= 0 (0 = one per core), got {self.workers}")
        _require(self.seed >= 0, "seed", f"must be >= 0, got {self.seed}")
        _require(self.selection_seed >= 0, "selection_seed", f"must be >= 0, got {self.selection_seed}")
        _non_negative(self, "reset_noise_rad", "reset_velocity_noise", "walk_distance_m")
        _require(self.speed_m_s is None or (math.isfinite(self.speed_m_s) and self.speed_m_s >= 0), "speed_m_s",
                 f"must be a speed >= 0 in m/s, got {self.speed_m_s}")
        _require(self.speed_ramp_m_s2 is None or (math.isfinite(self.speed_ramp_m_s2) and self.speed_ramp_m_s2 >= 0),
                 "speed_ramp_m_s2", f"must be >= 0 in m/s^2 (0 = at once), got {self.speed_ramp_m_s2}")
        _positive(self, "episode_s", "walk_duration_s", "walk_lateral_m")
        self.speed_schedule = check_speed_schedule(self.speed_schedule, self.episode_s, "speed_schedule",
                                                   "eval.episode_s")
        _require(not self.speed_schedule or self.speed_m_s is None, "speed_schedule",
                 "sets v* itself: leave eval.speed_m_s unset")
        _require(self.walk_duration_s <= self.episode_s + 1e-9, "walk_duration_s",
                 f"must be <= episode_s ({self.episode_s} s): an episode ends before the test could pass")
        _require(len(self.rank_by) >= 1, "rank_by", "needs at least one metric")
        for name in self.rank_by:
            _require(name.lstrip("-") in RANK_METRICS, "rank_by",
                     f"unknown metric {name!r}; known: {', '.join(RANK_METRICS)} (prefix '-' for ascending)")
        for name in ("video_width", "video_height"):
            value = getattr(self, name)
            _require(16 <= value <= 1280 and value % 2 == 0, name, f"must be even and in [16, 1280], got {value}")
        _require(self.camera in CAMERAS, "camera", f"unknown camera {self.camera!r}; known: {', '.join(CAMERAS)}")
        fields = set(Perturbation.__dataclass_fields__)
        for name, spec in list(self.perturbations.items()):
            if isinstance(spec, Perturbation):
                continue
            _require(isinstance(spec, dict), f"perturbations.{name}", "must be a mapping of note, scale, values")
            for key in spec:
                _require(key in fields, f"perturbations.{name}.{key}", f"unknown key; a perturbation has: "
                                                                         f"{', '.join(sorted(fields))}")
            try:
                self.perturbations[name] = Perturbation(**spec)
            except ConfigError as err:
                raise ConfigError(f"perturbations.{name}.{err.key}", err.message) from None
        _require(not self.suite or self.suite in self.suites, "suite",
                 f"unknown suite {self.suite!r}; known: {', '.join(self.suites) or 'none'}")
        for suite, names in self.suites.items():
            _require(len(names) >= 1, f"suites.{suite}", "needs at least one perturbation")
            for name in names:
                _require(name in self.perturbations, f"suites.{suite}",
                         f"unknown perturbation {name!r}; known: {', '.join(self.perturbations)}")


# Per-job results a sweep summarises and Optuna can optimise (see pamrun/sweep/grid.py).
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
