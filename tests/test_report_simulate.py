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
    assert "scene" not in clip  # a flat walk: no inferred steps, nothing drawn nor written
    for r in rows:
        sim = {k: r["physics"][k] for k in SIMULATE_KEYS}
        assert sim["sim_error_mm"] > 0 and 0 <= sim["sim_torque_saturated"] <= 1
        assert sim["sim_fell"] in (0, 1) and (sim["sim_fall_s"] is None) == (sim["sim_fell"] == 0)
    # the original tracks itself: its error against the original is its tracking error
    o = clip["original"]["physics"]
    assert o["sim_error_original_mm"] == o["sim_error_mm"]
    text = page.read_text()
    assert "Forward simulation" in text and "sim. error vs original" in text


def test_report_shows_the_simulated_body_beside_each_reconstruction(cmu_dir, tmp_path):
    """Per clip a video of the simulated body for the original and beside every method's
    reconstruction; its points, stored in checks.json, start where the motion it tracked starts
    (the body starts in the reference's first pose, on the trial's floor)."""
    import numpy as np

    from sidql.evaluation.report import report_trial

    page = report_trial(
        cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc", tmp_path / "r", W=10,
        methods=["uniform"], videos=True, progress=False, simulate=True,
    )  # fmt: skip
    files = sorted(p.name for p in (tmp_path / "r").glob("*_simulated.mp4"))
    assert files == ["clip00_original_simulated.mp4", "clip00_uniform_simulated.mp4"]
    text = page.read_text()
    assert text.count("uniform, simulated") == 1 and text.count("original, simulated") == 1
    clip = json.loads((tmp_path / "r" / "checks.json").read_text())["clips"][0]
    # independent of the simulation's code: the clip's own points (the ingested trial)
    from sidql.keyframes.spherical import POINTS
    from sim.motion.ingest import load_motion
    from sim.replay.checks import from_clip

    first = from_clip(load_motion(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc",
                                  fps=30.0).split(60)[0]).restrict(POINTS).positions[0]  # fmt: skip
    for row in (clip["original"], clip["methods"][0]):
        sim = np.array(row["physics_per_frame"]["sim_positions"])
        assert sim.shape == (clip["frames"], 23, 3)
        # the body starts in the tracked motion's first pose (both begin at the original's
        # first frame: uniform keeps it) on the trial's floor: within the IK fit's error and
        # the reference's 1 cm lift, not the metres of another floor
        assert np.linalg.norm(sim[0] - first, axis=-1).mean() < 0.05
        assert np.linalg.norm(sim[-1] - first, axis=-1).mean() > 0.05  # and then it moved


def test_the_page_says_when_the_capture_is_not_supported_by_the_floor():
    """The sentence follows ``capture_unsupported`` (more than 5 % of the measured frames need
    over 0.5 BW with nothing on the floor) and names the original's fall time when it fell."""
    from sidql.evaluation.page import support_sentence

    assert support_sentence({"support_missing_share": 0.0, "sim_fall_s": 0.5}) == ""
    assert support_sentence({"support_missing_share": 0.05}) == ""  # at the rule: supported
    assert support_sentence({}) == ""  # no physics figures
    text = support_sentence({"support_missing_share": 0.62, "sim_fall_s": 0.37})
    assert "lacks support" in text and "62 %" in text and "fell at 0.37 s" in text
    assert "fell" not in support_sentence({"support_missing_share": 0.62, "sim_fall_s": None})
