"""Hostile graph and library files: every crafted file is a one-line GraphFormatError (or
LibraryFormatError) naming the field, memory stays bounded, and the CLI exits 2 without a
traceback. Crafted files carry a checksum recomputed by the attacker (a sha256 anyone can
recompute), so only the value checks stand between them and the numba kernels. Every case runs
on the .npz versions 1 and 2 and on the compact versions 3 and 4 (igraph_fight.graph_compact;
version 4 replays the edge features)."""
from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import resource
import shutil
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from igraph_fight import graph_compact
from igraph_fight.graph import (
    ALL_ARRAYS, HEADER_OPTIONS, SIM_OPTIONS, GraphFormatError, InteractionGraph, graph_checksum, header_summary,
    library_fingerprint, read_graph_file, write_compact)
from motion_graph.errors import LibraryFormatError
from motion_graph.library import library_from_bytes, load_library

ROOT = Path(__file__).resolve().parent.parent


VERSIONS = [1, 2, 3, 4]


# ---- crafting files as an attacker would ---------------------------------------------------------
def read_raw(path: Path) -> tuple[dict, dict[str, np.ndarray]]:
    """A graph file's header (as an .npz of version 2 holds it) and its arrays (plain copies)."""
    if graph_compact.is_compact(Path(path).read_bytes()[:8]):
        header, arrays = read_graph_file(path)
        header = {k: v for k, v in header.items() if k not in ("members", "checksum")}
        return {**header, "version": 2}, {k: np.array(arrays[k]) for k in arrays}
    with np.load(path, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    return json.loads(bytes(arrays.pop("header")).decode()), arrays


def savez(path: Path, **arrays: np.ndarray) -> None:
    """np.savez to exactly ``path`` (np.savez adds .npz to other names)."""
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def write_graph(path: Path, header: dict, arrays: dict[str, np.ndarray], version: int = 2) -> Path:
    """A graph file with ``header`` and ``arrays`` and a valid checksum of ``version``'s rule
    (versions 3 and 4: igraph_fight.graph.write_compact, which writes what it is given unchecked)."""
    if version in (3, 4):
        write_compact(path, header, arrays, version=version)
        return path
    header = {**header, "version": version}
    header["checksum"] = graph_checksum(header, arrays, version)
    savez(path, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays)
    return path


def library_checksum(arrays: dict[str, np.ndarray]) -> str:
    """A library file's checksum (sha256 over its arrays), recomputed as an attacker would."""
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


def library_bytes(header: dict, arrays: dict[str, np.ndarray]) -> bytes:
    header = {**header, "checksum": library_checksum(arrays)}
    buf = io.BytesIO()
    np.savez_compressed(buf, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays)
    return buf.getvalue()


def write_zip(path: Path, members: list[tuple[str, bytes, int, int, int]]) -> Path:
    """A zip file of raw members (name, data as stored, method, declared size, crc), written by hand
    so that a member can declare any size."""
    out, central = bytearray(), bytearray()
    for name, data, method, size, crc in members:
        n = name.encode()
        central += struct.pack("<4s4B4HL2L5H2L", b"PK\x01\x02", 20, 0, 20, 0, 0, method, 0, 33, crc, len(data),
                               size, len(n), 0, 0, 0, 0, 0, len(out)) + n
        out += struct.pack("<4s2B4HL2L2H", b"PK\x03\x04", 20, 0, 0, method, 0, 33, crc, len(data), size, len(n), 0)
        out += n + data
    end = struct.pack("<4s4H2LH", b"PK\x05\x06", 0, 0, len(members), len(members), len(central), len(out), 0)
    path.write_bytes(bytes(out + central + end))
    return path


def npy_bytes(a: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a, allow_pickle=False)
    return buf.getvalue()


def stored(name: str, data: bytes) -> tuple[str, bytes, int, int, int]:
    return name, data, 0, len(data), zlib.crc32(data)


def zeros_deflated(prefix: bytes, n_zeros: int) -> bytes:
    """A raw deflate stream of ``prefix`` and ``n_zeros`` zero bytes, built from one compressed
    block of up to 64 MiB repeated: milliseconds for gigabytes."""
    def block(data: bytes) -> bytes:
        c = zlib.compressobj(9, zlib.DEFLATED, -15)
        return c.compress(data) + c.flush(zlib.Z_FULL_FLUSH)

    n = min(n_zeros, 64 << 20)
    rest = n_zeros - n * (n_zeros // n)
    return (block(prefix) + block(bytes(n)) * (n_zeros // n) + (block(bytes(rest)) if rest else b"")
            + zlib.compressobj(9, zlib.DEFLATED, -15).flush())


def read_index(path: Path) -> tuple[dict, int, bytes]:
    """A compact file's index, where its blobs start and the whole file's bytes."""
    data = path.read_bytes()
    (n,) = struct.unpack("<Q", data[8:16])
    return json.loads(data[16:16 + n]), 16 + n, data


def reseal(path: Path, edit) -> Path:
    """Edit a compact file's index (``edit(index)`` in place), recompute its checksum as an
    attacker would and write it back in the index's place (compact JSON: it fits)."""
    index, start, data = read_index(path)
    edit(index)
    index["checksum"] = graph_checksum(index, {}, 3)
    text = json.dumps(index, separators=(",", ":")).encode()
    assert 16 + len(text) <= start, "the edited index does not fit"
    path.write_bytes(data[:16] + text + b" " * (start - 16 - len(text)) + data[start:])
    return path


def one_line(err: BaseException) -> str:
    msg = str(err)
    assert "\n" not in msg and len(msg) < 400, msg
    return msg


@pytest.fixture(scope="module")
def raw(tiny_graph_file) -> tuple[dict, dict[str, np.ndarray]]:
    return read_raw(tiny_graph_file)


@pytest.fixture(scope="module")
def lib(tiny_graph_file):
    return InteractionGraph.load(tiny_graph_file).load_library()


def crafted(tmp_path: Path, raw, version: int, arrays: dict | None = None, header: dict | None = None,
            name: str = "bad.igz") -> Path:
    h, a = raw
    return write_graph(tmp_path / name, {**h, **(header or {})}, {**a, **(arrays or {})}, version)


def changed(a: np.ndarray, i: int, value) -> np.ndarray:
    a = a.copy()
    a[i] = value
    return a


# ---- arrays out of range -------------------------------------------------------------------------
def _array_cases(h: dict, a: dict, lib) -> dict[str, tuple[str, np.ndarray]]:
    """case -> (array, its crafted value); every one loads with the code before value checks."""
    S, A = len(a["state_r"]), lib.n_actions
    s = S // 2
    e = int(a["state_offsets"][s])  # an edge of state s
    m_other = int(a["state_m_other"][s])
    frames = int(lib.frame_offsets[m_other + 1] - lib.frame_offsets[m_other])
    menu = set(int(x) for x in lib.next(int(a["state_m_self"][s])))
    off_menu = next(b for b in range(A) if b not in menu)
    other_nextset = int((a["state_nextset"][s] + 1) % (a["state_nextset"].max() + 1))
    return {
        "edge_action_huge": ("edge_action", changed(a["edge_action"], e, 2**31 - 1)),
        "edge_action_negative": ("edge_action", changed(a["edge_action"], e, -3)),
        "edge_action_off_menu": ("edge_action", changed(a["edge_action"], e, off_menu)),
        "state_m_self": ("state_m_self", changed(a["state_m_self"], s, A)),
        "state_m_other": ("state_m_other", changed(a["state_m_other"], s, -1)),
        "state_f_other_negative": ("state_f_other", changed(a["state_f_other"], s, -1)),
        "state_f_other_past_the_action": ("state_f_other", changed(a["state_f_other"], s, frames)),
        "state_nextset": ("state_nextset", changed(a["state_nextset"], s, other_nextset)),
        "state_mask_negative": ("state_mask_other", changed(a["state_mask_other"], s, -1)),
        "state_mask_huge": ("state_mask_other", changed(a["state_mask_other"], s, 1 << 40)),
        "state_size": ("state_size", changed(a["state_size"], s, 0)),
        "edge_swap": ("edge_swap", changed(a["edge_swap"], e, 7)),
        "feat_kind": ("feat_kind", changed(a["feat_kind"], e, 99)),
        "feat_other_kind": ("feat_other_kind", changed(a["feat_other_kind"], e, -1)),
        "feat_kind_of_another_action": ("feat_kind", changed(a["feat_kind"], e, (a["feat_kind"][e] + 1) % 14)),
        "feat_r_nan": ("feat_r", changed(a["feat_r"], e, np.nan)),
        "feat_dmg_inf": ("feat_dmg_given", changed(a["feat_dmg_given"], e, np.inf)),
        "state_r_negative": ("state_r", changed(a["state_r"], s, -1.0)),
        "state_theta_nan": ("state_theta_self", changed(a["state_theta_self"], s, np.nan)),
        "state_theta_huge": ("state_theta_other", changed(a["state_theta_other"], s, 1e300)),
        "edge_snap_negative": ("edge_snap_r", changed(a["edge_snap_r"], e, -0.5)),
    }


ARRAY_CASES = ("edge_action_huge", "edge_action_negative", "edge_action_off_menu", "state_m_self", "state_m_other",
               "state_f_other_negative", "state_f_other_past_the_action", "state_nextset", "state_mask_negative",
               "state_mask_huge", "state_size", "edge_swap", "feat_kind", "feat_other_kind",
               "feat_kind_of_another_action", "feat_r_nan", "feat_dmg_inf", "state_r_negative", "state_theta_nan",
               "state_theta_huge", "edge_snap_negative")


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("case", ARRAY_CASES)
def test_out_of_range_arrays_are_refused_naming_the_array(raw, lib, tmp_path, case, version):
    h, a = raw
    field, value = _array_cases(h, a, lib)[case]
    path = crafted(tmp_path, raw, version, arrays={field: value})
    with pytest.raises(GraphFormatError, match=rf"bad\.igz: {field}: ") as err:
        InteractionGraph.load(path)
    one_line(err.value)


def test_the_untouched_file_loads_in_every_version(raw, tmp_path, tiny_graph_file):
    want = InteractionGraph.load(tiny_graph_file).content_hash
    for version in VERSIONS:
        g = InteractionGraph.load(crafted(tmp_path, raw, version, name=f"v{version}.igz"))
        assert g.content_hash == want and g.header["version"] == version


# ---- the header ----------------------------------------------------------------------------------
def _options(h: dict, **kw) -> dict:
    return {"options": {**h["options"], **kw}}


HEADER_CASES = {
    "f0_zero": (lambda h: _options(h, f0=0), "options.f0"),
    "f0_string": (lambda h: _options(h, f0="10"), "options.f0"),
    "f0_huge": (lambda h: _options(h, f0=10**400), "options.f0"),
    "interaction_weight_huge": (lambda h: _options(h, interaction_weight=-(10**400)), "options.interaction_weight"),
    "s_r_m_zero": (lambda h: _options(h, s_r_m=0), "options.s_r_m"),
    "s_theta_negative": (lambda h: _options(h, s_theta_rad=-1.0), "options.s_theta_rad"),
    "link_tolerance_zero": (lambda h: _options(h, link_tol_r_m=0.0), "options.link_tol_r_m"),
    "unknown_option": (lambda h: _options(h, warp_speed=9), "options: unknown key 'warp_speed'"),
    "unknown_sim_option": (lambda h: _options(h, sim={**h["options"]["sim"], "gravity": 1}),
                           "options.sim: unknown key 'gravity'"),
    "sim_guard_negative": (lambda h: _options(h, sim={**h["options"]["sim"], "guard_radius_m": -0.1}),
                           "options.sim.guard_radius_m"),
    "sim_event_frames": (lambda h: _options(h, sim={**h["options"]["sim"], "max_event_frames": 0}),
                         "options.sim.max_event_frames"),
    "options_not_an_object": (lambda h: {"options": [1, 2]}, "options: not an object"),
    "library_n_actions": (lambda h: {"library": {**h["library"], "n_actions": 10**6}}, "library.n_actions"),
    "kinds_table": (lambda h: {"kinds_table": ["jab"] * 14}, "kinds_table"),
    "report_number": (lambda h: {"report": {**h["report"], "snap_mean_cm": "lots"}}, "report.snap_mean_cm"),
}


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("case", sorted(HEADER_CASES))
def test_bad_header_fields_are_refused_naming_the_field(raw, tmp_path, case, version):
    make, field = HEADER_CASES[case]
    path = crafted(tmp_path, raw, version, header=make(raw[0]))
    with pytest.raises(GraphFormatError, match=rf"bad\.igz: {field}") as err:
        InteractionGraph.load(path)
    one_line(err.value)


def test_a_long_quoted_value_is_cut(raw, tmp_path):
    path = crafted(tmp_path, raw, 2, header=_options(raw[0], **{"x" * 500: 1}))
    with pytest.raises(GraphFormatError, match="unknown key 'xxx") as err:
        InteractionGraph.load(path)
    assert len(one_line(err.value)) < len(str(path)) + 120


def test_the_checksum_covers_the_header_in_version_2(raw, tmp_path):
    h, a = raw
    path = crafted(tmp_path, raw, 2)
    header, arrays = read_raw(path)
    header["seed"] = 12345  # tampered after the checksum was computed
    savez(path, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays)
    with pytest.raises(GraphFormatError, match="checksum: mismatch"):
        InteractionGraph.load(path)
    # version 1's checksum covers the arrays only: the same edit loads (its values are in range)
    path1 = crafted(tmp_path, raw, 1, name="v1.igz")
    header, arrays = read_raw(path1)
    header["seed"] = 12345
    savez(path1, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays)
    assert InteractionGraph.load(path1).header["seed"] == 12345


def test_the_checksum_and_crcs_cover_a_compact_file(raw, tmp_path):
    path = crafted(tmp_path, raw, 3)
    index, start, data = read_index(path)
    index["seed"] = 12345  # tampered after the checksum was computed
    text = json.dumps(index, separators=(",", ":")).encode()
    path.write_bytes(data[:16] + text + b" " * (start - 16 - len(text)) + data[start:])
    with pytest.raises(GraphFormatError, match="checksum: mismatch"):
        InteractionGraph.load(path)
    path = crafted(tmp_path, raw, 3, name="flip.igz")
    index, start, data = read_index(path)
    for k in ("feat_r", "edge_action"):  # a memory-mapped blob and a deflated one
        b = index["members"][k]["data"]
        flipped = bytearray(data)
        flipped[b["offset"] + b["nbytes"] // 2] ^= 0x10
        path.write_bytes(bytes(flipped))
        with pytest.raises(GraphFormatError, match=rf"flip\.igz: {k}\.data: truncated or corrupted \(CRC-32") as err:
            InteractionGraph.load(path)
        one_line(err.value)


def test_an_npz_claiming_version_3_is_refused(raw, tmp_path):
    h, a = raw
    header = {**h, "version": 3}
    header["checksum"] = graph_checksum(header, a, 2)
    savez(tmp_path / "v3.igz", header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **a)
    with pytest.raises(GraphFormatError, match="version: an .npz graph file of version 3"):
        InteractionGraph.load(tmp_path / "v3.igz")


def _spec_cases(index: dict) -> dict:
    """case -> (edit of a compact file's index, what the error names)."""
    m = index["members"]

    def put(k, **kw):
        return lambda ix: ix["members"][k].update(kw)

    def put_blob(k, part="data", **kw):
        return lambda ix: ix["members"][k][part].update(kw)

    return {
        "unknown_encoding": (put("feat_r", encoding="guess"), "feat_r: encoding 'guess' is not one of"),
        "float32_feature": (put("feat_r", dtype="<f4"), r"feat_r: dtype '<f4' \(expected 1-d float64\)"),
        "big_endian_blob": (put_blob("feat_r", dtype=">f8"), "feat_r.data: dtype '>f8' is not a plain little-endian"),
        "two_dims": (put("edge_target", shape=[2, 3]), r"edge_target: shape \[2, 3\]"),
        "more_edges": (put("feat_r", shape=[m["feat_r"]["shape"][0] + 1]), "feat_r: raw data of"),
        "misaligned": (put_blob("feat_r", offset=m["feat_r"]["data"]["offset"] + 8), "feat_r.data: offset .* multiple of 64"),
        "past_the_end": (put_blob("feat_r_mean", offset=m["feat_r_mean"]["data"]["offset"] + (1 << 30)),
                         "truncated or corrupted \\(feat_r_mean.data ends at byte"),
        "inside_the_index": (put_blob("feat_r", offset=0), "feat_r.data: offset 0 lies inside the index"),
        "compression": (put_blob("edge_action", compression="lzma"), "edge_action.data: compression 'lzma'"),
        "derived_formula": (put("edge_snap_r", formula="edge_snap_theta"), "edge_snap_r: formula 'edge_snap_theta'"),
        "derived_feature": (lambda ix: ix["members"].update(feat_kind={"encoding": "derived", "formula": "feat_kind",
                                                                       "dtype": "<i4", "shape": m["feat_kind"]["shape"]}),
                            "feat_kind: formula 'feat_kind' is not known"),
        "table_of_ints": (put("edge_action", encoding="table", values=[0.0]), "edge_action: table values"),
        "offsets_elsewhere": (put("edge_action", encoding="offsets"), "edge_action: offset differences"),
        "unknown_member": (lambda ix: ix["members"].update(surprise=m["feat_r"]), "arrays: unexpected 'surprise'"),
        "missing_member": (lambda ix: ix["members"].pop("feat_r"), "arrays: missing feat_r"),
        "members_not_an_object": (lambda ix: ix.update(members=[1]), "members: not an object"),
        "version": (lambda ix: ix.update(version=2), "version: graph version 2 is not supported in a compact file"),
    }


SPEC_CASES = ("unknown_encoding", "float32_feature", "big_endian_blob", "two_dims", "more_edges", "misaligned",
              "past_the_end", "inside_the_index", "compression", "derived_formula", "derived_feature", "table_of_ints",
              "offsets_elsewhere", "unknown_member", "missing_member", "members_not_an_object", "version")


@pytest.mark.parametrize("case", SPEC_CASES)
def test_bad_member_specs_of_a_compact_file_are_refused(raw, tmp_path, case):
    path = crafted(tmp_path, raw, 3)
    edit, match = _spec_cases(read_index(path)[0])[case]
    reseal(path, edit)
    with pytest.raises(GraphFormatError, match=rf"bad\.igz: {match}") as err:
        InteractionGraph.load(path)
    one_line(err.value)


def test_table_codes_and_derived_exceptions_are_checked(raw, tmp_path):
    h, a = raw
    # a code past its table: the table of feat_dmg_given cut to one value, checksum recomputed
    path = crafted(tmp_path, raw, 3)
    index = read_index(path)[0]
    assert index["members"]["feat_dmg_given"]["encoding"] == "table"
    assert index["members"]["edge_snap_r"]["encoding"] == "derived"
    assert index["members"]["feat_r"]["encoding"] == "raw"
    if len(index["members"]["feat_dmg_given"]["values"]) > 1:
        reseal(path, lambda ix: ix["members"]["feat_dmg_given"].update(values=[0.0]))
        with pytest.raises(GraphFormatError, match=r"feat_dmg_given: code 1 at \[\d+\] is outside its table"):
            InteractionGraph.load(path)
    # a damage beyond the range in the table itself
    path = crafted(tmp_path, raw, 3, arrays={"feat_dmg_given": np.where(a["feat_dmg_given"] > 0, 1e13, 0.0)},
                   name="t.igz")
    assert read_index(path)[0]["members"]["feat_dmg_given"]["encoding"] == "table"
    with pytest.raises(GraphFormatError, match=r"feat_dmg_given: 10000000000000.0 in its table of values is outside"):
        InteractionGraph.load(path)


def test_version_4_replays_the_edge_features_exactly(raw, tmp_path):
    from igraph_fight.graph import REPLAYED, replay_formula
    v3, v4 = crafted(tmp_path, raw, 3, name="v3.igz"), crafted(tmp_path, raw, 4, name="v4.igz")
    members = read_index(v4)[0]["members"]
    for k in REPLAYED:  # no exception stored: the replay gives every bit
        assert members[k]["encoding"] == "derived" and members[k]["formula"] == replay_formula(k), k
        assert "mask" not in members[k] and "data" not in members[k] and "crc32" in members[k], k
    assert v4.stat().st_size < v3.stat().st_size
    g3, g4 = InteractionGraph.load(v3), InteractionGraph.load(v4)
    for k in ALL_ARRAYS:
        x, y = g3.arrays[k], g4.arrays[k]
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), k
    assert g4.content_hash == g3.content_hash == g4.header["content_hash"]


@pytest.mark.parametrize("version", [3, 4])
def test_a_file_written_in_many_pieces_is_the_same_file(raw, tmp_path, version, monkeypatch):
    """Pieces and replay shards far smaller than the arrays (every blob, formula and replay spans
    many of them) give the file the default pieces give, byte for byte, and it loads the same."""
    from igraph_fight.graph import replayed_shards
    h, a = raw
    E = len(a["edge_target"])
    assert E > 40 and len(a["state_r"]) > 10
    whole, pieces = tmp_path / "whole.igz", tmp_path / "pieces.igz"
    write_compact(whole, h, a, version=version)
    sizes = []
    chunks = graph_compact.chunks

    def spy(n, size=graph_compact.CHUNK):
        sizes.append(size)
        return chunks(n, size)
    monkeypatch.setattr(graph_compact, "chunks", spy)
    write_compact(pieces, h, a, version=version, chunk=7, shard_edges=E // 9)
    monkeypatch.undo()
    assert sizes.count(7) > 10  # the blobs and formulas went 7 values at a time
    assert len(list(replayed_shards(a, h, shard_edges=E // 9))) >= 5
    assert pieces.read_bytes() == whole.read_bytes()
    g = InteractionGraph.load(pieces)
    for k in ALL_ARRAYS:
        assert g.arrays[k].tobytes() == np.asarray(a[k]).astype(ALL_ARRAYS[k]).tobytes(), k
    if version == 4:  # the replay covered every edge shard by shard: nothing stored as an exception
        members = read_index(pieces)[0]["members"]
        assert all("mask" not in members[k] for k in members if k.startswith("feat_r")), members["feat_r_mean"]
    with pytest.raises(ValueError, match="chunk must be at least 1"):
        write_compact(tmp_path / "no.igz", h, a, version=version, chunk=0)


def test_replayed_members_are_checked(raw, tmp_path):
    crc = read_index(crafted(tmp_path, raw, 4))[0]["members"]["feat_r_mean"]["crc32"]
    cases = {
        "crc": (lambda ix: ix["members"]["feat_r_mean"].update(crc32=crc ^ 1), None),
        "crc_type": (lambda ix: ix["members"]["feat_r_mean"].update(crc32="x"), "feat_r_mean: crc32 'x' is not"),
        "crc_on_raw": (lambda ix: ix["members"]["state_r"].update(crc32=1), "state_r: unexpected key 'crc32'"),
        "other_array": (lambda ix: ix["members"]["feat_r"].update(formula="replay/feat_r_mean"),
                        "feat_r: formula 'replay/feat_r_mean' is not known"),
        "no_library": (lambda ix: ix["members"].pop("library_npz"),
                       "feat_r: replayed, and the file holds no library to replay it with"),
    }
    for case, (edit, match) in cases.items():
        path = reseal(crafted(tmp_path, raw, 4, name=f"{case}.igz"), edit)
        if match is not None:
            with pytest.raises(GraphFormatError, match=rf"{case}\.igz: {match}") as err:
                InteractionGraph.load(path)
            one_line(err.value)
            continue
        g = InteractionGraph.load(path)  # decoded on first access: refused then, naming the file
        with pytest.raises(GraphFormatError, match=rf"{case}\.igz: feat_r_mean: replay/feat_r_mean gives other "
                                                    r"values .* \(CRC-32 mismatch\)") as err:
            g.arrays["feat_r_mean"]
        one_line(err.value)


def test_the_replay_checks_what_it_indexes(raw, lib):
    from igraph_fight.graph import replayed_arrays
    h, a = raw
    assert isinstance(replayed_arrays(a, h), dict)
    bad = {"edge_action": np.full_like(a["edge_action"], lib.n_actions),
           "state_m_other": np.full_like(a["state_m_other"], -1),
           "state_f_other": np.full_like(a["state_f_other"], 1 << 30),
           "state_offsets": a["state_offsets"][::-1].copy()}
    for k, v in bad.items():
        why = replayed_arrays({**a, k: v}, h)
        assert isinstance(why, str) and why.startswith(f"cannot replay the edges ({k}: "), (k, why)
    assert "lacks" in replayed_arrays({k: v for k, v in a.items() if k != "library_npz"}, h)


def test_compact_header_json_is_strict_and_capped(raw, tmp_path):
    for text, match in ((b'{"format": NaN}', "header: not valid JSON"), (b'{"seed": 1e400}', "not a finite number"),
                        (b"[1, 2]", "header: not a JSON object"), (b'{"a": 1, "a": 2}', "duplicate key 'a'"),
                        (b"[" * 100_000, "header: not valid JSON"),
                        (b" " * (5 << 20), r"header: 5242880 bytes of JSON \(at most")):
        (tmp_path / "h.igz").write_bytes(graph_compact.MAGIC + struct.pack("<Q", len(text)) + text)
        with pytest.raises(GraphFormatError, match=match) as err:
            InteractionGraph.load(tmp_path / "h.igz")
        one_line(err.value)
    (tmp_path / "h.igz").write_bytes(graph_compact.MAGIC + struct.pack("<Q", 1 << 40))
    with pytest.raises(GraphFormatError, match=r"h\.igz: header: \d+ bytes of JSON"):
        InteractionGraph.load(tmp_path / "h.igz")
    (tmp_path / "h.igz").write_bytes(graph_compact.MAGIC + struct.pack("<Q", 100) + b"{}")
    with pytest.raises(GraphFormatError, match=r"h\.igz: truncated or corrupted"):
        InteractionGraph.load(tmp_path / "h.igz")


def test_a_compact_bomb_is_refused_before_it_inflates(raw, tmp_path):
    path = crafted(tmp_path, raw, 3)
    size = path.stat().st_size
    n = 3 << 30
    # (1) edge_action's deflated blob declares 3 Gi values: refused before anything is inflated
    bomb = reseal(Path(shutil.copy(path, tmp_path / "bomb.igz")), lambda ix: (
        ix["members"]["edge_action"].update(shape=[n]), ix["members"]["edge_action"]["data"].update(count=n)))
    # (2) the stream holds more than its blob declares: inflated no further than the declared size
    index, start, data = read_index(path)
    b = index["members"]["edge_action"]["data"]
    more = zlib.compress(bytes(b["count"] + (8 << 20)), 9)
    grown = data[:b["offset"]] + more + data[b["offset"] + b["nbytes"]:] if len(more) <= b["nbytes"] else None
    before = _peak_rss_mb()
    with pytest.raises(GraphFormatError, match=r"bomb\.igz: members declare \d+ bytes once decoded, more than") as err:
        InteractionGraph.load(bomb)
    one_line(err.value)
    if grown is not None:
        (tmp_path / "bomb2.igz").write_bytes(grown)
        reseal(tmp_path / "bomb2.igz", lambda ix: ix["members"]["edge_action"]["data"].update(
            nbytes=len(more), crc32=zlib.crc32(more)))
        with pytest.raises(GraphFormatError, match=r"edge_action\.data: truncated or corrupted \(the stream"):
            InteractionGraph.load(tmp_path / "bomb2.igz")
    assert _peak_rss_mb() - before < 100
    assert size < 16 << 20


def test_build_writes_the_compact_format_and_convert_goes_both_ways(raw, tmp_path, tiny_graph_file, capsys):
    from igraph_fight.cli import main

    g = InteractionGraph.load(tiny_graph_file)
    assert g.header["version"] == 4 and header_summary(tiny_graph_file)["version"] == 4
    want = g.content_hash
    old = crafted(tmp_path, raw, 2, name="old.igz")
    assert main(["graph", "convert", str(old), str(tmp_path / "new.igz"), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["src_version"] == 2 and rep["dst_version"] == 4 and rep["content_hash"] == want
    new = InteractionGraph.load(tmp_path / "new.igz")
    assert new.content_hash == want and new.header["content_hash"] == want
    back = tmp_path / "back.igz"
    assert main(["graph", "convert", str(tmp_path / "new.igz"), str(back), "--version", "2"]) == 0
    capsys.readouterr()
    assert InteractionGraph.load(back).header["version"] == 2 and InteractionGraph.load(back).content_hash == want
    for k in ALL_ARRAYS:  # bit for bit, dtypes included
        x, y = InteractionGraph.load(old).arrays[k], new.arrays[k]
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes(), k
    assert main(["graph", "info", str(tmp_path / "new.igz")]) == 0
    out = capsys.readouterr().out
    assert "file: compact (version 4" in out and f"content hash {want}" in out
    v3 = tmp_path / "v3.igz"
    assert main(["graph", "convert", str(tmp_path / "new.igz"), str(v3), "--version", "3"]) == 0
    capsys.readouterr()
    assert InteractionGraph.load(v3).header["version"] == 3 and InteractionGraph.load(v3).content_hash == want
    assert main(["graph", "info", str(old)]) == 0
    assert "file: npz (version 2, the old format" in capsys.readouterr().out


def test_header_json_is_strict_and_capped(raw, tmp_path):
    h, a = raw
    for text, match in ((b'{"format": NaN}', "header: not valid JSON"), (b'{"seed": 1e400}', "not a finite number"),
                        (b"[1, 2]", "header: not a JSON object"),
                        (b'{"a": 1, "a": 2}', "duplicate key 'a'"), (b"[" * 100_000, "header: not valid JSON"),
                        (b" " * (5 << 20), r"header: 5242880 bytes of JSON \(at most")):
        savez(tmp_path / "h.igz", header=np.frombuffer(text, dtype=np.uint8), **a)
        with pytest.raises(GraphFormatError, match=match) as err:
            InteractionGraph.load(tmp_path / "h.igz")
        one_line(err.value)


def test_option_tables_follow_build_options_and_sim_params():
    from igraph_fight.build.pipeline import BuildOptions
    from igraph_fight.build.seeding import SEED_PAIRINGS
    from igraph_fight.sim import SimParams

    assert set(HEADER_OPTIONS) == {f.name for f in dataclasses.fields(BuildOptions)}
    assert set(SIM_OPTIONS) == {f.name for f in dataclasses.fields(SimParams)}
    assert HEADER_OPTIONS["seed_pairing"] == ("choice", SEED_PAIRINGS)
    from igraph_fight.graph import check_options
    check_options(BuildOptions().to_json())
    check_options(dataclasses.replace(BuildOptions(), sim=SimParams(guard_radius_m=0.05)).to_json())


# ---- the embedded library ------------------------------------------------------------------------
def test_a_crafted_embedded_library_is_refused(raw, lib, tmp_path):
    h, a = raw
    lh, la = read_raw_library(a["library_npz"].tobytes())
    la["next_ids"] = changed(la["next_ids"], 3, -2)
    data = library_bytes(lh, la)
    with pytest.raises(LibraryFormatError, match="next_ids: -2 at"):
        library_from_bytes(data)
    # fingerprint and checksum recomputed: the graph names its embedded library
    bad = np.frombuffer(data, dtype=np.uint8)
    fake = dataclasses.replace(lib, next_ids=la["next_ids"])
    path = crafted(tmp_path, raw, 2, arrays={"library_npz": bad},
                   header={"library": {**h["library"], "fingerprint": library_fingerprint(fake)},
                           "shapes": {**h["shapes"], "library_npz": [len(bad)]}})
    with pytest.raises(GraphFormatError, match=r"bad\.igz: library_npz: next_ids: -2 at"):
        InteractionGraph.load(path)


def read_raw_library(data: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    with np.load(io.BytesIO(data), allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    return json.loads(bytes(arrays.pop("header")).decode()), arrays


# ---- bombs, foreign and broken files --------------------------------------------------------------
def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def test_a_decompression_bomb_is_refused_before_it_inflates(raw, tmp_path):
    h, a = raw
    E = len(a["edge_target"])
    n_zero = 3 << 30  # 3 GiB of zeros, about 3 MB deflated
    members = [stored(f"{k}.npy", npy_bytes(v)) for k, v in a.items() if k != "feat_r"]
    members.append(stored("header.npy", npy_bytes(np.frombuffer(json.dumps(h).encode(), dtype=np.uint8))))
    # (1) feat_r's .npy header declares 3 GiB of floats, the zip entry as much
    big = np.lib.format.header_data_from_array_1_0(np.zeros(1))
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {**big, "shape": (n_zero // 8,)})
    pre = buf.getvalue()
    bomb = zeros_deflated(pre, n_zero)
    path = write_zip(tmp_path / "bomb.igz", members + [("feat_r.npy", bomb, 8, len(pre) + n_zero, 0)])
    assert path.stat().st_size < 16 << 20
    # (2) feat_r's .npy header declares its E floats, the zip entry (within the file's budget) 512 KiB more
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {**big, "shape": (E,)})
    pre2 = buf.getvalue()
    more = 8 * E + (512 << 10)
    path2 = write_zip(tmp_path / "bomb2.igz", members + [("feat_r.npy", zeros_deflated(pre2, more), 8,
                                                            len(pre2) + more, 0)])
    before = _peak_rss_mb()
    with pytest.raises(GraphFormatError, match=r"bomb\.igz: members declare \d+ bytes, more than") as err:
        InteractionGraph.load(path)
    one_line(err.value)
    with pytest.raises(GraphFormatError, match=r"bomb2\.igz: feat_r: its zip entry declares \d+ bytes, its .npy"):
        InteractionGraph.load(path2)
    assert _peak_rss_mb() - before < 100


def test_a_bomb_in_a_library_is_refused(lib, tmp_path):
    lh, la = read_raw_library(lib.to_bytes())
    n_zero = 1 << 30
    members = [(f"{k}.npy", zlib.compress(npy_bytes(v))[2:-4], 8, len(npy_bytes(v)), zlib.crc32(npy_bytes(v)))
               for k, v in la.items()]
    members.append(stored("header.npy", npy_bytes(np.frombuffer(json.dumps(lh).encode(), dtype=np.uint8))))
    J = la["rotations"].shape[1]
    rows = n_zero // (J * 32)
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {**np.lib.format.header_data_from_array_1_0(np.zeros((1, J, 4))),
                                              "shape": (rows, J, 4)})
    members = [m for m in members if m[0] != "rotations.npy"]
    members.append(("rotations.npy", zeros_deflated(buf.getvalue(), n_zero), 8, len(buf.getvalue()) + rows * J * 32, 0))
    path = write_zip(tmp_path / "lib.npz", members)
    before = _peak_rss_mb()
    with pytest.raises(LibraryFormatError, match=r"lib\.npz: members declare \d+ bytes, more than"):
        load_library(path)
    assert _peak_rss_mb() - before < 100


def test_foreign_and_broken_files_are_named_so(raw, lib, tmp_path, tiny_graph_file):
    png = tmp_path / "picture.igz"
    shutil.copy(ROOT / "docs" / "media" / "bout.png", png)
    (tmp_path / "notes.igz").write_text("states: many\nedges: more\n")
    lib.save(tmp_path / "lib.npz")
    savez(tmp_path / "plain.igz", a=np.zeros(3))
    for name in ("picture.igz", "notes.igz", "lib.npz", "plain.igz"):
        with pytest.raises(GraphFormatError, match=rf"{name}: not an igraph-fight graph file") as err:
            InteractionGraph.load(tmp_path / name)
        one_line(err.value)
    with pytest.raises(GraphFormatError, match="not an igraph-fight graph file"):
        header_summary(png)
    data = Path(tiny_graph_file).read_bytes()
    (tmp_path / "cut.igz").write_bytes(data[: len(data) // 3])
    with pytest.raises(GraphFormatError, match="cut.igz: truncated or corrupted"):
        InteractionGraph.load(tmp_path / "cut.igz")
    h, a = raw
    savez(tmp_path / "obj.igz", header=np.frombuffer(json.dumps(h).encode(), dtype=np.uint8),
             **{**a, "feat_r": np.array([{"x": 1}] * len(a["feat_r"]), dtype=object)})
    with pytest.raises(GraphFormatError, match=r"feat_r: dtype '\|O' is not a plain"):
        InteractionGraph.load(tmp_path / "obj.igz")
    savez(tmp_path / "extra.igz", header=np.frombuffer(json.dumps(h).encode(), dtype=np.uint8),
             surprise=np.zeros(2), **a)
    with pytest.raises(GraphFormatError, match="arrays: unexpected 'surprise'"):
        InteractionGraph.load(tmp_path / "extra.igz")


def test_crafted_library_files_are_refused_naming_the_field(lib, tmp_path):
    lh, la = read_raw_library(lib.to_bytes())
    F = len(la["rotations"])
    offsets = la["frame_offsets"].copy()
    offsets[5], offsets[6] = offsets[6], offsets[5]
    cases = [  # (array, its crafted value)
        ("next_ids", changed(la["next_ids"], 0, -1)), ("frame_offsets", offsets),
        ("rotations", changed(la["rotations"], 7, np.nan)), ("rotations", changed(la["rotations"], 9, 0.0)),
        ("strike_joint", changed(la["strike_joint"], 0, 99)), ("strike_w1", changed(la["strike_w1"], 0, 10_000)),
        ("strike_peak", changed(la["strike_peak"], 0, -1)), ("kinds", changed(la["kinds"], 0, 50)),
        ("skel_parents", changed(la["skel_parents"], 3, 30)), ("next_offsets", changed(la["next_offsets"], 2, 10**9)),
        ("path", changed(la["path"], F - 1, np.inf)),
    ]
    for field, value in cases:
        with pytest.raises(LibraryFormatError, match=rf"lib\.npz: {field}: ") as err:
            (tmp_path / "lib.npz").write_bytes(library_bytes(lh, {**la, field: value}))
            load_library(tmp_path / "lib.npz")
        one_line(err.value)
    for field, value in (("fps", 0), ("labels", ["teleport", *lh["labels"][1:]]), ("parts", {"head": 999}),
                         ("sources", None)):
        with pytest.raises(LibraryFormatError, match=rf"lib\.npz: {field}: ") as err:
            (tmp_path / "lib.npz").write_bytes(library_bytes({**lh, field: value}, la))
            load_library(tmp_path / "lib.npz")
        one_line(err.value)


# ---- in memory ----------------------------------------------------------------------------------
def test_validate_checks_graphs_built_in_memory(raw, lib, tmp_path):
    h, a = raw
    g = InteractionGraph(dict(a), {k: v for k, v in h.items() if k in ("library", "options", "kinds_table")})
    g.validate()
    g.validate(lib)
    bad = InteractionGraph({**a, "edge_action": changed(a["edge_action"], 0, lib.n_actions)},
                           {"options": h["options"]})
    bad.validate()  # without the library's size nothing says action 68 does not exist
    with pytest.raises(GraphFormatError, match="<graph>: edge_action: "):
        bad.validate(lib)
    with pytest.raises(GraphFormatError, match="edge_action: "):  # what the controller calls first
        InteractionGraph(bad.arrays, dict(g.header)).check_library(lib)
    with pytest.raises(GraphFormatError, match="state_r: nan"):
        InteractionGraph({**a, "state_r": changed(a["state_r"], 0, np.nan)}, {}).save(tmp_path / "x.igz")
    assert not (tmp_path / "x.igz").exists()
    with pytest.raises(GraphFormatError, match="options.f0"):
        InteractionGraph(dict(a), {"options": {"f0": 0}}).validate()


# ---- the CLI -------------------------------------------------------------------------------------
def test_cli_exits_2_with_one_line_and_no_traceback(raw, tmp_path, capsys):
    from igraph_fight.cli import main

    h, a = raw
    every_7th = np.arange(0, len(a["edge_action"]), 7)
    files = [crafted(tmp_path, raw, 1, arrays={"edge_action": changed(a["edge_action"], every_7th, 2**31 - 1)},
                     name="action.igz"),
             crafted(tmp_path, raw, 1, header=_options(h, f0=0), name="f0.igz"),
             crafted(tmp_path, raw, 1, header=_options(h, s_r_m=0), name="s_r_m.igz"),
             crafted(tmp_path, raw, 1, header=_options(h, colour="red"), name="key.igz")]
    for path in files:
        assert main(["graph", "info", str(path)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("igraph-fight: error: ") and path.name in err, err
    # the bout itself in a fresh process (the old code died there with SIGSEGV)
    r = subprocess.run([sys.executable, "-m", "igraph_fight", "fight", "--graph", str(files[0]), "--seconds", "2",
                        "--out", str(tmp_path / "bout")], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1 and "edge_action: 2147483647" in r.stderr
