"""Retargeting: map motions of several performers and skeletons onto one body.

Joints are paired through the semantic part map (motion_graph.semantics), then by normalised
joint name. Every paired joint's world rotation is carried over after the rest-pose difference is
removed: ``G_target = G_source @ A``, where the rest alignment A takes the target joint's rest
segment (the direction from the joint to the next body part) onto the source's by the shortest arc
in the body's rest frame (left, up, forward from the hip line), so both segments point the same way
in the world in every frame. Target joints without a partner keep the identity local rotation (they follow
their parent). Joints the target's own take never moves (held joints: the CMU hip joints and
clavicles of subject 13, which its ASF gives no degrees of freedom) keep that take's rotation, and
their children keep their world rotations, so every library on the target body animates the same
joints as the target performer and its physics body has the same actuators. The pelvis path is scaled by the leg-length ratio (hip to ankle, rest pose), the
frame rate resampled to the target's, and a per-frame vertical shift of the root keeps the feet on
the floor: the lowest sole point's clearance above the floor (measured against the foot's
flat-footed rest geometry) equals the source's, scaled by the leg ratio.

All lengths are metres, Y up, rotations (x, y, z, w) quaternions as in motion_graph.motion.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_graph.errors import MocapFormatError, shorten
from motion_graph.features import foot_points
from motion_graph.io import find_mocap_files, load_motion
from motion_graph.motion import Motion, forward_kinematics
from motion_graph.rotations import matrix_to_quat, quat_to_matrix
from motion_graph.semantics import JOINT_LIST_CHARS, REQUIRED_PARTS, normalise, resolve_parts
from motion_graph.skeleton import Skeleton

#: Parts both skeletons must have for a retarget (the pipeline's parts plus elbows, wrists, knees).
ESSENTIAL_PARTS = REQUIRED_PARTS + ("l_elbow", "r_elbow", "l_wrist", "r_wrist", "l_knee", "r_knee")

#: Segment of each part: the rest direction from the part's joint to the first of these parts
#: that is a distinct point in both skeletons ("toe_end": the toe's end site).
_SEGMENT_TO: dict[str, tuple[str, ...]] = {
    "pelvis": ("chest", "neck", "head"), "belly": ("chest", "neck", "head"), "chest": ("neck", "head"),
    "neck": ("head", "head_top"), "head": ("head_top",),
    "shoulder": ("elbow",), "elbow": ("wrist",), "wrist": ("fist",),
    "hip": ("knee",), "knee": ("ankle",), "ankle": ("toe",), "toe": ("toe_end",),
}
#: Shorter rest vectors than this (metres) do not define a direction.
_MIN_SEGMENT_M = 1e-3
#: A joint is held when every frame of the target's take gives it this same local rotation
#: (largest component difference of the unit quaternions, sign-aligned).
HELD_ATOL = 1e-9
#: Floor height estimate: this percentile of the lowest sole point over the clip (as features.py).
_FLOOR_PERCENTILE = 3.0


@dataclass(frozen=True)
class RetargetTarget:
    """The body motions are mapped onto.

    Attributes:
        skeleton: target joint tree (offsets in metres).
        fps: target frame rate, frames per second.
        part_overrides: joint-map override for the target (``{"part": "JointName"}``), or None.
        source: where the skeleton came from (file path), for provenance.
        held: (joint index, (x, y, z, w) local rotation) of every joint the target's take never
            moves (end sites and the root excluded); retargeted takes keep them at that rotation.
    """

    skeleton: Skeleton
    fps: float
    part_overrides: dict | None = None
    source: str = ""
    held: tuple[tuple[int, tuple[float, float, float, float]], ...] = ()

    @classmethod
    def from_motion(cls, motion: Motion, part_overrides: dict | None = None) -> "RetargetTarget":
        """The skeleton, frame rate and held joints of a loaded take."""
        return cls(motion.skeleton, float(motion.fps), part_overrides, motion.source, held_joints(motion))

    @property
    def held_names(self) -> tuple[str, ...]:
        """Names of the held joints."""
        return tuple(self.skeleton.names[j] for j, _ in self.held)


def held_joints(motion: Motion) -> tuple[tuple[int, tuple[float, float, float, float]], ...]:
    """(joint, local rotation) of every joint (root and end sites excluded) with the same local
    rotation in every frame of ``motion`` (within HELD_ATOL)."""
    q = np.asarray(motion.rotations, dtype=float)
    if q.shape[0] == 0:
        return ()
    sk = motion.skeleton
    q0 = q[0]
    sign = np.where(np.sum(q * q0[None], axis=-1, keepdims=True) < 0.0, -1.0, 1.0)
    still = (np.abs(q * sign - q0[None]).max(axis=0) <= HELD_ATOL).all(axis=-1)
    return tuple((j, tuple(float(v) for v in q0[j])) for j in range(1, sk.n_joints)
                 if still[j] and not sk.is_end_site[j] and sk.parents[j] >= 0)


def load_target(path: str | os.PathLike, part_overrides: dict | None = None,
                fps: float | None = None) -> RetargetTarget:
    """The target body of a mocap file (.bvh, or .amc with its .asf): its skeleton, frame rate and held joints."""
    return RetargetTarget.from_motion(load_motion(path, fps=fps), part_overrides)


@dataclass(frozen=True)
class RetargetMap:
    """How one source skeleton maps onto a target skeleton.

    Attributes (J target joints):
        source, target: the two skeletons.
        source_joint: (J,) source joint paired with each target joint, -1 when unpaired.
        how: (J,) ``"part:<name>"``, ``"name"`` or ``""`` (unpaired).
        align: (J, 3, 3) rest alignment: target world rotation = source world rotation @ align.
        leg_scale: target leg length / source leg length (hip to ankle, rest pose).
        source_parts, target_parts: semantic part -> joint index of each skeleton.
        source_soles, target_soles: joint indices of all sole points (both feet).
        source_clearance, target_clearance: (P,) height of each sole point above its foot's lowest
            sole point in the rest pose, metres (the flat-footed planted height).
    """

    source: Skeleton
    target: Skeleton
    source_joint: np.ndarray
    how: tuple[str, ...]
    align: np.ndarray
    leg_scale: float
    source_parts: dict[str, int]
    target_parts: dict[str, int]
    source_soles: np.ndarray
    target_soles: np.ndarray
    source_clearance: np.ndarray
    target_clearance: np.ndarray

    @property
    def unmatched(self) -> tuple[str, ...]:
        """Target joints (end sites excluded) without a source partner: they keep the identity."""
        return tuple(n for n, s, e in zip(self.target.names, self.source_joint, self.target.is_end_site)
                     if s < 0 and not e)


def rest_positions(skeleton: Skeleton) -> np.ndarray:
    """(J, 3) joint positions in the rest pose (every local rotation the identity), metres."""
    p = np.zeros((skeleton.n_joints, 3))
    for j in range(1, skeleton.n_joints):
        p[j] = p[skeleton.parents[j]] + skeleton.offsets[j]
    return p


def _body_axes(rest: np.ndarray, parts: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """Rest-pose lateral (+left) and forward unit axes on the ground plane (forward = left x up)."""
    lat = rest[parts["l_hip"]] - rest[parts["r_hip"]]
    lat[1] = 0.0
    n = np.linalg.norm(lat)
    if n < _MIN_SEGMENT_M:
        lat = rest[parts["l_shoulder"]] - rest[parts["r_shoulder"]]
        lat[1] = 0.0
        n = np.linalg.norm(lat)
    lat = lat / n if n >= _MIN_SEGMENT_M else np.array([1.0, 0.0, 0.0])
    return lat, np.cross(lat, [0.0, 1.0, 0.0])


def _arc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The shortest-arc rotation (3, 3) taking unit vector a onto unit vector b."""
    v = np.cross(a, b)
    c = float(a @ b)
    if c < -1.0 + 1e-9:  # opposite: half a turn about any axis perpendicular to a
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 0.0, 1.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    K = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + K + K @ K / (1.0 + c)


