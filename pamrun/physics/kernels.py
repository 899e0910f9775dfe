"""Compiled (numba) muscle step of the kinematic coupling: ``muscle.kernel=numba``.

One call does for all 20 muscles what :meth:`pamrun.physics.actuation.MuscleDrive.apply` does with
numpy (``muscle.kernel=numpy``, the reference) in some forty array operations: the
regulator's first-order lag (:meth:`pamrun.physics.muscle.Regulator.step`), the force law's
coefficients at the new pressures (:meth:`pamrun.physics.force_laws.CoefficientLaw.at_pressure`; every
law is a 6 x 6 matrix of x^i P^j, so every law runs here unchanged), the
dampers from the spring table (:class:`pamrun.physics.muscle.SpringTable`), the contractions at the
joint angles, force and slope by Horner's rule, and MuJoCo's actuator inputs. Every
operation is the reference's, in the reference's order, except the coefficients
a_i(P) = sum_j c_ij P^j: numpy takes P^j from libm's pow and the sum from BLAS, this kernel
multiplies and adds left to right, so a coefficient may differ in its last bit and the two
kernels agree to float rounding, not bit for bit (pressures and observations come out
identical in the tests' episodes). NaN goes where numpy sends it (clips keep it, the spring
table puts it in the last band, a NaN force pulls with no slope).

``muscle.regulator.model=flow`` runs :class:`pamrun.physics.valve.FlowRegulator`'s step here
(:func:`_regulate_flow`) in place of the lag, with the same operations in the same order, except
that the air the valves draw from the reservoir is summed muscle by muscle (numpy: pairwise).

``muscle.spring.hysteresis=maxwell_slip`` (pamrun/physics/hysteresis.py) runs here too: each muscle's
elements are moved by its contraction change and their force and stiffness are taken off the
muscle's (:func:`_slip_force_and_slope`), the numpy reference's operations in its order; with
``none`` there are no elements and the step is the one without hysteresis, unchanged.

Compiled on first use (about 1.5 s) and cached next to this file (``cache=True``), so a
later process only loads it (about 0.4 s).

:class:`CompiledStep` owns the kernels' constants and buffers and spells their arguments
once; :class:`pamrun.physics.actuation.CompiledKinematicCoupling` steps the muscles through it.
A control step is one call (:func:`muscle_advance`): its muscle steps and MuJoCo's C ``mj_step``
between them, called by address from compiled code, where MuJoCo's library is found. A fatal
MuJoCo error (``mju_error``) inside it ends the process (the bindings raise ``mujoco.FatalError``).
"""

from __future__ import annotations

import ctypes
import glob
import math
import os

import mujoco
import numpy as np
from llvmlite import ir
from mujoco import mj_step
from numba import njit, types
from numba.extending import intrinsic

from pamrun.physics.hysteresis import M_PER_PCT
from pamrun.physics.muscle import ATMOSPHERE_KPA, MAX_CONTRACTION_PCT
from pamrun.physics.valve import KPA_L_PER_NL, FlowRegulator

# Layout of the ``params`` array (scalars of the muscle config, filled by CompiledStep).
P_VMIN, P_VMAX, P_GAIN, P_PMIN, P_PMAX, P_LAG, P_MUSCLE_MAX, P_LAW_MAX, P_REST, P_TAU, P_LENGTH_SCALE = range(11)
# The flow-limited valve's (model=flow, pamrun/physics/valve.py): P_MODEL is 1 for it (0: the lag), P_DT the
# step [s] (written with the lag factor), then C [Nl/(s kPa)], b, the supply [kPa], the reservoir
# [litres], the compressor [kPa litres/s] and the 4 coefficients of one muscle's volume cubic.
P_MODEL, P_DT, P_CONDUCTANCE, P_CRITICAL, P_SUPPLY, P_TANK, P_COMPRESSOR, P_VOLUME = range(11, 19)
# The hysteresis elements' reference pressure [kPa] (0: no elements, hysteresis=none).
P_SLIP_REF = P_VOLUME + 4
N_PARAMS = P_SLIP_REF + 1
MODEL_FLOW = 1.0
# Rows of the ``joint`` array, (5, n): per-joint constants (J_COUNT: muscles per side, which one valve fills).
J_PCT_PER_RAD, J_NEUTRAL, J_LEVER, J_RADIUS, J_COUNT = range(5)
N_JOINT_ROWS = 5


