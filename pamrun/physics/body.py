"""The robot's body: anthropometry from height and mass, and its MuJoCo model (thesis §8.1-8.2).

Every segment follows from body height H and mass M by the thesis' ratios (Table 8.2).
What the thesis leaves open, and what we chose:

* **Pelvis/torso block** (the free-floating base): mass 0.142 M, the pelvis segment of
  Winter, *Biomechanics and Motor Control of Human Movement* (4th ed., 2009), Table 4.1;
  width 0.191 H, the hip width of Drillis & Contini's segment-length ratios (in Winter,
  Fig. 4.1); depth and height 0.1 H. Hip joint centres 0.1 H apart. All in ``BodyConfig``.
* **Inertia**: the thesis gives one scalar I0 = m ro^2 per segment; we use it about both
  axes across the segment and a solid box's m (a^2 + b^2) / 12 about its long axis.
* **Foot-ground contact** (§8.1): four spheres per foot at the sole's corners, the only
  geoms that collide (with the floor). The thesis sets stiffness = weight / desired
  overlap and damping = stiffness / 10. MuJoCo's direct (negative) ``solref`` is a
  reference acceleration per metre, not N/m: a resting contact row satisfies
  R f = K I r (regulariser R, stiffness K, impedance I from ``efc_KBIP``, row force f,
  penetration r). :func:`match_contact_overlap` evaluates R, K and I at the standing
  pose with one ``mj_forward``, shares the robot's weight over the contact rows, and
  scales every foot sphere's solref so the standing robot sinks by exactly the designed
  overlap; the damping keeps the thesis' ratio, b = 0.1 s * k. MuJoCo has one sliding
  friction coefficient: we use the static 0.5; the thesis' dynamic coefficient and
  critical velocity have no counterpart.
* **Joint limits** (Table 8.3; right leg mirrors the roll joints). The thesis' Simscape
  stop is a linear spring-damper (1e4 N m/rad, 10 N m s/rad). MuJoCo's soft constraint
  cannot be one: with impedance d the joint obeys r'' = -d (K I r + B r') + (1 - d) tau / I,
  so its static stiffness (K I / R) and its stiffness against an impact (d K I times the
  inertia) differ by a factor ~(1 - d), and no solref gives both. Matching the static value
  would leave the hip limits ~20x too soft in motion (a swinging leg would pass its stop by ~13 deg).
  We use MuJoCo's own stiff, critically damped stop, ``solref = (timeconst, dampratio)``
  = (0.005 s, 1) from ``BodyConfig``, which holds every limit within a degree or two.
* Joint damping 1 N m s/rad, stiffness 0 (Table 8.2); one torque motor per hinge; a
  touch sensor under each sole gives the normal ground force (``FOOT_SENSORS``).
* **A passive toe** (``body.toe``, thesis §13 "future work"; off by default, and then the
  model is exactly the one-piece foot above). The foot's front ``toe_length_ratio`` becomes
  a toe, hinged about the lateral axis at the metatarsal line, level with the contact
  spheres' centres, held flat by MuJoCo's joint spring and damper
  (``toe_stiffness_nm_per_rad``, ``toe_damping_nms_per_rad``) within ``toe_range_deg``: no
  muscle, no actuator, no action, so the action and observation spaces do not change. It
  takes ``toe_mass_ratio`` of the foot's mass; the rear foot keeps the rest, placed so the two
  keep the foot's centre of mass, and the foot's radii of gyration. The foot's ``front``
  contact spheres move to the toe's tip (their names unchanged) and the rear foot gets two
  spheres at the metatarsal line, ``{side}_contact_ball_{edge}``: the foot stands on heel and
  ball, as a foot does, and rolls over the toe as the heel rises. A second touch sensor per
  foot (``TOE_SENSORS``) reads the toe; the env adds it to its foot's. The toe hinges
  (``TOE_JOINTS``) are not ``JOINTS``: read joints by name (:func:`joint_addresses`).

Axes: x forward, y left, z up; hinge angles follow the right-hand rule, so knee flexion
and hip extension are positive pitch, and the left hip abducts with positive roll.
All joints at 0 is the standing pose: legs straight down, soles flat on the floor.
"""

