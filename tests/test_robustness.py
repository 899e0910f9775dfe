"""Held-out reporting, Wilson intervals, the env's perturbation options and the robustness suite."""

from __future__ import annotations

import csv
import json

import mujoco
import numpy as np
import pytest
import torch

from pamrun.config import ConfigError, Perturbation, to_object
from pamrun.evaluation.episodes import agent_env, aggregate, wilson_interval
from pamrun.evaluation.evaluate import check_config
from pamrun.evaluation.evaluator import TrainingEvaluator
from pamrun.evaluation.ranking import held_out, selection_block
from pamrun.learning.checkpoints import load_agent
from pamrun.task.criteria import kept_command
from pamrun.task.env import PamWalkerEnv
from pamrun.task.observation import N_JOINTS, OBS_BASE, OBS_SIZE
from tests.conftest import compose_config, run_pamrun

# --------------------------------------------------------------------------- intervals


@pytest.mark.parametrize("k, n, low, high", [
    # Published values of the 95 % Wilson score interval (e.g. Newcombe, Stat. Med. 17, 1998, Table I:
    # 0/10 -> 0-0.2775, 1/29 -> 0.0061-0.1718, 81/263 -> 0.2553-0.3662)
    (0, 10, 0.0, 0.2775),
    (1, 29, 0.0061, 0.1718),
    (81, 263, 0.2553, 0.3662),
    (10, 10, 0.7225, 1.0),  # the mirror of 0/10
])
def test_wilson_interval_matches_published_values(k, n, low, high):
    lo, hi = wilson_interval(k, n)
    assert lo == pytest.approx(low, abs=1e-4) and hi == pytest.approx(high, abs=1e-4)


@pytest.mark.parametrize("n", [10, 50, 300])
def test_the_interval_holds_the_rate_at_all_or_none(n):
    """At n of n (and 0 of n) the rate is the interval's end exactly, not a rounding outside it."""
    assert wilson_interval(n, n)[1] == 1.0 and wilson_interval(0, n)[0] == 0.0
    assert wilson_interval(n, n)[0] < 1.0 and wilson_interval(0, n)[1] > 0.0


def test_a_pass_rate_comes_with_its_count_and_interval():
    ep = {"duration_s": 10.0, "fell": False, "max_abs_y_m": 0.1, "distance_m": 8.0, "return": 1.0,
          "speed_m_s": 0.8, "pressure_change_kpa": 1.0}
    agg = aggregate([ep] * 41 + [{**ep, "distance_m": 3.0}] * 9, to_object(compose_config()).eval)
    assert (agg["walk_passes"], agg["episodes"], agg["walk_pass_rate"]) == (41, 50, 0.82)
    assert agg["walk_pass_ci_low"] == pytest.approx(0.6920, abs=1e-3)
    assert agg["walk_pass_ci_high"] == pytest.approx(0.9023, abs=1e-3)
    assert np.isnan(agg["step_frequency_hz_mean"])  # no steps recorded: undefined, not 0


# --------------------------------------------------------------------------- held-out seeds


def _agent(tmp_path, meta):
    from pamrun.learning.checkpoints import agent_record
    from pamrun.learning.networks import ThesisActor

    path = tmp_path / "a.pt"
    torch.save(agent_record(ThesisActor(OBS_SIZE, N_JOINTS, (400, 300), 3e-3).state_dict(),
                            to_object(compose_config()), meta), path)
    return load_agent(path, OBS_SIZE, N_JOINTS)


def test_the_default_evaluation_is_held_out_from_the_selection_seeds(tmp_path):
    cfg = to_object(compose_config())
    assert cfg.eval.episodes >= 50 and cfg.eval.seed >= cfg.eval.selection_seed + cfg.train.eval_episodes
    recorded = _agent(tmp_path, {"eval": {"episodes": 10, "seeds": [1040, 1049]}})
    legacy = _agent(tmp_path, {"eval": {"episodes": 10}})  # saved before the seeds were recorded
    assert selection_block(recorded, cfg) == range(1040, 1050)
    assert selection_block(legacy, cfg) == range(0, 10)
    assert held_out([legacy], cfg) is True and held_out([recorded], cfg) is False
    assert held_out([legacy], to_object(compose_config("eval.seed=5"))) is False


