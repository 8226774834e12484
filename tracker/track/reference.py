"""Reference motion for tracking: a Motion converted into the model's qpos / qvel / PD targets.

A Reference holds, per frame at its own rate (normally the control rate, 30 Hz):
- qpos (T, nq) and qvel (T, nv) of one fighter (free joint: world position, world->body quaternion
  (w, x, y, z), linear velocity in world axes, angular velocity in body axes; joints relative to rest);
- ctrl (T, n_act): PD position targets (ball joint: rotation-vector components; hinge: angle) and
  ctrl_vel (T, n_act): their velocity targets (ball: body angular velocity components);
- sites (T, S, 3): MuJoCo world positions of the skeleton joints inside the model (for errors);
- the foot penetration report of the reference (how far the reference pushes feet into the floor).

The conversion is exact (to float precision) for tracked joints: tests check <= 1 cm.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from motion_graph.motion import Motion

from tracker.body.humanoid import C_MOCAP_TO_MJ, BodyMap, FighterScene
from tracker.track.grounding import floor_report, foot_heights, ground_heights, lowest_point


@dataclass
class FootPenetration:
    """How far the reference's foot collision geoms go below the floor (metres, >= 0).

    Attributes:
        per_frame_m: (T,) deepest foot penetration per frame (0 when above the floor).
        max_m, p95_m, mean_m: statistics of per_frame_m.
        share_over_1cm: share of frames deeper than 1 cm.
        lift_m: how far the reference was moved up to meet the floor (negative: moved down).
    """

    per_frame_m: np.ndarray
    max_m: float
    p95_m: float
    mean_m: float
    share_over_1cm: float
    lift_m: float = 0.0

    @classmethod
    def from_depths(cls, depth: np.ndarray, lift_m: float = 0.0) -> "FootPenetration":
        d = np.maximum(np.asarray(depth, dtype=np.float64), 0.0)
        if d.size == 0:
            return cls(d, 0.0, 0.0, 0.0, 0.0, lift_m)
        return cls(d, float(d.max()), float(np.percentile(d, 95)), float(d.mean()), float(np.mean(d > 0.01)), lift_m)

    def as_dict(self) -> dict:
        return dict(max_cm=100 * self.max_m, p95_cm=100 * self.p95_m, mean_cm=100 * self.mean_m,
                    share_over_1cm=self.share_over_1cm, lift_cm=100 * self.lift_m)


@dataclass
class Reference:
    """Reference trajectory of one fighter (see module doc). ``fps`` is its frame rate."""

    fps: float
    qpos: np.ndarray
    qvel: np.ndarray
    ctrl: np.ndarray
    ctrl_vel: np.ndarray
    sites: np.ndarray
    penetration: FootPenetration
    source: str = ""
    meta: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return int(self.qpos.shape[0])

    @property
    def duration(self) -> float:
        return (self.n_frames - 1) / self.fps


def placement_transform(dx: float = 0.0, dz: float = 0.0, heading: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Ground-plane placement in mocap axes (Y up): rotate by heading about +Y, then translate by (dx, 0, dz)."""
    c, s = np.cos(heading), np.sin(heading)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    return R, np.array([dx, 0.0, dz])


def motion_qpos(motion: Motion, fighter: BodyMap, placement: tuple[np.ndarray, np.ndarray] | None = None,
                lift_m: float = 0.0) -> np.ndarray:
    """(T, nq) qpos of one fighter for every frame of a motion of its skeleton."""
    spec = fighter.spec
    if motion.skeleton.n_joints != spec.skeleton.n_joints:
        raise ValueError("motion_qpos: motion and fighter have different skeletons")
    g_rot, g_pos = _pelvis_world(motion, spec.pelvis)
    if placement is not None:
        R, t = placement
        g_rot = np.einsum("ab,tbc->tac", R, g_rot)
        g_pos = g_pos @ R.T + t
    T = motion.n_frames
    q = np.zeros((T, fighter.nq))
    q[:, 0:3] = g_pos @ C_MOCAP_TO_MJ.T
    q[:, 2] += lift_m
    rw = Rotation.from_matrix(np.einsum("ab,tbc->tac", C_MOCAP_TO_MJ, g_rot)).as_quat()
    q[:, 3:7] = _wxyz(rw)
    rest = Rotation.from_quat(spec.rest[fighter.dof_joints])
    off = 7
    for i, j in enumerate(fighter.dof_joints):
        rel = rest[i].inv() * Rotation.from_quat(motion.rotations[:, j])
        if fighter.joint_type == "ball":
            q[:, off:off + 4] = _wxyz(rel.as_quat())
            off += 4
        else:
            # MuJoCo applies the body's hinges in order (z, y, x): R = Rz Ry Rx, intrinsic "ZYX".
            eul = rel.as_euler("ZYX")
            q[:, off:off + 3] = np.unwrap(eul, axis=0)
            off += 3
    return q


