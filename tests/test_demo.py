"""The main job: without CMU data it falls back to synthetic motion and still writes a report."""

from __future__ import annotations

import json

from sidql.commands.main import main


def test_demo_without_data_runs_the_pipeline_on_synthetic_motion(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(
        ["demo", "--data", str(tmp_path / "no-data"), "--out", str(out), "-W", "6",
         "--methods", "uniform", "optimal"]
    )  # fmt: skip
    text = capsys.readouterr().out
    assert code == 0
    assert "synthetic motion" in text and "| optimal | hermite |" in text
    checks = json.loads((out / "report" / "checks.json").read_text())
    runs = {m["method"]: m for m in checks["clips"][0]["methods"]}
    assert set(runs) == {"uniform", "optimal"}
    assert runs["optimal"]["indices"][0] == 0 and len(runs["optimal"]["indices"]) == 6
    # Spherical Hermite keeps bone lengths: the replay sees no drift.
    assert runs["optimal"]["summary"]["bone_drift_max_mm"] < 1e-6
    assert (out / "report" / "index.html").stat().st_size > 10_000
    assert (out / "motion.npz").exists()