from __future__ import annotations

import math

import mujoco  # its GL backend is chosen by pamrun.physics (MUJOCO_GL), imported first
import numpy as np

from pamrun.config import LEG_JOINTS, BodyConfig, EnvConfig  # LEG_JOINTS: one leg's hinges, their one home
from pamrun.config.robot import (
    FOOT_HEIGHT_RATIO,
    FOOT_LENGTH_RATIO,
    FOOT_MASS_RATIO,
    FOOT_WIDTH_RATIO,
)
from pamrun.physics.terrain import add_terrain

SIDES = ("right", "left")
JOINTS = tuple(f"{side}_{joint}" for side in SIDES for joint in LEG_JOINTS)  # every hinge, right leg first
TORSO = "torso"
FEET = ("right_foot", "left_foot")
FOOT_SENSORS = ("right_foot_force", "left_foot_force")
# A foot's four contact spheres at its sole's corners, ``{side}_contact_{end}_{edge}``, in the order
# the env reads their centres (sole_xyz_m): front left, front right, back left, back right.
SOLE_CORNERS = tuple((end, edge) for end in ("front", "back") for edge in ("left", "right"))
# body.toe: the passive toe hinges (not JOINTS: no muscle, no action) and the touch sensors under
# the toes; a foot's normal ground force is its FOOT_SENSORS value plus its TOE_SENSORS value.
TOE_JOINTS = ("right_toe", "left_toe")  # each hinged to its body of the same name
TOE_SENSORS = ("right_toe_force", "left_toe_force")
CAMERA = "track"
GRAVITY = 9.81
IMPEDANCE = 0.95  # constant solimp d of contacts and limits (MuJoCo's default range is 0.9-0.95)
SPHERE_RADIUS_RATIO = 0.006  # contact sphere radius / H (about 1 cm)
FIXED_TORSO_LIFT_M = 0.3  # how far the torso is raised for open-loop tests
_NO_COLLIDE = {"contype": 0, "conaffinity": 0}  # visual geoms: only the foot spheres collide


def anthropometry(cfg: BodyConfig) -> dict[str, dict[str, float]]:
    """Every segment's size [m], mass [kg], CoM [m], radius of gyration [m], inertia [kg m^2].

    Thesis §8.2 / Table 8.2 ratios; the pelvis block is ours (module docstring).
    ``com_m`` of a leg segment is measured from its geometric centre towards the proximal
    joint; the foot's ``offset_m`` is how far the ankle sits behind the foot's centre.
    """
    h, m = cfg.height_m, cfg.mass_kg
    foot_x, foot_y, foot_z = FOOT_LENGTH_RATIO * h, FOOT_WIDTH_RATIO * h, FOOT_HEIGHT_RATIO * h
    foot_offset = 0.0569 * h / 1.80  # -0.0569 m at H = 1.80 m, scaled with height
    foot_ro = math.hypot(foot_offset, foot_z / 2)
    lower_len = 0.285 * h - foot_z
    upper_len = 0.530 * h - lower_len - foot_z
    foot_mass, lower_mass, upper_mass = FOOT_MASS_RATIO * m, 0.0465 * m, 0.1 * m
    seg = {
        "foot": {
            "x_m": foot_x, "y_m": foot_y, "z_m": foot_z, "mass_kg": foot_mass,
            "com_m": foot_z / 2, "offset_m": foot_offset,
            "radius_gyration_m": foot_ro, "inertia_kgm2": foot_mass * foot_ro**2,
        },
        "lower_leg": {
            "x_m": 0.0444 * h, "y_m": 0.0444 * h, "z_m": lower_len, "mass_kg": lower_mass,
            "com_m": 0.567 * lower_len - lower_len / 2,
            "radius_gyration_m": 0.302 * lower_len, "inertia_kgm2": lower_mass * (0.302 * lower_len) ** 2,
        },
        "upper_leg": {
            "x_m": 0.0833 * h, "y_m": 0.0666 * h, "z_m": upper_len, "mass_kg": upper_mass,
            "com_m": 0.567 * upper_len - upper_len / 2,
            "radius_gyration_m": 0.323 * upper_len, "inertia_kgm2": upper_mass * (0.323 * upper_len) ** 2,
        },
        "pelvis": {
            "x_m": cfg.pelvis_depth_ratio * h, "y_m": cfg.pelvis_width_ratio * h, "z_m": cfg.pelvis_height_ratio * h,
            "mass_kg": cfg.pelvis_mass_ratio * m, "com_m": 0.0,
            "hip_width_m": cfg.hip_width_ratio * h,
        },
    }
    if cfg.toe:
        seg["toe"] = _toe_segment(cfg, seg["foot"])
    return seg


