"""Fingerprints of pamrun's behaviour, for a change that must not alter a number (a refactor).

    python benchmarks/behaviour_hashes.py [--out DIR]

Runs, with fixed seeds, ``pamrun train experiment=thesis train=smoke``, a 5,000-frame
``pamrun train experiment=walker`` (evaluating every 2,500 frames) and ``pamrun eval`` of the
shipped walker, then prints the md5 of ``episodes.csv`` and ``evals.csv`` (their rows without
the wall-clock columns; evals.csv's gait means, added after the lines below were taken, in a
line of their own) and of the evaluation's ``episodes.jsonl``, each with its row count (its
lines over the keys they had then; the keys added later, :data:`LATER_KEYS`, in a line of their own).
Equal lines before and after a change mean the same training and the same evaluation, bit for
bit, on this machine (floating point may differ on another CPU). On 2026-12-04 (2-core x86_64),
before and after the package split of issue 36:

    thesis episodes.csv 70de23038aed4b11fe84624719bcc4a0 31
    thesis evals.csv f29be19dba198172d7cd7cde1a7d388e 3
    walker episodes.csv 72c90ea8b2ec3d3aac7ad82a2b38f60b 66
    walker evals.csv 2d2ec5b2bd4c8d08e0c21db87b68aee2 2
    eval episodes.jsonl 7f0f6c6f75f0b45d1f738f1a43f0c7f3 50
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import subprocess
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WALL_CLOCK = {"wall_time_s", "eval_s"}
# evals.csv's columns when the fingerprints above were taken (its later columns, the gait means, are hashed apart)
EVAL_COLUMNS = ("frames", "episodes", "walk_pass_rate", "stand_rate", "fall_rate", "distance_mean", "distance_min",
                "duration_mean", "max_abs_y_max", "return_mean", "pressure_change_mean", "select_pass_rate", "best")
# episodes.jsonl's keys added after the lines above were taken (per episode, and in its "steps")
LATER_KEYS = ("speed_tracking_rms_m_s", "stand_still_feet_down_share", "stand_still_drift_m")
LATER_STEP_KEYS = ("target_speed_m_s",)
RUNS = {
    "thesis": ["train", "experiment=thesis", "train=smoke", "seed=0"],
    "walker": ["train", "experiment=walker", "train.max_frames=5000", "train.eval_every_frames=2500", "seed=0"],
    "eval": ["eval", f"ckpt={ROOT / 'agents' / 'walker_td3_seed0.pt'}"],
}


def csv_hash(path: Path, columns=None, leave_out=()) -> tuple[str, int]:
    """md5 of the rows' values but the wall-clock ones: of ``columns`` only, or all but ``leave_out``."""
    rows = list(csv.DictReader(path.open()))
    keep = lambda k: k not in WALL_CLOCK and (k in columns if columns else k not in leave_out)  # noqa: E731
    text = "\n".join(",".join(f"{k}={v}" for k, v in row.items() if keep(k)) for row in rows)
    return hashlib.md5(text.encode()).hexdigest(), len(rows)


def jsonl_hash(path: Path, later: bool = False) -> tuple[str, int]:
    """md5 of the lines over the keys they had when the fingerprints were taken (``later``: over
    :data:`LATER_KEYS` and :data:`LATER_STEP_KEYS` only), each written as pamrun writes it."""
    lines = []
    for line in path.read_text().splitlines():
        record = json.loads(line)
        keep = {k: v for k, v in record.items() if k == "steps" or (k in LATER_KEYS) == later}
        if "steps" in keep:
            keep["steps"] = {k: v for k, v in keep["steps"].items() if (k in LATER_STEP_KEYS) == later}
        lines.append(json.dumps(keep))
    return hashlib.md5("\n".join(lines).encode()).hexdigest(), len(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="where the runs go (default: a temporary folder)")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="pamrun-hashes-"))
    for name, command in RUNS.items():
        subprocess.run(["pamrun", *command, f"hydra.run.dir={out / name}"], check=True, cwd=ROOT,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for name in ("thesis", "walker"):
        print(name, "episodes.csv", *csv_hash(out / name / "episodes.csv"))
        print(name, "evals.csv", *csv_hash(out / name / "evals.csv", EVAL_COLUMNS))
        print(name, "evals.csv gait", *csv_hash(out / name / "evals.csv", leave_out=EVAL_COLUMNS))
    print("eval episodes.jsonl", *jsonl_hash(out / "eval" / "episodes.jsonl"))
    print("eval episodes.jsonl later keys", *jsonl_hash(out / "eval" / "episodes.jsonl", later=True))


if __name__ == "__main__":
    main()
