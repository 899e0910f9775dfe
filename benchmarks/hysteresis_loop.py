"""The muscle's hysteresis loop, ``muscle.spring.hysteresis=maxwell_slip`` against ``none``, for the default robot.

    python benchmarks/hysteresis_loop.py

One muscle of the default robot (a DMSP-40-300) at constant pressure, 3 and 6 bar, its contraction
cycled sinusoidally 9 +- 5 %: force against contraction without hysteresis (one curve) and with the
Maxwell-slip elements (a loop). Prints the loop area per cycle [J], simulated and analytic
(sum_i 4 f_i (A - f_i / k_i), scaled to the muscle's size and length); writes
benchmarks/results/hysteresis_loop.json and docs/img/hysteresis_loop.png (the same as
``pamrun muscle hysteresis`` writes into its run directory).
"""

from __future__ import annotations

import json
from pathlib import Path

from pamrun.bench import figures
from pamrun.bench.muscle import print_hysteresis_table
from pamrun.config import MuscleConfig
from pamrun.physics.hysteresis import hysteresis_loop

ROOT = Path(__file__).resolve().parent.parent


def main() -> None:
    results = hysteresis_loop(MuscleConfig())
    path = ROOT / "benchmarks" / "results" / "hysteresis_loop.json"
    path.write_text(json.dumps(results))
    figures.hysteresis_loop(path, ROOT / "docs" / "img" / "hysteresis_loop.png")
    print_hysteresis_table(results)
    print(f"Wrote {path.relative_to(ROOT)}, docs/img/hysteresis_loop.png")


if __name__ == "__main__":
    main()