@njit(cache=True)
def _clip(x, lo, hi):
    """np.clip for one value: NaN stays NaN."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@njit(cache=True)
def _set_targets(voltage, params, target):
    """The regulator's target for every muscle on a new command: clip(gain clip(V)) [kPa]."""
    vmin, vmax, gain = params[P_VMIN], params[P_VMAX], params[P_GAIN]
    pmin, pmax = params[P_PMIN], params[P_PMAX]
    for k in range(target.shape[0]):
        for s in range(2):
            target[k, s] = _clip(gain * _clip(voltage[k, s], vmin, vmax), pmin, pmax)


@njit(cache=True)
def _regulate(voltage, new_voltage, lag_factor, params, target, pressure):
    """:meth:`pamrun.physics.muscle.Regulator.step` for every muscle: target = clip(gain clip(V)) [kPa]
    on a new command, then the first-order lag. Returns whether the pressures changed."""
    n = pressure.shape[0]
    changed = False
    if new_voltage:
        _set_targets(voltage, params, target)
        if params[P_LAG] == 0:
            pressure[:, :] = target
        changed = params[P_LAG] == 0
    if params[P_LAG] > 0:
        for k in range(n):
            for s in range(2):
                pressure[k, s] += (target[k, s] - pressure[k, s]) * lag_factor
        changed = True
    return changed


@njit(cache=True)
def _flow_function(ratio, critical):
    """pamrun.physics.valve.flow_function for one ratio p_down / p_up: 1 choked (<= b), ISO 6358's ellipse, 0 at >= 1."""
    if ratio > 1.0:
        ratio = 1.0
    if ratio <= critical:
        return 1.0
    x = (ratio - critical) / (1.0 - critical)
    return math.sqrt(max(1.0 - x * x, 0.0))


@njit(cache=True)
def _regulate_flow(voltage, new_voltage, lag_factor, params, joint, contraction, target, pressure, volume, reservoir):
    """:meth:`pamrun.physics.valve.FlowRegulator.step` for every muscle: target = clip(gain clip(V)) [kPa] on a
    new command; the gas kept through the volume change; the lag's step capped by the valve's fill
    and exhaust at full opening; the reservoir. ``contraction``: the last step's [%]. Returns True."""
    n = pressure.shape[0]
    if new_voltage:
        _set_targets(voltage, params, target)
    dt, b, supply = params[P_DT], params[P_CRITICAL], reservoir[0]
    flow, up = KPA_L_PER_NL * params[P_CONDUCTANCE], supply + ATMOSPHERE_KPA
    share = lag_factor if params[P_LAG] > 0 else 1.0
    a0, a1, a2, a3 = params[P_VOLUME], params[P_VOLUME + 1], params[P_VOLUME + 2], params[P_VOLUME + 3]
    drawn = 0.0  # kPa litres
    for k in range(n):
        for s in range(2):
            c = contraction[k, s]
            if c > MAX_CONTRACTION_PCT:
                c = MAX_CONTRACTION_PCT
            v = joint[J_COUNT, k] * (((a3 * c + a2) * c + a1) * c + a0)
            p = pressure[k, s]
            if volume[k, s] > 0.0:  # the gas kept: P_abs V constant
                p = (p + ATMOSPHERE_KPA) * volume[k, s] / v - ATMOSPHERE_KPA
            volume[k, s] = v
            inside = p + ATMOSPHERE_KPA
            fill = flow * up * _flow_function(inside / up, b) / v
            exhaust = flow * inside * _flow_function(ATMOSPHERE_KPA / inside, b) / v
            change = _clip((target[k, s] - p) * share, -exhaust * dt, fill * dt)
            if change > 0.0:
                new = min(p + change, supply)
                drawn += (new - p) * v
            else:
                new = p + change
            pressure[k, s] = new
    tank = params[P_TANK]
    if tank > 0.0:
        left = supply - drawn / tank
        reservoir[0] = min(left + params[P_COMPRESSOR] * dt / tank, params[P_SUPPLY])
    return True