def _toe_segment(cfg: BodyConfig, foot: dict[str, float]) -> dict[str, float]:
    """``body.toe``: the toe box (BodyConfig.toe_box_m), its mass, CoM (its centre), radius of
    gyration and inertia about its centre across it, and where its hinge sits in the foot's
    frame (``hinge_x_m`` ahead of the ankle, at the metatarsal line; ``hinge_z_m``, at the height
    of the contact spheres' centres) with the toe's inertia about it (``hinge_inertia_kgm2``)."""
    length, width, height = cfg.toe_box_m()
    mass = cfg.toe_mass_kg()
    r_sphere = SPHERE_RADIUS_RATIO * cfg.height_m
    inertia = mass * (length**2 + height**2) / 12
    com_above_hinge = height / 2 - r_sphere  # the toe's bottom is the sole, r below the hinge
    return {
        "x_m": length, "y_m": width, "z_m": height, "mass_kg": mass, "com_m": 0.0,
        "radius_gyration_m": math.sqrt(inertia / mass), "inertia_kgm2": inertia,
        "hinge_x_m": foot["offset_m"] + foot["x_m"] / 2 - length, "hinge_z_m": -foot["z_m"] + r_sphere,
        "com_above_hinge_m": com_above_hinge,
        "hinge_inertia_kgm2": inertia + mass * ((length / 2) ** 2 + com_above_hinge**2),
    }


def segment_table(cfg: BodyConfig) -> list[dict[str, float | str]]:
    """Rows for printing and body.json: one per segment, both legs summed at the end."""
    seg = anthropometry(cfg)
    rows: list[dict[str, float | str]] = []
    for name, s in seg.items():
        rows.append({
            "segment": name, "x_m": s["x_m"], "y_m": s["y_m"], "z_m": s["z_m"], "mass_kg": s["mass_kg"],
            "com_m": s["com_m"], "radius_gyration_m": s.get("radius_gyration_m", float("nan")),
            "inertia_kgm2": s.get("inertia_kgm2", float("nan")),
        })
    legs = 2 * sum(seg[k]["mass_kg"] for k in ("foot", "lower_leg", "upper_leg"))
    rows.append({"segment": "both legs", "x_m": float("nan"), "y_m": float("nan"), "z_m": float("nan"),
                 "mass_kg": legs, "com_m": float("nan"), "radius_gyration_m": float("nan"),
                 "inertia_kgm2": float("nan")})
    return rows


def mirror_sign(side: str, joint: str) -> float:
    """-1 where the right leg mirrors the left (its roll joints, Table 8.3), else +1."""
    return -1.0 if side == "right" and joint.endswith("roll") else 1.0


