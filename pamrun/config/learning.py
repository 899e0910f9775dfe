"""Schemas of learning: the algorithm (thesis Tables 9.1, 9.2, 9.4) and the training budget."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Optional

from pamrun.config.checks import _non_negative, _positive, _require
from pamrun.config.task import RewardConfig

# --------------------------------------------------------------------------- learning


@dataclass
class AlgoConfig:
    """DDPG (the thesis, Table 9.4) or TD3 (its proposed next step, §13)."""

    name: str = "ddpg"  # ddpg (the thesis), td3 or sac
    gamma: float = 0.99  # discount (Table 9.4)
    batch_size: int = 128  # Table 9.4
    target_smoothing: float = 1e-3  # soft target update tau (Table 9.4)
    # The thesis prints actor 1e-3 / critic 1e-4, the reverse of the MathWorks example it
    # adapted (actor 1e-4, critic 1e-3): we keep the thesis' values (THESIS.md §7).
    actor_lr: float = 1e-3  # actor learning rate (Table 9.4)
    critic_lr: float = 1e-4  # critic learning rate (Table 9.4)
    hidden_sizes: list[int] = field(default_factory=lambda: [400, 300])  # Tables 9.1, 9.2
    critic: str = "thesis"  # thesis: Table 9.2 (the action joins after the first layer); concat: at the input
    output_init_scale: float = 3e-3  # uniform init range of the last layers (DDPG paper)
    loss_function: str = "l2"  # critic loss: l1, l2 or smooth_l1
    # Exploration: variance 0.5 decaying by 1e-5 per step (Table 9.4).
    noise_variance: float = 0.5  # exploration noise scale at the start (OU variance, Table 9.4)
    noise_decay: float = 1e-5  # noise scale decay per step (Table 9.4)
    noise_variance_min: float = 0.01  # floor of the decaying noise scale
    ou_theta: float = 0.15  # OU mean attraction (not in the thesis; TorchRL's default)
    ou_dt_s: float = 0.025  # OU time step = the control step Ts
    # TD3's exploration noise over time has the power spectrum 1/f^noise_beta: 0 white (independent each step, TD3's
    # Gaussian), 1 pink, 2 red. Eberhard et al., ICLR 2023 ("Pink noise is all you need"): pink explores better than
    # white and OU across off-policy continuous control. Drawn in chunks of noise_chunk_steps control steps (400: one
    # 10 s episode at 40 Hz), each action's series scaled to unit RMS; its std stays sqrt(noise_variance).
    noise_beta: float = 0.0
    noise_chunk_steps: int = 400
    # TD3 only (Fujimoto et al. 2018 defaults)
    policy_noise: float = 0.2  # TD3 target policy smoothing noise
    noise_clip: float = 0.5  # TD3 clip of the target policy noise
    actor_update_every: int = 1  # actor update every n critic updates (DDPG 1; TD3's delay: 2, algo=td3)
    # SAC only (Haarnoja et al. 2018; CleanRL's defaults)
    init_alpha: float = 1.0  # SAC's initial entropy temperature alpha (learned; lr = actor_lr)
    target_entropy: float = -1.0  # SAC's target entropy per action dimension
    grad_clip: float = 1.0  # gradient threshold of the MathWorks example
    # Weight w of the mirror loss added to the actor's loss, w mean|Q| mean ||pi(s) - M_a pi(M_s s)||^2 with M_s,
    # M_a the observation's and action's mirror images (pamrun/task/symmetry.py): the policy is asked to be its
    # own mirror image, beyond mirrored data (train.mirror) (Yu, Turk & Liu, SIGGRAPH 2018, beside PPO's
    # normalised surrogate: weight 4). Scaled by the batch's mean |Q| as the anchor below, so that w reads the
    # same under any reward scale (TensorBoard loss/mirror: the unscaled mean square). 0 = off.
    mirror_loss: float = 0.0
    # Weight b of the anchor added to the actor's loss when a run starts from a trained agent (train.init_from):
    # b mean|Q| mean ||pi(s) - pi_0(s)||^2, pi_0 the actor it started from, frozen. Scaled by the batch's mean |Q|
    # as TD3+BC's behaviour term (Fujimoto & Gu, NeurIPS 2021: -lambda Q + (pi - a)^2, lambda = alpha / mean|Q|,
    # alpha 2.5, i.e. b = 1/alpha = 0.4), so that b reads the same under any reward scale. New critics' first
    # gradients otherwise throw the started actor over in a hundred actor updates (docs/results.md, k12). 0 = off.
    anchor: float = 0.0
    # The anchor fades: its weight falls linearly from b to 0 over anchor_fade_frames, from frame
    # anchor_fade_start_frames of the run on (its frame count, as train.max_frames'), so that new critics learn
    # under it and the actor then goes where they lead (TensorBoard curriculum/anchor). Tried once (k16 in
    # docs/results.md), the freed actor drifted from its gait and fell as the weight passed 0.05. 0 = it holds all run.
    anchor_fade_start_frames: int = 0
    anchor_fade_frames: int = 0
    # CrossQ (Bhatt, Palenicek et al., ICLR 2024), for td3 or sac: the concatenating critics batch-renormalised
    # (Ioffe 2017: at the input and after each hidden layer), no target networks, and Q(s, a) with Q(s', a') in
    # one forward pass, so that both share the normalisation's statistics. The paper's other choices are keys of
    # their own: adam_beta1 0.5 and actor_update_every 3. Its renormalisation acts as batch normalisation for the
    # first renorm_warmup_updates updates (the paper's 100,000).
    crossq: bool = False
    renorm_warmup_updates: int = 100_000
    adam_beta1: float = 0.9  # Adam's beta1, every optimiser's (torch's default; CrossQ: 0.5)

    def __post_init__(self) -> None:
        _require(self.name in ("ddpg", "td3", "sac"), "name", f"unknown algorithm {self.name!r}; known: ddpg, td3, sac")
        _require(not self.crossq or self.name in ("td3", "sac"), "crossq",
                 f"drops the target networks of td3's or sac's twin critics; algo.name is {self.name}")
        _require(not self.crossq or self.critic == "concat", "crossq",
                 "batch-renormalises the concatenating critic: needs algo.critic=concat")
        _require(self.renorm_warmup_updates >= 0, "renorm_warmup_updates", f"must be >= 0, got {self.renorm_warmup_updates}")
        _require(0 <= self.adam_beta1 < 1, "adam_beta1", f"must lie in [0, 1), got {self.adam_beta1}")
        _require(0 < self.gamma <= 1, "gamma", f"must lie in (0, 1], got {self.gamma}")
        _require(self.batch_size >= 1, "batch_size", f"must be >= 1, got {self.batch_size}")
        _require(0 < self.target_smoothing <= 1, "target_smoothing", "must lie in (0, 1]")
        _positive(self, "actor_lr", "critic_lr", "output_init_scale", "ou_dt_s", "grad_clip", "init_alpha")
        _non_negative(self, "noise_variance", "noise_decay", "noise_variance_min", "ou_theta", "policy_noise",
                      "noise_clip", "mirror_loss", "anchor", "anchor_fade_start_frames", "anchor_fade_frames")
        for key in ("anchor_fade_start_frames", "anchor_fade_frames"):
            _require(not getattr(self, key) or self.anchor, key, "fades algo.anchor: needs algo.anchor > 0")
        _require(0 <= self.noise_beta <= 2, "noise_beta", f"must lie in [0, 2] (0 white, 1 pink, 2 red), got {self.noise_beta}")
        _require(self.noise_beta == 0 or self.name == "td3", "noise_beta",
                 f"colors TD3's Gaussian exploration; {self.name} explores otherwise (ddpg: OU, ou_theta; sac: its own spread)")
        _require(self.noise_chunk_steps >= 2, "noise_chunk_steps", f"must be >= 2, got {self.noise_chunk_steps}")
        _require(len(self.hidden_sizes) == 2 and min(self.hidden_sizes) > 0, "hidden_sizes",
                 f"needs two positive layer sizes, got {list(self.hidden_sizes)}")
        _require(self.critic in ("thesis", "concat"), "critic", f"must be thesis or concat, got {self.critic!r}")
        _require(self.actor_update_every >= 1, "actor_update_every", "must be >= 1")
        _require(self.loss_function in ("l1", "l2", "smooth_l1"), "loss_function", "must be l1, l2 or smooth_l1")


@dataclass
class TrainConfig:
    """Budget, stop criteria, saving and parallelism of ``pamrun train`` (thesis §9.5, Table 9.4)."""

    max_episodes: int = 5000  # Table 9.4
    max_frames: int = 2_000_000  # stop after this many env steps
    max_minutes: float = 0.0  # wall-clock limit; 0 = none
    target_avg_reward: float = 0.0  # stop when the windowed average reaches it; 0 = off
    avg_window: int = 100  # episodes in the average (MATLAB's ScoreAveragingWindowLength)
    save_threshold: float = 250.0  # save every agent whose episode reward reaches it (§9.5)
    keep_saved: int = 10  # keep the best this many threshold saves
    workers: int = 1  # collector processes (the thesis used 8)
    # Envs in their own process(es), stepping while the learner updates; batches lag the policy
    # by a batch or more and runs are no longer bit-for-bit reproducible.
    async_collection: bool = False  # collect and learn at once (TorchRL's AsyncCollector)
    threads: int = 0  # torch threads of the learner; 0 = the cores the collectors leave free
    frames_per_batch: int = 200  # env steps collected between learner phases
    init_random_frames: int = 2000  # uniform random actions before learning starts
    updates_per_frame: float = 1.0  # gradient updates per collected env step
    actor_start_frames: int = 0  # frames before the actor's first update: until then only the critics learn
    buffer_size: int = 1_000_000  # the MathWorks example's ExperienceBufferLength
    checkpoint_every_frames: int = 20_000  # write checkpoints/last.pt (and the buffer) this often
    # Start from a trained agent (a fine-tune, e.g. under other walk_weights): an agent file
    # (checkpoints/*.pt, agents/*.pt) gives the actor; a run's checkpoints/last.pt the actor, the
    # critics and, where reward.*, env.*, body.* and muscle.* are the same, its replay buffer
    # (re-weighted like every sample).
    # The counters start at 0, the agent is evaluated at frame 0, and a stand-then-walk curriculum
    # starts at its last stage (gait with gait_weights). Set train.init_random_frames=0 to keep its
    # first frames its own.
    # "" = from scratch
    init_from: str = ""
    # Evaluation during training: eval_episodes deterministic episodes of pamrun eval's walk test
    # (its seeds, start noise and criteria: the eval group) into evals.csv, TensorBoard eval/*, and
    # checkpoints/best_eval.pt (the best agent by eval.rank_by).
    eval_every_frames: int = 20_000  # evaluate the actor this often; 0 = never
    eval_episodes: int = 10  # episodes per evaluation (the walk test's 10)
    # Every eval_video_every-th evaluation (none without evaluations) also puts a video of the first seconds of its first episode in
    # TensorBoard (an animated GIF, image video/episode), rendered offscreen (MUJOCO_GL, egl by default;
    # 81 frames of 320 x 240: about 10 s a video on two CPU cores without a GPU, under 1 % of the training
    # time between 10 evaluations). Where rendering fails, the run says so once and goes on without videos.
    # 0 = never.
    eval_video_every: int = 10
    # Selection under perturbation (pamrun/evaluation/evaluator.py, TrainingEvaluator): once an evaluation has a
    # nominal pass, it also runs select_episodes episodes under each of these eval.perturbations, and
    # best_eval.pt is the agent with the best walk pass rate over all of them. [] = nominal only.
    select_perturbations: list[str] = field(default_factory=list)  # e.g. [friction_low, lag_x2, push_forward]
    select_episodes: int = 3  # episodes per perturbation (selection seeds eval.selection_seed + k)
    # A name's own count (others select_episodes), e.g. {friction_low: 10}: 3 episodes cannot tell
    # a 50 % agent from a 90 % one (3 of 3 passes: chance 0.13 against 0.73)
    select_episodes_of: dict[str, int] = field(default_factory=dict)
    # ... and, with select_schedule_episodes > 0, that many on this speed schedule ([[time_s, speed_m_s],
    # ...], as eval.speed_schedule), each counted as passed when it does not fall and stands still where
    # told 0 (pamrun.task.criteria.kept_command): an agent that walks but cannot stop is not selected.
    # e.g. [[0, 0], [2.5, 0.6], [5, 1.2], [7.5, 0]]; [] = none
    select_schedule: list[Any] = field(default_factory=list)
    select_schedule_episodes: int = 0
    stop_on_walk: bool = False  # stop the run once an evaluation passes the walk test (status: walked)
    # Curriculum, stand then walk: once an evaluation after the actor's first update stands in
    # every episode (the "stand, learned" milestone), the learner's reward weighs the forward
    # velocity by walk_kvx instead of reward.kvx: every replayed transition, old or new, gets
    # r + (walk_kvx - reward.kvx) Vx. The env, its logs and pamrun eval keep reward.kvx. None = off.
    walk_kvx: Optional[float] = None
    # The walking stage's other weights, any reward key (e.g. {kspeed: 3.0}), re-weighted the same way.
    walk_weights: dict[str, float] = field(default_factory=dict)
    # A third stage, gait: from the walking stage's first evaluation in which every episode passes
    # the walk test, these weights (any reward key, e.g. {kflight: 20}) replace the walking stage's,
    # re-weighted the same way. {} = no third stage
    gait_weights: dict[str, float] = field(default_factory=dict)
    # TD3's exploration noise spectrum (1/f^beta, as algo.noise_beta) from the walking stage on;
    # algo.noise_beta until then. E.g. algo.noise_beta=0 train.walk_noise_beta=1: white noise while
    # it learns to stand (k2: stood at 70,000 frames), pink once it walks (k4p: the first clocked
    # agent to pass the walk test). None = algo.noise_beta throughout
    walk_noise_beta: Optional[float] = None
    # The gait stage's milestone: None = the walk test (above); a distance = the walking stage's
    # first evaluation in which every episode lasts the full episode and covers at least this many
    # metres (e.g. 2.0: a march at 0.2 m/s that never passes the walk test's 7 m still moves on)
    gait_from_distance_m: Optional[float] = None
    # Costs raised while the walk holds (Schumacher et al. 2025, iScience 28:112203, raise an
    # effort cost while performance holds and lower it when it drops): in the gait stage, each
    # evaluation that meets the gait stage's milestone (the walk test, or gait_from_distance_m)
    # multiplies these weights by adapt_factor, up to the value given here; one that does not
    # divides them, down to the gait stage's own (which must be > 0). E.g. {kv: 1.0, kda: 4.0}. {} = off
    adapt_weights: dict[str, float] = field(default_factory=dict)
    adapt_factor: float = 1.25
    # Domain randomisation (pamrun/task/randomize.py): each episode, with probability randomize_prob,
    # randomize_count of these eval.perturbations (the robustness suite's), each at a strength drawn
    # in [0, randomize_reach] of the way to it. [] = off. The evaluations during training stay nominal.
    mirror: bool = False  # also store each transition's left-right mirror image in the replay buffer (pamrun/task/symmetry.py)
    randomize: list[str] = field(default_factory=list)  # names in eval.perturbations, e.g. [mass_heavy, lag_x2]
    randomize_prob: float = 0.5  # share of episodes with a perturbation
    randomize_reach: float = 1.0  # strength drawn uniformly in [0, this]; > 1 goes beyond the suite's sizes
    randomize_count: int = 1  # perturbations combined in a perturbed episode (two that set one value: not both)
    # Relative draw weights of names in randomize (others 1), e.g. {friction_low: 3}; {} = uniform
    randomize_weights: dict[str, float] = field(default_factory=dict)
    # Reach of names in randomize (others randomize_reach), e.g. {friction_low: 1.7}: that perturbation
    # alone drawn further beyond the suite's size; {} = randomize_reach for all
    randomize_reaches: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("max_episodes", "max_frames", "avg_window", "keep_saved", "workers", "frames_per_batch",
                     "buffer_size", "checkpoint_every_frames"):
            _require(getattr(self, name) >= 1, name, f"must be >= 1, got {getattr(self, name)}")
        _non_negative(self, "max_minutes", "updates_per_frame")
        _require(self.eval_every_frames >= 0, "eval_every_frames", f"must be >= 0 (0 = never), got {self.eval_every_frames}")
        _require(self.eval_episodes >= 1, "eval_episodes", f"must be >= 1, got {self.eval_episodes}")
        _require(self.eval_video_every >= 0, "eval_video_every", f"must be >= 0 (0 = never), got {self.eval_video_every}")
        _require(self.select_episodes >= 1, "select_episodes", f"must be >= 1, got {self.select_episodes}")
        _check_by_name(self.select_episodes_of, "select_episodes_of", self.select_perturbations,
                       "select_perturbations", lambda n: n >= 1, "must be >= 1")
        _require(not (self.select_perturbations and self.eval_every_frames == 0), "select_perturbations",
                 "needs evaluations during training (train.eval_every_frames > 0)")
        _require(self.select_schedule_episodes >= 0, "select_schedule_episodes",
                 f"must be >= 0, got {self.select_schedule_episodes}")
        _require(bool(self.select_schedule) == bool(self.select_schedule_episodes), "select_schedule",
                 "comes with select_schedule_episodes > 0 (both set, or neither)")
        _require(not (self.select_schedule and self.eval_every_frames == 0), "select_schedule",
                 "needs evaluations during training (train.eval_every_frames > 0)")
        _require(not (self.stop_on_walk and self.eval_every_frames == 0), "stop_on_walk",
                 "needs evaluations during training (train.eval_every_frames > 0)")
        _require(self.init_random_frames >= 0, "init_random_frames", "must be >= 0")
        _require(self.actor_start_frames >= 0, "actor_start_frames", "must be >= 0")
        self._check_stages()
        _require(self.threads >= 0, "threads", f"must be >= 0 (0 = automatic), got {self.threads}")
        _require(self.randomize_count >= 1, "randomize_count", f"must be >= 1, got {self.randomize_count}")
        _require(0 <= self.randomize_prob <= 1, "randomize_prob", f"must lie in [0, 1], got {self.randomize_prob}")
        _require(self.randomize_reach >= 0 and math.isfinite(self.randomize_reach), "randomize_reach",
                 f"must be a finite strength >= 0, got {self.randomize_reach}")
        _check_by_name(self.randomize_weights, "randomize_weights", self.randomize, "randomize",
                       lambda w: w > 0 and math.isfinite(w),
                       "must be a finite weight > 0 (leave a name out of train.randomize instead)")
        _check_by_name(self.randomize_reaches, "randomize_reaches", self.randomize, "randomize",
                       lambda r: r >= 0 and math.isfinite(r), "must be a finite strength >= 0")


    def _check_stages(self) -> None:
        """The curriculum's keys: walk_kvx, walk_weights, gait_weights and what depends on them."""
        _require(self.walk_kvx is None or self.eval_every_frames > 0, "walk_kvx",
                 "needs evaluations during training (train.eval_every_frames > 0) to know when the agent stands")
        _require(self.walk_kvx is None or math.isfinite(self.walk_kvx), "walk_kvx", "must be finite")
        for name in ("walk_weights", "gait_weights"):
            for key, weight in getattr(self, name).items():
                _require(key in RewardConfig.__dataclass_fields__, f"{name}.{key}",
                         f"not a reward weight; known: {', '.join(RewardConfig.__dataclass_fields__)}")
                _require(math.isfinite(weight), f"{name}.{key}", "must be finite")
        for key, cap in self.adapt_weights.items():
            _require(key in RewardConfig.__dataclass_fields__, f"adapt_weights.{key}",
                     f"not a reward weight; known: {', '.join(RewardConfig.__dataclass_fields__)}")
            _require(math.isfinite(cap) and cap > 0, f"adapt_weights.{key}", f"must be a finite weight > 0, got {cap}")
        _require(not self.adapt_weights or self.gait_weights, "adapt_weights",
                 "adapts the gait stage's weights: needs train.gait_weights")
        _require(math.isfinite(self.adapt_factor) and self.adapt_factor > 1, "adapt_factor",
                 f"must be > 1, got {self.adapt_factor}")
        _require(self.gait_from_distance_m is None or self.gait_weights, "gait_from_distance_m",
                 "starts the gait stage: needs train.gait_weights")
        _require(self.gait_from_distance_m is None
                 or (math.isfinite(self.gait_from_distance_m) and self.gait_from_distance_m > 0),
                 "gait_from_distance_m", f"must be a finite distance > 0 (None = the walk test), got {self.gait_from_distance_m}")
        _require(not self.gait_weights or self.walk_weights or self.walk_kvx is not None, "gait_weights",
                 "is the stage after walking: needs train.walk_weights or train.walk_kvx")
        _require(self.walk_noise_beta is None or self.walk_weights or self.walk_kvx is not None, "walk_noise_beta",
                 "sets the walking stage's noise: needs train.walk_weights or train.walk_kvx")
        _require(self.walk_noise_beta is None or 0 <= self.walk_noise_beta <= 2, "walk_noise_beta",
                 f"must lie in [0, 2] (0 white, 1 pink, 2 red), got {self.walk_noise_beta}")
        _require(not self.walk_weights or self.eval_every_frames > 0, "walk_weights",
                 "needs evaluations during training (train.eval_every_frames > 0) to know when the agent stands")


def _check_by_name(values: dict, key: str, names: list[str], names_key: str, ok, message: str) -> None:
    """Each ``train.<key>.<name>`` names an entry of ``train.<names_key>`` and has a value ``ok`` accepts."""
    for name, value in values.items():
        _require(name in names, f"{key}.{name}", f"not a name in train.{names_key} ({', '.join(names) or 'empty'})")
        _require(ok(value), f"{key}.{name}", f"{message}, got {value}")