@njit(cache=True)
def _spring_band(p, edges, last):
    """SpringTable.band for one pressure [kPa]: searchsorted(edges, p, "right") - 1, clipped to
    the bands 0..last; NaN goes to the last band."""
    if p != p:
        return last
    band = -1
    for e in range(edges.shape[0]):
        if edges[e] <= p:
            band = e
        else:
            break
    return min(max(band, 0), last)


@njit(cache=True)
def _at_pressure(params, pressure, law, edges, springs, joint, coef, damping, slip_gain):
    """What depends on pressure only: the force law reduced to each muscle's pressure, ``coef``
    a_i(P) [N / %^i] (CoefficientLaw.at_pressure), each pair's dampers k (D1 + D2) r^2
    [N m s/rad] with D = tau S (thesis §8.3), into ``damping``, and with hysteresis elements
    their scale P / P_ref into ``slip_gain`` (MaxwellSlip.at_pressure)."""
    muscle_max, law_max, slip_ref = params[P_MUSCLE_MAX], params[P_LAW_MAX], params[P_SLIP_REF]
    tau, length_scale = params[P_TAU], params[P_LENGTH_SCALE]
    last = springs.shape[0] - 1
    for k in range(pressure.shape[0]):
        spring_sum = 0.0
        for s in range(2):
            p = pressure[k, s]
            if p > muscle_max:  # AntagonisticPairs.pressure_kpa: np.minimum (NaN stays)
                p = muscle_max
            spring_sum += springs[_spring_band(p, edges, last)]
            # CoefficientLaw.at_pressure: a_i = sum_j c_ij P^j, P clipped to [0, law max]
            p = _clip(p, 0.0, law_max)
            if slip_ref > 0.0:
                slip_gain[k, s] = p / slip_ref
            p2 = p * p  # P^j by products (numpy: libm pow, several times slower)
            p3 = p2 * p
            p4 = p2 * p2
            p5 = p4 * p
            for i in range(6):
                coef[i, k, s] = (law[i, 0] + law[i, 1] * p + law[i, 2] * p2 + law[i, 3] * p3 + law[i, 4] * p4
                                 + law[i, 5] * p5)
        damping[k] = tau * spring_sum * length_scale * joint[J_LEVER, k] * joint[J_RADIUS, k]


@njit(cache=True)
def _horner(coef, k, s, x):
    """One muscle's signed force F [N] and slope dF/dx [N/%] at contraction x [%], by Horner's
    rule (CoefficientLaw.force_and_slope)."""
    force = coef[5, k, s] * x + coef[4, k, s]
    slope = 5.0 * coef[5, k, s] * x + 4.0 * coef[4, k, s]
    for i in (3, 2, 1):
        force = force * x + coef[i, k, s]
        slope = slope * x + i * coef[i, k, s]
    return force * x + coef[0, k, s], slope


@njit(cache=True)
def _slack(force, slope):
    """Force never negative, no slope where slack (np.maximum(force, 0), np.where(force > 0, slope, 0))."""
    if not force > 0.0:  # slack: no slope (np.where(force > 0, slope, 0))
        slope = 0.0
    if not (force >= 0.0 or force != force):  # np.maximum(force, 0.0)
        force = 0.0
    return force, slope


@njit(cache=True)
def _force_and_slope(coef, k, s, x):
    """One muscle's force F [N] (never negative) and slope dF/dx [N/%] (0 where slack) at
    contraction x [%]."""
    force, slope = _horner(coef, k, s, x)
    return _slack(force, slope)


@njit(cache=True)
def _slip_force_and_slope(coef, k, s, x, previous, slip_law, slip, slip_gain):
    """As :func:`_force_and_slope`, with hysteresis: the muscle's elements (``slip_law`` rows
    k_i [N/m], f_i / k_i [m]; ``slip`` their deflections [m]) moved by x - ``previous`` [%]
    (MaxwellSlip.move), then F - H [N] and dF/dx - dH/dx [N/%] (KinematicCoupling._net_force_and_slope)."""
    delta = (x - previous) * M_PER_PCT
    held, sticking = 0.0, 0.0
    for i in range(slip.shape[0]):
        width = slip_law[1, i]
        moved = _clip(slip[i, k, s] + delta, -width, width)
        slip[i, k, s] = moved
        held += slip_law[0, i] * moved
        if -width < moved < width:
            sticking += slip_law[0, i]
    force, slope = _horner(coef, k, s, x)
    gain = slip_gain[k, s]
    return _slack(force - gain * held, slope - gain * sticking * M_PER_PCT)


