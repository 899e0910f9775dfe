"""Schema of the muscles' proportional pressure regulator (thesis §8.3): ``muscle.regulator``."""

from __future__ import annotations

import math
from dataclasses import dataclass

from pamrun.config.checks import _non_negative, _positive, _require

# Regulator dynamics pamrun/physics/valve.py implements (RegulatorConfig.model).
REGULATOR_MODELS = ("lag", "flow")


@dataclass
class RegulatorConfig:
    """Festo VPPM-8L-L-1-G14-0L10H proportional pressure regulator (thesis §8.3).

    Input 0-10 V, output 0.1-10 bar. The thesis calls the relation linear and, with
    V0 = 2.12 V +- 0.71 V, quotes pressures of "about 1.4 to 3 bar" (§9.5): that is
    1 bar per volt, which we take. The thesis does not model the regulator's dynamics
    (an ideal regulator, ``lag_s = 0``, as ``muscle=thesis`` keeps). A real proportional
    regulator filling a muscle needs tens of milliseconds: Festo's proportional pressure
    regulators are quoted at about 50-100 ms response time, and the Lucy biped's team
    (VUB) found off-the-shelf regulating valves "too heavy and too slow" for walking. We
    take the fast end, a first-order lag of 50 ms (``lag_s``), for the default robot.

    ``model`` picks the regulator's dynamics (pamrun/physics/valve.py): ``lag``, that lag with
    unlimited flow (the default), or ``flow``, the same lag whose rate of change
    is capped by what a proportional valve can flow into (or out of) the muscle's current
    volume: ISO 6358 flow through the sonic conductance derived from ``nominal_flow_nl_min``
    and ``critical_pressure_ratio``, filling from ``supply_pressure_kpa`` (or from a reservoir
    of ``reservoir_volume_l`` refilled by a compressor) and exhausting to the atmosphere. The
    ``flow`` fields are read by ``model=flow`` only.
    """

    gain_kpa_per_v: float = 100.0  # pressure per volt: 1 bar/V, the thesis' "linear" (§9.5)
    min_voltage_v: float = 0.0  # lowest command voltage (VPPM input 0-10 V)
    max_voltage_v: float = 10.0  # highest command voltage
    min_pressure_kpa: float = 10.0  # 0.1 bar
    max_pressure_kpa: float = 1000.0  # 10 bar
    lag_s: float = 0.05  # first-order time constant [s]; 0 = ideal (the thesis)
    model: str = "lag"  # lag: first-order lag, unlimited flow; flow: its rate capped by the valve (pamrun/physics/valve.py)
    # Festo, proportional directional control valve MPYE datasheet: MPYE-5-1/8-HF-010-B, standard nominal flow rate
    # qnN = 700 l/min, which Festo measures from p1 = 6 bar to p2 = 5 bar (gauge; pamrun.physics.valve.NOMINAL_FLOW_*_KPA).
    # (The same datasheet gives 350 l/min for the low-flow MPYE-5-1/8-LF, which public valve models quote.)
    nominal_flow_nl_min: float = 700.0  # the valve's standard nominal flow qnN [normal l/min] (MPYE-5-1/8-HF)
    critical_pressure_ratio: float = 0.528  # ISO 6358 b (choked below it); the datasheet has none: an ideal nozzle's
    supply_pressure_kpa: float = 800.0  # supply (gauge) [kPa], >= the top pressure the muscles are driven to
    reservoir_volume_l: float = 0.0  # air tank between compressor and valves [litres]; 0 = an ideal supply
    compressor_flow_nl_min: float = 200.0  # compressor refilling the tank to the supply pressure [normal l/min]; assumed

    def __post_init__(self) -> None:
        _positive(self, "gain_kpa_per_v", "max_voltage_v", "max_pressure_kpa")
        _non_negative(self, "min_voltage_v", "min_pressure_kpa", "lag_s")
        _require(self.min_voltage_v < self.max_voltage_v, "max_voltage_v", "must exceed min_voltage_v")
        _require(self.min_pressure_kpa < self.max_pressure_kpa, "max_pressure_kpa", "must exceed min_pressure_kpa")
        _require(self.model in REGULATOR_MODELS, "model",
                 f"unknown {self.model!r}; known: {', '.join(REGULATOR_MODELS)}")
        _positive(self, "nominal_flow_nl_min", "supply_pressure_kpa")
        _non_negative(self, "reservoir_volume_l", "compressor_flow_nl_min")
        b = self.critical_pressure_ratio
        _require(math.isfinite(b) and 0.0 < b < 1.0, "critical_pressure_ratio", f"must lie in (0, 1), got {b}")

    def check_supply(self, muscle_max_pressure_kpa: float) -> None:
        """``model=flow``: the supply must reach the top pressure the muscles are driven to, the
        regulator's or the muscle's maximum, whichever is lower (a valve cannot fill above its supply)."""
        top = min(self.max_pressure_kpa, muscle_max_pressure_kpa)
        _require(self.model != "flow" or self.supply_pressure_kpa >= top, "supply_pressure_kpa",
                 f"{self.supply_pressure_kpa} kPa is below the top pressure the muscles are driven to, {top} kPa "
                 f"(min of regulator.max_pressure_kpa and the muscle's max_pressure_kpa)")
