"""The muscle-joint couplings of pamrun.physics.actuation: one class each, and the compiled step's arguments."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from pamrun.config import BodyConfig, MuscleConfig
from pamrun.physics import kernels
from pamrun.physics.actuation import (
    CompiledKinematicCoupling,
    KinematicCoupling,
    MuscleDrive,
    ThesisCoupling,
)
from tests.conftest import thesis_muscle


@pytest.mark.parametrize(("name", "coupling"), [
    ("kinematic_numba", CompiledKinematicCoupling),
    ("kinematic_numpy", KinematicCoupling),
    ("thesis", ThesisCoupling),  # kernel=numba (the default): the thesis coupling is numpy only
])
def test_the_config_picks_one_coupling_class(name, coupling):
    muscle = thesis_muscle() if name == "thesis" else MuscleConfig(kernel=name.split("_")[1])
    drive = MuscleDrive(muscle, BodyConfig())
    assert type(drive.coupling) is coupling
    assert drive.compiled == (coupling is CompiledKinematicCoupling)
    drive.reset()
    assert np.all(drive.contraction_pct == drive.coupling.rest_pct)


def test_compiled_step_arguments_are_the_kernels_in_order():
    """CompiledStep.arguments is muscle_step's argument list; muscle_apply takes the same, then MuJoCo's."""
    step = list(inspect.signature(kernels.muscle_step.py_func).parameters)
    apply = list(inspect.signature(kernels.muscle_apply.py_func).parameters)
    assert apply == step + ["qpos", "qpos_idx", "ctrl", "biasprm"]
    drive = MuscleDrive(MuscleConfig(), BodyConfig())
    drive.reset()
    compiled = drive.coupling.compiled
    args = compiled.arguments(drive.voltage_v, 0.005, compiled.angle)
    assert len(args) == len(step)
    named = dict(zip(step, args))
    assert named["voltage"] is drive.voltage_v and named["new_voltage"] and named["stale"]
    regulator = drive.pairs.regulator
    assert named["target"] is regulator.target_kpa and named["pressure"] is regulator.pressure_kpa
    assert named["contraction"] is drive.coupling.contraction_pct and named["damping"] is drive.coupling.damping


def test_static_torque_is_the_same_whichever_kernel():
    """The static torque (pamrun capacity's) does not depend on the kernel: no state, same numpy code."""
    rng = np.random.default_rng(0)
    angle, pressure = rng.uniform(-1, 1, (5, 10)), rng.uniform(0, 700, (5, 10, 2))
    fast, ref = (MuscleDrive(MuscleConfig(kernel=k), BodyConfig()) for k in ("numba", "numpy"))
    assert np.array_equal(fast.static_torque_nm(angle, pressure), ref.static_torque_nm(angle, pressure))


def test_one_call_control_step_is_the_python_loop_bit_for_bit():
    """muscle_advance (MuJoCo's C mj_step called from compiled code) gives the state that
    muscle_apply and the bindings' mj_step, called one by one from Python, give."""
    import mujoco

    from pamrun.task.env import PamWalkerEnv

    assert kernels.MJ_STEP, "MuJoCo's C library not found: the control step falls back to Python"
    envs = [PamWalkerEnv(), PamWalkerEnv()]
    envs[1].drive.coupling.compiled.mj_step = 0  # the Python loop
    rng = np.random.default_rng(0)
    for env in envs:
        env.reset(seed=0)
    for _ in range(60):
        action = rng.uniform(-1, 1, 10).astype(np.float32)
        for env in envs:
            env.step(action)
    fast, loop = (env.data for env in envs)
    for name in ("qpos", "qvel", "qacc", "ctrl", "sensordata"):
        assert np.array_equal(getattr(fast, name), getattr(loop, name)), name
    assert fast.time == loop.time
    assert np.array_equal(envs[0].model.actuator_biasprm, envs[1].model.actuator_biasprm)
    assert isinstance(fast, mujoco.MjData)