@njit(cache=True)
def _linearise(params, joint, angle, contraction, coef, slip_law, slip, slip_gain, torque, stiffness):
    """Contractions c1,2 = c_rest +- 100 r (theta - theta_n) / L0 [%] at ``angle`` [rad], and
    each pair's torque k (F1 - F2) r [N m] and stiffness -dT/dtheta [N m/rad]; with hysteresis
    elements (``slip``), F - H, the elements moved from the last contractions."""
    rest = params[P_REST]
    hysteresis = slip.shape[0] > 0
    for k in range(angle.shape[0]):
        pct_per_rad, lever = joint[J_PCT_PER_RAD, k], joint[J_LEVER, k]
        shift = pct_per_rad * (angle[k] - joint[J_NEUTRAL, k])
        if hysteresis:
            c0, c1 = rest + shift, rest - shift
            f0, g0 = _slip_force_and_slope(coef, k, 0, c0, contraction[k, 0], slip_law, slip, slip_gain)
            f1, g1 = _slip_force_and_slope(coef, k, 1, c1, contraction[k, 1], slip_law, slip, slip_gain)
            contraction[k, 0], contraction[k, 1] = c0, c1
        else:
            contraction[k, 0] = rest + shift
            contraction[k, 1] = rest - shift
            f0, g0 = _force_and_slope(coef, k, 0, contraction[k, 0])
            f1, g1 = _force_and_slope(coef, k, 1, contraction[k, 1])
        torque[k] = (f0 - f1) * lever
        stiffness[k] = -(g0 + g1) * pct_per_rad * lever


@njit(cache=True)
def muscle_step(voltage, new_voltage, stale, lag_factor, params, target, pressure, volume, reservoir, law, edges,
                springs, joint, angle, contraction, coef, damping, slip_law, slip, slip_gain, torque, stiffness):
    """Advance the regulators by one muscle step and linearise every pair at ``angle``.

    In/out: ``target`` and ``pressure`` (n, 2) [kPa], the regulator's state, and with the
    flow-limited valve (``params[P_MODEL]``) ``volume`` (n, 2) [litres] and ``reservoir`` (1,)
    [kPa] (FlowRegulator's ``volume_l``, ``reservoir_kpa``; unused by the lag); ``coef`` (6, n, 2)
    and ``damping`` (n,), kept from the last pressure change; the hysteresis elements' ``slip``
    (N, n, 2) [m] (MaxwellSlip.slip_m; N = 0 for none) and scale ``slip_gain`` (n, 2), their
    constants ``slip_law`` (2, N): k_i [N/m], f_i / k_i [m]. Out: ``contraction`` (n, 2) [%],
    ``torque`` k (F1 - F2) r [N m] and ``stiffness`` -dT/dtheta [N m/rad] (n,).
    ``new_voltage``: the command changed (recompute the target); ``stale``: no coefficients
    yet (after a reset). ``lag_factor`` is -expm1(-dt / lag_s) (0 when lag_s is 0).
    Returns whether the pressures changed (as Regulator.step).
    """
    n = pressure.shape[0]
    # no bounds checks in compiled code: every array must fit the n pairs
    if (pressure.shape[1] != 2 or target.shape != pressure.shape or voltage.shape != pressure.shape
            or contraction.shape != pressure.shape or coef.shape[0] != 6 or coef.shape[1] != n or coef.shape[2] != 2
            or angle.shape[0] != n or damping.shape[0] != n or torque.shape[0] != n or stiffness.shape[0] != n
            or joint.shape[0] != N_JOINT_ROWS or joint.shape[1] != n or law.shape[0] != 6 or law.shape[1] != 6
            or params.shape[0] != N_PARAMS or edges.shape[0] < 1 or springs.shape[0] < 1
            or volume.shape != pressure.shape or reservoir.shape[0] < 1 or slip_law.shape[0] != 2
            or slip.shape[0] != slip_law.shape[1] or slip.shape[1] != n or slip.shape[2] != 2
            or slip_gain.shape != pressure.shape):
        raise ValueError("muscle_step: array shapes do not fit the number of pairs")
    if params[P_MODEL] == MODEL_FLOW:  # before _linearise: ``contraction`` is still the last step's
        changed = _regulate_flow(voltage, new_voltage, lag_factor, params, joint, contraction, target, pressure,
                                 volume, reservoir)
    else:
        changed = _regulate(voltage, new_voltage, lag_factor, params, target, pressure)
    if changed or stale:
        _at_pressure(params, pressure, law, edges, springs, joint, coef, damping, slip_gain)
    _linearise(params, joint, angle, contraction, coef, slip_law, slip, slip_gain, torque, stiffness)
    return changed


