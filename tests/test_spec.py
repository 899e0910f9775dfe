"""An agent's env (pamrun.task.spec.EnvSpec): made from a config or an agent file's stored dict,
stored as plain dicts, changed only into a new spec, each change validated naming its key."""

from __future__ import annotations

import dataclasses
from dataclasses import asdict
from pathlib import Path

import pytest
import torch

from pamrun.config import ENV_SECTIONS, ConfigError, Perturbation, to_object
from pamrun.evaluation.evaluator import TrainingEvaluator
from pamrun.learning.checkpoints import agent_record, load_agent
from pamrun.learning.networks import ThesisActor
from pamrun.task.observation import N_JOINTS, OBS_SIZE
from pamrun.task.spec import EnvSpec, eval_env_options
from tests.conftest import compose_config

AGENT = Path(__file__).parents[1] / "agents" / "walker_td3_seed0.pt"


def test_one_name_for_the_four_sections():
    assert tuple(f.name for f in dataclasses.fields(EnvSpec)) == ENV_SECTIONS
    with pytest.raises(ConfigError, match="a perturbation changes body, muscle, reward, env"):
        Perturbation(values={"algo": {"gamma": 0.9}})


def test_an_agent_file_stores_the_spec_and_gives_it_back(tmp_path):
    """agent_record's ``config`` is the run's sections as plain dicts (the agent file's format);
    the agent loaded from the file gives back the same spec."""
    cfg = to_object(compose_config("body.mass_kg=7.5", "env.episode_s=8", "reward.kda=0.3"))
    record = agent_record(ThesisActor(OBS_SIZE, N_JOINTS, (400, 300), 3e-3).state_dict(), cfg, {})
    assert record["config"] == {name: asdict(getattr(cfg, name)) for name in ENV_SECTIONS}
    torch.save(record, tmp_path / "a.pt")
    agent = load_agent(tmp_path / "a.pt")
    spec = EnvSpec.from_dict(agent.config)
    assert spec == EnvSpec.from_config(cfg) and spec.to_dict() == record["config"]
    assert spec.body.mass_kg == 7.5 and spec.env.episode_s == 8.0 and spec.reward.kda == 0.3
    env = spec.make()
    assert env.body_cfg is spec.body and env.max_steps == 320
    env.close()


def test_the_shipped_agent_and_an_old_agent_file_load():
    """The shipped agent's stored dict; a dict of an older pamrun (reward keys k_vx, ..., a
    muscle section from before the sizing options) in today's names and defaults."""
    shipped = EnvSpec.from_dict(load_agent(AGENT).config)
    assert shipped.env.gait_period_s == 0.8 and EnvSpec.from_dict(shipped.to_dict()) == shipped
    old = EnvSpec.from_dict({"reward": {"k_vx": 2.0, "k_y": 3.0},
                             "muscle": {"kinematic_rest_contraction_pct": 6.5, "kinematic_max_contraction_pct": 13.0}})
    assert old.reward.kvx == 2.0 and old.reward.ky == 3.0
    assert old.muscle.size == "DMSP-20" and old.muscle.min_contraction_pct == 0.0


def test_a_section_missing_from_the_stored_dict_is_the_base_s_and_values_come_last():
    base = EnvSpec.from_config(to_object(compose_config("body.mass_kg=7.5")))
    spec = EnvSpec.from_dict({"env": {"episode_s": 6.0}}, base=base, env={"episode_s": 4.0, "reset_noise_rad": 0.0})
    assert spec.body == base.body and spec.env.episode_s == 4.0 and spec.env.reset_noise_rad == 0.0
    with pytest.raises(ConfigError) as err:
        EnvSpec.from_dict({"body": {"mass_kg": -1.0}})
    assert err.value.key == "body.mass_kg"


def test_a_spec_is_its_own_copy_and_changes_into_a_new_one():
    cfg = to_object(compose_config())
    spec = EnvSpec.from_config(cfg)
    cfg.body.mass_kg = 99.0  # a later change of the config does not reach the spec
    assert spec.body.mass_kg != 99.0
    shorter = spec.with_values(env={"episode_s": 2.0})
    assert shorter.env.episode_s == 2.0 and spec.env.episode_s == 10.0 and shorter.body is spec.body
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.env = shorter.env
    with pytest.raises(ConfigError) as err:
        spec.with_values(env={"episode_s": -1.0})
    assert err.value.key == "env.episode_s"
    assert spec.changes_to(spec) == [] and spec.changes_to(EnvSpec.from_dict(spec.to_dict())) == []
    other = spec.with_values(env={"gait_period_s": 0.9}, reward={"kv": 0.5})
    assert spec.changes_to(other) == [f"env.gait_period_s {spec.env.gait_period_s} -> 0.9",
                                      f"reward.kv {spec.reward.kv} -> 0.5"]


