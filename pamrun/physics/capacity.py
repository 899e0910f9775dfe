"""What the muscles can do against what standing and walking demand (``pamrun capacity``).

For each joint of the left leg (the right one mirrors it) and the configured muscles:

* **Envelope**: the largest torque the pair gives towards each direction at every angle
  of the joint's range, with the agonist at the top of the command band and the
  antagonist at its bottom (``band``: V0 +- dV through the regulator), and at full
  pressure (``full``: the muscle's ``max_pressure_kpa`` against the regulator's minimum).
  In the kinematic coupling both muscles' contractions follow the angle. In the thesis
  coupling the contractions are not tied to the angle, and a pair's torque lasts only
  while they move after a pressure change (~20 ms) before settling near 0: its envelope
  is that **burst**, the torque at the instant the pressures are set with both muscles at
  the rest contraction, the same at every angle; its settled torque and its stiffness are 0.
* **Intrinsic stiffness** -dT/dtheta at the standing pose with both muscles at the same
  pressure (co-contraction), at a few pressures and at the zero-action pressure (V0).
* **Demand**, with its source:
  - walking: the peak joint moment of human walking per kg of body mass (below), times
    the robot's mass, required anywhere in the joint's walking range, in either direction
    (conservative: human flexor and extensor peaks differ, a symmetric pair serves both);
  - standing: holding a 5 deg lean of everything above the joint (two legs share it), and
    the gravitational stiffness m g h of the same inverted pendulum per leg (thesis §8 of
    THESIS.md; Loram & Lakie 2002: human intrinsic ankle stiffness is ~0.9 m g h).
* **Margin** = capacity / demand: the envelope's weakest point over the walking range
  against the walking peak, and the zero-action stiffness against m g h.
* **Air per gait cycle** at the walking demand, an estimate of what a supply must deliver:
  in each cycle every joint gives its walking peak moment once in each direction, at the
  middle of its walking range, with the antagonist at the band's low pressure. So each
  muscle swings once per cycle between that low pressure (antagonist) and the pressure the
  peak needs as agonist (found by bisection; the muscle's maximum where the peak is out of
  reach): it is filled once and exhausts once. Air = the growth of P V
  (:class:`pamrun.physics.muscle.AirMeter`), both legs, every muscle counted. A gait that co-contracts, or moves through larger ranges, uses
  more; the measured walker's air per metre is in ``pamrun eval``'s gait table.
* **Toe** (``body.toe``): the toe moves with the foot, so it is below every joint in the gravity
  loads; its passive spring is set against push-off and tip-toe (:func:`_toe_capacity`).
"""

from __future__ import annotations

import math
from dataclasses import asdict
from typing import Any

import mujoco
import numpy as np

from pamrun.config import LEG_JOINTS, BodyConfig, MuscleConfig
from pamrun.config.robot import MTP_PEAK_MOMENT_NM_PER_KG
from pamrun.physics.actuation import MuscleDrive, joint_limits_rad
from pamrun.physics.body import GRAVITY, JOINTS, SIDES, SPHERE_RADIUS_RATIO, build_model
from pamrun.physics.muscle import MUSCLE_INNER_DIAMETER_M, AirMeter

# Per-joint tables below are keyed by pamrun.config.LEG_JOINTS, in its order (tests/test_capacity.py checks it).
# Peak joint moments of human walking at natural cadence, N m per kg of body mass (Winter,
# "Biomechanics and Motor Control of Human Movement", 4th ed., 2009, gait data; sagittal
# peaks as collected in THESIS.md §8; frontal: hip abductor and ankle invertor/evertor
# moments from Winter's frontal-plane data, MacKinnon & Winter, J. Biomech. 26, 1993).
WALKING_PEAK_NM_PER_KG = {"hip_pitch": 1.0, "hip_roll": 1.0, "knee": 0.8, "ankle_pitch": 1.5, "ankle_roll": 0.3}
# Joint angles of human walking [deg], in the robot's convention (hip extension, knee flexion,
# plantar flexion, left hip abduction and ankle inversion positive; Winter 2009, Perry 1992):
# hip 30 deg flexion to 20 extension, knee 0-65, ankle 15 dorsi- to 20 plantar flexion, +-10 roll.
WALKING_RANGE_DEG = {"hip_pitch": (-30.0, 20.0), "hip_roll": (-10.0, 10.0), "knee": (0.0, 65.0),
                     "ankle_pitch": (-15.0, 20.0), "ankle_roll": (-10.0, 10.0)}
