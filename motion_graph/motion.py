"""The one in-memory motion type and vectorised forward kinematics."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion_graph.rotations import quat_to_matrix, slerp_quats
from motion_graph.skeleton import Skeleton


@dataclass
class Motion:
    """A single-actor motion clip.

    Attributes:
        skeleton: the joint tree (offsets in metres).
        rotations: (T, J, 4) local joint rotations as quaternions (x, y, z, w); identity for end sites.
        root_positions: (T, 3) root joint translation in metres, Y up.
        fps: frames per second.
        local_translations: optional (T, J, 3) per-frame local translations (metres) for skeletons
            whose files animate non-root joint positions (e.g. Bandai Namco's Hips); when given it
            overrides ``skeleton.offsets`` (row 0 equals ``root_positions``).
        source: where the clip came from (file path), for messages and provenance.
    """

    skeleton: Skeleton
    rotations: np.ndarray
    root_positions: np.ndarray
    fps: float
    local_translations: np.ndarray | None = None
    source: str = ""

    @property
    def n_frames(self) -> int:
        return int(self.rotations.shape[0])

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame."""
        return (self.n_frames - 1) / self.fps

    def translations(self) -> np.ndarray:
        """(T, J, 3) local translation of every joint, metres."""
        if self.local_translations is not None:
            t = self.local_translations.copy()
        else:
            t = np.broadcast_to(self.skeleton.offsets, (self.n_frames,) + self.skeleton.offsets.shape).copy()
        t[:, 0] = self.root_positions
        return t

    def global_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """Forward kinematics: global rotations (T, J, 3, 3) and positions (T, J, 3) in metres."""
        return forward_kinematics(self.skeleton.parents, quat_to_matrix(self.rotations), self.translations())

    def positions(self) -> np.ndarray:
        """(T, J, 3) global joint positions in metres."""
        return self.global_transforms()[1]

    def slice(self, start: int, stop: int) -> "Motion":
        """Frames [start, stop) as a new Motion."""
        lt = None if self.local_translations is None else self.local_translations[start:stop].copy()
        return Motion(self.skeleton, self.rotations[start:stop].copy(), self.root_positions[start:stop].copy(),
                      self.fps, lt, self.source)

    def resample(self, fps: float) -> "Motion":
        """Resample to a new frame rate: slerp for rotations, linear for translations."""
        if abs(fps - self.fps) < 1e-9:
            return self
        t_src = np.arange(self.n_frames) / self.fps
        n_dst = int(np.floor(self.duration * fps + 1e-6)) + 1
        t_dst = np.arange(n_dst) / fps
        rot = slerp_quats(self.rotations, t_src, t_dst)
        root = np.stack([np.interp(t_dst, t_src, self.root_positions[:, k]) for k in range(3)], axis=-1)
        lt = None
        if self.local_translations is not None:
            flat = self.local_translations.reshape(self.n_frames, -1)
            lt = np.stack([np.interp(t_dst, t_src, flat[:, k]) for k in range(flat.shape[1])], axis=-1)
            lt = lt.reshape(n_dst, -1, 3)
        return Motion(self.skeleton, rot, root, float(fps), lt, self.source)


def forward_kinematics(parents: np.ndarray, local_rot: np.ndarray, local_trans: np.ndarray
                       ) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised FK over frames.

    Args:
        parents: (J,) parent indices, parents before children.
        local_rot: (T, J, 3, 3) local rotation matrices.
        local_trans: (T, J, 3) local translations (metres).
    Returns:
        global rotations (T, J, 3, 3) and global positions (T, J, 3).
    """
    T, J = local_rot.shape[:2]
    g_rot = np.empty_like(local_rot)
    g_pos = np.empty((T, J, 3))
    for j in range(J):
        p = parents[j]
        if p < 0:
            g_rot[:, j] = local_rot[:, j]
            g_pos[:, j] = local_trans[:, j]
        else:
            g_rot[:, j] = g_rot[:, p] @ local_rot[:, j]
            g_pos[:, j] = g_pos[:, p] + np.einsum("tab,tb->ta", g_rot[:, p], local_trans[:, j])
    return g_rot, g_pos
