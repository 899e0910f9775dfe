"""Kill a training at random moments, then run the same command again: does the run hold?

    python benchmarks/fault_campaign.py [--trials 20] [--seed 0]

Each trial starts a small training (``train=smoke``, checkpoints every 400 frames) in its
own folder, sends SIGKILL or SIGTERM (alternating) to its process group after a random
0.5-14 s (early kills, before the first checkpoint, included), then runs the same command
again. A trial holds when the second command exits 0 with the run finished
(``max_frames``), episodes 1..N continuous with none duplicated, and every frame of the
budget accounted for. Prints one row per trial and ``held N/T``; appends to
benchmarks/results/fault_campaign.jsonl.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from pamrun.runs.directory import RunFiles
from pamrun.runs.files import read_json

COMMAND = ["train", "experiment=thesis", "muscle=sized", "train=smoke", "algo=td3", "train.max_frames=3000",
           "train.init_random_frames=200",
           "train.updates_per_frame=0.25", "train.checkpoint_every_frames=400", "seed=7"]


def trial(run_dir: Path, sig: signal.Signals, after_s: float) -> dict:
    args = [sys.executable, "-m", "pamrun.cli", *COMMAND, f"hydra.run.dir={run_dir}"]
    proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    time.sleep(after_s)
    finished_first = proc.poll() is not None
    if not finished_first:
        os.killpg(proc.pid, sig)
    proc.wait()
    files = RunFiles(run_dir)
    had_checkpoint = files.last.exists()
    again = subprocess.run(args, capture_output=True, text=True)
    run = read_json(files.run_json)
    rows = list(csv.DictReader(files.episodes.open())) if files.episodes.exists() else []
    episodes = [int(r["episode"]) for r in rows]
    held = (again.returncode == 0 and run.get("status") == "max_frames" and run.get("frames") == 3000
            and episodes == list(range(1, len(episodes) + 1)) and run.get("episodes") == len(episodes))
    return {"signal": sig.name, "after_s": round(after_s, 2), "first_rc": proc.returncode,
            "finished_before_kill": finished_first, "checkpoint_before_kill": had_checkpoint,
            "rerun_rc": again.returncode, "status": run.get("status"), "episodes": len(episodes), "held": held,
            "error": "" if held else (again.stderr.strip().splitlines() or [""])[-1][:200]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(args.trials):
            sig = signal.SIGKILL if k % 2 == 0 else signal.SIGTERM
            row = trial(Path(tmp) / f"t{k:02d}", sig, rng.uniform(0.5, 14.0))
            rows.append(row)
            print(f"{k + 1:2d} {row['signal']:<7} at {row['after_s']:5.2f} s  checkpoint before: "
                  f"{'yes' if row['checkpoint_before_kill'] else 'no ':<3}  first rc {row['first_rc']:>4}  "
                  f"rerun rc {row['rerun_rc']}  {row['status']}  {row['episodes']} episodes  "
                  f"{'held' if row['held'] else 'LOST: ' + row['error']}", flush=True)
    held = sum(r["held"] for r in rows)
    print(f"held {held}/{len(rows)}")
    out = Path(__file__).parent / "results" / "fault_campaign.jsonl"
    out.parent.mkdir(exist_ok=True)
    stamp = time.strftime("%Y-%m-%dT%H:%M:%S")
    with out.open("a") as fh:
        for r in rows:
            fh.write(json.dumps({"time": stamp, **r}) + "\n")
        fh.write(json.dumps({"time": stamp, "summary": f"held {held}/{len(rows)}"}) + "\n")


if __name__ == "__main__":
    main()
