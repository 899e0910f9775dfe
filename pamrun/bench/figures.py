"""The bench's figures (``pamrun muscle ...``, ``openloop``, ``capacity``), each drawn from the
json file its command wrote, so any of them can be redrawn without re-simulating."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from pamrun.evaluation.figures import save_figure  # importing it selects Matplotlib's Agg backend


def record(out: Path, stem: str, data: dict, draw: Callable[[Path, Path], object]) -> Path:
    """Write ``data`` to ``<stem>.json`` in ``out``, then ``draw`` ``<stem>.png`` from that file; the json's path."""
    path = out / f"{stem}.json"
    path.write_text(json.dumps(data))
    draw(path, out / f"{stem}.png")
    return path


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
    return save_figure(fig, png_path, dpi=120)


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
    return save_figure(fig, png_path, dpi=110)


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
    return save_figure(fig, png_path, dpi=110)


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
    # without curves_n (only the configured law's surface), its curves are read off the surface
    curves = data.get("curves_n") or {law: [f[int(np.argmin(np.abs(p - pc)))] for pc in data["curve_pressures_kpa"]]}

    measured = data.get("measured")
    fig, axes = plt.subplots(1, 2 if measured else 1, figsize=(13 if measured else 6.5, 4.5), squeeze=False)
    _law_panel(axes[0, 0], x, data["curve_pressures_kpa"], curves, [])
    axes[0, 0].set_title("DMSP-20 force-contraction (thesis Fig. 8.10)")
    if measured:
        _law_panel(axes[0, 1], x, data["measured_pressures_kpa"], data["measured_curves_n"], measured["points"])
        axes[0, 1].set_title(f"Measured (markers): {measured['source']}", fontsize=10)
    curves_path = save_figure(fig, curves_png, dpi=120)

    fig = plt.figure(figsize=(6.5, 5))
    ax3 = fig.add_subplot(projection="3d")
    xx, pp = np.meshgrid(x, p)
    ax3.plot_surface(xx, pp / 100, f, cmap="viridis", linewidth=0)
    ax3.set_xlabel("contraction [%]")
    ax3.set_ylabel("pressure [bar]")
    ax3.set_zlabel("force [N]")
    ax3.set_title(f"F(x, P), {law} (thesis Fig. 8.9)")
    return curves_path, save_figure(fig, surface_png, dpi=120)


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
    return save_figure(fig, png_path, dpi=100)


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
    return save_figure(fig, png_path, dpi=110)
