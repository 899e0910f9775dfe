"""The ground ahead of the robot: a slope, a step or uneven ground (``env.slope_deg``,
``env.step_height_m``, ``env.rough_height_m``; all 0 = the flat floor plane alone, and then the
model has no geom more).

The robot starts on flat ground at z = 0 and the terrain begins ``env.terrain_x_m`` ahead,
across the path. The floor geometry itself is tilted or raised, never gravity, so the torso's
sensed tilt stays true. No seam between two geoms lies level under the feet: a foot sphere
sliding over one meets the next geom's edge and is caught (a 1 um step between two boxes cost
the shipped walker a quarter of its walk passes), so each ground is one smooth solid or meets
the next at a real edge or a concave crease.

* **Slope**: uphill, a slab on the floor plane whose top rises at ``slope_deg`` (+ uphill in
  the walking direction +x) from (``terrain_x_m``, 0), reaching back under the plane; downhill,
  one convex solid, flat at z = 0 to ``terrain_x_m`` and falling beyond, the plane below it.
* **Step**: up, a box on the floor plane from ``terrain_x_m`` on, ``step_height_m`` high; down
  (negative), a box with its top at z = 0 up to ``terrain_x_m``, the floor plane that far below.
* **Uneven ground**: spheres of radius 0.5 m buried in the floor plane on a 10 cm grid, 12 m
  long and 1.4 m wide, each top drawn uniformly in [0, 2 ``rough_height_m``] above the floor
  (smooth domes, the ground +-``rough_height_m`` about ``rough_height_m``); fixed per model (the
  draw's seed is :data:`ROUGH_SEED`), so every episode meets the same ground. A heightfield's
  prisms let the foot spheres sink through, and level tiles have seams.

:func:`ground_height_m` is the ground's height under a point, which the fall check measures the
torso's height from.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from pamrun.config import EnvConfig

LENGTH_M = 50.0  # how far the terrain reaches ahead of terrain_x_m
HALF_WIDTH_M = 2.0  # the terrain's half width (the env ends an episode at |y| > env.max_lateral_m)
START_BACK_M = 5.0  # how far the start box reaches behind the start
DEPTH_M = 0.5  # the start box's and the step's thickness below their tops
CELL_M = 0.1  # the uneven ground's grid (a foot spans about three)
DOME_RADIUS_M = 0.5  # its spheres' radius: between two, the ground dips 2.5-5 mm below their tops
ROUGH_LENGTH_M = 12.0  # the uneven ground's length (a 10 s episode walks about 10 m)
ROUGH_HALF_WIDTH_M = 0.7  # its half width (the env ends an episode at |y| > env.max_lateral_m, 0.5 m)
ROUGH_SEED = 0  # the uneven ground's draw


def has_terrain(env: EnvConfig) -> bool:
    """Whether ``env`` asks for ground other than the flat floor."""
    return bool(env.slope_deg or env.step_height_m or env.rough_height_m)


def ground_height_m(env: EnvConfig, x: float) -> float:
    """The ground's height [m] at ``x`` (forward, in the world) along the path; uneven ground's
    middle, ``rough_height_m``, over its length."""
    if x <= env.terrain_x_m:
        return 0.0
    if env.slope_deg:
        return (x - env.terrain_x_m) * math.tan(math.radians(env.slope_deg))
    if env.rough_height_m:
        return env.rough_height_m if x <= env.terrain_x_m + ROUGH_LENGTH_M else 0.0
    return env.step_height_m


def add_terrain(spec: mujoco.MjSpec, env: EnvConfig, friction: list[float]) -> None:
    """Add ``env``'s terrain to ``spec`` (whose ``floor`` plane is at z = 0), each geom with the
    floor's ``friction``; nothing where :func:`has_terrain` is false."""
    if not has_terrain(env):
        return
    world, x0 = spec.worldbody, env.terrain_x_m
    ground = {"contype": 1, "conaffinity": 1, "friction": friction, "material": "grid"}
    if env.slope_deg > 0:  # the floor plane stays: no seam under the feet before the slope
        _add_slope_up(world, env, ground)
        return
    if env.slope_deg < 0:
        _add_slope_down(spec, env, ground)
        spec.geom("floor").pos = [0, 0, -LENGTH_M * math.sin(math.radians(-env.slope_deg)) - 2 * DEPTH_M]
        return
    box = mujoco.mjtGeom.mjGEOM_BOX
    h = env.step_height_m
    if h > 0:  # a box on the floor plane
        world.add_geom(name="step", type=box, pos=[x0 + LENGTH_M / 2, 0, h - DEPTH_M],
                       size=[LENGTH_M / 2, HALF_WIDTH_M, DEPTH_M], **ground)
        return
    if env.rough_height_m:  # spheres on the floor plane
        _add_rough(spec, env, ground)
        return
    world.add_geom(name="start_ground", type=box, pos=[(x0 - START_BACK_M) / 2, 0, -DEPTH_M],
                   size=[(x0 + START_BACK_M) / 2, HALF_WIDTH_M, DEPTH_M], **ground)
    spec.geom("floor").pos = [0, 0, h]  # the ground beyond the step down


