"""``pamrun sweep -m``: a grid of trainings, each evaluated, and a summary that answers
"which setting is better, and how sure are we".

Each combination of the sweep's overrides is one Hydra job (:func:`job`): it trains (or
resumes an interrupted training), evaluates the run's agents into ``<job>/eval/`` and
writes ``job.json`` with its status and metrics. Jobs run side by side through Hydra's
joblib launcher (``conf/config_sweep.yaml``), or on SLURM / Ray with the launcher configs in
``conf/hydra/launcher/``. Each job's directory is named by its overrides, and the sweep
directory by the command's overrides, so the same command again skips finished jobs and
resumes interrupted ones. A failing job is recorded (``job.json``, ``error.txt``) and
the others go on.

The summary (:func:`summarize`; at the end of a sweep and by ``pamrun sweep summarize
dir=<sweep dir>``) groups jobs by their overrides without the seed and gives, per group,
the mean and 95 % confidence interval (Student's t) of the final average reward, the best
evaluation distance, the walk-test pass rate and the frames to the first saved agent:
``summary.csv``, ``summary.md``, ``curves.png`` and a rich table.
"""

from __future__ import annotations

import copy
import csv
import json
import math
import os
import time
import traceback
from pathlib import Path
from typing import Any

import numpy as np
from hydra.core.hydra_config import HydraConfig
from hydra.experimental.callback import Callback
from omegaconf import DictConfig, OmegaConf
from rich.table import Table
from scipy import stats

from pamrun.config import JOB_METRICS, Config, to_object
from pamrun.runs.directory import RunFiles, read_episodes, read_evals, saved_config
from pamrun.runs.files import console as make_console
from pamrun.runs.files import read_json, write_json
from pamrun.runs.machine import (
    usable_cores,  # importing it registers the resolvers of conf/config_sweep.yaml
)
from pamrun.sweep import figures

JOB_FILE = "job.json"
FINISHED_TRAINING = ("max_frames", "max_episodes", "max_minutes", "target_avg_reward")
# Of the last evaluation during training and the best (best_eval.pt's): job.json's eval_last_<key>, eval_best_<key>
EVAL_METRICS = ("walk_pass_rate", "stand_rate", "distance_mean", "speed_mean", "step_frequency_hz_mean",
                "duty_factor_mean", "stop_share_gait_max_mean", "cost_of_transport_mean")
HPARAM_METRICS = (*JOB_METRICS, *(f"eval_{which}_{key}" for which in ("last", "best") for key in EVAL_METRICS))
METRIC_LABELS = {"final_avg_reward": "final avg reward", "best_distance_m": "best distance (m)",
                 "walk_pass_rate": "walk pass rate", "frames_to_first_save": "frames to 1st save"}


# --------------------------------------------------------------------------- one job


def write_job(job_dir: Path, record: dict) -> None:
    write_json(Path(job_dir) / JOB_FILE, record)


def job(dcfg: DictConfig) -> dict:
    """The Hydra task of ``pamrun sweep``: train (or resume), evaluate, record; never raises
    for a bad combination or a crash, so one failure does not stop the sweep."""
    hc = HydraConfig.get()
    out = Path(hc.runtime.output_dir)
    record = read_json(out / JOB_FILE)
    if record.get("status") == "done":
        print(f"[sweep] {out.name}: already done, skipped")
        return record
    os.environ["PAMRUN_PROGRESS"] = "lines"  # several jobs may share one terminal
    record = {"job": out.name, "overrides": list(hc.overrides.task), "status": "running",
              "start": time.strftime("%Y-%m-%dT%H:%M:%S"), "attempts": record.get("attempts", 0) + 1}
    write_job(out, record)
    print(f"[sweep] {out.name}: started (attempt {record['attempts']})")
    try:
        record.update(run_job(dcfg, out, hc))
        record["status"] = "done"
    except KeyboardInterrupt:
        record["status"] = "interrupted"
        raise
    except SystemExit as err:
        if err.code in (130, 143):  # its training was stopped by a signal, after a final checkpoint
            record["status"] = "interrupted" if err.code == 130 else "terminated"
            raise
        record.update(status="failed", error=f"{type(err).__name__}: {err}")
        (out / "error.txt").write_text(traceback.format_exc())
    except BaseException as err:  # a bad value or a crash fails this job alone
        record.update(status="failed", error=f"{type(err).__name__}: {err}")
        (out / "error.txt").write_text(traceback.format_exc())
    finally:
        record["end"] = time.strftime("%Y-%m-%dT%H:%M:%S")
        write_job(out, record)
    print(f"[sweep] {out.name}: {record['status']}" + (f" ({record['error']})" if "error" in record else ""))
    return record


