"""Flow-limited proportional valve: the regulator of ``muscle.regulator.model=flow``.

``model=lag`` (the default, :class:`pamrun.physics.muscle.Regulator`) moves each muscle's pressure
towards its target through a first-order lag and assumes the valve can always flow the air
that takes. ``model=flow`` (:class:`FlowRegulator`) keeps that lag as the valve's small-signal
response and caps the rate of change by the air the valve can pass at full opening:

    dP/dt = clip((P* - P) / lag_s, -G_exhaust, G_fill)            [kPa/s, gauge pressures]

so a proportional valve whose opening grows with the pressure error until it is fully open
(its proportional band is G lag_s wide; with ``lag_s`` = 0 it opens fully at any error). This
is the simplest form in which the flow depends on the muscle's volume and the fill slows as
the muscle nears the supply, and it leaves the small-signal behaviour the robot was tuned
with (the 50 ms lag) unchanged; only large steps are slower.

Flow at full opening, ISO 6358 (sonic conductance C, critical pressure ratio b), into the
muscle from the supply p_s and out of it to the atmosphere p_a (absolute pressures):

    Q = C p_up psi(p_down / p_up),  psi(r) = 1 for r <= b (choked),
                                    psi(r) = sqrt(1 - ((r - b) / (1 - b))^2) for b < r <= 1

in normal litres per second. Isothermal ideal gas (the muscle at room temperature T): a
normal litre (DIN 1343: P_N = 101.325 kPa, T_N = 273.15 K) adds P_N T / T_N [kPa litres] to
the gas P V of a volume V, so d(P_abs V)/dt = P_N Q T / T_N and

    G_fill = P_N T / T_N * Q(p_s -> P) / V,   G_exhaust = P_N T / T_N * Q(P -> p_a) / V.

V is the side's volume: ``muscles_per_side`` muscles of :func:`pamrun.physics.muscle.muscle_volume_l`
at the last step's contraction (one valve per side feeds the muscles in parallel, as one
regulator does in the lag model). When the volume changes between steps the gas is kept,
P_abs V_old = P_abs' V_new, which is the -P dV/dt term of dP/dt = (P_N Q T/T_N - P dV/dt) / V.

Each step (dt) freezes G at the step's start: the pressure moves by
clip((P* - P) (1 - exp(-dt / lag_s)), -G_exhaust dt, G_fill dt) (the lag's exact share, so it
never overshoots its target), and a fill stops at the supply. Reservoir
(``reservoir_volume_l`` > 0): the supply is a tank at ``reservoir_kpa``, starting at (and a
compressor of ``compressor_flow_nl_min`` refilling it up to) ``supply_pressure_kpa``; the air
the valves put into the muscles leaves it, Delta(P_res) V_res = -sum(Delta(P) V) over the
sides being filled (an exhaust draws nothing). 0 litres is an ideal supply.

The valve is a Festo MPYE-5-1/8-HF proportional directional control valve (its spool opening
follows its command: the usual way to drive a muscle with pressure feedback), not the VPPM
whose 0-10 V map and lag the regulator keeps: the MPYE's datasheet flow is the figure cited
(``RegulatorConfig.nominal_flow_nl_min``), and it fills and exhausts through the same
conductance. C comes from that standard nominal flow qnN, which Festo measures from 6 to
5 bar gauge: C = qnN / (p1 psi(p2 / p1)), p1 and p2 absolute. The datasheet gives no b; the
default, 0.528 = (2 / (gamma + 1))^(gamma / (gamma - 1)) for air (gamma = 1.4), is an ideal
nozzle's, and the cautious choice: a lower b derives a larger C from the same qnN, so a
faster fill. The datasheet's litres are taken as normal litres (DIN 1343, as
:func:`pamrun.physics.muscle.air_nl`); were they at 20 degC, the valve would be 7 % slower. The
supply default, 800 kPa, leaves 2 bar above the DMSP's rated 6 bar (``muscle.max_pressure_kpa``)
so the fill does not stall at the top of the band; the compressor default (200 normal l/min,
used only with a reservoir) is an assumed small compressor, not a datasheet figure.

Limits: isothermal (a fast fill heats the air; a real muscle's pressure overshoots, then
sags as it cools); the volume is the last muscle step's (5 ms late); and the reservoir is
stepped explicitly: each step fills up to the tank's pressure at its start, so a tank small
enough to equalise with the muscles may end a step a fraction of a kPa below them.

The compiled muscle step (:mod:`pamrun.physics.kernels`) runs the same model; this module is its
numpy reference.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from pamrun.config import ConfigError
from pamrun.config.robot import MUSCLE_INNER_DIAMETER_M
from pamrun.physics.air import (
    AIR_TEMPERATURE_K,
    ATMOSPHERE_KPA,
    MAX_CONTRACTION_PCT,
    NORMAL_PRESSURE_KPA,
    NORMAL_TEMPERATURE_K,
    muscle_volume_l,
)

if TYPE_CHECKING:
    from pamrun.config import MuscleConfig, RegulatorConfig

# Festo's standard nominal flow rate qnN is measured from p1 = 6 bar to p2 = 5 bar (gauge), at
# 20 degC (Festo catalogue "One-way flow control valves, flow control and functional
# combinations", 2010/10, key features: "Standard nominal flow rate qnN"). The datasheet figure
# lives in RegulatorConfig.nominal_flow_nl_min.
NOMINAL_FLOW_INLET_KPA = 600.0
NOMINAL_FLOW_OUTLET_KPA = 500.0
# kPa litres of gas (at the muscles' temperature) per normal litre of air: P_N T / T_N.
KPA_L_PER_NL = NORMAL_PRESSURE_KPA * AIR_TEMPERATURE_K / NORMAL_TEMPERATURE_K


def flow_function(pressure_ratio, critical_pressure_ratio: float) -> np.ndarray:
    """ISO 6358's psi(r) of r = p_down / p_up (absolute): 1 choked (r <= b), the subsonic
    ellipse sqrt(1 - ((r - b) / (1 - b))^2) above, 0 at r >= 1 (no flow uphill)."""
    r = np.minimum(np.asarray(pressure_ratio, float), 1.0)
    x = (r - critical_pressure_ratio) / (1.0 - critical_pressure_ratio)
    return np.where(r <= critical_pressure_ratio, 1.0, np.sqrt(np.maximum(1.0 - x * x, 0.0)))


def sonic_conductance_nl_s_kpa(nominal_flow_nl_min: float, critical_pressure_ratio: float) -> float:
    """ISO 6358 sonic conductance C [normal litres / (s kPa)] that passes ``nominal_flow_nl_min``
    from 6 to 5 bar gauge (how Festo quotes qnN)."""
    inlet = NOMINAL_FLOW_INLET_KPA + ATMOSPHERE_KPA
    ratio = (NOMINAL_FLOW_OUTLET_KPA + ATMOSPHERE_KPA) / inlet
    return nominal_flow_nl_min / 60.0 / (inlet * float(flow_function(ratio, critical_pressure_ratio)))


def volume_cubic_l(nominal_length_m: float, inner_diameter_m: float) -> np.ndarray:
    """Coefficients a0..a3 of one muscle's volume V(c) = a0 + a1 c + a2 c^2 + a3 c^3 [litres], c in %.

    :func:`pamrun.physics.muscle.muscle_volume_l` is k L (b^2 - L^2) with L = (1 - c / 100) L0 for
    c <= 25 %: a cubic in c, so four of its values fix it (the compiled step evaluates it so)."""
    c = np.array([0.0, 8.0, 16.0, 24.0])
    return np.linalg.solve(np.vander(c, 4, increasing=True), muscle_volume_l(c, nominal_length_m, inner_diameter_m))


class Regulator:
    """VPPM proportional pressure regulator: voltage [V] -> pressure [kPa] (thesis §8.3).

    Linear (``gain_kpa_per_v``), input clipped to its voltage range and output to its
    pressure range (0.1-10 bar). With ``lag_s`` > 0 the pressure follows the target
    through an exactly discretised first-order lag; with 0 it is reached at once.

    State: ``pressure_kpa`` (the output), :attr:`target_kpa` (where it is heading) and the
    command held (a voltage array; a new array is a new command). :meth:`step` advances all
    three; a caller that computes the target and the lag itself (the compiled muscle step,
    :class:`pamrun.physics.kernels.CompiledStep`) takes the command with :meth:`hold` and updates
    ``pressure_kpa`` and ``target_kpa`` in place.
    """

    def __init__(self, cfg: RegulatorConfig, initial_pressure_kpa: np.ndarray):
        self.cfg = cfg
        self.pressure_kpa = np.array(initial_pressure_kpa, dtype=float)
        self._voltage: np.ndarray | None = None
        self._target = self.pressure_kpa.copy()

    def reset(self, pressure_kpa: np.ndarray) -> None:
        """Output at ``pressure_kpa`` [kPa] (a new array) and no command held: the next is new."""
        self.pressure_kpa = np.array(pressure_kpa, dtype=float)
        self._voltage = None

    @property
    def target_kpa(self) -> np.ndarray:
        """Pressure [kPa] the output is heading to: the held command's, clipped (see :meth:`hold`)."""
        return self._target

    def target_pressure_kpa(self, voltage_v: np.ndarray) -> np.ndarray:
        c = self.cfg
        voltage_v = np.clip(voltage_v, c.min_voltage_v, c.max_voltage_v)
        return np.clip(c.gain_kpa_per_v * voltage_v, c.min_pressure_kpa, c.max_pressure_kpa)

    def voltage_for_pressure_v(self, pressure_kpa: np.ndarray) -> np.ndarray:
        """Inverse of the linear map (for experiments that are specified in pressure)."""
        return np.asarray(pressure_kpa, float) / self.cfg.gain_kpa_per_v

    def lag_factor(self, dt_s: float) -> float:
        """Share of the gap to the target the pressure closes in dt_s: 1 - exp(-dt_s / lag_s) (0 if no lag)."""
        lag = self.cfg.lag_s
        return float(-np.expm1(-dt_s / lag)) if lag > 0 else 0.0

    def hold(self, voltage_v: np.ndarray) -> bool:
        """Take ``voltage_v`` (the output's shape) [V] as the command, without computing its target.

        Returns whether it is a new command (another array than the one held), whose target
        the caller then writes into :attr:`target_kpa` in place, as :meth:`step` would
        compute it.
        """
        if voltage_v is self._voltage:
            return False
        if np.shape(voltage_v) != self.pressure_kpa.shape:
            raise ValueError(f"regulator voltages must have shape {self.pressure_kpa.shape}, "
                             f"got {np.shape(voltage_v)}")
        self._voltage = voltage_v
        if not isinstance(self._target, np.ndarray) or self._target.shape != self.pressure_kpa.shape:
            self._target = np.zeros(self.pressure_kpa.shape)
        return True

    def step(self, voltage_v: np.ndarray, dt_s: float, contraction_pct: np.ndarray | None = None) -> bool:
        """Advance by dt_s holding ``voltage_v``; return whether the pressure changed.

        The target is recomputed only when a new voltage array is passed (callers hold
        one array per command), so an ideal regulator costs nothing per physics step.
        ``contraction_pct`` is not read: the lag does not depend on the muscles' volume (the
        flow-limited valve, :class:`pamrun.physics.valve.FlowRegulator`, does).
        """
        if voltage_v is not self._voltage:
            self._voltage = voltage_v
            self._target = self.target_pressure_kpa(voltage_v)
            if self.cfg.lag_s == 0:
                self.pressure_kpa = self._target.copy()
                return True
        if self.cfg.lag_s > 0:
            self.pressure_kpa += (self._target - self.pressure_kpa) * self.lag_factor(dt_s)
            return True
        return False


