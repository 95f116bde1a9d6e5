"""Evaluation, the CLI commands and the rate/distortion sweep."""

import json
import shutil

import numpy as np
import pytest
from keyframe_synth import smooth_clip

from sidql.commands import main as cli
from sidql.evaluation import evaluate as evaluate_module
from sidql.evaluation.cases import make_case
from sidql.evaluation.evaluate import evaluate
from sidql.evaluation.rate import (
    CURVES,
    bytes_per_second,
    rate_distortion,
    raw_bytes_per_second,
    write_plot,
)
from sidql.evaluation.tables import PAPER_TABLE3, table3_markdown
from sidql.keyframes.metrics import q_error
from sidql.keyframes.reconstructions import RECONSTRUCTIONS
from sim.errors import MotionDataError


@pytest.fixture(scope="module")
def cases():
    return [make_case(smooth_clip(60, 30.0, seed=40 + i), i) for i in range(3)]


def test_evaluate_rows_are_consistent_with_per_clip_scores(cases):
    out = evaluate(
        cases, ["random", "uniform", "greedy", "optimal", "pitch"], [3, 6], progress=False
    )
    assert len(out["results"]) == 10 and len(out["per_clip"]) == 30
    for r in out["results"]:
        rows = [
            p
            for p in out["per_clip"]
            if p["method"] == r["method"] and p["keyframes"] == r["keyframes"]
        ]
        assert r["clips"] == 3 and r["mean_q"] == pytest.approx(np.mean([p["q"] for p in rows]))
        for p, case in zip(rows, cases, strict=True):
            assert len(p["indices"]) == r["keyframes"]
            assert p["q_hermite"] == pytest.approx(q_error(case.series, np.array(p["indices"])))
            if r["method"] != "pitch":
                assert p["q"] == p["q_hermite"]
    per = {
        (p["method"], p["keyframes"], p["source"], i % 3): p["q"]
        for i, p in enumerate(out["per_clip"])
    }
    for (m, W, src, i), qv in per.items():
        if m in ("greedy", "uniform", "random"):
            assert per[("optimal", W, src, i)] <= qv + 1e-12
    table = table3_markdown(out["results"])
    assert "random (RC)" in table and "optimal" in table and "| pitch | 6 |" in table


def test_a_failed_task_is_reported_and_skipped_and_the_good_results_are_kept(
    cases, monkeypatch, capsys
):
    full = evaluate(cases, ["uniform", "greedy"], [3, 5], progress=False, chunk=1)
    assert full["failed"] == []
    real_score = evaluate_module.score

    def score_failing_on_clip_1(case, *a, **k):
        if case.index == 1:
            raise MotionDataError(case.clip.source, 7, "bad frame")
        return real_score(case, *a, **k)

    monkeypatch.setattr(evaluate_module, "score", score_failing_on_clip_1)
    out = evaluate(cases, ["uniform", "greedy"], [3, 5], progress=False, chunk=1)
    assert len(out["failed"]) == 1
    failure = out["failed"][0]
    assert failure["source"] == cases[1].clip.source
    assert failure["start_frames"] == [cases[1].clip.start_frame]
    assert "bad frame" in failure["problem"] and "bad frame" in capsys.readouterr().err

    def timeless(rows):
        return [{k: v for k, v in r.items() if k != "decision_ms"} for r in rows]

    kept = [p for i, p in enumerate(full["per_clip"]) if i % 3 != 1]  # clips 0 and 2 of 3
    assert timeless(out["per_clip"]) == timeless(kept)
    for r in out["results"]:
        assert r["clips"] == 2
        rows = [p for p in kept if (p["method"], p["keyframes"]) == (r["method"], r["keyframes"])]
        assert r["mean_q"] == pytest.approx(np.mean([p["q"] for p in rows]))


def test_random_method_is_seeded_per_clip(cases):
    a = evaluate(cases, ["random"], [5], seed=1, progress=False)["per_clip"]
    b = evaluate(cases, ["random"], [5], seed=1, progress=False)["per_clip"]
    c = evaluate(cases, ["random"], [5], seed=2, progress=False)["per_clip"]
    assert [r["indices"] for r in a] == [r["indices"] for r in b]
    assert [r["indices"] for r in a] != [r["indices"] for r in c]
    assert len({tuple(r["indices"]) for r in a}) > 1  # clips do not share one draw


