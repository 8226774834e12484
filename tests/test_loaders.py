"""BVH and ASF/AMC loaders on the real mocap, their error messages on malformed and hostile input
(caps, ASCII numbers, deep and cyclic hierarchies), and semantic parts."""
from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np
import pytest

from motion_graph.errors import MocapFormatError
from motion_graph.io import find_mocap_files, load_motion
from motion_graph.io_asfamc import AsfSkeleton, load_amc, load_asf, load_asf_amc
from motion_graph.io_bvh import load_bvh, save_bvh
from motion_graph.motion import Motion
from motion_graph.semantics import REQUIRED_PARTS, load_part_overrides, require_parts, resolve_parts

#: README section 1: file -> (frames, fps).
EXPECTED = {
    "cmu/boxing/13_17.bvh": (4840, 120.0),
    "cmu/boxing/13_18.bvh": (3000, 120.0),
    "cmu/martial_arts/135_06.bvh": (3261, 120.0),
    "cmu/asf_amc/13_17.amc": (4840, 120.0),
    "cmu/asf_amc/13_18.amc": (3000, 120.0),
    "cmu/asf_amc/135_06.amc": (3261, 120.0),
    "bandai_namco/dataset-1_punch_normal_001.bvh": (224, 30.0),
    "bandai_namco/dataset-1_punch_normal_002.bvh": (284, 30.0),
    "bandai_namco/dataset-1_kick_normal_001.bvh": (358, 30.0),
    "bandai_namco/dataset-1_walk_normal_001.bvh": (195, 30.0),
    "bandai_namco/dataset-1_walk-back_normal_001.bvh": (31, 30.0),
    "bandai_namco/dataset-1_walk-left_normal_001.bvh": (135, 30.0),
    "bandai_namco/dataset-1_walk-right_normal_001.bvh": (135, 30.0),
}
CMU_M_PER_UNIT = 0.0254 / 0.45
BANDAI = "bandai_namco/dataset-1_punch_normal_001.bvh"

pytestmark = pytest.mark.realdata


