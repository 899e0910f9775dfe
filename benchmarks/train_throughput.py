"""Training throughput on this machine: pamrun vs a plain-PyTorch floor vs Stable-Baselines3.

    python benchmarks/train_throughput.py [--frames 3000] [--updates 400] [--repeats 3]

Measures, in one run, with the thesis' networks (400/300) at batch 128, each measurement
``--repeats`` times in turn (so a change of machine load hits all of them alike):
1. ``pamrun train`` with TD3 (and DDPG) at one gradient update per frame: environment
   frames/s of the whole loop (collection + learning), from run.json, with the env stepped
   between updates and with ``train.async_collection=true`` (stepped in its own process);
2. pamrun's TD3 update alone (``networks.Learner.update``: critics, actor, Adam, targets) on one batch;
3. TorchRL's TD3 update alone (``TD3Loss`` critic/actor halves + Adam + ``SoftUpdate``), which
   pamrun used before 0.2;
4. a plain-PyTorch TD3 update of the same networks and batch (CleanRL style): the floor;
5. Stable-Baselines3's TD3 on PamWalker-v0 with net_arch [400, 300], batch 128, one
   update per step (install with ``pip install -e .[bench]``; skipped if missing).
It prints min / median / max of each and the ratios of the medians, and appends them to
benchmarks/results/train_throughput.jsonl.
"""

from __future__ import annotations

import argparse
import copy
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

from pamrun.config import AlgoConfig
from pamrun.learning import networks
from pamrun.runs.directory import RunFiles
from pamrun.runs.files import read_json

OBS, ACT, BATCH = 43, 10, 128


def pamrun_loop(algo: str, frames: int, *extra: str) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "pamrun.cli", "train", "experiment=thesis", "muscle=sized", f"algo={algo}", "train=smoke",
               f"train.max_frames={frames}", "train.init_random_frames=200", "train.updates_per_frame=1",
               "train.checkpoint_every_frames=1000000", "train.save_threshold=1e9", "train.eval_every_frames=0",
               *extra, f"hydra.run.dir={tmp}/run"]
        subprocess.run(cmd, check=True, capture_output=True)
        run = read_json(RunFiles(Path(tmp, "run")).run_json)
    wall = run["wall_time_s"]
    return {"frames_per_s": round(run["frames"] / wall, 1), "updates_per_s": round(run["updates"] / wall, 1),
            "frames": run["frames"], "updates": run["updates"], "wall_s": wall}


def _batch():
    from tensordict import TensorDict

    return TensorDict({"observation": torch.randn(BATCH, OBS), "action": torch.rand(BATCH, ACT) * 2 - 1,
                       "next": {"observation": torch.randn(BATCH, OBS), "reward": torch.randn(BATCH, 1),
                                "done": torch.zeros(BATCH, 1, dtype=torch.bool),
                                "terminated": torch.zeros(BATCH, 1, dtype=torch.bool)}}, [BATCH])


def _spec():
    from torchrl.data import Bounded

    return Bounded(-torch.ones(ACT), torch.ones(ACT), (ACT,))


def pamrun_td3_updates(n: int) -> float:
    """pamrun's own update (what ``pamrun train algo=td3`` runs per gradient step)."""
    learner = networks.make_learner(AlgoConfig(name="td3", actor_update_every=2), OBS, ACT, _spec())
    batch = _batch()
    for _ in range(20):
        learner.update(batch)
    start = time.perf_counter()
    for _ in range(n):
        learner.update(batch)
    return n / (time.perf_counter() - start)


