"""Small rotation helpers on plain arrays.

Conventions used across the project:
- Quaternions are scalar-last (x, y, z, w), as scipy.spatial.transform.Rotation.
- Y is up. The ground plane is (x, z). A heading angle h (radians) is a rotation about +Y;
  a body whose local forward is +Z faces world direction (sin h, 0, cos h). Local +X is the
  body's left.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from scipy.spatial.transform import Rotation

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def euler_to_matrix(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles (degrees, shape (..., k)) in channel order, e.g. "ZYX" -> (..., 3, 3).

    The BVH rule: R = R_{order[0]} @ R_{order[1]} @ R_{order[2]} applied to column vectors.
    """
    a = np.radians(np.asarray(angles_deg, dtype=np.float64))
    shape = a.shape[:-1]
    out = np.broadcast_to(np.eye(3), shape + (3, 3)).copy()
    for k, ax in enumerate(order):
        c, s = np.cos(a[..., k]), np.sin(a[..., k])
        m = np.zeros(shape + (3, 3))
        i = _AXIS[ax]
        j, l = [(1, 2), (2, 0), (0, 1)][i]
        m[..., i, i] = 1.0
        m[..., j, j] = c
        m[..., l, l] = c
        m[..., j, l] = -s
        m[..., l, j] = s
        out = out @ m
    return out


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotation matrices -> (..., 4) quaternions (x, y, z, w), w >= 0."""
    shape = m.shape[:-2]
    q = Rotation.from_matrix(m.reshape(-1, 3, 3)).as_quat()
    q[q[:, 3] < 0] *= -1.0
    return q.reshape(shape + (4,))


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (x, y, z, w) -> (..., 3, 3)."""
    shape = q.shape[:-1]
    return Rotation.from_quat(q.reshape(-1, 4)).as_matrix().reshape(shape + (3, 3))


def yaw_matrix(heading: np.ndarray | float) -> np.ndarray:
    """Rotation about +Y by heading (radians): (..., 3, 3)."""
    h = np.asarray(heading, dtype=np.float64)
    c, s = np.cos(h), np.sin(h)
    m = np.zeros(h.shape + (3, 3))
    m[..., 0, 0] = c
    m[..., 0, 2] = s
    m[..., 1, 1] = 1.0
    m[..., 2, 0] = -s
    m[..., 2, 2] = c
    return m


def heading_of(forward: np.ndarray) -> np.ndarray:
    """Heading angle (radians) of a forward direction (..., 3) projected on the ground plane."""
    return np.arctan2(forward[..., 0], forward[..., 2])


def wrap_angle(a: np.ndarray | float) -> np.ndarray:
    """Wrap radians to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True, inline="always")
def wrap_angle_nb(a: float) -> float:
    """Wrap radians to [-pi, pi) inside numba kernels (floor form: a - 2 pi floor((a + pi) / 2 pi)).

    The last bit can differ from :func:`wrap_angle` (modulo form); each caller keeps the form its
    stored results were computed with."""
    return a - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))


def slerp_quats(q: np.ndarray, t_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Resample a (T, J, 4) quaternion track from times t_src to t_dst by spherical interpolation."""
    T, J, _ = q.shape
    t_dst = np.clip(t_dst, t_src[0], t_src[-1])
    idx = np.clip(np.searchsorted(t_src, t_dst, side="right") - 1, 0, T - 2) if T > 1 else np.zeros(len(t_dst), int)
    if T == 1:
        return np.repeat(q, len(t_dst), axis=0)
    u = ((t_dst - t_src[idx]) / (t_src[idx + 1] - t_src[idx]))[:, None, None]
    q0, q1 = q[idx], q[idx + 1].copy()
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    small = sin_t < 1e-6
    w0 = np.where(small, 1.0 - u, np.sin((1.0 - u) * theta) / np.where(small, 1.0, sin_t))
    w1 = np.where(small, u, np.sin(u * theta) / np.where(small, 1.0, sin_t))
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


# ----------------------------------------------------------------------------------------------
# scalar-first (w, x, y, z) quaternions, MuJoCo's order (the physics fighters, tracker.bouts)


def yaw_quat_wxyz(h: float) -> np.ndarray:
    """Rotation by h about +Z as a (w, x, y, z) quaternion (MuJoCo's z-up world)."""
    return np.array([np.cos(h / 2), 0.0, 0.0, np.sin(h / 2)])


def quat_mul_wxyz(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a (4,) times b (..., 4), quaternions (w, x, y, z)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b[..., 0], b[..., 1], b[..., 2], b[..., 3]
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], axis=-1)


def slerp_wxyz(q_to: np.ndarray, q_from: np.ndarray, w_from: float) -> np.ndarray:
    """Per-row slerp of unit quaternions (N, 4): weight w_from on q_from (sign-aligned)."""
    dot = (q_to * q_from).sum(-1)
    q_from = np.where(dot[:, None] < 0, -q_from, q_from)
    dot = np.abs(dot).clip(-1.0, 1.0)
    th = np.arccos(dot)
    s = np.sin(th)
    small = s < 1e-6
    a = np.where(small, 1.0 - w_from, np.sin((1.0 - w_from) * th) / np.where(small, 1.0, s))
    b = np.where(small, w_from, np.sin(w_from * th) / np.where(small, 1.0, s))
    q = a[:, None] * q_to + b[:, None] * q_from
    return q / np.linalg.norm(q, axis=1, keepdims=True)
