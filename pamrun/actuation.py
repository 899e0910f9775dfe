"""Muscle pairs on the robot's joints: action -> pressures -> forces -> joint torques.

Ten antagonistic pairs, one per hinge (``pamrun.body.JOINTS`` order). Muscle 1 of a pair
pulls the joint towards positive angles, muscle 2 towards negative ones. Each side of a
pair is ``muscle.count.<joint>`` muscles of ``muscle.size`` in parallel, so its force is
k F(c, P) with k = count x the size's force ratio (:attr:`MuscleConfig.force_scale`).

Command (``muscle.command``): ``antagonistic`` takes 10 actions a in [-1, 1] and sets
V1 = V0 + dV a, V2 = V0 - dV a (thesis §9.5: V0 = 2.12 V, dV = 0.71 V); ``independent``
takes 20 actions, V = V0 + dV a for each muscle (muscle 1 of every pair first), so a
policy sets each pair's co-contraction as well as its torque.

Two couplings of muscle and joint (``muscle.coupling``):

* ``thesis`` — as the thesis built it (§8.3): each muscle's contraction is its own dynamic
  state (D x' + S x = Fce - FL, :class:`pamrun.muscle.FirstOrderPairDynamics`) and the
  joint angle does not feed back into it; T = k (F1 - F2) r. A pair gives torque only
  while its contractions move after a pressure change (~20 ms), then ~0.
* ``kinematic`` — physically consistent: each muscle's contraction follows the joint
  through its pulley, c1,2 = c_rest +- 100 r (theta - theta_n) / L0 (theta_n: ``neutral_deg``),
  so co-contraction stiffens the joint; the muscles' dampers (D = tau S) act on the joint
  velocity, T = k (F1 - F2) r - k (D1 + D2) r^2 theta'. Pressure follows the command
  through the regulator (and its lag).

Pulley radii and rest contractions are not in the thesis. Both muscles of a pair sit at
``kinematic_rest_contraction_pct`` at the joint's neutral angle (``muscle.neutral_deg``: the
standing pose, except the knee, whose pair presses it into its extension stop). Each
joint's radius is ``muscle.radius_mm.<joint>`` or, at 0, the largest
that keeps the stretched muscle at or above ``min_contraction_pct`` at the farthest limit:

    r_j = (c_rest - c_min) / 100 * L0 / max(|theta_lo - theta_n|, |theta_hi - theta_n|)

so every contraction stays inside the force polynomial's fitted range (>= -3 %); the
contracting muscle may go slack near a limit. ``muscle=thesis`` (c_rest = 6.5 %,
c_min = 0 %) gives the radii the thesis model has always used: 21.5 mm at hip and ankle
pitch, 43.0 mm hip roll, 10.8 mm knee, 27.7 mm ankle roll.

Kernel (``muscle.kernel``): the kinematic coupling's muscle step runs as one compiled numba
call (``numba``, :mod:`pamrun.kernels`) or as the numpy code below (``numpy``, the
reference); both give the same results to float rounding. The thesis coupling is numpy only.
"""

from __future__ import annotations

import numpy as np

from pamrun.config import BodyConfig, MuscleConfig
from pamrun.muscle import AntagonisticPairs


def joint_limits_rad(body: BodyConfig) -> np.ndarray:
    """(10, 2) joint limits [rad] in JOINTS order (the mirroring lives in pamrun.body)."""
    from pamrun.body import SIDES, joint_limits_deg

    return np.deg2rad([lim for side in SIDES for lim in joint_limits_deg(body, side).values()])


def pulley_radii_m(muscle: MuscleConfig, body: BodyConfig) -> np.ndarray:
    """(10,) pulley radius of each joint [m] (see the module docstring for the rule)."""
    from pamrun.body import JOINTS, LEG_JOINTS

    names = [LEG_JOINTS[k % len(LEG_JOINTS)] for k in range(len(JOINTS))]
    reach = [muscle.reach_rad(name, getattr(body, f"{name}_limits_deg")) for name in names]
    return np.array([muscle.radius_m(name, r) for name, r in zip(names, reach)])


def neutral_angles_rad(muscle: MuscleConfig) -> np.ndarray:
    """(10,) angle of each joint where its pair is balanced at equal pressures, JOINTS order.

    The right leg mirrors the roll joints (as its limits do)."""
    from pamrun.body import LEG_JOINTS, SIDES, mirror_sign

    return np.deg2rad([getattr(muscle.neutral_deg, j) * mirror_sign(side, j) for side in SIDES for j in LEG_JOINTS])


