"""Fingerprints of pamrun's behaviour, for a change that must not alter a number (a refactor).

    python benchmarks/behaviour_hashes.py [--out DIR] [--only thesis walker eval]

Runs, with fixed seeds, ``pamrun train experiment=thesis train=smoke``, a 5,000-frame
``pamrun train experiment=walker`` (evaluating every 2,500 frames) and ``pamrun eval`` of the
shipped walker, then prints the md5 of ``episodes.csv`` and ``evals.csv`` (their rows without
the wall-clock columns; evals.csv's first gait means, added after the lines below were taken,
in a line of their own, its columns added since in another) and of the evaluation's
``episodes.jsonl`` (its records over the keys they had then; the later keys in a line of their
own), each with its row count; ``--only`` runs and prints only the runs it names.
Equal lines before and after a change mean the same training and the same evaluation, bit for
bit, on this machine (floating point may differ on another CPU). On 2026-12-04 (2-core x86_64),
before and after the package split of issue 36:

    thesis episodes.csv 70de23038aed4b11fe84624719bcc4a0 31
    thesis evals.csv f29be19dba198172d7cd7cde1a7d388e 3
    walker episodes.csv 72c90ea8b2ec3d3aac7ad82a2b38f60b 66
    walker evals.csv 2d2ec5b2bd4c8d08e0c21db87b68aee2 2
    eval episodes.jsonl 7f0f6c6f75f0b45d1f738f1a43f0c7f3 50

Counting a foot that bounces as it lands as one step (steady contact, pamrun.evaluation.metrics)
changed the evaluation's step metrics, and so its line, on purpose; since then:

    eval episodes.jsonl 6ea2837016f2fa6d2f3f85d28affd126 50
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
# evals.csv's first gait means (its columns added since are hashed apart)
EVAL_GAIT_COLUMNS = ("speed_mean", "step_frequency_hz_mean", "stride_length_m_mean", "duty_factor_mean",
                     "step_time_symmetry_mean", "step_length_symmetry_mean", "stop_share_gait_max_mean",
                     "cost_of_transport_mean", "air_nl_per_m_mean")
# episodes.jsonl's keys when the fingerprints above were taken (its later keys are hashed apart)
EPISODE_KEYS = ("agent", "episode", "seed", "return", "distance_m", "duration_s", "fell", "physics_error", "max_abs_y_m",
                "speed_m_s", "pressure_change_kpa", "step_count", "step_frequency_hz", "step_length_m",
                "stride_length_m", "step_time_symmetry", "step_length_symmetry", "hop_share", "duty_factor",
                *(f"stop_share_{side}_{joint}" for side in ("right", "left")
                  for joint in ("hip_pitch", "hip_roll", "knee", "ankle_pitch", "ankle_roll")),
                "stop_share_max", "knee_swing_stop_share", "stop_share_gait_max", "swing_clearance_m", "foot_slip_m_s",
                "cost_of_transport", "air_nl", "air_nl_per_m", "steps", "walk_pass")
LATER_STEP_KEYS = ("target_speed_m_s",)  # keys of an episode's "steps" added since (hashed with the later keys)
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


def jsonl_hash(path: Path, keys=None, leave_out=()) -> tuple[str, int]:
    """md5 of the records, each written as pamrun writes it, of ``keys`` only (their "steps" without
    :data:`LATER_STEP_KEYS`), or all but ``leave_out`` (with "steps" of those keys only)."""
    records = [json.loads(line) for line in path.read_text().splitlines()]
    keep = lambda k: k in keys if keys else k not in leave_out or k == "steps"  # noqa: E731
    lines = []
    for record in records:
        kept = {k: v for k, v in record.items() if keep(k)}
        if "steps" in kept:
            kept["steps"] = {k: v for k, v in kept["steps"].items() if (k in LATER_STEP_KEYS) == (keys is None)}
        lines.append(json.dumps(kept))
    return hashlib.md5("\n".join(lines).encode()).hexdigest(), len(records)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="where the runs go (default: a temporary folder)")
    parser.add_argument("--only", nargs="+", choices=list(RUNS), default=list(RUNS), help="run only these")
    args = parser.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="pamrun-hashes-"))
    for name in args.only:
        subprocess.run(["pamrun", *RUNS[name], f"hydra.run.dir={out / name}"], check=True, cwd=ROOT,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    for name in ("thesis", "walker"):
        if name in args.only:
            print(name, "episodes.csv", *csv_hash(out / name / "episodes.csv"))
            print(name, "evals.csv", *csv_hash(out / name / "evals.csv", EVAL_COLUMNS))
            print(name, "evals.csv gait", *csv_hash(out / name / "evals.csv", EVAL_GAIT_COLUMNS))
            print(name, "evals.csv later columns",
                  *csv_hash(out / name / "evals.csv", leave_out=EVAL_COLUMNS + EVAL_GAIT_COLUMNS))
    if "eval" in args.only:
        print("eval episodes.jsonl", *jsonl_hash(out / "eval" / "episodes.jsonl", EPISODE_KEYS))
        print("eval episodes.jsonl later keys", *jsonl_hash(out / "eval" / "episodes.jsonl", leave_out=EPISODE_KEYS))


if __name__ == "__main__":
    main()
