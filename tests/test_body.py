"""The body against thesis Table 8.2/8.3, contact overlap, stability and rendering."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from pamrun.config import BodyConfig, ConfigError
from pamrun.physics import body


def test_anthropometry_reproduces_table_8_2():
    seg = body.anthropometry(BodyConfig())
    foot, lower, upper = seg["foot"], seg["lower_leg"], seg["upper_leg"]
    assert (foot["x_m"], foot["y_m"], foot["z_m"]) == pytest.approx((0.2736, 0.099, 0.0702), abs=1e-4)
    assert foot["mass_kg"] == pytest.approx(1.16, abs=1e-3)
    assert foot["radius_gyration_m"] == pytest.approx(0.0668, abs=2e-4)
    assert foot["inertia_kgm2"] == pytest.approx(0.00517, abs=5e-5)
    assert lower["z_m"] == pytest.approx(0.4428, abs=1e-4)
    assert lower["x_m"] == pytest.approx(0.08, abs=1e-3)
    assert lower["mass_kg"] == pytest.approx(3.72, abs=1e-3)
    assert lower["com_m"] == pytest.approx(0.0297, abs=1e-4)
    assert lower["radius_gyration_m"] == pytest.approx(0.1337, abs=2e-4)
    assert lower["inertia_kgm2"] == pytest.approx(0.0665, abs=2e-4)
    assert upper["z_m"] == pytest.approx(0.441, abs=1e-3)
    assert (upper["x_m"], upper["y_m"]) == pytest.approx((0.15, 0.12), abs=1e-3)
    assert upper["mass_kg"] == pytest.approx(8.0)
    assert upper["com_m"] == pytest.approx(0.0295, abs=1e-4)
    assert upper["radius_gyration_m"] == pytest.approx(0.1424, abs=2e-4)
    assert upper["inertia_kgm2"] == pytest.approx(0.1623, abs=3e-4)
    legs = [r for r in body.segment_table(BodyConfig()) if r["segment"] == "both legs"][0]
    assert legs["mass_kg"] == pytest.approx(25.76, abs=1e-3)


def test_other_bodies_scale():
    small = body.anthropometry(BodyConfig(height_m=1.6, mass_kg=60))
    ref = body.anthropometry(BodyConfig())
    assert small["upper_leg"]["mass_kg"] == pytest.approx(ref["upper_leg"]["mass_kg"] * 60 / 80)
    assert small["foot"]["x_m"] == pytest.approx(ref["foot"]["x_m"] * 1.6 / 1.8)
    model = body.build_model(BodyConfig(height_m=1.6, mass_kg=60))
    assert model.body_subtreemass[0] == pytest.approx((0.142 + 2 * (0.0145 + 0.0465 + 0.1)) * 60)


def test_model_joints_and_limits():
    cfg = BodyConfig()
    model = body.build_model(cfg)
    assert model.nu == 10 and model.nq == 7 + 10
    names = [model.joint(i).name for i in range(1, model.njnt)]
    assert names == list(body.JOINTS)
    for side in ("left", "right"):
        for joint, (lo, hi) in body.joint_limits_deg(cfg, side).items():
            rng = np.degrees(model.joint(f"{side}_{joint}").range)
            np.testing.assert_allclose(rng, [lo, hi], atol=1e-9)
    np.testing.assert_allclose(np.degrees(model.joint("left_hip_roll").range), [-22.5, 11.25])
    np.testing.assert_allclose(np.degrees(model.joint("right_hip_roll").range), [-11.25, 22.5])
    np.testing.assert_allclose(np.degrees(model.joint("right_ankle_roll").range), [-35, 25])
    np.testing.assert_allclose(np.degrees(model.joint("left_knee").range), [0, 90])
    assert np.all(model.dof_damping[6:] == 1.0)


def test_every_per_joint_table_follows_leg_joints():
    """LEG_JOINTS (pamrun.config) is the one list of a leg's hinges: each per-joint config table
    has one field per name, in its order (the YAML keys muscle.count.<joint>,
    body.<joint>_limits_deg), and the body's joints are named from it."""
    from dataclasses import fields

    from pamrun.config import LEG_JOINTS, JointAngles, JointCounts, JointRadii

    for table in (JointCounts, JointRadii, JointAngles):
        assert tuple(f.name for f in fields(table)) == LEG_JOINTS, table.__name__
    limits = tuple(f.name for f in fields(BodyConfig) if f.name.endswith("_limits_deg"))
    assert limits == tuple(f"{joint}_limits_deg" for joint in LEG_JOINTS)
    assert body.LEG_JOINTS is LEG_JOINTS
    assert body.JOINTS == tuple(f"{side}_{joint}" for side in body.SIDES for joint in LEG_JOINTS)


