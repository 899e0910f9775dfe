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
