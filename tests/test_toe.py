"""body.toe: a passive toe on each foot (thesis §13, future work), and body.toe=false as before."""

from __future__ import annotations

import json
import math

import mujoco
import numpy as np
import pytest

from pamrun.config import BodyConfig, ConfigError, MuscleConfig, to_object
from pamrun.config.robot import MTP_PEAK_MOMENT_NM_PER_KG
from pamrun.physics import body
from pamrun.physics.capacity import _gravity_loads, analyse
from pamrun.task.env import PamWalkerEnv
from tests.conftest import compose_config, run_pamrun

DT = 0.0025  # env.physics_dt_s
TOE = BodyConfig(toe=True)
# Any toe_* values: with toe=false they must not reach the model.
ODD_TOE = {"toe_length_ratio": 0.2, "toe_mass_ratio": 0.3, "toe_stiffness_nm_per_rad": 9.0,
           "toe_damping_nms_per_rad": 2.0, "toe_range_deg": [-30.0, 10.0]}


# --------------------------------------------------------------------------- toe=false: today's model


def test_toe_false_is_the_model_built_before_the_toe():
    """Invariants read from the build before body.toe existed (H = 1.8 m, M = 80 kg, dt = 2.5 ms)."""
    model = body.build_model(BodyConfig(), timestep_s=DT)
    assert (model.nq, model.nv, model.nu, model.njnt, model.nbody, model.ngeom, model.nsite, model.nsensor,
            model.nkey) == (17, 16, 10, 11, 8, 16, 2, 2, 1)
    assert model.body_mass.tolist() == [0.0, 11.36, 8.0, 3.7199999999999998, 1.1600000000000001, 8.0,
                                        3.7199999999999998, 1.1600000000000001]
    assert float(model.body_subtreemass[0]) == 37.12
    np.testing.assert_array_equal(model.body_inertia[4], [0.0051847592000000015, 0.0051847592000000015,
                                                          0.008183602800000002])
    assert [model.joint(i).name for i in range(1, model.njnt)] == list(body.JOINTS)
    assert [model.sensor(i).name for i in range(model.nsensor)] == list(body.FOOT_SENSORS)
    spheres = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    assert [model.geom(g).name for g in spheres] == [f"{side}_contact_{end}_{edge}" for side in body.SIDES
                                                      for end in ("back", "front") for edge in ("right", "left")]
    x, y, z = 0.1829, 0.0387, -0.059399999999999994
    corners = [[-0.0691, -y, z], [-0.0691, y, z], [x, -y, z], [x, y, z]]
    np.testing.assert_array_equal(model.geom_pos[spheres], corners * 2)
    assert model.geom_solref[spheres[0]].tolist() == [-146.1010890841703, -14.61010890841703]
    assert "toe" not in body.anthropometry(BodyConfig())


def test_toe_false_ignores_the_toe_fields_bit_for_bit():
    """The same XML, and the same seeded rollout's observations to the bit, whatever toe_* say."""
    assert (body.build_spec(BodyConfig(**ODD_TOE), timestep_s=DT).to_xml()
            == body.build_spec(BodyConfig(), timestep_s=DT).to_xml())
    runs = []
    for cfg in ({}, {"toe": False, **ODD_TOE}):
        env = PamWalkerEnv(body=cfg, env={"reset_noise_rad": 0.02})
        obs, _ = env.reset(seed=3)
        rng = np.random.default_rng(0)
        out = [obs]
        for _ in range(20):
            out.append(env.step(rng.uniform(-0.3, 0.3, 10).astype(np.float32))[0])
        runs.append(np.array(out))
    assert runs[0].tobytes() == runs[1].tobytes()


# --------------------------------------------------------------------------- toe=true: the model