@njit(cache=True)
def muscle_apply(voltage, new_voltage, stale, lag_factor, params, target, pressure, volume, reservoir, law, edges,
                 springs, joint, angle, contraction, coef, damping, slip_law, slip, slip_gain, torque, stiffness, qpos,
                 qpos_idx, ctrl, biasprm):
    """:func:`muscle_step` (same arguments; ``angle`` is overwritten) at the joint angles
    theta0 = ``qpos[qpos_idx]`` [rad], then MuJoCo's actuator inputs ctrl = T + K theta0,
    biasprm[:, 1] = -K, biasprm[:, 2] = -D, so that each physics step applies
    T - K (theta - theta0) - D theta' [N m] (see MuscleDrive.apply)."""
    n = angle.shape[0]
    if qpos_idx.shape[0] != n or ctrl.shape[0] != n or biasprm.shape[0] != n or biasprm.shape[1] < 3:
        raise ValueError("muscle_apply: one actuator and one joint per pair expected")
    for k in range(n):
        if qpos_idx[k] < 0 or qpos_idx[k] >= qpos.shape[0]:
            raise IndexError("muscle_apply: joint address outside qpos")
        angle[k] = qpos[qpos_idx[k]]
    changed = muscle_step(voltage, new_voltage, stale, lag_factor, params, target, pressure, volume, reservoir, law,
                          edges, springs, joint, angle, contraction, coef, damping, slip_law, slip, slip_gain, torque,
                          stiffness)
    for k in range(n):
        ctrl[k] = torque[k] + stiffness[k] * angle[k]
        biasprm[k, 1] = -stiffness[k]
        biasprm[k, 2] = -damping[k]
    return changed


def mj_step_address() -> int:
    """The address of MuJoCo's C ``mj_step(m, d)`` in the library the bindings use (0: not found,
    or bindings that do not expose their structs' addresses)."""
    if not hasattr(mujoco.MjModel, "_address") or not hasattr(mujoco.MjData, "_address"):
        return 0
    folder = os.path.dirname(mujoco.__file__)
    for name in ("libmujoco.so*", "libmujoco*.dylib", "mujoco.dll"):
        for path in sorted(glob.glob(os.path.join(folder, name))):
            try:
                return ctypes.cast(ctypes.CDLL(path).mj_step, ctypes.c_void_p).value or 0
            except (OSError, AttributeError):
                continue
    return 0


@intrinsic
def _mj_step(typingctx, function, model, data):
    """Call the C function ``void f(const mjModel*, mjData*)`` at address ``function`` on the
    structs at ``model``, ``data`` (addresses as integers)."""
    def codegen(context, builder, signature, args):
        pointer = ir.IntType(8).as_pointer()
        callee = builder.inttoptr(args[0], ir.FunctionType(ir.VoidType(), [pointer, pointer]).as_pointer())
        builder.call(callee, [builder.inttoptr(args[1], pointer), builder.inttoptr(args[2], pointer)])
        return context.get_dummy_value()
    return types.none(types.intp, types.intp, types.intp), codegen


@njit(cache=True)
def muscle_advance(step_function, model, data, muscle_steps, physics_steps, voltage, new_voltage, stale, lag_factor,
                   params, target, pressure, volume, reservoir, law, edges, springs, joint, angle, contraction, coef,
                   damping, slip_law, slip, slip_gain, torque, stiffness, qpos, qpos_idx, ctrl, biasprm):
    """``muscle_steps`` times :func:`muscle_apply` (its arguments after the first five; ``new_voltage``
    and ``stale`` hold for the first), then ``physics_steps`` calls of MuJoCo's mj_step, the C
    function at address ``step_function`` (:func:`mj_step_address`), on the mjModel and mjData at
    addresses ``model`` and ``data``: one control step in one call."""
    for k in range(muscle_steps):
        first = k == 0
        muscle_apply(voltage, new_voltage and first, stale and first, lag_factor, params, target, pressure, volume,
                     reservoir, law, edges, springs, joint, angle, contraction, coef, damping, slip_law, slip,
                     slip_gain, torque, stiffness, qpos, qpos_idx, ctrl, biasprm)
        for _ in range(physics_steps):
            _mj_step(step_function, model, data)


