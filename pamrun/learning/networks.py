"""Actor, critic, losses and exploration of DDPG and TD3, from TorchRL parts (thesis §9.3, 9.5).

* Actor (Table 9.1): 43 -> FC400 -> ReLU -> FC300 -> ReLU -> FC10 -> tanh.
* Critic (Table 9.2): observation path 43 -> FC400 -> ReLU -> FC300; action path
  10 -> FC300; the two added -> ReLU -> FC1.
* ``ddpg``: the loss of TorchRL's ``DDPGLoss`` with TorchRL's Ornstein-Uhlenbeck exploration,
  whose variance starts at 0.5 and decays by 1e-5 per step (Table 9.4, as MATLAB's
  ``VarianceDecayRate``).
* ``td3``: the loss of ``TD3Loss`` (twin critics, target policy smoothing) with delayed
  actor updates and Gaussian exploration, the thesis' proposed next step (§13); with
  ``algo.noise_beta`` the Gaussian is colored over time (:mod:`pamrun.learning.exploration`).

The losses are computed on plain tensors by :class:`Learner` (checked against TorchRL's).

Output layers start uniform in +-3e-3 (the MathWorks example uses 5e-3; DDPG's paper 3e-3).
"""

from __future__ import annotations

import copy
import math

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.modules import BatchRenorm1d, TanhNormal

from pamrun.config import AlgoConfig
from pamrun.learning.exploration import make_exploration

ALGOS = ("ddpg", "td3", "sac")


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