def test_toe_takes_its_mass_from_the_foot_and_keeps_the_centre_of_mass():
    plain, toe = body.build_model(BodyConfig(), timestep_s=DT), body.build_model(TOE, timestep_s=DT)
    assert toe.body_subtreemass[0] == pytest.approx(plain.body_subtreemass[0], rel=1e-12)
    assert (toe.nq, toe.nv, toe.nu, toe.nbody) == (plain.nq + 2, plain.nv + 2, 10, plain.nbody + 2)
    for side in body.SIDES:
        foot = toe.body(f"{side}_foot").id
        assert toe.body_subtreemass[foot] == pytest.approx(plain.body_mass[plain.body(f"{side}_foot").id], rel=1e-12)
        assert toe.body_mass[toe.body(f"{side}_toe").id] == pytest.approx(0.138 * 0.0145 * 80.0)
    data = [mujoco.MjData(m) for m in (plain, toe)]
    for m, d in zip((plain, toe), data):
        mujoco.mj_resetDataKeyframe(m, d, m.key("stand").id)
        mujoco.mj_forward(m, d)
    np.testing.assert_allclose(data[1].subtree_com[0], data[0].subtree_com[0], atol=1e-12)
    np.testing.assert_allclose(data[1].subtree_com[toe.body("left_foot").id],
                               data[0].subtree_com[plain.body("left_foot").id], atol=1e-12)
    # the capacity analysis counts the toe with the foot: the same loads on every joint
    with_toe, without = _gravity_loads(TOE), _gravity_loads(BodyConfig())
    for group, load in without.items():
        assert with_toe[group] == pytest.approx(load, rel=1e-12), group


def test_toe_hinge_is_passive_with_the_configured_spring():
    cfg = BodyConfig(toe=True, toe_stiffness_nm_per_rad=7.5, toe_damping_nms_per_rad=0.2, toe_range_deg=[-50.0, 20.0])
    model = body.build_model(cfg, timestep_s=DT)
    for name in body.TOE_JOINTS:
        joint = model.joint(name)
        assert joint.type[0] == mujoco.mjtJoint.mjJNT_HINGE and joint.axis.tolist() == [0, 1, 0]
        assert model.body(joint.bodyid[0]).name == name
        assert model.body(model.body(name).parentid[0]).name.endswith("_foot")
        assert model.jnt_stiffness[joint.id] == 7.5 and model.dof_damping[joint.dofadr[0]] == 0.2
        np.testing.assert_allclose(np.degrees(joint.range), [-50.0, 20.0])
    # no actuator on it: the ten muscles' motors act on the JOINTS only
    driven = {model.joint(model.actuator_trnid[a, 0]).name for a in range(model.nu)}
    assert model.nu == 10 and driven == set(body.JOINTS)
    qpos, qvel = body.joint_addresses(model)
    toe_qpos = [model.joint(n).qposadr[0] for n in body.TOE_JOINTS]
    assert not set(toe_qpos) & set(qpos.tolist()) and len(qvel) == 10
    assert [model.joint(j).name for j in range(model.njnt) if model.jnt_qposadr[j] in qpos] == sorted(
        body.JOINTS, key=lambda n: model.joint(n).qposadr[0])


def test_front_spheres_are_on_the_toe_and_the_foot_stands_on_heel_and_ball():
    model = body.build_model(TOE, timestep_s=DT)
    for side in body.SIDES:
        for edge in ("left", "right"):
            assert model.body(model.geom(f"{side}_contact_front_{edge}").bodyid[0]).name == f"{side}_toe"
            assert model.body(model.geom(f"{side}_contact_back_{edge}").bodyid[0]).name == f"{side}_foot"
            assert model.body(model.geom(f"{side}_contact_ball_{edge}").bodyid[0]).name == f"{side}_foot"
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, model.key("stand").id)
    mujoco.mj_forward(model, d)
    front, ball = (d.geom_xpos[model.geom(f"left_contact_{end}_left").id] for end in ("front", "ball"))
    plain = body.build_model(BodyConfig(), timestep_s=DT)
    pd = mujoco.MjData(plain)
    mujoco.mj_resetDataKeyframe(plain, pd, plain.key("stand").id)
    mujoco.mj_forward(plain, pd)
    np.testing.assert_allclose(front, pd.geom_xpos[plain.geom("left_contact_front_left").id], atol=1e-12)
    foot_length = 0.152 * 1.8
    hinge = d.xanchor[model.joint("left_toe").id]
    assert front[0] - hinge[0] == pytest.approx(0.30 * foot_length - 0.006 * 1.8)  # toe length less a radius
    assert ball[0] < hinge[0] and ball[2] == pytest.approx(front[2])


