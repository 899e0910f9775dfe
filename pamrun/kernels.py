"""Compiled (numba) muscle step of the kinematic coupling: ``muscle.kernel=numba``.

One call does for all 20 muscles what :meth:`pamrun.actuation.MuscleDrive.apply` does with
numpy (``muscle.kernel=numpy``, the reference) in some forty array operations: the
regulator's first-order lag (:meth:`pamrun.muscle.Regulator.step`), the force polynomial's
coefficients at the new pressures (:meth:`pamrun.muscle.ThesisPolynomial.at_pressure`), the
dampers from the spring table (:class:`pamrun.muscle.SpringTable`), the contractions at the
joint angles, force and slope by Horner's rule, and MuJoCo's actuator inputs. Every
operation is the reference's, in the reference's order, except the coefficients
a_i(P) = sum_j c_ij P^j: numpy takes P^j from libm's pow and the sum from BLAS, this kernel
multiplies and adds left to right, so a coefficient may differ in its last bit and the two
kernels agree to float rounding, not bit for bit (pressures and observations come out
identical in the tests' episodes). NaN goes where numpy sends it (clips keep it, the spring
table puts it in the last band, a NaN force pulls with no slope).

Compiled on first use (about 1.5 s) and cached next to this file (``cache=True``), so a
later process only loads it (about 0.4 s).
"""

from __future__ import annotations

from numba import njit

# Layout of the ``params`` array (scalars of the muscle config, see MuscleDrive).
P_VMIN, P_VMAX, P_GAIN, P_PMIN, P_PMAX, P_LAG, P_MUSCLE_MAX, P_LAW_MAX, P_REST, P_TAU, P_LENGTH_SCALE = range(11)
N_PARAMS = 11
# Rows of the ``joint`` array, (4, n): per-joint constants.
J_PCT_PER_RAD, J_NEUTRAL, J_LEVER, J_RADIUS = range(4)


@njit(cache=True)
def _clip(x, lo, hi):
    """np.clip for one value: NaN stays NaN."""
    if x < lo:
        return lo
    if x > hi:
        return hi
    return x


