"""Shared fixtures: the real CMU files (the data folder setting of :mod:`sim.paths`: $SIDQL_DATA,
else ../shared/cmu beside the checkout)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from sim.paths import DATA_ENV, default_data_dir  # standard library only: MuJoCo not yet imported

os.environ.setdefault("MUJOCO_GL", "egl")

REPO = Path(__file__).resolve().parent.parent
CMU = default_data_dir()


@pytest.fixture(scope="session")
def cmu_dir() -> Path:
    """The real CMU data folder; tests that need it skip (saying why) when it is absent."""
    if CMU is None or not (CMU / "MANIFEST.tsv").exists():
        pytest.skip(f"real CMU data not found at {CMU or '../shared/cmu'} (set {DATA_ENV})")
    return CMU


@pytest.fixture(scope="session")
def walk_bvh(cmu_dir, tmp_path_factory) -> Path:
    """01_01 (2,751 frames at 120 fps, many text chunks) written as BVH by ``sidql convert``."""
    from sidql.commands.main import main

    bvh = tmp_path_factory.mktemp("bvh") / "walk.bvh"
    assert main(["convert", str(cmu_dir / "01" / "01.asf"), str(cmu_dir / "01" / "01_01.amc"),
                 str(bvh)]) == 0  # fmt: skip
    return bvh


@pytest.fixture(scope="session")
def walk_clip(cmu_dir):
    """Subject 02's walk 02_01 at 30 fps on its own skeleton."""
    from sim.motion.ingest import load_motion

    return load_motion(cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc")


@pytest.fixture(scope="session")
def trial_on_floor(cmu_dir):
    """A function: ``(model, "02_01")`` -> that CMU trial's ``qpos`` (T, nq) at 120 Hz for the
    simulated ``model``, lowered onto its floor (``sim.simulate.reference``)."""
    from sim.simulate.reference import on_floor, trial_qpos

    def reference(model, trial: str):
        subject = cmu_dir / trial.split("_")[0]
        return on_floor(
            model, trial_qpos(subject / f"{subject.name}.asf", subject / f"{trial}.amc")
        )

    return reference


@pytest.fixture(scope="session")
def gl_context() -> None:
    """Skip (saying why) only when no offscreen OpenGL context can be created on this machine.

    The probe is a bare MuJoCo GL context, nothing of ours: any failure after it (a bad scene,
    a bad material) fails the test instead of skipping it.
    """
    try:
        import mujoco  # after MUJOCO_GL is set above

        ctx = mujoco.GLContext(64, 64)
        ctx.make_current()
        ctx.free()
    except (ImportError, RuntimeError, OSError) as e:
        pytest.skip(f"no offscreen GL context (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {e}")
