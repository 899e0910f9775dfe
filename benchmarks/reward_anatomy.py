"""What an agent's reward is made of: each term's mean per control step, unweighted and under the
weights of each stage of its run's curriculum (stand, walk, gait), over deterministic episodes.

    python benchmarks/reward_anatomy.py <run>/checkpoints/best_eval.pt [--episodes 5] [--seed 2000]
        [--set kstep=30 kgait=8 ...]

The agent's env is the one its run stored; every term of ``pamrun.task.reward`` is computed,
whatever its weight (the env's ``features``). The stages' weights are those of its run's
``pamrun_config.yaml`` (``pamrun.learning.curriculum.WalkCurriculum``: ``reward.*``, then
``train.walk_weights``, then ``train.gait_weights``); ``--set`` adds a column of other weights
(the gait stage's, with these changed), to see what a change would charge. A term's weighted
mean is its share of the return per step: the terms a learner can gain most on head the table.

With a gait clock, it then splits ``kgait``'s miss by want (``pamrun.task.clock.foot_wants``):
each want's mean miss over the feet's control steps in the clock's swing (swing weight over
1/2) and in its stance, and the share of those steps in which that want is the foot's largest
miss (the one the clock charges), and the feet's own step rate against the clock's. Last, a gait cycle against the clock: each
foot's contact, load, knee and sole speed through its own clock phase, in 20 bins.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pamrun.evaluation.episodes import make_policy
from pamrun.learning.checkpoints import Agent, load_agent
from pamrun.learning.curriculum import WalkCurriculum
from pamrun.runs.directory import saved_config
from pamrun.task import clock
from pamrun.task.env import PamWalkerEnv
from pamrun.task.reward import REWARD_KEYS
from pamrun.task.spec import EnvSpec


@dataclass
class Anatomy:
    """What :func:`measure` counts over its episodes."""

    means: dict[str, float]  # each term's unweighted mean per control step
    steps: int  # control steps
    fall_share: float  # episodes that ended in a fall
    wants: list[tuple[float, dict[str, float]]] = field(default_factory=list)  # per foot and step: swing weight, misses
    cycle: list[tuple[float, bool, bool, float, float, float]] = field(default_factory=list)  # per foot and step:
    # its own clock phase, down, the other foot down, load share, knee [rad], sole speed [m/s]
    touchdowns: int = 0  # the feet's touchdowns (kstep's)
    clock_steps_per_s: float = 0.0  # the clock's step rate, 2 / its period
    swing_share: float = 0.4  # the clock's env.swing_share
    control_dt_s: float = 0.025


def measure(agent: Agent, episodes: int, seed: int) -> Anatomy:
    """Every term's unweighted mean per control step over ``episodes`` deterministic episodes from
    ``seed``, and, with a gait clock, each foot's misses of its wants at every step."""
    spec = EnvSpec.from_dict(agent.config)
    env = PamWalkerEnv(**spec.sections(), features=REWARD_KEYS)
    cfg, policy = env.env_cfg, make_policy(agent)
    out = Anatomy(dict.fromkeys(REWARD_KEYS, 0.0), 0, 0.0)
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        while True:
            before, contact_before = env.episode.soles, env.episode.contact
            obs, _, terminated, truncated, info = env.step(policy(obs))
            ep = env.episode
            for key, value in info["reward_unweighted"].items():
                out.means[key] += float(value)
            out.steps += 1
            out.touchdowns += sum(now and not then for now, then in zip(ep.contact, contact_before))
            if env.gait_clock and not ep.clock_stopped:
                ground = ([env.ground_height_m(float(x)) for x in ep.soles[:, :, 0].mean(axis=1)]
                          if env.on_terrain else None)
                speeds, lifts = clock.foot_motion(before, ep.soles, env.sole_radius_m, cfg.control_dt_s, ground)
                knees = [env.data.qpos[adr] for adr in env.knee_addresses]
                for foot, swing in enumerate(clock.swing_weights(ep.phase(cfg), cfg.swing_share)):
                    share = float(info["foot_force_n"][foot]) / env.weight_n
                    out.wants.append((swing, clock.foot_wants(share, speeds[foot], lifts[foot], knees[foot], cfg)))
                    out.cycle.append(((ep.phase(cfg) + 0.5 * foot) % 1.0, bool(ep.contact[foot]),
                                      bool(ep.contact[1 - foot]), share, float(knees[foot]), speeds[foot]))
            if terminated or truncated:
                out.fall_share += bool(terminated) / episodes
                break
    out.means = {k: v / out.steps for k, v in out.means.items()}
    out.clock_steps_per_s = 2.0 / cfg.gait_period_s if env.gait_clock else 0.0
    out.swing_share = cfg.swing_share
    out.control_dt_s = cfg.control_dt_s
    return out


