"""Where files are found: shipped files through importlib.resources, one setting for the data
folder ($SIDQL_DATA, else ../shared/cmu beside the checkout)."""

from pathlib import Path

import mujoco

from sidql.learning.policy import DEFAULT_POLICY
from sim import paths
from sim.model.humanoid import CANONICAL_ASF, HUMANOID_XML, humanoid_model

REPO = Path(__file__).resolve().parents[1]


def test_shipped_files_are_package_data_and_load():
    for f, package in ((HUMANOID_XML, "sim"), (CANONICAL_ASF, "sim"), (DEFAULT_POLICY, "sidql")):
        assert f.is_file() and f.resolve().parent == (REPO / package / "data").resolve()
    skeleton, model = humanoid_model()
    assert isinstance(model, mujoco.MjModel) and model.nbody > 20 and skeleton.bone_names


def test_the_checkout_models_folder_links_to_the_shipped_humanoid():
    link = REPO / "models" / "cmu_humanoid.xml"
    assert link.resolve() == HUMANOID_XML.resolve()


def test_the_data_folder_is_one_setting(monkeypatch, tmp_path):
    monkeypatch.setenv(paths.DATA_ENV, str(tmp_path / "cmu"))
    assert paths.default_data_dir() == tmp_path / "cmu"  # named, even if absent: fail loudly
    assert paths.data_dir(tmp_path / "other") == tmp_path / "other"  # --data wins
    monkeypatch.delenv(paths.DATA_ENV)
    beside = REPO.parent / "shared" / "cmu"
    assert paths.checkout_root() == REPO
    assert paths.default_data_dir() == (beside if beside.is_dir() else None)
