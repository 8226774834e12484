"""Property: load_motion on any mutation of a real mocap file either returns a usable Motion
(finite arrays, fps > 0, at least one frame) or raises MocapFormatError with a one-line message
naming a file of the case. The mutations are those of benchmarks/bench_mocap_fuzz.py (which runs
thousands of them); here a small fixed-seed budget (Hypothesis, derandomized)."""
from __future__ import annotations

import random
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchmarks.bench_mocap_fuzz import (
    MUTATIONS, SPECIAL_NUMBERS, base_case, check_motion, main_file, mutate_case, replace_number, source_cases,
    structure_lines,
)
from motion_graph.errors import QUOTE_CHARS, MocapFormatError
from motion_graph.io import load_motion
from motion_graph.motion import Motion

pytestmark = pytest.mark.realdata

FUZZ = settings(max_examples=100, derandomize=True, deadline=None, database=None, print_blob=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@pytest.fixture(scope="module")
def cases(mocap_root: Path) -> dict[str, list[dict[str, Path]]]:
    """The real cases, BVH and AMC (+ ASF) apart."""
    found = source_cases(mocap_root)
    out = {"bvh": [c for c in found if main_file(c).endswith(".bvh")],
           "amc": [c for c in found if main_file(c).endswith(".amc")]}
    if not out["bvh"] or not out["amc"]:
        pytest.skip(f"real BVH and AMC files needed under {mocap_root}")
    return out


def _load(files: dict[str, bytes]) -> Motion | MocapFormatError:
    """Write the case's files to a fresh folder and load its main file."""
    with tempfile.TemporaryDirectory() as d:
        for name, data in files.items():
            Path(d, name).write_bytes(data)
        path = str(Path(d, main_file(files)))
        try:
            return load_motion(path)
        except MocapFormatError as e:
            s = str(e)
            assert "\n" not in s and "\r" not in s, s
            assert Path(e.path).parent == Path(d) and s.startswith(e.path), s
            assert len(e.problem) <= 5 * QUOTE_CHARS + 100, s
            return e


def _holds(files: dict[str, bytes]) -> None:
    out = _load(files)
    if isinstance(out, Motion):
        assert check_motion(out) is None, check_motion(out)


@FUZZ
@given(st.randoms(use_true_random=False))
def test_mutated_bvh_loads_or_is_a_format_error(cases, rng: random.Random) -> None:
    files, _ = mutate_case(base_case(rng.choice(cases["bvh"]), rng), rng)
    _holds(files)


@FUZZ
@given(st.randoms(use_true_random=False))
def test_mutated_asf_amc_loads_or_is_a_format_error(cases, rng: random.Random) -> None:
    files, _ = mutate_case(base_case(rng.choice(cases["amc"]), rng), rng)
    _holds(files)


@settings(FUZZ, max_examples=80)
@given(st.randoms(use_true_random=False), st.sampled_from(sorted(MUTATIONS)))
def test_every_mutation_kind_holds(cases, rng: random.Random, kind: str) -> None:
    source = rng.choice(cases["bvh"] + cases["amc"])
    files = base_case(source, rng)
    target = rng.choice(sorted(files))
    files[target] = MUTATIONS[kind](files[target], rng)
    _holds(files)


@FUZZ
@given(st.data())
def test_special_number_on_a_structure_line_holds(cases, data: st.DataObject) -> None:
    """A special number in an OFFSET, CHANNELS, Frames:, Frame Time:, ASF length / direction /
    axis / units line or an AMC frame number (where the old loaders crashed or loaded nan)."""
    source = data.draw(st.sampled_from(cases["bvh"] + cases["amc"]), label="source")
    files = base_case(source, data.draw(st.randoms(use_true_random=False), label="rng"))
    target = data.draw(st.sampled_from(sorted(files)), label="file")
    lines = files[target].splitlines(keepends=True)
    i = data.draw(st.sampled_from(structure_lines(lines)), label="line")
    lines[i] = replace_number(lines[i], data.draw(st.integers(0, 8), label="number"),
                              data.draw(st.sampled_from(SPECIAL_NUMBERS), label="special"))
    files[target] = b"".join(lines)
    _holds(files)


@pytest.mark.parametrize("special", [s for s in SPECIAL_NUMBERS if s != "0" * 5000 + "1"])  # that one reads as 1
def test_special_numbers_in_bvh_header_are_format_errors(cases, special: str) -> None:
    """Each special number as the Frames: count and as the Frame Time (these crashed with
    ValueError, allocated from the count, or loaded 0 or nan fps)."""
    src = next(c for c in cases["bvh"] if main_file(c) == "13_17.bvh")
    files = base_case(src, random.Random(1))  # cut to a few frames
    name = main_file(files)
    lines = files[name].decode().split("\n")
    i = next(k for k, line in enumerate(lines) if line.startswith("Frames:"))
    for k, line in ((i, f"Frames: {special}"), (i + 1, f"Frame Time: {special}")):
        edited = list(lines)
        edited[k] = line
        assert isinstance(_load({name: "\n".join(edited).encode()}), MocapFormatError), line[:40]


def test_unmutated_bases_load(cases) -> None:
    """The bases the mutations start from are valid files (the property's other branch is reached)."""
    rng = random.Random(0)
    for case in cases["bvh"][:3] + cases["amc"][:1]:
        m = _load(base_case(case, rng))
        assert isinstance(m, Motion) and check_motion(m) is None


def test_check_motion_flags_unusable_motions(cases) -> None:
    """The property's oracle rejects what it must: nan, inf, fps <= 0."""
    m = _load(base_case(cases["bvh"][0], random.Random(2)))
    assert isinstance(m, Motion) and check_motion(m) is None
    bad = Motion(m.skeleton, m.rotations.copy(), m.root_positions.copy(), m.fps, m.local_translations, m.source)
    bad.root_positions[0, 1] = np.nan
    assert check_motion(bad) is not None
    bad = Motion(m.skeleton, m.rotations, m.root_positions, 0.0, m.local_translations, m.source)
    assert check_motion(bad) is not None
