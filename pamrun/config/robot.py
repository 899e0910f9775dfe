"""Schemas of the robot: the pneumatic muscles (thesis §8.3, §9.5) and the body (§8.1-8.2).

The muscles' pressure regulator has its own module, :mod:`pamrun.config.regulator`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import yaml

from pamrun.config.checks import CONF_DIR, _non_negative, _positive, _require
from pamrun.config.regulator import RegulatorConfig

# --------------------------------------------------------------------------- joints

# The hinges of one leg, hip to ankle (thesis §8.1, Table 8.3): the one list of them. The
# per-joint tables below (JointCounts, JointRadii, JointAngles and BodyConfig's
# ``<joint>_limits_deg``) have one field per name, in this order (tests/test_body.py checks
# it), and ``pamrun.physics.body.JOINTS`` names each leg's hinges from it.
LEG_JOINTS = ("hip_pitch", "hip_roll", "knee", "ankle_pitch", "ankle_roll")

# --------------------------------------------------------------------------- muscle

# The spring table S(P) is for the thesis' DMSP-20-260: a muscle of length L0 has S * L_ref / L0.
SPRING_REFERENCE_LENGTH_M = 0.26

SPRING_FILE = CONF_DIR / "muscle" / "spring" / "calibrated.yaml"


def _calibrated_spring() -> dict[str, list[float]]:
    """The table written by ``pamrun muscle calibrate``: the one source of default S(P)."""
    data = _read_spring_file(SPRING_FILE.stat().st_mtime_ns)
    return {k: list(v) for k, v in data.items()}  # fresh lists: dataclass fields are mutable


@functools.lru_cache(maxsize=4)
def _read_spring_file(mtime_ns: int) -> dict[str, tuple[float, ...]]:
    """Parsed once per file version (keyed by mtime, so a new calibration is picked up)."""
    data = yaml.safe_load(SPRING_FILE.read_text())
    return {k: tuple(float(v) for v in data[k]) for k in ("band_edges_kpa", "stiffness_n_per_m")}


# Muscle hysteresis laws pamrun/physics/hysteresis.py implements (SpringConfig.hysteresis; a test keeps the two in step).
HYSTERESIS_LAWS = ("none", "maxwell_slip")


@dataclass
class SpringConfig:
    """Spring coefficient S(P) of the muscle, piecewise constant in pressure bands.

    The thesis used 1-bar bands from 0 to 8 bar and tuned the values by hand without
    publishing them (§8.3); ``pamrun muscle calibrate`` fits them to the step responses
    of §10.1 and writes ``conf/muscle/spring/calibrated.yaml``. Band k covers
    ``[band_edges_kpa[k], band_edges_kpa[k+1])``; pressures past the last edge use the
    last band.

    ``hysteresis`` names the muscle's hysteresis law (pamrun/physics/hysteresis.py): ``none``, one
    force-contraction curve for both directions (the thesis), or ``maxwell_slip``, elasto-slide
    elements (stiffness ``slip_stiffness_n_per_m``, slip force ``slip_force_n``, both scaled by
    P / ``slip_reference_pressure_kpa``) whose force opposes the muscle's on contraction and
    adds to it on extension, so that a cycle encloses a loop. The ``slip_*`` fields are read by
    ``maxwell_slip`` only.
    """

    band_edges_kpa: list[float] = field(default_factory=lambda: _calibrated_spring()["band_edges_kpa"])  # [kPa]
    stiffness_n_per_m: list[float] = field(default_factory=lambda: _calibrated_spring()["stiffness_n_per_m"])  # S [N/m]
    hysteresis: str = "none"  # none (one force-contraction curve, the thesis) or maxwell_slip (pamrun/physics/hysteresis.py)
    # Maxwell-slip elements (one list entry each) of the DMSP-20-260 at slip_reference_pressure_kpa. No
    # published DMSP value: assumed (pamrun/physics/hysteresis.py), a loop 2 sum(f_i) = 75 N wide at 6 bar.
    slip_stiffness_n_per_m: list[float] = field(
        default_factory=lambda: [50000.0, 16000.0, 6000.0])  # k_i [N/m]; assumed: break-away f_i/k_i 0.25-2.1 mm
    slip_force_n: list[float] = field(
        default_factory=lambda: [12.5, 12.5, 12.5])  # f_i [N]; assumed: loop 2 sum(f_i) = 5 % of the rated 1500 N
    slip_reference_pressure_kpa: float = 600.0  # P where k_i, f_i hold [kPa] (Festo's rated 6 bar); both scale P / it

    def __post_init__(self) -> None:
        edges, values = self.band_edges_kpa, self.stiffness_n_per_m
        _require(len(edges) >= 2, "band_edges_kpa", "needs at least two edges")
        _require(
            all(b > a for a, b in zip(edges, edges[1:])),
            "band_edges_kpa",
            f"must be strictly increasing in pressure, got {list(edges)}",
        )
        _require(edges[0] >= 0, "band_edges_kpa", f"pressures must be >= 0 kPa, got {edges[0]}")
        _require(
            len(values) == len(edges) - 1,
            "stiffness_n_per_m",
            f"needs one value per band: {len(edges) - 1} bands, got {len(values)} values",
        )
        _require(
            all(math.isfinite(v) and v > 0 for v in values),
            "stiffness_n_per_m",
            f"every value must be > 0 N/m, got {list(values)}",
        )
        _require(self.hysteresis in HYSTERESIS_LAWS, "hysteresis",
                 f"unknown law {self.hysteresis!r}; known: {', '.join(HYSTERESIS_LAWS)}")
        stiffness, force = self.slip_stiffness_n_per_m, self.slip_force_n
        _require(len(force) == len(stiffness), "slip_force_n",
                 f"needs one value per element: {len(stiffness)} stiffnesses, got {len(force)} slip forces")
        _require(all(math.isfinite(k) and k > 0 for k in stiffness), "slip_stiffness_n_per_m",
                 f"every element's stiffness must be > 0 N/m, got {list(stiffness)}")
        _require(all(math.isfinite(f) and f >= 0 for f in force), "slip_force_n",
                 f"every element's slip force must be >= 0 N, got {list(force)}")
        _positive(self, "slip_reference_pressure_kpa")


# Festo DMSP fluidic muscles by inner diameter: catalogue maximum force [N] (Festo, Fluidic
# Muscle DMSP/MAS catalogue; THESIS.md §8). Every force law (the thesis' polynomial, Table 8.4,
# and the Tondu-Lopez model fitted to it) is the DMSP-20's; another size scales it by the ratio
# of these ratings (see MuscleConfig).
MUSCLE_RATED_FORCE_N = {"DMSP-10": 630.0, "DMSP-20": 1500.0, "DMSP-40": 6000.0}
# Inner diameter D0 [m] of each size: the number in the name is the inner diameter in mm
# (Festo, Fluidic Muscle DMSP/MAS catalogue; THESIS.md §2: the DMSP-20 has a 20 mm one).
MUSCLE_INNER_DIAMETER_M = {"DMSP-10": 0.010, "DMSP-20": 0.020, "DMSP-40": 0.040}
FITTED_SIZE = "DMSP-20"
COUPLINGS = ("thesis", "kinematic")
# Names of the force laws and muscle dynamics pamrun/physics/muscle.py implements (its FORCE_LAWS and
# DYNAMICS registries hold one class per name; a test keeps the two in step).
FORCE_LAW_NAMES = ("thesis_polynomial", "tondu_lopez")
DYNAMICS_NAMES = ("first_order",)
COMMANDS = ("antagonistic", "independent")
# How MuscleDrive steps the kinematic coupling: pamrun/physics/kernels.py (compiled) or numpy (the reference).
KERNELS = ("numba", "numpy")


@dataclass
class JointCounts:
    """Muscles in parallel per direction, per joint (both legs alike); one field per LEG_JOINTS name."""

    hip_pitch: int = 1  # hip flexion/extension
    hip_roll: int = 1  # hip abduction/adduction
    knee: int = 2  # knee flexion/extension
    ankle_pitch: int = 2  # ankle plantar/dorsiflexion
    ankle_roll: int = 1  # ankle inversion/eversion

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            _require(1 <= value <= 8, name, f"must be 1..8 muscles per direction, got {value}")


@dataclass
class JointRadii:
    """Pulley radius per joint [mm]; 0 = automatic (see MuscleConfig.min_contraction_pct).

    One field per LEG_JOINTS name."""

    hip_pitch: float = 0.0  # hip pitch
    hip_roll: float = 0.0  # hip roll
    knee: float = 0.0  # knee
    ankle_pitch: float = 0.0  # ankle pitch
    ankle_roll: float = 0.0  # ankle roll

    def __post_init__(self) -> None:
        for name in vars(self):
            _non_negative(self, name)


@dataclass
class JointAngles:
    """Per-joint angle [deg] at which both muscles of the pair sit at their rest contraction.

    One field per LEG_JOINTS name."""

    hip_pitch: float = 0.0  # hip pitch
    hip_roll: float = 0.0  # hip roll
    knee: float = -5.0  # knee: 5 deg past its extension stop, so equal pressures lock the straight knee
    ankle_pitch: float = 0.0  # ankle pitch
    ankle_roll: float = 0.0  # ankle roll

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            _require(math.isfinite(value) and abs(value) <= 90, name, f"must lie in [-90, 90] deg, got {value}")


@dataclass
class MuscleConfig:
    """The robot's pneumatic muscles, how they sit on the joints and how they are commanded.

    Defaults are the robot that can stand and walk (``muscle=sized``, chosen with
    ``pamrun capacity``: see the README); ``muscle=thesis`` restores the thesis' model
    exactly (one DMSP-20-260 per direction, thesis coupling, 2.12 +- 0.71 V, 8 bar, ideal
    regulator). Fields:

    * ``size``: DMSP-10, -20 or -40. The force law F(x, P) (``force_law``, either) is the
      DMSP-20's; another size multiplies it by the ratio of Festo's rated forces (0.42, 1, 4). Chou &
      Hannaford's model scales force with D0^2 at equal contraction, which the 20 -> 40 mm
      step matches (x4) and the 10 -> 20 mm step does not (x2.4, not x4): the ratings are the
      measured scale. Contraction stays in % of the nominal length, and the spring S and
      damper D = tau S scale with the force, so a pair's step response in % is the same at
      every size (§10.1 holds for all).
    * ``nominal_length_m``: DMSP is sold by length (40 mm to 9 m); the stroke in metres,
      and with it the work, scales with it.
    * ``count``: muscles in parallel per direction at each joint; forces add.
    * ``radius_mm``: pulley radius per joint; 0 picks the largest radius that keeps the
      stretched muscle at or above ``min_contraction_pct`` at the joint's farthest limit,
      r = (c_rest - c_min) / 100 * L0 / max|limit - neutral|: the muscle covers the whole range. A
      larger explicit radius would over-stretch the muscle and is refused at config time,
      naming the key; a smaller one is allowed. The contracting muscle may go slack near a
      limit (its force is 0 past the zero-force contraction: a muscle cannot push).
    * ``neutral_deg``: the angle of each joint at which both muscles sit at
      ``kinematic_rest_contraction_pct`` (zero torque at equal pressures). 0 is the
      standing pose, except the knee: at -5 deg, past its extension stop, equal pressures
      press the straight knee into the stop (about 7 N m at zero action), which locks it
      as a standing person's knee is locked; without it the knee buckles and the robot falls
      within 2.3-3.0 s.
    * ``min_contraction_pct``: the most a muscle may be stretched, as a (negative)
      contraction, at least -3 % (the bottom of the thesis' force fit, §8.3, inside
      Festo's permitted pre-tension of about 5 %). The default -1 % is chosen with
      ``pamrun openloop``: at -2 % the deflated, stretched antagonist pulls back so hard that
      the hip-pitch limits are missed (7 of 9 reached), at -3 % 2 of 9.
    * ``command``: ``antagonistic`` is the thesis' 10 actions, V1,2 = V0 +- dV a (§9.5);
      ``independent`` gives 20 actions, V = V0 + dV a per muscle, so a policy sets each
      pair's co-contraction (stiffness) as well as its torque. Zero action is V0 in both.
    * ``kernel``: how the kinematic coupling's muscle step is computed, ``numba`` (one compiled
      call per muscle step, pamrun/physics/kernels.py) or ``numpy`` (the reference, several times
      slower); both give the same results to float rounding. The thesis coupling is numpy only.
    """

    force_law: str = "thesis_polynomial"  # F(x, P): thesis_polynomial (Table 8.4) or tondu_lopez (geometric, fitted to it)
    dynamics: str = "first_order"  # D x' + S x = Fce - FL (§8.3), used by the thesis coupling
    size: str = "DMSP-40"  # DMSP-10, DMSP-20 or DMSP-40 (thesis: DMSP-20)
    nominal_length_m: float = 0.30  # nominal length L0 [m] (thesis: 0.26, the DMSP-20-260N)
    count: JointCounts = field(default_factory=JointCounts)  # muscles in parallel per direction (thesis: 1)
    radius_mm: JointRadii = field(default_factory=JointRadii)  # pulley radius [mm]; 0 = automatic
    neutral_deg: JointAngles = field(default_factory=JointAngles)  # angle where the pair balances [deg]
    # Festo rates the DMSP for 0-6 bar; the thesis drove it to 8 bar, the top of its fit (§8.3).
    max_pressure_kpa: float = 600.0  # the muscle's top pressure [kPa] (Festo: 6 bar; thesis: 8)
    tau_s: float = 0.3  # D = tau * S (§8.3)
    rest_contraction_pct: float = 14.06  # thesis coupling: zero-force contraction at 176.4 kPa (§10.1)
    command: str = "antagonistic"  # antagonistic (10 actions, the thesis) or independent (20)
    v0_v: float = 3.0  # common command voltage V0; thesis 2.12 V (§9.5)
    dv_max_v: float = 3.0  # |dV| bound; thesis 0.71 V (§9.5), i.e. 1.4-2.8 bar
    # Muscle-joint coupling (see pamrun/physics/actuation.py): "kinematic" (contraction follows the
    # joint through its pulley) or "thesis" (contraction is a dynamic state, the thesis' Simulink model).
    coupling: str = "kinematic"  # kinematic (contraction follows the joint) or thesis
    # Kinematic coupling, not in the thesis: both muscles' contraction in the standing pose
    # (a pre-tensioned pair: zero torque at zero action), and the most either may be stretched.
    kinematic_rest_contraction_pct: float = 9.0  # both muscles at the neutral angle [%] (thesis model: 6.5)
    min_contraction_pct: float = -1.0  # the most a muscle may be stretched [%]; >= -3
    regulator: RegulatorConfig = field(default_factory=RegulatorConfig)  # VPPM pressure regulator
    spring: SpringConfig = field(default_factory=SpringConfig)  # spring table S(P) of the thesis dynamics
    kernel: str = "numba"  # numba: fused compiled muscle step (kinematic coupling); numpy: the reference; same results

    def __post_init__(self) -> None:
        _require(self.force_law in FORCE_LAW_NAMES, "force_law",
                 f"unknown {self.force_law!r}; known: {', '.join(FORCE_LAW_NAMES)}")
        _require(self.dynamics in DYNAMICS_NAMES, "dynamics",
                 f"unknown {self.dynamics!r}; known: {', '.join(DYNAMICS_NAMES)}")
        _require(self.size in MUSCLE_RATED_FORCE_N, "size",
                 f"unknown {self.size!r}; known: {', '.join(MUSCLE_RATED_FORCE_N)}")
        _positive(self, "nominal_length_m", "max_pressure_kpa", "tau_s", "v0_v")
        _non_negative(self, "dv_max_v")
        _require(0.04 <= self.nominal_length_m <= 9.0, "nominal_length_m",
                 f"must lie in [0.04, 9] m (Festo's DMSP lengths), got {self.nominal_length_m}")
        _require(-3.0 <= self.rest_contraction_pct < 30.0, "rest_contraction_pct", "must lie in [-3, 30) %")
        _require(self.coupling in COUPLINGS, "coupling", f"unknown {self.coupling!r}; known: {', '.join(COUPLINGS)}")
        _require(self.command in COMMANDS, "command", f"unknown {self.command!r}; known: {', '.join(COMMANDS)}")
        _require(self.kernel in KERNELS, "kernel", f"unknown {self.kernel!r}; known: {', '.join(KERNELS)}")
        _require(-3.0 <= self.min_contraction_pct <= 0.0, "min_contraction_pct",
                 f"must lie in [-3, 0] % (the force law is fitted down to -3 %), got {self.min_contraction_pct}")
        _require(self.min_contraction_pct < self.kinematic_rest_contraction_pct <= 25.0,
                 "kinematic_rest_contraction_pct",
                 f"must exceed min_contraction_pct ({self.min_contraction_pct} %) and be <= 25 % (the DMSP's "
                 f"stroke), got {self.kinematic_rest_contraction_pct}")
        _require(self.dv_max_v <= self.v0_v, "dv_max_v",
                 f"must be <= v0_v ({self.v0_v} V): a voltage cannot go negative")

    @property
    def force_scale(self) -> float:
        """Force of one muscle of ``size`` relative to the fitted DMSP-20 (rated-force ratio)."""
        return MUSCLE_RATED_FORCE_N[self.size] / MUSCLE_RATED_FORCE_N[FITTED_SIZE]

    def reach_rad(self, joint: str, limits_deg: list[float]) -> float:
        """How far [rad] the joint's farthest limit lies from its neutral angle."""
        neutral = getattr(self.neutral_deg, joint)
        return math.radians(max(abs(limits_deg[0] - neutral), abs(limits_deg[1] - neutral)))

    def radius_m(self, joint: str, reach_rad: float) -> float:
        """Pulley radius [m] of a joint whose farthest limit is ``reach_rad`` from its neutral angle."""
        explicit = getattr(self.radius_mm, joint) / 1000.0
        return explicit if explicit > 0 else self.largest_radius_m(reach_rad)

    def largest_radius_m(self, reach_rad: float) -> float:
        """The radius [m] that stretches a muscle exactly to ``min_contraction_pct`` at ``reach_rad``."""
        span_pct = self.kinematic_rest_contraction_pct - self.min_contraction_pct
        return span_pct / 100.0 * self.nominal_length_m / reach_rad


