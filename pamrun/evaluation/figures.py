"""The figures of training and evaluation runs, drawn from files on disk (csv, json, jsonl),
never from live objects: any figure can be redrawn from a finished run without re-simulating.

The bench's and the sweep's figures follow the same rule (:mod:`pamrun.bench.figures`,
:mod:`pamrun.sweep.figures`); :func:`save_figure` is every figure's last step.
"""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only, no display: set before pyplot loads
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pamrun.evaluation.metrics import contacts, gait_cycle, steady, touchdowns  # noqa: E402
from pamrun.physics.body import LEG_JOINTS, SIDES  # noqa: E402


def save_figure(fig, png_path: Path, dpi: int) -> Path:
    """Lay ``fig`` out, write it to ``png_path`` at ``dpi`` and close it: every figure's last step."""
    fig.tight_layout()
    fig.savefig(png_path, dpi=dpi)
    plt.close(fig)
    return Path(png_path)


def png_bytes(fig, dpi: int) -> bytes:
    """Lay ``fig`` out, encode it as PNG at ``dpi`` and close it (a figure for TensorBoard)."""
    out = io.BytesIO()
    fig.tight_layout()
    fig.savefig(out, format="png", dpi=dpi)
    plt.close(fig)
    return out.getvalue()


def training_curves(csv_path: Path, png_path: Path) -> Path:
    """Episode reward, average reward and episode Q0 against episode (thesis Fig. 10.24)."""
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
    return save_figure(fig, png_path, dpi=110)


def eval_curves(csv_path: Path, png_path: Path, walk_distance_m: float = 7.0, episode_s: float = 10.0) -> Path:
    """The evaluations during training (``evals.csv``) against frames: mean and minimum
    distance, mean duration, the stand and walk-test pass rates, the pass rate with the
    perturbed selection episodes (``train.select_perturbations``; where a run has them) and
    the evaluation whose agent is ``best_eval.pt``."""
    rows = list(csv.DictReader(Path(csv_path).open()))
    frames = np.array([int(r["frames"]) for r in rows])
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    col = lambda key: np.array([float(r[key]) for r in rows])  # noqa: E731
    if rows:
        top.plot(frames, col("distance_mean"), "o-", color="tab:blue", label="distance, mean (m)")
        top.plot(frames, col("distance_min"), ".--", color="tab:blue", alpha=0.5, label="distance, min (m)")
        top.axhline(walk_distance_m, color="tab:green", lw=0.8, ls=":", label=f"walk test: {walk_distance_m:g} m")
        twin = top.twinx()
        twin.plot(frames, col("duration_mean"), "s-", color="tab:orange", label="duration, mean (s)")
        twin.set_ylim(0, episode_s * 1.05)
        twin.set_ylabel("duration (s)")
        twin.legend(loc="lower right")
        bottom.plot(frames, col("stand_rate"), "o-", color="tab:orange", label="stand rate")
        bottom.plot(frames, col("walk_pass_rate"), "o-", color="tab:green", label="walk-test pass rate")
        bottom.plot(frames, col("fall_rate"), ".-", color="tab:red", alpha=0.6, label="fall rate")
        select = np.array([float(r.get("select_pass_rate") or "nan") for r in rows])
        if not np.allclose(select, col("walk_pass_rate"), equal_nan=True):  # a run selecting under perturbation
            bottom.plot(frames, select, "^-", color="tab:purple", label="pass rate, with perturbed episodes")
        kept = [int(r["frames"]) for r in rows if r.get("best") == "1"]
        if kept:
            bottom.axvline(kept[-1], color="k", lw=0.8, ls="--", label="best_eval.pt")
    top.set_ylabel("distance (m)")
    top.set_title(f"Evaluations during training ({len(rows)}; deterministic policy, fixed seeds)")
    top.legend(loc="upper left")
    bottom.set_ylim(-0.05, 1.05)
    bottom.set_xlabel("frames")
    bottom.set_ylabel("share of episodes")
    bottom.legend(loc="upper left")
    for ax in (top, bottom):
        ax.grid(alpha=0.3)
    return save_figure(fig, png_path, dpi=110)


