"""Muscle pairs on the robot's joints: action -> pressures -> forces -> joint torques.

Ten antagonistic pairs, one per hinge (``pamrun.physics.body.JOINTS`` order). Muscle 1 of a pair
pulls the joint towards positive angles, muscle 2 towards negative ones. Each side of a
pair is ``muscle.count.<joint>`` muscles of ``muscle.size`` in parallel, so its force is
k F(c, P) with k = count x the size's force ratio (:attr:`MuscleConfig.force_scale`).

Command (``muscle.command``): ``antagonistic`` takes 10 actions a in [-1, 1] and sets
V1 = V0 + dV a, V2 = V0 - dV a (thesis §9.5: V0 = 2.12 V, dV = 0.71 V); ``independent``
takes 20 actions, V = V0 + dV a for each muscle (muscle 1 of every pair first), so a
policy sets each pair's co-contraction as well as its torque.

Two couplings of muscle and joint (``muscle.coupling``):

* ``thesis`` — as the thesis built it (§8.3): each muscle's contraction is its own dynamic
  state (D x' + S x = Fce - FL, :class:`pamrun.physics.muscle.FirstOrderPairDynamics`) and the
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
call (``numba``, :mod:`pamrun.physics.kernels`) or as the numpy code below (``numpy``, the
reference); both give the same results to float rounding. The thesis coupling is numpy only.

One class per coupling (:class:`ThesisCoupling`, :class:`KinematicCoupling` and its compiled
twin :class:`CompiledKinematicCoupling`), chosen once by :func:`make_coupling`;
:class:`MuscleDrive` turns actions into voltages and hands them to it.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from mujoco import mj_step

from pamrun.config import LEG_JOINTS, BodyConfig, MuscleConfig, check_muscle_stretch
from pamrun.physics.body import JOINTS, SIDES, joint_limits_deg, mirror_sign
from pamrun.physics.muscle import AntagonisticPairs


def joint_limits_rad(body: BodyConfig) -> np.ndarray:
    """(10, 2) joint limits [rad] in JOINTS order (the mirroring lives in pamrun.physics.body)."""
    return np.deg2rad([lim for side in SIDES for lim in joint_limits_deg(body, side).values()])


def _leg_joint_of_each_hinge() -> list[str]:
    """The LEG_JOINTS name of each of the 10 hinges, JOINTS order (both legs alike)."""
    return [joint for _ in SIDES for joint in LEG_JOINTS]


def pulley_radii_m(muscle: MuscleConfig, body: BodyConfig) -> np.ndarray:
    """(10,) pulley radius of each joint [m] (see the module docstring for the rule)."""
    names = _leg_joint_of_each_hinge()
    reach = [muscle.reach_rad(name, getattr(body, f"{name}_limits_deg")) for name in names]
    return np.array([muscle.radius_m(name, r) for name, r in zip(names, reach)])


def neutral_angles_rad(muscle: MuscleConfig) -> np.ndarray:
    """(10,) angle of each joint where its pair is balanced at equal pressures, JOINTS order.

    The right leg mirrors the roll joints (as its limits do)."""
    return np.deg2rad([getattr(muscle.neutral_deg, j) * mirror_sign(side, j) for side in SIDES for j in LEG_JOINTS])


def muscle_counts(muscle: MuscleConfig) -> np.ndarray:
    """(10,) muscles in parallel per direction, JOINTS order."""
    return np.array([getattr(muscle.count, name) for name in _leg_joint_of_each_hinge()], float)


def force_scales(muscle: MuscleConfig) -> np.ndarray:
    """(10,) muscles per direction x the size's force ratio, JOINTS order."""
    return muscle_counts(muscle) * muscle.force_scale


def n_actions(muscle: MuscleConfig) -> int:
    """Actions the policy gives: one per pair (antagonistic) or one per muscle (independent)."""
    return len(JOINTS) * (2 if muscle.command == "independent" else 1)