def force_scales(muscle: MuscleConfig) -> np.ndarray:
    """(10,) muscles per direction x the size's force ratio, JOINTS order."""
    from pamrun.body import JOINTS, LEG_JOINTS

    return np.array([getattr(muscle.count, LEG_JOINTS[k % len(LEG_JOINTS)]) for k in range(len(JOINTS))],
                    float) * muscle.force_scale


def n_actions(muscle: MuscleConfig) -> int:
    """Actions the policy gives: one per pair (antagonistic) or one per muscle (independent)."""
    from pamrun.body import JOINTS

    return len(JOINTS) * (2 if muscle.command == "independent" else 1)


class MuscleDrive:
    """All 20 muscles of the robot, stepped together.

    ``muscle.kernel=numba`` (the default) steps the kinematic coupling with one compiled call
    per muscle step (:mod:`pamrun.kernels`); ``numpy`` is the reference it matches to float
    rounding. The thesis coupling always uses numpy. Either way the state lives where the
    numpy code keeps it (``pairs.regulator.pressure_kpa``, ``contraction_pct``, ``voltage_v``).
    """

    def __init__(self, muscle: MuscleConfig, body: BodyConfig):
        from pamrun.config import check_muscle_stretch

        check_muscle_stretch(muscle, body)
        self.cfg = muscle
        self.kinematic = muscle.coupling == "kinematic"
        self.radius_m = pulley_radii_m(muscle, body)
        self.force_scale = force_scales(muscle)
        self.n_actions = n_actions(muscle)
        n = len(self.radius_m)
        self.pairs = AntagonisticPairs(muscle, n, self.force_scale)
        self.voltage_v = self.voltages_v(np.zeros(self.n_actions))
        self._pct_per_rad = 100.0 * self.radius_m / muscle.nominal_length_m
        self._neutral = neutral_angles_rad(muscle)
        self._lever = self.force_scale * self.radius_m  # k r [m]
        self._contraction = np.zeros((n, 2))
        self._coef: np.ndarray | None = None
        self._damping = np.zeros(n)
        self._kernel = None
        if self.kinematic and muscle.kernel == "numba":
            self._init_kernel()

    def _init_kernel(self) -> None:
        """Constants and buffers of the compiled step (pamrun.kernels), from this drive's own."""
        from pamrun import kernels as K

        pairs, reg, n = self.pairs, self.cfg.regulator, len(self.radius_m)
        params = np.zeros(K.N_PARAMS)
        for index, value in ((K.P_VMIN, reg.min_voltage_v), (K.P_VMAX, reg.max_voltage_v),
                             (K.P_GAIN, reg.gain_kpa_per_v), (K.P_PMIN, reg.min_pressure_kpa),
                             (K.P_PMAX, reg.max_pressure_kpa), (K.P_LAG, reg.lag_s),
                             (K.P_MUSCLE_MAX, self.cfg.max_pressure_kpa), (K.P_LAW_MAX, pairs.law.max_pressure_kpa),
                             (K.P_REST, self.cfg.kinematic_rest_contraction_pct), (K.P_TAU, self.cfg.tau_s),
                             (K.P_LENGTH_SCALE, pairs.dynamics.length_scale)):
            params[index] = value
        self._params = params
        self._law = np.ascontiguousarray(pairs.law.coefficients, dtype=float)
        self._edges = np.ascontiguousarray(pairs.dynamics.spring.edges_kpa, dtype=float)
        self._springs = np.ascontiguousarray(pairs.dynamics.spring.values_n_per_m, dtype=float)
        joint = np.empty((4, n))
        joint[K.J_PCT_PER_RAD], joint[K.J_NEUTRAL] = self._pct_per_rad, self._neutral
        joint[K.J_LEVER], joint[K.J_RADIUS] = self._lever, self.radius_m
        self._joint = joint
        self._coef_buf = np.zeros((6, n, 2))
        self._angle, self._torque, self._stiffness = np.zeros(n), np.zeros(n), np.zeros(n)
        self._lag_dt: float | None = None
        self._lag_factor = 0.0
        self._kernel = K

    def _kernel_inputs(self, dt_s: float) -> tuple:
        """The regulator's side of a compiled step: (voltage, new voltage?, no coefficients yet?,
        lag factor), keeping Regulator.step's bookkeeping (a new voltage array -> a new target)."""
        reg = self.pairs.regulator
        voltage = self.voltage_v
        new = voltage is not reg._voltage
        if new:
            if np.shape(voltage) != self._contraction.shape:
                raise ValueError(f"regulator voltages must have shape {self._contraction.shape}, "
                                 f"got {np.shape(voltage)}")
            reg._voltage = voltage
            if not isinstance(reg._target, np.ndarray) or reg._target.shape != voltage.shape:
                reg._target = np.zeros(voltage.shape)
        if dt_s != self._lag_dt:
            lag = self.cfg.regulator.lag_s
            self._lag_factor = float(-np.expm1(-dt_s / lag)) if lag > 0 else 0.0
            self._lag_dt = dt_s
        return voltage, new, self._coef is None, self._lag_factor

    def reset(self) -> None:
        """Both muscles of every pair at V0's pressure and their rest contraction."""
        v0_kpa = self.pairs.regulator.target_pressure_kpa(np.full((1, 2), self.cfg.v0_v))[0, 0]
        rest = self.cfg.kinematic_rest_contraction_pct if self.kinematic else self.cfg.rest_contraction_pct
        self.pairs.reset(v0_kpa, rest)
        self.voltage_v = self.voltages_v(np.zeros(self.n_actions))
        self._contraction[:] = rest
        self._coef = None

    def voltages_v(self, action: np.ndarray) -> np.ndarray:
        """Actions in [-1, 1] -> (10, 2) regulator voltages (see ``muscle.command``).

        The values of ``pairs.voltages_v`` (V0 + dV a, V0 - dV a), bit for bit, without its
        np.clip and np.stack, whose Python wrappers cost more than the arithmetic."""
        a = np.maximum(np.asarray(action, dtype=float), -1.0)  # np.clip(a, -1, 1), NaN kept
        np.minimum(a, 1.0, out=a)
        n, v0 = len(self.radius_m), self.cfg.v0_v
        if self.n_actions == n:
            # a * -dV is exactly -(dV a), and V0 + -(dV a) is V0 - dV a
            return v0 + np.multiply.outer(a, (self.cfg.dv_max_v, -self.cfg.dv_max_v))
        return v0 + self.cfg.dv_max_v * a.reshape(n, 2)

    def set_action(self, action: np.ndarray) -> None:
        """Hold the regulator voltages for this action until the next call."""
        self.voltage_v = self.voltages_v(action)

    def set_voltages(self, voltage_v: np.ndarray) -> None:
        """Direct regulator voltages (n, 2), e.g. for open-loop pressure steps."""
        self.voltage_v = np.asarray(voltage_v, dtype=float)

    def apply(self, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray, dt_s: float) -> None:
        """Advance the muscles by dt_s and set MuJoCo's joint actuators for the next dt_s.

        Thesis coupling: the torque, held. Kinematic coupling: the pair's torque linearised
        at the current angle, T = T0 - K (theta - theta0) - D theta', which MuJoCo evaluates
        at every physics step through the actuators' affine bias. Holding T0 for a whole
        muscle step instead is unstable once K / inertia is large (a stiff ankle pair on
        a light foot), since the muscle spring would act only every muscle step.
        """
        if self._kernel is not None:
            reg = self.pairs.regulator
            self._kernel.muscle_apply(*self._kernel_inputs(dt_s), self._params, reg._target, reg.pressure_kpa,
                                      self._law, self._edges, self._springs, self._joint, data.qpos, qpos_idx,
                                      self._angle, self._contraction, self._coef_buf, self._damping, self._torque,
                                      self._stiffness, data.ctrl, model.actuator_biasprm)
            self._coef = self._coef_buf
            return
        angle, velocity = data.qpos[qpos_idx], data.qvel[qvel_idx]
        if not self.kinematic:
            data.ctrl[:] = self.torques_nm(angle, velocity, dt_s)
            return
        torque, stiffness = self._kinematic_torque(angle, dt_s)
        data.ctrl[:] = torque + stiffness * angle
        model.actuator_biasprm[:, 1] = -stiffness
        model.actuator_biasprm[:, 2] = -self._damping

    def advance(self, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray, dt_s: float, muscle_steps: int,
                physics_steps: int) -> None:
        """``muscle_steps`` times: :meth:`apply` for dt_s, then ``physics_steps`` MuJoCo steps.

        The same as that loop, call for call; with the compiled kernel the arguments are
        gathered once, so between MuJoCo steps there is one kernel call and no other Python.
        """
        from mujoco import mj_step

        if self._kernel is None:
            for _ in range(muscle_steps):
                self.apply(model, data, qpos_idx, qvel_idx, dt_s)
                mj_step(model, data, physics_steps)
            return
        voltage, new, stale, lag_factor = self._kernel_inputs(dt_s)
        reg, kernel = self.pairs.regulator, self._kernel.muscle_apply
        state = (self._params, reg._target, reg.pressure_kpa, self._law, self._edges, self._springs, self._joint,
                 data.qpos, qpos_idx, self._angle, self._contraction, self._coef_buf, self._damping, self._torque,
                 self._stiffness, data.ctrl, model.actuator_biasprm)
        for k in range(muscle_steps):
            # after the first call the voltage is the regulator's and the coefficients exist,
            # as apply() would find them
            kernel(voltage, new and k == 0, stale and k == 0, lag_factor, *state)
            self._coef = self._coef_buf
            mj_step(model, data, physics_steps)

    def torques_nm(self, angle_rad: np.ndarray, velocity_rad_s: np.ndarray, dt_s: float) -> np.ndarray:
        """Advance the muscles by dt_s and return the (10,) joint torques [N m]."""
        pairs = self.pairs
        if not self.kinematic:
            changed = pairs.regulator.step(self.voltage_v, dt_s)
            pairs.dynamics.step(pairs.pressure_kpa, dt_s, changed)
            self._contraction = pairs.dynamics.contraction_pct()
            return pairs.torque_nm(self.radius_m)
        return self._kinematic_torque(angle_rad, dt_s)[0] - self._damping * velocity_rad_s

    def _kinematic_torque(self, angle_rad: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Step the regulator; the pairs' torque k (F1 - F2) r [N m] at ``angle_rad`` and its
        stiffness -dT/dtheta [N m/rad] (a slack muscle adds none)."""
        pairs = self.pairs
        if self._kernel is not None:
            angle = np.asarray(angle_rad, dtype=float)
            if angle.shape != self._angle.shape:
                raise ValueError(f"joint angles must have shape {self._angle.shape}, got {angle.shape}")
            reg = pairs.regulator
            self._kernel.muscle_step(*self._kernel_inputs(dt_s), self._params, reg._target, reg.pressure_kpa,
                                     self._law, self._edges, self._springs, self._joint, angle, self._contraction,
                                     self._coef_buf, self._damping, self._torque, self._stiffness)
            self._coef = self._coef_buf
            return self._torque.copy(), self._stiffness.copy()
        changed = pairs.regulator.step(self.voltage_v, dt_s)
        if changed or self._coef is None:
            pressure = pairs.pressure_kpa
            self._coef = pairs.law.at_pressure(pressure)
            # Both sides' dampers act on the joint: k (D1 + D2) r^2 [N m s/rad], D = tau S.
            d_n_s_per_m = self.cfg.tau_s * pairs.dynamics.spring(pressure).sum(axis=1) * pairs.dynamics.length_scale
            self._damping = d_n_s_per_m * self._lever * self.radius_m
        shift = self._pct_per_rad * (angle_rad - self._neutral)
        c = self._contraction
        c[:, 0] = self.cfg.kinematic_rest_contraction_pct + shift
        c[:, 1] = self.cfg.kinematic_rest_contraction_pct - shift
        force, slope = pairs.law.force_and_slope(self._coef, c)
        slope = np.where(force > 0.0, slope, 0.0)  # dF/dc [N/%], 0 where slack
        force = np.maximum(force, 0.0)
        torque = (force[:, 0] - force[:, 1]) * self._lever
        stiffness = -(slope[:, 0] + slope[:, 1]) * self._pct_per_rad * self._lever
        return torque, stiffness

    def static_torque_nm(self, angle_rad: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        """Torque [N m] at rest, no state: angles (..., 10), pressures (..., 10, 2) -> (..., 10).

        Kinematic coupling: the pair's torque at that angle. Thesis coupling: the burst
        right after the pressures are set, both muscles still at ``rest_contraction_pct``,
        which does not depend on the angle (and decays to ~0 within ~20 ms).
        """
        angle = np.asarray(angle_rad, float)
        pressure = np.minimum(np.asarray(pressure_kpa, float), self.cfg.max_pressure_kpa)
        if self.kinematic:
            shift = self._pct_per_rad * (angle - self._neutral)
            rest = self.cfg.kinematic_rest_contraction_pct
            c = np.stack([rest + shift, rest - shift], axis=-1)
        else:
            c = np.full(np.broadcast_shapes(angle.shape + (2,), pressure.shape), self.cfg.rest_contraction_pct)
        c, pressure = np.broadcast_arrays(c, pressure)
        force = np.maximum(self.pairs.law.signed_force_n(c, pressure), 0.0)
        return (force[..., 0] - force[..., 1]) * self._lever

    @property
    def pressure_kpa(self) -> np.ndarray:
        return self.pairs.pressure_kpa

    @property
    def contraction_pct(self) -> np.ndarray:
        return self._contraction
