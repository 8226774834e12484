"""Reference conversion: Motion (clips and action-library walks) -> qpos/qvel/PD targets that match
the kinematic skeleton within 1 cm, consistent velocities, foot penetration reported."""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np
import pytest

from motion_graph.io import load_motion
from tracker.body.humanoid import ModelOptions, build_fighter_scene
from tracker.track.reference import build_reference, kinematic_error, placement_transform
from tracker.body.spec import fighter_spec

pytestmark = pytest.mark.realdata


@lru_cache(maxsize=None)
def _clip(path: str, seconds: float = 6.0):
    m = load_motion(path)
    return m.slice(0, min(m.n_frames, int(seconds * m.fps)))


@pytest.mark.parametrize("rel", ["cmu/boxing/13_18.bvh", "cmu/asf_amc/135_06.amc",
                                 "bandai_namco/dataset-1_kick_normal_001.bvh"])
@pytest.mark.parametrize("joint_type", ["ball", "hinge3"])
def test_clip_reference_matches_kinematics_within_1cm(mocap_root, rel, joint_type):
    m = _clip(str(Path(mocap_root) / rel))
    spec = fighter_spec(m.skeleton, [m])
    scene = build_fighter_scene(spec, 1, ModelOptions(joint_type=joint_type))
    ref = build_reference(m, scene, fps=30.0, lift="none")
    err = kinematic_error(m.resample(30.0), ref, scene.fighters[0])
    assert err.shape[1] >= 20            # every joint the model represents is compared
    assert err.max() < 0.01


def test_library_walk_reference_matches_within_1cm_and_reports_penetration(boxing_library):
    lib = boxing_library
    from tracker.track.walks import LibraryWalks
    src = LibraryWalks(lib)
    spec = fighter_spec(src.skeleton, src.calibration_motions())
    scene = build_fighter_scene(spec, 2)
    walk = src.random_walk(8, np.random.default_rng(5))
    motion = src.sequence_motion(walk)
    assert motion.fps == 30.0
    # Placed anywhere in the ring, for either fighter.
    ref = build_reference(motion, scene, 1, placement=placement_transform(1.0, -0.5, 2.0), lift="none")
    pos = motion.positions()
    R, t = placement_transform(1.0, -0.5, 2.0)
    from tracker.body.humanoid import C_MOCAP_TO_MJ
    f = scene.fighters[1]
    want = (pos[:, f.site_joints[f.tracked]] @ R.T + t) @ C_MOCAP_TO_MJ.T
    assert np.abs(ref.sites[:, f.tracked] - want).max() < 0.01
    # Foot penetration: reported per frame; lifting reduces it and is recorded.
    pen = ref.penetration
    assert pen.per_frame_m.shape == (ref.n_frames,) and pen.lift_m == 0.0
    assert pen.max_m >= pen.p95_m >= 0.0
    lifted = build_reference(motion, scene, 1, lift="max")
    assert lifted.penetration.max_m < 1e-9 <= lifted.penetration.lift_m + 1e-9
    assert abs(lifted.penetration.lift_m - pen.max_m) < 1e-9
    assert set(pen.as_dict()) >= {"max_cm", "p95_cm", "mean_cm", "share_over_1cm", "lift_cm"}


def test_velocities_and_pd_targets_are_consistent_with_mujoco(mocap_root):
    m = _clip(str(Path(mocap_root) / "cmu/boxing/13_18.bvh"), 3.0)
    spec = fighter_spec(m.skeleton, [m])
    scene = build_fighter_scene(spec, 1)
    ref = build_reference(m, scene, fps=120.0, lift="none")
    model, d = scene.model, mujoco.MjData(scene.model)
    f = scene.fighters[0]
    dt = 1.0 / ref.fps
    worst_int, worst_len = 0.0, 0.0
    for t in range(10, ref.n_frames - 10, 37):
        # qvel in MuJoCo's convention (world linear, body-frame angular velocities): the central
        # difference integrated from the previous frame over two frame times lands on the next one.
        q = ref.qpos[t - 1].copy()
        mujoco.mj_integratePos(model, q, ref.qvel[t], 2 * dt)
        dv = np.zeros(model.nv)
        mujoco.mj_differentiatePos(model, dv, 1.0, ref.qpos[t + 1], q)
        worst_int = max(worst_int, float(np.abs(dv).max()))
        # The PD target of each actuator equals the actuator length at the reference pose.
        d.qpos[:] = ref.qpos[t]
        mujoco.mj_forward(model, d)
        worst_len = max(worst_len, float(np.abs(d.actuator_length[f.ctrl_slice] - ref.ctrl[t]).max()))
    assert worst_int < 1e-6
    assert worst_len < 1e-6
