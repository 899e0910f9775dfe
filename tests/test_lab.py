"""End-to-end: the `pamrun muscle` commands write their files with the thesis' numbers."""

from __future__ import annotations

import json

from pamrun.config import CONF_DIR, SPRING_FILE
from tests.conftest import run_pamrun


def test_muscle_step_writes_json_and_png(tmp_path):
    run_dir = tmp_path / "step"
    proc = run_pamrun("muscle", "step", "muscle=thesis", f"hydra.run.dir={run_dir}")
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
        "muscle", "step", "muscle=thesis", "muscle.spring.stiffness_n_per_m=[5000,5000,5000,5000,5000,5000,5000,5000]",
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
    before, mtime = SPRING_FILE.read_text(), SPRING_FILE.stat().st_mtime_ns
    proc = run_pamrun(
        "muscle", "calibrate", "muscle=thesis", "pair.calibrate_write_conf=false", "pair.duration_s=1.5",
        "pair.dt_s=0.002", "muscle.spring.stiffness_n_per_m=[900,900,900,900,900,900,900,900]",
        f"hydra.run.dir={run_dir}",
    )
    assert proc.returncode == 0, proc.stderr
    text = (run_dir / "spring_table.yaml").read_text()
    assert "stiffness_n_per_m" in text and "Fitted bands" in text
    assert SPRING_FILE.read_text() == before and SPRING_FILE.stat().st_mtime_ns == mtime


def test_step_on_a_6_bar_muscle_says_so_and_calibration_refuses_it(tmp_path):
    """The default muscle is rated 6 bar: §10.1 steps to 8 bar, so its numbers are the thesis muscle's."""
    proc = run_pamrun("muscle", "step", f"hydra.run.dir={tmp_path / 'step'}")
    assert proc.returncode == 0, proc.stderr
    assert "caps the experiments" in " ".join(proc.stdout.split()) and "muscle=thesis" in proc.stdout
    conf = CONF_DIR / "muscle" / "spring" / "calibrated.yaml"
    before = conf.read_text()
    proc = run_pamrun("muscle", "calibrate", f"hydra.run.dir={tmp_path / 'cal'}")
    assert proc.returncode != 0 and "muscle=thesis" in proc.stderr
    assert conf.read_text() == before


def test_pamrun_body_writes_model_table_and_picture(tmp_path):
    run_dir = tmp_path / "body"
    proc = run_pamrun("body", "body.height_m=1.6", "body.mass_kg=60", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    data = json.loads((run_dir / "body.json").read_text())
    assert data["height_m"] == 1.6 and abs(data["robot_mass_kg"] - 0.464 * 60) < 1e-6
    assert "<mujoco" in (run_dir / "robot.xml").read_text()
    assert (run_dir / "robot.png").stat().st_size > 10_000


def test_openloop_kinematic_reaches_the_limits_it_can(tmp_path):
    """The thesis' muscles in kinematic coupling: every joint whose muscles out-pull gravity reaches its limit."""
    run_dir = tmp_path / "ol"
    proc = run_pamrun("openloop", "muscle=thesis", "muscle.coupling=kinematic", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    moves = json.loads((run_dir / "openloop.json").read_text())["movements"]
    assert len(moves) == 9 and len(list(run_dir.glob("openloop_*.png"))) == 9
    for name, r in moves.items():
        strong = abs(r["muscle_torque_at_limit_nm"]) > abs(r["gravity_torque_at_limit_nm"]) + 2.0
        assert r["reached"] == strong, name
    for name in ("ankle_dorsiflexion", "ankle_plantar_flexion", "ankle_inversion", "ankle_eversion",
                 "hip_abduction", "hip_adduction"):
        assert moves[name]["reached"], name


def test_openloop_thesis_coupling_has_no_steady_torque(tmp_path):
    """Thesis coupling: once settled, both muscles sit at their zero-force contraction."""
    run_dir = tmp_path / "olt"
    proc = run_pamrun("openloop", "muscle=thesis", f"hydra.run.dir={run_dir}")
    assert proc.returncode == 0, proc.stderr
    moves = json.loads((run_dir / "openloop.json").read_text())["movements"]
    assert all(abs(r["muscle_torque_at_limit_nm"]) < 1.0 for r in moves.values())
    assert not moves["knee_flexion"]["reached"] and not moves["hip_flexion"]["reached"]