class FlowRegulator(Regulator):
    """The VPPM's voltage -> target map and lag (:class:`pamrun.physics.muscle.Regulator`), its rate
    capped by a proportional valve's flow into the muscles' current volume (module docstring).

    ``muscles_per_side`` (n,): the muscles one valve fills, per pair. State beyond the lag's:
    ``volume_l`` (n, 2), each side's volume at the last step [litres] (0 after a reset: the
    next step takes its own), and ``reservoir_kpa`` (1,), the supply's pressure [kPa gauge].
    :meth:`step` needs the muscles' contraction [%], (n, 2).
    """

    def __init__(self, cfg: RegulatorConfig, initial_pressure_kpa: np.ndarray, nominal_length_m: float,
                 inner_diameter_m: float, muscles_per_side=1.0):
        super().__init__(cfg, initial_pressure_kpa)
        shape = self.pressure_kpa.shape
        self.conductance_nl_s_kpa = sonic_conductance_nl_s_kpa(cfg.nominal_flow_nl_min, cfg.critical_pressure_ratio)
        self.compressor_kpa_l_s = cfg.compressor_flow_nl_min / 60.0 * KPA_L_PER_NL  # P V the compressor adds per s
        self.volume_cubic = volume_cubic_l(nominal_length_m, inner_diameter_m)
        self.muscles_per_side = np.broadcast_to(np.asarray(muscles_per_side, float), shape[:1]).copy()  # (n,)
        self.volume_l = np.zeros(shape)
        self.reservoir_kpa = np.array([cfg.supply_pressure_kpa])

    def reset(self, pressure_kpa: np.ndarray) -> None:
        """As :meth:`Regulator.reset`; the volumes are taken afresh and the reservoir is full."""
        super().reset(pressure_kpa)
        self.volume_l = np.zeros(self.pressure_kpa.shape)
        self.reservoir_kpa[0] = self.cfg.supply_pressure_kpa

    def side_volume_l(self, contraction_pct: np.ndarray) -> np.ndarray:
        """Volume [litres] of each side's muscles, (n, 2), at ``contraction_pct`` (clipped at 25 %)."""
        c = np.minimum(contraction_pct, MAX_CONTRACTION_PCT)
        a0, a1, a2, a3 = self.volume_cubic
        return self.muscles_per_side[:, None] * (((a3 * c + a2) * c + a1) * c + a0)

    def rates_kpa_s(self, volume_l: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fastest fill and exhaust [kPa/s] at the current pressures into ``volume_l`` (both >= 0)."""
        b, supply = self.cfg.critical_pressure_ratio, self.reservoir_kpa[0]
        up, inside = supply + ATMOSPHERE_KPA, self.pressure_kpa + ATMOSPHERE_KPA
        flow = KPA_L_PER_NL * self.conductance_nl_s_kpa
        fill = flow * up * flow_function(inside / up, b) / volume_l  # 0 at or above the supply
        exhaust = flow * inside * flow_function(ATMOSPHERE_KPA / inside, b) / volume_l
        return fill, exhaust

    def step(self, voltage_v: np.ndarray, dt_s: float, contraction_pct: np.ndarray | None = None) -> bool:
        """Advance by dt_s holding ``voltage_v`` at the muscles' ``contraction_pct``; always True."""
        if contraction_pct is None:
            raise ValueError("regulator.model=flow needs the muscles' contraction [%] to know their volume")
        if voltage_v is not self._voltage:
            self._voltage = voltage_v
            self._target = self.target_pressure_kpa(voltage_v)
        volume = self.side_volume_l(np.asarray(contraction_pct, float))
        p = self.pressure_kpa
        kept = self.volume_l > 0.0  # the gas kept through the volume change: P_abs V constant
        p[kept] = (p[kept] + ATMOSPHERE_KPA) * self.volume_l[kept] / volume[kept] - ATMOSPHERE_KPA
        self.volume_l = volume
        fill, exhaust = self.rates_kpa_s(volume)
        lag = self.cfg.lag_s
        share = self.lag_factor(dt_s) if lag > 0 else 1.0
        change = np.clip((self._target - p) * share, -exhaust * dt_s, fill * dt_s)
        supply = self.reservoir_kpa[0]
        filled = change > 0.0
        new = np.where(filled, np.minimum(p + change, supply), p + change)
        self._draw((new - p) * filled, volume, dt_s)
        p[:] = new
        return True

    def _draw(self, rise_kpa: np.ndarray, volume_l: np.ndarray, dt_s: float) -> None:
        """The reservoir gives the air of the fills (rise [kPa] in ``volume_l``), then the compressor
        refills it for dt_s, up to the supply pressure. Nothing with an ideal supply."""
        tank = self.cfg.reservoir_volume_l
        if tank <= 0.0:
            return
        pressure = self.reservoir_kpa[0] - (rise_kpa * volume_l).sum() / tank
        self.reservoir_kpa[0] = min(pressure + self.compressor_kpa_l_s * dt_s / tank, self.cfg.supply_pressure_kpa)


def make_regulator(muscle: MuscleConfig, initial_pressure_kpa: np.ndarray, muscles_per_side=1.0) -> Regulator:
    """The regulator ``muscle.regulator.model`` names: the lag (:class:`Regulator`) or the valve."""
    cfg = muscle.regulator
    if cfg.model == "lag":
        return Regulator(cfg, initial_pressure_kpa)
    try:
        cfg.check_supply(muscle.max_pressure_kpa)
    except ConfigError as err:
        raise ConfigError(f"regulator.{err.key}", err.message) from None
    return FlowRegulator(cfg, initial_pressure_kpa, muscle.nominal_length_m, MUSCLE_INNER_DIAMETER_M[muscle.size],
                         muscles_per_side)
