"""``pamrun export``: the exported actor computes the agent's actions, and says what they mean."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from pamrun.config import to_object
from pamrun.evaluation.export import actor_of, metadata, read_metadata
from pamrun.learning.checkpoints import agent_record, load_agent
from pamrun.physics.body import JOINTS
from pamrun.task.observation import OBSERVATION_UNITS, observation_structure
from tests.conftest import compose_config, run_pamrun

pytest.importorskip("onnx")


def _agent_file(tmp_path, *overrides: str):
    """An untrained actor with large random weights (actions spread over [-1, 1]) as an agent
    file, its robot the thesis' muscle model so its scaling differs from the defaults."""
    from pamrun.learning.networks import ThesisActor
    from pamrun.task.observation import space_sizes

    cfg = to_object(compose_config("muscle=thesis", *overrides))
    obs_size, action_size = space_sizes(cfg.muscle)
    torch.manual_seed(7)
    actor = ThesisActor(obs_size, action_size, (64, 48), init_scale=1.0)
    path = tmp_path / "agent_ep000012_r3.5.pt"
    torch.save(agent_record(actor.state_dict(), cfg, {"episode": 12, "reward": 3.5}), path)
    return path


def _observations(obs_size: int) -> np.ndarray:
    return np.random.default_rng(0).normal(size=(1000, obs_size)).astype(np.float32)


def _expected_actions(path, obs: np.ndarray) -> np.ndarray:
    with torch.no_grad():
        return actor_of(load_agent(path))(torch.from_numpy(obs)).numpy()


def _export(path, out, file_format: str) -> dict:
    proc = run_pamrun("export", f"ckpt={path}", f"format={file_format}", f"hydra.run.dir={out}")
    assert proc.returncode == 0, proc.stderr
    written = json.loads((out / "export.json").read_text())
    assert str(out / written["file"]) in proc.stdout
    return written


def _check_metadata(meta: dict, path) -> None:
    agent = load_agent(path)
    layout = observation_structure(agent.action_size)
    assert meta["observation_layout"] == {k: [s.start, s.stop] for k, s in layout.items()}
    assert meta["observation_units"]["joint_angle"] == "rad"
    muscle = agent.config["muscle"]
    action = meta["action"]
    assert (action["v0_v"], action["dv_max_v"], action["command"]) == (2.12, 0.71, "antagonistic")
    assert (action["v0_v"], action["dv_max_v"], action["command"]) == (muscle["v0_v"], muscle["dv_max_v"],
                                                                       muscle["command"])
    assert action["gain_kpa_per_v"] == muscle["regulator"]["gain_kpa_per_v"]
    assert action["names"] == list(JOINTS)
    assert meta["control_dt_s"] == agent.config["env"]["control_dt_s"]
    assert meta["action_filter"]["alpha"] == agent.config["env"].get("action_filter_alpha", 1.0) == 1.0
    assert meta["checkpoint"]["path"] == str(path.resolve())
    assert meta["checkpoint"]["meta"] == {"episode": 12, "reward": 3.5}
    assert meta["pamrun_version"]


def test_onnx_runs_the_agents_actor(tmp_path):
    import onnxruntime

    path, out = _agent_file(tmp_path), tmp_path / "out"
    written = _export(path, out, "onnx")
    assert written["file"] == "actor.onnx"
    session = onnxruntime.InferenceSession(str(out / "actor.onnx"))
    obs = _observations(written["observation_size"])
    (actions,) = session.run(["action"], {"observation": obs})
    expected = _expected_actions(path, obs)
    assert expected.std() > 0.3  # the weights are not trivial: actions spread over [-1, 1]
    assert np.abs(actions - expected).max() <= 1e-5
    meta = read_metadata(out / "actor.onnx")
    assert json.loads(session.get_modelmeta().custom_metadata_map["pamrun"]) == meta
    assert {"file": "actor.onnx", **meta} == written
    _check_metadata(meta, path)