def test_table_shows_the_papers_figures():
    rows = [
        {
            "method": "greedy",
            "keyframes": W,
            "clips": 1,
            "mean_q": 0.1,
            "mean_q_hermite": 0.1,
            "mean_geodesic_deg": 1,
            "mpjpe_mm": 1,
            "velocity_error_mm_s": 1,
            "mean_li_error_mm": 1,
            "median_decision_ms": 1,
        }
        for W in (5, 10)
    ]
    t = table3_markdown(rows)
    assert f"({PAPER_TABLE3['Greedy'][5]:.4f})" in t and f"({PAPER_TABLE3['Greedy'][10]:.4f})" in t


def test_rate_distortion_optima_beat_uniform_and_bytes_add_up(tmp_path):
    cases = [make_case(smooth_clip(24, 30.0, seed=50 + i), i) for i in range(2)]
    rd = rate_distortion(cases, counts=(2, 3, 5, 8), progress=False)
    curves = {(c["method"], c["scheme"]): c for c in rd["curves"]}
    assert set(curves) == set(CURVES)
    for c in rd["curves"]:
        assert len(c["mean_q"]) == len(c["mpjpe_mm"]) == len(c["velocity_error_mm_s"]) == 4
        assert all(np.isfinite(c["velocity_error_mm_s"])) and min(c["velocity_error_mm_s"]) > 0
    for scheme in ("hermite", "linear", "catmull_rom"):
        opt, uni = curves[("optimal", scheme)], curves[("uniform", scheme)]
        assert all(o <= u + 1e-12 for o, u in zip(opt["mean_q"], uni["mean_q"], strict=True))
    assert curves[("optimal", "hermite")]["bytes_per_second"][0] == pytest.approx(
        2 * RECONSTRUCTIONS["hermite"].payload_bytes * 30 / 24
    )
    assert RECONSTRUCTIONS["hermite"].payload_bytes - 1 == 2 * (
        RECONSTRUCTIONS["linear"].payload_bytes - 1
    )
    assert bytes_per_second("linear", 60) == pytest.approx(raw_bytes_per_second() + 30)
    write_plot(rd, tmp_path / "rd.png")
    assert (tmp_path / "rd.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture
def tiny_data(cmu_dir, tmp_path):
    """One real trial (copied: links leaving the folder are skipped) and one broken AMC beside it."""
    good = tmp_path / "data" / "02"
    good.mkdir(parents=True)
    shutil.copy(cmu_dir / "02" / "02.asf", good / "02.asf")
    shutil.copy(cmu_dir / "02" / "02_02.amc", good / "02_02.amc")
    (good / "02_99.amc").write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot 0 0 nonsense\n")
    return tmp_path / "data"


def test_eval_command_writes_results_and_skips_bad_files(tiny_data, tmp_path, capsys):
    out = tmp_path / "res.json"
    rc = cli.main(
        [
            "eval",
            "--data",
            str(tiny_data),
            "--keyframes",
            "3",
            "5",
            "--methods",
            "uniform",
            "optimal",
            "pitch",
            "--out",
            str(out),
            "--quiet",
        ]
    )
    assert rc == 0
    res = json.loads(out.read_text())
    assert len(res["skipped"]) == 1 and "02_99" in res["skipped"][0]["amc"]
    assert {(r["method"], r["keyframes"]) for r in res["results"]} == {
        (m, W) for m in ("uniform", "optimal", "pitch") for W in (3, 5)
    }
    clips = res["protocol"]["clips"]
    assert clips == 1  # 298 frames at 120 fps -> 75 at 30 fps -> one 60-frame clip
    row = res["per_clip"][0]
    assert {"source", "start_frame", "method", "keyframes", "indices", "q"} <= set(row)
    assert "| optimal |" in capsys.readouterr().out


def test_extract_command_prints_and_writes_keyframes(cmu_dir, tmp_path, capsys):
    out = tmp_path / "k.json"
    rc = cli.main(
        [
            "extract",
            str(cmu_dir / "02" / "02.asf"),
            str(cmu_dir / "02" / "02_01.amc"),
            "--keyframes",
            "6",
            "--methods",
            "greedy",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    rows = json.loads(out.read_text())["clips"]
    assert rows and all(len(r["indices"]) == 6 and r["indices"][-1] == 59 for r in rows)
    assert "keyframes 0" in capsys.readouterr().out


def test_unknown_method_is_reported_with_choices(cmu_dir, tmp_path, capsys):
    asf, amc = str(cmu_dir / "02" / "02.asf"), str(cmu_dir / "02" / "02_01.amc")
    assert cli.main(["extract", asf, amc, "--keyframes", "6", "--methods", "nope"]) == 2
    assert "known:" in capsys.readouterr().err
    rc = cli.main(
        ["eval", "--data", str(cmu_dir), "--methods", "nope", "--out", str(tmp_path / "r")]
    )
    assert rc == 2 and "greedy" in capsys.readouterr().err


def test_load_cases_keeps_only_the_named_subjects(cmu_dir):
    from sidql.evaluation.cases import load_cases

    cases, skipped = load_cases(cmu_dir, subjects=["02", "35"], progress=False)
    sources = {c.clip.source.replace("\\", "/").split("/")[-2] for c in cases}
    assert sources == {"02", "35"} and not skipped


def test_case_indices_count_clips_across_trials_with_several_clips(cmu_dir):
    """The index seeds the random method: one per clip, in order, also inside trials of several
    clips (a skipped number would change Table 3's random row)."""
    from sidql.evaluation.cases import load_cases

    cases, _ = load_cases(cmu_dir, subjects=["05"], progress=False)
    assert len(cases) > len({c.clip.source for c in cases})
    assert [c.index for c in cases] == list(range(len(cases)))


def test_a_dataset_folder_at_another_rate_is_refused_not_mislabelled(walk_clip, tmp_path):
    """load_cases read a dataset folder's clips at their own rate whatever --fps said, and
    results.json recorded the --fps value as the protocol's."""
    from sidql.evaluation.cases import load_cases
    from sim.errors import MotionDataError
    from sim.motion.clip import save_npz

    save_npz(walk_clip, tmp_path / "02" / "c.npz")
    (tmp_path / "index.json").write_text(
        json.dumps({"trials": [{"subject": "02", "file": "02/c.npz"}]})
    )
    cases, _ = load_cases(tmp_path, fps=walk_clip.fps, progress=False)
    assert len(cases) == walk_clip.n_frames // 60
    with pytest.raises(MotionDataError, match="index.json: clips at 30 fps, not 60"):
        load_cases(tmp_path, fps=60.0, progress=False)


def test_a_trial_without_the_protocol_bones_is_skipped_not_fatal(cmu_dir, tmp_path):
    """A well-formed trial whose skeleton names its bones otherwise (no 'lhumerus') made the
    driver's make_case raise, and the whole evaluation exited 2, every good trial lost."""
    from sidql.evaluation.cases import load_cases

    for s, trial in (("02", "02_01"), ("07", "07_01")):
        (tmp_path / s).mkdir()
        for name in (f"{s}.asf", f"{trial}.amc"):
            text = (cmu_dir / s / name).read_text()
            (tmp_path / s / name).write_text(
                text.replace("lhumerus", "lupperarm") if s == "02" else text
            )
    cases, skipped = load_cases(tmp_path, progress=False)
    assert [c.clip.source for c in cases] == [str(tmp_path / "07" / "07_01.amc")]
    assert cases[0].index == 0
    assert len(skipped) == 1 and "lacks protocol point(s) lhumerus" in skipped[0]["problem"]


def test_a_dataset_clip_without_the_protocol_bones_is_skipped_not_fatal(cmu_dir, tmp_path):
    from sidql.evaluation.cases import load_cases
    from sim.motion.dataset import ingest_directory

    src = tmp_path / "cmu"
    for s, trial in (("02", "02_01"), ("07", "07_01")):
        (src / s).mkdir(parents=True)
        for name in (f"{s}.asf", f"{trial}.amc"):
            text = (cmu_dir / s / name).read_text()
            (src / s / name).write_text(
                text.replace("lhumerus", "lupperarm") if s == "02" else text
            )
    ingest_directory(src, tmp_path / "ds", workers=1, progress=False)
    cases, skipped = load_cases(tmp_path / "ds", progress=False)
    assert [c.clip.source for c in cases] == [str(src / "07" / "07_01.amc")]
    assert cases[0].index == 0
    assert len(skipped) == 1 and "lacks protocol point(s) lhumerus" in skipped[0]["problem"]