def _settle(model: mujoco.MjModel, seconds: float, force_n: float = 0.0) -> mujoco.MjData:
    """Torso welded, gravity off, every JOINT held at 0 by a stiff PD; ``force_n`` pushes the left
    toe's tip up (world z) at its front spheres' midpoint. Returns the settled data."""
    model.opt.gravity[:] = 0.0
    d = mujoco.MjData(model)
    qpos, qvel = body.joint_addresses(model)
    toe = model.body("left_toe").id
    spheres = [model.geom(f"left_contact_front_{edge}").id for edge in ("left", "right")]
    for _ in range(int(seconds / model.opt.timestep)):
        d.ctrl[:] = -300.0 * d.qpos[qpos] - 5.0 * d.qvel[qvel]
        d.qfrc_applied[:] = 0.0
        if force_n:
            mujoco.mj_applyFT(model, d, np.array([0.0, 0.0, force_n]), np.zeros(3), d.geom_xpos[spheres].mean(axis=0),
                              toe, d.qfrc_applied)
        mujoco.mj_step(model, d)
    return d


def test_toe_bends_under_a_load_as_its_spring_says():
    """F at the tip, arm l (hinge to the tip spheres' centres): k theta = F l cos(theta)."""
    cfg = BodyConfig(toe=True)
    model = body.build_fixed_model(cfg, timestep_s=DT)
    force = 2.0
    d = _settle(model, 1.0, force)
    adr = model.joint("left_toe").qposadr[0]
    theta = float(d.qpos[adr])
    arm = cfg.toe_box_m()[0] - body.SPHERE_RADIUS_RATIO * cfg.height_m
    assert theta < 0  # pushed up: dorsiflexion is negative
    assert -theta == pytest.approx(force * arm * math.cos(theta) / cfg.toe_stiffness_nm_per_rad, rel=0.01)
    assert abs(d.qpos[model.joint("right_toe").qposadr[0]]) < 1e-9  # the other toe untouched


def test_stability_bound_is_conservative():
    """At the bound a swinging toe (no damping of its own) stays bounded (Euler's overshoot of a
    released spring is 1 / sqrt(1 - (omega dt / 2)^2), here about 1.2); at 4x the bound
    (omega dt = 2 with the toe's own inertia, past the limit with its effective one) MuJoCo's
    step blows up (it then resets the state and warns)."""
    bound = TOE.toe_critical_stiffness_nm_per_rad(DT)
    outcomes = []
    for k in (bound, 4 * bound):
        cfg = BodyConfig(toe=True, toe_stiffness_nm_per_rad=k, toe_damping_nms_per_rad=0.0, toe_range_deg=[-90, 90])
        model = body.build_fixed_model(cfg, timestep_s=DT)
        model.opt.gravity[:] = 0.0
        d = mujoco.MjData(model)
        adr = model.joint("left_toe").qposadr[0]
        d.qpos[adr] = 0.01
        peak = 0.0
        for _ in range(800):
            mujoco.mj_step(model, d)
            peak = max(peak, abs(float(d.qpos[adr])))
        outcomes.append((peak, int(d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)))
    assert outcomes[0][0] < 0.015 and outcomes[0][1] == 0
    assert outcomes[1][1] > 0 or outcomes[1][0] > 0.1


# --------------------------------------------------------------------------- config


def test_bad_toe_values_fail_naming_the_key():
    for key, value in (("toe_stiffness_nm_per_rad", 0.0), ("toe_stiffness_nm_per_rad", -1.0),
                       ("toe_damping_nms_per_rad", -0.1), ("toe_length_ratio", 0.8), ("toe_mass_ratio", 1.0),
                       ("toe_range_deg", [10.0, 20.0])):
        with pytest.raises(ConfigError, match=key):
            BodyConfig(toe=True, **{key: value})
    # too stiff for the physics step: named with its section, before any run
    with pytest.raises(ConfigError, match=r"body\.toe_stiffness_nm_per_rad: .*at most 60\.1"):
        to_object(compose_config("body.toe=true", "body.toe_stiffness_nm_per_rad=100"))
    # the bound goes as 1 / dt^2: at 1 ms the same spring is fine, and without the toe it is never read
    assert to_object(compose_config("body.toe=true", "body.toe_stiffness_nm_per_rad=100", "env.physics_dt_s=0.001"))
    assert to_object(compose_config("body.toe_stiffness_nm_per_rad=100")).body.toe is False


# --------------------------------------------------------------------------- toe=true: the env


