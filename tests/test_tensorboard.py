"""TensorBoard as a window on learning: the gait scalars, gait figure and video (animated GIF)
of the evaluations during training, the GIF summary itself, and a sweep job's HParams record."""

from __future__ import annotations

import csv
import io
import math

import numpy as np
import pytest
from PIL import Image
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from pamrun.config import ConfigError, to_object
from tests.conftest import compose_config


def read_events(logdir) -> EventAccumulator:
    return EventAccumulator(str(logdir), size_guidance={"images": 0, "scalars": 0, "tensors": 0}).Reload()


def test_gif_summary_plays_back_its_frames(tmp_path):
    """encode_gif: one GIF frame per RGB frame, at the frame rate, looping; as an image summary
    it reads back from the event file byte for byte, with its size."""
    from torch.utils.tensorboard import SummaryWriter

    from pamrun.evaluation.board import add_encoded_image, encode_gif

    frames = [np.full((24, 32, 3), (40 * k, 255 - 40 * k, 90), np.uint8) for k in range(6)]
    gif = encode_gif(frames, fps=20.0)
    with Image.open(io.BytesIO(gif)) as image:
        assert image.format == "GIF" and image.size == (32, 24) and image.n_frames == 6
        assert image.info["duration"] == 50 and image.info["loop"] == 0
        image.seek(3)
        assert np.abs(np.asarray(image.convert("RGB"), int)[5, 5] - frames[3][5, 5]).max() <= 8
    with SummaryWriter(str(tmp_path)) as writer:
        add_encoded_image(writer, "video/episode", gif, step=7)
    [event] = read_events(tmp_path).Images("video/episode")
    assert (event.step, event.width, event.height, event.encoded_image_string) == (7, 32, 24, gif)


def test_eval_video_every_is_checked():
    assert to_object(compose_config()).train.eval_video_every == 10  # a video every 10th evaluation
    with pytest.raises(ConfigError, match="eval_video_every"):
        to_object(compose_config("train.eval_video_every=-1"))


def test_a_machine_that_cannot_render_gets_no_video_and_says_why(monkeypatch, cfg):
    from pamrun.evaluation.evaluator import TrainingEvaluator
    from pamrun.task.env import PamWalkerEnv

    def render(self):
        raise RuntimeError("no EGL display")

    monkeypatch.setattr(PamWalkerEnv, "render", render)
    evaluator = TrainingEvaluator(cfg)  # renders nothing until its first video
    assert evaluator.video(actor=None) is None
    assert "no EGL display" in evaluator.no_video and "train.eval_video_every=0" in evaluator.no_video
    assert evaluator.video(actor=None) is None  # tried once
    evaluator.close()


def test_evaluations_show_gait_figure_and_video_in_tensorboard(tmp_path):
    """A 600-frame run evaluating every 200 frames (one half-second episode) with a video every
    2nd evaluation: gait scalars and a gait figure at each evaluation, a multi-frame GIF at the
    2nd, the gait means in evals.csv."""
    from pamrun.training.recipe import train

    overrides = ["train=smoke", "train.max_frames=600", "train.init_random_frames=200", "train.updates_per_frame=0.1",
                 "train.eval_every_frames=200", "train.eval_episodes=1", "train.eval_video_every=2",
                 "eval.episode_s=0.5", "eval.walk_duration_s=0.5", "seed=1"]
    assert train(to_object(compose_config(*overrides)), tmp_path, overrides) == "max_frames"
    events = read_events(tmp_path / "tensorboard")
    for tag in ("gait/speed_m_s", "gait/duty_factor", "gait/pressure_change_kpa", "gait/stop_share_gait_max",
                "stop_share/right_knee", "eval/figure_s"):
        values = events.Scalars(tag)
        assert [e.step for e in values] == [200, 400, 600], tag
        assert all(math.isfinite(e.value) for e in values), tag
    assert 0 < events.Scalars("gait/duty_factor")[0].value <= 1
    figures = events.Images("gait/figure")
    assert [e.step for e in figures] == [200, 400, 600]
    with Image.open(io.BytesIO(figures[0].encoded_image_string)) as image:
        assert image.format == "PNG" and image.size == (figures[0].width, figures[0].height) and image.width > 500
    [video] = events.Images("video/episode")
    assert video.step == 400 and [e.step for e in events.Scalars("eval/video_s")] == [400]
    with Image.open(io.BytesIO(video.encoded_image_string)) as image:
        # 0.5 s: the first frame and one every 2nd control step of 20 (or fewer: a fall ends it)
        assert image.format == "GIF" and image.size == (320, 240) and 2 <= image.n_frames <= 11
    rows = list(csv.DictReader((tmp_path / "evals.csv").open()))
    assert len(rows) == 3 and float(rows[0]["duty_factor_mean"]) == pytest.approx(
        events.Scalars("gait/duty_factor")[0].value, abs=1e-5)


def test_sweep_job_hparams_name_every_metric(tmp_path):
    """write_hparams: the swept values and every metric of HPARAM_METRICS (NaN where a job has
    none), among them the last and best evaluation's during training from evals.csv."""
    from tensorboard.plugins.hparams import metadata

    from pamrun.runs.directory import EVAL_FIELDS, write_log
    from pamrun.sweep.grid import HPARAM_METRICS, job_metrics, write_hparams

    rows = [{"frames": 200, "walk_pass_rate": 0.0, "stand_rate": 0.5, "speed_mean": 0.1, "best": 1},
            {"frames": 400, "walk_pass_rate": 0.0, "stand_rate": 0.25, "speed_mean": "nan", "best": 0}]
    write_log(tmp_path / "evals.csv", EVAL_FIELDS, rows)
    metrics = job_metrics(tmp_path)
    assert metrics["eval_last_stand_rate"] == 0.25 and metrics["eval_best_stand_rate"] == 0.5
    assert metrics["eval_last_speed_mean"] is None and metrics["eval_best_speed_mean"] == 0.1
    write_hparams(tmp_path, {"reward.kz": 30.0, "algo": "td3"}, metrics)
    events = read_events(tmp_path / "tensorboard")
    content = events.PluginTagToContent(metadata.PLUGIN_NAME)
    experiment = metadata.parse_experiment_plugin_data(content[metadata.EXPERIMENT_TAG])
    assert [m.name.tag for m in experiment.metric_infos] == [f"sweep/{k}" for k in HPARAM_METRICS]
    start = metadata.parse_session_start_info_plugin_data(content[metadata.SESSION_START_INFO_TAG])
    assert start.hparams["reward.kz"].number_value == 30.0 and start.hparams["algo"].string_value == "td3"
    assert events.Scalars("sweep/eval_best_stand_rate")[0].value == 0.5
    assert math.isnan(events.Scalars("sweep/final_avg_reward")[0].value)  # no episodes.csv