def test_a_buffer_gathered_under_other_command_draws_is_still_the_tasks():
    """A fine-tune (train.init_from) keeps its source's replay buffer where only the drawn speed
    commands differ (each transition carries its own v*), not where a transition's reward differs."""
    commanded = EnvSpec.from_config(to_object(compose_config("experiment=command")))
    draws = commanded.with_values(env={"speed_stop_share": 0.3, "speed_changes": 2, "speed_range_m_s": [0.0, 1.4],
                                       "speed_ramp_m_s2": 1.5})
    assert len(commanded.changes_to(draws)) == 4 and commanded.transition_changes_to(draws) == []
    narrower = draws.with_values(env={"speed_sigma_m_s": 0.25})
    assert commanded.transition_changes_to(narrower) == ["env.speed_sigma_m_s 0.5 -> 0.25"]


@pytest.mark.parametrize("perturbation, key", [
    (Perturbation(scale={"body": {"friction_static": 0.5}}), None),  # x0.5: possible
    (Perturbation(values={"body": {"friction_static": -0.1}}), "eval.perturbations.p.values.body.friction_static"),
    (Perturbation(values={"muscle": {"regulator": {"lag_s": -1.0}}}), "eval.perturbations.p.values.muscle.regulator.lag_s"),
    (Perturbation(values={"env": {"no_such_key": 1.0}}), "eval.perturbations.p.values.env.no_such_key"),
    (Perturbation(scale={"muscle": {"size": 2.0}}), "eval.perturbations.p.scale.muscle.size"),
])
def test_a_perturbation_names_its_key_on_a_bad_value(perturbation, key):
    spec = EnvSpec()
    if key is None:
        assert spec.perturbed(perturbation, "eval.perturbations.p").body.friction_static == 0.5 * spec.body.friction_static
        return
    with pytest.raises(ConfigError) as err:
        spec.perturbed(perturbation, "eval.perturbations.p")
    assert err.value.key == key


def test_a_perturbation_goes_part_of_the_way_at_a_strength():
    spec = EnvSpec()
    heavy = Perturbation(scale={"body": {"mass_kg": 1.2}}, values={"env": {"reset_noise_rad": 0.05}})
    half = spec.perturbed(heavy, "x", strength=0.5)
    assert half.body.mass_kg == pytest.approx(1.1 * spec.body.mass_kg)
    assert half.env.reset_noise_rad == pytest.approx(spec.env.reset_noise_rad + 0.5 * (0.05 - spec.env.reset_noise_rad))
    assert half.muscle is spec.muscle and half.reward is spec.reward


def test_evaluations_hold_one_commanded_speed_in_pamrun_eval_and_in_training():
    """eval_env_options: an evaluation holds v* (eval.speed_m_s, else the agent's own) with no
    drawn range, changes or stops, in pamrun eval and in the selection evaluations during
    training alike (the walk test is defined at one speed)."""
    cfg = to_object(compose_config("env.speed_command=true", "env.speed_range_m_s=[0.5,1.2]", "env.speed_changes=2",
                                   "env.speed_stop_share=0.2", "eval.speed_m_s=0.8",
                                   "train.eval_episodes=1", "eval.episode_s=0.5", "eval.walk_duration_s=0.5"))
    held = eval_env_options(cfg.eval)
    assert held["speed_range_m_s"] == [] and held["target_speed_m_s"] == 0.8 and held["episode_s"] == 0.5
    assert "speed_ramp_m_s2" not in held  # the agent's own ramp ...
    ramped = to_object(compose_config("eval.speed_ramp_m_s2=3"))
    assert eval_env_options(ramped.eval)["speed_ramp_m_s2"] == 3.0  # ... unless eval.speed_ramp_m_s2 sets one
    evaluator = TrainingEvaluator(cfg)
    env = evaluator.env.env_cfg
    assert (env.speed_range_m_s, env.speed_changes, env.speed_stop_share) == ([], 0, 0.0)
    assert env.target_speed_m_s == 0.8 and env.episode_s == 0.5 and env.speed_command
    evaluator.env.reset(seed=3)
    assert evaluator.env.target_speed_m_s == 0.8 and evaluator.env.episode.changes == []
    evaluator.close()
