"""Learner updates per second with TorchRL/torch public parts against the private/hand-written ones they replace.

    python benchmarks/agent_update.py [--updates 300] [--repeats 5] [--threads 1]

With the thesis' networks (AlgoConfig's 400/300) at batch 128, ``--repeats`` times with fresh
learners, each variant timed against its baseline in alternating chunks of 10 calls (so a
change of machine load hits both alike):
1. TD3's ``Learner.update`` (conf/algo/td3.yaml: tau 0.005, actor every 2nd update) with
   ``Learner.soft_update`` as shipped (one public ``Tensor.lerp_`` per tensor) and with the
   baseline it replaced, ``torch._foreach_lerp_`` over each target list (inline here);
2. the soft update alone (calls/s and microseconds per call), both ways;
3. SAC's update with ``SquashedGaussianActor.sample`` as shipped (TorchRL's ``TanhNormal``) and
   with the hand-written tanh-Gaussian it replaced (inline here).
It checks the numbers too: the TD3 targets after ``--updates`` updates from the same seed both
ways (max abs difference, bitwise equality), and SAC's actions and log-probabilities from the
same generator state with a third of the actions saturated. It prints min / median / max and
the ratios of the medians, and appends them to benchmarks/results/agent_update.jsonl.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import torch
import torchrl
from train_throughput import (  # the sibling benchmark's batch and summary
    ACT,
    BATCH,
    OBS,
    _batch,
    _spec,
    machine_stamp,
    report,
    spread,
)

from pamrun.config import AlgoConfig
from pamrun.learning import networks

TD3 = {"name": "td3", "target_smoothing": 0.005, "critic_lr": 1e-3, "actor_update_every": 2}  # conf/algo/td3.yaml
SAC = {"name": "sac", "target_smoothing": 0.005, "actor_lr": 3e-4, "critic_lr": 1e-3}  # conf/algo/sac.yaml
RESULTS = Path(__file__).parent / "results" / "agent_update.jsonl"


def _learner(algo: dict, baseline: bool, seed: int = 0) -> networks.Learner:
    """A learner of ``algo``; ``baseline``: with the private/hand-written part it replaced."""
    torch.manual_seed(seed)
    learner = networks.make_learner(AlgoConfig(**algo), OBS, ACT, _spec())
    if baseline and algo["name"] == "sac":
        actor = learner.actor.module
        actor.sample = actor.sample_by_hand
    elif baseline:
        learner.soft_update = lambda: _foreach_soft_update(learner)
    return learner


@torch.no_grad()
def _foreach_soft_update(learner: networks.Learner) -> None:
    """The soft update before: torch's private multi-tensor lerp over each target list."""
    for targets, params in learner._pairs:
        torch._foreach_lerp_(targets, params, learner.cfg.target_smoothing)