def joint_limits_deg(cfg: BodyConfig, side: str) -> dict[str, tuple[float, float]]:
    """Limits [deg] of one leg's joints; the right leg mirrors the roll joints (Table 8.3)."""
    out = {}
    for joint in LEG_JOINTS:
        lo, hi = getattr(cfg, f"{joint}_limits_deg")
        out[joint] = (-hi, -lo) if mirror_sign(side, joint) < 0 else (lo, hi)
    return out


def joint_addresses(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the JOINTS' angles in ``qpos`` and velocities in ``qvel``, JOINTS order."""
    ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name) for name in JOINTS]
    return np.array([model.jnt_qposadr[j] for j in ids]), np.array([model.jnt_dofadr[j] for j in ids])


def standing_height_m(cfg: BodyConfig) -> float:
    """Torso (pelvis block centre) height [m] with straight legs and soles on the floor."""
    seg = anthropometry(cfg)
    return seg["foot"]["z_m"] + seg["lower_leg"]["z_m"] + seg["upper_leg"]["z_m"] + seg["pelvis"]["z_m"] / 2


def _inertia(mass: float, i0: float, a: float, b: float) -> list[float]:
    """Diagonal inertia: I0 about the two axes across the segment, box about its long one."""
    return [i0, i0, mass * (a**2 + b**2) / 12]


def _box_inertia(mass: float, x: float, y: float, z: float) -> list[float]:
    return [mass * (y * y + z * z) / 12, mass * (x * x + z * z) / 12, mass * (x * x + y * y) / 12]


def _add_hinge(body, name: str, axis: list[float], limits_deg: tuple[float, float], cfg: BodyConfig) -> None:
    body.add_joint(
        name=name,
        type=mujoco.mjtJoint.mjJNT_HINGE,
        axis=axis,
        range=[math.radians(limits_deg[0]), math.radians(limits_deg[1])],
        limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        damping=cfg.joint_damping_nms_per_rad,
        stiffness=cfg.joint_stiffness_nm_per_rad,
        solref_limit=[cfg.joint_limit_timeconst_s, cfg.joint_limit_dampratio],
    )


def _add_leg(torso, side: str, sign: float, cfg: BodyConfig) -> None:
    """One leg under the torso (``sign``: -1 right, +1 left): thigh (hip pitch and roll), shin
    (knee), foot (ankle pitch and roll, :func:`_add_foot`), their visual boxes, sizes from
    :func:`anthropometry`."""
    seg = anthropometry(cfg)
    lower, upper, pelvis = seg["lower_leg"], seg["upper_leg"], seg["pelvis"]
    lim = joint_limits_deg(cfg, side)
    thigh = torso.add_body(name=f"{side}_thigh", pos=[0, sign * pelvis["hip_width_m"] / 2, -pelvis["z_m"] / 2],
                           mass=upper["mass_kg"], ipos=[0, 0, -upper["z_m"] / 2 + upper["com_m"]],
                           inertia=_inertia(upper["mass_kg"], upper["inertia_kgm2"], upper["x_m"], upper["y_m"]))
    _add_hinge(thigh, f"{side}_hip_pitch", [0, 1, 0], lim["hip_pitch"], cfg)
    _add_hinge(thigh, f"{side}_hip_roll", [1, 0, 0], lim["hip_roll"], cfg)
    thigh.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0, 0, -upper["z_m"] / 2], mass=0,
                   size=[upper["x_m"] / 2, upper["y_m"] / 2, upper["z_m"] / 2], rgba=[0.8, 0.5, 0.3, 1],
                   **_NO_COLLIDE)
    shin = thigh.add_body(name=f"{side}_shin", pos=[0, 0, -upper["z_m"]], mass=lower["mass_kg"],
                          ipos=[0, 0, -lower["z_m"] / 2 + lower["com_m"]],
                          inertia=_inertia(lower["mass_kg"], lower["inertia_kgm2"], lower["x_m"], lower["y_m"]))
    _add_hinge(shin, f"{side}_knee", [0, 1, 0], lim["knee"], cfg)
    shin.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0, 0, -lower["z_m"] / 2], mass=0,
                  size=[lower["x_m"] / 2, lower["y_m"] / 2, lower["z_m"] / 2], rgba=[0.85, 0.6, 0.4, 1],
                  **_NO_COLLIDE)
    _add_foot(shin, side, cfg, seg, lim)