def video_frames(mp4_path: Path, png_path: Path, n: int = 8, every_s: float = 0.1, width_share: float = 1.0,
                 from_start: bool = False) -> Path:
    """``n`` frames of a video ``every_s`` apart about its middle (8 x 0.1 s: about a stride of the
    walkers; ``from_start``: its first ones; a video too short for them: ``n`` evenly over it) side
    by side, each labelled with its time; ``width_share`` < 1 keeps that share of each frame's
    width, about its centre."""
    # PyAV (FFmpeg) is heavy: only eval.render's video needs it, and training imports this module
    from pamrun.evaluation.video import picked_frames

    times, frames = picked_frames(mp4_path, n, every_s, from_start)
    height, width = frames[0].shape[:2]
    cut = int(round(width * (1 - width_share) / 2))
    fig, axes = plt.subplots(1, len(frames), figsize=(2.3 * (width - 2 * cut) / height * len(frames), 2.75))
    for ax, t, frame in zip(np.atleast_1d(axes), times, frames):
        ax.imshow(frame[:, cut:width - cut])
        ax.set_title(f"t = {t:.2f} s", fontsize=9)
        ax.axis("off")
    return save_figure(fig, png_path, dpi=100)


def read_episodes_jsonl(jsonl_path: Path, agents: set[str] | None = None) -> list[dict]:
    """Episode records of an evaluation (``episodes.jsonl``), optionally of some agents only."""
    prefixes = None if agents is None else tuple('{"agent": ' + json.dumps(a) + "," for a in agents)
    with Path(jsonl_path).open() as fh:
        return [json.loads(line) for line in fh if prefixes is None or line.startswith(prefixes)]


