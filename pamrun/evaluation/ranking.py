"""Ranking evaluated agents: the order of ``eval.rank_by``, why the first won, the pass count in
words, and whether an evaluation's seeds are held out from those its agents were selected on."""

from __future__ import annotations

import numpy as np

from pamrun.learning.checkpoints import Agent


def pass_text(row: dict) -> str:
    """'41/50 (69-90 %)': passes of episodes with the 95 % Wilson interval."""
    return (f"{row['walk_passes']}/{row['episodes']} ({100 * row['walk_pass_ci_low']:.0f}-"
            f"{100 * row['walk_pass_ci_high']:.0f} %)")


def rank(rows: list[dict], rank_by: list[str]) -> list[dict]:
    """Rows sorted best first by ``rank_by`` (descending; '-name' ascending), ties by label.
    Each row gets its 1-based ``rank``; a NaN ranks last, and so does an agent any of whose
    episodes blew up in the physics (its numbers mean nothing)."""
    def key(row: dict) -> tuple:
        out = [row.get("physics_error_rate", 0.0) > 0]
        for name in rank_by:
            value = float(row[name.lstrip("-")])
            value = value if name.startswith("-") else -value
            out.append(np.inf if np.isnan(value) else value)
        return (*out, row["agent"])

    ranked = sorted(rows, key=key)
    for n, row in enumerate(ranked, 1):
        row["rank"] = n
    return ranked


def selection_reason(ranked: list[dict], rank_by: list[str]) -> str:
    """Why the first row won, in words."""
    best = ranked[0]
    by = ", then ".join(f"{n.lstrip('-')} = {best[n.lstrip('-')]:.4g}" + (" (lower is better)" if n[0] == "-" else "")
                        for n in rank_by)
    text = f"{best['agent']} ranks first of {len(ranked)} by {by}"
    if len(ranked) > 1:
        second = ranked[1]
        diff = next((n.lstrip("-") for n in rank_by if second[n.lstrip("-")] != best[n.lstrip("-")]), None)
        text += (f"; runner-up {second['agent']} has {diff} = {second[diff]:.4g}" if diff
                 else f"; tied with {second['agent']} on every criterion, first by name")
    return text + "."


def selection_block(agent: Agent, cfg) -> range:
    """The seeds ``agent`` was selected on: those its best_eval record names, else (an agent
    saved before the record) ``eval.selection_seed`` onwards for its evaluation's episodes."""
    record = agent.meta.get("eval") or {}
    if "seeds" in record:
        return range(int(record["seeds"][0]), int(record["seeds"][1]) + 1)
    return range(cfg.eval.selection_seed,
                 cfg.eval.selection_seed + int(record.get("episodes") or cfg.train.eval_episodes))


def held_out(agents: list[Agent], cfg) -> bool:
    """Whether the evaluation's seeds miss every agent's selection block."""
    seeds = set(range(cfg.eval.seed, cfg.eval.seed + cfg.eval.episodes))
    return not any(seeds & set(selection_block(a, cfg)) for a in agents)


def warn_if_not_held_out(agents: list[Agent], cfg, console) -> bool:
    ok = held_out(agents, cfg)
    if not ok:
        console.print(f"[red]Seeds {cfg.eval.seed}..{cfg.eval.seed + cfg.eval.episodes - 1} overlap the seeds an "
                      f"agent was selected on: these numbers are biased (use eval.seed >= 1000)[/red]", soft_wrap=True)
    return ok
