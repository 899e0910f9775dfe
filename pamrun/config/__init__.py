"""Typed configuration: the dataclasses that hold every default, and the checks that name a bad key."""

# Every dataclass here is the schema of one config group under ``conf/``; its defaults are the
# thesis values, each with the section it comes from. YAML files in ``conf/`` select and override
# them. Hydra rejects unknown keys and wrong types while composing; :func:`validate` then checks
# values (a negative height, tau <= 0, a pressure table that is not monotone) and raises
# :class:`ConfigError` naming the full key, before any run directory is created
# (``pamrun.cli.ValidateConfig`` runs it as a Hydra callback). This package is the bottom layer:
# it imports no other pamrun module. The schemas live by subject: robot (muscle, body), task
# (reward, env), learning (algo, train) and experiments (eval, sweep, pair); all are importable
# from here.

from __future__ import annotations

import copy
import dataclasses
from dataclasses import asdict, dataclass, field, is_dataclass
from typing import Any

import yaml
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf, open_dict, read_write

from pamrun.config.checks import CONF_DIR, ConfigError, _require
from pamrun.config.experiments import (
    CAMERAS,
    JOB_METRICS,
    RANK_METRICS,
    EvalConfig,
    OptunaConfig,
    PairConfig,
    Perturbation,
    StepExperiment,
    SweepConfig,
    flatten,
)
from pamrun.config.learning import AlgoConfig, TrainConfig
from pamrun.config.robot import (
    DYNAMICS_NAMES,
    FORCE_LAW_NAMES,
    LEG_JOINTS,
    SPRING_FILE,
    BodyConfig,
    JointAngles,
    JointCounts,
    JointRadii,
    MuscleConfig,
    RegulatorConfig,
    SpringConfig,
    check_muscle_stretch,
    check_toe_stiffness,
)
from pamrun.config.task import ENV_SECTIONS, EnvConfig, RewardConfig, check_speed_schedule

__all__ = ["CONF_DIR", "SPRING_FILE", "CAMERAS", "JOB_METRICS", "RANK_METRICS", "FORCE_LAW_NAMES", "DYNAMICS_NAMES", "ConfigError",
           "Config", "LEG_JOINTS", "RegulatorConfig", "SpringConfig", "MuscleConfig", "JointAngles", "JointCounts",
           "JointRadii",
           "check_muscle_stretch", "check_toe_stiffness",
           "BodyConfig", "RewardConfig", "EnvConfig", "AlgoConfig", "TrainConfig", "EvalConfig",
           "OptunaConfig", "Perturbation", "flatten", "ENV_SECTIONS", "SweepConfig", "StepExperiment", "PairConfig", "register_configs", "validate", "without_hydra", "to_object",
           "preset", "upgrade_saved_config", "as_config"]


# --------------------------------------------------------------------------- root


