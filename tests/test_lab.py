"""End-to-end: the `pamrun muscle` commands write their files with the thesis' numbers."""

from __future__ import annotations

import json

from tests.test_config import run_pamrun


def test_muscle_step_writes_json_and_png(tmp_path):
    run_dir = tmp_path / "step"
    proc = run_pamrun("muscle", "step", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    assert f"Run directory: {run_dir}" in proc.stdout.replace("\n", "")
    data = json.loads((run_dir / "step_response.json").read_text())
    finals = {k: v["final_contraction_pct"] for k, v in data["experiments"].items()}
    thesis = {"plus_minus_1bar": [20.22, 3.44], "max_and_1bar": [28.12, 6.28]}
    for name, expected in thesis.items():
        for got, want in zip(finals[name], expected):
            assert abs(got - want) <= 0.5
    assert (run_dir / "step_response.png").stat().st_size > 10_000
    assert "within 0.5 points of the thesis: yes" in proc.stdout


def test_muscle_step_reports_a_miss(tmp_path):
    """A spring table far from the calibrated one must show up as a miss, not pass silently."""
    proc = run_pamrun(
        "muscle", "step", "muscle.spring.stiffness_n_per_m=[5000,5000,5000,5000,5000,5000,5000,5000]",
        f"hydra.run.dir={tmp_path / 'miss'}",
    )
    assert proc.returncode == 0, proc.stderr
    assert "within 0.5 points of the thesis: NO" in proc.stdout


def test_muscle_curves_writes_figures(tmp_path):
    run_dir = tmp_path / "curves"
    proc = run_pamrun("muscle", "curves", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    for name in ("force_curves.png", "force_surface.png", "force_curves.json"):
        assert (run_dir / name).stat().st_size > 1000
    data = json.loads((run_dir / "force_curves.json").read_text())
    assert min(min(row) for row in data["force_n"]) >= 0


def test_muscle_calibrate_writes_yaml_without_touching_conf(tmp_path):
    run_dir = tmp_path / "cal"
    proc = run_pamrun(
        "muscle", "calibrate", "pair.calibrate_write_conf=false", "pair.duration_s=1.5", "pair.dt_s=0.002",
        f"hydra.run.dir={run_dir}",
    )
    assert proc.returncode == 0, proc.stderr
    text = (run_dir / "spring_table.yaml").read_text()
    assert "stiffness_n_per_m" in text and "Fitted bands" in text