def trajectories(jsonl_path: Path, leaderboard_path: Path, png_path: Path, top_k: int = 5,
                 lateral_m: float = 0.5) -> Path:
    """x-y paths of the best ``top_k`` agents with the lateral band (thesis Fig. 10.25).

    Each agent's first episode is drawn solid, its other episodes faint.
    """
    board = json.loads(Path(leaderboard_path).read_text())
    top = [row["agent"] for row in board["agents"][:top_k]]
    episodes = read_episodes_jsonl(jsonl_path, set(top))
    fig, ax = plt.subplots(figsize=(9, 4.5))
    colors = plt.cm.tab10(np.arange(len(top)) % 10)
    x_max = 1.0
    for color, row in zip(colors, board["agents"][:top_k]):
        mine = [e for e in episodes if e["agent"] == row["agent"]]
        for e in mine:
            x, y = np.asarray(e["steps"]["x_m"]), np.asarray(e["steps"]["y_m"])
            first = e["episode"] == 0
            ax.plot(x, y, color=color, lw=1.6 if first else 0.6, alpha=1.0 if first else 0.35,
                    label=f"#{row['rank']} {row['agent']} ({row['distance_mean']:.2f} m)" if first else None)
            ax.plot(x[-1], y[-1], "x" if e["fell"] else "o", color=color, ms=5 if first else 3)
            x_max = max(x_max, float(np.max(x)))
    ax.axhspan(-lateral_m, lateral_m, color="tab:green", alpha=0.07, label=f"±{lateral_m} m band")
    for yb in (-lateral_m, lateral_m):
        ax.axhline(yb, color="tab:green", lw=1, ls="--")
    ax.axhline(0.0, color="k", lw=0.8, ls=":", label="straight line")
    ax.set_xlim(min(-0.1, ax.get_xlim()[0]), x_max * 1.05)
    ax.set_ylim(-1.6 * lateral_m, 1.6 * lateral_m)
    ax.set_xlabel("x, forward [m]")
    ax.set_ylabel("y, lateral [m]")
    ax.set_title(f"Paths of the best {len(top)} agents (o: end, x: fall; thesis Fig. 10.25)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return save_figure(fig, png_path, dpi=110)


def pressures(jsonl_path: Path, agent: str, episode: int, png_path: Path) -> Path:
    """Both muscle pressures of every joint pair, with the joint angle, over one episode
    (thesis Figs 10.26-10.31): rows are joints, columns the right and left leg."""
    record = next(e for e in read_episodes_jsonl(jsonl_path, {agent}) if e["episode"] == episode)
    s = record["steps"]
    t = np.asarray(s["t_s"])
    p = np.asarray(s["pressure_kpa"]).reshape(len(t), -1, 2) / 100.0  # bar
    angle = np.rad2deg(np.asarray(s["joint_angle_rad"]))
    fig, axes = plt.subplots(len(LEG_JOINTS), len(SIDES), figsize=(11, 11), sharex=True, squeeze=False)
    for col, side in enumerate(SIDES):
        for row, joint in enumerate(LEG_JOINTS):
            j = col * len(LEG_JOINTS) + row
            ax = axes[row, col]
            ax.plot(t, p[:, j, 0], color="tab:blue", lw=1, label="muscle 1 (+)")
            ax.plot(t, p[:, j, 1], color="tab:red", lw=1, label="muscle 2 (-)")
            ax.set_ylabel("pressure [bar]", fontsize=8)
            ax.set_title(f"{side} {joint.replace('_', ' ')}", fontsize=9)
            ax.grid(alpha=0.3)
            twin = ax.twinx()
            twin.plot(t, angle[:, j], color="k", lw=0.8, alpha=0.7, label="angle")
            twin.set_ylabel("angle [deg]", fontsize=8)
            if row == 0 and col == 0:
                lines = ax.get_lines()[:2] + twin.get_lines()
                ax.legend(lines, [ln.get_label() for ln in lines], fontsize=7, loc="upper right")
    for ax in axes[-1]:
        ax.set_xlabel("time [s]")
    outcome = "fell" if record["fell"] else "no fall"
    fig.suptitle(f"Muscle pressures of {agent}, episode {episode} (seed {record['seed']}): "
                 f"{record['distance_m']:.2f} m in {record['duration_s']:.2f} s, {outcome} (thesis Figs 10.26-10.31)",
                 fontsize=10)
    return save_figure(fig, png_path, dpi=100)


def control_step_s(t: np.ndarray) -> float:
    """The control step [s] of an episode's row times ``t`` (its first time when it has one row)."""
    return float(np.median(np.diff(t))) if len(t) > 1 else float(t[0])


def _strides(episodes: list[dict], contact_threshold_n: float) -> tuple[np.ndarray | None, dict[str, list]]:
    """Each leg's joint angles over its strides (touchdown to touchdown of its foot), in deg:
    the gait-cycle grid (None without episodes) and per side a list of (k, points, 5) arrays."""
    strides = {side: [] for side in SIDES}
    grid = None
    for e in episodes:
        s = e["steps"]
        if not len(s["t_s"]):
            continue
        angle = np.rad2deg(np.asarray(s["joint_angle_rad"], float)).reshape(len(s["t_s"]), len(SIDES), -1)
        t = np.asarray(s["t_s"], float)
        dt = control_step_s(t)
        for foot, (side, rows) in enumerate(zip(SIDES, touchdowns(steady(contacts(s, contact_threshold_n), dt)))):
            grid, cycles = gait_cycle(angle[:, foot], rows)
            strides[side].append(cycles)
    return grid, strides


def _footfalls(ax, episodes: list[dict], contact_threshold_n: float, footfall_s: float, colors: dict) -> None:
    """Footfall diagram on ``ax``: when each foot is down in the first ``footfall_s`` s of the first episode."""
    if episodes and len(episodes[0]["steps"]["t_s"]):
        s = episodes[0]["steps"]
        t = np.asarray(s["t_s"], float)
        dt = control_step_s(t)
        down = contacts(s, contact_threshold_n)
        for foot, side in enumerate(SIDES):
            edges = np.diff(np.concatenate(([0], down[:, foot].astype(int), [0])))
            runs = [(t[a] - dt, (b - a) * dt) for a, b in zip(np.flatnonzero(edges > 0), np.flatnonzero(edges < 0))]
            ax.broken_barh([r for r in runs if r[0] < footfall_s], (1 - foot - 0.35, 0.7), color=colors[side])
        first = episodes[0]
        label = f"episode {first.get('episode', 0)}" + (f", seed {first['seed']}" if "seed" in first else "")
        ax.set_xlim(0, min(footfall_s, t[-1]))
    else:
        label = "no steps"
    ax.set_yticks([1, 0], [f"{side} foot" for side in SIDES])
    ax.set_ylim(-0.6, 1.6)
    ax.set_xlabel("time [s]")
    ax.set_title(f"Footfalls ({label}; foot down above {contact_threshold_n:.0f} N)", fontsize=10)
    ax.grid(alpha=0.3, axis="x")


def gait(episodes: list[dict], joint_limits_rad, contact_threshold_n: float, png_path: Path,
         footfall_s: float = 5.0) -> Path:
    """``gait.png``: :func:`gait_figure` of ``episodes``."""
    return save_figure(gait_figure(episodes, joint_limits_rad, contact_threshold_n, footfall_s), png_path, dpi=110)


def gait_figure(episodes: list[dict], joint_limits_rad, contact_threshold_n: float, footfall_s: float = 5.0):
    """Left and right joint angles over the gait cycle, and a footfall diagram (a matplotlib figure).

    ``episodes``: records as read from ``episodes.jsonl`` (each with its ``steps``);
    ``joint_limits_rad``: the (10, 2) limits in JOINTS order; ``contact_threshold_n``: a foot
    is down above it (``GaitSpec.contact_threshold_n``). Top: one panel per leg joint, each
    leg over its own strides (touchdown to touchdown of its foot, resampled to 0-100 % and
    pooled over the episodes): mean line and a +-1 std band, the leg's stops dashed (the
    right leg mirrors the roll joints' stops). Bottom: when each foot is down during the first
    ``footfall_s`` seconds of the first episode.
    """
    limits = np.rad2deg(np.asarray(joint_limits_rad, float).reshape(-1, 2))
    colors = {"right": "tab:blue", "left": "tab:red"}
    grid, strides = _strides(episodes, contact_threshold_n)
    fig = plt.figure(figsize=(3.2 * len(LEG_JOINTS), 6.4))
    grid_spec = fig.add_gridspec(2, len(LEG_JOINTS), height_ratios=(2.2, 1.0))
    for j, joint in enumerate(LEG_JOINTS):
        ax = fig.add_subplot(grid_spec[0, j])
        drawn = False
        for k, side in enumerate(SIDES):
            color = colors[side]
            cycles = np.concatenate(strides[side]) if strides[side] else np.empty((0, 0, 0))
            if len(cycles):
                mean, std = cycles[:, :, j].mean(axis=0), cycles[:, :, j].std(axis=0)
                ax.plot(grid, mean, color=color, lw=1.5, label=f"{side} ({len(cycles)} strides)")
                ax.fill_between(grid, mean - std, mean + std, color=color, alpha=0.2)
                drawn = True
            for bound in limits[k * len(LEG_JOINTS) + j]:
                ax.axhline(bound, color=color, ls="--", lw=0.9, alpha=0.7)
        if not drawn:
            ax.text(0.5, 0.5, "no full stride", transform=ax.transAxes, ha="center", va="center", color="0.4")
        ax.set_xlim(0, 100)
        ax.set_title(joint.replace("_", " "), fontsize=10)
        ax.set_xlabel("gait cycle [%]")
        ax.grid(alpha=0.3)
        if j == 0:
            ax.set_ylabel("angle [deg] (dashed: stops)")
            if drawn:
                ax.legend(fontsize=7)

    _footfalls(fig.add_subplot(grid_spec[1, :]), episodes, contact_threshold_n, footfall_s, colors)
    fig.suptitle(f"Gait: joint angles over each leg's stride (touchdown to touchdown of its foot), mean ± std "
                 f"of {len(episodes)} episodes; dashed: the stops", fontsize=11)
    return fig


def robustness(json_path: Path, png_path: Path) -> Path:
    """Heat map of ``robustness.json``: agents (rows) x perturbations (columns), coloured by the
    walk-test pass rate, each cell labelled with its passes of episodes and 95 % interval."""
    data = json.loads(Path(json_path).read_text())
    agents, names = data["agents"], list(data["perturbations"])
    rows = {(r["agent"], r["perturbation"]): r for r in data["rows"]}
    rate = np.array([[rows[a, n]["walk_pass_rate"] for n in names] for a in agents])
    fig, ax = plt.subplots(figsize=(2.5 + 0.95 * len(names), 2.6 + 0.6 * len(agents)))
    image = ax.imshow(rate, cmap="RdYlGn", vmin=0.0, vmax=1.0, aspect="auto")
    for i, a in enumerate(agents):
        for j, n in enumerate(names):
            r = rows[a, n]
            ax.text(j, i, f"{r['walk_passes']}/{r['episodes']}\n{100 * r['walk_pass_ci_low']:.0f}-"
                          f"{100 * r['walk_pass_ci_high']:.0f} %", ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(names)), [f"{n}\n({data['perturbations'][n]['note']})" for n in names], rotation=40,
                  ha="right", fontsize=7)
    ax.set_yticks(range(len(agents)), agents, fontsize=7)
    fig.colorbar(image, ax=ax, label="walk-test pass rate", fraction=0.025, pad=0.01)
    ax.set_title(f"Robustness: walk-test passes of {data['episodes']} episodes per cell, seeds "
                 f"{data['seeds'][0]}..{data['seeds'][1]} (95 % Wilson interval)", fontsize=9)
    return save_figure(fig, png_path, dpi=110)