def _add_slope_up(world, env: EnvConfig, ground: dict) -> None:
    """A slab on the floor plane whose top rises at ``slope_deg`` from (``terrain_x_m``, z = 0); it
    reaches 1 m further back under the plane, so a foot meets no edge where the slope begins."""
    angle, back = math.radians(env.slope_deg), 1.0
    length = LENGTH_M + back
    # the slab's top face passes through (x0, 0), rotated by -angle about y so +x rises
    along = length / 2 - back
    centre = [env.terrain_x_m + along * math.cos(angle) + DEPTH_M * math.sin(angle), 0,
              along * math.sin(angle) - DEPTH_M * math.cos(angle)]
    world.add_geom(name="slope", type=mujoco.mjtGeom.mjGEOM_BOX, pos=centre, size=[length / 2, HALF_WIDTH_M, DEPTH_M],
                   quat=[math.cos(-angle / 2), 0, math.sin(-angle / 2), 0], **ground)


def _add_slope_down(spec: mujoco.MjSpec, env: EnvConfig, ground: dict) -> None:
    """One convex solid (a mesh) whose top is flat at z = 0 up to ``terrain_x_m`` and falls at
    ``slope_deg`` beyond: the ridge is one body's edge, so no seam lies under the feet."""
    angle, x0 = math.radians(-env.slope_deg), env.terrain_x_m
    x1, z1 = x0 + LENGTH_M * math.cos(angle), -LENGTH_M * math.sin(angle)
    bottom = z1 - DEPTH_M
    profile = [(-START_BACK_M, 0.0), (x0, 0.0), (x1, z1), (x1, bottom), (-START_BACK_M, bottom)]
    vertices = [[x, y, z] for x, z in profile for y in (-HALF_WIDTH_M, HALF_WIDTH_M)]
    spec.add_mesh(name="slope", uservert=np.ravel(vertices).tolist())
    spec.worldbody.add_geom(name="slope", type=mujoco.mjtGeom.mjGEOM_MESH, meshname="slope", **ground)


def _add_rough(spec: mujoco.MjSpec, env: EnvConfig, ground: dict) -> None:
    """The uneven ground: buried spheres on a ``CELL_M`` grid from ``terrain_x_m``,
    ``ROUGH_LENGTH_M`` long and ``ROUGH_HALF_WIDTH_M`` each side, each sphere's top drawn
    uniformly in [0, 2 ``rough_height_m``] above the floor plane."""
    h, x0 = env.rough_height_m, env.terrain_x_m
    nx, ny = int(round(ROUGH_LENGTH_M / CELL_M)), int(round(2 * ROUGH_HALF_WIDTH_M / CELL_M))
    tops = np.random.default_rng(ROUGH_SEED).uniform(0.0, 2 * h, (nx, ny))
    for i, j in np.ndindex(nx, ny):
        spec.worldbody.add_geom(name=f"rough_{i}_{j}", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[DOME_RADIUS_M, 0, 0],
                                pos=[x0 + (i + 0.5) * CELL_M, -ROUGH_HALF_WIDTH_M + (j + 0.5) * CELL_M,
                                     tops[i, j] - DOME_RADIUS_M], **ground)