def run_job(dcfg: DictConfig, out: Path, hc) -> dict:
    """Train (or resume), then evaluate the run's agents; the job's metrics."""
    # heavy (torch, TorchRL: ~5 s): only a job trains; pamrun sweep summarize and the sweep's own process do not
    from pamrun.evaluation.evaluate import run_evaluation
    from pamrun.training.recipe import train

    cfg: Config = to_object(dcfg)  # raises ConfigError for an impossible combination
    share = job_cores(hc)
    dcfg = copy.deepcopy(dcfg)
    if not cfg.train.threads:
        dcfg.train.threads = max(1, share - cfg.train.workers + 1)
    files = RunFiles(out)
    if read_json(files.run_json).get("status") not in FINISHED_TRAINING:
        if files.last.exists():
            dcfg.resume = str(out)
        train(to_object(dcfg), out, list(hc.overrides.task))
    if not (out / "eval" / "selection.json").exists():
        if not cfg.eval.workers:
            cfg.eval.workers = share
        run_evaluation(cfg, str(out), out / "eval")
    metrics = job_metrics(out)
    write_hparams(out, hparams_of(list(hc.overrides.task)), metrics)
    return {"metrics": metrics}


def job_cores(hc) -> int:
    """Cores one job may use: its share of this machine (joblib), its Ray reservation, or
    its allocation (SLURM: the CPU affinity)."""

    ray_cpus = OmegaConf.select(hc, "launcher.ray.remote.num_cpus", default=None)
    if ray_cpus:
        return max(1, int(ray_cpus))
    n_jobs = int(OmegaConf.select(hc, "launcher.n_jobs", default=1) or 1)
    return max(1, usable_cores() // n_jobs)


def job_metrics(job_dir: Path) -> dict[str, float | None]:
    """What the summary compares, from the files a job left (episodes.csv, eval/)."""
    files = RunFiles(job_dir)
    rows = read_episodes(job_dir) if files.episodes.exists() else []
    cfg = saved_config(job_dir) if files.config.exists() else Config()
    threshold = float(cfg.train.save_threshold)
    first_save = next((int(r["frames"]) for r in rows if float(r["reward"]) >= threshold), None)
    agents = read_json(job_dir / "eval" / "leaderboard.json").get("agents", [])
    run = read_json(files.run_json)
    return {
        "final_avg_reward": float(rows[-1]["avg_reward"]) if rows else None,
        "best_distance_m": max((a["distance_mean"] for a in agents), default=None),
        "walk_pass_rate": max((a["walk_pass_rate"] for a in agents), default=None),
        "frames_to_first_save": first_save,
        "frames": run.get("frames"),
        "episodes": run.get("episodes"),
        "train_wall_time_s": run.get("wall_time_s"),
        **training_evals(job_dir),
    }


def training_evals(job_dir: Path) -> dict[str, float | None]:
    """:data:`EVAL_METRICS` of the last evaluation during training and of the best (evals.csv);
    None where there is none or the value is undefined."""
    rows = read_evals(job_dir)
    best = [r for r in rows if r.get("best") == "1"]
    out = {}
    for which, row in (("last", rows[-1] if rows else {}), ("best", best[-1] if best else {})):
        for key in EVAL_METRICS:
            value = float(row.get(key) or "nan")  # (a column an older evals.csv lacks reads "")
            out[f"eval_{which}_{key}"] = value if math.isfinite(value) else None
    return out


def hparams_of(overrides: list[str]) -> dict[str, Any]:
    """Overrides as TensorBoard hyperparameters (numbers where they parse)."""
    out: dict[str, Any] = {}
    for item in overrides:
        key, _, value = item.lstrip("+~").partition("=")
        try:
            out[key] = float(value) if any(c in value for c in ".eE") else int(value)
        except ValueError:
            out[key] = value
    return out


def write_hparams(job_dir: Path, hparams: dict, metrics: dict) -> None:
    """The job's row of TensorBoard's HParams view (``tensorboard --logdir <sweep dir>``): the
    metrics of :data:`HPARAM_METRICS`, NaN where undefined (every job names them all: TensorBoard
    takes the columns from one job's record)."""
    from torch.utils.tensorboard import SummaryWriter  # heavy (torch, TensorBoard): only a job writes it

    values = {f"sweep/{k}": math.nan if metrics.get(k) is None else float(metrics[k]) for k in HPARAM_METRICS}
    with SummaryWriter(str(job_dir / "tensorboard")) as writer:
        writer.add_hparams(hparams or {"setting": "default"}, values, run_name=".")


# --------------------------------------------------------------------------- the summary


def collect_jobs(sweep_dir: Path) -> list[dict]:
    """Every job of a sweep (each folder with a job.json), with its directory."""
    jobs = []
    for path in sorted(Path(sweep_dir).glob(f"*/{JOB_FILE}")):
        record = json.loads(path.read_text())
        record["dir"] = str(path.parent)
        jobs.append(record)
    return jobs


def group_key(overrides: list[str], exclude: list[str]) -> tuple[str, ...]:
    return tuple(sorted(o for o in overrides if o.lstrip("+~").split("=", 1)[0] not in exclude))


def mean_ci(values: list[float], confidence: float = 0.95) -> tuple[float, float]:
    """Mean and half-width of its ``confidence`` interval (Student's t; NaN for fewer than 2)."""
    x = np.asarray([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if len(x) == 0:
        return math.nan, math.nan
    if len(x) < 2:
        return float(x.mean()), math.nan
    half = stats.t.ppf(0.5 + confidence / 2, len(x) - 1) * x.std(ddof=1) / math.sqrt(len(x))
    return float(x.mean()), float(half)


def summarize(sweep_dir: Path, exclude: list[str], metric: str = "final_avg_reward",
              direction: str = "maximize") -> dict:
    """Group the jobs, write summary.csv, summary.md and curves.png; the groups and the verdict."""
    sweep_dir = Path(sweep_dir)
    jobs = collect_jobs(sweep_dir)
    if not jobs:
        raise SystemExit(f"pamrun: no sweep jobs (*/{JOB_FILE}) in {sweep_dir}")
    groups: dict[tuple, list[dict]] = {}
    for j in jobs:
        groups.setdefault(group_key(j["overrides"], exclude), []).append(j)
    common = set.intersection(*(set(k) for k in groups))  # shown once, not in every row
    rows = []
    for key, members in groups.items():
        done = [j for j in members if j["status"] == "done"]
        row = {"setting": ", ".join(o for o in key if o not in common) or "(all)",
               "overrides": " ".join(key), "jobs": len(members), "done": len(done),
               "failed": sum(j["status"] == "failed" for j in members),
               "seeds": " ".join(sorted((o.split("=", 1)[1] for j in members for o in j["overrides"]
                                         if o.split("=", 1)[0] in exclude), key=str)),
               "job_dirs": [j["dir"] for j in done]}
        for name in JOB_METRICS:
            values = [j["metrics"][name] for j in done if j.get("metrics", {}).get(name) is not None]
            row[name], row[f"{name}_ci95"] = mean_ci(values)
            row[f"{name}_n"] = len(values)
            row[f"{name}_values"] = values
        rows.append(row)
    sign = 1 if direction == "maximize" else -1
    rows.sort(key=lambda r: (-sign * r[metric] if math.isfinite(r[metric]) else math.inf, r["setting"]))
    verdict = compare(rows, metric, direction)
    failed = [{"job": j["job"], "error": j.get("error", j["status"])} for j in jobs if j["status"] != "done"]
    write_summary_files(sweep_dir, rows, common, verdict, failed)
    curves = [(r["setting"], [RunFiles(d).episodes for d in r["job_dirs"]]) for r in rows]
    figures.sweep_curves(curves, sweep_dir / "curves.png")
    return {"rows": rows, "common": sorted(common), "verdict": verdict, "failed": failed, "jobs": len(jobs)}


def compare(rows: list[dict], metric: str, direction: str) -> str:
    """Which group is best on ``metric``, and whether the runner-up is distinguishable (Welch's t-test)."""
    ranked = [r for r in rows if math.isfinite(r[metric])]
    label = METRIC_LABELS[metric]
    if not ranked:
        return f"No finished job has a {label}."
    best = ranked[0]
    text = (f"By {label} ({'higher' if direction == 'maximize' else 'lower'} is better), the best setting is "
            f"{best['setting']} ({fmt_ci(best[metric], best[f'{metric}_ci95'])}, n={best[f'{metric}_n']})")
    if len(ranked) < 2:
        return text + "."
    second = ranked[1]
    a, b = best[f"{metric}_values"], second[f"{metric}_values"]
    if len(a) < 2 or len(b) < 2:
        return text + f"; runner-up {second['setting']} ({fmt_ci(second[metric], math.nan)}): too few seeds to tell."
    p = stats.ttest_ind(a, b, equal_var=False).pvalue
    p = 1.0 if not math.isfinite(p) else p
    sure = "a real difference at 95 %" if p < 0.05 else "not distinguishable at 95 %: run more seeds"
    return (text + f"; runner-up {second['setting']} ({fmt_ci(second[metric], second[f'{metric}_ci95'])}): "
            f"Welch's t-test p = {p:.3f}, {sure}.")


def fmt_ci(mean: float, half: float, digits: int = 2) -> str:
    if not math.isfinite(mean):
        return "n/a"
    return f"{mean:.{digits}f}" + (f" ± {half:.{digits}f}" if math.isfinite(half) else "")


def write_summary_files(sweep_dir: Path, rows: list[dict], common: set, verdict: str, failed: list[dict]) -> None:
    fields = ["setting", "overrides", "jobs", "done", "failed", "seeds"] + [
        f"{m}{s}" for m in JOB_METRICS for s in ("", "_ci95", "_n")]
    with (sweep_dir / "summary.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    lines = [f"# Sweep summary: {sweep_dir.name}", "",
             f"Common to every job: `{' '.join(sorted(common))}`" if common else "", "",
             "Mean ± 95 % confidence interval (Student's t) over seeds.", "",
             "| setting | done/jobs | " + " | ".join(METRIC_LABELS[m] for m in JOB_METRICS) + " |",
             "|---|---|" + "---|" * len(JOB_METRICS)]
    for r in rows:
        cells = [fmt_ci(r[m], r[f"{m}_ci95"], 0 if m == "frames_to_first_save" else 2)
                 + (f" ({r[f'{m}_n']}/{r['done']} saved)" if m == "frames_to_first_save" else "")
                 for m in JOB_METRICS]
        lines.append(f"| {r['setting']} | {r['done']}/{r['jobs']} | " + " | ".join(cells) + " |")
    lines += ["", f"**{verdict}**", ""]
    if failed:
        lines += ["Jobs not done:", ""] + [f"- `{f['job']}`: {f['error']}" for f in failed] + [""]
    lines += ["![learning curves](curves.png)", ""]
    (sweep_dir / "summary.md").write_text("\n".join(lines))


def summary_table(result: dict):
    table = Table(title="Sweep summary (mean ± 95 % CI over seeds)",
                  caption=("common: " + " ".join(result["common"])) if result["common"] else None)
    for col in ("setting", "done", *(METRIC_LABELS[m] for m in JOB_METRICS)):
        table.add_column(col, justify="left" if col == "setting" else "right", overflow="fold")
    for r in result["rows"]:
        done = f"{r['done']}/{r['jobs']}" + (f" [red]({r['failed']} failed)[/red]" if r["failed"] else "")
        cells = [fmt_ci(r[m], r[f"{m}_ci95"], 0 if m == "frames_to_first_save" else 2) for m in JOB_METRICS]
        cells[-1] += f" ({r['frames_to_first_save_n']}/{r['done']})"
        table.add_row(r["setting"], done, *cells)
    return table


def print_summary(result: dict, sweep_dir: Path) -> None:
    console = make_console()
    console.print(summary_table(result))
    console.print(result["verdict"], soft_wrap=True)
    for f in result["failed"]:
        console.print(f"[red]not done[/red] {f['job']}: {f['error']}", soft_wrap=True)
    console.print(f"Wrote {sweep_dir / 'summary.csv'}, summary.md, curves.png. "
                  f"TensorBoard HParams: tensorboard --logdir {sweep_dir}", soft_wrap=True)


class SummarizeAtEnd(Callback):
    """Hydra callback of ``pamrun sweep``: the summary once every job has returned."""

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(str(config.hydra.sweep.dir))
        result = summarize(sweep_dir, list(config.sweep.group_exclude), config.sweep.metric, config.sweep.direction)
        print_summary(result, sweep_dir)
        failed = [j for j in collect_jobs(sweep_dir) if j.get("status") != "done"]
        if failed:  # the others finished; the sweep still says it did not all go through
            raise SystemExit(f"pamrun: {len(failed)} sweep job(s) did not finish: "
                             + ", ".join(f"{j.get('job')} ({j.get('status')})" for j in failed))


def summarize_command(dcfg: DictConfig) -> None:
    """``pamrun sweep summarize dir=<sweep dir>``."""
    cfg = to_object(dcfg)
    if not cfg.dir:
        raise SystemExit("pamrun: pass dir=<sweep directory>")
    result = summarize(Path(cfg.dir), list(cfg.sweep.group_exclude), cfg.sweep.metric, cfg.sweep.direction)
    print_summary(result, Path(cfg.dir))
