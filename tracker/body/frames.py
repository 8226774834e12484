"""MuJoCo z-up frame helpers of the fighters' bodies (world axes: x, y on the ground, z up).

- ``ground_yaw(R, direction)``: the yaw (about world z) of a body-fixed direction of a body whose
  world orientation is the matrix R, projected on the ground (the fighters' facing uses the hip
  line, right to left hip: TrackingEnv's ``lateral``);
- ``ground_yaws(q_wxyz, direction)``: the same for rows of MuJoCo quaternions (w, x, y, z);
- ``quat_matrix(q_wxyz)``: a MuJoCo quaternion as a 3 x 3 matrix (mujoco.mju_quat2Mat);
- ``facing_rotation(yaw)``: world -> facing frame (x along the facing direction's yaw);
- ``z_rotation(h)``: the rotation by h about +z (a mocap heading h is a MuJoCo yaw of +h).

Pure-numpy quaternion algebra (products, slerp, a yaw as a quaternion) lives in motion_graph.rotations.
"""
from __future__ import annotations

import mujoco
import numpy as np


def ground_yaw(R: np.ndarray, lateral: np.ndarray) -> float:
    """Yaw (about world z) of a body-fixed direction (the hip line) projected on the ground."""
    w = R @ lateral
    return float(np.arctan2(w[1], w[0]))


def ground_yaws(q_wxyz: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """Yaw of the body-fixed ``lateral`` direction for each quaternion (w, x, y, z)."""
    w, x, y, z = q_wxyz[:, 0], q_wxyz[:, 1], q_wxyz[:, 2], q_wxyz[:, 3]
    lx, ly, lz = lateral
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    return np.arctan2(r10 * lx + r11 * ly + r12 * lz, r00 * lx + r01 * ly + r02 * lz)


def quat_matrix(q_wxyz: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix of a MuJoCo quaternion (w, x, y, z)."""
    m = np.empty(9)
    mujoco.mju_quat2Mat(m, q_wxyz)
    return m.reshape(3, 3)


def facing_rotation(yaw: float) -> np.ndarray:
    """World -> facing frame rotation for a facing yaw (rad)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array([[cy, sy, 0.0], [-sy, cy, 0.0], [0.0, 0.0, 1.0]])


def z_rotation(h: float) -> np.ndarray:
    """Rotation by h about MuJoCo's +Z (a mocap heading h is a MuJoCo yaw of +h)."""
    c, s = np.cos(h), np.sin(h)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