class Coupling(ABC):
    """What every muscle-joint coupling shares: the pairs, their levers and the static torque.

    A coupling steps the pairs (:meth:`torques_nm`, :meth:`apply`, :meth:`advance`) holding a
    command of (n, 2) regulator voltages [V]; ``contraction_pct`` (n, 2) [%] is each muscle's
    contraction after the last step, ``rest_pct`` [%] where a reset puts both muscles.
    """

    rest_pct: float

    def __init__(self, muscle: MuscleConfig, pairs: AntagonisticPairs, radius_m: np.ndarray):
        self.cfg, self.pairs, self.radius_m = muscle, pairs, radius_m
        self.lever = pairs.force_scale * radius_m  # k r [m]: torque per newton of one muscle
        self.contraction_pct = np.zeros((len(radius_m), 2))

    def reset(self) -> None:
        """Both muscles of every pair at ``rest_pct`` (the pairs' own state: AntagonisticPairs.reset)."""
        self.contraction_pct[:] = self.rest_pct

    @abstractmethod
    def torques_nm(self, voltage_v: np.ndarray, angle_rad: np.ndarray, velocity_rad_s: np.ndarray,
                   dt_s: float) -> np.ndarray:
        """Advance the muscles by dt_s [s]; the (n,) joint torques [N m]."""

    @abstractmethod
    def apply(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray,
              dt_s: float) -> None:
        """Advance the muscles by dt_s [s] and set MuJoCo's joint actuators for the next dt_s."""

    def advance(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray, dt_s: float,
                muscle_steps: int, physics_steps: int) -> None:
        """``muscle_steps`` times: :meth:`apply` for dt_s, then ``physics_steps`` MuJoCo steps."""
        for _ in range(muscle_steps):
            self.apply(voltage_v, model, data, qpos_idx, qvel_idx, dt_s)
            mj_step(model, data, physics_steps)

    @abstractmethod
    def static_contraction_pct(self, angle_rad: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        """Both muscles' contraction [%], (..., n, 2), at rest at these angles [rad] and pressures [kPa]."""

    def static_torque_nm(self, angle_rad: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        """Torque k (F1 - F2) r [N m] at rest, no state: angles (..., n) [rad], pressures (..., n, 2)
        [kPa, capped at the muscle's max] -> (..., n); forces never negative."""
        angle = np.asarray(angle_rad, float)
        pressure = np.minimum(np.asarray(pressure_kpa, float), self.cfg.max_pressure_kpa)
        c, pressure = np.broadcast_arrays(self.static_contraction_pct(angle, pressure), pressure)
        force = np.maximum(self.pairs.law.signed_force_n(c, pressure), 0.0)
        return (force[..., 0] - force[..., 1]) * self.lever


class ThesisCoupling(Coupling):
    """The thesis' coupling (§8.3): each muscle's contraction is its own dynamic state.

    D x' + S x = Fce - FL (:class:`pamrun.physics.muscle.FirstOrderPairDynamics`), starting from
    ``rest_contraction_pct`` (14.06 %, the zero-force contraction at 176.4 kPa, §10.1); the
    joint angle does not feed back into it. T = k (F1 - F2) r [N m], held over the muscle
    step: a pair gives torque only while its contractions move after a pressure change
    (~20 ms), then ~0. Its static torque is that burst, the same at every angle.
    """

    def __init__(self, muscle: MuscleConfig, pairs: AntagonisticPairs, radius_m: np.ndarray):
        super().__init__(muscle, pairs, radius_m)
        self.rest_pct = muscle.rest_contraction_pct

    def torques_nm(self, voltage_v: np.ndarray, angle_rad: np.ndarray, velocity_rad_s: np.ndarray,
                   dt_s: float) -> np.ndarray:
        pairs = self.pairs
        changed = pairs.regulator.step(voltage_v, dt_s, self.contraction_pct)
        pairs.dynamics.step(pairs.pressure_kpa, dt_s, changed)
        self.contraction_pct = pairs.dynamics.contraction_pct()
        return pairs.torque_nm(self.radius_m)

    def apply(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray,
              dt_s: float) -> None:
        """The torque, held for dt_s (plain motors: no bias)."""
        data.ctrl[:] = self.torques_nm(voltage_v, data.qpos[qpos_idx], data.qvel[qvel_idx], dt_s)

    def static_contraction_pct(self, angle_rad: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        """Both muscles still at ``rest_contraction_pct``, whatever the angle (the burst)."""
        return np.full(np.broadcast_shapes(angle_rad.shape + (2,), pressure_kpa.shape), self.rest_pct)


class KinematicCoupling(Coupling):
    """Contraction follows the joint through its pulley (physically consistent; numpy reference).

    c1,2 = c_rest +- 100 r (theta - theta_n) / L0 [%] (c_rest: ``kinematic_rest_contraction_pct``,
    theta_n: ``neutral_deg``), so co-contraction stiffens the joint; both dampers D = tau S
    (thesis §8.3) act on the joint velocity: T = k (F1 - F2) r - k (D1 + D2) r^2 theta' [N m].
    Pressure follows the command through the regulator (and its lag). With hysteresis
    (``muscle.spring.hysteresis``, pamrun/physics/hysteresis.py) each F is F - H, H moved along by each
    muscle's contraction, and the sticking elements stiffen the pair.
    """

    def __init__(self, muscle: MuscleConfig, pairs: AntagonisticPairs, radius_m: np.ndarray):
        super().__init__(muscle, pairs, radius_m)
        self.hysteresis = pairs.dynamics.hysteresis  # None for none; reset with the pairs
        self.rest_pct = muscle.kinematic_rest_contraction_pct
        self.pct_per_rad = 100.0 * radius_m / muscle.nominal_length_m  # 100 r / L0 [%/rad]
        self.neutral = neutral_angles_rad(muscle)  # theta_n [rad]
        self.coef: np.ndarray | None = None  # force law at the current pressures (None: recompute)
        self.damping = np.zeros(len(radius_m))  # k (D1 + D2) r^2 [N m s/rad]

    def reset(self) -> None:
        super().reset()
        self.coef = None

    def torque_and_stiffness(self, voltage_v: np.ndarray, angle_rad: np.ndarray,
                             dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Step the regulator by dt_s [s]; the pairs' torque k (F1 - F2) r [N m] at ``angle_rad``
        and its stiffness -dT/dtheta [N m/rad] (a slack muscle adds none)."""
        pairs = self.pairs
        changed = pairs.regulator.step(voltage_v, dt_s, self.contraction_pct)  # the last step's (valve: volume)
        if changed or self.coef is None:
            pressure = pairs.pressure_kpa
            self.coef = pairs.law.at_pressure(pressure)
            # Both sides' dampers act on the joint: k (D1 + D2) r^2 [N m s/rad], D = tau S.
            d_n_s_per_m = self.cfg.tau_s * pairs.dynamics.spring(pressure).sum(axis=1) * pairs.dynamics.length_scale
            self.damping = d_n_s_per_m * self.lever * self.radius_m
            if self.hysteresis is not None:
                self.hysteresis.at_pressure(pressure)
        shift = self.pct_per_rad * (angle_rad - self.neutral)
        if self.hysteresis is None:
            c = self.contraction_pct
            c[:, 0] = self.rest_pct + shift
            c[:, 1] = self.rest_pct - shift
            force, slope = pairs.law.force_and_slope(self.coef, c)
        else:
            force, slope = self._net_force_and_slope(shift)
        slope = np.where(force > 0.0, slope, 0.0)  # dF/dc [N/%], 0 where slack
        force = np.maximum(force, 0.0)
        torque = (force[:, 0] - force[:, 1]) * self.lever
        stiffness = -(slope[:, 0] + slope[:, 1]) * self.pct_per_rad * self.lever
        return torque, stiffness

    def _net_force_and_slope(self, shift: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Contractions at the pulley ``shift`` [%]; the hysteresis elements moved by each muscle's
        change; F - H [N] and dF/dc - dH/dc [N/%], signed (n, 2)."""
        c, hysteresis = self.contraction_pct, self.hysteresis
        previous = c.copy()
        c[:, 0] = self.rest_pct + shift
        c[:, 1] = self.rest_pct - shift
        hysteresis.move(c - previous)
        force, slope = self.pairs.law.force_and_slope(self.coef, c)
        return force - hysteresis.force_n(), slope - hysteresis.stiffness_n_per_pct()

    def torques_nm(self, voltage_v: np.ndarray, angle_rad: np.ndarray, velocity_rad_s: np.ndarray,
                   dt_s: float) -> np.ndarray:
        return self.torque_and_stiffness(voltage_v, angle_rad, dt_s)[0] - self.damping * velocity_rad_s

    def apply(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray,
              dt_s: float) -> None:
        """The pair's torque linearised at the current angle theta0, T0 - K (theta - theta0) - D theta',
        through the actuators' affine bias (ctrl = T0 + K theta0, biasprm[:, 1:3] = -K, -D)."""
        angle = data.qpos[qpos_idx]
        torque, stiffness = self.torque_and_stiffness(voltage_v, angle, dt_s)
        data.ctrl[:] = torque + stiffness * angle
        model.actuator_biasprm[:, 1] = -stiffness
        model.actuator_biasprm[:, 2] = -self.damping

    def static_contraction_pct(self, angle_rad: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        shift = self.pct_per_rad * (angle_rad - self.neutral)
        return np.stack([self.rest_pct + shift, self.rest_pct - shift], axis=-1)


class CompiledKinematicCoupling(KinematicCoupling):
    """:class:`KinematicCoupling` stepped by one compiled call per muscle step
    (:class:`pamrun.physics.kernels.CompiledStep`); the numpy reference's results to float rounding."""

    def __init__(self, muscle: MuscleConfig, pairs: AntagonisticPairs, radius_m: np.ndarray):
        from pamrun.physics.kernels import CompiledStep  # heavy (numba): loaded only for muscle.kernel=numba

        super().__init__(muscle, pairs, radius_m)
        self.compiled = CompiledStep(self)  # writes this coupling's contraction_pct and damping in place

    def reset(self) -> None:
        super().reset()
        self.compiled.stale = True

    def torque_and_stiffness(self, voltage_v: np.ndarray, angle_rad: np.ndarray,
                             dt_s: float) -> tuple[np.ndarray, np.ndarray]:
        return self.compiled.step(voltage_v, angle_rad, dt_s)

    def apply(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray,
              dt_s: float) -> None:
        self.compiled.apply(voltage_v, model, data, qpos_idx, dt_s)

    def advance(self, voltage_v: np.ndarray, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray, dt_s: float,
                muscle_steps: int, physics_steps: int) -> None:
        self.compiled.advance(voltage_v, model, data, qpos_idx, dt_s, muscle_steps, physics_steps)


def make_coupling(muscle: MuscleConfig, pairs: AntagonisticPairs, radius_m: np.ndarray) -> Coupling:
    """The coupling ``muscle.coupling`` names, stepped as ``muscle.kernel`` says (thesis: numpy only)."""
    if muscle.coupling == "thesis":
        return ThesisCoupling(muscle, pairs, radius_m)
    kinematic = CompiledKinematicCoupling if muscle.kernel == "numba" else KinematicCoupling
    return kinematic(muscle, pairs, radius_m)


class MuscleDrive:
    """All 20 muscles of the robot, stepped together: actions -> voltages -> the coupling.

    ``coupling`` (:func:`make_coupling`) does the physics; the state lives where the numpy
    code keeps it (``pairs.regulator.pressure_kpa``, ``contraction_pct``, ``voltage_v``)
    whichever kernel steps it.
    """

    def __init__(self, muscle: MuscleConfig, body: BodyConfig):
        check_muscle_stretch(muscle, body)
        self.cfg = muscle
        self.kinematic = muscle.coupling == "kinematic"
        self.radius_m = pulley_radii_m(muscle, body)
        self.force_scale = force_scales(muscle)
        self.n_actions = n_actions(muscle)
        self.pairs = AntagonisticPairs(muscle, len(self.radius_m), self.force_scale, muscle_counts(muscle))
        self._swing_v = np.array([muscle.dv_max_v, -muscle.dv_max_v])  # dV, -dV: each pair's (antagonistic)
        self._rest_action = np.zeros(self.n_actions)
        # V0's pressure [kPa], where a reset puts every muscle (the config is fixed for the drive's life)
        self._v0_kpa = self.pairs.regulator.target_pressure_kpa(np.full((1, 2), muscle.v0_v))[0, 0]
        self.voltage_v = self.voltages_v(self._rest_action)
        self.coupling = make_coupling(muscle, self.pairs, self.radius_m)

    @property
    def compiled(self) -> bool:
        """Whether the compiled kernel steps the muscles (``kernel=numba`` and the kinematic coupling)."""
        return isinstance(self.coupling, CompiledKinematicCoupling)

    def reset(self) -> None:
        """Both muscles of every pair at V0's pressure and the coupling's rest contraction."""
        self.pairs.reset(self._v0_kpa, self.coupling.rest_pct)
        self.voltage_v = self.voltages_v(self._rest_action)
        self.coupling.reset()

    def voltages_v(self, action: np.ndarray, clipped: bool = False) -> np.ndarray:
        """Actions in [-1, 1] -> (10, 2) regulator voltages (see ``muscle.command``); ``clipped``:
        the actions are a float array already in [-1, 1] (or NaN), which the clip would leave as they are.

        The values of ``pairs.voltages_v`` (V0 + dV a, V0 - dV a), bit for bit, without its
        np.clip and np.stack, whose Python wrappers cost more than the arithmetic."""
        a = action
        if not clipped:
            a = np.maximum(action, -1.0, dtype=float)  # np.clip(a, -1, 1), NaN kept
            np.minimum(a, 1.0, out=a)
        if self.n_actions == len(self.radius_m):
            # a * -dV is exactly -(dV a), and (-(dV a)) + V0 is V0 - dV a (a sum is the same either way round)
            voltage = np.multiply.outer(a, self._swing_v)
        else:
            voltage = self.cfg.dv_max_v * a.reshape(len(self.radius_m), 2)
        voltage += self.cfg.v0_v
        return voltage

    def set_action(self, action: np.ndarray, clipped: bool = False) -> None:
        """Hold the regulator voltages for this action until the next call (``clipped``: see :meth:`voltages_v`)."""
        self.voltage_v = self.voltages_v(action, clipped)

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
        self.coupling.apply(self.voltage_v, model, data, qpos_idx, qvel_idx, dt_s)

    def advance(self, model, data, qpos_idx: np.ndarray, qvel_idx: np.ndarray, dt_s: float, muscle_steps: int,
                physics_steps: int) -> None:
        """``muscle_steps`` times: :meth:`apply` for dt_s, then ``physics_steps`` MuJoCo steps.

        The same as that loop, call for call; with the compiled kernel the arguments are
        gathered once, so between MuJoCo steps there is one kernel call and no other Python.
        """
        self.coupling.advance(self.voltage_v, model, data, qpos_idx, qvel_idx, dt_s, muscle_steps, physics_steps)

    def torques_nm(self, angle_rad: np.ndarray, velocity_rad_s: np.ndarray, dt_s: float) -> np.ndarray:
        """Advance the muscles by dt_s and return the (10,) joint torques [N m]."""
        return self.coupling.torques_nm(self.voltage_v, angle_rad, velocity_rad_s, dt_s)

    def static_torque_nm(self, angle_rad: np.ndarray, pressure_kpa: np.ndarray) -> np.ndarray:
        """Torque [N m] at rest, no state: angles (..., 10), pressures (..., 10, 2) -> (..., 10).

        Kinematic coupling: the pair's torque at that angle. Thesis coupling: the burst
        right after the pressures are set, both muscles still at ``rest_contraction_pct``,
        which does not depend on the angle (and decays to ~0 within ~20 ms).
        """
        return self.coupling.static_torque_nm(angle_rad, pressure_kpa)

    @property
    def pressure_kpa(self) -> np.ndarray:
        return self.pairs.pressure_kpa

    @property
    def contraction_pct(self) -> np.ndarray:
        return self.coupling.contraction_pct
