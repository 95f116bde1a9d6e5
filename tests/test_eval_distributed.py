"""``evaluate`` distributes the per-clip work (methods, physics, forward simulation): the rows are
the same in this process, in a process pool and on Ray, in the same order."""

from __future__ import annotations

import math

import pytest

from sidql.evaluation.cases import load_cases
from sidql.evaluation.evaluate import evaluate


def _without_times(out: dict) -> dict:
    """The rows without what measures time (decision and simulation CPU time), NaN as None
    (NaN != NaN: a figure with no value compares equal to itself)."""
    drop = {"decision_ms", "median_decision_ms"}

    def keep(f: str) -> bool:
        return f not in drop and not f.startswith("sim_cpu_s_per_s")

    def same(v):
        return None if isinstance(v, float) and math.isnan(v) else v

    return {k: [{f: same(v) for f, v in r.items() if keep(f)} for r in rows]
            for k, rows in out.items()}  # fmt: skip


@pytest.fixture(scope="module")
def cases(cmu_dir):
    cases, _ = load_cases(cmu_dir, subjects=["02", "07"], progress=False)
    by_trial: dict = {}
    for c in cases:  # two clips of each of three trials: chunks of two trials' clips
        by_trial.setdefault(c.clip.source, []).append(c)
    return [c for group in list(by_trial.values())[:3] for c in group[:2]]


def test_pool_and_ray_give_the_rows_of_one_process(cases, monkeypatch):
    # the plain tracker: the rows' equality does not depend on the controller, and the default
    # (the sampler, about 5 CPU s per simulated second) would take minutes here
    monkeypatch.setattr("sim.simulate.validate.DEFAULT_CONTROLLER", "plain")
    kw = dict(seed=3, progress=False, physics=True, simulate=True, chunk=1)
    one = evaluate(cases, ["random", "optimal"], [8], **kw)
    methods = ["original", "noise floor", "random", "optimal"]
    assert [r["method"] for r in one["results"]] == methods
    assert len(one["per_clip"]) == len(methods) * len(cases)
    simulated = [r for r in one["per_clip"] if r["method"] != "noise floor"]
    assert all(r["sim_error_mm"] is not None for r in simulated)
    decided = {(r["method"], r["metric"]): r for r in one["versus_original"]}  # the decision
    assert set(decided) == {(m, k) for m in ("random", "optimal")
                            for k in ("sim_fell", "sim_error_mm", "sim_error_local_mm")}  # fmt: skip
    assert all(r["clips"] == len(cases) and 0 < r["p_value"] <= 1 for r in decided.values())
    pool = evaluate(cases, ["random", "optimal"], [8], workers=2, **kw)
    assert _without_times(pool) == _without_times(one)
    pytest.importorskip("ray")
    on_ray = evaluate(cases, ["random", "optimal"], [8], workers=2, ray="local", **kw)
    assert _without_times(on_ray) == _without_times(one)