def _add_sphere(body, name: str, pos: list[float], r_sphere: float, cfg: BodyConfig) -> None:
    """A contact sphere: the only geoms that collide (with the floor), §8.1."""
    body.add_geom(
        name=name, type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[r_sphere, 0, 0], mass=0, pos=pos,
        contype=2, conaffinity=1, condim=3, rgba=[0.9, 0.2, 0.2, 1],
        friction=[cfg.friction_static, 0.005, 0.0001],
        solref=list(contact_solref(cfg)), solimp=[IMPEDANCE, IMPEDANCE, 0.001, 0.5, 2.0],
    )


def _add_foot(shin, side: str, cfg: BodyConfig, seg: dict, lim: dict) -> None:
    """The foot under the shin: ankle pitch and roll, its visual box, the sole's touch site and
    four contact spheres at the sole's corners (§8.1). With ``body.toe`` the foot ends at the
    metatarsal line: its mass less the toe's (the two together keep the foot's centre of mass),
    its front spheres there (the ball of the foot, ``{side}_contact_ball_*``), and the toe
    (:func:`_add_toe`) carries the ``front`` ones at the tip."""
    foot, lower = seg["foot"], seg["lower_leg"]
    r_sphere = SPHERE_RADIUS_RATIO * cfg.height_m
    foot_centre = [foot["offset_m"], 0, -foot["z_m"] / 2]
    inertia = [foot["inertia_kgm2"], foot["inertia_kgm2"], foot["mass_kg"] * (foot["x_m"] ** 2 + foot["y_m"] ** 2) / 12]
    mass, ipos, length, centre = foot["mass_kg"], foot_centre, foot["x_m"], foot_centre
    if cfg.toe:  # the rear foot: heel to the metatarsal line
        toe = seg["toe"]
        mass = foot["mass_kg"] - toe["mass_kg"]
        toe_com = np.array([toe["hinge_x_m"] + toe["x_m"] / 2, 0.0, toe["hinge_z_m"] + toe["com_above_hinge_m"]])
        ipos = ((foot["mass_kg"] * np.array(foot_centre) - toe["mass_kg"] * toe_com) / mass).tolist()
        inertia = [i * mass / foot["mass_kg"] for i in inertia]  # the foot's radii of gyration
        length = foot["x_m"] - toe["x_m"]
        centre = [toe["hinge_x_m"] - length / 2, 0, -foot["z_m"] / 2]
    foot_body = shin.add_body(name=f"{side}_foot", pos=[0, 0, -lower["z_m"]], mass=mass, ipos=ipos, inertia=inertia)
    _add_hinge(foot_body, f"{side}_ankle_pitch", [0, 1, 0], lim["ankle_pitch"], cfg)
    _add_hinge(foot_body, f"{side}_ankle_roll", [1, 0, 0], lim["ankle_roll"], cfg)
    foot_body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, pos=centre, mass=0,
                       size=[length / 2, foot["y_m"] / 2, foot["z_m"] / 2], rgba=[0.3, 0.3, 0.3, 1],
                       **_NO_COLLIDE)
    # Touch sensor: sum of normal contact forces [N] in a box around the sole (this body's contacts only).
    foot_body.add_site(name=f"{side}_sole", type=mujoco.mjtGeom.mjGEOM_BOX, pos=centre,
                       size=[length / 2 + r_sphere, foot["y_m"] / 2 + r_sphere, foot["z_m"] / 2 + 0.02],
                       rgba=[0, 0, 0, 0])
    for cx in (-1, 1):
        for cy in (-1, 1):
            edge = "left" if cy > 0 else "right"
            if cfg.toe and cx > 0:
                name, x = f"{side}_contact_ball_{edge}", seg["toe"]["hinge_x_m"] - r_sphere
            else:
                name, x = (f"{side}_contact_{'front' if cx > 0 else 'back'}_{edge}",
                           foot["offset_m"] + cx * (foot["x_m"] / 2 - r_sphere))
            _add_sphere(foot_body, name, [x, cy * (foot["y_m"] / 2 - r_sphere), -foot["z_m"] + r_sphere], r_sphere, cfg)
    if cfg.toe:
        _add_toe(foot_body, side, cfg, seg["toe"], r_sphere)


