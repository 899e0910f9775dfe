"""Where a walker's feet slip: its foot slip split by the part of the stance, by the foot (the
leading or the trailing one) while both are down, and by how the sole meets the ground.

    python benchmarks/slip_anatomy.py <eval dir>/episodes.jsonl [--episodes 10] [--agent NAME]

Reads the per-step rows ``pamrun eval`` writes (``episodes.jsonl``; the first agent in it unless
``--agent``) and measures with pamrun's own definitions (``pamrun.evaluation.metrics``): contact
(5 % of the weight), the ground point's slip (``measures.ground_point_shift_m``) and the sole's
side-to-side tilt (``measures.sole_tilt_rad``). Prints:

* slip by tenth of the stance (complete stances in steady contact) and each tenth's share of it;
* in the rows with both feet down, the forward slip of the leading foot and of the trailing one;
* in the step into a touchdown, the landing foot's horizontal speed;
* slip with the sole flat (every corner within 5 mm of the lowest) and on its edge (tilted over 5 deg).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from pamrun.evaluation import metrics as M
from pamrun.task.measures import CONTACT_WEIGHT_SHARE, ground_point_shift_m, sole_tilt_rad


def episodes(path: str, agent: str | None, limit: int):
    with open(path) as f:
        for line in f:
            e = json.loads(line)
            agent = agent or e["agent"]
            if e["agent"] == agent and "sole_xyz_m" in e["steps"]:
                yield e
                limit -= 1
                if limit == 0:
                    return


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("episodes_jsonl")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--agent", default=None)
    ap.add_argument("--mass-kg", type=float, default=None, help="the robot's mass (default: the sized robot's)")
    args = ap.parse_args()
    if args.mass_kg is None:
        from pamrun.config import BodyConfig
        from pamrun.physics.body import build_model
        args.mass_kg = float(build_model(BodyConfig()).body_subtreemass[0])
    threshold = CONTACT_WEIGHT_SHARE * args.mass_kg * 9.81
    by_tenth = [[] for _ in range(10)]
    lead, trail, landing, flat, edge, n_ep = [], [], [], [], [], 0
    for e in episodes(args.episodes_jsonl, args.agent, args.episodes):
        n_ep += 1
        s = e["steps"]
        t = np.asarray(s["t_s"], float)
        contact = M.contacts(s, threshold)
        events = M.steady(contact, t[1] - t[0])
        points = M.sole_points(s)
        shift = ground_point_shift_m(points[:-1], points[1:]) / np.diff(t)[:, None, None]  # (n-1, 2, 2) [m/s]
        speed = np.linalg.norm(shift, axis=-1)
        both = contact[1:] & contact[:-1]
        tilt = np.degrees(np.abs(sole_tilt_rad(points)))
        spread = points[..., 2].max(axis=2) - points[..., 2].min(axis=2)
        x = points[..., 0].mean(axis=2)
        for foot in (0, 1):
            for down, a, b in M.phases(events[:, foot]):
                if down:
                    for row in range(a, b - 1):
                        if both[row, foot]:
                            by_tenth[min(9, int(10 * (row - a) / (b - a)))].append(speed[row, foot])
            for row in M.touchdowns(contact)[foot]:
                if row >= 1:
                    landing.append(speed[row - 1, foot])
            for row in np.flatnonzero(both[:, foot]):
                if spread[row, foot] < 0.005:
                    flat.append(speed[row, foot])
                elif tilt[row, foot] > 5.0:
                    edge.append(speed[row, foot])
        for row in np.flatnonzero(both.all(axis=1)):
            front = int(x[row, 1] > x[row, 0])
            lead.append(shift[row, front, 0])
            trail.append(shift[row, 1 - front, 0])
    total = sum(sum(v) for v in by_tenth)
    print(f"{n_ep} episodes of {args.episodes_jsonl}")
    print("slip by tenth of the stance: mean [m/s], share of the slip")
    for k, v in enumerate(by_tenth):
        print(f"  {10 * k:3d}-{10 * k + 10:3d} %  {np.mean(v) if v else float('nan'):.3f}  {sum(v) / total:.0%}")
    for name, v in (("both feet down, leading foot: forward slip", lead),
                    ("both feet down, trailing foot: forward slip", trail)):
        print(f"{name} {np.mean(v) if v else float('nan'):+.3f} m/s ({len(v)} rows)")
    print(f"landing foot's speed in the step into its touchdown {np.mean(landing):.3f} m/s ({len(landing)} touchdowns)")
    rows = len(flat) + len(edge)
    print(f"sole flat: {len(flat)} rows, slip {np.mean(flat) if flat else float('nan'):.3f} m/s; "
          f"on its edge (> 5 deg): {len(edge)} rows, slip {np.mean(edge) if edge else float('nan'):.3f} m/s "
          f"({len(edge) / max(rows, 1):.0%} of these)")


if __name__ == "__main__":
    main()
