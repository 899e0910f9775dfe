"""The regulator's step response, ``muscle.regulator.model=lag`` against ``=flow``, for the default robot.

    python benchmarks/valve_step.py

A 0 -> 600 kPa command into one side (one DMSP-40-300, or two: the knee and ankle pitch) held
at 0 % and at 20 % contraction; the lag's response does not depend on the volume. Prints the
10-90 % rise time and the times to 90 and 95 %; writes benchmarks/results/valve_step.json and
docs/img/valve_step.png (the same as ``pamrun muscle valve`` writes into its run directory).
"""

from __future__ import annotations

import json
from pathlib import Path

from pamrun.bench import figures
from pamrun.bench.muscle import print_valve_table, valve_step_responses
from pamrun.config import MuscleConfig

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    results = valve_step_responses(MuscleConfig())
    path = ROOT / "benchmarks" / "results" / "valve_step.json"
    path.write_text(json.dumps(results))
    figures.valve_step(path, ROOT / "docs" / "img" / "valve_step.png")
    print_valve_table(results)
    print(f"Wrote {path.relative_to(ROOT)}, docs/img/valve_step.png")


if __name__ == "__main__":
    main()
