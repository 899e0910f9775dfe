"""Wall time of the same evaluation with 1, 2, ... workers (``pamrun eval``'s parallelism).

    python benchmarks/eval_scaling.py [--ckpt PATH] [--agents 4] [--episodes 10] [--workers 1 2]

Evaluates N agents x K episodes with ``pamrun.evaluation.episodes.evaluate_agents`` once per worker
count, checks the results are identical, and prints the wall times and speed-ups. Without
``--ckpt`` it writes ``--agents`` untrained actors (different seeds) to a temporary folder;
those fall within ~1-2 s, so their episodes are short. ``--ckpt`` takes what ``pamrun eval
ckpt=`` takes. Results are appended to benchmarks/results/eval_scaling.jsonl.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import torch

from pamrun.config import Config, register_configs, to_object
from pamrun.evaluation.episodes import evaluate_agents
from pamrun.evaluation.evaluate import load_agents
from pamrun.learning.checkpoints import agent_record
from pamrun.learning.networks import ThesisActor
from pamrun.task.observation import N_JOINTS, OBS_SIZE


def untrained_agents(folder: Path, n: int, cfg: Config) -> str:
    for seed in range(n):
        torch.manual_seed(seed)
        actor = ThesisActor(OBS_SIZE, N_JOINTS, (400, 300), 3e-3)
        torch.save(agent_record(actor.state_dict(), cfg, {"episode": seed}), folder / f"agent_ep{seed:06d}_r0.pt")
    return str(folder)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ckpt", default="")
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()

    from hydra import compose, initialize_config_dir

    from pamrun.config import CONF_DIR

    register_configs()
    with initialize_config_dir(str(CONF_DIR), version_base="1.3"):
        cfg = to_object(compose("config", overrides=[f"eval.episodes={args.episodes}"]))
    with tempfile.TemporaryDirectory() as tmp:
        spec = args.ckpt or untrained_agents(Path(tmp), args.agents, cfg)
        agents, kwargs, errors = load_agents(spec, cfg)
        assert not errors, errors
        times, reference = {}, None
        for workers in args.workers:
            start = time.perf_counter()
            results = evaluate_agents(agents, kwargs, args.episodes, cfg.eval.seed, workers)
            times[workers] = time.perf_counter() - start
            reference = reference or results
            assert results == reference, "results differ between worker counts"
    steps = sum(len(e["steps"]["x_m"]) for per_agent in reference for e in per_agent)
    base = times[args.workers[0]]
    record = {"time": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": platform.node(), "cpu_count": os.cpu_count(),
              "agents": len(agents), "episodes": args.episodes, "control_steps": steps,
              "ckpt": args.ckpt or "untrained", "identical": True,
              "wall_s": {str(w): round(t, 2) for w, t in times.items()},
              "speedup": {str(w): round(base / t, 2) for w, t in times.items()}}
    for w, t in times.items():
        print(f"{w} worker(s): {t:6.2f} s  {steps / t:7.0f} control steps/s  speed-up {base / t:.2f}x")
    out = Path(__file__).parent / "results" / "eval_scaling.jsonl"
    with out.open("a") as fh:
        fh.write(json.dumps(record) + "\n")
    print(f"identical results at every worker count; appended to {out}")


if __name__ == "__main__":
    main()
