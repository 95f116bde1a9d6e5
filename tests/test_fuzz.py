"""Property-based fuzzing of every reader over mutations of real files.

Property: reading a mutated ASF/AMC raises only MotionDataError (naming a file, and a real line when
it gives one) or returns all-finite values; for a subset the full path (parse -> model build ->
retarget -> velocities) holds it too. The same holds for every other file type a command reads
(``.sidq`` streams, clip ``.npz`` files, dataset folders with their ``index.json``, policy files,
training checkpoints; ``tests/hostile_inputs.py``): one printable line naming a file inside the
input's folder, nothing read from outside it, or finite values (valid decisions, a checkpoint that
resumes and trains a step). Deterministic (``derandomize``) and bounded for CI; the long campaign,
with memory and time measured per input, is ``benchmarks/fuzz_campaign.py``.
"""

from __future__ import annotations

import functools
import random
from pathlib import Path

import hostile_inputs
import pytest
from acclaim_mutations import MUTATORS, check_outcome, mutate, seed_amc
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

# Subjects with different skeleton files; trials chosen small.
PAIRS = (("02", "02_01"), ("07", "07_12"), ("09", "09_06"), ("16", "16_25"), ("60", "60_01"))
FUZZ = settings(
    max_examples=250,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    database=None,
)


def rng_from(data) -> random.Random:
    """A ``random.Random`` seeded by hypothesis: positions spread over the whole file.

    (Drawing each position through hypothesis would let it shrink them, but its integer draws
    favour small values, i.e. the first lines of a file, where a few mutations only ever hit the
    header; a drawn seed covers the whole file and still replays exactly.)
    """
    return random.Random(data.draw(st.integers(0, 2**64 - 1), label="seed"))


@functools.lru_cache(maxsize=1)
def load_seeds(cmu_dir: Path) -> dict[str, tuple[bytes, bytes]]:
    """trial -> (ASF bytes, AMC bytes cut to its first frames). Not a fixture: hypothesis would
    print its whole value in a failure report."""
    out = {}
    for subject, trial in PAIRS:
        if not (cmu_dir / subject / f"{trial}.amc").exists():
            continue
        asf = (cmu_dir / subject / f"{subject}.asf").read_bytes()
        amc = seed_amc((cmu_dir / subject / f"{trial}.amc").read_bytes())
        out[trial] = (asf, amc)
    assert out, "no seed trials found"
    return out


def run_case(tmp: Path, asf: bytes, amc: bytes, *, full: bool, skeleton: str = "subject") -> str:
    tmp.mkdir(parents=True, exist_ok=True)
    (tmp / "t.asf").write_bytes(asf)
    (tmp / "t.amc").write_bytes(amc)
    return check_outcome(tmp / "t.asf", tmp / "t.amc", full=full, skeleton=skeleton)


def test_every_mutator_changes_some_seed(cmu_dir):
    seeds = load_seeds(cmu_dir)
    asf, amc = next(iter(seeds.values()))
    for m in MUTATORS:
        rng = random.Random(0)
        assert any(m(amc, rng) != amc for _ in range(20)), m.__name__


@FUZZ
@given(data=st.data())
def test_mutated_amc_reads_cleanly_or_fails_cleanly(cmu_dir, tmp_path_factory, data):
    seeds = load_seeds(cmu_dir)
    trial = data.draw(st.sampled_from(sorted(seeds)))
    asf, amc = seeds[trial]
    amc, _ = mutate(amc, rng_from(data))
    run_case(tmp_path_factory.mktemp("amc"), asf, amc, full=False)


@FUZZ
@given(data=st.data())
def test_mutated_asf_reads_cleanly_or_fails_cleanly(cmu_dir, tmp_path_factory, data):
    seeds = load_seeds(cmu_dir)
    trial = data.draw(st.sampled_from(sorted(seeds)))
    asf, amc = seeds[trial]
    asf, _ = mutate(asf, rng_from(data))
    run_case(tmp_path_factory.mktemp("asf"), asf, amc, full=False)


@settings(FUZZ, max_examples=60)
@given(data=st.data())
def test_mutated_files_survive_model_build_retarget_and_velocities(cmu_dir, tmp_path_factory, data):
    seeds = load_seeds(cmu_dir)
    trial = data.draw(st.sampled_from(sorted(seeds)))
    asf, amc = seeds[trial]
    which = data.draw(st.sampled_from(("asf", "amc", "both")))
    rng = rng_from(data)
    if which in ("asf", "both"):
        asf, _ = mutate(asf, rng)
    if which in ("amc", "both"):
        amc, _ = mutate(amc, rng)
    skeleton = data.draw(st.sampled_from(("subject", "humanoid")))
    run_case(tmp_path_factory.mktemp("full"), asf, amc, full=True, skeleton=skeleton)


# --- every other file type --------------------------------------------------------------------


@pytest.fixture(scope="session")
def hostile_seeds(cmu_dir, tmp_path_factory):
    """Real seeds of every file type (``hostile_inputs.build_seeds``: a few seconds)."""
    return hostile_inputs.build_seeds(cmu_dir, tmp_path_factory.mktemp("seeds"))


def read_hostile(kind, seeds, tmp_path_factory, data) -> str:
    case = hostile_inputs.make_case(kind, seeds, rng_from(data))
    folder = tmp_path_factory.mktemp(kind) / "case"
    folder.mkdir()
    return hostile_inputs.run_case(case, folder, seeds.checkpoint_args)


@pytest.mark.parametrize(
    ("kind", "examples"),
    [
        ("bvh", 60),
        ("sidq", 60),
        ("sidm", 40),
        ("npz", 60),
        ("index", 40),
        ("policy", 40),
        ("checkpoint", 30),
    ],
)
def test_every_reader_reads_cleanly_or_fails_cleanly(kind, examples, hostile_seeds,
                                                      tmp_path_factory):  # fmt: skip
    @settings(FUZZ, max_examples=examples)
    @given(data=st.data())
    def property_holds(data):
        assert read_hostile(kind, hostile_seeds, tmp_path_factory, data) in ("ok", "error")

    property_holds()


@pytest.mark.parametrize("kind", hostile_inputs.KINDS)
def test_the_seeds_themselves_read(kind, hostile_seeds, tmp_path):
    """The property is not vacuous: every unmutated seed reads to finite values."""
    folder = tmp_path / "case"
    folder.mkdir()
    case = hostile_inputs.seed_case(kind, hostile_seeds)
    assert hostile_inputs.run_case(case, folder, hostile_seeds.checkpoint_args) == "ok"
