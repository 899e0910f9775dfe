"""The muscle bench of thesis §10.1: ``pamrun muscle step | calibrate | curves | valve | hysteresis``.

Each ``muscle_*`` function is a Hydra task: it takes the composed config, writes its files into
the run directory, prints where, and shows a rich table of what it measured.
"""

from __future__ import annotations

import datetime as dt
import json
from dataclasses import replace

import numpy as np
from omegaconf import DictConfig
from rich.table import Table

from pamrun.bench import figures
from pamrun.config import SPRING_FILE, Config, MuscleConfig, to_object
from pamrun.physics.force_laws import FORCE_LAWS, MARTENS_BOBLAN_DMSP20_300
from pamrun.physics.hysteresis import hysteresis_loop
from pamrun.physics.muscle import calibrate_spring, simulate_step
from pamrun.physics.valve import make_regulator
from pamrun.runs.files import console as make_console
from pamrun.runs.files import run_dir

console = make_console()  # a terminal's width, or wide enough in a log that no table is cut


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
    capped = _capped_experiment_kpa(cfg)
    results = step_responses(cfg)
    figures.record(out, "step_response", {"spring_n_per_m": list(cfg.muscle.spring.stiffness_n_per_m),
                                          "experiments": results}, figures.step_response)
    print_step_table(results, cfg.pair.tolerance_pct)
    if capped:
        console.print(f"[yellow]muscle.max_pressure_kpa = {cfg.muscle.max_pressure_kpa:.0f} kPa caps the experiments' "
                      f"{capped:.0f} kPa: the §10.1 numbers are the thesis muscle's (muscle=thesis).[/yellow]")
    console.print("Wrote step_response.json, step_response.png")


def _capped_experiment_kpa(cfg: Config) -> float:
    """The highest §10.1 experiment pressure this muscle cannot reach (0 if it reaches all)."""
    top = max(max(e.pressure1_kpa, e.pressure2_kpa) for e in cfg.pair.experiments.values())
    return top if top > cfg.muscle.max_pressure_kpa else 0.0


def muscle_calibrate(dcfg: DictConfig) -> None:
    """``pamrun muscle calibrate``: fit S(P), write it as YAML, show the step responses."""
    cfg: Config = to_object(dcfg)
    capped = _capped_experiment_kpa(cfg)
    if capped:
        raise SystemExit(f"pamrun: muscle calibrate fits S(P) to the §10.1 steps up to {capped:.0f} kPa, but "
                         f"muscle.max_pressure_kpa is {cfg.muscle.max_pressure_kpa:.0f}: run it with muscle=thesis")
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


def force_curve_data(force_law: str, max_pressure_kpa: float) -> dict:
    """What ``force_curves.json`` holds: the configured law's F(x, P) surface [N] (never
    negative), every law's curves at every 100 kPa and at the measured DMSP-20-300's pressures,
    and those measured points (Martens & Boblan 2017)."""
    laws = {name: law_class(max_pressure_kpa) for name, law_class in FORCE_LAWS.items()}
    x = np.linspace(-3.0, 30.0, 133)
    p = np.linspace(0.0, max_pressure_kpa, 33)
    curve_p = [float(v) for v in np.arange(0.0, max_pressure_kpa + 1, 100.0)]
    measured_p = sorted({float(row[0]) for row in MARTENS_BOBLAN_DMSP20_300})

    def forces(law, pressures) -> list:
        return np.maximum(law.signed_force_n(x[None, :], np.asarray(pressures)[:, None]), 0.0).round(3).tolist()

    return {
        "force_law": force_law,
        "contraction_pct": x.round(4).tolist(),
        "pressure_kpa": p.round(3).tolist(),
        "force_n": forces(laws[force_law], p),
        "curve_pressures_kpa": curve_p,
        "curves_n": {name: forces(law, curve_p) for name, law in laws.items()},
        "measured_pressures_kpa": measured_p,
        "measured_curves_n": {name: forces(law, measured_p) for name, law in laws.items()},
        "measured": {"source": "Festo DMSP-20-300, Martens & Boblan 2017 (THESIS.md §8)",
                     "points": [{"pressure_kpa": a, "contraction_pct": b, "force_n": c}
                                for a, b, c in MARTENS_BOBLAN_DMSP20_300]},
    }


