"""The robot and its muscles: body, pneumatic muscles, valve, air, hysteresis, and their coupling to the joints."""

import os

# MuJoCo picks its OpenGL backend when it is first imported: headless EGL unless the user chose one.
# Here, so that it is set before any module of this package imports mujoco.
os.environ.setdefault("MUJOCO_GL", "egl")
