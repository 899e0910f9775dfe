"""What ``pamrun train`` shows while it runs: how far the run is into its budget and the time
remaining (:func:`budget`), the recent frame rate (:class:`Rates`), the episodes, and the latest
evaluation, on :class:`pamrun.runs.files.Progress` (a bar on a terminal, plain lines otherwise)."""

from __future__ import annotations

import time
from collections import deque
from typing import Callable

from pamrun.config import TrainConfig
from pamrun.evaluation.ranking import pass_text
from pamrun.evaluation.targets import WALK_TARGETS
from pamrun.runs.files import Progress, duration

RATE_WINDOW_S = 30.0  # the frames/s and updates/s shown: over about this many recent seconds
ETA_WINDOW_S = 300.0  # the time remaining: at the rate of about this many recent seconds (evaluations included)


def budget(t: TrainConfig, frames: int, episodes: int, elapsed_s: float, frame_rate: float | None,
           episode_rate: float | None) -> tuple[str, float, float | None]:
    """The budget the run is furthest into (``"frames"``: ``train.max_frames``, ``"minutes"``:
    ``train.max_minutes`` if set, ``"episodes"``: ``train.max_episodes``), the fraction of it done,
    and the seconds until the first budget runs out: frames and episodes at their rates per second
    (None: not known yet), minutes by the clock; None while no rate is known.

    The counts and seconds are the run's own, a resumed run's earlier part included. At a steady
    rate the budget furthest in is the first to run out."""

    def left(remaining: float, rate: float | None) -> float | None:
        return max(0.0, remaining) / rate if rate else None

    parts = {"frames": (frames / t.max_frames, left(t.max_frames - frames, frame_rate)),
             "episodes": (episodes / t.max_episodes, left(t.max_episodes - episodes, episode_rate))}
    if t.max_minutes:
        limit_s = 60 * t.max_minutes
        parts["minutes"] = (elapsed_s / limit_s, max(0.0, limit_s - elapsed_s))
    name = max(parts, key=lambda k: parts[k][0])
    etas = [eta for _, eta in parts.values() if eta is not None]
    return name, min(1.0, parts[name][0]), min(etas) if etas else None


class Rates:
    """Counts per second over recent seconds, from samples of the counts (the last ``keep_s`` kept)."""

    def __init__(self, now: float, counts: dict[str, float], keep_s: float = ETA_WINDOW_S):
        self.samples, self.keep_s = deque([(now, dict(counts))]), keep_s

    def add(self, now: float, counts: dict[str, float]) -> None:
        self.samples.append((now, dict(counts)))
        while len(self.samples) > 2 and self.samples[1][0] <= now - self.keep_s:
            self.samples.popleft()

    def per_s(self, name: str, window_s: float) -> float | None:
        """``name``'s rate since the newest sample at least ``window_s`` old (else the oldest); None
        before two samples apart in time."""
        t1, c1 = self.samples[-1]
        for t0, c0 in reversed(self.samples):
            if t1 - t0 >= window_s:
                break
        return (c1[name] - c0[name]) / (t1 - t0) if t1 > t0 else None


class TrainingProgress:
    """A training run's progress line: its budget's fraction with the time remaining (:func:`budget`),
    the recent frames/s and updates/s, the episodes, the caller's info (average and best reward),
    the latest evaluation (stand count, walk passes with their 95 % Wilson interval) and the
    curriculum's stage. Outside a terminal a line every ~10 s, and one after each evaluation.

    ``counters``: those a run keeps (frames, episodes, updates, wall_time_s), a resumed run's
    earlier part included; ``curriculum``: a :class:`pamrun.learning.curriculum.WalkCurriculum`."""

    def __init__(self, console, t: TrainConfig, counters: dict, curriculum=None,
                 clock: Callable[[], float] = time.monotonic):
        self.t, self.curriculum, self.clock = t, curriculum, clock
        self.rates = Rates(clock(), counters)
        self.progress = Progress(console, t.max_frames, counters["frames"], clock=clock)
        self.counters, self.info, self.eval_text = dict(counters), "", ""

    def update(self, counters: dict, info: str = "") -> None:
        """The run at ``counters``; ``info`` follows the episodes."""
        self.rates.add(self.clock(), counters)
        self.counters, self.info = dict(counters), info
        self.show()

    def evaluated(self, result: dict, counters: dict) -> None:
        """The evaluation ``result`` (:class:`pamrun.evaluation.evaluator.TrainingEvaluator`'s) shown at once."""
        stand = round(result["stand_rate"] * result["episodes"])
        self.eval_text = (f"eval: stand {stand}/{result['episodes']} walk {pass_text(result)}"
                          f" targets {result.get('walk_targets_met', 0)}/{len(WALK_TARGETS)}")
        kept = result.get("select_schedule_rate", float("nan"))
        if kept == kept:  # the selection's speed schedule ran (train.select_schedule)
            self.eval_text += f" schedule {kept:.0%}"
        self.counters = dict(counters)
        self.show(now=True)

    def show(self, now: bool = False) -> None:
        c, t = self.counters, self.t
        name, fraction, eta = budget(t, c["frames"], c["episodes"], c["wall_time_s"],
                                     self.rates.per_s("frames", ETA_WINDOW_S),
                                     self.rates.per_s("episodes", ETA_WINDOW_S))
        head = {"frames": f"frames {c['frames']}/{t.max_frames}", "episodes": f"episodes {c['episodes']}/"
                f"{t.max_episodes}", "minutes": f"time {duration(c['wall_time_s'])}/{duration(60 * t.max_minutes)}"}
        fps, ups = self.rates.per_s("frames", RATE_WINDOW_S), self.rates.per_s("updates", RATE_WINDOW_S)
        parts = [f"{head[name]} ({fraction:.1%})", f"eta {duration(eta)}",
                 f"{fps:.0f} frames/s" if fps is not None else "? frames/s",
                 f"{ups:.1f} updates/s" if ups is not None else "? updates/s"]
        parts += [f"frames {c['frames']}"] * (name != "frames") + [f"episodes {c['episodes']}"] * (name != "episodes")
        parts += [self.info, self.eval_text]
        if self.curriculum is not None and self.curriculum.active:
            parts.append(f"stage {self.curriculum.stage}")
        self.progress.show(fraction, "  ".join(p for p in parts if p), now)

    def stop(self) -> None:
        self.progress.stop()
