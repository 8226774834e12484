"""Per-frame kinematic features of a clip used by contacts, segmentation and classification.

All positions in metres (Y up), speeds in metres per second, angles in radians; time in frames
of the clip's own rate, smoothed over about 0.02 s before differentiating.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from motion_graph.motion import Motion
from motion_graph.rotations import wrap_angle
from motion_graph.semantics import require_parts, resolve_parts

SMOOTH_S = 0.02


@dataclass
class ClipFeatures:
    """Smoothed joint positions and derived signals of one clip.

    Attributes:
        fps: frame rate.
        positions: (T, J, 3) smoothed global joint positions, metres, floor at y = 0.
        parts: semantic part -> joint index.
        heading: (T,) body heading from the hip line (radians about +Y; 0 faces +Z), unwrapped.
        facing: (T,) facing of the head (radians, unwrapped, smoothed over ~0.1 s): the head's
            forward axis, calibrated per clip as the head-local direction that best matches the
            hip heading on average (skeletons differ in their rest orientation).
        floor_y: the floor height that was subtracted, metres (in the file's frame).
        foot_height: (T, 2) lowest point of the left/right foot above the floor, metres.
        foot_speed: (T, 2) horizontal speed of the left/right foot, m/s.
        hand_speed: (T, 2) speed of the left/right fist, m/s.
        pelvis_speed: (T,) horizontal pelvis speed, m/s.
        reach: (T, 2) fist distance from its shoulder divided by the arm's rest length.
    """

    fps: float
    positions: np.ndarray
    parts: dict[str, int]
    heading: np.ndarray
    floor_y: float
    foot_height: np.ndarray
    foot_speed: np.ndarray
    hand_speed: np.ndarray
    pelvis_speed: np.ndarray
    reach: np.ndarray
    arm_length: np.ndarray
    facing: np.ndarray

    @property
    def n_frames(self) -> int:
        return self.positions.shape[0]


def _speed(x: np.ndarray, fps: float) -> np.ndarray:
    v = np.gradient(x, axis=0) * fps
    return np.linalg.norm(v, axis=-1)


def hip_heading(positions: np.ndarray, parts: dict[str, int]) -> np.ndarray:
    """Facing angle per frame from the hip line (left hip minus right hip, crossed with up)."""
    left = positions[..., parts["l_hip"], :] - positions[..., parts["r_hip"], :]
    # forward = left x up, with up = +Y: (lx, ly, lz) x (0, 1, 0) = (-lz, 0, lx)
    fwd_x, fwd_z = -left[..., 2], left[..., 0]
    return np.arctan2(fwd_x, fwd_z)


def foot_points(skeleton, parts: dict[str, int]) -> list[list[int]]:
    """Joint indices that make up each foot's sole (ankle, toe, toe tip when present)."""
    out = []
    for side in "lr":
        pts = [parts[f"{side}_ankle"], parts[f"{side}_toe"]]
        pts += [k for k in skeleton.children(parts[f"{side}_toe"]) if skeleton.is_end_site[k]]
        out.append(pts)
    return out


def clip_features(motion: Motion, overrides: dict[str, str] | None = None, floor_y: float | None = None) -> ClipFeatures:
    """Compute smoothed positions and per-frame signals for a clip."""
    parts = resolve_parts(motion.skeleton, overrides)
    require_parts(motion.skeleton, parts, motion.source)
    fps = motion.fps
    P = motion.positions()
    sigma = max(SMOOTH_S * fps / 2.0, 0.5)
    P = gaussian_filter1d(P, sigma, axis=0, mode="nearest")
    feet = foot_points(motion.skeleton, parts)
    # Each sole point (ankle, ball, toe tip) sits at its own height above the floor when planted
    # (the ankle ~8 cm, the ball joint a few cm): measure each against its own low level.
    lows = []
    for pts in feet:
        h = P[:, pts, 1]
        lows.append((h - np.percentile(h, 3, axis=0)).min(axis=1))
    low = np.stack(lows, axis=1)
    ground = np.percentile(P[:, [p for pts in feet for p in pts], 1].min(axis=1), 3)
    if floor_y is None:
        floor_y = float(ground)
    P = P.copy()
    P[..., 1] -= floor_y
    foot_speed = np.stack([_speed(P[:, pts[1], [0, 2]], fps) for pts in feet], axis=1)
    hand_speed = np.stack([_speed(P[:, parts[f"{s}_fist"]], fps) for s in "lr"], axis=1)
    pelvis_speed = _speed(P[:, parts["pelvis"], [0, 2]], fps)
    sk = motion.skeleton
    arm = np.array([sk.chain_length(parts[f"{s}_shoulder"], parts[f"{s}_fist"]) for s in "lr"])
    reach = np.stack([np.linalg.norm(P[:, parts[f"{s}_fist"]] - P[:, parts[f"{s}_shoulder"]], axis=-1) for s in "lr"],
                     axis=1) / arm
    heading = np.unwrap(hip_heading(P, parts))
    facing = head_facing(motion, parts, heading)
    return ClipFeatures(fps, P, parts, heading, floor_y, low, foot_speed, hand_speed, pelvis_speed, reach, arm, facing)


FACING_SMOOTH_S = 0.10


def head_facing(motion: Motion, parts: dict[str, int], hip_heading_rad: np.ndarray) -> np.ndarray:
    """Unwrapped facing angle of the head per frame (radians about +Y).

    The head's forward axis in its own frame is the normalised mean over the clip of the hip
    forward direction expressed in the head frame (so it is found for any rest orientation).
    """
    R, _ = motion.global_transforms()
    Rh = R[:, parts["head"]]
    fwd = np.stack([np.sin(hip_heading_rad), np.zeros_like(hip_heading_rad), np.cos(hip_heading_rad)], axis=1)
    local = np.einsum("tba,tb->ta", Rh, fwd).mean(axis=0)
    local /= max(np.linalg.norm(local), 1e-9)
    world = Rh @ local
    ang = np.unwrap(np.arctan2(world[:, 0], world[:, 2]))
    sigma = max(FACING_SMOOTH_S * motion.fps / 2.0, 0.5)
    return gaussian_filter1d(ang, sigma, mode="nearest")


def to_local(points: np.ndarray, origin: np.ndarray, heading: float) -> np.ndarray:
    """Express world points (..., 3) in a frame at origin (ground projection used) facing `heading`.

    Local axes: +Z forward, +X left, +Y up.
    """
    c, s = np.cos(heading), np.sin(heading)
    d = points - np.array([origin[0], 0.0, origin[2]])
    x = c * d[..., 0] - s * d[..., 2]
    z = s * d[..., 0] + c * d[..., 2]
    return np.stack([x, d[..., 1], z], axis=-1)


def heading_change(h: np.ndarray) -> float:
    return float(wrap_angle(h[-1] - h[0]))
