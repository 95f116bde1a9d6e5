"""The API reference builds from the docstrings (scripts/make_api_docs.py, pdoc) and documents
the public names a user reaches first."""

from __future__ import annotations

import importlib.util
import pkgutil
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

pytest.importorskip("pdoc", reason="pdoc (extra 'test') builds the API reference")


def _script():
    spec = importlib.util.spec_from_file_location(
        "make_api_docs", ROOT / "scripts" / "make_api_docs.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_module_is_named_once():
    names = _script().module_names()
    assert len(names) == len(set(names))
    # modules importable as found by pkgutil, plus namespace packages' modules by hand
    expected = {"sim.analysis.job", "sidql.commands.main", "sim.errors", "sidql.keyframes.counts"}
    for package in ("sim", "sidql"):
        expected |= {m.name for m in pkgutil.walk_packages([str(ROOT / package)], f"{package}.")}
    assert expected <= set(names), sorted(expected - set(names))


@pytest.mark.slow
def test_the_api_reference_documents_the_public_names(tmp_path):
    index = _script().build(tmp_path / "api")
    assert index.is_file()

    def page(module: str) -> str:
        return (tmp_path / "api" / (module.replace(".", "/") + ".html")).read_text()

    def documented(module: str, name: str) -> bool:  # pdoc anchors each member by its name
        return re.search(rf'id="{re.escape(name)}"', page(module)) is not None

    for module, name in [
        ("sidql", "select"), ("sidql", "reconstruct"), ("sidql", "q_error"),
        ("sidql.keyframes.methods", "select"), ("sidql.keyframes.counts", "check_counts"),
        ("sidql.keyframes.reconstructions", "RECONSTRUCTIONS"),
        ("sidql.learning.env", "KeyframeEnv"), ("sidql.codec.encode", "encode_files"),
        ("sidql.evaluation.report", "report_trial"), ("sim", "SidqlError"),
        ("sim.errors", "UsageError"), ("sim.motion.ingest", "load_motion"),
        ("sim.batch", "run_batch"), ("sim.analysis.job", "PhysicsJob"),
    ]:  # fmt: skip
        assert documented(module, name), (module, name)
    assert "Choose W keyframes of" in page("sidql.keyframes.methods")  # a docstring, whole