MJ_STEP = mj_step_address()


class CompiledStep:
    """The compiled muscle step's state and arguments, spelled once (``muscle.kernel=numba``).

    Built from a kinematic coupling (:class:`pamrun.physics.actuation.KinematicCoupling`): its config,
    pairs and per-joint constants (pulley radius r [m], lever k r [m], contraction per radian
    100 r / L0 [%/rad], neutral angle [rad]). Owns the kernels' constants (``params``, the
    force law's coefficients, the spring table, ``joint``) and buffers (the force law reduced
    to the current pressures ``coef``, joint angles, torques [N m], stiffnesses [N m/rad]);
    writes the coupling's own ``contraction_pct`` [%] and ``damping`` [N m s/rad] arrays, and
    the regulator's ``pressure_kpa`` and ``target_kpa`` in place (the regulator keeps the
    command's bookkeeping: :meth:`pamrun.physics.muscle.Regulator.hold`), and the flow-limited valve's
    ``volume_l`` and ``reservoir_kpa`` (:class:`pamrun.physics.valve.FlowRegulator`; the lag: buffers nobody reads),
    and the hysteresis elements' ``slip_m`` and ``gain`` (:class:`pamrun.physics.hysteresis.MaxwellSlip`;
    none: no elements).
    """

    def __init__(self, coupling):
        cfg, pairs, n = coupling.cfg, coupling.pairs, len(coupling.radius_m)
        reg = cfg.regulator
        self.params = np.zeros(N_PARAMS)
        for index, value in ((P_VMIN, reg.min_voltage_v), (P_VMAX, reg.max_voltage_v),
                             (P_GAIN, reg.gain_kpa_per_v), (P_PMIN, reg.min_pressure_kpa),
                             (P_PMAX, reg.max_pressure_kpa), (P_LAG, reg.lag_s),
                             (P_MUSCLE_MAX, cfg.max_pressure_kpa), (P_LAW_MAX, pairs.law.max_pressure_kpa),
                             (P_REST, coupling.rest_pct), (P_TAU, cfg.tau_s),
                             (P_LENGTH_SCALE, pairs.dynamics.length_scale)):
            self.params[index] = value
        self.regulator = regulator = pairs.regulator
        self.flow = isinstance(regulator, FlowRegulator)
        self._no_volume, self._no_reservoir = np.zeros((n, 2)), np.zeros(1)
        if self.flow:
            self.params[P_MODEL] = MODEL_FLOW
            self.params[P_VOLUME:P_VOLUME + 4] = regulator.volume_cubic
            for index, value in ((P_CONDUCTANCE, regulator.conductance_nl_s_kpa),
                                 (P_CRITICAL, reg.critical_pressure_ratio), (P_SUPPLY, reg.supply_pressure_kpa),
                                 (P_TANK, reg.reservoir_volume_l), (P_COMPRESSOR, regulator.compressor_kpa_l_s)):
                self.params[index] = value
        self.law = np.ascontiguousarray(pairs.law.coefficients, dtype=float)
        self.edges = np.ascontiguousarray(pairs.dynamics.spring.edges_kpa, dtype=float)
        self.springs = np.ascontiguousarray(pairs.dynamics.spring.values_n_per_m, dtype=float)
        self.joint = np.empty((N_JOINT_ROWS, n))
        self.joint[J_PCT_PER_RAD], self.joint[J_NEUTRAL] = coupling.pct_per_rad, coupling.neutral
        self.joint[J_LEVER], self.joint[J_RADIUS] = coupling.lever, coupling.radius_m
        self.joint[J_COUNT] = regulator.muscles_per_side if self.flow else 1.0
        hysteresis = coupling.hysteresis  # the elements' state is the numpy reference's, updated in place
        if hysteresis is None:
            self.slip_law, self.slip, self.slip_gain = np.zeros((2, 0)), np.zeros((0, n, 2)), np.zeros((n, 2))
        else:
            self.params[P_SLIP_REF] = hysteresis.reference_pressure_kpa
            self.slip_law = np.ascontiguousarray([hysteresis.stiffness_n_per_m, hysteresis.width_m], dtype=float)
            self.slip, self.slip_gain = hysteresis.slip_m, hysteresis.gain
        self.contraction, self.damping = coupling.contraction_pct, coupling.damping
        self.coef = np.zeros((6, n, 2))
        self.angle, self.torque, self.stiffness = np.zeros(n), np.zeros(n), np.zeros(n)
        self.stale = True  # no coefficients yet (after a reset): the next step computes them
        self._lag_dt: float | None = None
        self._lag_factor = 0.0
        self.mj_step = MJ_STEP  # MuJoCo's C mj_step (0: MuJoCo stepped from Python)

    def arguments(self, voltage_v: np.ndarray, dt_s: float, angle_rad: np.ndarray) -> tuple:
        """:func:`muscle_step`'s arguments, in its order, for holding ``voltage_v`` (n, 2) [V]
        over dt_s [s] at the joint angles ``angle_rad`` (n,) [rad]."""
        reg = self.regulator
        new = reg.hold(voltage_v)  # before target_kpa, which a first command may replace
        if dt_s != self._lag_dt:
            self._lag_factor, self._lag_dt = reg.lag_factor(dt_s), dt_s
            self.params[P_DT] = dt_s
        volume, reservoir = (reg.volume_l, reg.reservoir_kpa) if self.flow else (self._no_volume, self._no_reservoir)
        return (voltage_v, new, self.stale, self._lag_factor, self.params, reg.target_kpa, reg.pressure_kpa, volume,
                reservoir, self.law, self.edges, self.springs, self.joint, angle_rad, self.contraction, self.coef,
                self.damping, self.slip_law, self.slip, self.slip_gain, self.torque, self.stiffness)

    def step(self, voltage_v: np.ndarray, angle_rad: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Advance by dt_s; the pairs' torque k (F1 - F2) r [N m] at ``angle_rad`` and their
        stiffness -dT/dtheta [N m/rad], both (n,) and fresh arrays."""
        angle = np.asarray(angle_rad, dtype=float)
        if angle.shape != self.angle.shape:
            raise ValueError(f"joint angles must have shape {self.angle.shape}, got {angle.shape}")
        muscle_step(*self.arguments(voltage_v, dt_s, angle))
        self.stale = False
        return self.torque.copy(), self.stiffness.copy()

    def _mujoco_arguments(self, voltage_v: np.ndarray, dt_s: float, model, data, qpos_idx: np.ndarray) -> tuple:
        """:func:`muscle_apply`'s arguments: the step's, at the angles ``data.qpos[qpos_idx]``."""
        return (*self.arguments(voltage_v, dt_s, self.angle), data.qpos, qpos_idx, data.ctrl, model.actuator_biasprm)

    def apply(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, dt_s: float) -> None:
        """Advance by dt_s and set MuJoCo's actuators to the pairs linearised at the current angles."""
        muscle_apply(*self._mujoco_arguments(voltage_v, dt_s, model, data, qpos_idx))
        self.stale = False

    def advance(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, dt_s: float, muscle_steps: int,
                physics_steps: int) -> None:
        """``muscle_steps`` times :meth:`apply`, then ``physics_steps`` MuJoCo steps; the arguments
        gathered once, so between MuJoCo steps there is one kernel call and no other Python. Where
        MuJoCo's C library is found (:func:`mj_step_address`) the whole loop is one compiled call
        (:func:`muscle_advance`), the same calls in the same order."""
        first = self._mujoco_arguments(voltage_v, dt_s, model, data, qpos_idx)
        if self.mj_step and muscle_steps:
            muscle_advance(self.mj_step, model._address, data._address, muscle_steps, physics_steps, *first)
            self.stale = False
            return
        # after the first call the command is the regulator's and the coefficients exist
        later = (first[0], False, False, *first[3:])
        for k in range(muscle_steps):
            muscle_apply(*(later if k else first))
            self.stale = False
            mj_step(model, data, physics_steps)
