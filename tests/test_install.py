"""The project installs like a package: a wheel built from this tree, installed into a fresh
virtual environment, runs from outside the checkout and finds its own files (the shared humanoid,
the canonical skeleton, the policy) inside the installation.

Offline and quick: the wheel is built with this environment's setuptools (no build isolation),
installed without dependencies, and the fresh environment sees this environment's packages
(numpy, MuJoCo, ...) through a path entry, not the checkout.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

import sidql

REPO = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def run(argv, cwd, env=None, timeout=300) -> str:
    out = subprocess.run(
        [str(a) for a in argv], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )
    assert out.returncode == 0, f"{argv}:\n{out.stdout}\n{out.stderr}"
    return out.stdout


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> dict:
    """A fresh venv holding only the built wheel (plus a path entry to this environment's
    third-party packages); returns its bin folder and an environment for running it."""
    tmp = tmp_path_factory.mktemp("install")
    src = (
        tmp / "src"
    )  # build from a copy: setuptools writes build/ and *.egg-info beside the source
    junk = shutil.ignore_patterns("__pycache__", "*.pyc", "*.nbi", "*.nbc")
    for name in ("sim", "sidql"):
        shutil.copytree(REPO / name, src / name, ignore=junk)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name)
    py = sys.executable
    run([py, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
         "-w", tmp / "dist", src], cwd=tmp)  # fmt: skip
    (wheel,) = (tmp / "dist").glob("sidql-*.whl")
    venv = tmp / "venv"
    run([py, "-m", "venv", "--without-pip", venv], cwd=tmp)
    vpy = venv / "bin" / "python"
    run([py, "-m", "pip", "--python", vpy, "install", "--no-deps", "--no-index", "-q", wheel],
        cwd=tmp)  # fmt: skip
    # This environment's third-party packages, as a plain path entry: its .pth files (among them
    # an editable install of this checkout) are not processed, so sim and sidql come from the wheel.
    site = run([vpy, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"], tmp)
    Path(site.strip(), "parent_env.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    elsewhere = tmp / "elsewhere"
    elsewhere.mkdir()
    env = {
        "PATH": f"{venv / 'bin'}:/usr/bin:/bin",
        "HOME": str(tmp),
        "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl"),
        "NUMBA_CACHE_DIR": str(tmp / "numba"),
    }
    return {"bin": venv / "bin", "env": env, "cwd": elsewhere, "venv": venv, "wheel": wheel}


def test_the_wheel_holds_the_packages_and_their_files(installed):
    names = set(zipfile.ZipFile(installed["wheel"]).namelist())
    for f in ("sim/data/cmu_humanoid.xml", "sim/data/canonical.asf", "sidql/data/policy.pt",
              "sidql/data/report.css", "sidql/data/report.js", "sim/paths.py",
              "sidql/commands/main.py"):  # fmt: skip
        assert f in names, f
    assert not any(n.startswith(("tests/", "benchmarks/", "docs/")) for n in names)


def test_the_installed_command_runs_from_outside_the_checkout(installed, tmp_path):
    bin_, env, cwd = installed["bin"], installed["env"], installed["cwd"]
    assert run([bin_ / "sidql", "--version"], cwd, env).strip() == f"sidql {sidql.__version__}"
    where = run(
        [bin_ / "python", "-c", "import sidql, sim.model.humanoid as h, sidql.learning.policy as p; "
         "print(sidql.__file__, h.HUMANOID_XML, h.CANONICAL_ASF, p.DEFAULT_POLICY, sep='\\n')"],
        cwd, env,
    ).split()  # fmt: skip
    for path in where:  # the installation's own files, not the checkout's
        assert Path(path).is_relative_to(installed["venv"]) and Path(path).is_file(), path
    # no --data, no $SIDQL_DATA, no checkout: the demo's motion is generated on the shared humanoid
    out = run([bin_ / "sidql", "demo", "--no-report", "--out", tmp_path / "demo"], cwd, env)
    assert "synthetic motion" in out and (tmp_path / "demo" / "motion.npz").is_file()


def test_the_installed_command_ingests_onto_the_shared_humanoid(installed, cmu_dir, tmp_path):
    bin_, env, cwd = installed["bin"], installed["env"], installed["cwd"]
    asf, amc = cmu_dir / "02" / "02.asf", cmu_dir / "02" / "02_01.amc"
    out = tmp_path / "walk.npz"
    run([bin_ / "sidql", "ingest", asf, amc, "--skeleton", "humanoid", "--out", out], cwd, env)
    assert out.is_file()
    # the data folder setting of an installed package: $SIDQL_DATA (there is no checkout)
    env = {**env, "SIDQL_DATA": str(cmu_dir)}
    shown = run([bin_ / "python", "-c", "from sim.paths import data_dir; print(data_dir())"],
                cwd, env)  # fmt: skip
    assert shown.strip() == str(cmu_dir)