def _essential_missing(parts: dict[str, int]) -> list[str]:
    return [p for p in ESSENTIAL_PARTS if p not in parts]


def _toe_end(sk: Skeleton, parts: dict[str, int], side: str) -> int | None:
    kids = [k for k in sk.children(parts[f"{side}_toe"]) if sk.is_end_site[k]]
    return kids[0] if kids else None


def _part_point(sk: Skeleton, parts: dict[str, int], side: str, base: str) -> int | None:
    if base == "toe_end":
        return _toe_end(sk, parts, side)
    return parts.get(f"{side}_{base}" if side else base)


def plan_retarget(source: Skeleton, target: Skeleton, source_overrides: dict | None = None,
                  target_overrides: dict | None = None, source_name: str = "source",
                  target_name: str = "target") -> RetargetMap:
    """Pair the joints of two skeletons and compute the rest alignment and leg scale.

    Raises:
        ValueError: a skeleton lacks essential parts (ESSENTIAL_PARTS); the message names them and
            the skeleton's joints. Give a joint-map override for unknown naming.
    """
    ps = resolve_parts(source, source_overrides)
    pt = resolve_parts(target, target_overrides)
    miss_s, miss_t = _essential_missing(ps), _essential_missing(pt)
    if miss_s or miss_t:
        what = [f"{name} lacks {', '.join(miss)} (joints: {shorten(', '.join(sk.names), JOINT_LIST_CHARS)})"
                for name, miss, sk in ((source_name, miss_s, source), (target_name, miss_t, target)) if miss]
        raise ValueError("cannot retarget: " + "; ".join(what) +
                         '; give a joint-map override (JSON {"part": "JointName"})')
    Jt = target.n_joints
    src_of = np.full(Jt, -1, dtype=np.int64)
    how = [""] * Jt
    part_of_t = {j: p for p, j in pt.items()}
    used: set[int] = set()
    for j, p in part_of_t.items():
        if p in ps:
            src_of[j] = ps[p]
            how[j] = f"part:{p}"
            used.add(ps[p])
    by_name = {normalise(n): i for i, n in enumerate(source.names)}
    for j in range(Jt):
        if src_of[j] < 0:
            s = by_name.get(normalise(target.names[j]))
            if s is not None and s not in used and bool(source.is_end_site[s]) == bool(target.is_end_site[j]):
                src_of[j] = s
                how[j] = "name"
                used.add(s)

    rs, rt = rest_positions(source), rest_positions(target)
    lat_s, fwd_s = _body_axes(rs, ps)
    lat_t, fwd_t = _body_axes(rt, pt)
    body_s = np.stack([lat_s, [0.0, 1.0, 0.0], fwd_s], axis=1)  # columns: left, up, forward
    body_t = np.stack([lat_t, [0.0, 1.0, 0.0], fwd_t], axis=1)
    body = body_s @ body_t.T

    def segment(jt: int) -> tuple[np.ndarray, np.ndarray] | None:
        """Rest vectors (source, target) of the segment that starts at target joint jt."""
        js = int(src_of[jt])
        p = part_of_t.get(jt)
        if p is not None and src_of[jt] >= 0 and how[jt].startswith("part:"):
            side, base = (p[0], p[2:]) if p[1:2] == "_" else ("", p)
            for nxt in _SEGMENT_TO.get(base, ()):
                a, b = _part_point(source, ps, side, nxt), _part_point(target, pt, side, nxt)
                if a is None or b is None:
                    continue
                vs, vt = rs[a] - rs[js], rt[b] - rt[jt]
                if min(np.linalg.norm(vs), np.linalg.norm(vt)) >= _MIN_SEGMENT_M:
                    return vs, vt
        # any paired descendant (breadth first) at a distinct point in both skeletons
        queue = target.children(jt)
        while queue:
            c = queue.pop(0)
            cs = int(src_of[c])
            if cs >= 0 and js in source.chain(cs):
                vs, vt = rs[cs] - rs[js], rt[c] - rt[jt]
                if min(np.linalg.norm(vs), np.linalg.norm(vt)) >= _MIN_SEGMENT_M:
                    return vs, vt
            queue.extend(target.children(c))
        return None

    align = np.broadcast_to(np.eye(3), (Jt, 3, 3)).copy()
    for j in range(Jt):
        if src_of[j] < 0:
            continue
        seg = segment(j)
        A = None
        if seg is not None:  # body frame of the target -> shortest arc onto the source's direction
            vs, vt = seg
            A = body_s @ _arc(body_t.T @ (vt / np.linalg.norm(vt)), body_s.T @ (vs / np.linalg.norm(vs))) @ body_t.T
        if A is None:  # no segment of its own: keep the parent's alignment (or the body's)
            p = int(target.parents[j])
            A = align[p] if p >= 0 and src_of[p] >= 0 else body
        align[j] = A

    def leg(sk: Skeleton, parts: dict[str, int]) -> float:
        return 0.5 * sum(sk.chain_length(parts[f"{s}_hip"], parts[f"{s}_ankle"]) for s in "lr")

    ls, lt = leg(source, ps), leg(target, pt)
    if ls <= 0 or lt <= 0:
        raise ValueError(f"cannot retarget: zero leg length ({source_name} {ls:g} m, {target_name} {lt:g} m)")

    def soles(sk: Skeleton, parts: dict[str, int], rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        idx, clr = [], []
        for pts in foot_points(sk, parts):
            h = rest[pts, 1]
            idx += list(pts)
            clr += list(h - h.min())
        return np.array(idx, dtype=np.int64), np.array(clr)

    ss, cs = soles(source, ps, rs)
    st, ct = soles(target, pt, rt)
    return RetargetMap(source, target, src_of, tuple(how), align, lt / ls, ps, pt, ss, st, cs, ct)


def _floor_clearance(P: np.ndarray, soles: np.ndarray, clearance: np.ndarray) -> np.ndarray:
    """(T,) lowest sole point's height above its flat-footed planted height, metres (file floor y = 0)."""
    return (P[:, soles, 1] - clearance).min(axis=1)


def floor_height(positions: np.ndarray, soles: np.ndarray) -> float:
    """The floor's y (metres): the 3rd percentile over frames of the lowest sole point."""
    return float(np.percentile(positions[:, soles, 1].min(axis=1), _FLOOR_PERCENTILE))


def retarget(motion: Motion, target: RetargetTarget | Skeleton, plan: RetargetMap | None = None,
             source_overrides: dict | None = None) -> Motion:
    """The motion on the target body, at the target's frame rate.

    Args:
        motion: source take (any skeleton the part map resolves).
        target: target body (a bare Skeleton keeps the source frame rate).
        plan: a precomputed plan_retarget(source skeleton, target skeleton), reused across takes.
        source_overrides: joint-map override for the source skeleton.
    Returns:
        A Motion of the target skeleton (no animated local translations), ``source`` kept; the
        target's held joints keep their rotation (their children their world rotations). The floor sits where the source's does, scaled by the leg ratio (retargeting onto the same
        skeleton returns the same joint positions).
    Raises:
        ValueError: essential parts missing in either skeleton (named in the message).
    """
    tgt = target if isinstance(target, RetargetTarget) else RetargetTarget(target, float(motion.fps))
    if plan is None:
        plan = plan_retarget(motion.skeleton, tgt.skeleton, source_overrides, tgt.part_overrides,
                             motion.source or "source", tgt.source or "target")
    m = motion.resample(tgt.fps)
    sk = tgt.skeleton
    Gs, Ps = m.global_transforms()
    T, J = m.n_frames, sk.n_joints
    G = np.empty((T, J, 3, 3))
    held = {j: quat_to_matrix(np.asarray(q, dtype=float)) for j, q in tgt.held}
    for j in range(J):
        s, p = int(plan.source_joint[j]), int(sk.parents[j])
        if j in held and p >= 0:
            G[:, j] = G[:, p] @ held[j]
        elif s >= 0 and not sk.is_end_site[j]:
            G[:, j] = Gs[:, s] @ plan.align[j]
        elif p >= 0:
            G[:, j] = G[:, p]
        else:
            G[:, j] = np.eye(3)
    local = G.copy()
    for j in range(1, J):
        local[:, j] = np.swapaxes(G[:, sk.parents[j]], -1, -2) @ G[:, j]
    rot = matrix_to_quat(local)
    rot[:, sk.is_end_site] = (0.0, 0.0, 0.0, 1.0)
    local = quat_to_matrix(rot)

    s = plan.leg_scale
    trans = np.broadcast_to(sk.offsets, (T, J, 3)).copy()
    trans[:, 0] = 0.0
    _, P0 = forward_kinematics(sk.parents, local, trans)
    root = s * Ps[:, plan.source_parts["pelvis"]] - P0[:, plan.target_parts["pelvis"]]
    # feet on the floor: the target's lowest sole clearance = the source's, scaled
    floor_s = floor_height(Ps, plan.source_soles)
    want = s * (_floor_clearance(Ps, plan.source_soles, plan.source_clearance) - floor_s)
    have = _floor_clearance(P0 + root[:, None], plan.target_soles, plan.target_clearance) - s * floor_s
    root[:, 1] += want - have
    return Motion(sk, rot, root, float(tgt.fps), None, motion.source)


def same_body(motion: Motion, target: RetargetTarget) -> bool:
    """True when the take already has the target's skeleton (names, tree, offsets) and frame rate."""
    a, b = motion.skeleton, target.skeleton
    return (a.names == b.names and np.array_equal(a.parents, b.parents) and np.array_equal(a.offsets, b.offsets)
            and motion.local_translations is None and abs(motion.fps - target.fps) < 1e-9)


# ----- a library from takes of several skeletons --------------------------------------------

def segment_motion(motion: Motion, path: str | os.PathLike, params=None):
    """motion_graph.library.segment_file for a Motion already in memory (path: its source file)."""
    from motion_graph.library import LibraryParams
    from motion_graph.library import segment_motion as segment
    return segment(motion, path, params or LibraryParams())


def segment_retargeted(files: list[str | os.PathLike], params=None,
                       target: RetargetTarget | str | os.PathLike | None = None, progress: bool = False,
                       fps_override: float | None = None) -> tuple[list, RetargetTarget, dict]:
    """Load takes of any skeletons, retarget them onto one body and segment them.

    Args:
        files: .bvh/.amc files or folders.
        params: LibraryParams (its part_overrides apply to the target skeleton).
        target: target body or a mocap file holding it; default the first take's skeleton and rate.
        progress: show a progress bar.
        fps_override: override the source files' frame rate.
    Returns:
        (ClipResult per take, the target, per-take report {path: {"leg_scale", "unmatched", "held",
        "fps"}}; "held": the target's held joints, whose motion in the take its children carry).
    """
    from motion_graph.library import LibraryParams

    params = params or LibraryParams()
    paths = find_mocap_files(list(files))
    if not paths:
        raise MocapFormatError(", ".join(str(f) for f in files), "no .bvh or .amc files found")
    tgt: RetargetTarget | None
    if target is None or isinstance(target, RetargetTarget):
        tgt = target
    else:
        tgt = load_target(target, params.part_overrides)
    it = paths
    if progress:
        from tqdm import tqdm
        it = tqdm(paths, desc="retarget+segment", unit="file")
    clips, report = [], {}
    for f in it:
        m = load_motion(f, fps=fps_override)
        if tgt is None:
            tgt = RetargetTarget.from_motion(m, params.part_overrides)
        if same_body(m, tgt):
            mt, scale, unmatched, held = m, 1.0, [], []
        else:
            plan = plan_retarget(m.skeleton, tgt.skeleton, None, tgt.part_overrides, str(f), tgt.source or "target")
            mt = retarget(m, tgt, plan)
            scale, unmatched, held = plan.leg_scale, list(plan.unmatched), list(tgt.held_names)
        report[str(f)] = {"leg_scale": round(float(scale), 6), "unmatched": unmatched, "held": held,
                          "fps": float(m.fps)}
        clips.append(segment_motion(mt, f, params))
        del m
    return clips, tgt, report


def build_retargeted_library(files: list[str | os.PathLike], params=None,
                             target: RetargetTarget | str | os.PathLike | None = None,
                             labels_file: str | os.PathLike | None = None, progress: bool = False,
                             fps_override: float | None = None):
    """An ActionLibrary of takes of several skeletons on one body (see segment_retargeted).

    The library's skeleton is the target's; ``meta["retarget"]`` records the target file and, per
    take, the leg scale and the target joints left at the identity. Takes on the target's own
    body pass unchanged, so takes of one skeleton give the plain library.
    """
    return retargeted_library_and_clips(files, params, target, labels_file, progress, fps_override)[0]


def retargeted_library_and_clips(files: list[str | os.PathLike], params=None,
                                 target: RetargetTarget | str | os.PathLike | None = None,
                                 labels_file: str | os.PathLike | None = None, progress: bool = False,
                                 fps_override: float | None = None) -> tuple:
    """build_retargeted_library, also returning the segmented clips (for timelines and reports)."""
    from motion_graph.library import LibraryParams, library_from_clips

    params = params or LibraryParams()
    clips, tgt, report = segment_retargeted(files, params, target, progress, fps_override)
    lib = library_from_clips(clips, params, labels_file)
    lib.meta["retarget"] = {"target": str(Path(tgt.source)) if tgt.source else "", "target_fps": tgt.fps,
                            "takes": report}
    return lib, clips


def default_boxing_library(mocap: str | os.PathLike | None = None, params=None, progress: bool = False):
    """The default action library: the shared boxing takes (motion_graph.paths.boxing_takes: 13_17,
    13_18 and, where present, 14_02) on 13_17's body. A MocapFormatError says where to get them."""
    from motion_graph.paths import boxing_files
    return build_retargeted_library(boxing_files(mocap), params, progress=progress)


# ----- contact sheet ----------------------------------------------------------------------

def contact_sheet(before: Motion, after: Motion, frames: list[int], path: str | os.PathLike,
                  title: str = "", labels: tuple[str, str] = ("before", "after")) -> None:
    """PNG of the same frames before and after retargeting: stick figures, side and front views.

    Rows: side view before, after; front view before, after. Both figures of a frame are seen along
    the same axes: forward = the fighting direction of ``before`` at that frame (head facing plus
    the clip's punch offset, motion_graph.strikes), centred on the pelvis,
    with the floor at y = 0 (each motion's floor estimate). Red: left limbs, blue: right limbs.
    Both motions must share the frame rate so that frame numbers mean the same instant.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from motion_graph.features import clip_features
    from motion_graph.strikes import detect_strikes, stance_offset

    fb, fa = clip_features(before), clip_features(after)
    fighting = fb.facing + stance_offset(detect_strikes(fb))
    rows = [(before, fb, labels[0]), (after, fa, labels[1])]
    n = len(frames)
    fig, axes = plt.subplots(4, n, figsize=(1.55 * n, 9.2), squeeze=False)
    for r, (m, feat, name) in enumerate(rows):
        P = m.positions()
        P[..., 1] -= floor_height(P, np.concatenate(foot_points(m.skeleton, feat.parts)))
        sk, parts = m.skeleton, feat.parts
        side_of = {}
        for side in "lr":
            for root in (parts[f"{side}_shoulder"], parts[f"{side}_hip"]):
                side_of.update({j: side for j in range(sk.n_joints) if root in sk.chain(j)})
        for c, f in enumerate(frames):
            h = float(fighting[f])
            fwd = np.array([np.sin(h), 0.0, np.cos(h)])
            lat = np.array([np.cos(h), 0.0, -np.sin(h)])  # the body's left
            pel = P[f, parts["pelvis"]]
            d = P[f] - np.array([pel[0], 0.0, pel[2]])
            for v, (ax_h, view) in enumerate(((fwd, "side"), (lat, "front"))):
                ax = axes[2 * v + r, c]
                x, y = d @ ax_h, d[:, 1]
                for j in range(1, sk.n_joints):
                    p = int(sk.parents[j])
                    if np.linalg.norm(sk.offsets[j]) < _MIN_SEGMENT_M:
                        continue
                    col = {"l": "tab:red", "r": "tab:blue"}.get(side_of.get(j, ""), "0.3")
                    ax.plot([x[p], x[j]], [y[p], y[j]], color=col, lw=1.6, solid_capstyle="round")
                ax.axhline(0.0, color="0.6", lw=0.8)
                ax.set_xlim(-1.0, 1.0)
                ax.set_ylim(-0.05, 1.95)
                ax.set_aspect("equal")
                ax.set_xticks([])
                ax.set_yticks([])
                if c == 0:
                    ax.set_ylabel(f"{name}\n{view}", fontsize=8)
                if v == 0 and r == 0:
                    ax.set_title(f"frame {f}\n{f / m.fps:.2f} s", fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