def check_muscle_stretch(muscle: MuscleConfig, body: "BodyConfig") -> None:
    """An explicit pulley radius must not stretch a muscle past ``min_contraction_pct``."""
    for joint in LEG_JOINTS:
        reach = muscle.reach_rad(joint, getattr(body, f"{joint}_limits_deg"))
        radius = muscle.radius_m(joint, reach)
        stretched = muscle.kinematic_rest_contraction_pct - 100.0 * radius * reach / muscle.nominal_length_m
        largest_mm = 1000.0 * muscle.largest_radius_m(reach)
        _require(
            stretched >= muscle.min_contraction_pct - 1e-9,
            f"radius_mm.{joint}",
            f"{radius * 1000:.1f} mm stretches a muscle to {stretched:.2f} % at the {math.degrees(reach):.1f} deg "
            f"limit, past min_contraction_pct ({muscle.min_contraction_pct} %); at most {largest_mm:.1f} mm",
        )


# --------------------------------------------------------------------------- body

# The foot as ratios of body height H and mass M (thesis Table 8.2): length (heel to toe tip),
# width and height (ankle to sole) / H, mass / M. pamrun/physics/body.py builds the foot from them, and
# the toe (BodyConfig.toe) is a part of that foot.
FOOT_LENGTH_RATIO = 0.152
FOOT_WIDTH_RATIO = 0.055
FOOT_HEIGHT_RATIO = 0.039
FOOT_MASS_RATIO = 0.0145
# The toe box's height / the foot's: ours (the toes are thinner than the foot at the ankle). It
# sets the toe's look and inertia, not where it touches the floor.
TOE_HEIGHT_RATIO = 0.5
# The human metatarsophalangeal (MTP) joint in walking, the reference of the toe's spring: the peak
# MTP moment, 0.13 N m per kg of body mass, at pre-swing (Kim, Kim, Son & Jeong, "Kinetic role of
# the metatarsophalangeal joint in normal walking: joint moment and power", Int. J. Precis. Eng.
# Manuf. 13(8):1481-1485, 2012; 22 adults, barefoot), and the peak MTP dorsiflexion at push-off,
# 60 deg barefoot (Bojsen-Moller & Lamoreux, "Significance of free dorsiflexion of the toes in
# walking", Acta Orthop. Scand. 50:471-479, 1979).
MTP_PEAK_MOMENT_NM_PER_KG = 0.13
MTP_PEAK_DORSIFLEXION_DEG = 60.0
# The largest omega * dt (omega = sqrt(k / I), the toe's own frequency) allowed: half the 2 at
# which MuJoCo's Euler step of an explicit spring goes unstable (BodyConfig.toe_critical_stiffness_nm_per_rad).
TOE_MAX_OMEGA_DT = 1.0


