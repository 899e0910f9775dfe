"""What would make the walking recipe's learner update cheaper: each lever against the update as shipped.

    python benchmarks/update_levers.py [--updates 200] [--repeats 5] [--threads 2]

The shipped update is the walking recipe's (experiment=command: TD3, the concatenating critic,
400/300, batch 128, the mirror loss weighed 0.6 x mean|Q|, the actor every 2nd update) on the command
recipe's observation (speed command and gait clock) and 10 actions. Each lever is timed against a
fresh shipped learner in alternating chunks of 10 updates (so load that comes and goes hits both
alike), ``--repeats`` times:

1. ``stacked``: the twin critics and their targets as one stacked network, one batched matmul per
   layer for both (the first layer one matmul of the shared input), written inline here: the
   same numbers in another order of operations;
2. ``compiled``: ``torch.compile`` of the critic loss (inductor, C++ on CPU);
3. ``hidden_256``: both networks 256/256 instead of the thesis' 400/300 (a change of the
   learner, not of its speed alone);
4. ``batch_256_half``: batch 256 at one update every 2nd frame: the same samples per frame in
   half the updates (also a change of the learner); its rate is reported per frame, i.e. twice
   its updates/s;
5. ``crossq``: ``algo.crossq`` with the paper's actor every 3rd update and Adam beta1 0.5
   (batch-renormalised critics, no targets, one pass of both batches; a change of the learner).

It prints each lever's rate and the shipped one's (updates per second, or frames per second of
updates for ``batch_256_half``), min / median / max and the ratio of the medians, and appends them
to benchmarks/results/update_levers.jsonl. The result moves with the machine: a lever that pays
where updates are bound by kernel launches may not where they are bound by the matmuls.
"""

from __future__ import annotations

import argparse
import copy
import math
import statistics
import time
from pathlib import Path

import torch
from tensordict import TensorDict
from torch import nn
from torchrl.data import Bounded
from train_throughput import machine_stamp, report, spread  # the sibling benchmark's summary

from pamrun.config import AlgoConfig
from pamrun.learning import networks
from pamrun.task.observation import obs_size, observation_structure
from pamrun.task.symmetry import action_map, observation_map

ACT = 10
OBS = obs_size(observation_structure(ACT, speed_command=True, gait_clock=True))
WALKING = {"name": "td3", "critic": "concat", "target_smoothing": 0.005, "critic_lr": 1e-3, "actor_update_every": 2,
           "mirror_loss": 0.6}  # conf/algo/td3.yaml with conf/experiment/walk.yaml's and gait.yaml's changes
RESULTS = Path(__file__).parent / "results" / "update_levers.jsonl"


def _batch(size: int) -> TensorDict:
    return TensorDict({"observation": torch.randn(size, OBS), "action": torch.rand(size, ACT) * 2 - 1,
                       "next": {"observation": torch.randn(size, OBS), "reward": torch.randn(size, 1),
                                "done": torch.zeros(size, 1, dtype=torch.bool),
                                "terminated": torch.zeros(size, 1, dtype=torch.bool)}}, [size])


def _learner(**changes) -> networks.Learner:
    mirror = (*observation_map(ACT, True, True), *action_map(ACT))
    spec = Bounded(-torch.ones(ACT), torch.ones(ACT), (ACT,))
    return networks.make_learner(AlgoConfig(**{**WALKING, **changes}), OBS, ACT, spec, mirror)


