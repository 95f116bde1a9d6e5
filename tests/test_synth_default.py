"""``synth`` by default: the real-motion kinds are tracked by ``eval --simulate``'s controller
(the sampler at its default count) with no assistance; the episodes replay bit for bit, and the
clips do not depend on the number of workers, the sampler's threads, a stop and resume, or Ray.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from synth_replay import PER_KIND, REAL, SECONDS, check_replays

from sim.motion.clip import load_extra, load_npz
from sim.simulate.generate import SYNTH_SAMPLES
from sim.simulate.validate import DEFAULT_CONTROLLER

SHORT = 0.5  # [s] the default count costs about 5 CPU s per simulated second


def _arrays(path) -> dict:
    """Every array of a clip file: the clip's and its labels."""
    clip = load_npz(path)
    return {"qpos": clip.qpos, "qvel": clip.qvel, "positions": clip.positions,
            **load_extra(path, "sim_")}  # fmt: skip


def _same_folders(a, b, written) -> None:
    for r in written:
        x, y = _arrays(a / r["file"]), _arrays(b / r["file"])
        assert x.keys() == y.keys() and all(np.array_equal(x[k], y[k]) for k in x), r["file"]


@pytest.fixture(scope="module")
def default_run(cmu_dir, tmp_path_factory):
    """One short clip of each real-motion kind, ``synthesize`` given no controller at all."""
    from sim.simulate.dataset import synthesize

    out = tmp_path_factory.mktemp("default")
    s = synthesize(cmu_dir, out, 3, kinds=REAL, seconds=SHORT, seed=3, workers=1,
                   progress=False)  # fmt: skip
    assert not s.skipped and len(s.written) == 3
    return out, s.written


def test_the_default_is_eval_s_sampler_with_no_help_and_it_replays_bit_for_bit(default_run):
    from synth_replay import oracle_replay

    from sim.simulate.episode import array_text
    from sim.simulate.model import human_torque_limit

    out, written = default_run
    index = json.loads((out / "index.json").read_text())["synthetic"]
    assert DEFAULT_CONTROLLER == "sampling"  # the premise: eval's default samples
    assert (index["controller"], index["samples"], index["assist"]) == (
        DEFAULT_CONTROLLER, SYNTH_SAMPLES, 0.0
    )  # fmt: skip
    for r in written:
        g = r["generation"]
        assert g["controller"] == "sampling" and g["sampling"]["samples"] == SYNTH_SAMPLES
        assert g["assist_limit"] == 0 and r["mean_assistance"] == 0 and r["physical"]
        labels = load_extra(out / r["file"], "sim_")
        assert not labels["sim_qfrc_applied"].any() and not labels["sim_assist_wrench"].any()
        names = load_npz(out / r["file"]).joint_names
        mass = 75.0 * g["scale"] ** 3
        limits = np.array([human_torque_limit(n, mass) for n in names])
        q, v, worst, _ = oracle_replay(labels, limits)
        assert np.array_equal(q, labels["sim_tick_qpos"]) and np.array_equal(
            v, labels["sim_tick_qvel"]
        )
        assert worst <= 1 + 1e-12 and len(labels["sim_actions"]) == round(SHORT * 120)
        assert json.loads(array_text(labels["sim_generation"])) == g


def test_workers_and_sampler_threads_change_nothing(default_run, cmu_dir, tmp_path):
    from sim.simulate.dataset import synthesize

    out, written = default_run
    s = synthesize(cmu_dir, tmp_path / "par", 3, kinds=REAL, seconds=SHORT, seed=3, workers=2,
                   threads=2, progress=False)  # fmt: skip
    assert s.written == written
    _same_folders(out, tmp_path / "par", written)


def test_a_stopped_default_run_resumes_to_the_same_clips(default_run, cmu_dir, tmp_path,
                                                         monkeypatch):  # fmt: skip
    import sim.simulate.dataset as dataset
    from sim.simulate.generate import generate

    out, written = default_run
    kw = dict(kinds=REAL, seconds=SHORT, seed=3, workers=1, progress=False)

    def stopped_at_the_second(task):
        if task.index == 1:
            raise KeyboardInterrupt
        return generate(task)

    monkeypatch.setattr(dataset, "generate", stopped_at_the_second)
    with pytest.raises(KeyboardInterrupt):
        dataset.synthesize(cmu_dir, tmp_path / "run", 3, **kw)
    calls = []
    monkeypatch.setattr(dataset, "generate", lambda t: calls.append(t.index) or generate(t))
    with pytest.raises(ValueError, match="other parameters"):  # another controller: another run
        dataset.synthesize(cmu_dir, tmp_path / "run", 3, resume=True, controller="plain", **kw)
    resumed = dataset.synthesize(cmu_dir, tmp_path / "run", 3, resume=True, threads=2, **kw)
    assert calls == [1, 2] and resumed.written == written
    _same_folders(out, tmp_path / "run", written)


@pytest.mark.slow
def test_ray_gives_the_default_run_s_clips(default_run, cmu_dir, tmp_path):
    pytest.importorskip("ray")
    from sim.simulate.dataset import synthesize

    out, written = default_run
    s = synthesize(cmu_dir, tmp_path / "ray", 3, kinds=REAL, seconds=SHORT, seed=3, workers=2,
                   ray="local", progress=False)  # fmt: skip
    assert s.written == written
    _same_folders(out, tmp_path / "ray", written)


def test_samples_belong_to_the_sampler_alone(cmu_dir, tmp_path):
    from sim.errors import UsageError
    from sim.simulate.dataset import synthesize

    for kw in ({"controller": "plain", "samples": 8}, {"controller": "sampling", "assist": 0.2}):
        with pytest.raises(UsageError):
            synthesize(cmu_dir, tmp_path / "o", 1, kinds=("track",), progress=False, **kw)
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_sampled_episodes_of_every_real_kind_replay_bit_for_bit(cmu_dir, tmp_path):
    """``PER_KIND`` clips of each real-motion kind tracked by the sampler (at 4 rollouts per
    window, to keep the test short; the default count is checked above) replay bit for bit
    from their first state within the human torque limits, pushed and weakened alike."""
    from sim.simulate.dataset import synthesize

    s = synthesize(cmu_dir, tmp_path, (PER_KIND + 1) * len(REAL), kinds=REAL, seconds=SECONDS,
                   seed=0, samples=4, workers=2, progress=False)  # fmt: skip
    assert not s.skipped
    count = check_replays(tmp_path, s.written, REAL)
    assert count["pushed"] >= 10 and count["weakened"] >= 5 and count["assisted"] == 0
    assert all(r["generation"]["controller"] == "sampling" for r in s.written)
