"""The tracking reward of the learned policy's training (and of the searches that steer it): a
DeepMimic / ScaDiver-style imitation reward in [0, 1] per fighter and control step.

    rr = RewardRef.build(env, scene, ref)       # per-frame reference quantities, once per reference
    r = tracking_reward(env, rr, weights, k)    # after each env.step

Terms (weights: pose, joint velocity, end effectors, root, centre-of-mass velocity): joint rotation
error, joint velocity error, end effectors relative to the pelvis in the facing frame (a drifted but
balanced body is not scored as lost: the reference's feet slide, the simulated ones stick), root
(height, tilt, heading and a mild drift term) and the centre of mass's velocity. The environment's
own reward (TrackingEnv.reward) is a simpler variant of the first four terms.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from motion_graph.rotations import wrap_angle

from tracker.body.frames import facing_rotation, ground_yaw, quat_matrix


@dataclass
class RewardRef:
    """Per-frame reference quantities of tracking_reward: end effectors relative to the pelvis in the
    facing frame (T, E, 3), pelvis up vector (T, 3), heading (T,), centre-of-mass velocity (T, 3)."""

    ee_local: np.ndarray
    up: np.ndarray
    heading: np.ndarray
    com_vel: np.ndarray

    @classmethod
    def build(cls, env, scene, ref) -> "RewardRef":
        from tracker.track.env import TrackingEnv
        env = env or TrackingEnv(scene)
        c = env._cache[0]
        m = scene.model
        d = mujoco.MjData(m)
        f = scene.fighters[0]
        T = ref.n_frames
        com = np.zeros((T, 3))
        for t in range(T):
            d.qpos[f.qpos_slice] = ref.qpos[t]
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            com[t] = d.subtree_com[f.pelvis_body]
        com_vel = np.gradient(com, 1.0 / ref.fps, axis=0) if T > 1 else np.zeros_like(com)
        ee_local = np.zeros((T, len(c.ee_sites), 3))
        up = np.zeros((T, 3))
        heading = np.zeros(T)
        for t in range(T):
            R = quat_matrix(ref.qpos[t, 3:7])
            yaw = ground_yaw(R, c.lateral)
            heading[t] = yaw
            up[t] = R[2]
            ee_local[t] = (ref.sites[t, c.ee_sites] - ref.qpos[t, :3]) @ facing_rotation(yaw).T
        return cls(ee_local, up, heading, com_vel)


def tracking_reward(env, rr: RewardRef, w: tuple[float, ...], k: int = 0) -> float:
    """DeepMimic / ScaDiver-style imitation reward in [0, 1] for fighter k of ``env`` at its step:
    pose (joint rotation error), joint velocity, end effectors relative to the pelvis in the facing
    frame (so a drifted but balanced body is not scored as lost: the reference's feet slide, the
    simulated ones stick), root (height, tilt, heading and a mild drift term), centre-of-mass velocity."""
    c = env._cache[k]
    d = env.data
    r = env.refs[k]
    t = env.t
    q = d.qpos[c.qpos]
    base = c.qpos.start
    qs = q[c.joint_q - base]
    qr = r.qpos[t][c.joint_q - base]
    ang = 2.0 * np.arccos(np.abs((qs * qr).sum(axis=1)).clip(0.0, 1.0))
    pose_err = float(ang @ ang)
    v = d.qvel[c.qvel][6:] - r.qvel[t, 6:]
    vel_err = float(v @ v)
    R = d.xmat[c.pelvis].reshape(3, 3)
    yaw = ground_yaw(R, c.lateral)
    ee = (d.site_xpos[c.sites[c.ee_sites]] - q[:3]) @ facing_rotation(yaw).T - rr.ee_local[t]
    ee_err = float((ee * ee).sum())
    dp = q[:3] - r.qpos[t, :3]
    dyaw = wrap_angle(yaw - rr.heading[t])
    root_err = 20.0 * dp[2] ** 2 + 5.0 * (1.0 - float(R[2] @ rr.up[t])) + 2.0 * (1.0 - np.cos(dyaw)) \
        + 2.0 * float(dp[:2] @ dp[:2])
    mujoco.mj_subtreeVel(env.model, d)
    dv = d.subtree_linvel[c.pelvis] - rr.com_vel[t]
    com_err = float(dv @ dv)
    return (w[0] * math.exp(-2.0 * pose_err) + w[1] * math.exp(-0.1 * vel_err) + w[2] * math.exp(-40.0 * ee_err)
            + w[3] * math.exp(-root_err) + w[4] * math.exp(-1.0 * com_err))
