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


class Learner:
    """Everything that learns, for any algorithm: networks, exploration, loss, targets, optimisers.

    ``update(sample)`` is one gradient step of the critic and, every ``actor_update_every``
    steps, of the actor and the target networks; the DDPG/TD3 differences stay in
    :func:`make_learner`.
    """

    def __init__(self, cfg: AlgoConfig, actor, critic, explore, loss, updater, critic_params, actor_params):
        self.cfg = cfg
        self.actor, self.critic, self.explore = actor, critic, explore
        self.loss, self.updater = loss, updater
        self.critic_loss_fn, self.actor_loss_fn = loss_parts(loss)
        self.critic_params, self.actor_params = critic_params, actor_params
        self.critic_opt = torch.optim.Adam(critic_params, lr=cfg.critic_lr)
        self.actor_opt = torch.optim.Adam(actor_params, lr=cfg.actor_lr)
        self.updates = 0
        # The last losses, for logging; the actor's is set only on actor updates (TD3: every 2nd),
        # so a run resumed between two of them has none yet.
        self._actor_loss: torch.Tensor | None = None
        self._critic_loss: torch.Tensor | None = None

    def update(self, sample) -> None:
        # Critic and actor losses separately (as TorchRL's sota scripts): computing only what
        # each step needs is ~1.5x faster than the full loss forward.
        critic_loss = self.critic_loss_fn(sample)[0]
        self.critic_opt.zero_grad()
        critic_loss.backward()
        nn.utils.clip_grad_norm_(self.critic_params, self.cfg.grad_clip)
        self.critic_opt.step()
        if self.updates % self.cfg.actor_update_every == 0:
            actor_loss = self.actor_loss_fn(sample)[0]
            self.actor_opt.zero_grad()
            actor_loss.backward()
            nn.utils.clip_grad_norm_(self.actor_params, self.cfg.grad_clip)
            self.actor_opt.step()
            self.updater.step()
            self._actor_loss = actor_loss
        self.updates += 1
        self._critic_loss = critic_loss

    def losses(self) -> tuple[float, float]:
        """The last (actor, critic) losses, for logging (nan where there is none yet)."""
        return tuple(math.nan if t is None else t.item() for t in (self._actor_loss, self._critic_loss))

    def q0(self, observations: torch.Tensor) -> list[float]:
        """Q(s, pi(s)) of each observation: the thesis' Q0 curve at episode starts (Fig. 10.24)."""
        with torch.no_grad():
            return self.critic.module(observations, self.actor.module(observations)).reshape(-1).tolist()

    def state_dict(self) -> dict:
        return {"loss": self.loss.state_dict(), "actor_opt": self.actor_opt.state_dict(),
                "critic_opt": self.critic_opt.state_dict()}

    def load_state_dict(self, state: dict, updates: int) -> None:
        self.loss.load_state_dict(state["loss"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.updates = updates


def make_learner(cfg: AlgoConfig, obs_size: int, action_size: int, action_spec) -> Learner:
    """The learner of ``cfg.name`` for an env with these sizes and action spec."""
    actor = make_actor(cfg, obs_size, action_size)
    critic = make_critic(cfg, obs_size, action_size)
    explore = make_exploration(cfg, actor, action_spec)
    loss, updater, _ = make_loss(cfg, actor, critic, action_spec)
    critic_net = loss.value_network_params if cfg.name == "ddpg" else loss.qvalue_network_params
    return Learner(cfg, actor, critic, explore, loss, updater,
                   critic_params=list(critic_net.flatten_keys().values()),
                   actor_params=list(loss.actor_network_params.flatten_keys().values()))