class _Cache:
    """Loads each file (and its positions) once per module."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self._m: dict[str, Motion] = {}
        self._p: dict[str, np.ndarray] = {}

    def motion(self, rel: str) -> Motion:
        if rel not in self._m:
            f = self.root / rel
            if not f.is_file():  # e.g. a root that is only the fetch-cmu cache
                msg = f"{rel} not under the mocap root {self.root}"
                if os.environ.get("CI") == "true":
                    pytest.fail(msg)
                pytest.skip(msg)
            self._m[rel] = load_motion(f)
        return self._m[rel]

    def positions(self, rel: str) -> np.ndarray:
        if rel not in self._p:
            self._p[rel] = self.motion(rel).positions()
        return self._p[rel]


@pytest.fixture(scope="module")
def cache(mocap_root: Path) -> _Cache:
    return _Cache(mocap_root)


# ---------------------------------------------------------------- real files


@pytest.mark.parametrize("rel", sorted(EXPECTED))
def test_real_file_loads(cache: _Cache, rel: str) -> None:
    frames, fps = EXPECTED[rel]
    m = cache.motion(rel)
    assert m.n_frames == frames
    assert m.fps == fps
    sk = m.skeleton
    assert sk.metres_per_unit == pytest.approx(0.01 if rel.startswith("bandai") else CMU_M_PER_UNIT)
    pos = cache.positions(rel)
    assert pos.shape == (frames, sk.n_joints, 3) and np.all(np.isfinite(pos))
    pelvis = resolve_parts(sk)["pelvis"]
    assert 0.7 <= float(np.median(pos[:, pelvis, 1])) <= 1.2  # metres, Y up
    # Whole body in metres: head above pelvis by a human amount.
    head = resolve_parts(sk)["head"]
    assert 0.3 <= float(np.median(pos[:, head, 1] - pos[:, pelvis, 1])) <= 0.9


def test_every_mocap_file_under_root_loads(mocap_root: Path, cache: _Cache) -> None:
    files = [f for f in mocap_root.rglob("*") if f.suffix.lower() in (".bvh", ".amc")]
    rels = {f.relative_to(mocap_root).as_posix() for f in files}
    assert rels
    for rel in sorted(rels - set(EXPECTED)):  # files not in the README table: at least they load
        m = cache.motion(rel)
        assert m.n_frames > 0 and m.fps > 0
    # find_mocap_files drops an AMC when a BVH of the same stem was found (anywhere under the root).
    bvh_stems = {Path(r).stem for r in rels if r.endswith(".bvh")}
    want = sorted(r for r in rels if r.endswith(".bvh") or Path(r).stem not in bvh_stems)
    assert sorted(f.relative_to(mocap_root).as_posix() for f in find_mocap_files([mocap_root])) == want


def test_asf_amc_matches_bvh_13_17(cache: _Cache) -> None:
    amc, bvh = cache.motion("cmu/asf_amc/13_17.amc"), cache.motion("cmu/boxing/13_17.bvh")
    # Same DFS joint order, different names: map by index.
    assert amc.skeleton.n_joints == bvh.skeleton.n_joints
    np.testing.assert_array_equal(amc.skeleton.parents, bvh.skeleton.parents)
    np.testing.assert_array_equal(amc.skeleton.is_end_site, bvh.skeleton.is_end_site)
    pa, pb = cache.positions("cmu/asf_amc/13_17.amc"), cache.positions("cmu/boxing/13_17.bvh")
    assert pa.shape == pb.shape
    err = np.linalg.norm(pa - pb, axis=-1)  # (T, J) metres
    assert float(err.max()) < 0.01, f"max joint error {err.max():.4f} m at frame {np.unravel_index(err.argmax(), err.shape)}"


# ---------------------------------------------------------------- malformed BVH

N_SMALL = 20


@pytest.fixture(scope="module")
def bvh_lines(boxing_files: list[Path]) -> list[str]:
    """13_17.bvh cut to its hierarchy and first N_SMALL frames (a valid file)."""
    lines = boxing_files[0].read_text().splitlines()
    m = lines.index("MOTION")
    assert lines[m + 1].startswith("Frames:")
    return lines[:m + 1] + [f"Frames: {N_SMALL}"] + lines[m + 2:m + 3 + N_SMALL]


def _frame_line(lines: list[str], k: int) -> int:
    """1-based file line of frame k (1-based) in a BVH."""
    return lines.index("MOTION") + 3 + k


def _write(tmp_path: Path, name: str, lines: list[str], eol: str = "\n") -> Path:
    p = tmp_path / name
    p.write_bytes((eol.join(lines) + eol).encode() if lines else b"")
    return p


def _raises(load, path: Path, line: int | None = None, match: str | None = None) -> MocapFormatError:
    with pytest.raises(MocapFormatError) as ei:
        load(path)
    e = ei.value
    s = str(e)
    assert "\n" not in s and "\r" not in s, f"message is not one line: {s!r}"
    assert s.startswith(str(path)) and e.path == str(path)
    if line is not None:
        assert e.line == line and s.startswith(f"{path}:{line}: "), s
    if match is not None:
        assert match in s, s
    return e


def test_small_bvh_is_valid(tmp_path: Path, bvh_lines: list[str]) -> None:
    m = load_bvh(_write(tmp_path, "ok.bvh", bvh_lines))
    assert m.n_frames == N_SMALL and m.fps == 120.0


def test_bvh_fps_override(tmp_path: Path, bvh_lines: list[str]) -> None:
    p = _write(tmp_path, "ok.bvh", bvh_lines)
    for m in (load_bvh(p, fps=30), load_motion(p, fps=30)):
        assert m.fps == 30.0 and m.n_frames == N_SMALL
        assert m.duration == pytest.approx((N_SMALL - 1) / 30)


def test_bvh_truncated_at_line_boundary(tmp_path: Path, bvh_lines: list[str]) -> None:
    lines = bvh_lines[:_frame_line(bvh_lines, 11)]  # frames 1..11 of 20
    p = _write(tmp_path, "trunc.bvh", lines)
    e = _raises(load_bvh, p, line=len(lines), match="truncated")
    assert "20 frames" in str(e) and "found 11" in str(e)


def test_bvh_truncated_mid_line(tmp_path: Path, bvh_lines: list[str]) -> None:
    ln = _frame_line(bvh_lines, 11)
    text = "\n".join(bvh_lines[:ln])
    p = tmp_path / "cut.bvh"
    p.write_text(text[:len(text) - len(bvh_lines[ln - 1]) // 2])  # half of frame 11's numbers
    _raises(load_bvh, p, line=ln, match="frame 11 has")


def test_bvh_wrong_channel_count(tmp_path: Path, bvh_lines: list[str]) -> None:
    lines = list(bvh_lines)
    ln = _frame_line(lines, 5)
    lines[ln - 1] = " ".join(lines[ln - 1].split()[:-1])
    _raises(load_bvh, _write(tmp_path, "count.bvh", lines), line=ln, match="frame 5 has 95 values")


def test_bvh_non_numeric(tmp_path: Path, bvh_lines: list[str]) -> None:
    lines = list(bvh_lines)
    ln = _frame_line(lines, 7)
    toks = lines[ln - 1].split()
    toks[10] = "1.2.3"
    lines[ln - 1] = " ".join(toks)
    _raises(load_bvh, _write(tmp_path, "nan.bvh", lines), line=ln, match="'1.2.3'")


def test_bvh_non_finite(tmp_path: Path, bvh_lines: list[str]) -> None:
    lines = list(bvh_lines)
    ln = _frame_line(lines, 3)
    toks = lines[ln - 1].split()
    toks[4] = "inf"
    lines[ln - 1] = " ".join(toks)
    _raises(load_bvh, _write(tmp_path, "inf.bvh", lines), match="non-finite")


def test_bvh_missing_motion_section(tmp_path: Path, bvh_lines: list[str]) -> None:
    m = bvh_lines.index("MOTION")
    _raises(load_bvh, _write(tmp_path, "nomotion.bvh", bvh_lines[:m]), match="no MOTION section")
    # Only the keyword missing: the error points at the first line after the hierarchy.
    lines = bvh_lines[:m] + bvh_lines[m + 1:]
    _raises(load_bvh, _write(tmp_path, "nokeyword.bvh", lines), line=m + 1, match="Frames:")


def test_bvh_empty_file(tmp_path: Path) -> None:
    _raises(load_bvh, _write(tmp_path, "empty.bvh", []), match="empty file")
    _raises(load_bvh, _write(tmp_path, "blank.bvh", ["", "   "]), match="empty file")


# ---------------------------------------------------------------- malformed ASF / AMC


@pytest.fixture(scope="module")
def asf_path(mocap_root: Path) -> Path:
    return mocap_root / "cmu" / "asf_amc" / "13.asf"


@pytest.fixture(scope="module")
def asf(asf_path: Path) -> AsfSkeleton:
    return load_asf(asf_path)


@pytest.fixture(scope="module")
def amc_lines(mocap_root: Path) -> list[str]:
    """13_17.amc cut to its header and first N_SMALL frames (a valid file)."""
    lines = (mocap_root / "cmu" / "asf_amc" / "13_17.amc").read_bytes().decode().splitlines()
    end = lines.index(str(N_SMALL + 1))
    return lines[:end]


def _amc_line(lines: list[str], frame: int, bone: str) -> int:
    """1-based line of `bone` in AMC frame `frame`."""
    i = lines.index(str(frame))
    while lines[i].split()[0] != bone:
        i += 1
    return i + 1


def test_small_amc_is_valid_and_fps_override(tmp_path: Path, amc_lines: list[str], asf: AsfSkeleton,
                                             asf_path: Path) -> None:
    p = _write(tmp_path, "13_90.amc", amc_lines, eol="\r\n")  # CRLF, as the CMU files
    m = load_amc(p, asf)
    assert m.n_frames == N_SMALL and m.fps == 120.0
    assert load_amc(p, asf, fps=30).fps == 30.0
    (tmp_path / "13.asf").write_bytes(asf_path.read_bytes())
    assert load_motion(p, fps=30).fps == 30.0 and load_motion(p).fps == 120.0
    assert load_asf_amc(p).n_frames == N_SMALL


def test_amc_wrong_value_count(tmp_path: Path, amc_lines: list[str], asf: AsfSkeleton) -> None:
    lines = list(amc_lines)
    ln = _amc_line(lines, 4, "lfemur")
    lines[ln - 1] = " ".join(lines[ln - 1].split()[:-1])
    p = _write(tmp_path, "count.amc", lines, eol="\r\n")
    _raises(lambda q: load_amc(q, asf), p, line=ln, match="'lfemur' has 2 values")


def test_amc_non_numeric(tmp_path: Path, amc_lines: list[str], asf: AsfSkeleton) -> None:
    lines = list(amc_lines)
    ln = _amc_line(lines, 9, "rhumerus")
    toks = lines[ln - 1].split()
    toks[2] = "x12"
    lines[ln - 1] = " ".join(toks)
    p = _write(tmp_path, "nan.amc", lines, eol="\r\n")
    _raises(lambda q: load_amc(q, asf), p, line=ln, match="'x12'")


def test_amc_non_finite(tmp_path: Path, amc_lines: list[str], asf: AsfSkeleton) -> None:
    # Regression: 'nan' parses as a float; it used to reach scipy and fail with LinAlgError.
    for bone in ("lfemur", "root"):
        lines = list(amc_lines)
        ln = _amc_line(lines, 6, bone)
        toks = lines[ln - 1].split()
        toks[1] = "nan"
        lines[ln - 1] = " ".join(toks)
        p = _write(tmp_path, f"nan_{bone}.amc", lines, eol="\r\n")
        _raises(lambda q: load_amc(q, asf), p, line=ln, match="non-finite")


def test_amc_truncated_last_frame(tmp_path: Path, amc_lines: list[str], asf: AsfSkeleton) -> None:
    ln = _amc_line(amc_lines, N_SMALL, "thorax")
    lines = amc_lines[:ln - 1]  # last frame stops before thorax
    p = _write(tmp_path, "trunc.amc", lines, eol="\r\n")
    _raises(lambda q: load_amc(q, asf), p, line=len(lines), match="truncated")
    # Cut in the middle of a bone line: its value count is wrong.
    cut = amc_lines[:ln - 1] + [" ".join(amc_lines[ln - 1].split()[:2])]
    p = _write(tmp_path, "cut.amc", cut, eol="\r\n")
    _raises(lambda q: load_amc(q, asf), p, line=ln, match="'thorax' has 1 values")


def test_amc_empty(tmp_path: Path, asf: AsfSkeleton) -> None:
    _raises(lambda q: load_amc(q, asf), _write(tmp_path, "empty.amc", []), match="empty file")


def test_asf_missing_bonedata(tmp_path: Path, asf_path: Path) -> None:
    lines = asf_path.read_bytes().decode().splitlines()
    lines = [l for l in lines if l.strip() != ":bonedata"]
    _raises(load_asf, _write(tmp_path, "nobones.asf", lines, eol="\r\n"), match=":bonedata")
    _raises(load_asf, _write(tmp_path, "empty.asf", []), match="empty file")


# ---------------------------------------------------------------- semantic parts


@pytest.mark.parametrize("rel", ["cmu/boxing/13_17.bvh", "cmu/asf_amc/13_17.amc", BANDAI])
def test_resolve_parts_finds_required(cache: _Cache, rel: str) -> None:
    sk = cache.motion(rel).skeleton
    parts = resolve_parts(sk)
    missing = [p for p in REQUIRED_PARTS if p not in parts]
    assert not missing, f"{rel}: missing {missing}"
    require_parts(sk, parts, rel)
    assert len({parts["l_fist"], parts["r_fist"], parts["l_toe"], parts["r_toe"]}) == 4


def test_resolve_parts_same_joints_for_bvh_and_asf(cache: _Cache) -> None:
    a = resolve_parts(cache.motion("cmu/boxing/13_17.bvh").skeleton)
    b = resolve_parts(cache.motion("cmu/asf_amc/13_17.amc").skeleton)
    assert a == b  # same joint order, so the same indices


def test_part_override_file(cache: _Cache, tmp_path: Path) -> None:
    sk = cache.motion(BANDAI).skeleton
    # An unknown skeleton: the pelvis joint renamed so that no candidate matches.
    odd = dataclasses.replace(sk, names=tuple("Bassin" if n == "Hips" else n for n in sk.names))
    parts = resolve_parts(odd)
    assert "pelvis" not in parts
    with pytest.raises(MocapFormatError, match="pelvis"):
        require_parts(odd, parts, "odd.bvh")
    f = tmp_path / "map.json"
    f.write_text(json.dumps({"pelvis": "Bassin", "l_fist": "Hand_L"}))
    parts = resolve_parts(odd, load_part_overrides(f))
    require_parts(odd, parts, "odd.bvh")
    assert parts["pelvis"] == odd.index("Bassin") and parts["l_fist"] == odd.index("Hand_L")

    with pytest.raises(KeyError, match="nose"):
        resolve_parts(odd, {"nose": "Head"})
    with pytest.raises(KeyError, match="NoSuchJoint"):
        resolve_parts(odd, {"pelvis": "NoSuchJoint"})
    bad = tmp_path / "bad.json"
    bad.write_text('["pelvis", "Hips"]')
    with pytest.raises(MocapFormatError, match="JSON object"):
        load_part_overrides(bad)
    bad.write_text("{not json")
    with pytest.raises(MocapFormatError, match=str(bad)):
        load_part_overrides(bad)


# ---------------------------------------------------------------- hostile input
# Each of these crashed with another exception type, allocated from a declared count, or loaded
# unusable data before the loaders were hardened.


def _with(lines: list[str], index: int, new: str) -> list[str]:
    out = list(lines)
    out[index] = new
    return out


def _frames_index(lines: list[str]) -> int:
    return lines.index("MOTION") + 1


def _first_channels(lines: list[str]) -> int:
    return next(i for i, line in enumerate(lines) if "CHANNELS" in line)


def _nested(n: int, channels: str = "") -> list[str]:
    """n nested JOINT blocks (and an End Site) as BVH lines."""
    head = [f"JOINT j{k}\n{{\nOFFSET 0 1 0" + (f"\n{channels}" if channels else "") for k in range(n)]
    return head + ["End Site\n{\nOFFSET 0 0 0\n}"] + ["}"] * n


@pytest.mark.parametrize("value, match", [
    ("\u00b2", "whole number"), ("+5", "whole number"), ("\uff12\uff10", "whole number"),
    ("9" * 4301, "MAX_FRAMES"), ("300000000", "MAX_FRAMES"), ("300000", "MAX_FRAME_JOINTS"),
])
def test_bvh_frames_count_ascii_and_capped(tmp_path: Path, bvh_lines: list[str], value: str, match: str) -> None:
    i = _frames_index(bvh_lines)
    e = _raises(load_bvh, _write(tmp_path, "frames.bvh", _with(bvh_lines, i, f"Frames: {value}")), line=i + 1, match=match)
    assert len(e.problem) < 200


def test_bvh_declared_frames_beyond_the_data_allocate_nothing_large(tmp_path: Path, bvh_lines: list[str]) -> None:
    import tracemalloc

    p = _write(tmp_path, "many.bvh", _with(bvh_lines, _frames_index(bvh_lines), "Frames: 100000"))  # 20 lines present
    tracemalloc.start()
    try:
        _raises(load_bvh, p, match="found 20")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 5 * 2**20, f"{peak / 2**20:.1f} MB allocated for 20 frames"  # 100000 x 96 floats = 77 MB


@pytest.mark.parametrize("value, match", [
    ("nan", "positive number"), ("inf", "positive number"), ("-0.01", "positive number"), ("0", "positive number"),
    ("1_0", "positive number"), ("\uff10.1", "positive number"), ("1e-320", "outside"), ("11", "outside"),
])
def test_bvh_frame_time_finite_and_sane(tmp_path: Path, bvh_lines: list[str], value: str, match: str) -> None:
    i = _frames_index(bvh_lines) + 1
    _raises(load_bvh, _write(tmp_path, "ft.bvh", _with(bvh_lines, i, f"Frame Time: {value}")), line=i + 1, match=match)


@pytest.mark.parametrize("value, match", [
    ("nan", "non-finite value 'nan'"), ("-inf", "non-finite"), ("1e400", "overflows"), ("1_0", "non-numeric"),
    ("\uff11", "non-numeric"), ("1e9", "MAX_ABS_LENGTH"),
])
def test_bvh_offsets_finite(tmp_path: Path, bvh_lines: list[str], value: str, match: str) -> None:
    i = next(k for k, line in enumerate(bvh_lines) if "OFFSET" in line and k > 5)
    _raises(load_bvh, _write(tmp_path, "off.bvh", _with(bvh_lines, i, f"OFFSET {value} 0 0")), line=i + 1, match=match)


@pytest.mark.parametrize("value, match", [
    ("1_0", "non-numeric value '1_0'"), ("infinity", "non-finite"), ("\uff11\uff12", "non-numeric"),
    ("\u0663", "non-numeric"), ("0x1A", "non-numeric"), ("1e999", "overflows"), ("1e8", "MAX_ABS_LENGTH"),
])
def test_bvh_frame_values_ascii_and_finite(tmp_path: Path, bvh_lines: list[str], value: str, match: str) -> None:
    i = _frame_line(bvh_lines, 2) - 1
    toks = bvh_lines[i].split()  # the root's Xposition comes first
    _raises(load_bvh, _write(tmp_path, "v.bvh", _with(bvh_lines, i, " ".join([value] + toks[1:]))), line=i + 1, match=match)


@pytest.mark.parametrize("line, match", [
    ("CHANNELS \u00b3 Zrotation Yrotation Xrotation", "needs a count"),
    ("CHANNELS 7 Zrotation Yrotation Xrotation Xrotation Xposition Yposition Zposition", "at most 6"),
    ("CHANNELS 3 Zrotation Zrotation Xrotation", "twice"),
    ("CHANNELS 3 Zrotation Yrotation", "names 2"),
])
def test_bvh_channels_checked(tmp_path: Path, bvh_lines: list[str], line: str, match: str) -> None:
    i = _first_channels(bvh_lines)
    _raises(load_bvh, _write(tmp_path, "ch.bvh", _with(bvh_lines, i, line)), line=i + 1, match=match)


def test_bvh_20000_nested_joints_refused_early(tmp_path: Path, bvh_lines: list[str]) -> None:
    import tracemalloc

    i = _first_channels(bvh_lines) + 1
    p = _write(tmp_path, "deep.bvh", bvh_lines[:i] + _nested(20_000) + bvh_lines[i:])
    tracemalloc.start()
    try:
        _raises(load_bvh, p, match="MAX_JOINTS")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 40 * 2**20, f"{peak / 2**20:.0f} MB"


def test_bvh_deep_chain_loads_and_saves(tmp_path: Path, bvh_lines: list[str]) -> None:
    i = _first_channels(bvh_lines) + 1
    m = load_bvh(_write(tmp_path, "chain.bvh", bvh_lines[:i] + _nested(3000) + bvh_lines[i:]))
    assert m.skeleton.n_joints == 38 + 3001 and m.n_frames == N_SMALL
    assert int(m.skeleton.parents[3001]) == 3000  # the chain's End Site hangs under its deepest joint
    assert np.all(np.isfinite(m.positions()))
    save_bvh(m, tmp_path / "back.bvh")  # the writer walks the tree without recursion too
    back = load_bvh(tmp_path / "back.bvh", metres_per_unit=0.01)
    np.testing.assert_array_equal(back.skeleton.parents, m.skeleton.parents)
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-4)


def test_bvh_bom_and_line_ends_load_the_same(tmp_path: Path, bvh_lines: list[str]) -> None:
    ref = load_bvh(_write(tmp_path, "lf.bvh", bvh_lines))
    text = "\n".join(bvh_lines) + "\n"
    for name, data in (("bom.bvh", b"\xef\xbb\xbf" + text.encode()), ("crlf.bvh", text.replace("\n", "\r\n").encode()),
                       ("cr.bvh", text.replace("\n", "\r").encode())):
        (tmp_path / name).write_bytes(data)
        m = load_bvh(tmp_path / name)
        np.testing.assert_array_equal(m.rotations, ref.rotations)
        np.testing.assert_array_equal(m.root_positions, ref.root_positions)
        assert m.skeleton.names == ref.skeleton.names and m.fps == ref.fps


def test_bvh_messages_quote_at_most_80_characters(tmp_path: Path, bvh_lines: list[str]) -> None:
    e = _raises(load_bvh, _write(tmp_path, "long.bvh", _with(bvh_lines, 3, "x" * 10_000)), line=4)
    assert "'" + "x" * 80 + "'..." in e.problem and len(e.problem) < 140
    name = "J" * 5000
    i = next(k for k, line in enumerate(bvh_lines) if line.strip().startswith("JOINT"))
    _raises(load_bvh, _write(tmp_path, "name.bvh", _with(bvh_lines, i, f"JOINT {name}")), line=i + 1, match="longer than")


@pytest.mark.parametrize("fps", [-30, 0, float("nan"), float("inf"), 1e9])
def test_fps_override_must_be_positive_and_finite(tmp_path: Path, bvh_lines: list[str], fps: float) -> None:
    p = _write(tmp_path, "ok.bvh", bvh_lines)
    for load in (load_motion, load_bvh):
        with pytest.raises(MocapFormatError, match="fps must be") as ei:
            load(p, fps=fps)
        assert isinstance(ei.value, ValueError) and ei.value.path == str(p)
    with pytest.raises(MocapFormatError, match="metres_per_unit"):
        load_motion(p, metres_per_unit=float("nan"))
    with pytest.raises(MocapFormatError, match="metres_per_unit"):
        load_motion(p, metres_per_unit=-1)


def _asf_with(asf_path: Path, edit) -> list[str]:
    return edit(asf_path.read_bytes().decode().splitlines())


def _hierarchy_end(lines: list[str]) -> int:
    return max(i for i, line in enumerate(lines) if line.strip() == "end")


@pytest.mark.parametrize("extra", ["ltibia lfemur", "lfemur lfemur", "root lhipjoint"])
def test_asf_cycle_or_two_parents_refused(tmp_path: Path, asf_path: Path, extra: str) -> None:
    lines = _asf_with(asf_path, lambda ls: ls[:_hierarchy_end(ls)] + [f"    {extra}"] + ls[_hierarchy_end(ls):])
    _raises(load_asf, _write(tmp_path, "cyc.asf", lines, eol="\r\n"), match="reached twice")


def test_asf_2000_bone_chain_loads(tmp_path: Path, asf_path: Path, amc_lines: list[str]) -> None:
    def edit(ls: list[str]) -> list[str]:
        bones = [f"  begin\n     id {100 + k}\n     name b{k}\n     direction 0 1 0\n     length 0.5\n"
                 f"     axis 0 0 0  XYZ\n  end" for k in range(2000)]
        links = ["    lowerback b0"] + [f"    b{k} b{k + 1}" for k in range(1999)]
        h, e = ls.index(":hierarchy"), _hierarchy_end(ls)
        return ls[:h] + bones + ls[h:e] + links + ls[e:]
    _write(tmp_path, "13.asf", _asf_with(asf_path, edit), eol="\r\n")
    m = load_motion(_write(tmp_path, "13_90.amc", amc_lines, eol="\r\n"))
    assert m.skeleton.n_joints == 38 + 2001 and m.n_frames == N_SMALL  # 2000 bones and an end site
    assert np.all(np.isfinite(m.positions()))


@pytest.mark.parametrize("old, new, match", [
    ("axis 0 0 20  XYZ", "axis 0 0 20  XYQ", "axis order"),
    ("axis 0 0 20  XYZ", "axis 0 0 20  XY", "axis order"),
    ("axis XYZ", "axis XXY", "axis order"),
    ("name lfemur", "name", "name needs one value"),
    ("length 7.61162", "length", "length needs one value"),
    ("axis 0 0 20  XYZ", "axis", "axis needs 3 angles"),
    ("axis 0 0 20  XYZ", "axis nan 0 20 XYZ", "non-finite"),
    ("length 0.45", "length nan", "non-finite"),
    ("length 0.45", "length inf", "non-finite"),
    ("length 0.45", "length 1e-320", "no finite metres per unit"),
    ("length 7.61162", "length 1e300", "MAX_ABS_LENGTH"),
    ("direction 0.34202 -0.939693 0", "direction inf 0 0", "non-finite"),
    ("dof rx ry rz", "dof rx rx rz", "twice"),
])
def test_asf_bad_values_refused(tmp_path: Path, asf_path: Path, old: str, new: str, match: str) -> None:
    def edit(ls: list[str]) -> list[str]:
        i = next(k for k, line in enumerate(ls) if line.strip().startswith(old))
        return _with(ls, i, "     " + new)
    _raises(load_asf, _write(tmp_path, "bad.asf", _asf_with(asf_path, edit), eol="\r\n"), match=match)


@pytest.mark.parametrize("number", ["\u00b2", "9" * 5000, "\uff15"])
def test_amc_frame_number_ascii(tmp_path: Path, amc_lines: list[str], asf: AsfSkeleton, number: str) -> None:
    i = amc_lines.index("5")
    _raises(lambda q: load_amc(q, asf), _write(tmp_path, "n.amc", _with(amc_lines, i, number), eol="\r\n"), line=i + 1)


def test_amc_angle_overflow_refused(tmp_path: Path, amc_lines: list[str], asf: AsfSkeleton) -> None:
    lines = [line for line in amc_lines if line != ":DEGREES"]
    lines.insert(1, ":RADIANS")  # 1e307 radians overflows to inf degrees
    ln = _amc_line(lines, 3, "lfemur")
    lines[ln - 1] = "lfemur 1e307 0 0"
    _raises(lambda q: load_amc(q, asf), _write(tmp_path, "big.amc", lines, eol="\r\n"), match="not finite")
    ln = _amc_line(amc_lines, 3, "root")
    _raises(lambda q: load_amc(q, asf), _write(tmp_path, "far.amc", _with(amc_lines, ln - 1, "root 1e300 0 0 0 0 0"),
                                                  eol="\r\n"), line=ln, match="MAX_ABS_LENGTH")


def test_missing_parts_message_is_short(cache: _Cache) -> None:
    sk = cache.motion(BANDAI).skeleton
    odd = dataclasses.replace(sk, names=tuple("Q" * 500 + str(i) for i in range(sk.n_joints)))
    with pytest.raises(MocapFormatError, match="pelvis") as ei:
        require_parts(odd, resolve_parts(odd), "odd.bvh")
    assert len(ei.value.problem) < 800 and f"({sk.n_joints})" in ei.value.problem  # 27 names of 500 characters cut
