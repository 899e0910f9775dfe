"""Schemas of the robot: the pneumatic muscles (thesis §8.3, §9.5) and the body (§8.1-8.2)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

from pamrun.config.checks import CONF_DIR, _non_negative, _positive, _require

# --------------------------------------------------------------------------- muscle


@dataclass
class RegulatorConfig:
    """Festo VPPM-8L-L-1-G14-0L10H proportional pressure regulator (thesis §8.3).

    Input 0-10 V, output 0.1-10 bar. The thesis calls the relation linear and, with
    V0 = 2.12 V +- 0.71 V, quotes pressures of "about 1.4 to 3 bar" (§9.5): that is
    1 bar per volt, which we take. Its dynamics are not modelled in the thesis;
    ``lag_s`` adds an optional first-order lag (0 = ideal regulator, the thesis).
    """

    gain_kpa_per_v: float = 100.0
    min_voltage_v: float = 0.0
    max_voltage_v: float = 10.0
    min_pressure_kpa: float = 10.0  # 0.1 bar
    max_pressure_kpa: float = 1000.0  # 10 bar
    lag_s: float = 0.0

    def __post_init__(self) -> None:
        _positive(self, "gain_kpa_per_v", "max_voltage_v", "max_pressure_kpa")
        _non_negative(self, "min_voltage_v", "min_pressure_kpa", "lag_s")
        _require(self.min_voltage_v < self.max_voltage_v, "max_voltage_v", "must exceed min_voltage_v")
        _require(self.min_pressure_kpa < self.max_pressure_kpa, "max_pressure_kpa", "must exceed min_pressure_kpa")


SPRING_FILE = CONF_DIR / "muscle" / "spring" / "calibrated.yaml"


def _calibrated_spring() -> dict[str, list[float]]:
    """The table written by ``pamrun muscle calibrate``: the one source of default S(P)."""
    data = _read_spring_file(SPRING_FILE.stat().st_mtime_ns)
    return {k: list(v) for k, v in data.items()}  # fresh lists: dataclass fields are mutable


@functools.lru_cache(maxsize=4)
def _read_spring_file(mtime_ns: int) -> dict[str, tuple[float, ...]]:
    """Parsed once per file version (keyed by mtime, so a new calibration is picked up)."""
    import yaml

    data = yaml.safe_load(SPRING_FILE.read_text())
    return {k: tuple(float(v) for v in data[k]) for k in ("band_edges_kpa", "stiffness_n_per_m")}


@dataclass
class SpringConfig:
    """Spring coefficient S(P) of the muscle, piecewise constant in pressure bands.

    The thesis used 1-bar bands from 0 to 8 bar and tuned the values by hand without
    publishing them (§8.3); ``pamrun muscle calibrate`` fits them to the step responses
    of §10.1 and writes ``conf/muscle/spring/calibrated.yaml``. Band k covers
    ``[band_edges_kpa[k], band_edges_kpa[k+1])``; pressures past the last edge use the
    last band. ``hysteresis`` names the law that chooses between inflation and deflation
    tables (only ``none`` so far: one table for both, as in the thesis).
    """

    band_edges_kpa: list[float] = field(default_factory=lambda: _calibrated_spring()["band_edges_kpa"])
    stiffness_n_per_m: list[float] = field(default_factory=lambda: _calibrated_spring()["stiffness_n_per_m"])
    hysteresis: str = "none"

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
        _require(self.hysteresis in ("none",), "hysteresis", f"unknown law {self.hysteresis!r}; known: none")


@dataclass
class MuscleConfig:
    """One Festo DMSP-20-260N fluidic muscle and its antagonistic command (thesis §8.3, §9.5)."""

    force_law: str = "thesis_polynomial"  # F(x, P) of Table 8.4
    dynamics: str = "first_order"  # D x' + S x = Fce - FL (§8.3)
    nominal_length_m: float = 0.26  # DMSP-20-260N: 260 mm nominal length
    max_pressure_kpa: float = 800.0  # top of the polynomial's fitted range (§8.3): 8 bar
    tau_s: float = 0.3  # D = tau * S (§8.3)
    rest_contraction_pct: float = 14.06  # zero-force contraction at 176.4 kPa (§10.1)
    v0_v: float = 2.12  # common command voltage V0 (§9.5)
    dv_max_v: float = 0.71  # |dV| <= 0.71 V (§9.5)
    # Muscle-joint coupling (see pamrun/actuation.py): "thesis" (contraction is a dynamic
    # state, the thesis' Simulink model) or "kinematic" (contraction follows the joint).
    coupling: str = "thesis"
    # Not in the thesis: pre-tension and stroke of each pair (pulley radii follow from them).
    kinematic_rest_contraction_pct: float = 6.5
    kinematic_max_contraction_pct: float = 13.0
    regulator: RegulatorConfig = field(default_factory=RegulatorConfig)
    spring: SpringConfig = field(default_factory=SpringConfig)

    def __post_init__(self) -> None:
        from pamrun.muscle import DYNAMICS, FORCE_LAWS  # the registries live with the physics

        _require(self.force_law in FORCE_LAWS, "force_law", f"unknown {self.force_law!r}; known: {sorted(FORCE_LAWS)}")
        _require(self.dynamics in DYNAMICS, "dynamics", f"unknown {self.dynamics!r}; known: {sorted(DYNAMICS)}")
        _positive(self, "nominal_length_m", "max_pressure_kpa", "tau_s", "v0_v")
        _non_negative(self, "dv_max_v")
        _require(-3.0 <= self.rest_contraction_pct < 30.0, "rest_contraction_pct", "must lie in [-3, 30) %")
        _require(self.coupling in ("thesis", "kinematic"), "coupling", f"unknown {self.coupling!r}; known: thesis, kinematic")
        _require(
            0.0 <= 2 * self.kinematic_rest_contraction_pct - self.kinematic_max_contraction_pct
            and self.kinematic_rest_contraction_pct < self.kinematic_max_contraction_pct <= 28.0,
            "kinematic_max_contraction_pct",
            "must exceed kinematic_rest_contraction_pct, be <= 28 % and <= twice the rest contraction "
            "(so the antagonist never stretches below 0 %)",
        )
        _require(self.dv_max_v <= self.v0_v, "dv_max_v", f"must be <= v0_v ({self.v0_v} V): a voltage cannot go negative")


# --------------------------------------------------------------------------- body


@dataclass
class BodyConfig:
    """Body generated from height and mass by anthropometric ratios (thesis §8.1-8.2).

    Joint limits are degrees from the standing pose, for the left leg (Table 8.3); the
    right leg mirrors the roll joints. What the thesis leaves open (pelvis block, hip
    width, contact overlap) is documented field by field.
    """

    height_m: float = 1.80  # Table 8.2 reference
    mass_kg: float = 80.0  # Table 8.2 reference
    # Pelvis/torso block: not in the thesis. Ratios of H and M, see pamrun/body.py for the source.
    pelvis_mass_ratio: float = 0.142
    pelvis_width_ratio: float = 0.191
    pelvis_depth_ratio: float = 0.1
    pelvis_height_ratio: float = 0.1
    hip_width_ratio: float = 0.1  # lateral distance between the two hip joint centres / H
    # Foot-ground contact (§8.1): stiffness = robot weight / overlap, damping = stiffness / 10.
    contact_overlap_m: float = 0.001
    contact_damping_ratio: float = 0.1  # damping [N s/m] = ratio * stiffness [N/m]
    friction_static: float = 0.5
    friction_dynamic: float = 0.6
    friction_critical_velocity_m_s: float = 0.10
    # Joints (Table 8.2)
    joint_stiffness_nm_per_rad: float = 0.0
    joint_damping_nms_per_rad: float = 1.0
    # Joint limits: the thesis' Simscape stop is a spring-damper (1e4 N m/rad, 10 N m s/rad,
    # Table 8.2). MuJoCo's soft limit cannot be one (see pamrun/body.py); we use its own stiff,
    # critically damped stop: time constant [s] and damping ratio of the constraint.
    joint_limit_timeconst_s: float = 0.01
    joint_limit_dampratio: float = 1.0
    # Left-leg limits, degrees from the standing pose (Table 8.3)
    hip_pitch_limits_deg: list[float] = field(default_factory=lambda: [-45.0, 45.0])
    hip_roll_limits_deg: list[float] = field(default_factory=lambda: [-22.5, 11.25])
    knee_limits_deg: list[float] = field(default_factory=lambda: [0.0, 90.0])
    ankle_pitch_limits_deg: list[float] = field(default_factory=lambda: [-45.0, 45.0])
    ankle_roll_limits_deg: list[float] = field(default_factory=lambda: [-25.0, 35.0])

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
        for name in ("hip_pitch", "hip_roll", "knee", "ankle_pitch", "ankle_roll"):
            key = f"{name}_limits_deg"
            lo_hi = getattr(self, key)
            _require(
                len(lo_hi) == 2 and lo_hi[0] < lo_hi[1],
                key,
                f"must be [lower, upper] with lower < upper, got {list(lo_hi)}",
            )
