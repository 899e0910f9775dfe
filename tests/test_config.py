"""Configuration: composition, validation with the full key, and the CLI's handling of bad input."""

from __future__ import annotations

import pytest
from hydra.errors import ConfigCompositionException

from pamrun.config import (
    AlgoConfig,
    BodyConfig,
    ConfigError,
    MuscleConfig,
    RewardConfig,
    TrainConfig,
    to_object,
)
from tests.conftest import compose_config, run_pamrun


def test_default_config_is_the_sized_robot_and_muscle_thesis_is_the_thesis(cfg):
    assert cfg.muscle == MuscleConfig()  # the dataclass is the one source of defaults (muscle=sized)
    assert (cfg.muscle.size, cfg.muscle.coupling, cfg.muscle.command) == ("DMSP-40", "kinematic", "antagonistic")
    assert cfg.body.height_m == 1.80 and cfg.body.mass_kg == 80.0
    thesis = to_object(compose_config("muscle=thesis")).muscle
    assert thesis.tau_s == 0.3 and thesis.v0_v == 2.12 and thesis.dv_max_v == 0.71
    assert (thesis.size, thesis.nominal_length_m, thesis.coupling, thesis.max_pressure_kpa) == ("DMSP-20", 0.26,
                                                                                             "thesis", 800.0)
    assert thesis.regulator.lag_s == 0 and thesis.force_scale == 1.0
    assert all(v == 1 for v in vars(thesis.count).values())
    assert len(thesis.spring.stiffness_n_per_m) == 8


@pytest.mark.parametrize(
    "override, key",
    [
        ("muscle.tau_s=0", "muscle.tau_s"),
        ("muscle.tau_s=-0.3", "muscle.tau_s"),
        ("muscle.regulator.max_pressure_kpa=-5", "muscle.regulator.max_pressure_kpa"),
        ("muscle.spring.band_edges_kpa=[0,200,100,300,400,500,600,700,800]", "muscle.spring.band_edges_kpa"),
        ("muscle.spring.stiffness_n_per_m=[1,2,3]", "muscle.spring.stiffness_n_per_m"),
        ("muscle.spring.stiffness_n_per_m=[1,2,3,-4,5,6,7,8]", "muscle.spring.stiffness_n_per_m"),
        ("muscle.force_law=geometric", "muscle.force_law"),
        ("body.height_m=-1.8", "body.height_m"),
        ("body.knee_limits_deg=[90,0]", "body.knee_limits_deg"),
        ("muscle.size=DMSP-30", "muscle.size"),
        ("muscle.count.knee=0", "muscle.count.knee"),
        ("muscle.command=both", "muscle.command"),
        ("muscle.min_contraction_pct=-4", "muscle.min_contraction_pct"),
        ("muscle.radius_mm.ankle_pitch=80", "muscle.radius_mm.ankle_pitch"),
        ("muscle.neutral_deg.knee=120", "muscle.neutral_deg.knee"),
        ("pair.experiments.max_and_1bar.pressure1_kpa=-1", "pair.experiments.max_and_1bar.pressure1_kpa"),
        ("algo.anchor=-0.4", "algo.anchor"),
        ("algo.anchor=0.4", "algo.anchor"),  # no train.init_from to anchor to
        ("algo.anchor_fade_frames=-1", "algo.anchor_fade_frames"),
        ("algo.anchor_fade_start_frames=1000", "algo.anchor_fade_start_frames"),  # no algo.anchor to fade
    ],
)
def test_impossible_values_name_the_key(override, key):
    with pytest.raises(ConfigError) as err:
        to_object(compose_config(override))
    assert err.value.key == key
    assert str(err.value).startswith(key + ":")


def test_unknown_key_and_wrong_type_fail_in_composition():
    with pytest.raises(ConfigCompositionException, match="tau"):
        compose_config("muscle.tau=0.2")
    with pytest.raises(ConfigCompositionException, match="tau_s"):
        compose_config("muscle.tau_s=fast")


def test_dataclasses_validate_without_hydra():
    with pytest.raises(ConfigError, match="tau_s"):
        MuscleConfig(tau_s=-1)
    with pytest.raises(ConfigError, match="height_m"):
        BodyConfig(height_m=-1)