@dataclass
class Config:
    """The composed configuration of every pamrun command."""

    seed: int = 0  # seed of everything random: torch, numpy, the envs, the collectors
    muscle: MuscleConfig = field(default_factory=MuscleConfig)
    body: BodyConfig = field(default_factory=BodyConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    algo: AlgoConfig = field(default_factory=AlgoConfig)
    train: TrainConfig = field(default_factory=TrainConfig)
    resume: str = ""  # a run directory to continue from its last checkpoint
    dir: str = ""  # a run directory, for commands that read one (pamrun plot training)
    ckpt: str = ""  # pamrun eval: a checkpoint, a run directory, a folder of runs or a glob; pamrun export: one agent file
    format: str = "onnx"  # pamrun export: onnx or torchscript
    eval: EvalConfig = field(default_factory=EvalConfig)
    sweep: SweepConfig = field(default_factory=SweepConfig)
    pair: PairConfig = field(default_factory=PairConfig)

    def __post_init__(self) -> None:
        _require(self.seed >= 0, "seed", f"must be >= 0, got {self.seed}")
        _require(self.format in ("onnx", "torchscript"), "format", f"must be onnx or torchscript, got {self.format!r}")
        for key in ("randomize", "select_perturbations"):
            for name in getattr(self.train, key):
                _require(name in self.eval.perturbations, f"train.{key}", f"unknown perturbation {name!r}; "
                         f"known (eval.perturbations): {', '.join(self.eval.perturbations)}")
        self.train.select_schedule = check_speed_schedule(self.train.select_schedule, self.eval.episode_s,
                                                          "train.select_schedule", "eval.episode_s")
        for key, weight in (("reward.kgait", self.reward.kgait), ("train.walk_weights.kgait",
                                                                  self.train.walk_weights.get("kgait", 0.0))):
            _require(not weight or self.env.gait_period_s > 0, key,
                     "needs a gait clock to follow (env.gait_period_s > 0, e.g. 0.8)")
        _require(not self.algo.anchor or self.train.init_from, "algo.anchor",
                 "anchors the actor to the one it starts from: needs train.init_from")
        _require(self.train.walk_noise_beta is None or self.algo.name == "td3", "train.walk_noise_beta",
                 f"colors TD3's exploration noise; algo.name is {self.algo.name}")
        for key, cap in self.train.adapt_weights.items():  # from the gait stage's own weight up to cap
            stage = {**asdict(self.reward), **self.train.walk_weights, **self.train.gait_weights}[key]
            _require(0 < stage <= cap, f"train.adapt_weights.{key}",
                     f"adapts from the gait stage's weight ({stage:g}), which must be > 0 and <= {cap:g}")
        try:
            check_muscle_stretch(self.muscle, self.body)
        except ConfigError as err:
            raise ConfigError(f"muscle.{err.key}", err.message) from None
        try:  # body.toe: a spring MuJoCo integrates stably at the physics step
            check_toe_stiffness(self.body, self.env.physics_dt_s)
        except ConfigError as err:
            raise ConfigError(f"body.{err.key}", err.message) from None
        try:  # regulator.model=flow: the supply reaches the muscles' top pressure
            self.muscle.regulator.check_supply(self.muscle.max_pressure_kpa)
        except ConfigError as err:
            raise ConfigError(f"muscle.regulator.{err.key}", err.message) from None


# Keys renamed since a config could have been saved with a run: old section.key -> new key.
RENAMED_KEYS = {"reward": {"k_vx": "kvx", "k_y": "ky", "k_z": "kz", "k_v": "kv", "k_t": "kt"}}


def upgrade_saved_config(data: dict) -> dict:
    """A config saved by an older pamrun (a run's pamrun_config.yaml, an agent file) with
    today's key names, so old runs can still be resumed and evaluated."""
    data = dict(data)
    for section, renames in RENAMED_KEYS.items():
        if isinstance(data.get(section), dict):
            data[section] = {renames.get(k, k): v for k, v in data[section].items()}
    muscle = data.get("muscle")
    if isinstance(muscle, dict) and "size" not in muscle:
        data["muscle"] = _pre_sizing_muscle(muscle)
    return data


def _pre_sizing_muscle(muscle: dict) -> dict:
    """A muscle section saved before the sizing options (before the sizing options): the keys it lacks
    get the values its robot had (one DMSP-20 per direction, automatic radii, the 10
    antagonistic commands); ``kinematic_max_contraction_pct`` becomes ``min_contraction_pct``."""
    muscle = dict(muscle)
    rest = float(muscle.get("kinematic_rest_contraction_pct", 6.5))
    most = float(muscle.pop("kinematic_max_contraction_pct", 13.0))
    muscle.setdefault("min_contraction_pct", 2 * rest - most)
    muscle.setdefault("size", "DMSP-20")
    muscle.setdefault("count", {name: 1 for name in LEG_JOINTS})
    muscle.setdefault("neutral_deg", {name: 0.0 for name in LEG_JOINTS})
    muscle.setdefault("command", "antagonistic")
    for key, value in (("nominal_length_m", 0.26), ("max_pressure_kpa", 800.0), ("v0_v", 2.12),
                       ("dv_max_v", 0.71), ("coupling", "thesis")):
        muscle.setdefault(key, value)
    muscle["regulator"] = {"lag_s": 0.0, **dict(muscle.get("regulator") or {})}
    return muscle


def preset(group: str, name: str) -> dict:
    """What ``conf/<group>/<name>.yaml`` sets, as a dict for e.g. ``PamWalkerEnv(muscle=...)``.

    Its Hydra defaults list is left out (the dataclass defaults equal those sub-presets)."""

    path = CONF_DIR / group / f"{name}.yaml"
    if not path.is_file():
        known = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))
        raise ConfigError(group, f"no preset {name!r}; known: {', '.join(known)}")
    data = yaml.safe_load(path.read_text()) or {}
    data.pop("defaults", None)
    return data


def register_configs() -> None:
    """Register the root schema; every group's YAML is merged into its typed field."""
    ConfigStore.instance().store(name="pamrun_schema", node=Config)


def without_hydra(cfg: DictConfig) -> DictConfig:
    """The config without its ``hydra`` node (present in callbacks), a copy where it had one."""
    if "hydra" in cfg:
        cfg = copy.deepcopy(cfg)
        with read_write(cfg), open_dict(cfg):
            cfg.pop("hydra")
    return cfg


def validate(cfg: DictConfig, path: str = "") -> None:
    """Check every value of a composed config; raise ConfigError with the full key.

    Children are checked before their parent so the error names the deepest key. The
    ``hydra`` node (present in callbacks) is left out.
    """
    cfg = without_hydra(cfg)
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
    known = {f.name for f in dataclasses.fields(OmegaConf.get_type(cfg))}
    for key in cfg.keys():  # `+section.key=...` adds keys a dataclass does not have: a typo
        _require(key in known, f"{path}{key}", f"unknown key; {path.rstrip('.') or 'the config'} has: "
                                               f"{', '.join(sorted(known))}")
    try:
        OmegaConf.to_object(cfg)
    except ConfigError as err:
        raise ConfigError(path + err.key, err.message) from None


def to_object(cfg: DictConfig) -> Any:
    """Validated dataclass instance of a composed config (or of one of its sections)."""
    validate(cfg)
    return OmegaConf.to_object(cfg)


def as_config(value: Any, cls: type) -> Any:
    """A dataclass of type ``cls`` from None, a dataclass, or a (nested, partial) dict.

    Dicts are merged over the defaults through OmegaConf, so unknown keys and wrong types
    fail with the key named, then values are validated (:class:`ConfigError`).
    """
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if is_dataclass(value):
        value = asdict(value)
    merged = OmegaConf.merge(OmegaConf.structured(cls), OmegaConf.create(dict(value)))
    return to_object(merged)