def speed(episodes: list[dict], png_path: Path, max_episodes: int = 5) -> Path:
    """Commanded speed v* (a step line) against the measured forward speed (over
    :data:`pamrun.evaluation.tracking.SMOOTH_S` windows) over time, for the first
    ``max_episodes`` episodes of ``episodes`` (records of ``episodes.jsonl``, with steps)."""
    from pamrun.evaluation.tracking import SMOOTH_S, smoothed_speed

    fig, ax = plt.subplots(figsize=(9, 4))
    colors = plt.cm.tab10(np.arange(max_episodes) % 10)
    for color, e in zip(colors, episodes[:max_episodes]):
        s = e["steps"]
        t, command = np.asarray(s["t_s"]), np.asarray(s.get("target_speed_m_s", []))
        if len(command):
            ax.step(np.r_[0.0, t], np.r_[command[0], command], where="post", color=color, lw=2.2, alpha=0.45)
        ts, measured = smoothed_speed(t, s["x_m"], SMOOTH_S)
        rms = e.get("speed_tracking_rms_m_s", float("nan"))
        ax.plot(ts, measured, color=color, lw=1.0,
                label=f"{e['agent']} ep {e['episode']}: tracking RMS {rms:.2f} m/s" + (" (fell)" if e["fell"] else ""))
    ax.plot([], [], color="grey", lw=2.2, alpha=0.45, label="commanded v*")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("forward speed [m/s]")
    ax.set_title(f"Commanded against measured speed (measured over {SMOOTH_S} s windows)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return save_figure(fig, png_path, dpi=110)