@dataclass
class BodyConfig:
    """Body generated from height and mass by anthropometric ratios (thesis §8.1-8.2).

    Joint limits are degrees from the standing pose, for the left leg (Table 8.3), one
    ``<joint>_limits_deg`` field per LEG_JOINTS name; the right leg mirrors the roll joints.
    What the thesis leaves open (pelvis block, hip width, contact overlap) is documented
    field by field. ``toe`` adds a passive toe to each foot (thesis §13, future work), its
    ``toe_*`` fields with their sources; its spring is checked against the physics step at
    config time (:func:`check_toe_stiffness`, from ``Config``).
    """

    height_m: float = 1.80  # Table 8.2 reference
    mass_kg: float = 80.0  # Table 8.2 reference
    # Pelvis/torso block: not in the thesis. Ratios of H and M, see pamrun/physics/body.py for the source.
    pelvis_mass_ratio: float = 0.142  # pelvis/torso block mass / M (Winter, Table 4.1)
    pelvis_width_ratio: float = 0.191  # pelvis block width / H (Drillis & Contini hip width)
    pelvis_depth_ratio: float = 0.1  # pelvis block depth / H
    pelvis_height_ratio: float = 0.1  # pelvis block height / H
    hip_width_ratio: float = 0.1  # lateral distance between the two hip joint centres / H
    # Foot-ground contact (§8.1): stiffness = robot weight / overlap, damping = stiffness / 10.
    contact_overlap_m: float = 0.001
    contact_damping_ratio: float = 0.1  # damping [N s/m] = ratio * stiffness [N/m]
    friction_static: float = 0.5  # sliding friction coefficient of the feet (MuJoCo has one: the static one)
    friction_dynamic: float = 0.6  # the thesis' dynamic coefficient (no MuJoCo counterpart; kept for the record)
    friction_critical_velocity_m_s: float = 0.10  # the thesis' critical velocity (no MuJoCo counterpart)
    # Joints (Table 8.2)
    joint_stiffness_nm_per_rad: float = 0.0  # passive joint spring (Table 8.2: none)
    joint_damping_nms_per_rad: float = 1.0  # passive joint damping (Table 8.2)
    # Joint limits: the thesis' Simscape stop is a spring-damper (1e4 N m/rad, 10 N m s/rad,
    # Table 8.2). MuJoCo's soft limit cannot be one (see pamrun/physics/body.py); we use its own stiff,
    # critically damped stop: time constant [s] and damping ratio of the constraint. 5 ms holds
    # the sized muscles (up to ~100 N m at a limit) within 2 deg; 10 ms lets the ankle pass by 4.
    joint_limit_timeconst_s: float = 0.005  # 2 physics steps, MuJoCo's stiffest stable stop
    joint_limit_dampratio: float = 1.0  # damping ratio of the limit stop (1 = critically damped)
    # Left-leg limits, degrees from the standing pose (Table 8.3)
    hip_pitch_limits_deg: list[float] = field(default_factory=lambda: [-45.0, 45.0])
    hip_roll_limits_deg: list[float] = field(default_factory=lambda: [-22.5, 11.25])
    knee_limits_deg: list[float] = field(default_factory=lambda: [0.0, 90.0])
    ankle_pitch_limits_deg: list[float] = field(default_factory=lambda: [-45.0, 45.0])
    ankle_roll_limits_deg: list[float] = field(default_factory=lambda: [-25.0, 35.0])
    # A passive toe (thesis §13, future work): a toe segment hinged about the lateral axis at the
    # metatarsal line, held flat by a torsional spring; no muscle, no action (pamrun/physics/body.py).
    toe: bool = False  # add the passive toe to each foot (false: the thesis' one-piece foot, unchanged)
    # toe (metatarsal line to tip) / foot length: the first MTP joint lies at 70-79 % of the foot's
    # length from the heel (3-D scans of 453 feet: "Flexion location of the first metatarsophalangeal
    # joint and the location of forefoot bend in general purpose women's footwear"), the lateral ones
    # further back (OpenSim gait2392's oblique MTP axis: 65 %); a straight hinge line at 70 %.
    toe_length_ratio: float = 0.30
    # toe mass / foot mass: OpenSim gait2392 (Delp et al., IEEE TBME 37:757, 1990; masses after
    # Anderson & Pandy 1999): talus 0.1, calcaneus 1.25, toes 0.2166 kg, so 0.2166 / 1.5666.
    toe_mass_ratio: float = 0.138
    # MTP spring [N m/rad]: the human's peak walking moment at its peak dorsiflexion (MTP_PEAK_*),
    # for the default robot's 37.12 kg: 0.13 N m/kg * 37.12 kg / 1.047 rad = 4.61.
    toe_stiffness_nm_per_rad: float = 4.61
    # MTP damping [N m s/rad]: a tenth of the hinges' 1 (Table 8.2); for the default toe
    # (I = 3.8e-4 kg m^2 about its hinge) a damping ratio b / (2 sqrt(k I)) of 1.2, so it settles flat.
    toe_damping_nms_per_rad: float = 0.1
    # MTP range [deg], dorsiflexion (toe up) negative: -60, the peak in barefoot walking (MTP_PEAK_*);
    # +30, ours, a stop that keeps a swinging toe from folding under. (Not *_limits_deg: those are LEG_JOINTS'.)
    toe_range_deg: list[float] = field(default_factory=lambda: [-MTP_PEAK_DORSIFLEXION_DEG, 30.0])

    def __post_init__(self) -> None:
        _positive(
            self,
            "height_m",
            "mass_kg",
            "pelvis_mass_ratio",
            "pelvis_width_ratio",
            "pelvis_depth_ratio",
            "pelvis_height_ratio",
            "hip_width_ratio",
            "contact_overlap_m",
            "contact_damping_ratio",
            "friction_critical_velocity_m_s",
        )
        _non_negative(
            self,
            "friction_static",
            "friction_dynamic",
            "joint_stiffness_nm_per_rad",
            "joint_damping_nms_per_rad",
        )
        _positive(self, "joint_limit_timeconst_s", "joint_limit_dampratio")
        _require(0.5 <= self.height_m <= 3.0, "height_m", f"must lie in [0.5, 3.0] m, got {self.height_m}")
        for name in LEG_JOINTS:
            key = f"{name}_limits_deg"
            lo_hi = getattr(self, key)
            _require(
                len(lo_hi) == 2 and lo_hi[0] < lo_hi[1],
                key,
                f"must be [lower, upper] with lower < upper, got {list(lo_hi)}",
            )
        _positive(self, "toe_length_ratio", "toe_mass_ratio", "toe_stiffness_nm_per_rad")
        _non_negative(self, "toe_damping_nms_per_rad")
        _require(self.toe_length_ratio <= 0.5, "toe_length_ratio",
                 f"must lie in (0, 0.5]: the toe is the foot's front part, got {self.toe_length_ratio}")
        _require(self.toe_mass_ratio < 1.0, "toe_mass_ratio",
                 f"must lie in (0, 1): the toe is a part of the foot's mass, got {self.toe_mass_ratio}")
        lo_hi = self.toe_range_deg
        _require(len(lo_hi) == 2 and -90.0 <= lo_hi[0] < 0.0 < lo_hi[1] <= 90.0, "toe_range_deg",
                 f"must be [lower, upper] with -90 <= lower < 0 < upper <= 90 (0: the toe flat), got {list(lo_hi)}")

    def toe_box_m(self) -> tuple[float, float, float]:
        """The toe's box: length (metatarsal line to tip), width, height [m]."""
        foot_length, foot_height = FOOT_LENGTH_RATIO * self.height_m, FOOT_HEIGHT_RATIO * self.height_m
        return self.toe_length_ratio * foot_length, FOOT_WIDTH_RATIO * self.height_m, TOE_HEIGHT_RATIO * foot_height

    def toe_mass_kg(self) -> float:
        return self.toe_mass_ratio * FOOT_MASS_RATIO * self.mass_kg

    def toe_critical_stiffness_nm_per_rad(self, physics_dt_s: float) -> float:
        """The stiffest toe spring [N m/rad] MuJoCo integrates stably, with margin, at ``physics_dt_s``.

        MuJoCo's Euler step treats a joint's damping implicitly and its spring explicitly. For
        the toe's hinge alone (inertia I about it, spring k, omega = sqrt(k / I)) one step is
        v' = v - dt (k q + b v') / I, q' = q + dt v'. Without damping the step's two eigenvalues
        solve l^2 - (2 - (omega dt)^2) l + 1 = 0: they stay on the unit circle while omega dt <= 2
        and one grows past it, so k < 4 I / dt^2; the implicit damping only shrinks them. We
        allow half that omega (TOE_MAX_OMEGA_DT = 1, k <= I / dt^2): the toe's effective inertia
        in the robot is below its own (the foot moves with it), and at omega dt = 2 a period has
        only pi steps. I is bounded below by the toe box's about its rear edge's line,
        m (l^2 / 3 + h^2 / 12); the hinge sits a little above the sole, which only adds to it.
        Checked on the default robot at dt = 2.5 ms: the toe's own inertia about its hinge is
        3.8e-4 kg m^2, its effective one (1 / (M^-1)_toe, the foot moving with it) 2.75e-4, so
        4 I_eff / dt^2 = 176 N m/rad; undamped, a swinging toe grows between 180 and 190 N m/rad.
        This bound allows 60 (the default spring is 4.61).
        """
        length, _, height = self.toe_box_m()
        inertia = self.toe_mass_kg() * (length**2 / 3 + height**2 / 12)
        return inertia * (TOE_MAX_OMEGA_DT / physics_dt_s) ** 2


def check_toe_stiffness(body: BodyConfig, physics_dt_s: float) -> None:
    """``body.toe``: its spring must be one MuJoCo integrates stably at the physics step."""
    if not body.toe:
        return
    most = body.toe_critical_stiffness_nm_per_rad(physics_dt_s)
    _require(body.toe_stiffness_nm_per_rad <= most, "toe_stiffness_nm_per_rad",
             f"{body.toe_stiffness_nm_per_rad} N m/rad is too stiff for the toe's inertia at env.physics_dt_s = "
             f"{physics_dt_s} s: at most {most:.1f} N m/rad (omega dt <= {TOE_MAX_OMEGA_DT}, see "
             "BodyConfig.toe_critical_stiffness_nm_per_rad); lower it or the physics step")
