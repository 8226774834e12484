"""FighterSpec: what the MJCF builder needs to know about a skeleton, from the skeleton alone or
calibrated on motions of that skeleton.

The spec decides, per skeleton joint:
- whether it gets degrees of freedom (``dof``) or is welded into its parent body, and why;
- its rest rotation (the body's fixed orientation in the model; the joint's qpos is the rotation
  relative to it, so PD targets in exponential coordinates stay far from the +-pi wrap);
- a ball-joint range (cone half-angle, radians);
and, per foot, how the sole sits in the foot frame (up direction, ankle height), so contact
spheres can be put under the heel and the ball of the foot.

Conventions: skeleton frame, Y up, metres, quaternions (x, y, z, w) as in motion_graph.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from motion_graph.motion import Motion, forward_kinematics
from motion_graph.semantics import REQUIRED_PARTS, resolve_parts
from motion_graph.skeleton import Skeleton

#: A welded joint whose rotation in the calibration motions never leaves its mean by more than this.
STATIC_DEG = 0.5
#: Margin added to the largest rotation seen in the data when setting a ball joint's range.
RANGE_MARGIN_DEG = 20.0
#: Range used when no motion is given.
DEFAULT_RANGE_DEG = 150.0
#: Ankle height above the sole when no motion is given, as a share of the body height.
DEFAULT_ANKLE_HEIGHT_SHARE = 0.045


@dataclass(frozen=True)
class FootCalibration:
    """Sole geometry of one foot in the ankle body's rest frame (skeleton axes, metres).

    Attributes:
        up: (3,) unit vector, world up seen from the ankle frame when the foot is flat on the floor.
        ankle_height_m: height of the ankle joint above the sole when the foot is flat.
    """

    up: np.ndarray
    ankle_height_m: float


@dataclass(frozen=True)
class FighterSpec:
    """Skeleton-derived description of one fighter model (see module doc).

    Attributes:
        skeleton: the joint tree (metres).
        parts: semantic part -> joint index (motion_graph.semantics.resolve_parts).
        pelvis: joint index of the free-floating body; joints above it are virtual (their motion
            is folded into the pelvis's world pose).
        rest: (J, 4) rest rotation per joint (x, y, z, w).
        dof: (J,) True where the joint is a ball joint (or three hinges) in the model.
        forced_weld: (J,) True where the joint is welded although it may move (fingers, thumbs):
            positions of its descendants are not reproduced exactly.
        range_rad: (J,) ball-joint range (largest rotation away from rest), radians.
        feet: {"l": FootCalibration, "r": FootCalibration}.
        height_m: standing height used to scale radii.
        mass_kg: total body mass.
    """

    skeleton: Skeleton
    parts: dict[str, int]
    pelvis: int
    rest: np.ndarray
    dof: np.ndarray
    forced_weld: np.ndarray
    range_rad: np.ndarray
    feet: dict[str, FootCalibration]
    height_m: float
    mass_kg: float = 70.0
    calibrated_on: tuple[str, ...] = field(default=())

    @property
    def subtree(self) -> np.ndarray:
        """(J,) True for the pelvis and every joint below it (the joints the model contains)."""
        sk = self.skeleton
        inside = np.zeros(sk.n_joints, bool)
        inside[self.pelvis] = True
        for j in range(self.pelvis + 1, sk.n_joints):
            p = sk.parents[j]
            if p >= 0 and inside[p]:
                inside[j] = True
        return inside

    def tracked(self) -> np.ndarray:
        """(J,) True for joints whose position the model reproduces exactly from qpos: inside the
        model and with no forced-welded strict ancestor."""
        sk = self.skeleton
        inside = self.subtree
        out = inside.copy()
        for j in range(sk.n_joints):
            if not inside[j]:
                continue
            p = sk.parents[j]
            if j != self.pelvis and p >= 0 and (self.forced_weld[p] or not out[p]):
                out[j] = False
        return out


def _rot_channels(ch: tuple[str, ...]) -> bool:
    return any(c.lower() in ("xrotation", "yrotation", "zrotation", "rx", "ry", "rz") for c in ch)


def _descendants(sk: Skeleton, j: int) -> list[int]:
    out, stack = [], list(sk.children(j))
    while stack:
        k = stack.pop()
        out.append(k)
        stack.extend(sk.children(k))
    return out


def _mean_rotation(q: np.ndarray) -> np.ndarray:
    """Chordal mean of (T, 4) quaternions (x, y, z, w)."""
    return Rotation.from_quat(q).mean().as_quat()


def skeleton_height(sk: Skeleton, parts: dict[str, int], rest: np.ndarray | None = None) -> float:
    """Standing height estimate in metres: leg length + spine + neck/head chain (rest-pose free)."""
    h = 0.0
    if "l_ankle" in parts and "l_hip" in parts:
        h += sk.chain_length(parts["l_hip"], parts["l_ankle"])
    if "head" in parts:
        top = parts.get("head_top", parts["head"])
        h += sk.chain_length(parts["pelvis"], top)
        if sk.chain_length(parts["head"], top) < 0.04:
            h += 0.12  # no head-top marker: add the skull
    h += 0.16  # hip joint below pelvis, ankle above sole, skull above head_top (rough)
    return float(np.clip(h, 1.2, 2.2))


def fighter_spec(skeleton: Skeleton, motions: list[Motion] | tuple[Motion, ...] = (),
                 mass_kg: float = 70.0, parts: dict[str, int] | None = None) -> FighterSpec:
    """Build the spec for a skeleton, calibrated on motions of it when given.

    With motions: rest rotation = mean local rotation; joints whose rotation never moves more than
    STATIC_DEG are welded; ranges = largest deviation from rest + RANGE_MARGIN_DEG; foot sole
    calibrated on frames where the foot is flat. Without motions: identity rest, DOF for every joint
    with rotation channels, default ranges and foot heights.
    """
    sk = skeleton
    J = sk.n_joints
    parts = dict(parts) if parts is not None else resolve_parts(sk)
    missing = [p for p in REQUIRED_PARTS if p not in parts]
    if missing:
        raise ValueError(f"fighter_spec: skeleton lacks semantic parts {missing}; give a joint-map override")
    pelvis = parts["pelvis"]
    rest = np.tile([0.0, 0.0, 0.0, 1.0], (J, 1))
    has_rot = np.array([_rot_channels(c) for c in sk.channels]) & ~np.asarray(sk.is_end_site, bool)
    static = ~has_rot
    range_rad = np.full(J, np.radians(DEFAULT_RANGE_DEG))
    motions = [m for m in motions if m.n_frames > 0]
    if motions:
        for m in motions:
            if m.skeleton.n_joints != J:
                raise ValueError("fighter_spec: calibration motion has another skeleton")
        rot = np.concatenate([m.rotations for m in motions], axis=0)
        step = max(1, rot.shape[0] // 4000)
        rot = rot[::step]
        for j in range(J):
            if sk.is_end_site[j]:
                continue
            rest[j] = _mean_rotation(rot[:, j])
            dev = np.linalg.norm((Rotation.from_quat(rest[j]).inv() * Rotation.from_quat(rot[:, j])).as_rotvec(), axis=1)
            dmax = float(np.degrees(dev.max()))
            if dmax <= STATIC_DEG:
                static[j] = True
            range_rad[j] = np.radians(min(179.0, dmax + RANGE_MARGIN_DEG))
    # Everything below the wrist except the fist joint (and the fist's own end) is welded.
    forced = np.zeros(J, bool)
    for side in "lr":
        w = parts.get(f"{side}_wrist")
        f = parts.get(f"{side}_fist")
        if w is None:
            continue
        keep = set()
        if f is not None and f != w:
            k = f
            while k != w and k >= 0:
                keep.add(k)
                k = int(sk.parents[k])
        for d in _descendants(sk, w):
            if d not in keep:
                forced[d] = True
    dof = has_rot & ~static & ~forced
    inside = np.zeros(J, bool)
    inside[pelvis] = True
    for j in range(pelvis + 1, J):
        if sk.parents[j] >= 0 and inside[sk.parents[j]]:
            inside[j] = True
    dof &= inside
    dof[pelvis] = False  # the pelvis is the free joint
    forced &= ~static  # a static joint welded below the wrist is exact
    height = skeleton_height(sk, parts)
    feet = {side: _foot_calibration(sk, parts, rest, side, height, motions) for side in "lr"}
    # Symmetric body: one ankle height for both feet (the lower estimate: a boxer on his toes
    # all take long leaves one foot's heel rarely down).
    h = min(feet["l"].ankle_height_m, feet["r"].ankle_height_m)
    feet = {s: FootCalibration(c.up, h) for s, c in feet.items()}
    return FighterSpec(sk, parts, pelvis, rest, dof, forced & inside, range_rad, feet, height, mass_kg,
                       tuple(m.source for m in motions))


def _foot_calibration(sk: Skeleton, parts: dict[str, int], rest: np.ndarray, side: str, height: float,
                      motions: list[Motion]) -> FootCalibration:
    a = parts[f"{side}_ankle"]
    t = parts[f"{side}_toe"]
    default_h = DEFAULT_ANKLE_HEIGHT_SHARE * height
    ups, hs = [], []
    for m in motions:
        step = max(1, int(round(m.fps / 30.0)))
        g_rot, g_pos = _fk_sub(m, step)
        ay, ty = g_pos[:, a, 1], g_pos[:, t, 1]
        flat = (ay < np.percentile(ay, 5) + 0.01) & (ty < np.percentile(ty, 5) + 0.01)
        if flat.sum() < 3:
            continue
        ups.append(np.einsum("tba,b->ta", g_rot[flat, a], np.array([0.0, 1.0, 0.0])))
        hs.append(ay[flat])
    if ups:
        u = np.concatenate(ups).mean(axis=0)
        u /= np.linalg.norm(u)
        h = float(np.clip(np.median(np.concatenate(hs)), 0.5 * default_h, 2.0 * default_h))
        return FootCalibration(u, h)
    # No data: world up through the rest pose (pelvis upright, identity).
    R = np.eye(3)
    chain = sk.chain(a)
    for j in chain[chain.index(parts["pelvis"]) + 1:]:
        R = R @ Rotation.from_quat(rest[j]).as_matrix()
    return FootCalibration(R.T @ np.array([0.0, 1.0, 0.0]), default_h)


def _fk_sub(m: Motion, step: int) -> tuple[np.ndarray, np.ndarray]:
    from motion_graph.rotations import quat_to_matrix
    rot = quat_to_matrix(m.rotations[::step])
    return forward_kinematics(m.skeleton.parents, rot, m.translations()[::step])
