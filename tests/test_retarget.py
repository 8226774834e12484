"""Retargeting onto one body: identity, rest-pose and naming differences, scale, rate, floor,
missing parts; on real mocap: foot contacts and strike reach of CMU 14_02 on the 13 skeleton, and
the library of 13_17 + 13_18 + 14_02.

Tolerances: joint positions 1e-6 m where the result is exact in theory; foot contacts
(motion_graph.contacts with its default thresholds: planted below 4 cm and 0.3 m/s, released above
6 cm or 0.5 m/s) agree on >= 90% of frames per foot; fist reach (fist-to-shoulder distance over
the arm's rest length) at every source punch peak within 0.03 arm lengths.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from motion_graph.contacts import foot_contacts
from motion_graph.features import clip_features
from motion_graph.motion import Motion
from motion_graph.retarget import (
    RetargetTarget, build_retargeted_library, load_target, plan_retarget, retarget)
from motion_graph.skeleton import Skeleton
from motion_graph.strikes import detect_strikes
from motion_graph.synthetic_boxer import synthetic_boxer

TOL_M = 1e-6
CONTACT_AGREEMENT = 0.90
REACH_TOL = 0.03


@pytest.fixture(scope="module")
def boxer() -> Motion:
    return synthetic_boxer(duration_s=3.0, punch_at_s=(0.8,), knee_lift_at_s=(2.0,), step_at_s=(1.5,))


def _with(sk: Skeleton, names=None, offsets=None) -> Skeleton:
    return Skeleton(tuple(names or sk.names), sk.parents, sk.offsets if offsets is None else offsets,
                    sk.channels, sk.is_end_site, sk.metres_per_unit)


def test_own_skeleton_is_identity(boxer):
    out = retarget(boxer, RetargetTarget.from_motion(boxer))
    assert out.fps == boxer.fps and out.n_frames == boxer.n_frames
    assert np.abs(out.positions() - boxer.positions()).max() < TOL_M


def test_rest_pose_difference_is_removed(boxer):
    """A target whose arms rest sideways (T-pose) instead of hanging: same bone lengths, same poses."""
    sk = boxer.skeleton
    off = sk.offsets.copy()
    for side, sign in (("Left", 1.0), ("Right", -1.0)):
        for n in (f"{side}ForeArm", f"{side}Hand", f"{side}Hand_End"):
            j = sk.index(n)
            off[j] = [sign * np.linalg.norm(off[j]), 0.0, 0.0]
    out = retarget(boxer, _with(sk, offsets=off))
    assert np.abs(out.positions() - boxer.positions()).max() < TOL_M
    assert not np.allclose(out.rotations, boxer.rotations)  # the local rotations did change


def test_other_naming_matched_through_parts(boxer):
    rename = {"Spine1": "Chest", "LeftArm": "UpperArm_L", "LeftForeArm": "LowerArm_L", "LeftHand": "Hand_L",
              "RightArm": "UpperArm_R", "RightForeArm": "LowerArm_R", "RightHand": "Hand_R",
              "LeftUpLeg": "UpperLeg_L", "LeftLeg": "LowerLeg_L", "LeftFoot": "Foot_L", "LeftToeBase": "Toes_L",
              "RightUpLeg": "UpperLeg_R", "RightLeg": "LowerLeg_R", "RightFoot": "Foot_R", "RightToeBase": "Toes_R"}
    names = [rename.get(n, n) for n in boxer.skeleton.names]
    target = _with(boxer.skeleton, names=names)
    plan = plan_retarget(boxer.skeleton, target)
    assert plan.unmatched == ()
    assert plan.how[target.index("LowerArm_L")] == "part:l_elbow"
    out = retarget(boxer, target, plan)
    assert out.skeleton.names == tuple(names)
    assert np.abs(out.positions() - boxer.positions()).max() < TOL_M


def test_larger_body_scales_root_by_leg_length(boxer):
    target = boxer.skeleton.scaled(1.2)
    plan = plan_retarget(boxer.skeleton, target)
    assert plan.leg_scale == pytest.approx(1.2)
    out = retarget(boxer, target, plan)
    np.testing.assert_allclose(out.root_positions, 1.2 * boxer.root_positions, atol=TOL_M)
    assert np.abs(out.positions() - 1.2 * boxer.positions()).max() < TOL_M


def test_frame_rate_is_resampled(boxer):
    out = retarget(boxer, RetargetTarget(boxer.skeleton, 30.0))
    assert out.fps == 30.0 and out.n_frames == int(boxer.duration * 30) + 1
    assert np.abs(out.positions() - boxer.positions()[::4]).max() < TOL_M


def test_feet_stay_on_the_floor_on_longer_legs(boxer):
    sk = boxer.skeleton
    off = sk.offsets.copy()
    for n in ("LeftLeg", "LeftFoot", "RightLeg", "RightFoot"):  # thigh and shin 15% longer
        off[sk.index(n)] *= 1.15
    out = retarget(boxer, _with(sk, offsets=off))
    src, dst = clip_features(boxer), clip_features(out)
    assert abs(dst.floor_y - src.floor_y) < 0.01
    agree = (foot_contacts(src) == foot_contacts(dst)).mean(axis=0)
    assert (agree >= CONTACT_AGREEMENT).all(), agree


def test_unmatched_joint_keeps_identity(boxer):
    sk = boxer.skeleton
    names = sk.names + ("Tail", "Tail_End")
    parents = np.concatenate([sk.parents, [0, sk.n_joints]])
    offsets = np.concatenate([sk.offsets, [[0.0, 0.0, -0.1], [0.0, -0.2, -0.1]]])
    target = Skeleton(names, parents, offsets, sk.channels + (("Zrotation", "Yrotation", "Xrotation"), ()),
                      np.concatenate([sk.is_end_site, [False, True]]), 1.0)
    plan = plan_retarget(sk, target)
    assert plan.unmatched == ("Tail",)
    out = retarget(boxer, target, plan)
    np.testing.assert_allclose(out.rotations[:, sk.n_joints], [[0.0, 0.0, 0.0, 1.0]] * out.n_frames, atol=1e-12)
    assert np.abs(out.positions()[:, :sk.n_joints] - boxer.positions()).max() < TOL_M


def test_held_joint_keeps_the_targets_rotation_and_its_children_their_world_rotation(boxer):
    """A joint the target's take never moves (here the neck; CMU 13 holds its clavicles and hip
    joints) stays at that rotation in every retargeted take; the head keeps its world rotation."""
    sk = boxer.skeleton
    clav, arm = sk.index("Neck"), sk.index("Head")
    def wobble(axis: int, amp: float) -> np.ndarray:
        q = np.zeros((boxer.n_frames, 4))
        q[:, axis] = amp * np.sin(np.linspace(0, 6, boxer.n_frames))
        q[:, 3] = 1.0
        return q / np.linalg.norm(q, axis=1, keepdims=True)

    moving = boxer.rotations.copy()
    moving[:, clav], moving[:, arm] = wobble(0, 0.1), wobble(1, 0.2)
    source = Motion(sk, moving, boxer.root_positions, boxer.fps, None, "moving.bvh")
    still = np.broadcast_to([0.0, 0.0, np.sin(0.05), np.cos(0.05)], (boxer.n_frames, 4))
    held_rot = boxer.rotations.copy()
    held_rot[:, clav], held_rot[:, arm] = still, wobble(1, 0.3)
    target = RetargetTarget.from_motion(Motion(sk, held_rot, boxer.root_positions, boxer.fps, None, "target.bvh"))
    assert "Neck" in target.held_names and "Head" not in target.held_names
    out = retarget(source, target)
    np.testing.assert_allclose(np.abs(out.rotations[:, clav]), np.abs(still), atol=1e-12)
    free = retarget(source, RetargetTarget(sk, boxer.fps))  # nothing held
    G_out, _ = out.global_transforms()
    G_free, _ = free.global_transforms()
    np.testing.assert_allclose(G_out[:, arm], G_free[:, arm], atol=1e-9)
    assert not np.allclose(G_out[:, clav], G_free[:, clav], atol=1e-3)


def test_missing_essential_parts_are_named(boxer):
    sk = boxer.skeleton
    no_elbow = _with(sk, names=["Blob" if n == "LeftForeArm" else n for n in sk.names])
    with pytest.raises(ValueError, match=r"target lacks l_elbow \(joints: .*Blob"):
        retarget(boxer, no_elbow)
    no_ankle = Motion(_with(sk, names=["Lump" if n == "RightFoot" else n for n in sk.names]), boxer.rotations,
                      boxer.root_positions, boxer.fps, None, "lumpy.bvh")
    with pytest.raises(ValueError, match=r"lumpy.bvh lacks r_ankle"):
        retarget(no_ankle, sk)


# ----- real mocap --------------------------------------------------------------------------

@pytest.fixture(scope="module")
def take_14_02(mocap_root):
    from motion_graph.io import load_motion
    path = mocap_root / "cmu" / "bvh_hahne" / "14_02.bvh"
    if not path.is_file():
        pytest.skip(f"{path} missing")
    return load_motion(path)


@pytest.mark.realdata
def test_cmu_take_onto_its_own_skeleton_is_identity(boxing_files):
    from motion_graph.io import load_motion
    m = load_motion(boxing_files[0]).slice(0, 1200)
    out = retarget(m, RetargetTarget.from_motion(m))
    assert np.abs(out.positions() - m.positions()).max() < TOL_M


@pytest.mark.realdata
def test_14_02_onto_13_keeps_contacts_and_reach(take_14_02, boxing_files):
    target = load_target(boxing_files[0])
    plan = plan_retarget(take_14_02.skeleton, target.skeleton)
    assert plan.unmatched == () and 1.0 < plan.leg_scale < 1.1
    out = retarget(take_14_02, target, plan)
    assert out.skeleton is target.skeleton and out.n_frames == take_14_02.n_frames
    src, dst = clip_features(take_14_02), clip_features(out)
    agree = (foot_contacts(src) == foot_contacts(dst)).mean(axis=0)
    assert (agree >= CONTACT_AGREEMENT).all(), agree
    punches = [s for s in detect_strikes(src) if s.limb.endswith("fist")]
    assert len(punches) >= 20
    for s in punches:
        k = 0 if s.limb[0] == "l" else 1
        assert abs(dst.reach[s.peak, k] - src.reach[s.peak, k]) <= REACH_TOL, s
    n_dst = sum(s.limb.endswith("fist") for s in detect_strikes(dst))
    assert abs(n_dst - len(punches)) <= 0.1 * len(punches)


def test_default_takes_are_13s_two_then_14_02_where_present(tmp_path):
    from motion_graph.paths import boxing_takes
    (tmp_path / "cmu" / "boxing").mkdir(parents=True)
    (tmp_path / "cmu" / "hahne").mkdir()
    for name in ("cmu/boxing/13_18.bvh", "cmu/boxing/13_17.bvh"):
        (tmp_path / name).write_text("")
    assert [p.name for p in boxing_takes(tmp_path)] == ["13_17.bvh", "13_18.bvh"]
    (tmp_path / "cmu" / "hahne" / "14_02.bvh").write_text("")
    assert [p.name for p in boxing_takes(tmp_path)] == ["13_17.bvh", "13_18.bvh", "14_02.bvh"]
    assert boxing_takes(tmp_path / "cmu" / "hahne") == []       # 14_02 alone is not the default library


@pytest.mark.realdata
def test_library_of_two_performers_on_one_body(take_14_02, boxing_files, default_library):
    lib = default_library                          # motion_graph.retarget.default_boxing_library
    again = build_retargeted_library([*boxing_files, take_14_02.source])
    assert lib.n_actions == again.n_actions and np.array_equal(lib.rotations, again.rotations)
    assert lib.skeleton.names == load_target(boxing_files[0]).skeleton.names
    assert lib.n_actions >= 110 and len(lib.label_counts()) >= 10
    assert {p.split("/")[-1] for p in lib.sources} == {"13_17.bvh", "13_18.bvh", "14_02.bvh"}
    assert lib.graph_report()["largest_scc_fraction"] >= 0.9
    takes = lib.meta["retarget"]["takes"]
    assert takes[str(boxing_files[0])]["leg_scale"] == 1.0 and takes[take_14_02.source]["leg_scale"] > 1.0
    # the joints 13 never moves (hip joints, clavicles) stay still, so the physics body is 13's own
    held = takes[take_14_02.source]["held"]
    assert {"LHipJoint", "RHipJoint", "LeftShoulder", "RightShoulder"} <= set(held)
    from motion_graph.io import load_motion
    from tracker.body.spec import fighter_spec
    own = fighter_spec(lib.skeleton, [load_motion(f) for f in boxing_files])
    mixed = fighter_spec(lib.skeleton, [Motion(lib.skeleton, lib.rotations, lib.root_positions, lib.fps,
                                               lib.local_translations, "library")])
    assert np.array_equal(own.dof, mixed.dof)


@pytest.mark.realdata
def test_segment_cli_target_skeleton(take_14_02, boxing_files, tmp_path, capsys):
    from igraph_fight.cli import main
    from motion_graph.library import load_library
    out = tmp_path / "lib.npz"
    rc = main(["mocap", "segment", str(boxing_files[1]), take_14_02.source, "--target-skeleton", take_14_02.source,
               "--out", str(out), "--json"])
    assert rc == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["retarget"]["target"] == take_14_02.source
    assert summary["retarget"]["takes"][str(boxing_files[1])]["leg_scale"] < 1.0
    lib = load_library(out)
    assert lib.n_actions == summary["n_actions"] and lib.skeleton.offsets.tolist() == \
        take_14_02.skeleton.offsets.tolist()


@pytest.mark.realdata
def test_build_cli_retargets_takes_of_two_skeletons(take_14_02, boxing_files, tmp_path, capsys):
    from igraph_fight.cli import main
    from igraph_fight.graph import load_graph
    out = tmp_path / "g.igz"
    small = ["--max-samples", "2000", "--n-initial", "16", "--seed-bouts", "0", "--json"]
    assert main(["build", "--mocap", str(boxing_files[1]), take_14_02.source, "--out", str(out), *small]) == 0
    rep = json.loads(capsys.readouterr().out)
    lib = load_graph(out).load_library()
    assert rep["n_states"] > 0 and lib.skeleton.names == load_target(boxing_files[1]).skeleton.names
    assert {p.split("/")[-1] for p in lib.sources} == {"13_18.bvh", "14_02.bvh"}
    assert main(["build", "--library", str(tmp_path / "x.npz"), "--target-skeleton", take_14_02.source,
                 "--out", str(out)]) == 2
    assert "--target-skeleton applies to mocap takes" in capsys.readouterr().err
