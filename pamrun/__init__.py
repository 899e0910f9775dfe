"""pamrun: learning to control robots driven by pneumatic artificial muscles.

Importing the package registers ``pamrun/PamWalker-v0`` with Gymnasium; nothing else.
"""

from gymnasium.envs.registration import register

__version__ = "0.1.0"

register(id="pamrun/PamWalker-v0", entry_point="pamrun.task.env:PamWalkerEnv", max_episode_steps=None)
