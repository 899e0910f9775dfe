"""What ``pamrun train`` and ``pamrun eval`` show while they run: the budget's fraction and the time
remaining, plain lines outside a terminal (rate-limited, one at once after an evaluation), a bar
on a terminal. Driven by a clock of the test's own, on a rich Console writing to a string."""

from __future__ import annotations

import io
import re

import pytest
from rich.console import Console

from pamrun.config import TrainConfig
from pamrun.evaluation.episodes import wilson_interval
from pamrun.runs.files import LOG_WIDTH, Progress, duration
from pamrun.training.progress import TrainingProgress, budget

START = {"frames": 0, "episodes": 0, "updates": 0, "wall_time_s": 0.0}


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def console(terminal: bool) -> tuple[Console, io.StringIO]:
    out = io.StringIO()
    return Console(file=out, force_terminal=terminal, width=200 if terminal else LOG_WIDTH), out


def evaluation(stands: int, passes: int, n: int = 10) -> dict:
    """The fields of an evaluation's result (:func:`pamrun.evaluation.episodes.aggregate`) the progress shows."""
    low, high = wilson_interval(passes, n)
    return {"episodes": n, "stand_rate": stands / n, "walk_passes": passes, "walk_pass_rate": passes / n,
            "walk_pass_ci_low": low, "walk_pass_ci_high": high, "walk_targets_met": 4}


def run_for(progress: TrainingProgress, clock: Clock, seconds: int, fps: int = 140, start: dict = START) -> dict:
    """One batch a second at ``fps`` frames per second, an episode every 3 s, 2 updates per frame."""
    for s in range(1, seconds + 1):
        clock.now += 1.0
        counters = {"frames": start["frames"] + fps * s, "episodes": start["episodes"] + s // 3,
                    "updates": start["updates"] + 2 * fps * s, "wall_time_s": start["wall_time_s"] + s}
        progress.update(counters, "avg 30.25  best 94.76")
    return counters


def test_duration():
    assert [duration(s) for s in (0, 42.4, 65, 3720, 7199.6, None, float("inf"))] == [
        "0s", "42s", "1m05s", "1h02m", "2h00m", "?", "?"]


def test_budget_frames_minutes_episodes():
    frames_only = TrainConfig(max_frames=1000, max_episodes=100, max_minutes=0)
    assert budget(frames_only, 250, 5, 60.0, 10.0, 0.1) == ("frames", 0.25, 75.0)
    assert budget(frames_only, 250, 5, 60.0, None, None) == ("frames", 0.25, None)  # no rate yet
    assert budget(frames_only, 250, 5, 60.0, 10.0, 1.0) == ("frames", 0.25, 75.0)
    # the episodes run out first: their time remaining, and the fraction of the budget furthest in
    assert budget(frames_only, 250, 80, 60.0, 10.0, 1.0) == ("episodes", 0.8, 20.0)
    minutes = TrainConfig(max_frames=1000, max_episodes=100, max_minutes=2)
    assert budget(minutes, 250, 5, 60.0, 10.0, 0.1) == ("minutes", 0.5, 60.0)  # by the clock, rate or not
    assert budget(minutes, 250, 5, 60.0, None, None) == ("minutes", 0.5, 60.0)
    assert budget(minutes, 900, 5, 60.0, 10.0, 0.1) == ("frames", 0.9, 10.0)
    assert budget(minutes, 1000, 5, 130.0, 10.0, 0.1) == ("minutes", 1.0, 0.0)  # past it: 100 %, nothing left


def test_plain_lines_outside_a_terminal():
    """One line about every 10 s with the fraction, time remaining, rates, episodes and info;
    one at once after an evaluation; the last one on stop if it was not printed."""
    clock, (con, out) = Clock(), console(terminal=False)
    progress = TrainingProgress(con, TrainConfig(max_frames=200_000, max_minutes=0), START, clock=clock)
    assert progress.progress.bar is None
    run_for(progress, clock, 35)
    lines = out.getvalue().splitlines()
    assert [line.split("  ")[0] for line in lines] == [
        "frames 140/200000 (0.1%)", "frames 1540/200000 (0.8%)", "frames 2940/200000 (1.5%)",
        "frames 4340/200000 (2.2%)"]  # at 1, 11, 21 and 31 s
    assert lines[-1] == ("frames 4340/200000 (2.2%)  eta 23m18s  140 frames/s  280.0 updates/s  episodes 10  "
                         "avg 30.25  best 94.76")  # 195660 frames left at 140/s
    counters = run_for(progress, clock, 2, start={"frames": 4900, "episodes": 11, "updates": 9800, "wall_time_s": 35})
    assert len(out.getvalue().splitlines()) == 4
    progress.evaluated(evaluation(8, 3), counters)
    last = out.getvalue().splitlines()[-1]
    assert last.startswith("frames 5180/200000 (2.6%)") and last.endswith("eval: stand 8/10 walk 3/10 (11-60 %) targets 4/13")
    run_for(progress, clock, 3, start=counters)
    assert len(out.getvalue().splitlines()) == 5
    progress.stop()
    lines = out.getvalue().splitlines()
    assert len(lines) == 6 and lines[-1].startswith("frames 5600/200000 (2.8%)") and "walk 3/10" in lines[-1]