def test_cli_bad_value_fails_before_the_run_dir(tmp_path):
    run_dir = tmp_path / "run"
    proc = run_pamrun("muscle", "step", "muscle.tau_s=-1", f"hydra.run.dir={run_dir}")
    assert proc.returncode != 0
    assert "muscle.tau_s" in proc.stderr + proc.stdout
    assert not run_dir.exists()


@pytest.mark.parametrize("args, said", [
    (("muscle", "step", "muscle.tua_s=0.2"), "tua_s"),
    # experiment=command's train.adapt_weights has entries: '{}' would leave them in place unsaid
    (("train", "experiment=command", "train.adapt_weights={}"), "train.adapt_weights={} would change nothing"),
])
def test_cli_unknown_key_or_empty_dict_fails_naming_it(tmp_path, args, said):
    run_dir = tmp_path / "run"
    proc = run_pamrun(*args, f"hydra.run.dir={run_dir}")
    assert proc.returncode != 0
    assert said in proc.stderr
    assert not run_dir.exists()


def test_cli_unknown_command():
    proc = run_pamrun("fly")
    assert proc.returncode == 2
    assert "unknown command" in proc.stderr and "muscle step" in proc.stderr


def test_cli_prints_config_and_help():
    proc = run_pamrun("muscle", "step", "muscle.tau_s=0.2", "--cfg", "job")
    assert proc.returncode == 0, proc.stderr
    assert "tau_s: 0.2" in proc.stdout
    proc = run_pamrun("muscle", "step", "--help")
    assert proc.returncode == 0
    assert "  muscle   sized*, thesis" in proc.stdout and "pair.dt_s = 0.001  # integration step" in proc.stdout
    assert "algo." not in proc.stdout  # only what the command uses
    proc = run_pamrun("train", "--help")
    keys = [line.split(" = ")[0].strip() for line in proc.stdout.splitlines() if " = " in line]
    assert {"seed", "muscle.size", "algo.actor_lr", "train.max_minutes", "resume"} <= set(keys)
    assert all("  # " in line for line in proc.stdout.splitlines() if " = " in line)  # every key has its doc


def _repeated_defaults(data: dict, defaults: dict, prefix: str = "") -> list[str]:
    """Keys of a preset whose values equal the dataclass defaults (they belong in the dataclass only)."""
    out = []
    for key, value in data.items():
        if isinstance(value, dict) and isinstance(defaults.get(key), dict):
            out += _repeated_defaults(value, defaults[key], f"{prefix}{key}.")
        elif key in defaults and value == defaults[key]:
            out.append(prefix + key)
    return out


def test_presets_hold_only_what_they_change():
    """One source of defaults: the dataclasses. A YAML preset that repeats a default is a second copy.
    A preset built on another of its group (experiment=walker on walk) is compared with that one:
    it may set a value back to the dataclass' default, never repeat its parent's."""
    from dataclasses import asdict

    import yaml

    from pamrun.config import CONF_DIR, Config

    defaults = asdict(Config())
    checked = 0
    for group in ("experiment", "muscle", "body", "reward", "env", "algo", "train", "eval", "sweep"):
        for path in sorted((CONF_DIR / group).glob("*.yaml")):
            text = path.read_text()
            data = yaml.safe_load(text) or {}
            parents = [d for d in data.pop("defaults", None) or [] if isinstance(d, str) and d != "_self_"]
            scope = defaults if text.startswith("# @package _global_") else defaults[group]  # e.g. train=walk
            if parents:  # the composed parent preset
                scope = asdict(to_object(compose_config(f"{group}={parents[-1]}")))
            assert _repeated_defaults(data, scope) == [], path.name
            checked += 1
    assert checked >= 14
    thesis_recipe = to_object(compose_config("experiment=thesis", "muscle=sized"))  # the dataclass' defaults
    assert thesis_recipe.algo == AlgoConfig() and thesis_recipe.train == TrainConfig()
    assert thesis_recipe.muscle == MuscleConfig() and thesis_recipe.reward == RewardConfig()


