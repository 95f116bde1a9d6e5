"""sim.physics wired into ``sidql eval --physics`` and the report's checks.json."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

KEYS = (
    "ground_z_m", "penetration_mm", "float_mm", "skate_mm_s", "contact_precision",
    "contact_recall", "self_pen_excess_mm", "lost_contacts", "limit_excess_deg",
    "residual_force_bw", "residual_force_bw_p95", "residual_torque_nm_kg",
    "joint_torque_rms_nm_kg", "physdiff_penetrate_mm", "physdiff_float_mm", "physdiff_skate",
    "floor_fits", "floor_deviation_mm",
)  # fmt: skip


def test_eval_physics_adds_figures_an_original_row_a_noise_floor_and_comparisons(cmu_dir):
    from sidql.evaluation.cases import load_cases
    from sidql.evaluation.evaluate import evaluate
    from sidql.evaluation.scoring import NOISE_FLOOR, PHYSICS_KEYS
    from sidql.evaluation.significance import comparisons_markdown
    from sidql.evaluation.tables import floors_markdown, physics_markdown, table3_markdown

    cases, _ = load_cases(cmu_dir, subjects=["02"], progress=False)
    cases = cases[:2]
    out = evaluate(cases, ["uniform", "optimal"], [5], progress=False, physics=True)
    rows = {r["method"]: r for r in out["results"]}
    assert set(rows) == {"original", NOISE_FLOOR, "uniform", "optimal"}
    for r in rows.values():
        assert all(k in r for k in PHYSICS_KEYS)
        assert r["clips"] == len(cases)
    # the noise floor: how far marker noise moves each figure (the original's own: 0)
    noise = rows[NOISE_FLOOR]
    assert noise["contact_recall"] > 0 and noise["residual_force_bw"] > 0  # noise always moves it
    # closeness to the original's joint torques, clip by clip
    per_u = [r for r in out["per_clip"] if r["method"] == "uniform"]
    per_o = [r for r in out["per_clip"] if r["method"] == "original"]
    assert per_u[0]["joint_torque_rms_nm_kg_distance"] == pytest.approx(
        abs(per_u[0]["joint_torque_rms_nm_kg"] - per_o[0]["joint_torque_rms_nm_kg"])
    )
    # paired bootstrap comparisons: every figure, the interval around the mean difference
    cmp = [c for c in out["comparisons"] if c["metric"] == "q"]
    assert cmp and cmp[0]["ci_low"] <= cmp[0]["mean_diff"] <= cmp[0]["ci_high"]
    assert cmp[0]["better"] in (None, "uniform", "optimal") and cmp[0]["clips"] == len(cases)
    assert "uniform vs optimal" in comparisons_markdown(out["comparisons"])
    # the trial's floor, and the word when it does not fit
    assert out["floors"] and "floor_fits" in out["floors"][0]
    assert "floor" in floors_markdown(out["floors"]).lower()
    orig, uni = rows["original"], rows["uniform"]
    assert orig["contact_recall"] == 1.0 and orig["self_pen_excess_mm"] == 0.0
    assert orig["residual_force_bw_excess"] == 0.0
    per = [r for r in out["per_clip"] if r["method"] == "uniform"]
    assert np.isclose(uni["residual_force_bw"], np.mean([r["residual_force_bw"] for r in per]))
    assert all(k in per[0] for k in KEYS)
    assert "original" not in table3_markdown(out["results"])
    assert NOISE_FLOOR not in table3_markdown(out["results"])
    assert "| original | 60 |" in physics_markdown(out["results"])
    assert f"| {NOISE_FLOOR} | 60 |" in physics_markdown(out["results"])
    json.dumps(out, allow_nan=False)  # standard JSON


def test_report_checks_json_carries_physics_for_original_and_methods(cmu_dir, tmp_path):
    from sidql.evaluation.validation import (
        checks_document,
        physics_job,
        trial_ground,
        validate_clip,
    )
    from sim.model.humanoid import subject_model
    from sim.motion.ingest import load_clips

    asf = cmu_dir / "02" / "02.asf"
    clips = load_clips(asf, cmu_dir / "02" / "02_01.amc")
    model = subject_model(asf)[1]
    ground = trial_ground(clips)
    v = validate_clip(clips[0], ["uniform"], 5, physics=physics_job(model, clips[0]), ground=ground)
    doc = json.loads(json.dumps(checks_document([v], {})))
    c = doc["clips"][0]
    # each figure's noise floor on this clip: marker noise always moves the marker-driven figures
    # (the residual force of a walk may stay 0: its contacts supply every force, noisy or not)
    nf = c["noise_floor"]
    assert min(nf["skate_mm_s"], nf["ik_error_mm"], nf["joint_torque_rms_nm_kg"]) > 0
    assert 0 <= nf["contact_recall"] < 1 and nf["residual_force_bw"] >= 0
    for row in [c["original"], *c["methods"]]:
        assert all(k in row["physics"] for k in KEYS)
        assert len(row["physics_per_frame"]["residual_force_bw"]) == clips[0].n_frames
        assert row["physics"]["ground_z_m"] == round(ground.z, 6)
    assert c["original"]["physics"]["contact_recall"] == 1.0
    # the page shows one column per idea: the physics figures; the kinematic replay's own floor,
    # skating and joint-limit figures are in checks.json only
    from sidql.evaluation.metrics import METRICS, shown_metrics

    shown = {m.key for m in shown_metrics(v)}
    assert {"residual_force_bw", "penetration_mm", "skate_mm_s", "mpjpe_mm"} <= shown
    replay_only = {
        "floor_depth_max_mm",
        "skate_mean_mm_s",
        "self_pen_frames",
        "joint_limit_max_deg",
    }
    assert replay_only <= set(c["original"]["summary"]) and replay_only <= set(
        c["methods"][0]["excess"]
    )
    assert not replay_only & {m.key for m in METRICS}
    plain = validate_clip(clips[0], ["uniform"], 5)  # no physics: accuracy and geometry only
    assert {m.key for m in shown_metrics(plain)} == {
        "mpjpe_mm",
        "velocity_error_mm_s",
        "bone_drift_max_mm",
    }


def test_a_physics_job_sent_to_another_process_measures_the_same(cmu_dir):
    """Pool and Ray workers get the job pickled: it is rebuilt from its constructor's arguments
    (fresh, writable MuJoCo buffers) and gives the same figures."""
    import pickle

    from sidql.evaluation.validation import physics_job, trial_ground
    from sim.model.humanoid import subject_model
    from sim.motion.ingest import load_clips

    asf = cmu_dir / "05" / "05.asf"
    clips = load_clips(asf, cmu_dir / "05" / "05_01.amc")
    job = physics_job(subject_model(asf)[1], clips[0])
    ground = trial_ground(clips)
    a = job.analyse(clips[1], None, ground)
    b = pickle.loads(pickle.dumps(job)).analyse(clips[1], None, ground)
    assert a["residual_force_bw"] == b["residual_force_bw"] and a["float_mm"] == b["float_mm"]


@pytest.mark.slow
def test_report_on_ray_equals_the_report_in_process(cmu_dir, tmp_path):
    from sidql.evaluation.report import report_trial

    asf, amc = cmu_dir / "05" / "05.asf", cmu_dir / "05" / "05_01.amc"
    kw = dict(W=6, methods=["uniform"], clips=(0, 1), videos=False, progress=False)
    report_trial(asf, amc, tmp_path / "local", **kw)
    report_trial(asf, amc, tmp_path / "ray", ray="local", workers=2, **kw)
    a, b = (json.loads((tmp_path / d / "checks.json").read_text()) for d in ("local", "ray"))
    assert a["clips"] == b["clips"]


def test_eval_physics_on_a_dataset_folder_and_clean_refusals(cmu_dir, tmp_path, capsys):
    """A 'sidql dataset' folder of subject-skeleton trials gets the same physics as the CMU files
    (no ValueError); clips not on their subject's skeleton exit 2 with one line
    (the humanoid's points were fitted with the subject's model)."""
    import shutil

    from sidql.commands.main import main

    src = tmp_path / "cmu" / "02"
    src.mkdir(parents=True)
    for f in ("02.asf", "02_01.amc"):
        shutil.copy(cmu_dir / "02" / f, src / f)
    argv = ["--keyframes", "5", "--methods", "uniform", "--physics", "--quiet"]
    assert (
        main(["eval", "--data", str(tmp_path / "cmu"), *argv, "--out", str(tmp_path / "a.json")])
        == 0
    )
    assert (
        main(
            [
                "dataset",
                "--data",
                str(tmp_path / "cmu"),
                "--out",
                str(tmp_path / "ds"),
                "--workers",
                "1",
            ]
        )
        == 0
    )
    assert (
        main(["eval", "--data", str(tmp_path / "ds"), *argv, "--out", str(tmp_path / "b.json")])
        == 0
    )
    a, b = (json.loads((tmp_path / f).read_text())["results"] for f in ("a.json", "b.json"))
    assert [r["method"] for r in b] == ["original", "noise floor", "uniform"]
    assert b[2]["residual_force_bw"] == pytest.approx(a[2]["residual_force_bw"])
    capsys.readouterr()
    out = tmp_path / "c.json"
    humanoid = ["eval", "--data", str(tmp_path / "cmu"), "--skeleton", "humanoid", *argv]
    assert main([*humanoid, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "02_01.amc" in err[0] and "own skeleton" in err[0]
    assert not out.exists()


def test_floor_report_says_where_each_trials_support_was_found():
    """Per trial: the original's residual, the body points on the floor and, where more than 5 %
    of its frames need support found nowhere on the floor, the flag and why."""
    from types import SimpleNamespace

    from sidql.evaluation.floors import floor_report
    from sidql.evaluation.tables import floors_markdown
    from sim.physics.ground import Ground
    from sim.physics.support import support_verdict

    setup = {s: SimpleNamespace(ground=Ground(0.0)) for s in ("x/climb.amc", "x/walk.amc")}
    climb = {"source": "x/climb.amc", "dynamics_n": 60, "residual_force_bw": 0.5,
             "support_missing_share": 0.4, "support_above_floor_share": 0.3,
             "support_above_floor_mm": 480.0, "ground_parts": {"lhand": 0.1}}  # fmt: skip
    walk = {"source": "x/walk.amc", "dynamics_n": 60, "residual_force_bw": 0.01,
            "support_missing_share": 0.0, "support_above_floor_share": 0.0,
            "support_above_floor_mm": None, "ground_parts": {}}  # fmt: skip
    rows = [climb, {**climb, "support_above_floor_mm": 520.0, "ground_parts": {}}, walk]
    floors = {Path(f["source"]).stem: f for f in floor_report(setup, rows)}
    assert floors["climb"]["support_off_floor"] and not floors["walk"]["support_off_floor"]
    assert floors["climb"]["support_above_floor_mm"] == pytest.approx(500.0)
    assert floors["climb"]["ground_parts"] == pytest.approx({"lhand": 0.05})
    assert "stands still about 50 cm above" in floors["climb"]["support_why"]
    text = floors_markdown(list(floors.values()))
    assert "Support off the floor in 1 of 2 trials" in text and "| climb | 0.500 |" in text
    assert "climb: lhand 5.0 %" in text
    # the other reasons
    assert support_verdict(0.2, 0.0, False)[1].endswith("the floor does not fit")
    assert "partner" in support_verdict(0.2, 0.0, True)[1]
    assert support_verdict(0.04, 0.04, True) == (False, "")


def test_the_held_verdict_flags_the_salsa_partner_and_no_clean_trial(cmu_dir):
    """One rule for every trial: 61_01 (salsa; its partner is subject 60) needs a sideways force
    no floor contact supplies for 0.2 s and longer in more than 2 % of its frames; the walks,
    the forward jumps (impacts) and the boxing (hops) never do."""
    from sidql.evaluation.cases import load_cases
    from sidql.evaluation.floors import floor_report
    from sidql.evaluation.trial_physics import physics_setup

    cases, _ = load_cases(cmu_dir, subjects=["01", "02", "07", "17", "61"], progress=False)
    keep = {"01_01", "02_01", "07_04", "17_10", "61_01"}
    cases = [c for c in cases if Path(c.clip.source).stem in keep]
    setup = physics_setup(cases)
    rows = []
    for c in cases:
        r = setup[c.clip.source].analyse(c.clip)
        rows.append({k: v for k, v in r.items() if k != "per_frame"} | {"source": c.clip.source})
    floors = {Path(f["source"]).stem: f for f in floor_report(setup, rows)}
    assert set(floors) == keep
    salsa = floors["61_01"]
    assert salsa["support_off_floor"] and salsa["support_held_share"] > 0.02
    assert "held by something else (a partner, a prop)" in salsa["support_why"]
    for t in keep - {"61_01"}:
        assert floors[t]["support_held_share"] == 0.0, t
        assert not floors[t]["support_off_floor"], t
    # the take's first frame is reported, not scored
    assert all(floors[t]["dynamics_unmeasured_n"] >= 1 for t in keep)