def muscle_curves(dcfg: DictConfig) -> None:
    """``pamrun muscle curves``: force_curves.png (Fig. 8.10, every force law against the measured
    DMSP-20-300) and force_surface.png (Fig. 8.9, the configured ``muscle.force_law``)."""
    cfg: Config = to_object(dcfg)
    out = run_dir()
    top = cfg.muscle.max_pressure_kpa
    path = out / "force_curves.json"
    path.write_text(json.dumps(force_curve_data(cfg.muscle.force_law, top)))
    figures.force_curves(path, out / "force_curves.png", out / "force_surface.png")
    table = Table(title="DMSP-20 force (N) at contraction x, pressure P, per force law")
    table.add_column("P (kPa)", justify="right")
    table.add_column("law")
    shown = [0, 5, 10, 15, 20, 25]
    for xc in shown:
        table.add_column(f"x={xc}%", justify="right")
    laws = {name: law_class(top) for name, law_class in FORCE_LAWS.items()}
    for pk in (200, 400, 600, 800):
        for name, law in laws.items():
            vals = np.maximum(law.signed_force_n(np.array(shown, float), float(pk)), 0.0)
            table.add_row(str(pk), name, *(f"{v:.0f}" for v in vals))
    console.print(table)
    p, x, f = np.asarray(MARTENS_BOBLAN_DMSP20_300, float).T
    for name, law in laws.items():
        miss = np.maximum(law.signed_force_n(x, p), 0.0) - f
        console.print(f"{name}: RMSE {np.sqrt(np.mean(miss**2)):.0f} N, worst {np.abs(miss).max():.0f} N against the "
                      f"{len(f)} measured DMSP-20-300 points (Martens & Boblan 2017)")
    console.print(f"Wrote force_curves.json, force_curves.png, force_surface.png (surface: {cfg.muscle.force_law})")


# --------------------------------------------------------------------------- valve


def _crossing_s(time_s: np.ndarray, pressure_kpa: np.ndarray, level_kpa: float) -> float | None:
    """First time [s] the rising pressure reaches ``level_kpa``, interpolated linearly (None: never)."""
    above = np.flatnonzero(pressure_kpa >= level_kpa)
    if not len(above):
        return None
    k = int(above[0])
    if k == 0:
        return float(time_s[0])
    t0, t1, p0, p1 = time_s[k - 1], time_s[k], pressure_kpa[k - 1], pressure_kpa[k]
    return float(t0 + (t1 - t0) * (level_kpa - p0) / (p1 - p0))


def valve_step_responses(muscle: MuscleConfig, contractions_pct=(0.0, 20.0), muscles_per_side=(1, 2),
                         step_kpa: float = 600.0, duration_s: float = 0.5, dt_s: float = 0.0005) -> dict:
    """One side's pressure after a 0 -> ``step_kpa`` command at fixed contractions, for
    ``muscle.regulator.model`` = lag and = flow (the rest of ``muscle`` as given): time series
    and the 10-90 % rise time, the times to 10, 90 and 95 % [s], per contraction [%] and
    number of muscles the valve fills. The lag's response does not depend on either: one case."""
    time_s = np.arange(int(round(duration_s / dt_s)) + 1) * dt_s
    every = max(1, int(round(0.002 / dt_s)))  # the series kept: every 2 ms
    cases = []
    for model in ("lag", "flow"):
        cfg = replace(muscle, regulator=replace(muscle.regulator, model=model))
        for contraction in contractions_pct if model == "flow" else contractions_pct[:1]:
            for count in muscles_per_side if model == "flow" else muscles_per_side[:1]:
                reg = make_regulator(cfg, np.zeros((1, 2)), count)
                reg.reset(np.zeros((1, 2)))
                voltage = reg.voltage_for_pressure_v(np.full((1, 2), step_kpa))
                at = np.full((1, 2), float(contraction))
                pressure = np.empty(len(time_s))
                pressure[0] = reg.pressure_kpa[0, 0]
                for k in range(1, len(time_s)):
                    reg.step(voltage, dt_s, at)
                    pressure[k] = reg.pressure_kpa[0, 0]
                times = {f"t{share}_s": _crossing_s(time_s, pressure, share / 100 * step_kpa) for share in (10, 90, 95)}
                rise = None if None in (times["t10_s"], times["t90_s"]) else times["t90_s"] - times["t10_s"]
                flow = model == "flow"
                cases.append({"model": model, "contraction_pct": float(contraction) if flow else None,
                              "muscles_per_side": int(count) if flow else None,
                              "volume_l": round(float(reg.volume_l[0, 0]), 5) if flow else None,
                              "rise_10_90_s": None if rise is None else round(rise, 5),
                              **{k: None if v is None else round(v, 5) for k, v in times.items()},
                              "pressure_kpa": pressure[::every].round(2).tolist()})
    reg = muscle.regulator
    return {"step_kpa": step_kpa, "dt_s": dt_s, "every_s": every * dt_s,
            "size": muscle.size, "nominal_length_m": muscle.nominal_length_m,
            "regulator": {k: getattr(reg, k) for k in ("lag_s", "nominal_flow_nl_min", "critical_pressure_ratio",
                                                         "supply_pressure_kpa", "reservoir_volume_l")},
            "cases": cases}


