"""Exploration during collection: TorchRL's noise modules after the actor, their schedule and spectrum.

* ``ddpg``: TorchRL's Ornstein-Uhlenbeck process, variance 0.5 decaying by 1e-5 per step
  (thesis Table 9.4, as MATLAB's ``VarianceDecayRate``);
* ``td3``: TorchRL's additive Gaussian, or with ``algo.noise_beta`` (or ``train.walk_noise_beta``)
  the same Gaussian colored over time (pink: Eberhard et al., ICLR 2023);
* ``sac``: actions sampled from the actor's own distribution.
"""

from __future__ import annotations

import math

import torch
from tensordict.nn import TensorDictModule, TensorDictSequential
from torch import nn
from torchrl.modules import AdditiveGaussianModule, OrnsteinUhlenbeckProcessModule

from pamrun.config import AlgoConfig


class _Sampler(nn.Module):
    """The collector's SAC policy: an action sampled from the actor's distribution."""

    def __init__(self, actor: nn.Module):
        super().__init__()
        self.actor = actor

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            return self.actor.sample(observation)[0]


def make_exploration(cfg: AlgoConfig, actor: TensorDictModule, action_spec, colored: bool = False) -> TensorDictSequential:
    """The actor followed by TorchRL's exploration noise module for this algorithm (SAC: its own
    sampled actions); TD3's is a :class:`ColoredNoiseModule` with ``algo.noise_beta`` or ``colored``
    (its spectrum to change during the run: :func:`set_noise_beta`)."""
    if cfg.name == "sac":
        return TensorDictSequential(TensorDictModule(_Sampler(actor.module), in_keys=["observation"],
                                                     out_keys=["action"]))
    if cfg.name == "ddpg":
        noise = OrnsteinUhlenbeckProcessModule(
            spec=action_spec,
            sigma=math.sqrt(cfg.noise_variance),
            theta=cfg.ou_theta,
            dt=cfg.ou_dt_s,
            eps_init=1.0,
            eps_end=1.0,  # the decay is set by set_noise_scale (exponential, as MATLAB's)
        )
    elif cfg.noise_beta or colored:
        noise = ColoredNoiseModule(action_spec, math.sqrt(cfg.noise_variance), cfg.noise_beta, cfg.noise_chunk_steps)
    else:
        noise = AdditiveGaussianModule(
            spec=action_spec, sigma_init=1.0, sigma_end=1.0, mean=0.0, std=math.sqrt(cfg.noise_variance)
        )
    return TensorDictSequential(actor, noise)


def colored_noise(beta: float, steps: int, shape: tuple[int, ...]) -> torch.Tensor:
    """(steps, *shape) Gaussian series whose power spectrum along the first axis falls as 1/f^beta
    (0 white, 1 pink, 2 red), each scaled to unit RMS: random Fourier coefficients of amplitude
    f^(-beta/2), the lowest frequency standing in for f = 0 (Timmer & Koenig 1995)."""
    freqs = torch.fft.rfftfreq(steps)
    freqs[0] = freqs[1]
    amplitude = (freqs ** (-beta / 2)).reshape(-1, *(1,) * len(shape))
    coeffs = torch.complex(torch.randn(len(freqs), *shape), torch.randn(len(freqs), *shape)) * amplitude
    series = torch.fft.irfft(coeffs, n=steps, dim=0)
    return series / series.pow(2).mean(dim=0).sqrt()


class ColoredNoiseModule(AdditiveGaussianModule):
    """TD3's additive exploration noise, colored (``algo.noise_beta``): each action's noise is a
    :func:`colored_noise` series through a chunk of ``chunk_steps`` control steps, then a fresh
    chunk; its std and the ``sigma`` multiplier (:func:`set_noise_scale`) are the Gaussian's. ``beta``
    is a buffer, so a collector's workers take a change of it (:func:`set_noise_beta`) with the
    policy's weights; a chunk drawn at another beta is dropped."""

    def __init__(self, action_spec, std: float, beta: float, chunk_steps: int):
        super().__init__(spec=action_spec, sigma_init=1.0, sigma_end=1.0, mean=0.0, std=std)
        self.register_buffer("beta", torch.tensor(float(beta)))
        self.chunk_steps = chunk_steps
        self._chunk, self._next, self._chunk_beta = None, 0, float(beta)

    def _add_noise(self, action: torch.Tensor) -> torch.Tensor:
        beta = float(self.beta)
        if (self._chunk is None or self._next == self.chunk_steps or self._chunk.shape[1:] != action.shape
                or beta != self._chunk_beta):
            self._chunk, self._next, self._chunk_beta = colored_noise(beta, self.chunk_steps, tuple(action.shape)), 0, beta
        noise = self._chunk[self._next].to(action)
        self._next += 1
        return self.spec[self.action_key].project(action + noise * self.std * self.sigma)


def set_noise_beta(explore: TensorDictSequential, beta: float) -> None:
    """The exploration noise's spectrum from the next action on (1/f^beta): a
    :class:`ColoredNoiseModule` only (``make_exploration``'s ``colored``)."""
    explore.module[-1].beta.fill_(beta)


def noise_scale(cfg: AlgoConfig, frames: int) -> float:
    """Multiplier of the noise's standard deviation after ``frames`` steps.

    The variance decays as (1 - decay)^frames (MATLAB's VarianceDecayRate, Table 9.4) and
    never falls below ``noise_variance_min``.
    """
    variance = max(cfg.noise_variance * (1.0 - cfg.noise_decay) ** frames, cfg.noise_variance_min)
    return math.sqrt(variance / cfg.noise_variance)


def set_noise_scale(explore: TensorDictSequential, scale: float) -> None:
    """Write the noise multiplier into TorchRL's exploration module (its ``eps``/``sigma`` buffer);
    SAC's exploration is its own entropy-tuned spread, left alone."""
    noise = explore.module[-1]
    if isinstance(noise, OrnsteinUhlenbeckProcessModule):
        noise.eps.fill_(scale)
    elif isinstance(noise, AdditiveGaussianModule):
        noise.sigma.fill_(scale)
