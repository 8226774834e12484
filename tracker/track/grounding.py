"""Grounded reference: every supported frame of a reference has a foot on the floor.

Motion capture floats once it is put on the model: the performer's feet and the model's collision
soles differ, so after a constant lift the lowest foot point of a frame sits centimetres above the
floor in most frames while the motion's centre of mass is not in free fall (the performer was
standing on something). Tracked in physics, such a reference makes the body hang from whatever
holds the pelvis at the reference height, or drop.

``ground_heights`` moves the root vertically, frame by frame: in every frame the motion's centre
of mass says is supported (its vertical acceleration above ``flight_acc`` m/s^2 downward), the
lowest point of the lower foot goes to the floor (within ``tolerance_m``); frames of flight keep
their height relative to the neighbouring supported frames (linear in time). The offset is
smoothed over ``smooth_frames`` and re-clamped to the tolerance. Joint rotations are unchanged, so
the other foot keeps its height above the supporting one.

``floor_report`` gives the statistics before and after: the lower foot's height (median and p90,
cm), the share of frames with both feet more than 1.5 cm up, and the penetration (p95, max, cm).
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from tracker.body.humanoid import BodyMap, FighterScene


@dataclass(frozen=True)
class GroundConfig:
    """Attributes:
        tolerance_m: in supported frames the lower foot's lowest point ends within
            [-tolerance_m / 2, tolerance_m] of the floor.
        flight_acc: frames whose centre of mass accelerates down faster than this (m/s^2) are flight
            (free fall is 9.81).
        smooth_frames: width of the moving average of the height offset (frames, odd).
        com_smooth_frames: width of the moving average of the centre of mass's height before it is
            differentiated twice (mocap noise at 30 fps would otherwise look like flight).
    """

    tolerance_m: float = 0.01
    flight_acc: float = 8.0
    smooth_frames: int = 3
    com_smooth_frames: int = 5


def lowest_point(m: mujoco.MjModel, d: mujoco.MjData, geoms: np.ndarray) -> np.ndarray:
    """World z of the lowest point of each geom (spheres, capsules, boxes; others by bounding sphere)."""
    geoms = np.asarray(geoms, dtype=int)
    z = d.geom_xpos[geoms, 2]
    size = m.geom_size[geoms]
    typ = m.geom_type[geoms]
    Rz = np.abs(d.geom_xmat[geoms, 6:9])         # world-z row of each geom's rotation
    out = z - m.geom_rbound[geoms]
    sph = typ == mujoco.mjtGeom.mjGEOM_SPHERE
    out[sph] = z[sph] - size[sph, 0]
    cap = typ == mujoco.mjtGeom.mjGEOM_CAPSULE
    out[cap] = z[cap] - Rz[cap, 2] * size[cap, 1] - size[cap, 0]
    box = typ == mujoco.mjtGeom.mjGEOM_BOX
    out[box] = z[box] - (Rz[box] * size[box]).sum(axis=1)
    return out


def foot_heights(scene: FighterScene, fighter: BodyMap, qpos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 2) lowest point (m, MuJoCo z) of the left and right foot's collision geoms per frame, and
    (T, 3) the centre of mass."""
    m = scene.model
    d = mujoco.MjData(m)
    sides = [np.asarray(fighter.geom_label.get(lab, []), int) for lab in ("l_foot", "r_foot")]
    T = qpos.shape[0]
    low = np.full((T, 2), np.inf)
    com = np.zeros((T, 3))
    for t in range(T):
        d.qpos[fighter.qpos_slice] = qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        com[t] = d.subtree_com[fighter.pelvis_body]
        for s, g in enumerate(sides):
            if len(g):
                low[t, s] = lowest_point(m, d, g).min()
    return low, com


def ground_heights(low: np.ndarray, com: np.ndarray, fps: float, cfg: GroundConfig = GroundConfig()) -> np.ndarray:
    """(T,) vertical offsets (m) that ground the reference (module docstring), from the per-frame
    foot heights ``low`` (T, 2) and centre of mass ``com`` (T, 3)."""
    T = low.shape[0]
    if T == 0:
        return np.zeros(0)
    lower = low.min(axis=1)
    if T >= 3:
        z = com[:, 2]
        kz = max(1, int(cfg.com_smooth_frames) | 1)
        if kz > 1 and T >= kz:
            z = np.convolve(np.pad(z, kz // 2, mode="edge"), np.ones(kz) / kz, mode="valid")
        acc = np.gradient(np.gradient(z, 1.0 / fps), 1.0 / fps)
    else:
        acc = np.zeros(T)
    supported = acc > -cfg.flight_acc
    if not supported.any():
        supported[:] = True
    t = np.arange(T)
    want = -lower
    off = np.interp(t, t[supported], want[supported])
    k = max(1, int(cfg.smooth_frames) | 1)
    if k > 1 and T >= k:
        pad = np.pad(off, k // 2, mode="edge")
        off = np.convolve(pad, np.ones(k) / k, mode="valid")
    # re-clamp the supported frames to the tolerance band
    lo = want - cfg.tolerance_m * 0.5
    hi = want + cfg.tolerance_m
    off = np.where(supported, np.clip(off, lo, hi), off)
    return off


def floor_report(low: np.ndarray) -> dict:
    """Statistics of a reference's foot heights (cm): the lower foot's height median / p90, the share
    of frames with both feet more than 1.5 cm up, the penetration p95 / max."""
    if low.size == 0:
        return {"lower_foot_median_cm": 0.0, "lower_foot_p90_cm": 0.0, "both_up_share": 0.0,
                "penetration_p95_cm": 0.0, "penetration_max_cm": 0.0}
    lower = low.min(axis=1)
    pen = np.maximum(-low.min(axis=1), 0.0)
    return {"lower_foot_median_cm": float(100 * np.median(lower)), "lower_foot_p90_cm": float(100 * np.percentile(lower, 90)),
            "both_up_share": float(np.mean((low > 0.015).all(axis=1))),
            "penetration_p95_cm": float(100 * np.percentile(pen, 95)), "penetration_max_cm": float(100 * pen.max())}