LEAN_DEG = 5.0  # a lean to hold while standing (THESIS.md §8: 2, 5 or 10 deg)
REQUIRED_MARGIN = 1.5  # capacity over walking demand a robot that should learn to walk needs
STIFFNESS_LEVELS_KPA = (100.0, 200.0, 300.0, 400.0, 600.0, 800.0)
# Bodies that move with each joint group's distal side, i.e. not carried by it (left leg; both legs share).
# A group is the first word of its joints' names: hip (pitch, roll), knee, ankle (pitch, roll). The toe
# (body.toe) is a part of the foot; without it the name matches no body.
_BELOW = {"ankle": ("foot", "toe"), "knee": ("shin", "foot", "toe"), "hip": ("thigh", "shin", "foot", "toe")}


def _gravity_loads(body: BodyConfig) -> dict[str, dict[str, float]]:
    """Per joint group: mass carried above it [kg] and its centre-of-mass height above the joint [m]."""

    model = build_model(body)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "stand"))
    mujoco.mj_forward(model, data)
    out = {"robot": {"mass_kg": float(model.body_subtreemass[0]), "com_height_m": float(data.subtree_com[0][2])}}
    for group, below in _BELOW.items():
        excluded = {f"{side}_{b}" for side in SIDES for b in below}
        ids = [i for i in range(1, model.nbody) if model.body(i).name not in excluded]
        mass = float(model.body_mass[ids].sum())
        com_z = float((model.body_mass[ids] * data.xipos[ids, 2]).sum() / mass)
        anchor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"left_{group}" if group == "knee"
                                   else f"left_{group}_pitch")
        out[group] = {"mass_kg": mass, "height_m": com_z - float(data.xanchor[anchor][2])}
    return out


def _static_torque_nm(drive, j: int, angle: np.ndarray, p1: float, p2: float) -> np.ndarray:
    """Torque [N m] of joint j over its angles [rad], muscle 1 at p1 and muscle 2 at p2 [kPa]
    (every other joint at 0; no state, see MuscleDrive.static_torque_nm)."""
    n = len(drive.radius_m)
    angles = np.zeros((len(angle), n))
    angles[:, j] = angle
    pressure = np.broadcast_to(np.array([p1, p2]), (len(angle), n, 2))
    return drive.static_torque_nm(angles, pressure)[:, j]


def _stiffness_nm_per_rad(drive, j: int, p_kpa: float, step_rad: float = 1e-3) -> float:
    """-dT/dtheta [N m/rad] of joint j at 0 with both muscles at p_kpa, by central difference."""
    t = _static_torque_nm(drive, j, np.array([-step_rad, step_rad]), p_kpa, p_kpa)
    return float(-(t[1] - t[0]) / (2 * step_rad))