def test_torchscript_runs_the_agents_actor(tmp_path):
    path, out = _agent_file(tmp_path), tmp_path / "out"
    written = _export(path, out, "torchscript")
    assert written["file"] == "actor.pt"
    obs = _observations(written["observation_size"])
    with torch.no_grad():
        actions = torch.jit.load(str(out / "actor.pt"))(torch.from_numpy(obs)).numpy()
    assert np.abs(actions - _expected_actions(path, obs)).max() <= 1e-5
    meta = read_metadata(out / "actor.pt")
    assert {"file": "actor.pt", **meta} == written
    _check_metadata(meta, path)


def test_independent_command_is_one_action_per_muscle(tmp_path):
    agent = load_agent(_agent_file(tmp_path, "muscle.command=independent", "muscle.coupling=kinematic"))
    meta = metadata(agent, "onnx")
    assert (meta["observation_size"], meta["action_size"]) == (53, 20)
    assert meta["observation_layout"]["previous_action"] == [33, 53]
    assert meta["action"]["names"][:3] == [f"{JOINTS[0]}.muscle1", f"{JOINTS[0]}.muscle2", f"{JOINTS[1]}.muscle1"]
    assert meta["action"]["command"] == "independent"


def test_units_name_every_observation_block_as_the_env_docs_do():
    import pamrun.task.env

    assert set(OBSERVATION_UNITS) == set(observation_structure(speed_command=True, gait_clock=True))
    for name, unit in OBSERVATION_UNITS.items():
        row = next(line for line in pamrun.task.env.__doc__.splitlines() if f"| ``{name}`` |" in line)
        assert row.rstrip(" |").endswith(unit), (name, row)


@pytest.mark.parametrize("case, key", [("format", "format"), ("directory", "ckpt"), ("missing", "ckpt")])
def test_bad_input_fails_before_anything_is_written(tmp_path, case, key):
    path, out = _agent_file(tmp_path), tmp_path / "out"
    ckpt = {"format": path, "directory": tmp_path, "missing": tmp_path / "nope.pt"}[case]
    file_format = "tflite" if case == "format" else "onnx"
    proc = run_pamrun("export", f"ckpt={ckpt}", f"format={file_format}", f"hydra.run.dir={out}")
    assert proc.returncode != 0
    assert f"invalid configuration: {key}" in proc.stderr, proc.stderr
    assert not out.exists()



@pytest.mark.slow
def test_the_shipped_walker_exports_to_its_own_actions(tmp_path):
    """agents/walker_td3_seed0.pt on 1,000 observations of its own held-out episodes: ONNX Runtime
    and TorchScript give the actor's actions to 1e-5 (measured 1.4e-6 and 0; on N(0, 1)
    observations, far outside what the robot senses, ONNX Runtime's float32 GEMM differs by
    up to 1.03e-5)."""
    import onnxruntime as ort

    from pamrun.config import Config
    from pamrun.evaluation.episodes import agent_env, make_policy

    path = str(Path(__file__).parents[1] / "agents" / "walker_td3_seed0.pt")
    agent = load_agent(path)
    policy, env, obs = make_policy(agent), agent_env(agent, Config()).make(), []
    for seed in range(1000, 1010):  # its held-out episodes until 1,000 observations (a fall ends one early)
        o, _ = env.reset(seed=seed)
        for _ in range(400):
            obs.append(o)
            o, _, terminated, truncated, _ = env.step(policy(o))
            if terminated or truncated:
                break
        if len(obs) >= 1000:
            break
    obs = np.array(obs[:1000], np.float32)
    assert len(obs) == 1000
    expected = _expected_actions(path, obs)
    _export(path, tmp_path / "onnx", "onnx")
    onnx_actions = ort.InferenceSession(str(tmp_path / "onnx" / "actor.onnx")).run(["action"], {"observation": obs})[0]
    assert np.abs(onnx_actions - expected).max() <= 1e-5
    _export(path, tmp_path / "ts", "torchscript")
    with torch.no_grad():
        ts_actions = torch.jit.load(str(tmp_path / "ts" / "actor.pt"))(torch.from_numpy(obs)).numpy()
    assert np.abs(ts_actions - expected).max() <= 1e-5