def test_progress_lines_on_a_terminal_when_asked(monkeypatch):
    """PAMRUN_PROGRESS=lines (sweep jobs sharing a terminal): plain lines on a terminal too."""
    monkeypatch.setenv("PAMRUN_PROGRESS", "lines")
    clock, (con, out) = Clock(), console(terminal=True)
    progress = TrainingProgress(con, TrainConfig(max_frames=200_000), START, clock=clock)
    run_for(progress, clock, 12)
    progress.stop()
    assert progress.progress.bar is None
    assert [line.split("  ")[0] for line in out.getvalue().splitlines()] == [
        "frames 140/200000 (0.1%)", "frames 1540/200000 (0.8%)", "frames 1680/200000 (0.8%)"]


def test_recent_rate_and_a_resumed_run():
    """A run resumed at 100000 of 200000 frames after 50 min, with a one-hour budget: the time
    budget is furthest in, the rate is this part's own (not 101400 frames / 50 min)."""
    clock, (con, out) = Clock(), console(terminal=False)
    before = {"frames": 100_000, "episodes": 250, "updates": 180_000, "wall_time_s": 3000.0}
    progress = TrainingProgress(con, TrainConfig(max_frames=200_000, max_minutes=60), before, clock=clock)
    run_for(progress, clock, 10, fps=100, start=before)
    progress.stop()
    line = out.getvalue().splitlines()[-1]
    assert line.startswith("time 50m10s/1h00m (83.6%)  eta 9m50s  100 frames/s  200.0 updates/s  "
                           "frames 101000  episodes 253  avg")
    # without the time budget: the frames' fraction, and their time remaining at the recent rate
    clock, (con, out) = Clock(), console(terminal=False)
    progress = TrainingProgress(con, TrainConfig(max_frames=200_000, max_minutes=0), before, clock=clock)
    run_for(progress, clock, 1, fps=130, start=before)
    assert out.getvalue().startswith("frames 100130/200000 (50.1%)  eta 12m48s  130 frames/s")


def test_frames_per_second_is_recent():
    """After a slow start (the random phase is fast, evaluations pause), frames/s is the last ~30 s."""
    clock, (con, out) = Clock(), console(terminal=False)
    progress = TrainingProgress(con, TrainConfig(max_frames=10_000_000), START, clock=clock)
    counters = run_for(progress, clock, 120, fps=500)
    run_for(progress, clock, 60, fps=100, start=counters)
    progress.stop()
    assert "  100 frames/s" in out.getvalue().splitlines()[-1]


def test_bar_on_a_terminal():
    """On a terminal: a bar with the line's fields beside it, and the stage of a walk curriculum."""
    clock, (con, out) = Clock(), console(terminal=True)

    class Curriculum:  # the two attributes of pamrun.learning.curriculum.WalkCurriculum the progress reads
        active, stage = True, "stand"

    progress = TrainingProgress(con, TrainConfig(max_frames=200_000), START, Curriculum(), clock=clock)
    assert progress.progress.bar is not None
    counters = run_for(progress, clock, 6)
    progress.evaluated(evaluation(10, 0), counters)
    progress.stop()
    text = re.sub(r"\x1b\[[0-9;?]*[a-zA-Z]", "", out.getvalue())  # without the terminal's control codes
    assert "━" in text and "frames 840/200000 (0.4%)" in text and "140 frames/s" in text
    assert "eval: stand 10/10 walk 0/10 (0-28 %) targets 4/13" in text and "stage stand" in text


@pytest.mark.parametrize("terminal", [False, True])
def test_counted_progress_of_pamrun_eval(terminal):
    """pamrun eval's episodes: done of total with the time remaining at the rate since the start."""
    clock, (con, out) = Clock(), console(terminal)
    progress = Progress(con, 10, unit="episodes", clock=clock)
    for done in range(1, 4):
        clock.now += 2.0
        progress.update(done)
    progress.stop()
    text = re.sub(r"\x1b\[[0-9;?]*[a-zA-Z]", "", out.getvalue())
    assert "episodes 3/10 (30.0%)  eta 14s" in text
    assert ("episodes 1/10 (10.0%)  eta 18s" in text) == (not terminal)


def test_the_run_header_names_each_stage_s_weights(tmp_path):
    """The table a training opens with lists the env's weights, then those of the walking stage
    ('once it stands') and of the gait stage ('once every episode walks')."""
    from pamrun.config import Config
    from pamrun.training.console import header_table

    cfg = Config()
    cfg.train.walk_weights, cfg.train.gait_weights = {"kspeed": 4.0}, {"kflight": 20.0}
    out, text = console(False)
    out.print(header_table(cfg, tmp_path))
    line = " ".join(text.getvalue().split())
    assert "kflight 0," in line and "kspeed 4 once it stands" in line
    assert "kflight 20 once every episode walks" in line
