"""The best agent's episode as a video: an H.264 mp4 rendered from one of the env's cameras
(:mod:`pamrun.task.camera`, ``eval.camera``)."""

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


def record_video(agent: Agent, spec: EnvSpec, seed: int, width: int, height: int, path: Path,
                 camera: str = "follow") -> dict:
    """Re-run one episode with offscreen rendering from ``camera`` (:data:`pamrun.config.CAMERAS`);
    the episode's metrics."""
    env = spec.make(render_mode="rgb_array", width=width, height=height, camera=camera)
    writer = VideoWriter(path, 1.0 / env.env_cfg.control_dt_s, width, height)
    try:
        with torch_threads(1):
            result = run_episode(make_policy(agent), env, seed, frame_sink=writer.add)
    finally:
        writer.close()
        env.close()
    result["frames"] = writer.frames
    return result


def frame_picks(times: list[float], n: int, every_s: float, from_start: bool = False) -> list[int]:
    """Indices of ``n`` frames ``every_s`` apart (to the nearest frame) about the middle of a video
    whose frames are at ``times`` [s] (``from_start``: its first ones); of ``n`` evenly over all of
    it where it is shorter."""
    dt = (times[-1] - times[0]) / (len(times) - 1) if len(times) > 1 else 0.0
    step = max(1, round(every_s / dt)) if dt > 0 else 1
    span = (n - 1) * step
    if span > len(times) - 1:
        return sorted(set(np.linspace(0, len(times) - 1, min(n, len(times))).round().astype(int).tolist()))
    first = 0 if from_start else (len(times) - 1 - span) // 2
    return [first + step * k for k in range(n)]


def picked_frames(mp4_path: Path, n: int, every_s: float, from_start: bool = False
                  ) -> tuple[list[float], list[np.ndarray]]:
    """The times [s] and RGB arrays of a video's frames that :func:`frame_picks` picks (decoded
    twice: for the times, then keeping only those frames)."""
    with av.open(str(mp4_path)) as container:
        times = [f.time for f in container.decode(video=0)]
    picks = frame_picks(times, n, every_s, from_start)
    wanted = set(picks)
    with av.open(str(mp4_path)) as container:
        frames = [f.to_ndarray(format="rgb24") for k, f in enumerate(container.decode(video=0)) if k in wanted]
    return [times[k] for k in picks], frames


def write_gif(mp4_path: Path, gif_path: Path, seconds: float = 3.0, fps: float = 20.0, width: int = 360,
              from_start: bool = False) -> Path:
    """A looping GIF of ``seconds`` of a video about its middle (``from_start``: its first; all of
    it, where shorter), at about ``fps`` frames a second (every k-th frame), ``width`` pixels wide. One
    64-colour palette for every frame (Pillow's octree, from every 6th) and no dithering keep it
    small: the walker's 3 s at 360 x 270 take about 1 MB."""
    from PIL import Image  # Pillow (matplotlib's dependency): only the GIF needs it

    times, frames = picked_frames(mp4_path, max(1, int(round(seconds * fps))), 1.0 / fps, from_start)
    height = 2 * round(width * frames[0].shape[0] / frames[0].shape[1] / 2)
    images = [Image.fromarray(f).resize((width, height), Image.Resampling.LANCZOS) for f in frames]
    palette = Image.fromarray(np.concatenate([np.asarray(im) for im in images[::6]])).quantize(
        64, method=Image.Quantize.FASTOCTREE)
    images = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    frame_ms = round(1000 * (times[-1] - times[0]) / (len(times) - 1)) if len(times) > 1 else 100  # as recorded
    images[0].save(gif_path, save_all=True, append_images=images[1:], duration=frame_ms, loop=0)
    return Path(gif_path)