def test_training_selects_on_the_selection_block():
    cfg = to_object(compose_config("train.eval_episodes=2", "eval.episode_s=0.5", "eval.walk_duration_s=0.5",
                                   "eval.selection_seed=7"))
    evaluator = TrainingEvaluator(cfg)
    actor = torch.nn.Sequential(torch.nn.Linear(OBS_SIZE, N_JOINTS), torch.nn.Tanh())
    assert evaluator(actor)["seeds"] == [7, 8]
    evaluator.close()


def _select_evaluator(walk_distance_m: float, shoves: int | None = None):
    """A training evaluator whose nominal block a standing actor passes (1 s; a sway back of a
    few mm is no fall) when ``walk_distance_m`` is below 0, selecting also under a shove it
    cannot stand (``shoves`` episodes of it: train.select_episodes_of; None: select_episodes)."""
    overrides = ["train.eval_episodes=2", "train.select_episodes=3", "eval.episode_s=1.0", "eval.walk_duration_s=1.0",
                 "+eval.perturbations.shove={values:{env:{push_impulse_ns:[0,150,0],push_time_s:0.1,"
                 "push_duration_s:0.1}}}", "train.select_perturbations=[shove]"]
    if shoves is not None:
        overrides.append(f"+train.select_episodes_of.shove={shoves}")
    cfg = to_object(compose_config(*overrides))
    cfg.eval.walk_distance_m = walk_distance_m  # (a config refuses < 0: set past its check)
    return TrainingEvaluator(cfg)


def test_selection_under_perturbation_counts_the_perturbed_episodes_once_a_nominal_one_passes():
    actor = torch.nn.Sequential(torch.nn.Linear(OBS_SIZE, N_JOINTS), torch.nn.Tanh())
    torch.nn.init.zeros_(actor[0].weight), torch.nn.init.zeros_(actor[0].bias)  # holds its pressures: stands
    standing = _select_evaluator(-1.0)
    result = standing(actor)
    standing.close()
    assert result["walk_pass_rate"] == 1.0 and result["episodes"] == 2  # the nominal aggregate is the nominal block's
    assert result["select_pass_rate"] == pytest.approx(2 / 5)  # 2 nominal passes, 3 shoved falls
    more = _select_evaluator(-1.0, shoves=5)
    result = more(actor)
    more.close()
    assert result["select_pass_rate"] == pytest.approx(2 / 7)  # the shove's own count: 5 falls
    never = _select_evaluator(100.0)
    result = never(actor)
    never.close()
    assert result["walk_pass_rate"] == 0.0 and result["select_pass_rate"] == 0.0


@pytest.mark.parametrize("override, key", [("train.select_perturbations=[lag_x2,nope]", "train.select_perturbations"),
                                           ("train.select_episodes=0", "select_episodes"),
                                           ("+train.select_episodes_of.friction_low=5", "select_episodes_of.friction_low"),
                                           ("+train.select_episodes_of.lag_x2=0", "select_episodes_of.lag_x2"),
                                           ("train.eval_every_frames=0", "select_perturbations")])
def test_selection_under_perturbation_is_checked_with_the_config(override, key):
    with pytest.raises(ConfigError, match=key):
        to_object(compose_config("train.select_perturbations=[lag_x2]", override))


def test_selection_on_a_speed_schedule_counts_the_episodes_that_keep_to_it():
    actor = torch.nn.Sequential(torch.nn.Linear(OBS_SIZE, N_JOINTS), torch.nn.Tanh())
    torch.nn.init.zeros_(actor[0].weight), torch.nn.init.zeros_(actor[0].bias)  # holds its pressures: stands
    overrides = ("train.eval_episodes=2", "eval.episode_s=2.0", "eval.walk_duration_s=2.0",
                 "train.select_schedule=[[0,0],[0.25,0.6]]", "train.select_schedule_episodes=3")
    cfg = to_object(compose_config(*overrides, "train.select_schedule=[[0,0]]"))
    cfg.eval.walk_distance_m = -1.0  # (a config refuses < 0: set past its check) the nominal block passes
    told_to_stand = TrainingEvaluator(cfg)
    result = told_to_stand(actor)
    told_to_stand.close()
    # told 0 for 2 s, it stands still after 1.5 s of settling: 2 nominal passes and 3 kept schedules
    assert result["select_schedule_rate"] == 1.0 and result["select_pass_rate"] == 1.0
    assert result["episodes"] == 2  # the nominal aggregate is the nominal block's
    cfg.eval.walk_distance_m = 100.0
    never = TrainingEvaluator(cfg)
    result = never(actor)
    never.close()
    assert result["walk_pass_rate"] == 0.0 and np.isnan(result["select_schedule_rate"])  # no nominal pass: not run
    cfg = to_object(compose_config(*overrides))
    assert TrainingEvaluator(cfg).scheduled.env_cfg.speed_schedule == [[0.0, 0.0], [0.25, 0.6]]


