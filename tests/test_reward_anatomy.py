"""benchmarks/reward_anatomy.py, the split of an agent's reward by term: its terms add up to the
return pamrun eval's episode runner pays, and its clock's wants are those the env charges."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from pamrun.evaluation.episodes import make_policy, run_episode
from pamrun.learning.checkpoints import load_agent
from pamrun.task import clock
from pamrun.task.spec import EnvSpec

WALKER = Path(__file__).parent.parent / "agents" / "walker_td3_seed0.pt"


def anatomy_module():
    path = Path(__file__).parent.parent / "benchmarks" / "reward_anatomy.py"
    spec = importlib.util.spec_from_file_location("reward_anatomy", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # (its dataclass looks its module up there)
    spec.loader.exec_module(module)
    return module


def test_the_terms_add_up_to_the_return_and_the_clock_is_split_by_want():
    anatomy = anatomy_module()
    agent = load_agent(WALKER)
    weights = anatomy.stage_weights(agent)["env"]  # a file outside a run: its env's own weights
    out = anatomy.measure(agent, episodes=1, seed=1000)
    episode = run_episode(make_policy(agent), EnvSpec.from_dict(agent.config).make(), seed=1000, keep_steps=False)
    assert out.steps == round(episode["duration_s"] / out.control_dt_s)
    total = sum(weights[k] * out.means[k] for k in weights) * out.steps
    assert total == pytest.approx(episode["return"], rel=1e-9)
    assert 0.0 < out.means["kgait"] < 1.0  # computed at its env weight 0: the shipped walker follows its clock in part
    assert len(out.wants) == 2 * out.steps
    assert {name for _, wants in out.wants for name in wants} <= set(clock.SWING_WANTS) | set(clock.STANCE_WANTS)
    # kgait's feature is 1 - (1/2) sum over the feet of the miss their wants make
    rebuilt = 1.0 - 0.5 * sum(clock.miss_of(*row) for row in out.wants) / out.steps
    assert rebuilt == pytest.approx(out.means["kgait"], rel=1e-9)


def test_the_gait_cycle_follows_each_foot_through_its_own_clock_phase(capsys):
    anatomy = anatomy_module()
    out = anatomy.measure(load_agent(WALKER), episodes=1, seed=1000)
    assert len(out.cycle) == len(out.wants)
    right, left = np.array(out.cycle[0::2]), np.array(out.cycle[1::2])
    assert np.allclose((left[:, 0] - right[:, 0]) % 1.0, 0.5)  # the left foot's clock runs half a stride on
    period_s = load_agent(WALKER).config["env"]["gait_period_s"]
    assert np.allclose(np.diff(right[:, 0]) % 1.0, out.control_dt_s / period_s)
    assert np.array_equal(right[:, 2], left[:, 1])  # "the other foot down" is the other foot's own contact
    anatomy.print_cycle(out)
    table = capsys.readouterr().out.splitlines()
    assert len(table) == 3 + 20 and table[3].startswith("0.00-0.05")
