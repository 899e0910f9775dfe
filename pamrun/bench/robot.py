"""The robot bench: ``pamrun body`` (the generated robot), ``pamrun openloop`` (thesis §10.2)
and ``pamrun capacity`` (muscle torque and stiffness against the walking demand).

Each command function is a Hydra task: it takes the composed config, writes its files into
the run directory, prints where, and shows a rich table of what it measured.
"""

from __future__ import annotations

import json

import matplotlib.pyplot as plt
import mujoco
import numpy as np
from omegaconf import DictConfig
from rich.table import Table

from pamrun.bench import figures
from pamrun.config import Config, to_object
from pamrun.physics import body
from pamrun.physics.actuation import MuscleDrive, joint_limits_rad
from pamrun.physics.body import JOINTS, build_fixed_model, joint_addresses
from pamrun.physics.capacity import analyse
from pamrun.runs.files import console as make_console
from pamrun.runs.files import run_dir

console = make_console()  # a terminal's width, or wide enough in a log that no table is cut


# The nine movements of thesis §10.2, on the left leg: (joint, limit side, label).
# Signs follow the body's convention (right-hand rule about +x forward, +y left, +z up):
# knee flexion and hip extension are positive pitch, left hip abduction is positive roll;
# the larger ankle-roll range (+35 deg, Table 8.3) is taken as inversion.
MOVEMENTS: dict[str, tuple[str, int]] = {
    "ankle_dorsiflexion": ("ankle_pitch", 0),
    "ankle_plantar_flexion": ("ankle_pitch", 1),
    "ankle_inversion": ("ankle_roll", 1),
    "ankle_eversion": ("ankle_roll", 0),
    "knee_flexion": ("knee", 1),
    "hip_abduction": ("hip_roll", 1),
    "hip_adduction": ("hip_roll", 0),
    "hip_flexion": ("hip_pitch", 0),
    "hip_extension": ("hip_pitch", 1),
}


def openloop_movement(cfg: Config, movement: str, duration_s: float = 3.0, step_time_s: float = 0.2) -> dict:
    """Pressure step on one left-leg pair with the torso held in the air (thesis §10.2).

    The agonist steps to the muscle's maximum pressure, the antagonist to the regulator's
    minimum; the other pairs stay at V0. Returns the time series and the final angle.
    """
    joint, side = MOVEMENTS[movement]
    j = JOINTS.index(f"left_{joint}")
    limits = joint_limits_rad(cfg.body)[j]
    model = build_fixed_model(cfg.body, timestep_s=cfg.env.physics_dt_s)
    data = mujoco.MjData(model)
    drive = MuscleDrive(cfg.muscle, cfg.body)
    drive.reset()
    mujoco.mj_forward(model, data)

    rest, stepped = _step_voltages(cfg, drive.voltage_v, j, side)
    dt = cfg.env.muscle_dt_s
    series = _run_step(cfg, model, data, drive, j, (rest, stepped), duration_s, step_time_s)
    # The thesis' limit damping (10 N m s/rad) lets a joint bounce on its stop: average.
    angles = np.asarray(series["angle_deg"])
    final = float(angles[np.asarray(series["time_s"]) >= duration_s - 0.5].mean())
    limit = float(np.degrees(limits[side]))
    gravity, muscle_at_limit = _torques_at_limit(model, data, drive, j, limits[side], dt)
    return {
        "joint": f"left_{joint}",
        "limit_deg": round(limit, 3),
        "final_angle_deg": round(final, 3),
        "error_deg": round(final - limit, 3),
        "reached": abs(final - limit) <= 2.0,
        "pressures_kpa": [round(float(drive.pressure_kpa[j][0]), 1), round(float(drive.pressure_kpa[j][1]), 1)],
        "pulley_radius_m": round(float(drive.radius_m[j]), 5),
        "muscle_torque_at_limit_nm": round(muscle_at_limit, 3),
        "gravity_torque_at_limit_nm": round(gravity, 3),
        **series,
    }