def _pelvis_world(motion: Motion, pelvis: int) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3, 3), (T, 3): world rotation and position of the pelvis joint (mocap axes)."""
    if pelvis == 0:
        R = Rotation.from_quat(motion.rotations[:, 0]).as_matrix()
        return R, motion.root_positions.copy()
    g_rot, g_pos = motion.global_transforms()
    return g_rot[:, pelvis], g_pos[:, pelvis]


def _wxyz(q_xyzw: np.ndarray) -> np.ndarray:
    q = np.concatenate([q_xyzw[..., 3:4], q_xyzw[..., :3]], axis=-1)
    return q * np.where(q[..., :1] < 0, -1.0, 1.0)


def _xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    return np.concatenate([q_wxyz[..., 1:4], q_wxyz[..., :1]], axis=-1)


def qpos_velocity(qpos: np.ndarray, fighter: BodyMap, fps: float) -> np.ndarray:
    """(T, nv) velocities by central differences (one-sided at the ends) of a qpos track."""
    T = qpos.shape[0]
    nv = fighter.nv
    v = np.zeros((T, nv))
    if T < 2:
        return v
    i0 = np.r_[0, np.arange(T - 2), T - 2]
    i1 = np.r_[1, np.arange(2, T), T - 1]
    dt = (i1 - i0)[:, None] / fps
    v[:, 0:3] = (qpos[i1, 0:3] - qpos[i0, 0:3]) / dt
    v[:, 3:6] = _ang_vel(qpos[:, 3:7], i0, i1, dt)
    qo, vo = 7, 6
    for _ in fighter.dof_joints:
        if fighter.joint_type == "ball":
            v[:, vo:vo + 3] = _ang_vel(qpos[:, qo:qo + 4], i0, i1, dt)
            qo += 4
        else:
            v[:, vo:vo + 3] = (qpos[i1, qo:qo + 3] - qpos[i0, qo:qo + 3]) / dt
            qo += 3
        vo += 3
    return v


def _ang_vel(q_wxyz: np.ndarray, i0: np.ndarray, i1: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Body-frame angular velocity from quaternions (w, x, y, z) at frames i0 -> i1."""
    r = Rotation.from_quat(_xyzw(q_wxyz))
    return (r[i0].inv() * r[i1]).as_rotvec() / dt


def ctrl_targets(qpos: np.ndarray, qvel: np.ndarray, fighter: BodyMap) -> tuple[np.ndarray, np.ndarray]:
    """PD position and velocity targets (T, n_act) matching the actuators' length and velocity."""
    T = qpos.shape[0]
    pos = np.zeros((T, fighter.n_act))
    vel = np.zeros((T, fighter.n_act))
    # Per dof joint: length components then velocity components.
    jl = np.zeros((T, len(fighter.dof_joints), 3))
    jv = qvel[:, 6:].reshape(T, -1, 3)
    qo = 7
    for i in range(len(fighter.dof_joints)):
        if fighter.joint_type == "ball":
            jl[:, i] = Rotation.from_quat(_xyzw(qpos[:, qo:qo + 4])).as_rotvec()
            qo += 4
        else:
            # hinge order in the body is z, y, x: store as x, y, z components
            jl[:, i] = qpos[:, qo:qo + 3][:, ::-1]
            qo += 3
    if fighter.joint_type != "ball":
        jv = jv[:, :, ::-1]
    pos[:] = jl[:, fighter.act_joint, fighter.act_axis]
    vel[:] = jv[:, fighter.act_joint, fighter.act_axis]
    return pos, vel


