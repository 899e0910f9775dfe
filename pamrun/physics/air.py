"""A muscle's volume and the supply air it draws (Chou & Hannaford's braid geometry), shared
by the env's air meter, the gait metrics, the capacity analysis and the flow-limited valve."""

from __future__ import annotations

import math

import numpy as np

# Largest contraction: about 25 % of the nominal length (Festo DMSP catalogue; THESIS.md §8).
MAX_CONTRACTION_PCT = 25.0
# Braid angle at which a McKibben muscle stops contracting, arccos(1/sqrt(3)) = 54.7 deg
# (Chou & Hannaford 1996: the pressure force vanishes there).
NEUTRAL_BRAID_ANGLE_RAD = float(np.arccos(1.0 / np.sqrt(3.0)))
# Normal litres (DIN 1343 normal conditions): 101.325 kPa and 0 degC.
NORMAL_PRESSURE_KPA = 101.325
NORMAL_TEMPERATURE_K = 273.15
# The air in the muscles: room temperature, 20 degC (ISO 8778's standard reference atmosphere).
AIR_TEMPERATURE_K = 293.15
# Pressures in pamrun are gauge; absolute = gauge + the ambient, taken as the standard atmosphere.
ATMOSPHERE_KPA = 101.325


class AirMeter:
    """The volume, gas and supply air of a robot's muscles (:func:`muscle_volume_l`,
    :func:`air_nl`), its geometry's constants computed once: the env meters every control
    step with it (``info["air_nl"]``, ``reward.kair``).

    ``muscles_per_side``: muscles in parallel per direction of each of the 10 joints (one
    value, or (10,)); arrays of 20 values are the (10, 2) pairs raveled.
    """

    def __init__(self, nominal_length_m: float, inner_diameter_m: float, muscles_per_side=1,
                 temperature_k: float = AIR_TEMPERATURE_K):
        l0 = self.nominal_length_m = float(nominal_length_m)
        b = (1.0 - MAX_CONTRACTION_PCT / 100.0) * l0 / math.cos(NEUTRAL_BRAID_ANGLE_RAD)  # fibre length [m]
        turns = b * math.sqrt(1.0 - (l0 / b) ** 2) / (math.pi * inner_diameter_m)
        self._b2, self._litres = b * b, 1000.0 / (4.0 * math.pi * turns**2)  # m^3 -> litres
        count = np.asarray(muscles_per_side, float)
        self.count = np.repeat(count, 2) if count.ndim else count  # both muscles of a joint
        self.nl_per_kpa_l = NORMAL_TEMPERATURE_K / (NORMAL_PRESSURE_KPA * temperature_k)

    def volume_l(self, contraction_pct) -> np.ndarray:
        length = (1.0 - np.minimum(contraction_pct, MAX_CONTRACTION_PCT) / 100.0) * self.nominal_length_m
        return length * (self._b2 - length * length) * self._litres

    def gas_kpa_l(self, pressure_kpa, contraction_pct) -> np.ndarray:
        """Each muscle's gas amount P V [kPa litres], P absolute (gauge + 101.325 kPa)."""
        return (np.asarray(pressure_kpa, float) + ATMOSPHERE_KPA) * self.volume_l(contraction_pct)

    def drawn_nl(self, gas_before_kpa_l, gas_after_kpa_l) -> float:
        """Supply air [normal litres] drawn between two gas states: each muscle's growth of
        P V, none where it falls (it exhausts to the atmosphere), times its count."""
        drawn = np.maximum(np.subtract(gas_after_kpa_l, gas_before_kpa_l), 0.0) * self.count
        return float(drawn.sum() * self.nl_per_kpa_l)


def muscle_volume_l(contraction_pct, nominal_length_m: float, inner_diameter_m: float) -> np.ndarray:
    """Inner volume [litres] of one muscle at a contraction [% of nominal length], vectorised.

    Chou & Hannaford's geometric model (C.-P. Chou, B. Hannaford, "Measurement and modeling
    of McKibben pneumatic artificial muscles", IEEE Trans. Robotics and Automation 12(1),
    1996): the muscle is a cylinder inside a braid of fibres of length b wound n turns
    around it, at braid angle theta to the axis, so

        L = b cos(theta),   D = b sin(theta) / (n pi),   V = pi D^2 L / 4 = L (b^2 - L^2) / (4 pi n^2).

    b and n are fixed by two facts: the muscle contracts until the braid reaches its neutral
    angle 54.7 deg (cos = 1/sqrt(3)) at ``MAX_CONTRACTION_PCT`` (25 %), so
    b = sqrt(3) (1 - 0.25) L0; and at 0 % it has its nominal length L0 and inner diameter
    D0, so n = b sin(theta0) / (pi D0) with cos(theta0) = L0 / b. Then V(0 %) = pi D0^2 L0 / 4
    exactly, and V grows with contraction up to its maximum at 25 % (27/22 of V(0 %)).
    Contraction past 25 % is clipped to 25 % (the braid cannot pass its neutral angle); a
    stretched muscle (negative contraction) has a smaller volume.

    The rubber wall is ignored (a thin-walled braid): its thickness fills part of the
    cylinder, so the model slightly over-estimates the volume, and with it the air.
    """
    return AirMeter(nominal_length_m, inner_diameter_m).volume_l(np.asarray(contraction_pct, float))


def air_nl(pressure_kpa, contraction_pct, nominal_length_m: float, inner_diameter_m: float,
           muscles_per_side=1, temperature_k: float = AIR_TEMPERATURE_K) -> float:
    """Supply air [normal litres] the muscles draw over a series of states.

    ``pressure_kpa`` (gauge) and ``contraction_pct`` are (n, 20) arrays, one row per
    step, muscles ordered as the (10, 2) pairs raveled; ``muscles_per_side`` is the number of
    muscles in parallel per direction of each of the 10 joints (one value, or (10,)): each
    of them draws the same air as the muscle it doubles. Between consecutive rows a muscle
    holding the gas amount P V (absolute pressure P = gauge + 101.325 kPa, volume V from
    :func:`muscle_volume_l`) draws air only while P V grows (being filled, or contracting at
    constant pressure); when it falls the muscle exhausts to the atmosphere and draws none:

        air_nl = sum_steps sum_muscles count * max(0, Delta(P V)) / P_N * T_N / T

    with P_N = 101.325 kPa and T_N = 273.15 K (DIN 1343 normal litres). The fill is
    isothermal and the air an ideal gas at ``temperature_k``, by default room temperature
    (20 degC): a muscle filled from p1 to p2 at constant volume V draws
    V (p2 - p1) / 101.325 * 273.15 / 293.15 Nl (0.93 V (p2 - p1) / 101.325). Only changes
    between the rows count: the fill before the first row is not included.
    """
    meter = AirMeter(nominal_length_m, inner_diameter_m, muscles_per_side, temperature_k)
    gas = meter.gas_kpa_l(pressure_kpa, np.asarray(contraction_pct, float))
    return meter.drawn_nl(gas[:-1], gas[1:])