def _step_voltages(cfg: Config, rest_v: np.ndarray, j: int, side: int) -> tuple[np.ndarray, np.ndarray]:
    """The voltages before and after the step: the agonist of joint ``j`` towards its ``side``
    limit to the muscle's maximum pressure, its antagonist to the regulator's minimum."""
    reg = cfg.muscle.regulator
    v_max = min(cfg.muscle.max_pressure_kpa, reg.max_pressure_kpa) / reg.gain_kpa_per_v
    v_min = reg.min_voltage_v
    rest = rest_v.copy()
    stepped = rest.copy()
    # Muscle 1 pulls towards positive angles: it is the agonist for the upper limit.
    stepped[j] = [v_max, v_min] if side == 1 else [v_min, v_max]
    return rest, stepped


def _run_step(cfg: Config, model, data, drive, j: int, voltages: tuple[np.ndarray, np.ndarray], duration_s: float,
              step_time_s: float) -> dict[str, list]:
    """Simulate ``duration_s`` with the ``(rest, stepped)`` voltages switched at ``step_time_s``;
    joint ``j``'s pressures, contractions and angle every 10 ms."""
    rest, stepped = voltages
    qi, vi = joint_addresses(model)
    dt = cfg.env.muscle_dt_s
    nstep = int(round(dt / cfg.env.physics_dt_s))
    n = int(round(duration_s / dt))
    keep = max(1, int(round(0.01 / dt)))
    series: dict[str, list] = {"time_s": [], "pressure_kpa": [], "contraction_pct": [], "angle_deg": []}
    for k in range(n + 1):
        t = k * dt
        if k % keep == 0:
            series["time_s"].append(round(t, 4))
            series["pressure_kpa"].append(drive.pressure_kpa[j].round(2).tolist())
            series["contraction_pct"].append(drive.contraction_pct[j].round(3).tolist())
            series["angle_deg"].append(round(float(np.degrees(data.qpos[qi[j]])), 3))
        drive.set_voltages(stepped if t >= step_time_s else rest)
        drive.apply(model, data, qi, vi, dt)
        mujoco.mj_step(model, data, nstep)
    return series


def _torques_at_limit(model, data, drive, j: int, limit_rad: float, dt: float) -> tuple[float, float]:
    """Why a joint stalls: the gravity torque to hold joint ``j`` at its limit, and the muscles'
    torque there [N m] (the thesis coupling's: the torque it ended with)."""
    muscle_now = float(data.actuator_force[j])  # muscle torque at the end [N m]
    qi, vi = joint_addresses(model)
    data.qpos[:] = 0
    data.qpos[qi[j]] = limit_rad
    data.qvel[:] = 0
    mujoco.mj_forward(model, data)
    if not drive.kinematic:
        return float(data.qfrc_bias[vi[j]]), muscle_now
    angle = np.zeros(len(JOINTS))
    angle[j] = limit_rad
    return float(data.qfrc_bias[vi[j]]), float(drive.torques_nm(angle, np.zeros(len(JOINTS)), dt)[j])


def openloop(dcfg: DictConfig) -> None:
    """``pamrun openloop``: the nine §10.2 movements -> openloop.json, one figure each."""
    cfg: Config = to_object(dcfg)
    out = run_dir()
    results = {name: openloop_movement(cfg, name) for name in MOVEMENTS}
    path = out / "openloop.json"
    path.write_text(json.dumps({"coupling": cfg.muscle.coupling, "movements": results}))
    for name in results:
        figures.openloop_movement(path, name, out / f"openloop_{name}.png")
    table = Table(title=f"Open-loop tests, torso fixed (thesis §10.2), coupling={cfg.muscle.coupling}")
    for col in ("movement", "limit (deg)", "final (deg)", "p1/p2 (kPa)", "r (mm)", "muscle (N m)", "gravity (N m)", "reached"):
        table.add_column(col, justify="left" if col == "movement" else "right", no_wrap=col == "movement")
    for name, r in results.items():
        mark = "[green]yes[/green]" if r["reached"] else "[red]no[/red]"
        p1, p2 = r["pressures_kpa"]
        table.add_row(name, f"{r['limit_deg']:.2f}", f"{r['final_angle_deg']:.2f}", f"{p1:.0f}/{p2:.0f}",
                      f"{r['pulley_radius_m'] * 1000:.1f}", f"{r['muscle_torque_at_limit_nm']:.1f}",
                      f"{r['gravity_torque_at_limit_nm']:.1f}", mark)
    console.print(table)
    n_ok = sum(r["reached"] for r in results.values())
    console.print(
        f"{n_ok}/{len(results)} movements reach their limit within 2 deg (final: mean of the last 0.5 s). "
        "muscle: the pair's torque at the limit (thesis coupling: its settled torque); gravity: the torque "
        "gravity exerts on the joint there. Wrote openloop.json and 9 figures."
    )