def torchrl_td3_updates(n: int) -> float:
    from torchrl.objectives import SoftUpdate, TD3Loss

    cfg = AlgoConfig(name="td3")
    actor, critic = networks.make_actor(cfg, OBS, ACT), ValueOperatorCritic(cfg)
    loss = TD3Loss(actor, critic, action_spec=_spec(), num_qvalue_nets=2, loss_function="l2", delay_actor=True,
                   delay_qvalue=True)
    loss.make_value_estimator(gamma=cfg.gamma)
    updater = SoftUpdate(loss, tau=0.005)
    critic_loss, actor_loss = loss.value_loss, loss.actor_loss
    a_opt = torch.optim.Adam(list(loss.actor_network_params.flatten_keys().values()), 1e-3)
    c_opt = torch.optim.Adam(list(loss.qvalue_network_params.flatten_keys().values()), 1e-3)
    batch = _batch()
    start = None
    for i in range(n + 20):
        if i == 20:
            start = time.perf_counter()
        c_opt.zero_grad()
        critic_loss(batch)[0].backward()
        c_opt.step()
        if i % 2 == 0:
            a_opt.zero_grad()
            actor_loss(batch)[0].backward()
            a_opt.step()
            updater.step()
    return n / (time.perf_counter() - start)


def ValueOperatorCritic(cfg):  # noqa: N802 (a factory of TorchRL's critic wrapper)
    from torchrl.modules import ValueOperator

    return ValueOperator(networks.make_critic(cfg, OBS, ACT), in_keys=["observation", "action"])


def plain_td3_updates(n: int) -> float:
    """The same TD3 update in plain PyTorch (CleanRL style): the floor."""
    cfg = AlgoConfig(name="td3")
    actor = networks.ThesisActor(OBS, ACT, (400, 300), 3e-3)
    q1, q2 = networks.ThesisCritic(OBS, ACT, (400, 300), 3e-3), networks.ThesisCritic(OBS, ACT, (400, 300), 3e-3)
    actor_t, q1_t, q2_t = copy.deepcopy(actor), copy.deepcopy(q1), copy.deepcopy(q2)
    a_opt = torch.optim.Adam(actor.parameters(), 1e-3)
    q_opt = torch.optim.Adam(list(q1.parameters()) + list(q2.parameters()), 1e-3)
    obs, act, rew = torch.randn(BATCH, OBS), torch.rand(BATCH, ACT) * 2 - 1, torch.randn(BATCH, 1)
    nxt, done = torch.randn(BATCH, OBS), torch.zeros(BATCH, 1)
    start = None
    for i in range(n + 20):
        if i == 20:
            start = time.perf_counter()
        with torch.no_grad():
            noise = (torch.randn_like(act) * cfg.policy_noise).clamp(-cfg.noise_clip, cfg.noise_clip)
            a2 = (actor_t(nxt) + noise).clamp(-1, 1)
            target = rew + cfg.gamma * (1 - done) * torch.min(q1_t(nxt, a2), q2_t(nxt, a2))
        q_loss = ((q1(obs, act) - target) ** 2).mean() + ((q2(obs, act) - target) ** 2).mean()
        q_opt.zero_grad()
        q_loss.backward()
        q_opt.step()
        if i % 2 == 0:
            a_loss = -q1(obs, actor(obs)).mean()
            a_opt.zero_grad()
            a_loss.backward()
            a_opt.step()
            with torch.no_grad():
                for net, tgt in ((actor, actor_t), (q1, q1_t), (q2, q2_t)):
                    for p, tp in zip(net.parameters(), tgt.parameters()):
                        tp.lerp_(p, cfg.target_smoothing)
    return n / (time.perf_counter() - start)


def sb3_td3(frames: int) -> dict | None:
    try:
        from stable_baselines3 import TD3
    except ImportError:
        return None
    import gymnasium as gym

    import pamrun  # noqa: F401

    env = gym.make("pamrun/PamWalker-v0")
    model = TD3("MlpPolicy", env, policy_kwargs={"net_arch": [400, 300]}, batch_size=BATCH, learning_starts=200,
                train_freq=1, gradient_steps=1, verbose=0, seed=0, device="cpu")
    start = time.perf_counter()
    model.learn(total_timesteps=frames)
    wall = time.perf_counter() - start
    return {"frames_per_s": round(frames / wall, 1), "updates_per_s": round((frames - 200) / wall, 1), "wall_s": round(wall, 2)}