def _add_toe(foot_body, side: str, cfg: BodyConfig, toe: dict[str, float], r_sphere: float) -> None:
    """``body.toe``: the toe, hinged to the foot about the lateral axis at the metatarsal line,
    level with the contact spheres' centres. A passive joint: MuJoCo's joint spring
    (``toe_stiffness_nm_per_rad``, 0 = flat) and damping, within ``toe_range_deg``; no actuator.
    Its touch site (``{side}_toe_sole``, read by ``{side}_toe_force``) and the foot's front
    contact spheres (``{side}_contact_front_*``), at the toe's tip."""
    length, width, height = toe["x_m"], toe["y_m"], toe["z_m"]
    centre = [length / 2, 0, toe["com_above_hinge_m"]]
    body = foot_body.add_body(name=f"{side}_toe", pos=[toe["hinge_x_m"], 0, toe["hinge_z_m"]], mass=toe["mass_kg"],
                              ipos=centre, inertia=_box_inertia(toe["mass_kg"], length, width, height))
    lo, hi = cfg.toe_range_deg
    body.add_joint(name=f"{side}_toe", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0],
                   range=[math.radians(lo), math.radians(hi)], limited=mujoco.mjtLimited.mjLIMITED_TRUE,
                   damping=cfg.toe_damping_nms_per_rad, stiffness=cfg.toe_stiffness_nm_per_rad,
                   solref_limit=[cfg.joint_limit_timeconst_s, cfg.joint_limit_dampratio])
    body.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, pos=centre, mass=0, size=[length / 2, width / 2, height / 2],
                  rgba=[0.45, 0.45, 0.45, 1], **_NO_COLLIDE)
    body.add_site(name=f"{side}_toe_sole", type=mujoco.mjtGeom.mjGEOM_BOX, pos=centre,
                  size=[length / 2 + r_sphere, width / 2 + r_sphere, height / 2 + 0.02], rgba=[0, 0, 0, 0])
    for cy in (-1, 1):
        _add_sphere(body, f"{side}_contact_front_{'left' if cy > 0 else 'right'}",
                    [length - r_sphere, cy * (width / 2 - r_sphere), 0.0], r_sphere, cfg)


def _add_scene(spec: mujoco.MjSpec, cfg: BodyConfig) -> None:
    """The floor (a checkered plane with the feet's friction), the sky and a light from above."""
    tex = spec.add_texture(name="grid", type=mujoco.mjtTexture.mjTEXTURE_2D,
                           builtin=mujoco.mjtBuiltin.mjBUILTIN_CHECKER, width=512, height=512,
                           rgb1=[0.82, 0.84, 0.86], rgb2=[0.62, 0.65, 0.68])
    spec.add_texture(name="sky", type=mujoco.mjtTexture.mjTEXTURE_SKYBOX, builtin=mujoco.mjtBuiltin.mjBUILTIN_GRADIENT,
                     width=256, height=256, rgb1=[0.55, 0.7, 0.85], rgb2=[0.95, 0.97, 1.0])
    mat = spec.add_material(name="grid", texrepeat=[8, 8], reflectance=0.1)
    mat.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tex.name
    world = spec.worldbody
    world.add_light(pos=[0, 0, 4], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL,
                    diffuse=[0.8, 0.8, 0.8])
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[0, 0, 0.05], material="grid",
                   contype=1, conaffinity=1, friction=[cfg.friction_static, 0.005, 0.0001])


