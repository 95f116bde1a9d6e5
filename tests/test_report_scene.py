"""The report draws each clip's inferred scene (``sim.simulate.terrain``) in the original's
frame, where the original's feet stood (the frame itself: tests/test_simulate_terrain.py,
``clip_scene``; no scene for a flat walk: tests/test_report_simulate.py)."""

from __future__ import annotations

import json

import numpy as np


def test_report_on_the_playground_climb_draws_its_step(cmu_dir, tmp_path):
    """01_02's clip 3 (source frame 720, inferred steps in docs/results/simulate_terrain.md):
    the subject stands on the playground's high platform, one foot stepping down at the end.
    Without --simulate the report infers the same scene (cheap) and draws it in the filmstrip."""
    from PIL import Image

    from sidql.evaluation.report import report_trial
    from sim.motion.ingest import load_motion

    asf, amc = cmu_dir / "01" / "01.asf", cmu_dir / "01" / "01_02.amc"
    page = report_trial(asf, amc, tmp_path / "r", W=4, methods=["uniform"], clips=[3],
                        videos=False, progress=False)  # fmt: skip
    clip = json.loads((tmp_path / "r" / "checks.json").read_text())["clips"][0]
    assert clip["start_frame"] == 720 and len(clip["scene"]) == 1
    (box,) = clip["scene"]
    top = box["centre"][2] + box["half"][2]
    # the oracle: the clip's own foot points (joint centres a few cm above the soles)
    c = load_motion(asf, amc, fps=30.0).split(60)[3]
    feet = [c.names.index(n) for n in ("lfoot", "rfoot", "ltoes", "rtoes")]
    lowest = c.positions[:, feet, 2].min(axis=1)  # (T,) [m]
    standing = np.median(lowest[:40])  # both feet on the platform for the first 40 frames
    assert 0.0 < standing - top < 0.08  # the box's top just under them, in their frame
    assert clip["scene_ground"] < top - 0.1  # the ground it stands on, below
    xy = np.array(box["centre"][:2])
    on = np.linalg.norm(c.positions[:40, feet, :2].mean(axis=1) - xy, axis=1)
    assert np.median(on) < max(box["half"][:2]) + 0.1  # and under them horizontally
    assert "Scene inferred from the original" in page.read_text()
    strip = np.asarray(Image.open(tmp_path / "r" / "clip03_uniform_keyframes.png").convert("RGB"))
    warm = strip[..., 0].astype(int) - strip[..., 2] > 25  # the step's sand colour
    assert warm.sum() > 500
