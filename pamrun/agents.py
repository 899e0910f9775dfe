"""Actor, critic, losses and exploration of DDPG and TD3, from TorchRL parts (thesis §9.3, 9.5).

* Actor (Table 9.1): 43 -> FC400 -> ReLU -> FC300 -> ReLU -> FC10 -> tanh.
* Critic (Table 9.2): observation path 43 -> FC400 -> ReLU -> FC300; action path
  10 -> FC300; the two added -> ReLU -> FC1.
* ``ddpg``: TorchRL's ``DDPGLoss`` with Ornstein-Uhlenbeck exploration whose variance
  starts at 0.5 and decays by 1e-5 per step (Table 9.4, as MATLAB's ``VarianceDecayRate``).
* ``td3``: ``TD3Loss`` (twin critics, target policy smoothing) with delayed actor updates
  and Gaussian exploration, the thesis' proposed next step (§13).

Output layers start uniform in +-3e-3 (the MathWorks example uses 5e-3; DDPG's paper 3e-3).
"""

from __future__ import annotations

import math

import torch
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.modules import AdditiveGaussianModule, OrnsteinUhlenbeckProcessModule, ValueOperator
from torchrl.objectives import DDPGLoss, SoftUpdate, TD3Loss

from pamrun.config import AlgoConfig

ALGOS = ("ddpg", "td3")


class ThesisActor(nn.Module):
    """Table 9.1: observation -> action in [-1, 1]."""

    def __init__(self, obs_size: int, action_size: int, hidden: tuple[int, int], init_scale: float):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(obs_size, hidden[0]), nn.ReLU(),
            nn.Linear(hidden[0], hidden[1]), nn.ReLU(),
            nn.Linear(hidden[1], action_size), nn.Tanh(),
        )
        nn.init.uniform_(self.net[4].weight, -init_scale, init_scale)
        nn.init.uniform_(self.net[4].bias, -init_scale, init_scale)

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        return self.net(observation)


class ThesisCritic(nn.Module):
    """Table 9.2: Q(observation, action) with separate observation and action paths."""

    def __init__(self, obs_size: int, action_size: int, hidden: tuple[int, int], init_scale: float):
        super().__init__()
        self.obs_path = nn.Sequential(nn.Linear(obs_size, hidden[0]), nn.ReLU(), nn.Linear(hidden[0], hidden[1]))
        self.action_path = nn.Linear(action_size, hidden[1])
        self.head = nn.Sequential(nn.ReLU(), nn.Linear(hidden[1], 1))
        nn.init.uniform_(self.head[1].weight, -init_scale, init_scale)
        nn.init.uniform_(self.head[1].bias, -init_scale, init_scale)

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.head(self.obs_path(observation) + self.action_path(action))


def make_actor(cfg: AlgoConfig, obs_size: int, action_size: int) -> TensorDictModule:
    net = ThesisActor(obs_size, action_size, tuple(cfg.hidden_sizes), cfg.output_init_scale)
    return TensorDictModule(net, in_keys=["observation"], out_keys=["action"])


def make_critic(cfg: AlgoConfig, obs_size: int, action_size: int) -> ValueOperator:
    """A critic whose output key suits the algorithm's loss."""
    net = ThesisCritic(obs_size, action_size, tuple(cfg.hidden_sizes), cfg.output_init_scale)
    out_key = "state_action_value"
    return ValueOperator(net, in_keys=["observation", "action"], out_keys=[out_key])


def make_exploration(cfg: AlgoConfig, actor: TensorDictModule, action_spec) -> TensorDictSequential:
    """The actor followed by TorchRL's exploration noise module for this algorithm."""
    if cfg.name == "ddpg":
        noise = OrnsteinUhlenbeckProcessModule(
            spec=action_spec,
            sigma=math.sqrt(cfg.noise_variance),
            theta=cfg.ou_theta,
            dt=cfg.ou_dt_s,
            eps_init=1.0,
            eps_end=1.0,  # the decay is set by set_noise_scale (exponential, as MATLAB's)
        )
    else:
        noise = AdditiveGaussianModule(
            spec=action_spec, sigma_init=1.0, sigma_end=1.0, mean=0.0, std=math.sqrt(cfg.noise_variance)
        )
    return TensorDictSequential(actor, noise)


def noise_scale(cfg: AlgoConfig, frames: int) -> float:
    """Multiplier of the noise's standard deviation after ``frames`` steps.

    The variance decays as (1 - decay)^frames (MATLAB's VarianceDecayRate, Table 9.4) and
    never falls below ``noise_variance_min``.
    """
    variance = max(cfg.noise_variance * (1.0 - cfg.noise_decay) ** frames, cfg.noise_variance_min)
    return math.sqrt(variance / cfg.noise_variance)


def set_noise_scale(explore: TensorDictSequential, scale: float) -> None:
    """Write the noise multiplier into TorchRL's exploration module (its ``eps``/``sigma`` buffer)."""
    noise = explore.module[-1]
    if isinstance(noise, OrnsteinUhlenbeckProcessModule):
        noise.eps.fill_(scale)
    else:
        noise.sigma.fill_(scale)


def make_loss(cfg: AlgoConfig, actor: TensorDictModule, critic: ValueOperator, action_spec):
    """TorchRL loss, target updater and the loss keys of the actor and critic."""
    if cfg.name == "ddpg":
        loss = DDPGLoss(actor, critic, loss_function=cfg.loss_function, delay_actor=True, delay_value=True)
        keys = ("loss_actor", "loss_value")
    else:
        loss = TD3Loss(
            actor, critic, action_spec=action_spec, num_qvalue_nets=2, policy_noise=cfg.policy_noise,
            noise_clip=cfg.noise_clip, loss_function=cfg.loss_function, delay_actor=True, delay_qvalue=True,
        )
        keys = ("loss_actor", "loss_qvalue")
    loss.make_value_estimator(gamma=cfg.gamma)
    updater = SoftUpdate(loss, tau=cfg.target_smoothing)
    return loss, updater, keys


def loss_parts(loss):
    """The critic and actor halves of a TorchRL loss, each returning (loss, metadata)."""
    if isinstance(loss, TD3Loss):
        return loss.value_loss, loss.actor_loss
    return loss.loss_value, loss.loss_actor