def generate_body(dcfg: DictConfig) -> None:
    """``pamrun body``: robot.xml (generated model), body.json (segments), robot.png."""
    cfg: Config = to_object(dcfg)
    out = run_dir()
    spec = body.build_spec(cfg.body, timestep_s=cfg.env.physics_dt_s)
    model = spec.compile()
    (out / "robot.xml").write_text(spec.to_xml())
    rows = body.segment_table(cfg.body)
    total_kg = float(model.body_subtreemass[0])
    (out / "body.json").write_text(
        json.dumps({"height_m": cfg.body.height_m, "mass_kg": cfg.body.mass_kg, "robot_mass_kg": total_kg,
                    "segments": rows}, indent=2)
    )
    plt.imsave(out / "robot.png", body.render_standing(model, 640, 480))
    table = Table(title=f"Segments for H = {cfg.body.height_m} m, M = {cfg.body.mass_kg} kg (thesis Table 8.2)")
    headers = {"segment": "segment", "x_m": "x (m)", "y_m": "y (m)", "z_m": "z (m)", "mass_kg": "mass (kg)",
               "com_m": "CoM (m)", "radius_gyration_m": "ro (m)", "inertia_kgm2": "I0 (kg m2)"}
    for key, title in headers.items():
        table.add_column(title, justify="left" if key == "segment" else "right", no_wrap=key == "segment")
    for row in rows:
        table.add_row(*("" if isinstance(v, float) and np.isnan(v) else f"{v:.4f}" if isinstance(v, float) else str(v)
                        for v in (row[k] for k in headers)))
    console.print(table)
    if cfg.body.toe:
        _print_toe(console, cfg.body, body.anthropometry(cfg.body)["toe"], cfg.env.physics_dt_s)
    console.print(f"Robot mass {total_kg:.2f} kg. Wrote robot.xml, body.json, robot.png")


def _print_toe(console, body_cfg, toe: dict, physics_dt_s: float) -> None:
    """``pamrun body body.toe=true``: what the toe row is and how its hinge is set."""
    lo, hi = body_cfg.toe_range_deg
    console.print(
        f"Toe (body.toe): the foot's front {body_cfg.toe_length_ratio:.0%} ({toe['x_m'] * 1000:.0f} mm) and "
        f"{body_cfg.toe_mass_ratio:.1%} of its mass ({toe['mass_kg']:.3f} kg; the foot row is the whole foot), hinged "
        f"{toe['hinge_x_m'] * 1000:.0f} mm ahead of the ankle at the metatarsal line; I about the hinge "
        f"{toe['hinge_inertia_kgm2']:.2e} kg m2. Passive: spring {body_cfg.toe_stiffness_nm_per_rad} N m/rad (at most "
        f"{body_cfg.toe_critical_stiffness_nm_per_rad(physics_dt_s):.0f} at {physics_dt_s * 1000:g} ms), damping "
        f"{body_cfg.toe_damping_nms_per_rad} N m s/rad, range {lo:g}..{hi:g} deg (toe up negative). Its tip "
        "carries the foot's front contact spheres; the foot stands on heel and ball (contact_ball_*).")


def check_capacity(dcfg: DictConfig) -> None:
    """``pamrun capacity``: muscle envelope and stiffness against standing and walking demand."""
    cfg: Config = to_object(dcfg)
    out = run_dir()
    result = analyse(cfg.muscle, cfg.body)
    figures.record(out, "capacity", result, figures.capacity)
    console.print(capacity_table(result, cfg))
    _print_capacity_verdict(result, burst=cfg.muscle.coupling == "thesis")
    air = result["air_per_cycle_nl"]
    console.print(f"Air at the walking demand: about {air:.1f} normal litres per gait cycle, both legs (each muscle "
                  f"filled once from the band's low pressure to what its joint's peak needs; {air * 60:.0f} NL/min at one "
                  "cycle per second). Wrote capacity.json, capacity.png")