def _joint_capacity(drive, name: str, limits_rad: np.ndarray, pressures: dict[str, Any], load: dict[str, float],
                    mass_kg: float, n_angles: int) -> dict[str, Any]:
    """One left-leg joint's row: envelope over its range, walking and lean demand, stiffness.

    ``pressures``: ``band`` and ``full`` (agonist, antagonist) [kPa] and ``zero`` [kPa]."""

    muscle = drive.cfg
    j = JOINTS.index(f"left_{name}")
    lo, hi = limits_rad[j]
    angle = np.linspace(lo, hi, n_angles)
    walk_lo, walk_hi = (math.radians(v) for v in WALKING_RANGE_DEG[name])
    in_walk = (angle >= walk_lo - 1e-9) & (angle <= walk_hi + 1e-9)
    envelope = {}
    for label in ("band", "full"):
        p_hi, p_lo = pressures[label]
        plus, minus = _static_torque_nm(drive, j, angle, p_hi, p_lo), _static_torque_nm(drive, j, angle, p_lo, p_hi)
        envelope[label] = {"plus_nm": plus.round(3).tolist(), "minus_nm": minus.round(3).tolist(),
                           "walking_min_nm": float(min(plus[in_walk].min(), -minus[in_walk].max()))}
    walk_demand = WALKING_PEAK_NM_PER_KG[name] * mass_kg
    gravity_k = load["mass_kg"] * 9.81 * load["height_m"] / 2  # m g h [N m/rad], per leg
    k_zero = _stiffness_nm_per_rad(drive, j, pressures["zero"])
    air = _cycle_air(drive, j, 0.5 * (walk_lo + walk_hi), walk_demand, pressures["band"][1],
                     int(getattr(muscle.count, name)))
    return {
        "radius_mm": round(float(drive.radius_m[j]) * 1000, 2),
        "muscles_per_direction": int(getattr(muscle.count, name)),
        "limits_deg": [round(math.degrees(lo), 3), round(math.degrees(hi), 3)],
        "walking_range_deg": list(WALKING_RANGE_DEG[name]),
        "angle_deg": np.degrees(angle).round(3).tolist(),
        "envelope": envelope,
        "walking_demand_nm": round(walk_demand, 3),
        "walking_margin": round(envelope["band"]["walking_min_nm"] / walk_demand, 3),
        "walking_margin_full": round(envelope["full"]["walking_min_nm"] / walk_demand, 3),
        "lean_demand_nm": round(gravity_k * math.sin(math.radians(LEAN_DEG)), 3),
        "stiffness_nm_per_rad": {f"{p:.0f}": round(_stiffness_nm_per_rad(drive, j, p), 2) for p in STIFFNESS_LEVELS_KPA
                                 if p <= muscle.max_pressure_kpa},
        "stiffness_zero_action_nm_per_rad": round(k_zero, 2),
        "gravity_stiffness_nm_per_rad": round(gravity_k, 2),
        "stiffness_margin": round(k_zero / gravity_k, 3),
        **air,
    }


def _cycle_air(drive, j: int, angle_rad: float, demand_nm: float, low_kpa: float, count: int) -> dict[str, Any]:
    """Air [normal litres] joint j's pair (``count`` muscles per direction) draws per gait cycle
    at the walking demand, both legs (module docstring), and the pressure [kPa] each
    direction's peak needs (None: out of reach even at the muscle's maximum)."""

    muscle = drive.cfg
    meter = AirMeter(muscle.nominal_length_m, MUSCLE_INNER_DIAMETER_M[muscle.size])
    top = muscle.max_pressure_kpa
    angles = np.zeros((1, len(drive.radius_m)))
    angles[0, j] = angle_rad
    needs, air = [], 0.0
    for side, sign in ((0, 1.0), (1, -1.0)):  # muscle 1 pulls the + direction, muscle 2 the -
        def pressures(p: float) -> np.ndarray:  # this muscle at p, its antagonist at the band's low
            out = np.full((1, len(drive.radius_m), 2), low_kpa)
            out[0, j, side] = p
            return out

        def torque(p: float) -> float:
            return sign * float(_static_torque_nm(drive, j, angles[:, j], *pressures(p)[0, j])[0])

        p = top
        if torque(top) >= demand_nm:
            lo = low_kpa
            for _ in range(40):  # bisection: the torque grows with the agonist's pressure
                mid = 0.5 * (lo + p)
                lo, p = (lo, mid) if torque(mid) >= demand_nm else (mid, p)
        needs.append(round(float(p), 1) if torque(top) >= demand_nm else None)
        contraction = drive.coupling.static_contraction_pct(angles, pressures(p))[0, j, side]
        air += meter.drawn_nl(meter.gas_kpa_l(low_kpa, contraction), meter.gas_kpa_l(p, contraction))
    return {"walking_pressures_kpa": needs, "air_per_cycle_nl": round(2 * count * air, 4)}  # 2 legs