@pytest.mark.parametrize("changes, kept", [({}, True), ({"fell": True, "duration_s": 4.0}, False),
                                           ({"stand_still_feet_down_share": 0.85}, False),
                                           ({"stand_still_drift_m": 0.25}, False),
                                           ({"stand_still_feet_down_share": float("nan"),
                                             "stand_still_drift_m": float("nan")}, True)])
def test_an_episode_keeps_to_its_schedule_when_it_stands_still_where_told_0(changes, kept):
    cfg = to_object(compose_config())
    episode = {"fell": False, "physics_error": False, "duration_s": cfg.eval.walk_duration_s,
               "stand_still_feet_down_share": 0.95, "stand_still_drift_m": 0.1, **changes}
    assert kept_command(episode, cfg.eval) is kept


@pytest.mark.parametrize("override, key", [("train.select_schedule_episodes=0", "select_schedule"),
                                           ("train.select_schedule_episodes=-1", "select_schedule_episodes"),
                                           ("train.select_schedule=[[0,-0.5]]", "train.select_schedule"),
                                           ("train.select_schedule=[[0,0],[10.5,1.0]]", "train.select_schedule"),
                                           ("train.eval_every_frames=0", "select_schedule")])
def test_selection_on_a_speed_schedule_is_checked_with_the_config(override, key):
    with pytest.raises(ConfigError, match=key):
        to_object(compose_config("train.select_schedule=[[0,0],[2.5,1.0]]", "train.select_schedule_episodes=3",
                                 override))


def test_training_keeps_the_agent_that_holds_under_perturbation():
    evaluator = _select_evaluator(-1.0)
    evaluator.close()
    best = {"walk_pass_rate": 1.0, "stand_rate": 1.0, "distance_mean": 9.0, "select_pass_rate": 0.7}
    assert evaluator.better({**best, "distance_mean": 6.0, "select_pass_rate": 0.8}, best)
    assert not evaluator.better({**best, "distance_mean": 12.0, "select_pass_rate": 0.6}, best)
    assert evaluator.better({**best, "distance_mean": 9.5}, best)  # a tie goes on to eval.rank_by
    assert not evaluator.better(dict(best), best)  # a full tie keeps the old one
    legacy = {k: v for k, v in best.items() if k != "select_pass_rate"}  # saved before the key existed
    assert not evaluator.better({**best, "select_pass_rate": 0.9}, legacy)
    nominal = TrainingEvaluator(to_object(compose_config("train.eval_episodes=2")))  # no select_perturbations
    nominal.close()
    assert nominal.better({**best, "distance_mean": 12.0, "select_pass_rate": 0.6}, best)  # eval.rank_by alone


# --------------------------------------------------------------------------- the env's perturbation options


def test_a_push_gives_the_robot_its_impulse():
    """10 N s on the torso spread over 0.1 s (four control steps): the robot's momentum gains
    a quarter of it in each pushed step over its unpushed twin, nothing before; the ground's
    reaction as the pushed body pitches adds a little (measured: 2.56, 5.58, 8.60, 11.50 N s)."""
    def run(push):
        env = PamWalkerEnv(env={"push_impulse_ns": push, "push_time_s": 0.25, "push_duration_s": 0.1})
        env.reset(seed=0)
        momentum = []
        for _ in range(14):
            env.step(np.zeros(N_JOINTS))
            mujoco.mj_subtreeVel(env.model, env.data)
            momentum.append(env.mass_kg * env.data.subtree_linvel[1].copy())  # body 1: the torso, root of all
        return np.array(momentum)

    quiet = run([0, 0, 0])
    for axis, push in ((0, [10.0, 0, 0]), (1, [0, 10.0, 0]), (0, [-10.0, 0, 0])):
        gain = (run(push) - quiet)[:, axis] * np.sign(sum(push))
        assert np.allclose(gain[:10], 0.0)  # steps 1-10 end before 0.25 s
        assert gain[10] == pytest.approx(2.5, abs=0.3)  # the first pushed step: 100 N for 25 ms
        assert np.all(np.diff(gain[10:]) > 1.5) and 8.5 < gain[13] < 13.0