@njit(cache=True)
def muscle_step(voltage, new_voltage, stale, lag_factor, params, target, pressure, law, edges, springs, joint,
                angle, contraction, coef, damping, torque, stiffness):
    """Advance the regulators by one muscle step and linearise every pair at ``angle``.

    In/out: ``target`` and ``pressure`` (n, 2) [kPa], the regulator's state; ``coef`` (6, n, 2)
    and ``damping`` (n,), kept from the last pressure change. Out: ``contraction`` (n, 2) [%],
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
            or joint.shape[0] != 4 or joint.shape[1] != n or law.shape[0] != 6 or law.shape[1] != 6
            or params.shape[0] != N_PARAMS or edges.shape[0] < 1 or springs.shape[0] < 1):
        raise ValueError("muscle_step: array shapes do not fit the number of pairs")
    changed = False
    if new_voltage:
        vmin, vmax, gain = params[P_VMIN], params[P_VMAX], params[P_GAIN]
        pmin, pmax = params[P_PMIN], params[P_PMAX]
        for k in range(n):
            for s in range(2):
                target[k, s] = _clip(gain * _clip(voltage[k, s], vmin, vmax), pmin, pmax)
                if params[P_LAG] == 0:
                    pressure[k, s] = target[k, s]
        changed = params[P_LAG] == 0
    if params[P_LAG] > 0:
        for k in range(n):
            for s in range(2):
                pressure[k, s] += (target[k, s] - pressure[k, s]) * lag_factor
        changed = True
    if changed or stale:
        muscle_max, law_max = params[P_MUSCLE_MAX], params[P_LAW_MAX]
        tau, length_scale = params[P_TAU], params[P_LENGTH_SCALE]
        n_edges, last = edges.shape[0], springs.shape[0] - 1
        for k in range(n):
            spring_sum = 0.0
            for s in range(2):
                p = pressure[k, s]
                if p > muscle_max:  # AntagonisticPairs.pressure_kpa: np.minimum (NaN stays)
                    p = muscle_max
                # SpringTable.band: searchsorted(edges, p, "right") - 1, clipped to the bands
                if p != p:
                    band = last
                else:
                    band = -1
                    for e in range(n_edges):
                        if edges[e] <= p:
                            band = e
                        else:
                            break
                    band = min(max(band, 0), last)
                spring_sum += springs[band]
                # ThesisPolynomial.at_pressure: a_i = sum_j c_ij P^j, P clipped to [0, law max]
                p = _clip(p, 0.0, law_max)
                p2 = p * p  # P^j by products (numpy: libm pow, several times slower)
                p3 = p2 * p
                p4 = p2 * p2
                p5 = p4 * p
                for i in range(6):
                    coef[i, k, s] = (law[i, 0] + law[i, 1] * p + law[i, 2] * p2 + law[i, 3] * p3 + law[i, 4] * p4
                                     + law[i, 5] * p5)
            damping[k] = tau * spring_sum * length_scale * joint[J_LEVER, k] * joint[J_RADIUS, k]
    rest = params[P_REST]
    for k in range(n):
        pct_per_rad, lever = joint[J_PCT_PER_RAD, k], joint[J_LEVER, k]
        shift = pct_per_rad * (angle[k] - joint[J_NEUTRAL, k])
        contraction[k, 0] = rest + shift
        contraction[k, 1] = rest - shift
        f0 = 0.0
        f1 = 0.0
        g0 = 0.0
        g1 = 0.0
        for s in range(2):
            x = contraction[k, s]
            force = coef[5, k, s] * x + coef[4, k, s]
            slope = 5.0 * coef[5, k, s] * x + 4.0 * coef[4, k, s]
            for i in (3, 2, 1):
                force = force * x + coef[i, k, s]
                slope = slope * x + i * coef[i, k, s]
            force = force * x + coef[0, k, s]
            if not force > 0.0:  # slack: no slope (np.where(force > 0, slope, 0))
                slope = 0.0
            if not (force >= 0.0 or force != force):  # np.maximum(force, 0.0)
                force = 0.0
            if s == 0:
                f0, g0 = force, slope
            else:
                f1, g1 = force, slope
        torque[k] = (f0 - f1) * lever
        stiffness[k] = -(g0 + g1) * pct_per_rad * lever
    return changed


@njit(cache=True)
def muscle_apply(voltage, new_voltage, stale, lag_factor, params, target, pressure, law, edges, springs, joint,
                 qpos, qpos_idx, angle, contraction, coef, damping, torque, stiffness, ctrl, biasprm):
    """:func:`muscle_step` at the joint angles theta0 = ``qpos[qpos_idx]``, then MuJoCo's actuator
    inputs ctrl = T + K theta0, biasprm[:, 1] = -K, biasprm[:, 2] = -D, so that each physics step
    applies T - K (theta - theta0) - D theta' (see MuscleDrive.apply)."""
    n = angle.shape[0]
    if qpos_idx.shape[0] != n or ctrl.shape[0] != n or biasprm.shape[0] != n or biasprm.shape[1] < 3:
        raise ValueError("muscle_apply: one actuator and one joint per pair expected")
    for k in range(n):
        if qpos_idx[k] < 0 or qpos_idx[k] >= qpos.shape[0]:
            raise IndexError("muscle_apply: joint address outside qpos")
        angle[k] = qpos[qpos_idx[k]]
    changed = muscle_step(voltage, new_voltage, stale, lag_factor, params, target, pressure, law, edges, springs,
                          joint, angle, contraction, coef, damping, torque, stiffness)
    for k in range(n):
        ctrl[k] = torque[k] + stiffness[k] * angle[k]
        biasprm[k, 1] = -stiffness[k]
        biasprm[k, 2] = -damping[k]
    return changed

