"""``report --simulate``: the forward simulation's figures for the original (the baseline row) and
every method, in checks.json and in their own table of the page."""

from __future__ import annotations

import json

from sim.simulate.validate import SIMULATE_KEYS


def test_report_adds_forward_simulation_per_method_with_the_original_as_baseline(cmu_dir, tmp_path):
    from sidql.evaluation.report import report_trial

    page = report_trial(
        cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc", tmp_path / "r", W=10,
        methods=["uniform", "optimal"], videos=False, progress=False, simulate=True,
    )  # fmt: skip
    clip = json.loads((tmp_path / "r" / "checks.json").read_text())["clips"][0]
    rows = [clip["original"], *clip["methods"]]
    assert [r.get("method") for r in clip["methods"]] == ["uniform", "optimal"]
    for r in rows:
        sim = {k: r["physics"][k] for k in SIMULATE_KEYS}
        assert sim["sim_error_mm"] > 0 and 0 <= sim["sim_torque_saturated"] <= 1
        assert sim["sim_fell"] in (0, 1) and (sim["sim_fall_s"] is None) == (sim["sim_fell"] == 0)
    # the original tracks itself: its error against the original is its tracking error
    o = clip["original"]["physics"]
    assert o["sim_error_original_mm"] == o["sim_error_mm"]
    text = page.read_text()
    assert "Forward simulation" in text and "sim. error vs original" in text
