"""A quiet stance: the skeleton's rest pose standing flat-footed with its centre of mass over the
middle of its feet, as a Reference to hold (the test that the body can stand with no assist).

The rest pose is leaned as a whole about the ankles (the root turned, each ankle turned back so the
feet keep their orientation) until the centre of mass lies over the centroid of the feet's contact
spheres, then grounded (tracker.track.grounding). Two Newton steps on the lean's two angles
(about the world's x and y axes) with finite-difference slopes.
"""
from __future__ import annotations

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from motion_graph.motion import Motion
from tracker.body.humanoid import FighterScene
from tracker.track.reference import Reference, build_reference


def _pose(scene: FighterScene, k: int, base: np.ndarray, lean: np.ndarray, d: mujoco.MjData) -> np.ndarray:
    """qpos of fighter k: ``base`` with the root turned by ``lean`` (world rotation vector, x and y)
    and each ankle turned back so the feet keep their world orientation."""
    m = scene.model
    f = scene.fighters[k]
    q = base.copy()
    d.qpos[f.qpos_slice] = base
    mujoco.mj_kinematics(m, d)
    ankles = [f.spec.parts[p] for p in ("l_ankle", "r_ankle")]
    ids = [int(f.body_ids[list(f.body_joints).index(j)]) for j in ankles]
    foot_world = [_flat(m, d, b, np.asarray(f.geom_label.get(lab, []), int))
                  for b, lab in zip(ids, ("l_foot", "r_foot"))]
    R = Rotation.from_rotvec([lean[0], lean[1], 0.0])
    root = Rotation.from_quat(base[[4, 5, 6, 3]])
    q[3:7] = (R * root).as_quat()[[3, 0, 1, 2]]
    d.qpos[f.qpos_slice] = q
    mujoco.mj_kinematics(m, d)
    for b, j, fw in zip(ids, ankles, foot_world):
        parent = Rotation.from_quat(d.xquat[m.body_parentid[b]][[1, 2, 3, 0]])
        body = Rotation.from_quat(m.body_quat[b][[1, 2, 3, 0]])
        jq = (body.inv() * parent.inv() * fw).as_quat()[[3, 0, 1, 2]]
        a = int(f.joint_qpos[list(f.dof_joints).index(j)]) - f.qpos_adr
        q[a:a + 4] = jq
    return q


def _flat(m: mujoco.MjModel, d: mujoco.MjData, body: int, geoms: np.ndarray) -> Rotation:
    """The foot body's world orientation turned (least rotation) so that the sole spheres it holds lie
    in a horizontal plane."""
    own = [g for g in geoms if m.geom_bodyid[g] == body and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
    R = Rotation.from_quat(d.xquat[body][[1, 2, 3, 0]])
    if len(own) < 3:
        return R
    p = d.geom_xpos[own] - d.geom_xpos[own].mean(axis=0)
    n = np.linalg.svd(p)[2][-1]
    n = n if n[2] > 0 else -n
    axis = np.cross(n, [0.0, 0.0, 1.0])
    s = np.linalg.norm(axis)
    if s < 1e-9:
        return R
    return Rotation.from_rotvec(axis / s * np.arcsin(min(1.0, s))) * R


def _com_offset(scene: FighterScene, k: int, q: np.ndarray, d: mujoco.MjData) -> np.ndarray:
    """(2,) ground offset (m) of the centre of mass from the centroid of the foot contact spheres."""
    m = scene.model
    f = scene.fighters[k]
    d.qpos[f.qpos_slice] = q
    mujoco.mj_kinematics(m, d)
    mujoco.mj_comPos(m, d)
    feet = np.concatenate([f.geom_label.get("l_foot", []), f.geom_label.get("r_foot", [])]).astype(int)
    sph = feet[m.geom_type[feet] == mujoco.mjtGeom.mjGEOM_SPHERE]
    return d.subtree_com[f.pelvis_body, :2] - d.geom_xpos[sph, :2].mean(axis=0)


def quiet_stance(scene: FighterScene, seconds: float = 10.0, fps: float = 30.0, k: int = 0) -> Reference:
    """The quiet stance of fighter k held still for ``seconds`` (module docstring)."""
    spec = scene.fighters[k].spec
    sk = spec.skeleton
    T = int(round(seconds * fps)) + 2
    rot = np.zeros((T, sk.n_joints, 4))
    rot[..., 3] = 1.0
    root = np.zeros((T, 3))
    root[:, 1] = 1.0
    ref = build_reference(Motion(sk, rot, root, fps, None, "rest pose"), scene, k)
    d = mujoco.MjData(scene.model)
    base = ref.qpos[0]
    lean = np.zeros(2)
    h = 1e-3
    for _ in range(3):
        q = _pose(scene, k, base, lean, d)
        e = _com_offset(scene, k, q, d)
        J = np.zeros((2, 2))
        for i in range(2):
            dl = lean.copy()
            dl[i] += h
            J[:, i] = (_com_offset(scene, k, _pose(scene, k, base, dl, d), d) - e) / h
        lean = lean - np.linalg.lstsq(J, e, rcond=None)[0]
    q = _pose(scene, k, base, lean, d)
    motion = Motion(sk, rot, root, fps, None, "quiet stance")
    stance = build_reference(motion, scene, k, lift="none")
    stance.qpos[:] = q
    from tracker.track.reference import ctrl_targets, site_positions
    from tracker.track.grounding import floor_report, foot_heights, ground_heights
    feet, com = foot_heights(scene, scene.fighters[k], stance.qpos)
    stance.qpos[:, 2] += ground_heights(feet, com, fps)
    stance.qvel[:] = 0.0
    stance.ctrl[:], stance.ctrl_vel[:] = ctrl_targets(stance.qpos, stance.qvel, scene.fighters[k])
    stance.sites[:] = site_positions(scene, scene.fighters[k], stance.qpos)[0]
    stance.meta["lean_rad"] = lean.tolist()
    stance.meta["floor_after"] = floor_report(feet + 0.0)
    return stance
