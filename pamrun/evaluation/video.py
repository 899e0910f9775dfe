"""The best agent's episode as a video: an H.264 mp4 rendered from the tracking camera."""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np

from pamrun.evaluation.episodes import make_policy, run_episode, torch_threads
from pamrun.learning.checkpoints import Agent
from pamrun.task.spec import EnvSpec


class VideoWriter:
    """H.264 mp4 from RGB frames (PyAV), streamed to disk frame by frame."""

    def __init__(self, path: Path, fps: float, width: int, height: int):
        self.container = av.open(str(path), mode="w")
        self.stream = self.container.add_stream("libx264", rate=int(round(fps)))
        self.stream.width, self.stream.height, self.stream.pix_fmt = width, height, "yuv420p"
        self.frames = 0

    def add(self, frame: np.ndarray) -> None:
        for packet in self.stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
            self.container.mux(packet)
        self.frames += 1

    def close(self) -> None:
        for packet in self.stream.encode():
            self.container.mux(packet)
        self.container.close()


def record_video(agent: Agent, spec: EnvSpec, seed: int, width: int, height: int, path: Path) -> dict:
    """Re-run one episode with offscreen rendering from the tracking camera; the episode's metrics."""
    env = spec.make(render_mode="rgb_array", width=width, height=height)
    writer = VideoWriter(path, 1.0 / env.env_cfg.control_dt_s, width, height)
    try:
        with torch_threads(1):
            result = run_episode(make_policy(agent), env, seed, frame_sink=writer.add)
    finally:
        writer.close()
        env.close()
    result["frames"] = writer.frames
    return result