def capacity_table(result: dict, cfg: Config) -> Table:
    """Rich table of :func:`pamrun.physics.capacity.analyse`: per joint, demand, margins and stiffness."""
    m = cfg.muscle
    table = Table(title=f"Capacity vs demand: {m.size}, L0 {m.nominal_length_m * 1000:.0f} mm, {m.coupling} coupling, "
                        f"band {result['band_kpa'][1]:.0f}/{result['band_kpa'][0]:.0f} kPa, "
                        f"robot {result['robot_mass_kg']:.1f} kg")
    cols = ("joint", "n", "r mm", "walk Nm", "band Nm", "margin", "full", "lean Nm", "K0", "mgh", "K0/mgh")
    for col in cols:
        table.add_column(col, justify="left" if col == "joint" else "right", no_wrap=True)
    need = result["required_margin"]
    for name, r in result["joints"].items():
        ok = r["walking_margin"] >= need
        k_ok = r["stiffness_margin"] >= 1.0
        table.add_row(name, str(r["muscles_per_direction"]), f"{r['radius_mm']:.1f}", f"{r['walking_demand_nm']:.1f}",
                      f"{r['envelope']['band']['walking_min_nm']:.1f}",
                      f"[{'green' if ok else 'red'}]{r['walking_margin']:.2f}[/]", f"{r['walking_margin_full']:.2f}",
                      f"{r['lean_demand_nm']:.1f}", f"{abs(r['stiffness_zero_action_nm_per_rad']):.0f}",
                      f"{r['gravity_stiffness_nm_per_rad']:.0f}",
                      f"[{'green' if k_ok else 'red'}]{abs(r['stiffness_margin']):.2f}[/]")
    return table


def _print_capacity_verdict(result: dict, burst: bool) -> None:
    """What the table's columns mean, whether the demand is covered, and the toe's share (``body.toe``)."""
    need = result["required_margin"]
    v = result["verdict"]
    console.print(
        "n: muscles per direction; walk: peak walking moment; band: the weakest envelope point over the walking "
        "range in the command band; margin = band / walk (full: at full pressure); lean: holding a "
        f"{result['lean_deg']:.0f} deg lean; K0: stiffness at zero action; mgh: gravitational stiffness per leg "
        "(N m/rad)."
    )
    if burst:
        console.print("Thesis coupling: the envelope is the burst torque right after a pressure change (both "
                      "muscles still at their rest contraction); it decays to ~0 within ~20 ms, and the pair has no "
                      "stiffness: the robot cannot hold a pose by pressure alone.")
    console.print(
        f"Walking demand (peak human joint moments per kg x {result['robot_mass_kg']:.1f} kg, anywhere in the walking "
        f"range, either direction) covered with margin >= {need}: "
        + ("[green]yes[/green]" if v["walking_margin_ok"] else f"[red]no[/red] (weakest {v['min_walking_margin']:.2f})")
        + f". Ankle stiffness at zero action ({result['zero_action_kpa']:.0f} kPa both) >= m g h per ankle: "
        + ("[green]yes[/green]" if v["ankle_stiffness_ok"] else "[red]no[/red]")
        + f". Centre of mass {result['com_height_m']:.3f} m up."
    )
    if "toe" in result:
        toe = result["toe"]
        console.print(
            f"Toe (body.toe, passive, {toe['stiffness_nm_per_rad']} N m/rad): gives {toe['moment_at_stop_nm']:.1f} "
            f"N m at its {toe['dorsiflexion_stop_deg']:.0f} deg stop. Push-off (human peak MTP moment per kg): "
            f"{toe['push_off']['demand_nm']:.1f} N m at {toe['push_off']['angle_deg']:.0f} deg; standing on the toes "
            f"alone: {toe['tip_toe']['demand_nm']:.1f} N m per foot, "
            + (f"{toe['tip_toe']['angle_deg']:.0f} deg" if toe["tip_toe"]["within_range"]
               else "past its stop: the toe folds to the stop, which holds the rest")
            + ". Standing, the foot bears on heel and ball.")