def print_wants(anatomy: Anatomy) -> None:
    """kgait's miss split by want, in the clock's swing and in its stance."""
    seconds = anatomy.steps * anatomy.control_dt_s
    print(f"\nthe clock: {anatomy.clock_steps_per_s:.2f} steps/s asked; the feet touch down "
          f"{anatomy.touchdowns / seconds:.2f} times a second (the env's touchdowns, kstep's: a foot that unloads "
          f"below 5 % of the weight for a control step lands again)")
    for phase, names, in_phase in (("swing", clock.SWING_WANTS, lambda s: s > 0.5),
                                   ("stance", clock.STANCE_WANTS, lambda s: s <= 0.5)):
        rows = [wants for swing, wants in anatomy.wants if in_phase(swing)]
        if not rows:
            continue
        largest = [max((k for k in names if k in w), key=lambda k: w[k]) for w in rows]
        print(f"in the clock's {phase} ({len(rows)} foot-steps): miss {np.mean([w[k] for w, k in zip(rows, largest)]):.3f}")
        for name in names:
            if name in rows[0]:
                print(f"  {name:>13}: mean miss {np.mean([w[name] for w in rows]):.3f}, "
                      f"the largest in {largest.count(name) / len(rows):.0%}")


def print_cycle(anatomy: Anatomy, bins: int = 20) -> None:
    """Each foot through its own clock phase (0 to 1, the clock's swing first): what the clock asks
    and what the foot does, averaged over both feet and every stride."""
    rows = np.array(anatomy.cycle, dtype=float)
    where = np.minimum((rows[:, 0] * bins).astype(int), bins - 1)
    start = 0.25 - anatomy.swing_share / 2  # clock.swing_weights: sin 2 pi phi > cos pi sigma
    print(f"\nthrough a foot's clock phase ({bins} bins, both feet and every stride; the clock swings it from "
          f"{start:.2f} to {start + anatomy.swing_share:.2f}): the clock's swing weight, the share of steps the foot "
          f"is down, with no foot down, with both down, its load (share of the weight), knee, sole speed")
    print(f"{'phase':>9} {'swing':>6} {'down':>6} {'flight':>7} {'both':>6} {'load':>6} {'knee deg':>9} {'speed m/s':>10}")
    for b in range(bins):
        r = rows[where == b]
        if not len(r):
            continue
        mid = (b + 0.5) / bins
        swing = clock.swing_weights(mid, anatomy.swing_share)[0]
        print(f"{b / bins:4.2f}-{(b + 1) / bins:4.2f} {swing:>6.2f} {r[:, 1].mean():>6.0%} "
              f"{((r[:, 1] == 0) & (r[:, 2] == 0)).mean():>7.0%} {((r[:, 1] == 1) & (r[:, 2] == 1)).mean():>6.0%} "
              f"{r[:, 3].mean():>6.2f} {np.degrees(r[:, 4].mean()):>9.1f} {r[:, 5].mean():>10.2f}")


def stage_weights(agent: Agent) -> dict[str, dict[str, float]]:
    """The weights of each stage of the agent's run (just ``reward.*`` for a file outside a run)."""
    if agent.run_dir is None:
        spec = EnvSpec.from_dict(agent.config)
        return {"env": {k: getattr(spec.reward, k) for k in REWARD_KEYS}}
    cfg = saved_config(agent.run_dir)
    curriculum = WalkCurriculum(cfg)
    stages = {"stand": {k: getattr(cfg.reward, k) for k in REWARD_KEYS}}
    if curriculum.active:
        stages["walk"] = curriculum.weights
    if cfg.train.gait_weights:
        stages["gait"] = curriculum.gait_weights
    return stages


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("agent", help="an agent file (a run's checkpoints/*.pt)")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--seed", type=int, default=2000)
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=WEIGHT",
                        help="a column of the last stage's weights with these changed")
    args = parser.parse_args()
    agent = load_agent(args.agent)
    stages = stage_weights(agent)
    if args.set:
        changed = dict(stages[list(stages)[-1]])
        for item in args.set:
            key, _, value = item.partition("=")
            if key not in REWARD_KEYS:
                raise SystemExit(f"--set {item}: unknown weight {key!r}; known: {', '.join(REWARD_KEYS)}")
            changed[key] = float(value)
        stages["--set"] = changed
    anatomy = measure(agent, args.episodes, args.seed)
    means, last = anatomy.means, list(stages)[-1]
    print(f"{Path(args.agent)}: {args.episodes} episodes from seed {args.seed}, {anatomy.steps} control steps, "
          f"falls {anatomy.fall_share:.0%}; mean per step, unweighted and weighted by each stage")
    print(f"{'term':>8} {'feature':>10} " + " ".join(f"{name:>9}" for name in stages))
    order = sorted(REWARD_KEYS, key=lambda k: -abs(stages[last][k] * means[k]))
    for key in order:
        if not any(w[key] for w in stages.values()) and not means[key]:
            continue
        print(f"{key:>8} {means[key]:>10.4f} " + " ".join(f"{w[key] * means[key]:>9.3f}" for w in stages.values()))
    print(f"{'total':>8} {'':>10} " + " ".join(f"{sum(w[k] * means[k] for k in REWARD_KEYS):>9.3f}"
                                               for w in stages.values()))
    if anatomy.wants:
        print_wants(anatomy)
        print_cycle(anatomy)
    if np.isnan(sum(means.values())):
        raise SystemExit("a term came out NaN")


if __name__ == "__main__":
    main()
