"""Bench experiments on the physics, as the thesis ran them (§10.1): ``pamrun muscle ...``.

Each function is a Hydra task: it takes the composed config, writes its files into the
run directory, prints where, and shows a rich table of what it measured.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from omegaconf import DictConfig
from rich.console import Console
from rich.table import Table

from pamrun import plots
from pamrun.config import SPRING_FILE, Config, to_object
from pamrun.muscle import FORCE_LAWS, calibrate_spring, simulate_step

console = Console()


def run_dir() -> Path:
    """The Hydra run directory of this job (created by Hydra), announced on the console."""
    from hydra.core.hydra_config import HydraConfig

    path = Path(HydraConfig.get().runtime.output_dir)
    console.print(f"Run directory: [bold]{path}[/bold]")
    return path


def step_responses(cfg: Config, every_s: float = 0.01) -> dict:
    """Simulate every §10.1 experiment; keep the series at ``every_s`` for plotting."""
    keep = max(1, int(round(every_s / cfg.pair.dt_s)))
    out = {}
    for name, exp in cfg.pair.experiments.items():
        sim = simulate_step(cfg.muscle, cfg.pair, exp)
        final = sim["contraction_pct"][-1]
        out[name] = {
            "label": exp.label,
            "pressure_kpa": [exp.pressure1_kpa, exp.pressure2_kpa],
            "final_contraction_pct": [round(float(v), 4) for v in final],
            "thesis_final_pct": list(exp.thesis_final_pct),
            "error_points": [round(float(a - b), 4) for a, b in zip(final, exp.thesis_final_pct)],
            "time_s": sim["time_s"][::keep].round(4).tolist(),
            "contraction_pct": sim["contraction_pct"][::keep].round(4).tolist(),
        }
    return out


def print_step_table(results: dict, tolerance_pct: float) -> bool:
    """Rich table of final contractions beside the thesis; True if all within tolerance."""
    table = Table(title="Antagonistic pair step responses (thesis §10.1)")
    for col in ("experiment", "muscle", "pressure (kPa)", "pamrun (%)", "thesis (%)", "error (points)"):
        table.add_column(col, justify="left" if col in ("experiment",) else "right")
    ok = True
    for name, r in results.items():
        for i in range(2):
            err = r["error_points"][i]
            ok &= abs(err) <= tolerance_pct
            style = "green" if abs(err) <= tolerance_pct else "red"
            table.add_row(
                r["label"] or name if i == 0 else "",
                str(i + 1),
                f"{r['pressure_kpa'][i]:.1f}",
                f"{r['final_contraction_pct'][i]:.2f}",
                f"{r['thesis_final_pct'][i]:.2f}",
                f"[{style}]{err:+.3f}[/{style}]",
            )
    console.print(table)
    verdict = "[green]yes[/green]" if ok else "[red]NO[/red]"
    console.print(f"All final contractions within {tolerance_pct} points of the thesis: {verdict}")
    return ok


def muscle_step(dcfg: DictConfig) -> None:
    """``pamrun muscle step``: both §10.1 experiments -> step_response.json/.png."""
    cfg: Config = to_object(dcfg)
    out = run_dir()
    results = step_responses(cfg)
    path = out / "step_response.json"
    path.write_text(json.dumps({"spring_n_per_m": list(cfg.muscle.spring.stiffness_n_per_m), "experiments": results}))
    plots.step_response(path, out / "step_response.png")
    print_step_table(results, cfg.pair.tolerance_pct)
    console.print(f"Wrote {path.name}, step_response.png")


def muscle_calibrate(dcfg: DictConfig) -> None:
    """``pamrun muscle calibrate``: fit S(P), write it as YAML, show the step responses."""
    cfg: Config = to_object(dcfg)
    out = run_dir()
    table, fitted = calibrate_spring(cfg.muscle, cfg.pair)
    spring = replace(cfg.muscle.spring, stiffness_n_per_m=table)
    cfg = replace(cfg, muscle=replace(cfg.muscle, spring=spring))

    edges = spring.band_edges_kpa
    rich_table = Table(title="Fitted spring table S(P)")
    for col in ("band (kPa)", "S (N/m)", "D = tau*S (N s/m)", "source"):
        rich_table.add_column(col, justify="right")
    for k, s in enumerate(table):
        source = "fitted" if k in fitted else "interpolated"
        rich_table.add_row(f"{edges[k]:.0f}-{edges[k + 1]:.0f}", f"{s:.3f}", f"{cfg.muscle.tau_s * s:.3f}", source)
    console.print(rich_table)

    text = spring_yaml(edges, table, fitted)
    (out / "spring_table.yaml").write_text(text)
    written = ["spring_table.yaml"]
    if cfg.pair.calibrate_write_conf:
        SPRING_FILE.write_text(text)
        written.append(str(SPRING_FILE))
    results = step_responses(cfg)
    print_step_table(results, cfg.pair.tolerance_pct)
    console.print(f"Wrote {', '.join(written)}")


def spring_yaml(edges_kpa: list[float], table: list[float], fitted: list[int]) -> str:
    stamp = dt.datetime.now().isoformat(timespec="seconds")
    return (
        f"# Generated by `pamrun muscle calibrate` ({stamp}). Do not edit by hand: rerun it.\n"
        "# Spring coefficient S(P) of the DMSP-20 per pressure band, fitted so that the\n"
        "# simulated step responses of thesis §10.1 end at the published contractions.\n"
        f"# Fitted bands: {', '.join(f'{edges_kpa[k]:.0f}-{edges_kpa[k + 1]:.0f} kPa' for k in fitted)};\n"
        "# the others are interpolated linearly in pressure between fitted band centres.\n"
        f"band_edges_kpa: {[float(e) for e in edges_kpa]}\n"
        f"stiffness_n_per_m: {[float(s) for s in table]}\n"
        "hysteresis: none\n"
    )


def muscle_curves(dcfg: DictConfig) -> None:
    """``pamrun muscle curves``: force_curves.png (Fig. 8.10) and force_surface.png (Fig. 8.9)."""
    cfg: Config = to_object(dcfg)
    out = run_dir()
    law = FORCE_LAWS[cfg.muscle.force_law](cfg.muscle.max_pressure_kpa)
    x = np.linspace(-3.0, 30.0, 133)
    p = np.linspace(0.0, cfg.muscle.max_pressure_kpa, 33)
    force = np.maximum(law.signed_force_n(x[None, :], p[:, None]), 0.0)
    data = {
        "contraction_pct": x.round(4).tolist(),
        "pressure_kpa": p.round(3).tolist(),
        "force_n": force.round(3).tolist(),
        "curve_pressures_kpa": [float(v) for v in np.arange(0.0, cfg.muscle.max_pressure_kpa + 1, 100.0)],
    }
    path = out / "force_curves.json"
    path.write_text(json.dumps(data))
    plots.force_curves(path, out / "force_curves.png", out / "force_surface.png")
    table = Table(title="DMSP-20 force (N) at contraction x, pressure P (thesis Table 8.4 polynomial)")
    table.add_column("P (kPa)", justify="right")
    shown = [0, 5, 10, 15, 20, 25]
    for xc in shown:
        table.add_column(f"x={xc}%", justify="right")
    for pk in (200, 400, 600, 800):
        vals = np.maximum(law.signed_force_n(np.array(shown, float), float(pk)), 0.0)
        table.add_row(str(pk), *(f"{v:.0f}" for v in vals))
    console.print(table)
    console.print("Wrote force_curves.json, force_curves.png, force_surface.png")
