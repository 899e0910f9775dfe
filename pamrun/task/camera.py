"""The cameras PamWalker-v0 renders from (its keyword argument ``camera``; ``pamrun eval``'s ``eval.camera``).

* ``follow`` (default): side-on from the robot's right, so it walks left to right in the picture,
  slightly from above; the aim follows the torso's x and y every frame at a steady height (the
  floor does not bob with the torso), at a distance in proportion to body height, so the robot
  fills about 60 % of the picture's height whatever its size and however far it walks.
* ``fixed``: the same view, aimed where the torso starts (the standing keyframe's x and y), never
  moving: the robot walks out of the picture to the right after about a metre.
* ``three_quarter``: the model's own camera (:data:`pamrun.physics.body.CAMERA`), a three-quarter
  view from the front right that keeps its offset from the robot's centre of mass.
"""

from __future__ import annotations

import os

# Rendering headless: MuJoCo reads MUJOCO_GL when it is first imported, so it is set before.
os.environ.setdefault("MUJOCO_GL", "egl")
import mujoco
import numpy as np

from pamrun.config import CAMERAS
from pamrun.physics import body as body_mod

AZIMUTH_DEG = 90.0  # looking along +y, at the robot's right side: forward (+x) is to the right
ELEVATION_DEG = -8.0  # slightly from above
DISTANCE_PER_HEIGHT = 1.2  # the camera's distance from its aim, per metre of body height
AIM_PER_HEIGHT = 0.32  # the aim's height above the floor per metre of body height: mid-robot (legs 0.53 H, pelvis 0.1 H)


class Camera:
    """One of :data:`pamrun.config.CAMERAS` for a model of a robot ``height_m`` tall; ValueError for
    another name. Plain numbers only (MuJoCo's MjvCamera does not pickle; the env does)."""

    def __init__(self, name: str, model: mujoco.MjModel, height_m: float):
        if name not in CAMERAS:
            raise ValueError(f"camera must be one of {', '.join(CAMERAS)}, got {name!r}")
        self.name, self.distance_m = name, DISTANCE_PER_HEIGHT * height_m
        self._torso = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body_mod.TORSO)
        self.lookat = np.array([*model.body_pos[self._torso, :2], AIM_PER_HEIGHT * height_m])  # where the torso starts

    def update_scene(self, renderer: mujoco.Renderer, data: mujoco.MjData) -> None:
        """``renderer``'s scene of ``data`` from this camera; ``follow`` aims at the torso first."""
        if self.name == "three_quarter":
            renderer.update_scene(data, camera=body_mod.CAMERA)
            return
        if self.name == "follow":
            self.lookat[:2] = data.xpos[self._torso, :2]  # the torso as drawn (xpos: the drawn poses)
        view = mujoco.MjvCamera()
        view.type = mujoco.mjtCamera.mjCAMERA_FREE
        view.azimuth, view.elevation, view.distance = AZIMUTH_DEG, ELEVATION_DEG, self.distance_m
        view.lookat[:] = self.lookat
        renderer.update_scene(data, camera=view)
