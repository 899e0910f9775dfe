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


def _save(fig, png_path: Path, dpi: int) -> Path:
    """Lay ``fig`` out, write it to ``png_path`` at ``dpi`` and close it: every figure's last step."""
    fig.tight_layout()
    fig.savefig(png_path, dpi=dpi)
    plt.close(fig)
    return Path(png_path)


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
    return _save(fig, png_path, dpi=120)


def valve_step(json_path: Path, png_path: Path) -> Path:
    """A regulator's pressure after a step command, model=lag against model=flow, per contraction
    (colour) and muscles filled by one valve (line style)."""
    data = json.loads(Path(json_path).read_text())
    cases = data["cases"]
    contractions = sorted({c["contraction_pct"] for c in cases if c["model"] == "flow"})
    colors = dict(zip(contractions, plt.cm.viridis(np.linspace(0.1, 0.8, len(contractions)))))
    styles = {1: "-", 2: "--", 3: ":", 4: "-."}
    fig, ax = plt.subplots(figsize=(7, 4.2))
    lag = next(c for c in cases if c["model"] == "lag")
    t = np.arange(len(lag["pressure_kpa"])) * data["every_s"]
    ax.plot(t, lag["pressure_kpa"], color="k", lw=2.2, alpha=0.6,
            label=f"lag {1000 * data['regulator']['lag_s']:.0f} ms (any volume): 10-90 % "
                  f"{1000 * lag['rise_10_90_s']:.0f} ms")
    for c in cases:
        if c["model"] != "flow":
            continue
        rise = "never" if c["rise_10_90_s"] is None else f"{1000 * c['rise_10_90_s']:.0f} ms"
        ax.plot(t, c["pressure_kpa"], color=colors[c["contraction_pct"]], ls=styles.get(c["muscles_per_side"], "-"),
                label=f"flow, {c['contraction_pct']:.0f} %, {c['muscles_per_side']} muscle(s) "
                      f"({c['volume_l']:.2f} l): {rise}")
    for share in (0.1, 0.9):
        ax.axhline(share * data["step_kpa"], color="gray", lw=0.8, ls=":")
    reg = data["regulator"]
    ax.set_title(f"Regulator step 0 -> {data['step_kpa']:.0f} kPa, {data['size']} "
                 f"{1000 * data['nominal_length_m']:.0f} mm; valve {reg['nominal_flow_nl_min']:.0f} Nl/min, "
                 f"supply {reg['supply_pressure_kpa']:.0f} kPa", fontsize=9)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("pressure [kPa]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    return _save(fig, png_path, dpi=110)


def hysteresis_loop(json_path: Path, png_path: Path) -> Path:
    """Force against contraction of one muscle at constant pressure, cycled sinusoidally: without
    hysteresis (dashed, one curve) and with the Maxwell-slip elements (solid, a loop), per pressure;
    right, the elements' part alone (with - without: -H, the loop itself)."""
    data = json.loads(Path(json_path).read_text())
    x = np.asarray(data["contraction_pct"])
    second = slice(data["steps_per_cycle"], None)  # the steady cycle (the first starts at rest)
    colors = plt.cm.viridis(np.linspace(0.1, 0.75, len(data["cases"])))
    fig, (ax, right) = plt.subplots(1, 2, figsize=(11, 4.4), gridspec_kw={"width_ratios": [1.4, 1]})
    for color, case in zip(colors, data["cases"]):
        bar = case["pressure_kpa"] / 100
        none, slip = np.asarray(case["force_none_n"])[second], np.asarray(case["force_slip_n"])[second]
        ax.plot(x[second], none, color=color, ls="--", lw=1.2, label=f"{bar:g} bar, none: {case['area_none_j']:.1e} J")
        ax.plot(x[second], slip, color=color, lw=1.6, label=f"{bar:g} bar, maxwell_slip: {case['area_slip_j']:.3f} J "
                                                           f"(analytic {case['analytic_area_j']:.3f} J)")
        right.plot(x[second], slip - none, color=color, lw=1.6, label=f"{bar:g} bar")
    ax.set_title(f"Muscle hysteresis: {data['size']} {1000 * data['nominal_length_m']:.0f} mm, contraction "
                 f"{data['center_pct']:g} +- {data['amplitude_pct']:g} %; loop area per cycle", fontsize=9)
    right.set_title("the elements' force, with - without hysteresis", fontsize=9)
    for a in (ax, right):
        a.set_xlabel("contraction [%]")
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    ax.set_xlabel("contraction [%]  (lower branch: contracting, upper: extending)")
    ax.set_ylabel("force [N]")
    right.set_ylabel("force difference [N]")
    return _save(fig, png_path, dpi=110)


LAW_STYLES = ("-", "--", ":", "-.")  # line style of each force law, in FORCE_LAWS' order (polynomial solid)


def _law_panel(ax, x: np.ndarray, pressures: list[float], curves: dict[str, list], points: list[dict]) -> None:
    """Each law's force against contraction at ``pressures`` (one colour each, one line style
    per law), and ``points`` (measured force at a pressure) as markers in their pressure's colour."""
    colors = dict(zip(pressures, plt.cm.viridis(np.linspace(0, 0.9, len(pressures)))))
    for style, (name, rows) in zip(LAW_STYLES, curves.items()):
        for pressure, row in zip(pressures, rows):
            ax.plot(x, row, color=colors[pressure], ls=style, lw=1.3)
        ax.plot([], [], color="k", ls=style, label=name)
    for pressure in pressures:
        ax.plot([], [], color=colors[pressure], lw=4, label=f"{pressure / 100:g} bar")
    for point in points:
        ax.plot(point["contraction_pct"], point["force_n"], "o", color=colors[point["pressure_kpa"]], mec="k")
    ax.set_xlabel("contraction [% of nominal length]")
    ax.set_ylabel("force [N]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)


def force_curves(json_path: Path, curves_png: Path, surface_png: Path) -> tuple[Path, Path]:
    """Force against contraction per pressure (Fig. 8.10) for every force law, the measured
    DMSP-20-300 points among them, and the configured law's F(x, P) surface (Fig. 8.9)."""
    data = json.loads(Path(json_path).read_text())
    x = np.asarray(data["contraction_pct"])
    p = np.asarray(data["pressure_kpa"])
    f = np.asarray(data["force_n"])  # (len(p), len(x)), never negative
    law = data.get("force_law", "thesis_polynomial")
    # a file from before the laws were compared holds the configured law's surface only
    curves = data.get("curves_n") or {law: [f[int(np.argmin(np.abs(p - pc)))] for pc in data["curve_pressures_kpa"]]}

    measured = data.get("measured")
    fig, axes = plt.subplots(1, 2 if measured else 1, figsize=(13 if measured else 6.5, 4.5), squeeze=False)
    _law_panel(axes[0, 0], x, data["curve_pressures_kpa"], curves, [])
    axes[0, 0].set_title("DMSP-20 force-contraction (thesis Fig. 8.10)")
    if measured:
        _law_panel(axes[0, 1], x, data["measured_pressures_kpa"], data["measured_curves_n"], measured["points"])
        axes[0, 1].set_title(f"Measured (markers): {measured['source']}", fontsize=10)
    curves_path = _save(fig, curves_png, dpi=120)

    fig = plt.figure(figsize=(6.5, 5))
    ax3 = fig.add_subplot(projection="3d")
    xx, pp = np.meshgrid(x, p)
    ax3.plot_surface(xx, pp / 100, f, cmap="viridis", linewidth=0)
    ax3.set_xlabel("contraction [%]")
    ax3.set_ylabel("pressure [bar]")
    ax3.set_zlabel("force [N]")
    ax3.set_title(f"F(x, P), {law} (thesis Fig. 8.9)")
    return curves_path, _save(fig, surface_png, dpi=120)


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
    return _save(fig, png_path, dpi=100)


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
    return _save(fig, png_path, dpi=110)


def eval_curves(csv_path: Path, png_path: Path, walk_distance_m: float = 7.0, episode_s: float = 10.0) -> Path:
    """The evaluations during training (``evals.csv``) against frames: mean and minimum
    distance, mean duration, the stand and walk-test pass rates, the pass rate with the
    perturbed selection episodes (``train.select_perturbations``; where a run has them) and
    the evaluation whose agent is ``best_eval.pt``."""
    import csv

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
    return _save(fig, png_path, dpi=110)


def video_frames(mp4_path: Path, png_path: Path, n: int = 5, dt_s: float = 0.025) -> Path:
    """``n`` evenly spaced frames of a video side by side, each labelled with its time."""
    import av

    with av.open(str(mp4_path)) as container:
        frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    picks = np.linspace(0, len(frames) - 1, min(n, len(frames))).round().astype(int)
    fig, axes = plt.subplots(1, len(picks), figsize=(3.2 * len(picks), 2.6))
    for ax, k in zip(np.atleast_1d(axes), picks):
        ax.imshow(frames[k])
        ax.set_title(f"t = {k * dt_s:.2f} s", fontsize=9)
        ax.axis("off")
    return _save(fig, png_path, dpi=100)


def read_episodes(jsonl_path: Path, agents: set[str] | None = None) -> list[dict]:
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
    episodes = read_episodes(jsonl_path, set(top))
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
    return _save(fig, png_path, dpi=110)


def pressures(jsonl_path: Path, agent: str, episode: int, png_path: Path) -> Path:
    """Both muscle pressures of every joint pair, with the joint angle, over one episode
    (thesis Figs 10.26-10.31): rows are joints, columns the right and left leg."""
    from pamrun.physics.body import LEG_JOINTS, SIDES

    record = next(e for e in read_episodes(jsonl_path, {agent}) if e["episode"] == episode)
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
    return _save(fig, png_path, dpi=100)


def sweep_curves(groups: list[tuple[str, list[Path]]], png_path: Path, points: int = 100) -> Path:
    """Average reward against frames per sweep group: mean over its seeds with a shaded 95 %
    interval (Student's t), each run's ``episodes.csv`` interpolated onto a common frame grid."""
    import csv

    from scipy import stats

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
    return _save(fig, png_path, dpi=110)


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
    return _save(fig, png_path, dpi=110)


def capacity(json_path: Path, png_path: Path) -> Path:
    """Torque envelope of each joint against its walking and standing demand (pamrun capacity)."""
    data = json.loads(Path(json_path).read_text())
    joints = data["joints"]
    fig, axes = plt.subplots(1, len(joints), figsize=(3.6 * len(joints), 3.8), squeeze=False)
    need = data["required_margin"]
    for ax, (name, r) in zip(axes[0], joints.items()):
        angle = np.asarray(r["angle_deg"])
        for label, style in (("band", "-"), ("full", "--")):
            env = r["envelope"][label]
            legend = label == "band"
            ax.plot(angle, env["plus_nm"], "tab:blue", ls=style, lw=1.4, label="band +" if legend else None)
            ax.plot(angle, env["minus_nm"], "tab:red", ls=style, lw=1.4, label="band -" if legend else None)
        lo, hi = r["walking_range_deg"]
        ax.axvspan(lo, hi, color="0.9", zorder=0, label="walking range")
        d = r["walking_demand_nm"]
        for sign in (1, -1):
            ax.hlines(sign * d, lo, hi, colors="k", lw=1.2, label="walking peak" if sign > 0 else None)
            ax.hlines(sign * need * d, lo, hi, colors="k", lw=1, linestyles=":",
                      label=f"x{need}" if sign > 0 else None)
            ax.hlines(sign * r["lean_demand_nm"], angle[0], angle[-1], colors="tab:green", lw=1,
                      label=f"{data['lean_deg']:.0f} deg lean" if sign > 0 else None)
        ax.axhline(0, color="0.5", lw=0.5)
        ax.set_title(f"{name}: margin {r['walking_margin']:.2f}\n{r['muscles_per_direction']} x "
                     f"{data['muscle']['size']}, r {r['radius_mm']:.0f} mm", fontsize=9)
        ax.set_xlabel("joint angle [deg]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("torque [N m] (dashed: full pressure)")
    axes[0][0].legend(fontsize=7, loc="lower left")
    fig.suptitle(f"Capacity vs demand ({data['coupling']} coupling, band {data['band_kpa'][1]:.0f}-"
                 f"{data['band_kpa'][0]:.0f} kPa, robot {data['robot_mass_kg']:.1f} kg)", fontsize=10)
    return _save(fig, png_path, dpi=110)


def _strides(episodes: list[dict], contact_threshold_n: float) -> tuple[np.ndarray | None, dict[str, list]]:
    """Each leg's joint angles over its strides (touchdown to touchdown of its foot), in deg:
    the gait-cycle grid (None without episodes) and per side a list of (k, points, 5) arrays."""
    from pamrun.evaluation.metrics import contacts, gait_cycle, touchdowns
    from pamrun.physics.body import SIDES

    strides = {side: [] for side in SIDES}
    grid = None
    for e in episodes:
        s = e["steps"]
        if not len(s["t_s"]):
            continue
        angle = np.rad2deg(np.asarray(s["joint_angle_rad"], float)).reshape(len(s["t_s"]), len(SIDES), -1)
        for foot, (side, rows) in enumerate(zip(SIDES, touchdowns(contacts(s, contact_threshold_n)))):
            grid, cycles = gait_cycle(angle[:, foot], rows)
            strides[side].append(cycles)
    return grid, strides


def _footfalls(ax, episodes: list[dict], contact_threshold_n: float, footfall_s: float, colors: dict) -> None:
    """Footfall diagram on ``ax``: when each foot is down in the first ``footfall_s`` s of the first episode."""
    from pamrun.evaluation.metrics import contacts
    from pamrun.physics.body import SIDES

    if episodes and len(episodes[0]["steps"]["t_s"]):
        s = episodes[0]["steps"]
        t = np.asarray(s["t_s"], float)
        dt = float(np.median(np.diff(t))) if len(t) > 1 else float(t[0])
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
    """Left and right joint angles over the gait cycle, and a footfall diagram (``gait.png``).

    ``episodes``: records as read from ``episodes.jsonl`` (each with its ``steps``);
    ``joint_limits_rad``: the (10, 2) limits in JOINTS order; ``contact_threshold_n``: a foot
    is down above it (``GaitSpec.contact_threshold_n``). Top: one panel per leg joint, each
    leg over its own strides (touchdown to touchdown of its foot, resampled to 0-100 % and
    pooled over the episodes): mean line and a +-1 std band, the leg's stops dashed (the
    right leg mirrors the roll joints' stops). Bottom: when each foot is down during the first
    ``footfall_s`` seconds of the first episode.
    """
    from pamrun.physics.body import LEG_JOINTS, SIDES

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
    return _save(fig, png_path, dpi=110)


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
    return _save(fig, png_path, dpi=110)
