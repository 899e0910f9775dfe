"""Actor/critic of thesis Tables 9.1-9.2, TorchRL losses, exploration schedule."""

from __future__ import annotations

import math

import pytest
import torch
from torchrl.data import Bounded

from pamrun import agents
from pamrun.config import AlgoConfig, ConfigError

SPEC = Bounded(-torch.ones(10), torch.ones(10), (10,))


def test_actor_is_table_9_1():
    actor = agents.make_actor(AlgoConfig(), 43, 10).module
    layers = [m for m in actor.net]
    assert [type(m).__name__ for m in layers] == ["Linear", "ReLU", "Linear", "ReLU", "Linear", "Tanh"]
    assert [(m.in_features, m.out_features) for m in layers if isinstance(m, torch.nn.Linear)] == [
        (43, 400), (400, 300), (300, 10)]
    out = actor(torch.randn(5, 43) * 100)
    assert out.shape == (5, 10) and out.abs().max() <= 1


def test_critic_is_table_9_2():
    critic = agents.make_critic(AlgoConfig(), 43, 10).module
    assert (critic.obs_path[0].in_features, critic.obs_path[0].out_features) == (43, 400)
    assert (critic.obs_path[2].in_features, critic.obs_path[2].out_features) == (400, 300)
    assert (critic.action_path.in_features, critic.action_path.out_features) == (10, 300)
    assert (critic.head[1].in_features, critic.head[1].out_features) == (300, 1)
    assert critic(torch.randn(4, 43), torch.randn(4, 10)).shape == (4, 1)


@pytest.mark.parametrize("name, keys", [("ddpg", ("loss_actor", "loss_value")), ("td3", ("loss_actor", "loss_qvalue"))])
def test_losses_train_the_critic(name, keys):
    """A few updates on a fixed batch reduce the critic loss: the loss is wired to real gradients."""
    from tensordict import TensorDict

    torch.manual_seed(0)
    cfg = AlgoConfig(name=name)
    actor, critic = agents.make_actor(cfg, 43, 10), agents.make_critic(cfg, 43, 10)
    loss, updater, got_keys = agents.make_loss(cfg, actor, critic, SPEC)
    assert got_keys == keys
    n = 64
    batch = TensorDict({
        "observation": torch.randn(n, 43), "action": torch.rand(n, 10) * 2 - 1,
        "next": {"observation": torch.randn(n, 43), "reward": torch.randn(n, 1),
                 "done": torch.zeros(n, 1, dtype=torch.bool), "terminated": torch.zeros(n, 1, dtype=torch.bool)},
    }, batch_size=[n])
    params = loss.value_network_params if name == "ddpg" else loss.qvalue_network_params
    opt = torch.optim.Adam(list(params.flatten_keys().values()), lr=1e-3)
    first = float(loss(batch)[keys[1]])
    for _ in range(30):
        opt.zero_grad()
        loss(batch)[keys[1]].backward()
        opt.step()
        updater.step()
    assert float(loss(batch)[keys[1]]) < 0.5 * first


def test_noise_schedule_follows_matlab_variance_decay():
    cfg = AlgoConfig(noise_variance=0.5, noise_decay=1e-5, noise_variance_min=0.0)
    assert agents.noise_scale(cfg, 0) == 1.0
    # variance 0.5 * (1 - 1e-5)^k, so the std halves after ln(4) / 1e-5 ~ 138,629 steps
    assert agents.noise_scale(cfg, 138_629) == pytest.approx(0.5, rel=1e-3)
    floor = AlgoConfig(noise_variance=0.5, noise_decay=1e-5, noise_variance_min=0.05)
    assert agents.noise_scale(floor, 10_000_000) == pytest.approx(math.sqrt(0.1))


def test_exploration_modules_take_the_scale():
    """The scale written by set_noise_scale is the spread of the actions the policy explores with."""
    from tensordict import TensorDict

    for name in ("ddpg", "td3"):
        cfg = AlgoConfig(name=name)
        actor = agents.make_actor(cfg, 43, 10)
        explore = agents.make_exploration(cfg, actor, SPEC)
        spread = {}
        for scale in (0.1, 0.2):
            agents.set_noise_scale(explore, scale)
            td = TensorDict({"observation": torch.zeros(4000, 43), "is_init": torch.ones(4000, 1, dtype=torch.bool)},
                            [4000])
            with torch.no_grad():
                deviation = explore(td.clone())["action"] - actor(td.clone())["action"]
            spread[scale] = float(deviation.std())
        assert spread[0.1] > 0.01, name
        assert spread[0.2] / spread[0.1] == pytest.approx(2.0, rel=0.1), name


def test_bad_algo_values():
    with pytest.raises(ConfigError, match="name"):
        AlgoConfig(name="ppo")
    with pytest.raises(ConfigError, match="batch_size"):
        AlgoConfig(batch_size=-128)