def paired_rates(algo: dict, n: int, chunk: int = 10, soft_update_only: bool = False) -> tuple[float, float]:
    """Calls per second of the shipped and the baseline learner, timed in alternating chunks of
    ``chunk`` calls (so load that comes and goes hits both alike): their ``update`` on one batch,
    or (``soft_update_only``) their ``soft_update``."""
    learners, batch = (_learner(algo, False), _learner(algo, True)), _batch()
    calls = [(lambda lr=lr: lr.soft_update()) if soft_update_only else (lambda lr=lr: lr.update(batch))
             for lr in learners]
    for call in calls:
        for _ in range(20):
            call()
    wall = [0.0, 0.0]
    for _ in range(n // chunk):
        for k, call in enumerate(calls):
            start = time.perf_counter()
            for _ in range(chunk):
                call()
            wall[k] += time.perf_counter() - start
    return n // chunk * chunk / wall[0], n // chunk * chunk / wall[1]


def soft_update_equality(n: int) -> dict:
    """TD3 targets after ``n`` updates on one batch from one seed, shipped vs baseline."""
    batch, targets = _batch(), []
    for baseline in (False, True):
        learner = _learner(TD3, baseline)
        torch.manual_seed(1)  # the same target policy noise both ways
        for _ in range(n):
            learner.update(batch)
        targets.append([p.detach().clone() for p in (*learner.actor_target.parameters(),
                                                     *learner.critic_targets.parameters())])
    moved = _learner(TD3, False)
    start = [p.detach() for p in (*moved.actor_target.parameters(), *moved.critic_targets.parameters())]
    return {"updates": n, "tensors": len(targets[0]),
            "max_abs_diff": max(float((a - b).abs().max()) for a, b in zip(*targets)),
            "bitwise_equal": all(torch.equal(a, b) for a, b in zip(*targets)),
            "targets_moved_max": max(float((a - b).abs().max()) for a, b in zip(targets[0], start))}


def sample_equality() -> dict:
    """SAC's sample, TanhNormal vs hand-written, same generator state; ~1/3 of actions saturated."""
    torch.manual_seed(0)
    actor = networks.SquashedGaussianActor(OBS, ACT, (400, 300), 3e-3)
    with torch.no_grad():
        actor.net[4].weight.mul_(2000)
        actor.log_std_head.weight.mul_(3)
    obs = torch.randn(4096, OBS)
    with torch.no_grad():
        torch.manual_seed(1)
        action, log_prob = actor.sample(obs)
        torch.manual_seed(1)
        ref_action, ref_log_prob = actor.sample_by_hand(obs)
    diff = (log_prob - ref_log_prob).abs()
    return {"samples": obs.shape[0], "saturated_share": round(float((ref_action.abs() == 1).float().mean()), 3),
            "actions_bitwise_equal": torch.equal(action, ref_action),
            "action_max_abs_diff": float((action - ref_action).abs().max()),
            "log_prob_max_abs_diff": float(diff.max()),
            "log_prob_max_rel_diff": float((diff / ref_log_prob.abs()).max())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--updates", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=0, help="torch threads; 0 = torch's default")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    measures = {("td3_update_per_s", "td3_update_per_s_foreach_baseline"): lambda: paired_rates(TD3, args.updates),
                ("soft_update_per_s", "soft_update_per_s_foreach_baseline"):
                    lambda: paired_rates(TD3, 20 * args.updates, soft_update_only=True),
                ("sac_update_per_s", "sac_update_per_s_hand_written_baseline"): lambda: paired_rates(SAC, args.updates)}
    runs: dict[str, list[float]] = {}
    for _ in range(args.repeats):  # fresh learners each time; shipped and baseline in alternating chunks
        for keys, measure in measures.items():
            for key, value in zip(keys, measure()):
                runs.setdefault(key, []).append(value)
                print(f"{key:>40}: {value:.1f}", flush=True)
    row = {**machine_stamp(), "torchrl": torchrl.__version__, "batch": BATCH,
           "hidden_sizes": AlgoConfig().hidden_sizes, "updates": args.updates, **{k: spread(v) for k, v in runs.items()}}
    med = {k: statistics.median(v) for k, v in runs.items()}
    row["ratios_of_medians"] = {
        "td3_update lerp_ loop / foreach": round(med["td3_update_per_s"] / med["td3_update_per_s_foreach_baseline"], 3),
        "soft_update lerp_ loop / foreach": round(med["soft_update_per_s"] / med["soft_update_per_s_foreach_baseline"], 3),
        "sac_update TanhNormal / hand-written": round(med["sac_update_per_s"]
                                                      / med["sac_update_per_s_hand_written_baseline"], 3)}
    # a TD3 update soft-updates every 2nd time: the soft update's share of an update's time
    row["soft_update_us"] = {k: round(1e6 / med[f"soft_update_per_s{k}"], 1) for k in ("", "_foreach_baseline")}
    row["soft_update_share_of_td3_update"] = round(med["td3_update_per_s"] / med["soft_update_per_s"] / 2, 4)
    row["soft_update_equality"] = soft_update_equality(args.updates)
    row["sac_sample_equality"] = sample_equality()
    report(row, runs, RESULTS, extra=("soft_update_us", "soft_update_share_of_td3_update", "soft_update_equality",
                                      "sac_sample_equality"))


if __name__ == "__main__":
    main()
