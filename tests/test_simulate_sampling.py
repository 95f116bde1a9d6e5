"""The sampling tracker (``sim.simulate.sampling``): it keeps a walk up where the plain tracker
falls, with no assistance; it is deterministic given its seed; with no noise it is the plain
tracker."""

from __future__ import annotations

import numpy as np
import pytest

from sim.model.humanoid import canonical_skeleton
from sim.simulate.controller import track
from sim.simulate.model import sim_model
from sim.simulate.sampling import sample_track


@pytest.fixture(scope="module")
def model():
    return sim_model(canonical_skeleton())


@pytest.fixture(scope="module")
def walk_ref(cmu_dir, model):
    """2 s of the walk 07_01 on the canonical body, on the floor (120 Hz)."""
    from sim.simulate.reference import on_floor, trial_qpos

    q = trial_qpos(cmu_dir / "07" / "07.asf", cmu_dir / "07" / "07_01.amc")
    return on_floor(model, q)[:240]


def test_sampling_keeps_a_walk_up_where_the_plain_tracker_falls(model, walk_ref):
    plain = track(model, walk_ref, assist_limit=0.0)
    assert plain.fell  # the reason the sampler exists: without help the plain tracker falls
    r = sample_track(model, walk_ref, samples=64, keep=8)
    assert not r.fell and not r.unstable
    assert r.assistance.max() == 0.0 and r.mean_assistance_all == 0.0  # no hidden hand
    root_err = np.abs(r.qpos[:, :3] - walk_ref[::4, :3]).max()
    assert root_err < 0.4  # measured 0.28 m (the plain tracker: 1.2 m)
    assert root_err < np.abs(plain.qpos[:, :3] - walk_ref[::4, :3]).max()
    # the torques stay within the human limits: the actuators clamp them
    lim = model.actuator_forcerange[:, 1]
    assert np.all(np.abs(r.joint_torque) <= lim * (1 + 1e-9))


def test_same_seed_same_result_other_seed_another(model, walk_ref):
    ref = walk_ref[:60]
    a = sample_track(model, ref, samples=6, keep=2, seed=1)
    b = sample_track(model, ref, samples=6, keep=2, seed=1)
    c = sample_track(model, ref, samples=6, keep=2, seed=2)
    assert np.array_equal(a.qpos, b.qpos) and np.array_equal(a.actions, b.actions)
    assert not np.array_equal(a.qpos, c.qpos)


def test_without_noise_it_is_the_plain_tracker(model, walk_ref):
    ref = walk_ref[:60]
    r = sample_track(model, ref, samples=2, keep=1, torque_sigma=0.0)
    p = track(model, ref, assist_limit=0.0)
    assert np.array_equal(r.qpos, p.qpos) and np.array_equal(r.joint_torque, p.joint_torque)


def test_forward_validation_carries_its_sampling_to_other_processes(model):
    import pickle

    from sim.simulate.validate import ForwardValidation

    fv = pickle.loads(pickle.dumps(ForwardValidation(model, ("root",), samples=8)))
    assert fv.samples == 8 and fv.names == ("root",)
    assert pickle.loads(pickle.dumps(ForwardValidation(model, ("root",)))).samples == 0


def test_eval_simulate_samples_needs_simulate_and_a_positive_count(tmp_path, capsys):
    from sidql.commands import main as cli

    out = str(tmp_path / "r.json")
    argv = ["eval", "--data", str(tmp_path), "--physics", "--simulate-samples", "8", "--out", out]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["sidql eval: error: --simulate-samples needs --simulate"]
    with pytest.raises(SystemExit) as e:
        cli.main(["eval", "--data", str(tmp_path), "--simulate-samples", "0", "--out", out])
    assert e.value.code == 2
