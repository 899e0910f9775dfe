"""The console's tables of an evaluation: the leaderboard, the gait metrics per agent and the
robustness suite's agent x perturbation cells."""

from __future__ import annotations

import math

from rich.table import Table

from pamrun.evaluation.ranking import pass_text
from pamrun.evaluation.targets import WALK_TARGETS, bounds_text, met


def leaderboard_table(ranked: list[dict], ecfg, limit: int = 20):
    table = Table(title=f"Leaderboard ({ecfg.episodes} episodes each, seeds {ecfg.seed}..{ecfg.seed + ecfg.episodes - 1}; "
                        f"ranked by {', '.join(ecfg.rank_by)})")
    for col in ("#", "agent", "walk test (95 % CI)", "distance (m)", "min (m)", "return", "time (s)", "falls",
                "max |y| (m)", "dP (kPa/step)"):
        table.add_column(col, justify="left" if col == "agent" else "right", no_wrap=col != "agent", overflow="fold")
    for row in ranked[:limit]:
        verdict = f"[green]{pass_text(row)}[/green]" if row["walk_test"] else pass_text(row)
        table.add_row(str(row["rank"]), row["agent"], verdict,
                      f"{row['distance_mean']:.2f} ± {row['distance_std']:.2f}", f"{row['distance_min']:.2f}",
                      f"{row['return_mean']:.1f} ± {row['return_std']:.1f}", f"{row['duration_mean']:.2f}",
                      f"{row['fall_rate']:.0%}", f"{row['max_abs_y_max']:.3f}", f"{row['pressure_change_mean']:.1f}")
    if len(ranked) > limit:
        table.caption = f"{len(ranked) - limit} more in leaderboard.csv"
    return table


def gait_table(ranked: list[dict], limit: int = 20):
    """The gait metrics' means (and spreads) per agent (pamrun.evaluation.metrics defines them)."""
    table = Table(title="Gait (means ± std over episodes; 'hops': touchdowns with both feet together; 'at a stop': "
                        "the joint most often within 2° of a stop, knees only in swing; reach: a landing foot ahead of the torso; 'both down / flight': shares "
                        "of the time after the first second; knee: flexion at mid-stance / its peak in swing / at touchdown; hip: its largest flexion in swing / at touchdown / its largest extension in stance; sole tilt: a foot on the ground, side to side; lean / sway: the torso's pitch, + forward / how far it rocks side to side; "
                        "clock: the median touchdown's lag behind its gait clock's, in periods / the share within 0.1 of it)")
    for col in ("#", "agent", "speed (m/s)", "cadence (steps/s)", "stride (m)", "reach (m)", "symmetry time/length", "hops", "duty",
                "both down / flight", "knee stance / swing / landing (°)", "hip swing / landing / ext (°)", "at a stop", "clearance (m)", "slip (m/s)", "sole tilt (°)", "lean / sway (°)", "clock", "CoT",
                "air (NL/m)", "walk targets"):
        table.add_column(col, justify="left" if col == "agent" else "right", no_wrap=col != "agent", overflow="fold")

    def pm(row: dict, name: str, fmt: str = ".2f") -> str:
        return f"{row[f'{name}_mean']:{fmt}} ± {row[f'{name}_std']:{fmt}}"

    for row in ranked[:limit]:
        table.add_row(str(row["rank"]), row["agent"], pm(row, "speed"), pm(row, "step_frequency_hz"),
                      pm(row, "stride_length_m"), pm(row, "touchdown_reach_m"),
                      f"{row['step_time_symmetry_mean']:.2f} / {row['step_length_symmetry_mean']:.2f}",
                      f"{row['hop_share_mean']:.0%}", f"{row['duty_factor_mean']:.2f}",
                      f"{row['double_support_share_mean']:.0%} / {row['flight_share_mean']:.0%}",
                      f"{row['knee_midstance_deg_mean']:.0f} / {row['knee_swing_peak_deg_mean']:.0f} / {row['knee_touchdown_deg_mean']:.0f}",
                      f"{row['hip_swing_peak_deg_mean']:.0f} / {row['hip_touchdown_deg_mean']:.0f} / {row['hip_extension_deg_mean']:.0f}", f"{row['stop_share_gait_max_mean']:.0%}",
                      pm(row, "swing_clearance_m", ".3f"), pm(row, "foot_slip_m_s"),
                      pm(row, "sole_tilt_deg", ".0f"), f"{row['torso_pitch_deg_mean']:.0f} / {row['torso_sway_deg_mean']:.0f}", _clock(row), pm(row, "cost_of_transport"), pm(row, "air_nl_per_m", ".1f"),
                      f"{row['walk_targets_met']}/{len(WALK_TARGETS)}")
    return table


def _clock(row: dict) -> str:
    """The gait table's clock cell: the touchdowns' median lag and their share on the clock; '-' without a clock."""
    lag, share = row["touchdown_clock_offset_mean"], row["touchdown_on_clock_share_mean"]
    return "-" if math.isnan(lag) else f"{lag:+.2f} / {share:.0%}"


def targets_table(row: dict):
    """One agent's means against the walk's targets (pamrun.evaluation.targets), each met or missed."""
    table = Table(title=f"Walk targets: {row['agent']} (episode means; targets from human walking near 1 m/s)")
    for col in ("metric", "target", "value", ""):
        table.add_column(col, justify="left" if col in ("metric", "") else "right", no_wrap=True)
    for key in WALK_TARGETS:
        value = row.get(key, float("nan"))
        name = "pressure_change_kpa" if key == "pressure_change_mean" else key.removesuffix("_mean")  # per control step
        table.add_row(name, bounds_text(key), f"{value:.3g}",
                      "[green]met[/green]" if met(key, value) else "[red]missed[/red]")
    table.caption = f"{row['walk_targets_met']} of {len(WALK_TARGETS)} met"
    return table


def robustness_table(rows: list[dict], ecfg):
    table = Table(title=f"Robustness ({ecfg.episodes} episodes per cell, seeds {ecfg.seed}.."
                        f"{ecfg.seed + ecfg.episodes - 1}; walk test with its 95 % Wilson interval)")
    for col in ("agent", "perturbation", "what", "walk test (95 % CI)", "stands", "distance (m)", "blow-ups"):
        table.add_column(col, justify="left" if col in ("agent", "perturbation", "what") else "right",
                         no_wrap=col != "agent", overflow="fold")
    for row in rows:
        table.add_row(row["agent"], row["perturbation"], row["note"], pass_text(row), f"{row['stand_rate']:.0%}",
                      f"{row['distance_mean']:.2f} ± {row['distance_std']:.2f}", f"{row['physics_error_rate']:.0%}")
    return table