def test_observation_noise_is_seeded_and_spares_the_previous_action():
    noisy = PamWalkerEnv(env={"observation_noise_std": 0.02})
    clean = PamWalkerEnv()
    diffs = []
    for seed in range(20):
        a, b = noisy.reset(seed=seed)[0], clean.reset(seed=seed)[0]
        diffs.append(a - b)
    diffs = np.array(diffs)
    assert np.std(diffs[:, :OBS_BASE]) == pytest.approx(0.02, rel=0.15)
    assert np.all(diffs[:, OBS_BASE:] == 0)
    assert np.array_equal(noisy.reset(seed=3)[0], noisy.reset(seed=3)[0])


# --------------------------------------------------------------------------- perturbations


def test_a_perturbation_reaches_the_simulated_robot(tmp_path):
    cfg = to_object(compose_config())
    spec = agent_env(_agent(tmp_path, {}), cfg)
    p = cfg.eval.perturbations
    low = spec.perturbed(p["friction_low"], "eval.perturbations.friction_low")
    env, base = low.make(), spec.make()
    sole = mujoco.mj_name2id(env.model, mujoco.mjtObj.mjOBJ_GEOM, "left_contact_front_left")
    assert env.model.geom_friction[sole, 0] == pytest.approx(0.7 * base.model.geom_friction[sole, 0])
    heavy = spec.perturbed(p["mass_heavy"], "x").make()
    assert heavy.mass_kg == pytest.approx(1.1 * base.mass_kg, rel=1e-6)
    lag = spec.perturbed(p["lag_x2"], "x")
    assert lag.muscle.regulator.lag_s == 2 * spec.muscle.regulator.lag_s
    assert lag.body is spec.body and lag.env is spec.env  # the sections it leaves alone are shared
    assert spec.perturbed(p["start_noise"], "x").env.reset_noise_rad == 0.05
    assert spec.perturbed(p["nominal"], "x") == spec and spec.body.friction_static == 0.5  # no mutation


def test_the_models_suite_puts_each_pneumatic_model_into_the_robot(tmp_path):
    """eval.suite=models: each of its perturbations builds the agent's robot with that model
    (the valve, the hysteresis elements, the Tondu-Lopez law, the toes), and it steps."""
    cfg = to_object(compose_config())
    spec = agent_env(_agent(tmp_path, {}), cfg)
    assert cfg.eval.suites["models"] == ["nominal", "valve_flow", "hysteresis", "force_law", "toe"]
    built = {name: spec.perturbed(cfg.eval.perturbations[name], name).make()
             for name in cfg.eval.suites["models"]}
    assert type(built["valve_flow"].drive.pairs.regulator).__name__ == "FlowRegulator"
    assert built["hysteresis"].muscle_cfg.spring.hysteresis == "maxwell_slip"
    assert type(built["force_law"].drive.pairs.law).__name__ == "TonduLopez"
    assert built["toe"].model.nq == built["nominal"].model.nq + 2  # a hinge per toe
    for name, env in built.items():
        env.reset(seed=0)
        obs, *_ = env.step(np.zeros(N_JOINTS))
        assert obs.shape == (OBS_SIZE,) and np.all(np.isfinite(obs)), name
        env.close()


@pytest.mark.parametrize("spec, key", [
    (Perturbation(values={"body": {"friction_static": -0.1}}), "p.values.body.friction_static"),
    (Perturbation(values={"muscle": {"regulator": {"lag_s": -0.05}}}), "p.values.muscle.regulator.lag_s"),
    (Perturbation(values={"env": {"push_impulse_ns": [5.0, 0, 0], "push_time_s": 9.95}}), "p.values.env.push_time_s"),
    (Perturbation(values={"env": {"push_tme_s": 1.0}}), "p.values.env.push_tme_s"),
    (Perturbation(scale={"muscle": {"size": 2.0}}), "p.scale.muscle.size"),
])
def test_impossible_perturbations_name_the_key(spec, key):
    env = agent_env(_agent_free(), to_object(compose_config()))
    with pytest.raises(ConfigError) as err:
        env.perturbed(spec, "p")
    assert err.value.key == key


