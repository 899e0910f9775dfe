"""What an evaluation during training shows in TensorBoard besides ``eval/*``: its gait
metrics (``gait/*``, ``stop_share/*``), the gait figure of its first episode (image
``gait/figure``, :func:`pamrun.evaluation.figures.gait_figure`) and a short video of that
episode as an animated GIF (image ``video/episode``).

The figure and the GIF are image summaries of encoded bytes (PNG, GIF), as
``SummaryWriter.add_video`` writes a video, but encoded with Pillow: ``add_video`` needs
moviepy. TensorBoard's image tab plays an animated GIF.
"""

from __future__ import annotations

import io
import math

import numpy as np
from PIL import Image
from tensorboard.compat.proto.summary_pb2 import Summary

from pamrun.evaluation import figures
from pamrun.evaluation.metrics import GaitSpec
from pamrun.physics.body import JOINTS

# gait/<tag> -> the evaluation's key: means over its nominal episodes (pamrun.evaluation.metrics defines them)
GAIT_SCALARS = {
    "speed_m_s": "speed_mean",
    "steps_per_s": "step_frequency_hz_mean",
    "step_length_m": "step_length_m_mean",
    "stride_length_m": "stride_length_m_mean",
    "touchdown_reach_m": "touchdown_reach_m_mean",
    "duty_factor": "duty_factor_mean",
    "step_time_symmetry": "step_time_symmetry_mean",
    "step_length_symmetry": "step_length_symmetry_mean",
    "hop_share": "hop_share_mean",
    "retouch_share": "retouch_share_mean",
    "stop_share_gait_max": "stop_share_gait_max_mean",
    "knee_swing_stop_share": "knee_swing_stop_share_mean",
    "swing_clearance_m": "swing_clearance_m_mean",
    "foot_slip_m_s": "foot_slip_m_s_mean",
    "sole_tilt_deg": "sole_tilt_deg_mean",
    "torso_pitch_deg": "torso_pitch_deg_mean",
    "torso_sway_deg": "torso_sway_deg_mean",
    "pressure_change_kpa": "pressure_change_mean",
    "cost_of_transport": "cost_of_transport_mean",
    "air_nl_per_m": "air_nl_per_m_mean",
    "double_support_share": "double_support_share_mean",
    "flight_share": "flight_share_mean",
    "knee_midstance_deg": "knee_midstance_deg_mean",
    "knee_swing_peak_deg": "knee_swing_peak_deg_mean",
    "knee_touchdown_deg": "knee_touchdown_deg_mean",
    "hip_extension_deg": "hip_extension_deg_mean",
    "hip_touchdown_deg": "hip_touchdown_deg_mean",
    "hip_swing_peak_deg": "hip_swing_peak_deg_mean",
    "touchdown_clock_offset": "touchdown_clock_offset_mean",  # pamrun.evaluation.tracking defines these two
    "touchdown_on_clock_share": "touchdown_on_clock_share_mean",
    "walk_targets_met": "walk_targets_met",  # how many of the walk's targets (pamrun.evaluation.targets)
}
FIGURE_DPI = 60  # the gait figure at 960 x 384 pixels
GIF_COLOURS = 128  # palette of each GIF frame (fast octree quantization)


def log_gait(writer, result: dict, step: int) -> None:
    """The evaluation's gait metrics as scalars ``gait/*`` and each joint's stop share as
    ``stop_share/<joint>``; a metric undefined in all its episodes (NaN) is left out."""
    values = {f"gait/{tag}": result[key] for tag, key in GAIT_SCALARS.items()}
    values.update({f"stop_share/{joint}": result[f"stop_share_{joint}_mean"] for joint in JOINTS})
    for tag, value in values.items():
        if math.isfinite(value):
            writer.add_scalar(tag, value, step)


def log_gait_figure(writer, episode: dict, spec: GaitSpec, step: int) -> None:
    """The gait figure of one episode (a record with its ``steps``) as the image ``gait/figure``."""
    fig = figures.gait_figure([episode], spec.joint_limits_rad, spec.contact_threshold_n)
    add_encoded_image(writer, "gait/figure", figures.png_bytes(fig, FIGURE_DPI), step)


def log_video(writer, frames: list[np.ndarray], fps: float, step: int) -> None:
    """Rendered frames as the animated GIF ``video/episode``."""
    add_encoded_image(writer, "video/episode", encode_gif(frames, fps), step)


def encode_gif(frames: list[np.ndarray], fps: float) -> bytes:
    """An animated GIF of RGB frames (h, w, 3) uint8 at ``fps``, looping; each frame with its
    own palette of ``GIF_COLOURS``."""
    images = [Image.fromarray(np.ascontiguousarray(f)).quantize(GIF_COLOURS, method=Image.Quantize.FASTOCTREE)
              for f in frames]
    out = io.BytesIO()
    images[0].save(out, format="GIF", save_all=True, append_images=images[1:], duration=round(1000 / fps), loop=0)
    return out.getvalue()


def image_summary(tag: str, encoded: bytes) -> Summary:
    """A summary of one encoded image (PNG, GIF, ...) under ``tag``, its size read from the bytes."""
    with Image.open(io.BytesIO(encoded)) as image:
        width, height = image.size
    return Summary(value=[Summary.Value(tag=tag, image=Summary.Image(height=height, width=width, colorspace=3,
                                                                     encoded_image_string=encoded))])


def add_encoded_image(writer, tag: str, encoded: bytes, step: int) -> None:
    """Write ``image_summary(tag, encoded)`` with ``writer`` (a ``SummaryWriter``) at ``step``."""
    writer._get_file_writer().add_summary(image_summary(tag, encoded), step)
