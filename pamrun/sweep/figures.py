"""The sweep's figures: learning curves per setting (``curves.png``) and the Optuna history
(``optuna.png``), drawn from the files the jobs wrote."""

from __future__ import annotations

import csv
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
from scipy import stats

from pamrun.evaluation.figures import save_figure  # importing it selects Matplotlib's Agg backend


def sweep_curves(groups: list[tuple[str, list[Path]]], png_path: Path, points: int = 100) -> Path:
    """Average reward against frames per sweep group: mean over its seeds with a shaded 95 %
    interval (Student's t), each run's ``episodes.csv`` interpolated onto a common frame grid."""
    fig, ax = plt.subplots(figsize=(8, 4.8))
    colors = plt.cm.tab10(np.arange(max(1, len(groups))) % 10)
    for color, (label, paths) in zip(colors, groups):
        runs = []
        for path in paths:
            rows = list(csv.DictReader(Path(path).open())) if Path(path).exists() else []
            if rows:
                runs.append((np.array([float(r["frames"]) for r in rows]),
                             np.array([float(r["avg_reward"]) for r in rows])))
        if not runs:
            continue
        end = min(f[-1] for f, _ in runs)  # every seed covers the grid
        grid = np.linspace(max(f[0] for f, _ in runs), end, points) if end > 0 else np.array([0.0])
        ys = np.array([np.interp(grid, f, y) for f, y in runs])
        mean = ys.mean(axis=0)
        ax.plot(grid, mean, color=color, lw=1.6, label=f"{label} (n={len(runs)})")
        if len(runs) > 1:
            half = stats.t.ppf(0.975, len(runs) - 1) * ys.std(axis=0, ddof=1) / np.sqrt(len(runs))
            ax.fill_between(grid, mean - half, mean + half, color=color, alpha=0.2)
    ax.set_xlabel("frames (control steps)")
    ax.set_ylabel("average episode reward")
    ax.set_title("Learning curves per setting: mean over seeds, shaded 95 % interval")
    ax.grid(alpha=0.3)
    if groups:
        ax.legend(fontsize=8)
    return save_figure(fig, png_path, dpi=110)


def optuna_history(points: list[tuple[int, float]], direction: str, metric: str, png_path: Path) -> Path:
    """Objective of every finished Optuna trial and the best so far."""
    fig, ax = plt.subplots(figsize=(7, 4))
    if points:
        n, v = np.array(points, dtype=float).T
        best = np.maximum.accumulate(v) if direction == "maximize" else np.minimum.accumulate(v)
        ax.plot(n, v, "o", color="tab:blue", label="trial (mean over seeds)")
        ax.step(n, best, where="post", color="tab:red", label="best so far")
        ax.legend(fontsize=8)
    ax.set_xlabel("trial")
    ax.set_ylabel(metric)
    ax.set_title(f"Optuna search ({direction} {metric})")
    ax.grid(alpha=0.3)
    return save_figure(fig, png_path, dpi=110)