def _agent_free():
    class A:  # what agent_env reads of an agent with no stored config
        config = None
    return A()


@pytest.mark.parametrize("override, key", [
    ("eval.suite=robustnes", "eval.suite"),
    ("eval.suites.robustness=[nominal,gravity_x2]", "eval.suites.robustness"),
    ("+eval.perturbations.friction_low.values.body.friction_static=-0.2",
     "eval.perturbations.friction_low.values.body.friction_static"),
    ("+eval.perturbations.lag_x2.values.muscle.regulator.lag_s=-1", "eval.perturbations.lag_x2.values.muscle.regulator.lag_s"),
    ("eval.perturbations.push_forward.values.env.push_time_s=9.95", "eval.perturbations.push_forward.values.env.push_time_s"),
])
def test_bad_suites_fail_before_anything_is_written(tmp_path, override, key):
    cfg = compose_config("eval.suite=robustness", override, f"ckpt={tmp_path}")
    with pytest.raises(ConfigError) as err:
        check_config(cfg) if "suite=" not in override and "suites." not in override else to_object(cfg)
    assert err.value.key == key


def test_a_bad_perturbation_on_the_command_line_writes_nothing(tmp_path):
    out = tmp_path / "ev"
    proc = run_pamrun("eval", f"ckpt={tmp_path}", "eval.suite=robustness",
                      "+eval.perturbations.friction_low.values.body.friction_static=-0.2", f"hydra.run.dir={out}")
    assert proc.returncode != 0 and not out.exists()
    assert "eval.perturbations.friction_low.values.body.friction_static: must be >= 0" in proc.stderr


@pytest.mark.slow
def test_the_robustness_suite_end_to_end(tmp_path):
    """Two agents x three perturbations (one of them the user's own) through ``pamrun eval``."""
    folder = tmp_path / "agents"
    folder.mkdir()
    from pamrun.learning.checkpoints import agent_record
    from pamrun.learning.networks import ThesisActor

    for seed in (0, 1):
        torch.manual_seed(seed)
        torch.save(agent_record(ThesisActor(OBS_SIZE, N_JOINTS, (400, 300), 3e-3).state_dict(),
                                to_object(compose_config()), {"episode": seed}), folder / f"agent_ep{seed:06d}_r0.pt")
    out = tmp_path / "ev"
    proc = run_pamrun("eval", f"ckpt={folder}", "eval.suite=robustness", "eval.episodes=2", "eval.episode_s=1.0",
                      "eval.walk_duration_s=1.0", "eval.walk_distance_m=0",
                      "+eval.perturbations.mine={note:'shove',values:{env:{push_impulse_ns:[0,30,0],push_time_s:0.2}}}",
                      "eval.suites.robustness=[nominal,friction_low,mine]", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = list(csv.DictReader((out / "robustness.csv").open()))
    assert [(r["agent"][-17:], r["perturbation"]) for r in rows] == [
        (f"agent_ep00000{a}_r0", p) for a in (0, 1) for p in ("nominal", "friction_low", "mine")]
    data = json.loads((out / "robustness.json").read_text())
    assert data["perturbations"]["mine"]["note"] == "shove" and data["held_out"] is True
    assert data["seconds_per_episode"] > 0 and (out / "robustness.png").stat().st_size > 0
    episodes = [json.loads(line) for line in (out / "robustness_episodes.jsonl").open()]
    assert len(episodes) == 12 and "steps" not in episodes[0]
    # The user's sideways shove moved the robot sideways; the nominal episodes did not move that way.
    y = {(e["agent"], e["perturbation"]): e["max_abs_y_m"] for e in episodes if e["episode"] == 0}
    assert all(y[a, "mine"] > y[a, "nominal"] + 0.01 for a, _ in y)
    for r in rows:
        assert float(r["walk_pass_ci_low"]) <= float(r["walk_pass_rate"]) <= float(r["walk_pass_ci_high"])
    assert "Robustness" in proc.stdout and "shove" in proc.stdout