def site_positions(scene: FighterScene, fighter: BodyMap, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose the model at every frame: (T, S, 3) joint-site world positions, (T,) lowest foot-geom
    point (metres, MuJoCo z; negative = below the floor)."""
    m = scene.model
    d = mujoco.MjData(m)
    T = qpos.shape[0]
    sites = np.zeros((T, len(fighter.site_ids), 3))
    low = np.zeros(T)
    fg = fighter.foot_geoms
    for t in range(T):
        d.qpos[fighter.qpos_slice] = qpos[t]
        mujoco.mj_kinematics(m, d)
        sites[t] = d.site_xpos[fighter.site_ids]
        low[t] = lowest_point(m, d, fg).min() if len(fg) else np.inf
    return sites, low


def build_reference(motion: Motion, scene: FighterScene, fighter: int = 0, fps: float | None = None,
                    placement: tuple[np.ndarray, np.ndarray] | None = None, lift: str | float = "auto") -> Reference:
    """Convert a Motion into a Reference for one fighter of a scene.

    Args:
        motion: the motion (any rate; resampled to ``fps`` when given).
        fps: reference rate (frames per second); default the motion's rate.
        placement: ground-plane placement (placement_transform) applied before conversion.
        lift: move the reference vertically so its feet meet the floor: "auto" (default: the 10th
            percentile of the per-frame lowest foot point goes to the floor, so typical stance frames
            neither sink into nor float above it; negative when the whole reference floats), "p90"
            (lift by the 90th percentile of the per-frame penetration, never down), "max" (no
            penetration at all), "ground" (frame by frame: the lower foot on the floor in every
            supported frame, tracker.track.grounding), "none", or metres (positive up).
    """
    fm = scene.fighters[fighter]
    if fps is not None and abs(fps - motion.fps) > 1e-9:
        motion = motion.resample(fps)
    qpos = motion_qpos(motion, fm, placement)
    if lift == "ground":
        return _grounded_reference(motion, scene, fm, qpos)
    sites, low = site_positions(scene, fm, qpos)
    depth0 = np.maximum(-low, 0.0)
    if isinstance(lift, str):
        if lift == "none":
            lift_m = 0.0
        elif lift == "auto":
            lift_m = -float(np.percentile(low, 10)) if len(low) else 0.0
        elif lift == "p90":
            lift_m = float(np.percentile(depth0, 90)) if len(depth0) else 0.0
        elif lift == "max":
            lift_m = float(depth0.max()) if len(depth0) else 0.0
        else:
            raise ValueError(f"lift: 'auto', 'none', 'p90', 'max' or metres, not {lift!r}")
    else:
        lift_m = float(lift)
    if lift_m != 0.0:
        qpos[:, 2] += lift_m
        sites = sites + np.array([0.0, 0.0, lift_m])
        low = low + lift_m
    qvel = qpos_velocity(qpos, fm, motion.fps)
    ctrl, ctrl_vel = ctrl_targets(qpos, qvel, fm)
    pen = FootPenetration.from_depths(-low, lift_m)
    return Reference(motion.fps, qpos, qvel, ctrl, ctrl_vel, sites, pen, motion.source,
                     dict(penetration_before_lift=FootPenetration.from_depths(depth0).as_dict()))


def _grounded_reference(motion: Motion, scene: FighterScene, fm: BodyMap, qpos: np.ndarray) -> Reference:
    """build_reference with lift="ground": the root height offset frame by frame (grounding module)."""
    feet0, com = foot_heights(scene, fm, qpos)
    off = ground_heights(feet0, com, motion.fps)
    qpos = qpos.copy()
    qpos[:, 2] += off
    sites, low = site_positions(scene, fm, qpos)
    feet1 = feet0 + off[:, None]
    qvel = qpos_velocity(qpos, fm, motion.fps)
    ctrl, ctrl_vel = ctrl_targets(qpos, qvel, fm)
    pen = FootPenetration.from_depths(-low, float(np.mean(off)) if len(off) else 0.0)
    meta = dict(penetration_before_lift=FootPenetration.from_depths(np.maximum(-feet0.min(axis=1), 0.0)).as_dict(),
                floor_before=floor_report(feet0), floor_after=floor_report(feet1), ground_offset_m=off,
                feet_after_m=feet1)
    return Reference(motion.fps, qpos, qvel, ctrl, ctrl_vel, sites, pen, motion.source, meta)


def kinematic_error(motion: Motion, reference: Reference, fighter: BodyMap) -> np.ndarray:
    """(T, S_tracked) distance (metres) between the reference's joint sites and the motion's forward
    kinematics (mocap positions mapped to MuJoCo axes, the reference's lift removed)."""
    pos = motion.positions()[:, fighter.site_joints[fighter.tracked]] @ C_MOCAP_TO_MJ.T
    sites = reference.sites[:, fighter.tracked] - np.array([0.0, 0.0, reference.penetration.lift_m])
    return np.linalg.norm(sites - pos, axis=-1)