def test_the_default_recipe_walks_and_the_thesis_is_one_word_away():
    """``pamrun train`` with no arguments runs the gait recipe (experiment=gait: walker's recipe plus a
    gait stage); experiment=walk and experiment=thesis stay one word away; a group on the command line
    wins over the experiment's choice."""
    gait, walker = to_object(compose_config(recipe=None)), to_object(compose_config("experiment=walker"))
    assert (gait.algo.name, gait.algo.critic, gait.reward.kt, gait.algo.mirror_loss) == ("td3", "concat", 400.0, 0.6)
    assert gait.train.gait_weights["kflight"] > gait.train.walk_weights["kflight"] > 0
    assert gait.train.walk_weights["kspeed"] == walker.train.walk_weights["kspeed"] > 0  # walker's, extended
    assert gait.train.randomize == walker.train.randomize and gait.train.mirror and not gait.train.stop_on_walk
    assert gait.env.gait_period_s > walker.env.gait_period_s > 0 and gait.env.stance_knee_deg > 0
    assert gait.eval.rank_by[:2] == ["walk_pass_rate", "walk_targets_met"] and gait.muscle.size == "DMSP-40"
    walk = to_object(compose_config("experiment=walk"))
    assert (walk.algo.name, walk.train.walk_kvx, walk.train.stop_on_walk, walk.env.gait_period_s) == ("td3", 4.0, True, 0.0)
    thesis = to_object(compose_config("experiment=thesis"))
    assert thesis.algo == AlgoConfig() and thesis.train == TrainConfig() and thesis.reward == RewardConfig()
    assert (thesis.muscle.size, thesis.muscle.coupling, thesis.algo.name) == ("DMSP-20", "thesis", "ddpg")
    assert thesis.env.reset_noise_rad == 0.0 and thesis.train.max_episodes == 5000  # Table 9.4
    assert to_object(compose_config("algo=ddpg")).algo.name == "ddpg"


def test_the_command_recipe_is_the_gait_recipe_over_commanded_speeds():
    """experiment=command: experiment=gait trained over commanded speeds from 0 (standing still) to 1.2 m/s,
    its gait stage started at a march's 2 m and its step and flight costs raised from there up to caps,
    its best agent one that also stops where a speed schedule ends at 0 m/s, a changed command ramped."""
    command, gait = to_object(compose_config("experiment=command")), to_object(compose_config("experiment=gait"))
    assert command.env.speed_command and not gait.env.speed_command
    assert command.env.speed_range_m_s[0] == 0.0 < command.env.speed_stop_share and command.env.gait_follows_speed
    assert command.env.speed_ramp_m_s2 > 0 == gait.env.speed_ramp_m_s2
    assert command.train.gait_from_distance_m == 2.0 and gait.train.gait_from_distance_m is None
    for key, cap in command.train.adapt_weights.items():
        assert cap > command.train.gait_weights[key] > 0, key
    assert command.train.adapt_factor > 1
    schedule = command.train.select_schedule
    assert command.train.select_schedule_episodes > 0 and schedule[-1][1] == 0.0 < max(v for _, v in schedule)
    assert not gait.train.select_schedule
    assert command.train.walk_weights["kda"] == gait.train.walk_weights["kda"]  # gait's, extended
    assert (command.algo, command.train.randomize, command.eval) == (gait.algo, gait.train.randomize, gait.eval)


def test_every_config_field_has_a_doc():
    from pamrun.config import Config
    from pamrun.config.docs import describe

    rows = describe(Config)
    assert len(rows) > 140
    assert [key for key, _, doc in rows if not doc] == []
    docs = dict((key, doc) for key, _, doc in rows)
    assert docs["train.max_minutes"] == "wall-clock limit; 0 = none"  # the trailing comment in learning.py
    assert docs["body.knee_limits_deg"].startswith("Left-leg limits")  # the comment heading a run of fields


def test_walk_preset_composes_across_groups():
    """experiment=walk (a _global_ preset) sets the algorithm, reward and env, and train=walk the budget."""
    cfg = to_object(compose_config("experiment=walk"))
    assert (cfg.algo.name, cfg.algo.critic, cfg.algo.actor_lr) == ("td3", "concat", 1e-4)
    assert cfg.algo.actor_update_every == 2  # the rest of algo=td3 comes with it
    assert cfg.reward.kt == 400.0 and cfg.env.reset_noise_rad == 0.02
    assert cfg.train.stop_on_walk and cfg.train.eval_every_frames == 10_000 and cfg.train.actor_start_frames == 20_000
    assert to_object(compose_config("experiment=walk", "algo=sac")).algo.name == "sac"  # the command line still wins
