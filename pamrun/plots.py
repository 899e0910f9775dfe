"""Every figure of pamrun, drawn from files on disk (json/csv), never from live objects.

So any figure can be redrawn from a finished run without re-simulating.
"""

from __future__ import annotations

import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def step_response(json_path: Path, png_path: Path) -> Path:
    """Contraction of both muscles over time per experiment (thesis Figs 10.4-10.5)."""
    data = json.loads(Path(json_path).read_text())
    experiments = data["experiments"]
    fig, axes = plt.subplots(1, len(experiments), figsize=(5.5 * len(experiments), 4), squeeze=False)
    for ax, (name, exp) in zip(axes[0], experiments.items()):
        t = np.asarray(exp["time_s"])
        c = np.asarray(exp["contraction_pct"])
        for i, color in ((0, "tab:blue"), (1, "tab:red")):
            ax.plot(t, c[:, i], color=color, label=f"muscle {i + 1} ({exp['pressure_kpa'][i]:.0f} kPa)")
            ax.axhline(exp["thesis_final_pct"][i], color=color, ls=":", lw=1)
        ax.set_title(exp["label"] or name)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("contraction [%]")
        ax.grid(alpha=0.3)
        ax.legend(title="dotted: thesis final", fontsize=8)
    fig.tight_layout()
    fig.savefig(png_path, dpi=120)
    plt.close(fig)
    return Path(png_path)


def force_curves(json_path: Path, curves_png: Path, surface_png: Path) -> tuple[Path, Path]:
    """Force against contraction per pressure (Fig. 8.10) and the F(x, P) surface (Fig. 8.9)."""
    data = json.loads(Path(json_path).read_text())
    x = np.asarray(data["contraction_pct"])
    p = np.asarray(data["pressure_kpa"])
    f = np.asarray(data["force_n"])  # (len(p), len(x)), never negative

    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    colors = plt.cm.viridis(np.linspace(0, 1, len(data["curve_pressures_kpa"])))
    for color, pc in zip(colors, data["curve_pressures_kpa"]):
        k = int(np.argmin(np.abs(p - pc)))
        ax.plot(x, f[k], color=color, label=f"{pc / 100:.0f} bar")
    ax.set_xlabel("contraction [% of 260 mm]")
    ax.set_ylabel("force [N]")
    ax.set_title("DMSP-20 force-contraction (thesis Fig. 8.10)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, ncol=2)
    fig.tight_layout()
    fig.savefig(curves_png, dpi=120)
    plt.close(fig)

    fig = plt.figure(figsize=(6.5, 5))
    ax3 = fig.add_subplot(projection="3d")
    xx, pp = np.meshgrid(x, p)
    ax3.plot_surface(xx, pp / 100, f, cmap="viridis", linewidth=0)
    ax3.set_xlabel("contraction [%]")
    ax3.set_ylabel("pressure [bar]")
    ax3.set_zlabel("force [N]")
    ax3.set_title("F(x, P) polynomial (thesis Fig. 8.9)")
    fig.tight_layout()
    fig.savefig(surface_png, dpi=120)
    plt.close(fig)
    return Path(curves_png), Path(surface_png)


def openloop_movement(json_path: Path, movement: str, png_path: Path) -> Path:
    """Pressures, contractions and joint angle of one open-loop test (thesis Figs 10.6-10.23)."""
    data = json.loads(Path(json_path).read_text())
    r = data["movements"][movement]
    t = np.asarray(r["time_s"])
    fig, axes = plt.subplots(3, 1, figsize=(6, 7), sharex=True)
    p, c = np.asarray(r["pressure_kpa"]), np.asarray(r["contraction_pct"])
    for i, color in ((0, "tab:blue"), (1, "tab:red")):
        axes[0].plot(t, p[:, i] / 100, color=color, label=f"muscle {i + 1}")
        axes[1].plot(t, c[:, i], color=color, label=f"muscle {i + 1}")
    axes[2].plot(t, r["angle_deg"], color="k")
    axes[2].axhline(r["limit_deg"], color="gray", ls="--", label="limit")
    axes[0].set_ylabel("pressure [bar]")
    axes[1].set_ylabel("contraction [%]")
    axes[2].set_ylabel(f"{r['joint']} [deg]")
    axes[2].set_xlabel("time [s]")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(f"{movement.replace('_', ' ')} ({data['coupling']} coupling)")
    fig.tight_layout()
    fig.savefig(png_path, dpi=100)
    plt.close(fig)
    return Path(png_path)


def training_curves(csv_path: Path, png_path: Path) -> Path:
    """Episode reward, average reward and episode Q0 against episode (thesis Fig. 10.24)."""
    import csv

    rows = list(csv.DictReader(Path(csv_path).open()))
    fig, ax = plt.subplots(figsize=(8, 4.5))
    if rows:
        ep = np.array([int(r["episode"]) for r in rows])
        for key, label, style in (("reward", "episode reward", dict(color="tab:blue", alpha=0.45, lw=0.8)),
                                  ("avg_reward", "average reward", dict(color="tab:red", lw=1.8)),
                                  ("q0", "episode Q0", dict(color="tab:orange", lw=1.0))):
            ax.plot(ep, [float(r[key]) for r in rows], label=label, **style)
    ax.set_xlabel("episode")
    ax.set_ylabel("reward")
    ax.set_title(f"Training progress ({len(rows)} episodes; thesis Fig. 10.24)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return Path(png_path)
