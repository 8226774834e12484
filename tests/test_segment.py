"""Contacts, strikes, segmentation and classification: synthetic clips and the real takes."""
from __future__ import annotations

import numpy as np
import pytest

from motion_graph.classify import ATTACK_KINDS, annotate
from motion_graph.contacts import contact_summary, foot_contacts
from motion_graph.features import clip_features
from motion_graph.library import build_library, segment_files
from motion_graph.segment import segment_clip
from motion_graph.strikes import detect_strikes
from motion_graph.synthetic_boxer import synthetic_boxer


def test_synthetic_punch_is_found_and_not_cut():
    m = synthetic_boxer(duration_s=4.0, punch_at_s=(1.0, 3.0), knee_lift_at_s=(2.0,))
    feat = clip_features(m)
    strikes = detect_strikes(feat)
    assert [s.limb for s in strikes] == ["r_fist", "r_fist"]
    assert [round(s.peak / m.fps, 2) for s in strikes] == [1.0, 3.0]
    seg = segment_clip(feat, strikes)
    for s in strikes:
        assert not any(s.start < c < s.stop for c in seg.cuts), "cut inside a punch"
    labels = [annotate(feat, strikes, a, b, 0.0).label for a, b in zip(seg.cuts[:-1], seg.cuts[1:])]
    assert labels.count("straight") == 2  # rear hand of an orthodox stance


def test_synthetic_knee_lift_breaks_double_support():
    m = synthetic_boxer(duration_s=3.0, punch_at_s=(), knee_lift_at_s=(1.5,))
    c = foot_contacts(clip_features(m))
    t = np.arange(m.n_frames) / m.fps
    assert c[(t > 1.45) & (t < 1.55), 0].sum() == 0, "left foot in the air at the top of the lift"
    assert c[(t > 1.45) & (t < 1.55), 1].all(), "right foot stays planted"
    assert c[t < 1.0].all() and c[t > 2.0].all()


def test_synthetic_step_forward_label():
    m = synthetic_boxer(duration_s=3.0, punch_at_s=(), knee_lift_at_s=(), step_at_s=(1.5,), step_m=0.4)
    feat = clip_features(m)
    ann = annotate(feat, [], 0, m.n_frames - 1, 0.0)
    assert ann.label == "step_forward"
    assert ann.dz == pytest.approx(0.4, abs=0.02) and abs(ann.dx) < 0.02


def test_no_punch_without_fist_speed():
    # The same arm path played 5x slower is a reach, not a punch.
    m = synthetic_boxer(duration_s=4.0, punch_at_s=(2.0,), knee_lift_at_s=())
    slow = m.resample(m.fps * 5)
    slow.fps = m.fps
    assert detect_strikes(clip_features(slow)) == []


@pytest.fixture(scope="module")
def boxing_clips(boxing_files):
    return segment_files(boxing_files)


@pytest.fixture(scope="module")
def boxing_library(boxing_clips):
    from motion_graph.library import library_from_clips
    return library_from_clips(boxing_clips)


def test_cmu_boxing_contacts_match_design(boxing_files):
    from motion_graph.io import load_motion
    m = load_motion(boxing_files[0])
    s = contact_summary(foot_contacts(clip_features(m)), m.fps)
    # double-support intervals about 2.5 per second, a third of frames in flight (docs/architecture.md, actions from mocap).
    assert 1.8 < s["double_support_per_s"] < 3.5
    assert 0.2 < s["flight_share"] < 0.5


def test_cmu_boxing_segmentation_acceptance(boxing_library):
    lib = boxing_library
    assert 50 <= lib.n_actions <= 110
    counts = lib.label_counts()
    assert len(counts) >= 5
    n_attacks = sum(lib.is_attack(a) for a in range(lib.n_actions))
    assert n_attacks >= 10
    assert {"guard"} <= set(counts) and set(counts) & set(ATTACK_KINDS)
    assert any(l.startswith("step") or l.startswith("turn") for l in counts)
    assert lib.graph_report()["largest_scc_fraction"] >= 0.8


def test_no_attack_cut_inside_its_extension(boxing_clips):
    n = 0
    for clip in boxing_clips:
        cuts = clip.segmentation.cuts
        for s in clip.strikes:
            n += 1
            inside = [c for c in cuts if s.start < c < s.stop]
            assert not inside, f"{clip.path}: cut at frame {inside} inside strike {s}"
    assert n >= 20


def test_actions_are_mostly_about_a_second(boxing_library):
    d = boxing_library.duration
    assert d.min() >= 0.25 and d.max() <= 2.1
    assert 0.5 < np.median(d) < 1.5


def test_bandai_punches_and_walks(mocap_root):
    bandai = mocap_root / "bandai_namco"
    for name in ("dataset-1_punch_normal_001.bvh", "dataset-1_punch_normal_002.bvh"):
        lib = build_library([bandai / name])
        assert sum(lib.is_attack(a) for a in range(lib.n_actions)) >= 3, name
        assert set(lib.labels) & {"jab", "straight", "hook", "uppercut"}
    for name in ("dataset-1_walk_normal_001.bvh", "dataset-1_walk-left_normal_001.bvh",
                 "dataset-1_walk-right_normal_001.bvh", "dataset-1_walk-back_normal_001.bvh"):
        lib = build_library([bandai / name])
        assert not any(lib.is_attack(a) for a in range(lib.n_actions)), name
        steps = [l for l in lib.labels if l.startswith("step")]
        assert len(steps) >= max(1, lib.n_actions // 2), (name, lib.labels)
    lib = build_library([bandai / "dataset-1_walk-back_normal_001.bvh"])
    assert lib.labels[0] == "step_back"
    lib = build_library([bandai / "dataset-1_kick_normal_001.bvh"])
    assert lib.labels.count("kick") >= 2


def test_other_skeletons_segment(mocap_root):
    lib = build_library([mocap_root / "cmu" / "martial_arts" / "135_06.bvh"])
    assert lib.n_actions >= 15 and len(lib.label_counts()) >= 4