def spread(values: list[float]) -> dict:
    return {"min": round(min(values), 1), "median": round(statistics.median(values), 1), "max": round(max(values), 1),
            "n": len(values)}


def machine_stamp() -> dict:
    """The head of a results row: when, on which machine, with how many cores and torch threads."""
    return {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": platform.node(), "cpu_count": os.cpu_count(),
            "processor": platform.processor() or platform.machine(), "torch": torch.__version__,
            "torch_threads": torch.get_num_threads()}


def report(row: dict, runs: dict[str, list[float]], out: Path, extra: tuple[str, ...] = ()) -> None:
    """Print each measure's min, median and max (``row[key]``, :func:`spread`), then ``row``'s
    ratios of medians and its ``extra`` keys, and append ``row`` to the JSON-lines file ``out``."""
    width = max(map(len, runs)) + 2
    print(f"{'measure':>{width}}  {'min':>8} {'median':>8} {'max':>8}")
    for key in runs:
        print(f"{key:>{width}}  {row[key]['min']:8.1f} {row[key]['median']:8.1f} {row[key]['max']:8.1f}")
    for key in ("ratios_of_medians", *extra):
        print(f"{key}: {row[key]}")
    out.parent.mkdir(exist_ok=True)
    with out.open("a") as fh:
        fh.write(json.dumps(row) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=3000)
    parser.add_argument("--updates", type=int, default=400)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--ddpg", action="store_true", help="also measure pamrun train algo=ddpg")
    args = parser.parse_args()
    runs: dict[str, list[float]] = {}
    for _ in range(args.repeats):  # interleaved, so drifting load hits every measurement alike
        measures = {"pamrun_td3_loop_frames_per_s": lambda: pamrun_loop("td3", args.frames)["frames_per_s"],
                    "pamrun_td3_async_loop_frames_per_s":
                        lambda: pamrun_loop("td3", args.frames, "train.async_collection=true")["frames_per_s"],
                    "pamrun_td3_update_per_s": lambda: pamrun_td3_updates(args.updates),
                    "torchrl_td3_update_per_s": lambda: torchrl_td3_updates(args.updates),
                    "plain_pytorch_td3_update_per_s": lambda: plain_td3_updates(args.updates)}
        if args.ddpg:
            measures["pamrun_ddpg_loop_frames_per_s"] = lambda: pamrun_loop("ddpg", args.frames)["frames_per_s"]
        sb3 = sb3_td3(args.frames)
        if sb3:
            runs.setdefault("sb3_td3_loop_frames_per_s", []).append(sb3["frames_per_s"])
        for key, measure in measures.items():
            runs.setdefault(key, []).append(measure())
            print(f"{key:>34}: {runs[key][-1]:.1f}", flush=True)
    row = {**machine_stamp(), **{k: spread(v) for k, v in runs.items()}}
    med = {k: row[k]["median"] for k in runs}
    ratios = {"pamrun_update / plain_pytorch_update": med["pamrun_td3_update_per_s"] / med["plain_pytorch_td3_update_per_s"],
              "torchrl_update / plain_pytorch_update": med["torchrl_td3_update_per_s"] / med["plain_pytorch_td3_update_per_s"]}
    if "sb3_td3_loop_frames_per_s" in med:
        ratios["pamrun_loop / sb3_loop"] = med["pamrun_td3_loop_frames_per_s"] / med["sb3_td3_loop_frames_per_s"]
        ratios["pamrun_async_loop / sb3_loop"] = (med["pamrun_td3_async_loop_frames_per_s"]
                                                  / med["sb3_td3_loop_frames_per_s"])
    row["ratios_of_medians"] = {k: round(v, 3) for k, v in ratios.items()}
    report(row, runs, Path(__file__).parent / "results" / "train_throughput.jsonl")


if __name__ == "__main__":
    main()