class StackedCritics(nn.Module):
    """K concatenating critics (``networks.ConcatCritic``) as stacked weights: Q_k for every k at once."""

    def __init__(self, critics: nn.ModuleList):
        super().__init__()
        layers = [[c.net[i] for c in critics] for i in (0, 2, 4)]
        self.k, self.h0 = len(critics), layers[0][0].out_features
        # the first layer's input is shared: its K weight matrices side by side, one matmul
        self.w0 = nn.Parameter(torch.cat([m.weight.T for m in layers[0]], dim=1).detach().clone())
        self.b0 = nn.Parameter(torch.cat([m.bias for m in layers[0]]).detach().clone())
        self.w = nn.ParameterList(nn.Parameter(torch.stack([m.weight.T for m in ms]).detach().clone()) for ms in layers[1:])
        self.b = nn.ParameterList(nn.Parameter(torch.stack([m.bias[None] for m in ms]).detach().clone()) for ms in layers[1:])

    def forward(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        x = torch.cat([observation, action], dim=-1)
        h = torch.relu(torch.addmm(self.b0, x, self.w0)).view(x.shape[0], self.k, self.h0).transpose(0, 1)
        h = torch.relu(torch.baddbmm(self.b[0], h, self.w[0]))
        return torch.baddbmm(self.b[1], h, self.w[1])  # (K, batch, 1)

    def first(self, observation: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        x = torch.cat([observation, action], dim=-1)
        h = torch.relu(torch.addmm(self.b0[:self.h0], x, self.w0[:, :self.h0]))
        h = torch.relu(torch.addmm(self.b[0][0, 0], h, self.w[0][0]))
        return torch.addmm(self.b[1][0, 0], h, self.w[1][0])


def _stacked() -> networks.Learner:
    """The shipped learner with its critics and targets stacked (the losses' numbers unchanged)."""
    learner = _learner()
    learner.critics = StackedCritics(learner.critics)
    learner.critic_targets = copy.deepcopy(learner.critics).requires_grad_(False)
    learner.critic_params = list(learner.critics.parameters())
    learner.critic_opt = torch.optim.Adam(learner.critic_params, lr=learner.cfg.critic_lr, fused=True)
    learner._pairs = [(list(learner.critic_targets.parameters()), learner.critic_params),
                      (list(learner.actor_target.parameters()), learner.actor_params)]

    def critic_loss(obs, action, reward, next_obs, terminated):
        with torch.no_grad():
            next_action, _ = learner.next_action(next_obs, action)
            next_q = learner.critic_targets(next_obs, next_action).min(dim=0).values
            y = reward + learner.cfg.gamma * (~terminated) * next_q
        return (learner.critics(obs, action) - y).pow(2).mean(dim=(1, 2)).sum()

    learner.critic_loss = critic_loss
    learner.actor_loss = lambda obs: -learner.critics.first(obs, learner.actor.module(obs)).mean()
    return learner


def _compiled() -> networks.Learner:
    learner = _learner()
    learner.critic_loss = torch.compile(learner.critic_loss)
    return learner


LEVERS = {  # name -> (a learner with the lever, its batch size, updates per frame)
    "stacked": (_stacked, 128, 1.0),
    "compiled": (_compiled, 128, 1.0),
    "hidden_256": (lambda: _learner(hidden_sizes=[256, 256]), 128, 1.0),
    "batch_256_half": (lambda: _learner(batch_size=256), 256, 0.5),
    "crossq": (lambda: _learner(crossq=True, actor_update_every=3, adam_beta1=0.5), 128, 1.0),
}


def paired_rates(make, size: int, per_frame: float, n: int, chunk: int = 10) -> tuple[float, float]:
    """The lever's and the shipped learner's rate (updates/s divided by ``per_frame``), timed in
    alternating chunks of ``chunk`` updates."""
    learners, batches = (make(), _learner()), (_batch(size), _batch(128))
    for learner, batch in zip(learners, batches):
        for _ in range(20):  # warm-up (and, for ``compiled``, the compilation)
            learner.update(batch)
    wall = [0.0, 0.0]
    for _ in range(n // chunk):
        for k, (learner, batch) in enumerate(zip(learners, batches)):
            start = time.perf_counter()
            for _ in range(chunk):
                learner.update(batch)
            wall[k] += time.perf_counter() - start
    done = n // chunk * chunk
    return done / wall[0] / per_frame, done / wall[1]


def stacked_matches() -> float:
    """Max abs difference of the stacked critics' loss from the shipped one on the same weights."""
    torch.manual_seed(0)
    shipped = _learner()
    stacked = copy.deepcopy(shipped)
    stacked.critics, stacked.critic_targets = StackedCritics(shipped.critics), StackedCritics(shipped.critic_targets)
    batch = _batch(128)
    nxt = batch["next"]
    args = (batch["observation"], batch["action"], nxt["reward"], nxt["observation"], nxt["terminated"])
    torch.manual_seed(1)
    ours = float(shipped.critic_loss(*args).detach())
    torch.manual_seed(1)
    with torch.no_grad():
        next_action, _ = stacked.next_action(args[3], args[1])
        y = args[2] + stacked.cfg.gamma * (~args[4]) * stacked.critic_targets(args[3], next_action).min(dim=0).values
        theirs = float((stacked.critics(args[0], args[1]) - y).pow(2).mean(dim=(1, 2)).sum())
    return abs(ours - theirs) / max(abs(ours), math.ulp(1.0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=0, help="torch threads; 0 = torch's default")
    parser.add_argument("--levers", nargs="*", default=list(LEVERS), choices=list(LEVERS))
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    runs: dict[str, list[float]] = {}
    for _ in range(args.repeats):
        for name in args.levers:
            lever, shipped = paired_rates(*LEVERS[name], args.updates)
            runs.setdefault(name, []).append(lever)
            runs.setdefault(f"{name}_shipped", []).append(shipped)
            print(f"{name:>16}: {lever:7.1f}   shipped {shipped:7.1f}   x{lever / shipped:.3f}", flush=True)
    row = {**machine_stamp(), "obs": OBS, "act": ACT, "updates": args.updates,
           **{k: spread(v) for k, v in runs.items()},
           "ratios_of_medians": {name: round(statistics.median(runs[name]) / statistics.median(runs[f"{name}_shipped"]), 3)
                                 for name in args.levers},
           "stacked_loss_rel_diff": stacked_matches()}
    report(row, runs, RESULTS, extra=("stacked_loss_rel_diff",))


if __name__ == "__main__":
    main()
