"""``pamrun sweep optuna``: hyperparameter search with Optuna, each trial averaged over seeds.

A trial samples the overrides of ``sweep.optuna.params`` (TPE sampler), runs them as one
``pamrun sweep -m seed=<seeds>`` in ``<study dir>/trial-<hash of its overrides>`` (jobs side
by side, failures recorded, finished seeds skipped on a rerun) and is worth the mean of
``sweep.metric`` over the seeds that finished. The study lives in ``<study dir>/study.db``
(SQLite); the study directory is named by the command line, so the same command resumes
the search: finished trials count, and a trial cut off by Ctrl-C or a crash is run again
from its folder. ``trials.csv``, ``best.json`` and ``optuna.png`` sum it up.
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import subprocess
import sys
from pathlib import Path

import optuna
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig
from optuna.trial import TrialState
from rich.table import Table

from pamrun.config import to_object
from pamrun.runs.files import console as make_console
from pamrun.runs.files import run_dir
from pamrun.sweep import figures
from pamrun.sweep.grid import collect_jobs
from pamrun.sweep.overrides import task_overrides

STALE = "interrupted"  # user attribute of a trial a previous run left unfinished


def suggest(trial, params: dict[str, str]) -> list[str]:
    """The trial's overrides, one per searched key (``float:``, ``log:``, ``int:``, ``choice:``)."""
    out = []
    for key, spec in params.items():
        kind, _, rest = spec.partition(":")
        if kind == "choice":
            value = trial.suggest_categorical(key, rest.split(","))
        elif kind == "int":
            low, high = (int(float(v)) for v in rest.split(":"))
            value = trial.suggest_int(key, low, high)
        else:
            low, high = (float(v) for v in rest.split(":"))
            value = trial.suggest_float(key, low, high, log=kind == "log")
        out.append(f"{key}={value}")
    return out


def trial_value(trial_dir: Path, metric: str) -> tuple[float | None, int, int]:
    """Mean of ``metric`` over the trial's finished seeds; (value, seeds done, seeds in all)."""
    jobs = collect_jobs(trial_dir) if trial_dir.exists() else []
    values = [j["metrics"][metric] for j in jobs if j["status"] == "done" and j["metrics"].get(metric) is not None]
    return (sum(values) / len(values) if values else None), len(values), len(jobs)


def run_trial(overrides: list[str], seeds: list[int], base: list[str], trial_dir: Path) -> None:
    """One ``pamrun sweep -m`` over the seeds, in its own process (Hydra runs one app per process)."""
    cmd = [sys.executable, "-m", "pamrun.cli", "sweep", "-m", *base, *overrides,
           f"seed={','.join(str(s) for s in seeds)}", f"hydra.sweep.dir={trial_dir}"]
    subprocess.run(cmd, check=False)


def optuna_search(dcfg: DictConfig) -> None:
    """The Hydra task of ``pamrun sweep optuna``."""
    console = make_console()
    cfg = to_object(dcfg)
    ocfg, metric = cfg.sweep.optuna, cfg.sweep.metric
    if not ocfg.params:
        raise SystemExit("pamrun: sweep.optuna.params is empty: nothing to search "
                         "(e.g. sweep=reward_search, or '++sweep.optuna.params={reward.kz: float:10:100}')")
    out = run_dir()
    searched = set(ocfg.params)
    base = [o for o in task_overrides(list(HydraConfig.get().overrides.task))
            if o.lstrip("+~").split("=", 1)[0] not in searched | {"seed"}
            and not o.lstrip("+~").startswith("sweep.optuna.")]
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    study = optuna.create_study(study_name="pamrun", storage=f"sqlite:///{out / 'study.db'}", load_if_exists=True,
                                direction=cfg.sweep.direction,
                                sampler=optuna.samplers.TPESampler(seed=ocfg.sampler_seed))
    for stale in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,)):  # cut off last time
        optuna.Trial(study, stale._trial_id).set_user_attr(STALE, True)
        study.tell(stale.number, state=TrialState.FAIL)
        study.enqueue_trial(stale.params)
    counted = [t for t in study.get_trials(deepcopy=False) if t.state.is_finished() and not t.user_attrs.get(STALE)]
    remaining = ocfg.trials - len(counted)
    console.print(f"Optuna study {out / 'study.db'}: {len(counted)} trial(s) done, {max(0, remaining)} to run; "
                  f"objective: mean {metric} over seeds {list(ocfg.seeds)} ({cfg.sweep.direction})", soft_wrap=True)
    for _ in range(max(0, remaining)):
        trial = study.ask()
        overrides = suggest(trial, dict(ocfg.params))
        trial_dir = out / ("trial-" + hashlib.sha1(" ".join(sorted(overrides)).encode()).hexdigest()[:8])
        trial.set_user_attr("dir", trial_dir.name)
        trial.set_user_attr("overrides", overrides)
        console.print(f"[bold]trial {trial.number}[/bold]: {' '.join(overrides)} -> {trial_dir.name}")
        run_trial(overrides, list(ocfg.seeds), base, trial_dir)
        value, done, total = trial_value(trial_dir, metric)
        trial.set_user_attr("seeds_done", done)
        if value is None or not math.isfinite(value):
            study.tell(trial, state=TrialState.FAIL)
            console.print(f"trial {trial.number}: [red]failed[/red] (no seed finished with a {metric})")
        else:
            study.tell(trial, value)
            console.print(f"trial {trial.number}: {metric} = {value:.4g} (mean of {done}/{total} seeds)")
    write_study(study, out, metric, console)


def write_study(study, out: Path, metric: str, console) -> None:
    """trials.csv, best.json, optuna.png and a table of the trials."""
    trials = [t for t in study.get_trials(deepcopy=False) if not t.user_attrs.get(STALE)]
    keys = sorted({k for t in trials for k in t.params})
    rows = [{"trial": t.number, "state": t.state.name, "value": t.value, "seeds_done": t.user_attrs.get("seeds_done"),
             "dir": t.user_attrs.get("dir"), **{k: t.params.get(k) for k in keys}} for t in trials]
    with (out / "trials.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=["trial", "state", "value", "seeds_done", *keys, "dir"])
        writer.writeheader()
        writer.writerows(rows)
    complete = [t for t in trials if t.state == TrialState.COMPLETE]
    table = Table(title=f"Optuna trials (mean {metric} over seeds)")
    for col in ("trial", "state", metric, *keys):
        table.add_column(col, justify="right")
    for r in rows:
        value = "" if r["value"] is None else f"{r['value']:.4g}"
        table.add_row(str(r["trial"]), r["state"], value, *(str(r[k]) for k in keys))
    console.print(table)
    if complete:
        best = study.best_trial
        (out / "best.json").write_text(json.dumps({"trial": best.number, "value": best.value, "metric": metric,
                                                   "params": best.params, "dir": best.user_attrs.get("dir")},
                                                  indent=2))
        console.print(f"Best: trial {best.number}, {metric} = {best.value:.4g}: "
                      + " ".join(f"{k}={v}" for k, v in best.params.items()), soft_wrap=True)
    figures.optuna_history([(r["trial"], r["value"]) for r in rows if r["state"] == "COMPLETE"],
                         study.direction.name.lower(), metric, out / "optuna.png")
    console.print(f"Wrote {out / 'trials.csv'}, best.json, optuna.png")