def analyse(muscle: MuscleConfig, body: BodyConfig, n_angles: int = 91) -> dict[str, Any]:
    """The capacity table of every joint (see the module docstring); plain data for capacity.json."""

    drive = MuscleDrive(muscle, body)
    reg = drive.pairs.regulator
    band = reg.target_pressure_kpa(np.array([muscle.v0_v + muscle.dv_max_v, muscle.v0_v - muscle.dv_max_v]))
    band = np.minimum(band, muscle.max_pressure_kpa)
    full = np.array([muscle.max_pressure_kpa, muscle.regulator.min_pressure_kpa])
    zero_kpa = float(min(reg.target_pressure_kpa(np.array(muscle.v0_v)), muscle.max_pressure_kpa))
    loads = _gravity_loads(body)
    mass = loads["robot"]["mass_kg"]
    limits = joint_limits_rad(body)
    pressures = {"band": band, "full": full, "zero": zero_kpa}
    # hip, knee or ankle: the group (_BELOW) is the first word of the joint's name
    joints = {name: _joint_capacity(drive, name, limits, pressures, loads[name.split("_")[0]], mass, n_angles)
              for name in LEG_JOINTS}
    walks = all(v["walking_margin"] >= REQUIRED_MARGIN for v in joints.values())
    ankle_stiff = joints["ankle_pitch"]["stiffness_margin"] >= 1.0
    return {
        "coupling": muscle.coupling,
        "muscle": asdict(muscle),
        "robot_mass_kg": round(mass, 3),
        "com_height_m": round(loads["robot"]["com_height_m"], 4),
        "band_kpa": [round(float(v), 1) for v in band],
        "full_kpa": [round(float(v), 1) for v in full],
        "zero_action_kpa": round(zero_kpa, 1),
        "required_margin": REQUIRED_MARGIN,
        "lean_deg": LEAN_DEG,
        "joints": joints,
        "air_per_cycle_nl": round(sum(v["air_per_cycle_nl"] for v in joints.values()), 3),
        "verdict": {"walking_margin_ok": walks, "ankle_stiffness_ok": ankle_stiff,
                    "min_walking_margin": min(v["walking_margin"] for v in joints.values())},
        **({"toe": _toe_capacity(body, mass)} if body.toe else {}),
    }


def _toe_capacity(body: BodyConfig, mass_kg: float) -> dict[str, Any]:
    """``body.toe``: its passive spring against what the forefoot asks of it, per foot.

    * push-off: the human's peak MTP moment in walking per kg (MTP_PEAK_MOMENT_NM_PER_KG)
      times the robot's mass, and the dorsiflexion the spring needs to give it;
    * tip-toe: standing on the toes alone, half the robot's weight at the toe's contact
      spheres (their centres' distance from the hinge), and the dorsiflexion that needs. In
      stance the foot stands on its heel and ball: the toe bears only what its spring gives.
    Past ``toe_range_deg``'s dorsiflexion stop the stop (a joint limit) holds the rest."""

    k = body.toe_stiffness_nm_per_rad
    stop_deg = -body.toe_range_deg[0]
    arm_m = body.toe_box_m()[0] - SPHERE_RADIUS_RATIO * body.height_m
    out: dict[str, Any] = {"stiffness_nm_per_rad": k, "dorsiflexion_stop_deg": stop_deg, "arm_m": round(arm_m, 4),
                           "moment_at_stop_nm": round(k * math.radians(stop_deg), 3)}
    for name, demand in (("push_off", MTP_PEAK_MOMENT_NM_PER_KG * mass_kg), ("tip_toe", mass_kg * GRAVITY / 2 * arm_m)):
        angle = math.degrees(demand / k)
        out[name] = {"demand_nm": round(demand, 3), "angle_deg": round(angle, 2), "within_range": angle <= stop_deg}
    return out