def test_env_steps_with_the_toe_and_its_spaces_do_not_change():
    env = PamWalkerEnv(body={"toe": True})
    obs, _ = env.reset(seed=0)
    assert obs.shape == (43,) and env.action_space.shape == (10,)
    assert env.observation_space.shape == PamWalkerEnv().observation_space.shape
    toe_qpos = {env.model.joint(n).qposadr[0] for n in body.TOE_JOINTS}
    assert not toe_qpos & set(env.qpos_idx.tolist())
    np.testing.assert_array_equal(obs[11:21], env.data.qpos[env.qpos_idx].astype(np.float32))
    obs, _, _, _, info = env.step(env.action_space.sample())
    assert obs.shape == (43,) and np.isfinite(obs).all() and not info["physics_error"]
    front = [env.model.geom(f"right_contact_front_{edge}").id for edge in ("left", "right")]
    np.testing.assert_array_equal(info["sole_xyz_m"][0, :2], env.data.geom_xpos[front])


def test_feet_carry_the_whole_weight_toe_included():
    env = PamWalkerEnv(body={"toe": True})
    env.reset(seed=0)
    for _ in range(40):  # 1 s
        _, _, _, _, info = env.step(np.zeros(10, dtype=np.float32))
    feet = info["foot_force_n"]
    assert feet.sum() == pytest.approx(env.weight_n, rel=0.02)
    sole = env.data.sensordata[env._foot_sensor_adr]
    toe = env.data.sensordata[env._toe_sensor_adr]
    np.testing.assert_array_equal(env.foot_forces_n(), sole + toe)
    assert (toe > 0).all()  # the toes touch, and are counted


def test_feet_sink_by_the_designed_overlap_on_heel_and_ball():
    cfg = BodyConfig(toe=True)
    model = body.build_model(cfg, timestep_s=DT)
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, model.key("stand").id)
    qpos, qvel = body.joint_addresses(model)
    for _ in range(600):
        d.ctrl[:] = -300 * d.qpos[qpos] - 5 * d.qvel[qvel]
        mujoco.mj_step(model, d)
    bearing = [model.geom(f"{side}_contact_{end}_{edge}").id for side in body.SIDES for end in ("back", "ball")
               for edge in ("left", "right")]
    sink = model.geom_size[bearing, 0] - d.geom_xpos[bearing, 2]
    assert sink.mean() == pytest.approx(cfg.contact_overlap_m, rel=0.2)
    assert d.sensordata.sum() == pytest.approx(model.body_subtreemass[0] * 9.81, rel=0.02)


@pytest.mark.parametrize("seed, noise", [(0, 0.0), (1, 0.02), (2, 0.02)])
def test_robot_stands_ten_seconds_with_zero_action_on_toes(seed, noise):
    heights = []
    for toe in (False, True):
        env = PamWalkerEnv(body={"toe": toe}, env={"reset_noise_rad": noise})
        env.reset(seed=seed)
        for _ in range(env.max_steps):
            _, _, terminated, truncated, info = env.step(np.zeros(10, dtype=np.float32))
            assert not terminated
        assert truncated and abs(info["x"]) < 0.1 and info["z"] > 0.95 * env.z0
        heights.append(info["z"])
    assert heights[1] == pytest.approx(heights[0], abs=0.005)


# --------------------------------------------------------------------------- capacity and pamrun body


def test_capacity_reports_the_toe():
    result = analyse(MuscleConfig(), TOE, n_angles=11)
    toe = result["toe"]
    assert toe["push_off"]["demand_nm"] == pytest.approx(MTP_PEAK_MOMENT_NM_PER_KG * 37.12, abs=1e-3)
    assert toe["push_off"]["within_range"]  # the default spring gives the human's peak at its 60 deg stop
    assert toe["tip_toe"]["demand_nm"] == pytest.approx(37.12 * 9.81 / 2 * toe["arm_m"], rel=1e-3)
    assert "toe" not in analyse(MuscleConfig(), BodyConfig(), n_angles=11)


def test_pamrun_body_describes_the_toe(tmp_path):
    out = tmp_path / "body"
    proc = run_pamrun("body", "body.toe=true", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr
    assert "Toe (body.toe)" in proc.stdout and "4.61 N m/rad" in proc.stdout
    segments = {row["segment"]: row for row in json.loads((out / "body.json").read_text())["segments"]}
    assert segments["toe"]["mass_kg"] == pytest.approx(0.138 * segments["foot"]["mass_kg"])
    assert 'name="left_toe"' in (out / "robot.xml").read_text()