def test_only_foot_spheres_touch_the_floor():
    model = body.build_model(BodyConfig())
    floor = model.geom("floor").id

    def collide(a: int, b: int) -> bool:  # MuJoCo's contype/conaffinity rule
        ct, ca = model.geom_contype, model.geom_conaffinity
        return bool(ct[a] & ca[b] or ct[b] & ca[a])

    colliders = [g for g in range(model.ngeom) if g != floor and collide(g, floor)]
    assert len(colliders) == 8
    assert all(model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE for g in colliders)
    others = [g for g in range(model.ngeom) if g != floor]
    assert not any(collide(a, b) for a in others for b in others if a < b)


def _stand(cfg: BodyConfig, seconds: float = 1.5, timestep_s: float = 0.0025) -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Hold every joint at 0 with a PD law and let the robot settle on its feet."""
    model = body.build_model(cfg, timestep_s=timestep_s)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("stand").id)
    for _ in range(int(seconds / timestep_s)):
        data.ctrl[:] = -300 * data.qpos[7:] - 5 * data.qvel[6:]
        mujoco.mj_step(model, data)
    return model, data


@pytest.mark.parametrize("overlap_m", [0.001, 0.002])
def test_feet_sink_by_the_designed_overlap(overlap_m):
    model, data = _stand(BodyConfig(contact_overlap_m=overlap_m))
    spheres = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    sink = np.array([model.geom_size[g][0] - data.geom_xpos[g][2] for g in spheres])
    assert sink.mean() == pytest.approx(overlap_m, rel=0.2)
    # The feet carry the robot's weight.
    weight = model.body_subtreemass[0] * 9.81
    assert data.sensordata.sum() == pytest.approx(weight, rel=0.05)


def test_stable_at_5ms():
    model, data = _stand(BodyConfig(), seconds=2.0, timestep_s=0.005)
    assert np.all(np.isfinite(data.qpos))
    assert data.qpos[2] == pytest.approx(body.standing_height_m(BodyConfig()), abs=0.01)


def test_fixed_model_hangs_in_the_air():
    model = body.build_fixed_model(BodyConfig())
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, 200)
    assert model.nq == 10 and data.ncon == 0


def test_render_standing():
    image = body.render_standing(body.build_model(BodyConfig()), 160, 120)
    assert image.shape == (120, 160, 3)
    assert image.std() > 10


def test_bad_body_values_fail_with_the_key():
    with pytest.raises(ConfigError, match="height_m"):
        BodyConfig(height_m=-1)
    with pytest.raises(ConfigError, match="knee_limits_deg"):
        BodyConfig(knee_limits_deg=[10.0, 5.0])
    with pytest.raises(ConfigError, match="contact_overlap_m"):
        BodyConfig(contact_overlap_m=0.0)


def _standing_data(cfg: BodyConfig):
    model = body.build_model(cfg)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "stand"))
    mujoco.mj_forward(model, data)
    return model, data


@pytest.mark.parametrize("height_m, mass_kg", [(1.80, 80.0), (1.60, 60.0)])
def test_every_body_centre_of_mass_at_the_standing_pose(height_m, mass_kg):
    """World-frame centres of mass of the compiled model against the anthropometric ratios:
    the pelvis block's at its centre (half its height above the hips), the thigh's and the
    shank's 0.433 of their length below the proximal joint (Winter, Table 4.1, as Table
    8.2's CoM column), the foot's at half its height, 0.0569 H/1.8 in front of the ankle."""
    cfg = BodyConfig(height_m=height_m, mass_kg=mass_kg)
    seg = body.anthropometry(cfg)
    model, data = _standing_data(cfg)
    foot_z, shank, thigh, pelvis = seg["foot"]["z_m"], seg["lower_leg"]["z_m"], seg["upper_leg"]["z_m"], seg["pelvis"]
    hip_z = foot_z + shank + thigh
    expected_z = {"torso": hip_z + pelvis["z_m"] / 2, "thigh": hip_z - 0.433 * thigh,
                  "shin": foot_z + shank - 0.433 * shank, "foot": foot_z / 2}
    hip_y = pelvis["hip_width_m"] / 2
    for i in range(1, model.nbody):
        name = model.body(i).name
        part = name.split("_")[-1]
        side = {"right": -1.0, "left": 1.0}.get(name.split("_")[0], 0.0)
        x = 0.0569 * height_m / 1.8 if part == "foot" else 0.0
        np.testing.assert_allclose(data.xipos[i], [x, side * hip_y, expected_z[part]], atol=2e-3, err_msg=name)
    assert model.nbody - 1 == 7
    # The whole robot's centre of mass: ~0.40 H up (0.715 m at 1.80 m), over the feet.
    total = (sum(seg[k]["mass_kg"] * expected_z[n] for k, n in
                 (("upper_leg", "thigh"), ("lower_leg", "shin"), ("foot", "foot"))) * 2
             + pelvis["mass_kg"] * expected_z["torso"]) / model.body_subtreemass[0]
    assert data.subtree_com[0][2] == pytest.approx(total, abs=2e-3)
    assert 0.38 * height_m < data.subtree_com[0][2] < 0.42 * height_m