class SquashedGaussianActor(ThesisActor):
    """SAC's policy on the thesis' actor: tanh(N(mu(s), sigma(s))), mu from Table 9.1's network
    without its tanh, log sigma from a linear head on its last hidden layer.

    ``forward`` is the deterministic policy tanh(mu(s)), the part an agent file stores
    (:meth:`Learner.policy_state`), so ``pamrun eval`` runs a SAC agent like any other."""

    LOG_STD_RANGE = (-5.0, 2.0)  # clamp of log sigma (as CleanRL's SAC)

    def __init__(self, obs_size: int, action_size: int, hidden: tuple[int, int], init_scale: float):
        super().__init__(obs_size, action_size, hidden, init_scale)
        self.log_std_head = nn.Linear(hidden[1], action_size)

    def sample(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """A reparametrised action and its log-probability (with tanh's change of variables):
        TorchRL's ``TanhNormal``, scored at the pre-tanh sample (``rsample_and_log_prob``), not
        at atanh(action), which is lost once tanh saturates."""
        h = self.net[:4](observation)
        log_std = self.log_std_head(h).clamp(*self.LOG_STD_RANGE)
        # safe_tanh=False: TorchRL's default clamps |a| to 1 - 1e-6 (saturated actions move by 1e-6)
        dist = TanhNormal(self.net[4](h), log_std.exp(), event_dims=1, safe_tanh=False)
        action, log_prob = dist.rsample_and_log_prob()  # SAC updates ~5-9 % slower than by hand (benchmarks/)
        return action, log_prob.unsqueeze(-1)

    def sample_by_hand(self, observation: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`sample` written out, the reference it is tested and benchmarked against:
        u = mean + std * noise, a = tanh(u), log N(u; mean, std) - log(1 - tanh(u)^2) in softplus
        form, summed per action. Same actions from the same generator state."""
        h = self.net[:4](observation)
        mean = self.net[4](h)
        log_std = self.log_std_head(h).clamp(*self.LOG_STD_RANGE)
        u = mean + log_std.exp() * torch.randn_like(mean)
        log_prob = (-0.5 * ((u - mean) / log_std.exp()) ** 2 - log_std - 0.5 * math.log(2 * math.pi)
                    - 2.0 * (math.log(2.0) - u - nn.functional.softplus(-2.0 * u)))
        return torch.tanh(u), log_prob.sum(-1, keepdim=True)


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


class ConcatCritic(nn.Module):
    """Q(observation, action) with both concatenated at the input, then two hidden layers
    (Fujimoto et al.'s TD3, CleanRL): Q is nonlinear in the action through both layers, where
    Table 9.2's critic adds the action after the first and is piecewise linear in it through
    one ReLU layer, whose maximum over the action box tends to lie at a corner."""

    def __init__(self, obs_size: int, action_size: int, hidden: tuple[int, int], init_scale: float):
        super().__init__()
        self.net = nn.Sequential(nn.Linear(obs_size + action_size, hidden[0]), nn.ReLU(),
                                 nn.Linear(hidden[0], hidden[1]), nn.ReLU(), nn.Linear(hidden[1], 1))
        nn.init.uniform_(self.net[4].weight, -init_scale, init_scale)
        nn.init.uniform_(self.net[4].bias, -init_scale, init_scale)

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([observation, action], dim=-1))


class BatchRenorm(BatchRenorm1d):
    """TorchRL's ``BatchRenorm1d`` (Ioffe 2017) on a (batch, features) input, with two changes:
    - its count of training batches stops at ``warmup_steps``: TorchRL 0.14.1 caps it with
      ``clamp_max``, which is not in place, so its warm-up factor ``count // warmup_steps`` goes
      on past 1 (r - 1 and d doubled after twice the warm-up, tripled after three times);
    - the batch's mean and variance in one pass and the normalisation folded into one scale and
      shift per feature (the same numbers to rounding): TorchRL's five passes over the batch made
      CrossQ's update 1.8 times as slow as TD3's on 2 CPU cores (benchmarks/update_levers.py)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training:
            scale = self.weight / (self.running_var + self.eps).sqrt()
            return torch.addcmul(self.bias - self.running_mean * scale, x, scale)
        b_var, b_mean = torch.var_mean(x, dim=0, correction=0)
        b_std = (b_var + self.eps).sqrt()
        with torch.no_grad():
            running_std = (self.running_var + self.eps).sqrt()
            warm = 1.0 if self.warmup_steps == 0 else float(self.num_batches_tracked >= self.warmup_steps)
            r = 1.0 + (torch.clamp(b_std / running_std, 1 / self.max_r, self.max_r) - 1.0) * warm
            d = torch.clamp((b_mean - self.running_mean) / running_std, -self.max_d, self.max_d) * warm
            self.running_var += self.momentum * (b_var * x.shape[0] / (x.shape[0] - 1) - self.running_var)
            self.running_mean += self.momentum * (b_mean - self.running_mean)
            self.num_batches_tracked.add_(1).clamp_(max=self.warmup_steps)
        scale = self.weight * r / b_std  # y = w ((x - mean) r / std + d) + b
        return torch.addcmul(self.bias + self.weight * d - b_mean * scale, x, scale)


class CrossQCritic(nn.Module):
    """CrossQ's critic (Bhatt, Palenicek et al. 2024; as SBX's): the concatenated observation and
    action batch-renormalised, then two hidden layers, each ReLU followed by batch renormalisation
    (TorchRL's momentum 0.01, i.e. the paper's 0.99 in Flax's convention), then Q. In training mode
    it normalises with the batch's statistics (after the warm-up, renormalised towards the running
    ones) and moves the running ones; in eval mode it uses the running ones."""

    def __init__(self, obs_size: int, action_size: int, hidden: tuple[int, int], init_scale: float,
                 warmup_updates: int):
        super().__init__()
        def norm(n):
            return BatchRenorm(n, warmup_steps=warmup_updates)
        self.net = nn.Sequential(norm(obs_size + action_size),
                                 nn.Linear(obs_size + action_size, hidden[0]), nn.ReLU(), norm(hidden[0]),
                                 nn.Linear(hidden[0], hidden[1]), nn.ReLU(), norm(hidden[1]), nn.Linear(hidden[1], 1))
        nn.init.uniform_(self.net[-1].weight, -init_scale, init_scale)
        nn.init.uniform_(self.net[-1].bias, -init_scale, init_scale)

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        return self.net(torch.cat([observation, action], dim=-1))


def make_actor(cfg: AlgoConfig, obs_size: int, action_size: int) -> TensorDictModule:
    cls = SquashedGaussianActor if cfg.name == "sac" else ThesisActor
    net = cls(obs_size, action_size, tuple(cfg.hidden_sizes), cfg.output_init_scale)
    return TensorDictModule(net, in_keys=["observation"], out_keys=["action"])


def make_critic(cfg: AlgoConfig, obs_size: int, action_size: int) -> nn.Module:
    if cfg.crossq:
        return CrossQCritic(obs_size, action_size, tuple(cfg.hidden_sizes), cfg.output_init_scale,
                            cfg.renorm_warmup_updates)
    cls = ConcatCritic if cfg.critic == "concat" else ThesisCritic
    return cls(obs_size, action_size, tuple(cfg.hidden_sizes), cfg.output_init_scale)


class Learner:
    """DDPG's learner, and the base of every algorithm's: networks, targets, exploration, optimisers.

    ``update(sample)`` is one gradient step of the critic(s) and, every
    ``actor_update_every`` steps, of the actor and a soft update of every target network.
    It computes exactly what TorchRL's ``DDPGLoss`` (``ddpg``) and ``TD3Loss`` (``td3``,
    :class:`TD3Learner`) do with ``delay_actor=delay_value=True`` and a TD(0) target (a test
    checks loss values and gradients against them), but on plain tensors: on 2 CPU cores
    the losses' TensorDict and vmap plumbing costs a third of an update
    (benchmarks/train_throughput.py).

    * critic target: y = r + gamma (1 - terminated) min_k Q'_k(s', a'), with a' = pi'(s')
      (:meth:`next_action`; TD3 adds its target policy smoothing);
    * critic loss: sum over the critics of mean(loss_function(Q_k(s, a), y));
    * actor loss: -mean(Q_1(s, pi(s))), plus ``algo.mirror_loss`` x :meth:`mirror_loss` when the
      learner has the mirror maps (``mirror``: observation index and sign, action index and sign), plus
      ``anchor_weight`` x :meth:`anchor_loss` when it started from a trained actor (:meth:`start_from`;
      the weight ``algo.anchor``, or less as it fades: :func:`anchor_weight`, set by the trainer);
    * targets: theta' <- theta' + tau (theta - theta') (TorchRL's ``SoftUpdate``).

    With ``algo.crossq`` (:class:`CrossQCritic`) there are no targets: a' = pi(s') from the actor
    itself, and Q_k(s, a) and Q_k(s', a') come from one forward pass of the two batches stacked, y
    from the latter with its gradient stopped; the actor's Q comes from the critics in eval mode
    (their running statistics).

    An algorithm is a subclass that overrides :meth:`next_action`, :meth:`actor_loss` or
    :meth:`after_actor_step` (``LEARNERS`` maps ``algo.name`` to it).
    """

    follows_actor_target = True  # the actor has a target network that follows it

    def __init__(self, cfg: AlgoConfig, obs_size: int, action_size: int, action_spec, mirror=None,
                 colored_noise: bool = False):
        self.cfg = cfg
        self.mirror = None if mirror is None else tuple(torch.as_tensor(m) for m in mirror)
        self.actor = make_actor(cfg, obs_size, action_size)  # a TensorDictModule, for the collector
        self.critics = nn.ModuleList(make_critic(cfg, obs_size, action_size) for _ in range(n_critics(cfg)))
        self.actor_target = copy.deepcopy(self.actor.module).requires_grad_(False)  # unused by SAC and CrossQ
        self.critic_targets = nn.ModuleList() if cfg.crossq else copy.deepcopy(self.critics).requires_grad_(False)
        self.bootstrap = self.actor.module if cfg.crossq else self.actor_target  # the pi' of a' = pi'(s')
        self.explore = make_exploration(cfg, self.actor, action_spec, colored_noise)
        self.low, self.high = action_spec.space.low, action_spec.space.high
        self.critic_params = list(self.critics.parameters())
        self.actor_params = list(self.actor.module.parameters())
        # fused: one kernel per step for all parameters, ~15 % faster updates on 2 CPU cores
        betas = (cfg.adam_beta1, 0.999)
        self.critic_opt = torch.optim.Adam(self.critic_params, lr=cfg.critic_lr, betas=betas, fused=True)
        self.actor_opt = torch.optim.Adam(self.actor_params, lr=cfg.actor_lr, betas=betas, fused=True)
        self._pairs = [] if cfg.crossq else [(list(self.critic_targets.parameters()), self.critic_params)]
        if self.follows_actor_target and not cfg.crossq:
            self._pairs.append((list(self.actor_target.parameters()), self.actor_params))
        self._distance = {"l2": nn.functional.mse_loss, "l1": nn.functional.l1_loss,
                          "smooth_l1": nn.functional.smooth_l1_loss}[cfg.loss_function]
        self.updates = 0
        # The last losses, for logging; the actor's is set only on actor updates (TD3: every 2nd),
        # so a run resumed between two of them has none yet.
        self._actor_loss: torch.Tensor | None = None
        self._mirror_residual: torch.Tensor | None = None
        self._critic_loss: torch.Tensor | None = None
        self.anchor_actor: nn.Module | None = None  # pi_0 of algo.anchor: the actor start_from took, frozen
        self._q_scale = torch.tensor(0.0)  # the last actor loss's mean |Q|, the anchor's scale
        self.anchor_weight = cfg.anchor  # the anchor's weight now (anchor_weight: it may fade)

    def next_action(self, next_obs, action) -> tuple[torch.Tensor, torch.Tensor | float]:
        """The bootstrap action a' and what the target subtracts from min_k Q'_k(s', a')."""
        return self.bootstrap(next_obs), 0.0

    def critic_loss(self, obs, action, reward, next_obs, terminated) -> torch.Tensor:
        if self.cfg.crossq:
            return self.joint_critic_loss(obs, action, reward, next_obs, terminated)
        with torch.no_grad():
            next_action, correction = self.next_action(next_obs, action)
            next_q = self.critic_targets[0](next_obs, next_action)
            for target in self.critic_targets[1:]:
                next_q = torch.min(next_q, target(next_obs, next_action))
            y = reward + self.cfg.gamma * (~terminated) * (next_q - correction)
        return sum(self._distance(critic(obs, action), y) for critic in self.critics)

    def joint_critic_loss(self, obs, action, reward, next_obs, terminated) -> torch.Tensor:
        """CrossQ's critic loss: Q_k(s, a) and Q_k(s', a') from one pass, no targets."""
        with torch.no_grad():
            next_action, correction = self.next_action(next_obs, action)
        n = obs.shape[0]
        qs = [critic(torch.cat([obs, next_obs]), torch.cat([action, next_action])) for critic in self.critics]
        next_q = torch.stack([q[n:] for q in qs]).min(dim=0).values.detach()
        y = reward + self.cfg.gamma * (~terminated) * (next_q - correction)
        return sum(self._distance(q[:n], y) for q in qs)

    def actor_loss(self, obs) -> torch.Tensor:
        q = self.critics[0](obs, self.actor.module(obs))
        self._q_scale = q.detach().abs().mean()
        return -q.mean()

    def anchor_loss(self, obs) -> torch.Tensor:
        """mean|Q| x mean ||pi(s) - pi_0(s)||^2 over the batch and the actions, pi_0 the actor the run
        started from: 0 while the actor stays where it started (TD3+BC's behaviour term, with pi_0's
        action in place of the data's; mean|Q| from the :meth:`actor_loss` just computed)."""
        with torch.no_grad():
            start = self.anchor_actor(obs)
        return self._q_scale * (self.actor.module(obs) - start).pow(2).mean()

    def mirror_residual(self, obs) -> torch.Tensor:
        """mean ||pi(s) - M_a pi(M_s s)||^2 over the batch and the actions: 0 for a policy that is its
        own mirror image (Yu, Turk & Liu 2018)."""
        o_index, o_sign, a_index, a_sign = self.mirror
        action = self.actor.module(obs)
        mirrored = self.actor.module(obs[..., o_index] * o_sign.to(obs.dtype))
        return (action - mirrored[..., a_index] * a_sign.to(obs.dtype)).pow(2).mean()

    def mirror_loss(self, obs) -> torch.Tensor:
        """mean|Q| x :meth:`mirror_residual`, scaled as :meth:`anchor_loss` (mean|Q| from the
        :meth:`actor_loss` just computed); the residual is kept for TensorBoard's loss/mirror."""
        residual = self.mirror_residual(obs)
        self._mirror_residual = residual.detach()
        return self._q_scale * residual

    def after_actor_step(self) -> None:
        """What follows each actor step, before the targets' soft update (SAC: its temperature)."""

    def update(self, sample, actor: bool = True) -> None:
        """One update on a replay sample (a TensorDict with TorchRL's transition keys); with
        ``actor=False`` only the critics learn (the targets follow on the actor's schedule)."""
        obs, action = sample["observation"], sample["action"]
        nxt = sample["next"]
        critic_loss = self.critic_loss(obs, action, nxt["reward"], nxt["observation"], nxt["terminated"])
        self.critic_opt.zero_grad()
        critic_loss.backward()
        nn.utils.clip_grad_norm_(self.critic_params, self.cfg.grad_clip)
        self.critic_opt.step()
        if self.updates % self.cfg.actor_update_every == 0 and not actor:
            self.soft_update()
        elif self.updates % self.cfg.actor_update_every == 0:
            for p in self.critic_params:  # the actor's gradient must not touch the critic
                p.requires_grad_(False)
            self.critics.eval()  # (CrossQ's: Q from the running statistics, which stay as they are)
            actor_loss = self.actor_loss(obs)
            if self.mirror is not None and self.cfg.mirror_loss:
                actor_loss = actor_loss + self.cfg.mirror_loss * self.mirror_loss(obs)
            if self.anchor_actor is not None and self.anchor_weight:
                actor_loss = actor_loss + self.anchor_weight * self.anchor_loss(obs)
            self.actor_opt.zero_grad()
            actor_loss.backward()
            self.critics.train()
            for p in self.critic_params:
                p.requires_grad_(True)
            nn.utils.clip_grad_norm_(self.actor_params, self.cfg.grad_clip)
            self.actor_opt.step()
            self.after_actor_step()
            self.soft_update()
            self._actor_loss = actor_loss.detach()
        self.updates += 1
        self._critic_loss = critic_loss.detach()

    @torch.no_grad()
    def soft_update(self) -> None:
        """theta' <- theta' + tau (theta - theta'), one ``lerp_`` per tensor: the numbers of
        ``torch._foreach_lerp_`` (benchmarks/agent_update.py). TorchRL's ``SoftUpdate`` does the
        same lerp_ but needs a ``LossModule``'s target parameters, which the Learner does not hold."""
        tau = self.cfg.target_smoothing
        for targets, params in self._pairs:
            for target, param in zip(targets, params):
                target.lerp_(param, tau)

    def losses(self) -> dict[str, float]:
        """The last losses for logging, by name: actor, critic and, with ``algo.mirror_loss``, the
        actor's unscaled mean squared mirror residual (nan where there is none yet)."""
        values = {"actor": self._actor_loss, "critic": self._critic_loss}
        if self.mirror is not None and self.cfg.mirror_loss:
            values["mirror"] = self._mirror_residual
        return {name: math.nan if t is None else t.item() for name, t in values.items()}

    def q0(self, observations: torch.Tensor) -> list[float]:
        """Q(s, pi(s)) of each observation: the thesis' Q0 curve at episode starts (Fig. 10.24)."""
        self.critics.eval()
        with torch.no_grad():
            q = self.critics[0](observations, self.actor.module(observations)).reshape(-1).tolist()
        self.critics.train()
        return q

    def policy_state(self) -> dict:
        """The deterministic policy's weights (thesis Table 9.1's actor): what an agent file holds."""
        return {k: v for k, v in self.actor.module.state_dict().items() if k.startswith("net.")}

    def parameters(self) -> list[torch.Tensor]:
        """Every learned or target tensor (what a checkpoint writes, with two Adam moments each)."""
        return [*self.actor_params, *self.critic_params, *self.actor_target.parameters(),
                *self.critic_targets.parameters()]

    def state_dict(self) -> dict:
        return {"networks": {"actor": self.actor.module.state_dict(), "critics": self.critics.state_dict(),
                             "actor_target": self.actor_target.state_dict(),
                             "critic_targets": self.critic_targets.state_dict(),
                             **({} if self.anchor_actor is None else {"anchor_actor": self.anchor_actor.state_dict()})},
                "actor_opt": self.actor_opt.state_dict(), "critic_opt": self.critic_opt.state_dict()}

    def start_from(self, state: dict) -> str:
        """Take a trained agent's networks (``train.init_from``): a resume state's (``last.pt``)
        actor, critics and their targets, or an agent file's actor (its target a copy, the critics
        new). The optimisers and the update count start afresh. Returns what it took, in words."""
        nets = state.get("networks")
        if nets is None:
            self.actor.module.load_state_dict(state["actor"], strict=False)  # net.*: a SAC actor's head stays new
            self.actor_target.load_state_dict(self.actor.module.state_dict())
            took = "the actor (the critics learn from new)"
        else:
            self.actor.module.load_state_dict(nets["actor"])
            self.actor_target.load_state_dict(nets["actor_target"])
            self.critics.load_state_dict(nets["critics"])
            self.critic_targets.load_state_dict(nets["critic_targets"])
            took = "the actor, the critics and their targets"
        if self.cfg.anchor:
            self.anchor_actor = copy.deepcopy(self.actor.module).requires_grad_(False)
            took += f", the actor anchored where it starts (algo.anchor {self.cfg.anchor:g}"
            if self.cfg.anchor_fade_frames:
                start, fade = self.cfg.anchor_fade_start_frames, self.cfg.anchor_fade_frames
                took += f", fading to 0 from {start:,} to {start + fade:,} frames"
            took += ")"
        return took

    def load_state_dict(self, state: dict, updates: int) -> None:
        if "networks" not in state:
            raise ValueError("resume state of an earlier pamrun (TorchRL loss state): continue it with the pamrun that wrote it")
        nets = state["networks"]
        self.actor.module.load_state_dict(nets["actor"])
        self.critics.load_state_dict(nets["critics"])
        self.actor_target.load_state_dict(nets["actor_target"])
        self.critic_targets.load_state_dict(nets["critic_targets"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.updates = updates
        if "anchor_actor" in nets:
            self.anchor_actor = copy.deepcopy(self.actor.module).requires_grad_(False)
            self.anchor_actor.load_state_dict(nets["anchor_actor"])
        elif self.cfg.anchor:
            raise ValueError("algo.anchor: this resume state holds no actor to anchor to")


class TD3Learner(Learner):
    """TD3 (Fujimoto et al. 2018): twin critics (``n_critics``), delayed actor updates
    (``algo.actor_update_every``) and target policy smoothing:
    a' = clamp(pi'(s') + clamp(N(0, policy_noise), +-noise_clip)) inside the action box."""

    def next_action(self, next_obs, action):
        cfg = self.cfg
        noise = (torch.randn_like(action) * cfg.policy_noise).clamp(-cfg.noise_clip, cfg.noise_clip)
        return torch.max(torch.min(self.bootstrap(next_obs) + noise, self.high), self.low), 0.0


class SACLearner(Learner):
    """SAC (Haarnoja et al. 2018, as CleanRL's ``sac_continuous_action.py``): twin critics,
    a' ~ pi(s') and y = r + gamma (1 - terminated) (min_k Q'_k(s', a') - alpha log pi(a'|s'));
    actor loss mean(alpha log pi(a|s) - min_k Q_k(s, a)) with a ~ pi(s) reparametrised;
    alpha learned towards an entropy of ``target_entropy`` per action. Its tanh change of
    variables makes saturated actions improbable, where a deterministic actor drifts into
    full-band commands. It bootstraps from its current actor: no actor target follows."""

    follows_actor_target = False

    def __init__(self, cfg: AlgoConfig, obs_size: int, action_size: int, action_spec, mirror=None,
                 colored_noise: bool = False):
        super().__init__(cfg, obs_size, action_size, action_spec, mirror, colored_noise)
        self.log_alpha = torch.tensor(math.log(cfg.init_alpha), requires_grad=True)  # the temperature
        self.alpha_opt = torch.optim.Adam([self.log_alpha], lr=cfg.actor_lr, betas=(cfg.adam_beta1, 0.999))
        self.target_entropy = cfg.target_entropy * action_size

    def next_action(self, next_obs, action):
        next_action, next_log_prob = self.actor.module.sample(next_obs)
        return next_action, self.log_alpha.exp() * next_log_prob

    def actor_loss(self, obs) -> torch.Tensor:
        action, log_prob = self.actor.module.sample(obs)
        q = torch.min(self.critics[0](obs, action), self.critics[1](obs, action))
        self._log_prob = log_prob.detach()
        self._q_scale = q.detach().abs().mean()
        return (self.log_alpha.exp().detach() * log_prob - q).mean()

    def after_actor_step(self) -> None:
        """Move alpha so that the policy's entropy approaches the target."""
        loss = -(self.log_alpha * (self._log_prob + self.target_entropy)).mean()
        self.alpha_opt.zero_grad()
        loss.backward()
        self.alpha_opt.step()

    def state_dict(self) -> dict:
        return {**super().state_dict(), "log_alpha": self.log_alpha.detach().clone(),
                "alpha_opt": self.alpha_opt.state_dict()}

    def load_state_dict(self, state: dict, updates: int) -> None:
        super().load_state_dict(state, updates)
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])
        self.alpha_opt.load_state_dict(state["alpha_opt"])


LEARNERS = {"ddpg": Learner, "td3": TD3Learner, "sac": SACLearner}  # algo.name -> its learner


def anchor_weight(cfg: AlgoConfig, frames: int) -> float:
    """``algo.anchor``'s weight at a run's frame count: b until ``anchor_fade_start_frames``, then
    falling linearly to 0 over ``anchor_fade_frames`` (b all run when that is 0)."""
    if not cfg.anchor_fade_frames:
        return cfg.anchor
    left = 1.0 - (frames - cfg.anchor_fade_start_frames) / cfg.anchor_fade_frames
    return cfg.anchor * min(1.0, max(0.0, left))


def n_critics(cfg: AlgoConfig) -> int:
    """Critics the algorithm learns: one (DDPG) or the twin critics of TD3 and SAC."""
    return 1 if cfg.name == "ddpg" else 2


def make_learner(cfg: AlgoConfig, obs_size: int, action_size: int, action_spec, mirror=None,
                 colored_noise: bool = False) -> Learner:
    """The learner of ``cfg.name`` for an env with these sizes and action spec (``mirror``: the
    observation's and action's mirror maps, for ``algo.mirror_loss``; ``colored_noise``: TD3's
    exploration noise a :class:`ColoredNoiseModule` whatever ``algo.noise_beta``)."""
    return LEARNERS[cfg.name](cfg, obs_size, action_size, action_spec, mirror, colored_noise)