def print_valve_table(results: dict) -> None:
    """Rich table of the rise times of :func:`valve_step_responses`."""
    lag_ms = results["regulator"]["lag_s"] * 1000
    table = Table(title=f"Regulator step 0 -> {results['step_kpa']:.0f} kPa, {results['size']} "
                        f"{results['nominal_length_m'] * 1000:.0f} mm, lag {lag_ms:.0f} ms")
    for col in ("model", "contraction (%)", "muscles", "volume (l)", "10-90 % (ms)", "to 90 % (ms)", "to 95 % (ms)"):
        table.add_column(col, justify="left" if col == "model" else "right")

    def ms(value):
        return "never" if value is None else f"{1000 * value:.1f}"

    for c in results["cases"]:
        lag = c["model"] == "lag"  # any contraction, any volume
        table.add_row(c["model"], "any" if lag else f"{c['contraction_pct']:.0f}",
                      "any" if lag else str(c["muscles_per_side"]), "any" if lag else f"{c['volume_l']:.3f}",
                      ms(c["rise_10_90_s"]), ms(c["t90_s"]), ms(c["t95_s"]))
    console.print(table)


def report(out, name: str, results: dict, draw, print_table) -> None:
    """A bench experiment's results as ``<name>.json`` and its figure ``<name>.png`` in ``out``, and its table."""
    figures.record(out, name, results, draw)
    print_table(results)
    console.print(f"Wrote {name}.json, {name}.png")


def muscle_valve(dcfg: DictConfig) -> None:
    """``pamrun muscle valve``: regulator step 0 -> 600 kPa, lag vs flow -> valve_step.json/.png."""
    report(run_dir(), "valve_step", valve_step_responses(to_object(dcfg).muscle), figures.valve_step, print_valve_table)


# --------------------------------------------------------------------------- hysteresis


def print_hysteresis_table(results: dict) -> None:
    """Rich table of the loop areas of :func:`pamrun.physics.hysteresis.hysteresis_loop`."""
    table = Table(title=f"Loop area per cycle [J]: {results['size']} {results['nominal_length_m'] * 1000:.0f} mm, "
                        f"contraction {results['center_pct']:g} +- {results['amplitude_pct']:g} %")
    for col in ("pressure (kPa)", "none", "maxwell_slip", "analytic sum 4 f (A - f/k)"):
        table.add_column(col, justify="right")
    for c in results["cases"]:
        table.add_row(f"{c['pressure_kpa']:.0f}", f"{c['area_none_j']:.2e}", f"{c['area_slip_j']:.4f}",
                      f"{c['analytic_area_j']:.4f}")
    console.print(table)


def muscle_hysteresis(dcfg: DictConfig) -> None:
    """``pamrun muscle hysteresis``: one muscle cycled at constant pressure, force vs contraction
    with and without the Maxwell-slip elements -> hysteresis_loop.json/.png (loop areas [J])."""
    report(run_dir(), "hysteresis_loop", hysteresis_loop(to_object(dcfg).muscle), figures.hysteresis_loop,
           print_hysteresis_table)