def _add_camera(torso: mujoco.MjsBody, cfg: BodyConfig) -> None:
    """The tracking camera: a three-quarter view from the front right, aimed at mid-leg height."""
    scale = cfg.height_m / 1.80
    offset = np.array([1.9, -2.4, 0.5]) * scale
    aim = np.array([0.0, 0.0, -0.45]) * scale
    fwd = (aim - offset) / np.linalg.norm(aim - offset)
    right = np.cross(fwd, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    torso.add_camera(name=CAMERA, pos=offset.tolist(), mode=mujoco.mjtCamLight.mjCAMLIGHT_TRACKCOM,
                     xyaxes=[*right, *up], fovy=45)


def build_spec(cfg: BodyConfig, timestep_s: float = 0.005, fixed_torso: bool = False,
               env: EnvConfig | None = None) -> mujoco.MjSpec:
    """The robot as an MjSpec (no XML by hand). ``fixed_torso`` welds the torso in the air;
    ``env``'s terrain, if any, lies ahead (:mod:`pamrun.physics.terrain`)."""
    pelvis = anthropometry(cfg)["pelvis"]
    spec = mujoco.MjSpec()
    spec.modelname = "pamwalker"
    spec.compiler.degree = False  # every angle below is in radians
    spec.option.timestep = timestep_s
    spec.option.gravity = [0, 0, -GRAVITY]
    spec.visual.global_.offwidth = 1280
    spec.visual.global_.offheight = 960

    _add_scene(spec, cfg)
    if env is not None:
        add_terrain(spec, env, [cfg.friction_static, 0.005, 0.0001])

    z_torso = standing_height_m(cfg) + (FIXED_TORSO_LIFT_M if fixed_torso else 0.0)
    # ipos must be given: MjSpec's default (NaN) leaves the compiler to place the centre of
    # mass at the body's pos again, i.e. twice the standing height above the floor.
    inertia = _box_inertia(pelvis["mass_kg"], pelvis["x_m"], pelvis["y_m"], pelvis["z_m"])
    torso = spec.worldbody.add_body(name=TORSO, pos=[0, 0, z_torso], mass=pelvis["mass_kg"], ipos=[0, 0, 0],
                                    inertia=inertia)
    if not fixed_torso:
        torso.add_freejoint(name="root")
    torso.add_geom(type=mujoco.mjtGeom.mjGEOM_BOX, size=[pelvis["x_m"] / 2, pelvis["y_m"] / 2, pelvis["z_m"] / 2],
                   rgba=[0.25, 0.35, 0.6, 1], mass=0, **_NO_COLLIDE)

    _add_camera(torso, cfg)
    for side, sign in (("right", -1.0), ("left", 1.0)):
        _add_leg(torso, side, sign, cfg)
    for side in SIDES:
        spec.add_sensor(name=f"{side}_foot_force", type=mujoco.mjtSensor.mjSENS_TOUCH,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=f"{side}_sole")
    for side in SIDES if cfg.toe else ():  # after FOOT_SENSORS: their addresses stay 0 and 1
        spec.add_sensor(name=f"{side}_toe_force", type=mujoco.mjtSensor.mjSENS_TOUCH,
                        objtype=mujoco.mjtObj.mjOBJ_SITE, objname=f"{side}_toe_sole")
    for joint in JOINTS:
        # Torque = ctrl + biasprm[1] q + biasprm[2] q' (affine bias: the muscle drive sets a
        # linearised pair there, see pamrun.physics.actuation.MuscleDrive.apply; 0 = a plain motor).
        spec.add_actuator(name=joint, target=joint, trntype=mujoco.mjtTrn.mjTRN_JOINT, gear=[1, 0, 0, 0, 0, 0],
                          ctrllimited=mujoco.mjtLimited.mjLIMITED_FALSE, biastype=mujoco.mjtBias.mjBIAS_AFFINE)
    if not fixed_torso:
        hinges = len(JOINTS) + (len(TOE_JOINTS) if cfg.toe else 0)
        spec.add_key(name="stand", qpos=[0, 0, z_torso, 1, 0, 0, 0] + [0.0] * hinges)
    return spec


def contact_solref(cfg: BodyConfig) -> tuple[float, float]:
    """First-guess direct solref (single-contact formula); :func:`match_contact_overlap` corrects it."""
    k = (1 - IMPEDANCE) * GRAVITY / (IMPEDANCE * cfg.contact_overlap_m)
    return -k, -cfg.contact_damping_ratio * k


def match_contact_overlap(model: mujoco.MjModel, cfg: BodyConfig) -> float:
    """Scale the foot spheres' solref so the standing robot sinks by ``contact_overlap_m``.

    At rest each contact row satisfies R f = K I r. With the weight W shared evenly over
    the n pyramid rows (f = W / n), the mean penetration is mean(R / (K I)) W / n; K is
    proportional to the solref stiffness, so one scale factor gives the designed overlap.
    With ``body.toe`` the toes' rows are left out: held by a soft spring, a toe bears little.
    Returns that factor.
    """
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "stand")
    if key < 0:  # torso fixed in the air: no standing contact to match
        return 1.0
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, key)
    data.qpos[2] -= cfg.contact_overlap_m  # evaluate R, K, I at the designed penetration
    mujoco.mj_forward(model, data)
    rows = data.efc_type[: data.nefc] == mujoco.mjtConstraint.mjCNSTR_CONTACT_PYRAMIDAL
    toes = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name) for name in TOE_JOINTS]
    if min(toes) >= 0:  # body.toe: its soft spring bears little; heel and ball share the weight
        geoms = data.contact.geom[data.efc_id[: data.nefc]]
        rows &= ~np.isin(model.geom_bodyid[geoms], toes).any(axis=1)
    r_reg, kbip = data.efc_R[: data.nefc][rows], data.efc_KBIP[: data.nefc][rows]
    weight = model.body_subtreemass[0] * -model.opt.gravity[2]
    predicted = np.mean(r_reg / (kbip[:, 0] * kbip[:, 2])) * weight / rows.sum()
    scale = predicted / cfg.contact_overlap_m
    spheres = model.geom_type == mujoco.mjtGeom.mjGEOM_SPHERE
    model.geom_solref[spheres] *= scale
    return float(scale)


def build_model(cfg: BodyConfig, timestep_s: float = 0.005, fixed_torso: bool = False,
                env: EnvConfig | None = None) -> mujoco.MjModel:
    """Compiled model whose foot contacts sink by the designed overlap (:func:`match_contact_overlap`),
    with ``env``'s terrain, if any (:func:`build_spec`)."""
    model = build_spec(cfg, timestep_s, fixed_torso, env).compile()
    match_contact_overlap(model, cfg)
    return model


def build_fixed_model(cfg: BodyConfig, timestep_s: float = 0.005) -> mujoco.MjModel:
    """The robot with its torso welded in the air, legs hanging (open-loop tests, §10.2)."""
    return build_model(cfg, timestep_s, fixed_torso=True)


def render_standing(model: mujoco.MjModel, width: int = 640, height: int = 480) -> np.ndarray:
    """RGB image (height, width, 3) of the robot in its standing pose, offscreen."""
    data = mujoco.MjData(model)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "stand")
    if key >= 0:
        mujoco.mj_resetDataKeyframe(model, data, key)
    mujoco.mj_forward(model, data)
    with mujoco.Renderer(model, height, width) as renderer:
        renderer.update_scene(data, camera=CAMERA)
        return renderer.render().copy()
