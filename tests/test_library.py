"""ActionLibrary: file round trip and corruption, playback, transitions, user labels, CLI."""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from motion_graph.errors import LibraryFormatError
from motion_graph.io_bvh import load_bvh, save_bvh
from motion_graph.library import build_library, load_library
from motion_graph.synthetic_boxer import synthetic_boxer


@pytest.fixture(scope="module")
def lib(boxing_files):
    return build_library(boxing_files)


def test_round_trip(lib, tmp_path):
    p = tmp_path / "lib.npz"
    lib.save(p)
    back = load_library(p)
    assert back.labels == lib.labels and back.sources == lib.sources
    np.testing.assert_array_equal(back.next_ids, lib.next_ids)
    np.testing.assert_allclose(back.positions, lib.positions)
    assert back.parts == lib.parts


def test_truncated_and_corrupted_files(lib, tmp_path):
    p = tmp_path / "lib.npz"
    lib.save(p)
    data = p.read_bytes()
    (tmp_path / "trunc.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(LibraryFormatError, match="trunc.npz"):
        load_library(tmp_path / "trunc.npz")
    (tmp_path / "empty.npz").write_bytes(b"")
    with pytest.raises(LibraryFormatError, match="empty.npz"):
        load_library(tmp_path / "empty.npz")
    with pytest.raises(LibraryFormatError, match="no such file"):
        load_library(tmp_path / "missing.npz")
    # A valid archive whose array content was altered: the checksum catches it.
    with np.load(p) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["dx"] = arrays["dx"] + 0.01
    np.savez(tmp_path / "tampered.npz", **arrays)
    with pytest.raises(LibraryFormatError, match="checksum"):
        load_library(tmp_path / "tampered.npz")
    header = json.loads(bytes(arrays["header"]).decode())
    header["version"] = 999
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    arrays["dx"] = arrays["dx"] - 0.01
    np.savez(tmp_path / "future.npz", **arrays)
    with pytest.raises(LibraryFormatError, match="version 999"):
        load_library(tmp_path / "future.npz")


def test_foreign_files_and_an_out_of_range_library_in_memory(lib, tmp_path):
    from motion_graph.library import validate_library

    (tmp_path / "notes.npz").write_text("not a library\n")
    np.savez(tmp_path / "plain.npz", a=np.zeros(2))
    with open(tmp_path / "graph.npz", "wb") as fh:
        np.savez(fh, header=np.frombuffer(b'{"format": "igraph-fight/interaction-graph"}', dtype=np.uint8))
    for name, why in (("notes.npz", "not a zip archive"), ("plain.npz", "no header"),
                      ("graph.npz", "format 'igraph-fight/interaction-graph'")):
        with pytest.raises(LibraryFormatError, match=rf"{name}: not an igraph-fight action library \({why}"):
            load_library(tmp_path / name)
    validate_library(lib)
    with pytest.raises(LibraryFormatError, match=r"<library>: next_ids: .* is outside \[0, "):
        validate_library(dataclasses.replace(lib, next_ids=lib.next_ids + lib.n_actions))


def test_actions_start_at_origin_facing_forward(lib):
    for a in range(lib.n_actions):
        f0 = lib.frame_offsets[a]
        assert np.allclose(lib.path[f0], 0.0, atol=1e-9)
        pel = lib.positions[f0, lib.parts["pelvis"]]
        assert abs(pel[0]) < 1e-6 and abs(pel[2]) < 1e-6 and 0.7 < pel[1] < 1.2
    assert np.allclose(lib.dx, lib.path[lib.frame_offsets[1:] - 1, 0])


def test_sequence_of_consecutive_actions_reproduces_the_take(lib, boxing_files):
    """Playing actions k..k+2 of one take from the take's placement gives the take itself."""
    from motion_graph.features import clip_features
    from motion_graph.io import load_motion

    k = 3
    assert lib.sources[k] == lib.sources[k + 2] == str(boxing_files[0])
    x0, z0, h0 = lib.src_placement[k]
    m = lib.sequence_motion([k, k + 1, k + 2], blend_frames=0, start_xz=(x0, z0), start_heading=h0)
    take = load_motion(boxing_files[0])
    floor = clip_features(take).floor_y
    t = np.concatenate([np.linspace(lib.src_start[a], lib.src_end[a], lib.n_frames[a])[(0 if a == k else 1):]
                        for a in (k, k + 1, k + 2)]) / take.fps
    P_take = take.positions()
    idx = np.round(t * take.fps).astype(int)
    ref = P_take[idx] - np.array([0.0, floor, 0.0])
    # library frames are resampled at exactly the action boundaries: compare at source frames
    # that coincide with library frames (every 4th at 120 -> 30 fps, up to rounding of durations)
    close = np.abs(t * take.fps - idx) < 0.05
    assert close.sum() > 10
    err = np.linalg.norm(m.positions()[close] - ref[close], axis=-1)
    assert err.max() < 1e-3, err.max()


def test_blend_hides_transition_pops(lib):
    rng = np.random.default_rng(0)
    worst_raw = worst_blend = 0.0
    for _ in range(10):
        ids = lib.random_walk(6, rng)
        for i in range(len(ids) - 1):
            assert ids[i + 1] in lib.next(ids[i])
        raw = np.linalg.norm(np.diff(lib.sequence_motion(ids, blend_frames=0).positions(), axis=0), axis=-1).max()
        bl = np.linalg.norm(np.diff(lib.sequence_motion(ids, blend_frames=4).positions(), axis=0), axis=-1).max()
        worst_raw, worst_blend = max(worst_raw, raw), max(worst_blend, bl)
    assert worst_blend <= worst_raw + 1e-9


def test_user_labels_override(boxing_files, tmp_path):
    base = build_library(boxing_files[:1])
    a = 1
    src = boxing_files[0].name
    (tmp_path / "labels.txt").write_text(f"# my labels\n{src} {base.src_start[a]} duck\n")
    lib = build_library(boxing_files[:1], labels_file=tmp_path / "labels.txt")
    assert lib.labels[a] == "duck" and base.labels[a] != "duck" or base.labels[a] == "duck"
    assert lib.labels[:a] == base.labels[:a]
    (tmp_path / "bad.txt").write_text(f"{src} 0 haymaker\n")
    with pytest.raises(LibraryFormatError, match="haymaker"):
        build_library(boxing_files[:1], labels_file=tmp_path / "bad.txt")


def test_bvh_writer_round_trip(tmp_path):
    m = synthetic_boxer(duration_s=1.0, fps=30.0)
    save_bvh(m, tmp_path / "s.bvh")
    back = load_bvh(tmp_path / "s.bvh", metres_per_unit=0.01)
    assert back.fps == pytest.approx(30.0)
    np.testing.assert_allclose(back.positions(), m.positions(), atol=1e-4)


def test_cli_segment_json(boxing_files, tmp_path):
    out = subprocess.run([sys.executable, "-m", "igraph_fight", "mocap", "segment", *map(str, boxing_files),
                          "--out", str(tmp_path / "lib.npz"), "--plot", str(tmp_path / "t.png"), "--json"],
                         capture_output=True, text=True, check=True)
    rep = json.loads(out.stdout)
    for key in ("n_actions", "label_counts", "n_attacks", "largest_scc_fraction", "actions"):
        assert key in rep
    assert rep["n_actions"] == len(rep["actions"]) and rep["n_attacks"] >= 10
    a = next(r for r in rep["actions"] if "attacks" in r)
    assert {"kind", "effector", "hit_window", "reach_m"} <= set(a["attacks"][0])
    assert (tmp_path / "lib.npz").stat().st_size > 0 and (tmp_path / "t.png").stat().st_size > 10_000


def test_cli_bad_file_one_line_error(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n"
                   "MOTION\nFrames: 2\nFrame Time: 0.033\n1 2 3\n1 x 3\n")
    out = subprocess.run([sys.executable, "-m", "igraph_fight", "mocap", "inspect", str(bad)],
                         capture_output=True, text=True)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and f"{bad}:11" in out.stderr and "Traceback" not in out.stderr
