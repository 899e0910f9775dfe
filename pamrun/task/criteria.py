"""The walking task's criteria, in one place: when an episode ends by a fall, when it stood,
when it passed the walk test, and when training has learned to stand.

**Two lateral limits, for two reasons.** ``env.max_lateral_m`` is a *termination* rule
(thesis §9.5's trajectories stay inside |y| <= 0.5 m): the episode ends there, in training
and in evaluation alike, so the learner never sees states outside the band.
``eval.walk_lateral_m`` is the walk test's *pass* criterion (thesis Fig. 10.25): an
episode passes only if it stayed inside that band. Both are 0.5 m by default; a test
band wider than the env's has no effect (such an episode has already ended by a fall),
a narrower one makes the test stricter than the task.

The predicates take an episode record as :func:`pamrun.evaluation.episodes.run_episode` returns it
(``fell``, ``physics_error``, ``duration_s``, ``max_abs_y_m``, ``distance_m``) and the
``eval`` config section (:class:`pamrun.config.EvalConfig`).
"""

from __future__ import annotations

from pamrun.config import Config, EnvConfig


def fell(x_y_z_rpy: tuple, z0_m: float, env: EnvConfig) -> bool:
    """Termination by a fall (thesis §9, the MathWorks example's checks): the torso below
    ``env.fall_height_ratio`` of its standing height ``z0_m``, outside |y| <= ``env.max_lateral_m``,
    or |roll|, |pitch| or |yaw| >= ``env.max_tilt_rad``. ``x_y_z_rpy``: the torso's
    (x, y, z [m], roll, pitch, yaw [rad], ...)."""
    _, y, z, roll, pitch, yaw, *_ = x_y_z_rpy
    return bool(z < env.fall_height_ratio * z0_m or abs(y) > env.max_lateral_m
                or max(abs(roll), abs(pitch), abs(yaw)) >= env.max_tilt_rad)


def stood(episode: dict, ecfg) -> bool:
    """The episode lasted ``ecfg.walk_duration_s`` without a fall or a physics blow-up."""
    return (not episode["fell"] and not episode.get("physics_error", False)
            and episode["duration_s"] >= ecfg.walk_duration_s - 1e-9)


def walk_passed(episode: dict, ecfg) -> bool:
    """The walk test of one episode (thesis §10.3 and its abstract): ``ecfg.walk_duration_s``
    without a fall, never leaving |y| <= ``ecfg.walk_lateral_m``, at least
    ``ecfg.walk_distance_m`` forward, and no physics blow-up (whose distances mean nothing)."""
    return (stood(episode, ecfg) and episode["max_abs_y_m"] <= ecfg.walk_lateral_m
            and episode["distance_m"] >= ecfg.walk_distance_m)


# Standing still where told 0 m/s, in the settled stretches pamrun.evaluation.tracking measures
# (stand_still_*): both feet down at least this share of the time, the torso moving at most this far.
# The walk's stand-still targets: a robot on a test stand waits without stepping or creeping.
STAND_STILL_FEET_DOWN_SHARE = 0.9
STAND_STILL_DRIFT_M = 0.2


def stood_still(episode: dict) -> bool:
    """Both feet down at least ``STAND_STILL_FEET_DOWN_SHARE`` of the settled v* = 0 time and a drift
    of at most ``STAND_STILL_DRIFT_M`` there; True where those are NaN or absent: never told 0
    long enough to settle, or fallen before it (:func:`stood` judges a fall)."""
    share, drift = episode.get("stand_still_feet_down_share"), episode.get("stand_still_drift_m")
    if share is None or share != share:
        return True
    return share >= STAND_STILL_FEET_DOWN_SHARE and drift <= STAND_STILL_DRIFT_M


def kept_command(episode: dict, ecfg) -> bool:
    """An episode on a speed schedule (``train.select_schedule``) that kept to it: it lasted
    ``ecfg.walk_duration_s`` without a fall or blow-up (:func:`stood`) and stood still where told
    0 m/s (:func:`stood_still`). Its speed is not judged: the walk test judges that."""
    return stood(episode, ecfg) and stood_still(episode)


def actor_learns_from(cfg: Config) -> int:
    """Frames at the run's first actor update (after its random phase and critic warm-up); -1 for
    a run that starts from a trained agent (``train.init_from``): its actor learned before frame 0."""
    if cfg.train.init_from:
        return -1
    return max(cfg.train.init_random_frames, cfg.train.actor_start_frames)


def stands_learned(stand_rate: float, frames: int, cfg: Config) -> bool:
    """The "stand, learned" milestone: every evaluation episode lasts the full episode, in an
    evaluation after the actor's first update (the sized robot stands passively at zero
    command, so an untrained actor stands too: standing only counts once the actor learns)."""
    return stand_rate >= 1.0 and frames > actor_learns_from(cfg)
