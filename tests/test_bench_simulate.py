"""``benchmarks/bench_simulate.py``'s stiffer-controller candidates: each is eval's default
sampler on a body whose feedback is stiffer and whose torque limits are the human ones; the
controllers' table says where MuJoCo flagged an unstable simulation."""

from __future__ import annotations

import numpy as np
import pytest
from benchmark_modules import load_benchmark

from sim.model.humanoid import canonical_skeleton
from sim.simulate.model import MIN_DEFLECTION, human_torque_limit
from sim.simulate.validate import validation_model


@pytest.fixture(scope="module")
def bench():
    return load_benchmark("bench_simulate")


@pytest.fixture(scope="module")
def candidates():
    return load_benchmark("simulate_controllers")


def test_stiff_candidates_are_eval_default_with_a_stiffer_body_of_human_strength(candidates):
    skeleton = canonical_skeleton()
    base = validation_model(skeleton)
    default = candidates.CONTROLLERS["default28"]
    assert len(candidates.STIFF) <= 4
    for name in candidates.STIFF:
        label, kw, actuators, body = candidates.CONTROLLERS[name]
        assert kw["controller"] == default[1]["controller"] and kw["samples"] == 28
        assert actuators == "position" and set(body) == {"gains"}
        assert body["gains"].min_deflection < MIN_DEFLECTION
        model = validation_model(skeleton, actuators=actuators, **body)
        table = [human_torque_limit(model.actuator(i).name) for i in range(model.nu)]
        np.testing.assert_array_equal(model.actuator_forcerange[:, 1], table)
        kp, kp0 = model.actuator_gainprm[:, 0], base.actuator_gainprm[:, 0]
        assert np.all(kp >= kp0) and np.any(kp > 1.5 * kp0)
    assert candidates.CONTROLLERS["stiff0.1rad"][1]["search"] == {
        "noise_deflection": MIN_DEFLECTION
    }


def test_the_table_says_where_a_simulation_went_unstable(bench):
    row = {"sim_fell": 0, "sim_error_local_mm": 50.0, "sim_error_mm": 80.0,
           "sim_skate_mm_s": 100.0, "sim_skate_ref_mm_s": 90.0, "sim_cpu_s_per_s": 5.0}  # fmt: skip
    calm = bench.controllers_markdown({"stiff0.1": [row, row]})
    assert "diverging" not in calm
    text = bench.controllers_markdown({"stiff0.1": [row, {**row, "sim_unstable": 1}]})
    assert "diverging acceleration in 1 clips" in text


def test_mix_half_at_eval_s_count_is_eval_default_controller(candidates):
    from sim.simulate.validate import DEFAULT_GAIN_CHOICE, DEFAULT_SAMPLES, STIFF_GAINS

    _, kw, actuators, body = candidates.CONTROLLERS[f"mix0.5s{DEFAULT_SAMPLES}"]
    assert kw["search"] == {"choice": DEFAULT_GAIN_CHOICE} and kw["samples"] == DEFAULT_SAMPLES
    assert body == {"alternate_gains": (STIFF_GAINS,)} and actuators == "position"


def test_a_baseline_log_pairs_clip_by_clip(bench, tmp_path):
    """``--baseline-log``: another run's rows of the same controller, read from its log, are
    the first row and every clip is paired with its own: the mean difference is computed here
    by hand (one clip falls only in the baseline; errors 10 mm lower in each clip)."""
    import json

    def row(clip, fell, local, glob):
        return {"clip": clip, "controller": "mix0.5", "sim_fell": fell, "sim_error_local_mm":
                local, "sim_error_mm": glob, "sim_skate_mm_s": 1.0, "sim_skate_ref_mm_s": 1.0,
                "sim_cpu_s_per_s": 1.0}  # fmt: skip

    base = [row("a@0", 1, 100.0, 200.0), row("b@0", 0, 50.0, 80.0)]
    new = [row("b@0", 0, 40.0, 70.0), row("a@0", 0, 90.0, 190.0)]  # another order
    log = tmp_path / "base.jsonl"
    log.write_text("".join(json.dumps(r) + "\n" for r in base))
    logged = bench.read_log(str(log))
    assert logged == {"mix0.5": base}
    text = bench.paired_markdown({f"mix0.5@{log}": logged["mix0.5"], "mix0.5": new})
    assert "the baseline's rows (base.jsonl)" in text
    line = text.strip().splitlines()[-1]
    assert "| 2 | -0.50 [" in line and "| -10 [" in line and line.count("| -10 |") == 2


def test_kept_rows_write_the_page_again(bench, tmp_path, monkeypatch):
    """A page's rows are kept beside it (``docs/results/rows/<page>.jsonl``) and read back by
    ``--rows-log`` as the same rows per controller; the note names the command that writes the
    page again from them, baseline included."""
    import argparse

    results = load_benchmark("results")
    monkeypatch.setattr(results, "RESULTS_DIR", tmp_path / "docs" / "results")
    monkeypatch.setattr(bench, "keep_rows", results.keep_rows)
    a = {"clip": "a@0", "sim_fell": 0, "sim_error_mm": 12.5}
    b = {"clip": "b@0", "sim_fell": 1, "sim_error_mm": 99.0}
    kept = {"": [a | {"controller": "mix0.5"}, b | {"controller": "mix0.5"}],
            ".baseline": [b | {"controller": "mix0.5"}]}  # fmt: skip
    args = argparse.Namespace(page="demo_page", cmu="DATA", controllers=["mix0.5"], every=5,
                              offset=2)  # fmt: skip
    note = bench._kept_rows_note(args, kept)
    rows_path = tmp_path / "docs" / "results" / "rows" / "demo_page.jsonl"
    assert bench.read_log(str(rows_path)) == {"mix0.5": kept[""]}
    assert "--rows-log docs/results/rows/demo_page.jsonl" in note
    assert "--baseline-log docs/results/rows/demo_page.baseline.jsonl" in note
    assert "--every 5 --offset 2" in note and "--page demo_page" in note
