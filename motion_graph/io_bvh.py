"""BVH reader and writer for any skeleton.

Reads the Euler channel order that each joint declares, position channels on any joint, the
frame time from the header (overridable: some CMU conversions declare 30 fps for 120 fps data),
and converts lengths to metres (unit detected from the performer's height unless given).
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from motion_graph.errors import MocapFormatError
from motion_graph.motion import Motion, forward_kinematics
from motion_graph.rotations import euler_to_matrix, matrix_to_quat, quat_to_matrix
from motion_graph.skeleton import Skeleton
from motion_graph.units import guess_metres_per_unit

_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}


def _parse_floats(path: str, tokens: list[str], line: int, what: str) -> list[float]:
    try:
        return [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise MocapFormatError(path, f"non-numeric value {bad!r} in {what}", line) from None


def _is_float(t: str) -> bool:
    try:
        float(t)
        return True
    except ValueError:
        return False


def load_bvh(path: str | os.PathLike, fps: float | None = None, metres_per_unit: float | None = None) -> Motion:
    """Load a BVH file.

    Args:
        path: the file.
        fps: override the header's frame rate (frames per second).
        metres_per_unit: override the length unit; by default it is detected from the
            performer's height (m, cm, mm, inch or CMU ASF units).
    Raises:
        MocapFormatError: naming the file and line of the first problem.
    """
    path = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise MocapFormatError(path, f"cannot read file: {e.strerror}") from None
    lines = text.splitlines()
    if not any(l.strip() for l in lines):
        raise MocapFormatError(path, "empty file")

    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    end_site: list[bool] = []
    stack: list[int] = []
    pending: int | None = None  # joint declared, waiting for its "{"
    i = 0
    n = len(lines)
    seen_root = False
    while i < n:
        toks = lines[i].split()
        ln = i + 1
        i += 1
        if not toks:
            continue
        key = toks[0]
        if key == "HIERARCHY":
            continue
        if key in ("ROOT", "JOINT"):
            if len(toks) < 2:
                raise MocapFormatError(path, f"{key} without a name", ln)
            if key == "ROOT" and seen_root:
                raise MocapFormatError(path, "more than one ROOT (only one skeleton per file is supported)", ln)
            if key == "JOINT" and not stack:
                raise MocapFormatError(path, "JOINT outside of ROOT", ln)
            seen_root = True
            names.append(" ".join(toks[1:]))
            parents.append(stack[-1] if stack else -1)
            offsets.append([0.0, 0.0, 0.0])
            channels.append(())
            end_site.append(False)
            pending = len(names) - 1
        elif key == "End":
            if not stack:
                raise MocapFormatError(path, "End Site outside of a joint", ln)
            names.append(f"{names[stack[-1]]}_End")
            parents.append(stack[-1])
            offsets.append([0.0, 0.0, 0.0])
            channels.append(())
            end_site.append(True)
            pending = len(names) - 1
        elif key == "{":
            if pending is None:
                raise MocapFormatError(path, "unexpected '{'", ln)
            stack.append(pending)
            pending = None
        elif key == "}":
            if not stack:
                raise MocapFormatError(path, "unbalanced '}'", ln)
            stack.pop()
        elif key == "OFFSET":
            if not stack:
                raise MocapFormatError(path, "OFFSET outside of a joint", ln)
            if len(toks) != 4:
                raise MocapFormatError(path, f"OFFSET needs 3 numbers, got {len(toks) - 1}", ln)
            offsets[stack[-1]] = _parse_floats(path, toks[1:], ln, "OFFSET")
        elif key == "CHANNELS":
            if not stack:
                raise MocapFormatError(path, "CHANNELS outside of a joint", ln)
            if len(toks) < 2 or not toks[1].isdigit():
                raise MocapFormatError(path, "CHANNELS needs a count", ln)
            k = int(toks[1])
            ch = tuple(toks[2:])
            if len(ch) != k:
                raise MocapFormatError(path, f"CHANNELS declares {k} channels but names {len(ch)}", ln)
            for c in ch:
                if c not in _ROT and c not in _POS:
                    raise MocapFormatError(path, f"unknown channel {c!r}", ln)
            channels[stack[-1]] = ch
        elif key == "MOTION":
            break
        else:
            raise MocapFormatError(path, f"unexpected token {key!r} in HIERARCHY", ln)
    else:
        raise MocapFormatError(path, "no MOTION section" if names else "no HIERARCHY section", n)
    if not names:
        raise MocapFormatError(path, "no ROOT joint before MOTION", i)
    if stack:
        raise MocapFormatError(path, f"joint {names[stack[-1]]!r} is not closed before MOTION", i)

    # Header of the MOTION section.
    n_frames = frame_time = None
    while i < n and (n_frames is None or frame_time is None):
        raw = lines[i].strip()
        ln = i + 1
        i += 1
        if not raw:
            continue
        if raw.startswith("Frames:"):
            v = raw.split(":", 1)[1].strip()
            if not v.isdigit():
                raise MocapFormatError(path, f"Frames: expects a whole number, got {v!r}", ln)
            n_frames = int(v)
        elif raw.startswith("Frame Time:"):
            v = raw.split(":", 1)[1].strip()
            if not _is_float(v) or float(v) <= 0:
                raise MocapFormatError(path, f"Frame Time: expects a positive number, got {v!r}", ln)
            frame_time = float(v)
        else:
            raise MocapFormatError(path, f"expected 'Frames:' and 'Frame Time:' lines, got {raw[:40]!r}", ln)
    if n_frames is None or frame_time is None:
        raise MocapFormatError(path, "MOTION section lacks 'Frames:' or 'Frame Time:' (file truncated?)", n)
    if n_frames == 0:
        raise MocapFormatError(path, "MOTION section has 0 frames", i)

    n_ch = sum(len(c) for c in channels)
    data = np.empty((n_frames, n_ch))
    f = 0
    while f < n_frames:
        if i >= n:
            raise MocapFormatError(path, f"file truncated: header says {n_frames} frames, found {f}", n)
        toks = lines[i].split()
        ln = i + 1
        i += 1
        if not toks:
            continue
        if len(toks) != n_ch:
            raise MocapFormatError(path, f"frame {f + 1} has {len(toks)} values, the hierarchy declares {n_ch} channels", ln)
        data[f] = _parse_floats(path, toks, ln, f"frame {f + 1}")
        f += 1
    if not np.all(np.isfinite(data)):
        raise MocapFormatError(path, "non-finite value (nan/inf) in MOTION data")

    J = len(names)
    parents_a = np.array(parents)
    offsets_a = np.array(offsets, dtype=np.float64)
    local_rot = np.broadcast_to(np.eye(3), (n_frames, J, 3, 3)).copy()
    local_tr = np.broadcast_to(offsets_a, (n_frames, J, 3)).copy()
    animated_tr = np.zeros(J, bool)
    col = 0
    for j, ch in enumerate(channels):
        rot_order = "".join(_ROT[c] for c in ch if c in _ROT)
        rot_cols = [col + k for k, c in enumerate(ch) if c in _ROT]
        for k, c in enumerate(ch):
            if c in _POS:
                local_tr[:, j, _POS[c]] = data[:, col + k]
                animated_tr[j] = True
        if rot_order:
            local_rot[:, j] = euler_to_matrix(data[:, rot_cols], rot_order)
        col += len(ch)

    if metres_per_unit is None:
        _, pos = forward_kinematics(parents_a, local_rot, local_tr)
        _, metres_per_unit = guess_metres_per_unit(pos)
    s = float(metres_per_unit)
    skel = Skeleton(tuple(names), parents_a, offsets_a * s, tuple(channels), np.array(end_site), s)
    non_root_anim = animated_tr.copy()
    non_root_anim[0] = False
    lt = local_tr * s if non_root_anim.any() else None
    return Motion(skel, matrix_to_quat(local_rot), local_tr[:, 0] * s, float(fps) if fps else rate_from_frame_time(frame_time),
                  lt, path)


def rate_from_frame_time(frame_time: float) -> float:
    """Frames per second from a header frame time, snapped to a whole rate when within 0.01%
    (headers round 1/120 to 0.00833333)."""
    rate = 1.0 / frame_time
    whole = round(rate)
    return float(whole) if whole > 0 and abs(rate - whole) < 1e-4 * whole else rate


def save_bvh(motion: Motion, path: str | os.PathLike, units_per_metre: float = 100.0) -> None:
    """Write a Motion as BVH (lengths in centimetres by default, ZYX Euler rotations, written atomically).

    Joints with animated translations (or the root) get 6 channels; others 3; end sites become End Site.
    """
    from scipy.spatial.transform import Rotation

    sk = motion.skeleton
    J = sk.n_joints
    tr = motion.translations() * units_per_metre
    has_pos = np.zeros(J, bool)
    has_pos[0] = True
    if motion.local_translations is not None:
        has_pos |= np.ptp(motion.local_translations, axis=0).max(axis=1) > 1e-9
    out: list[str] = ["HIERARCHY"]
    order: list[int] = []

    def emit(j: int, depth: int) -> None:
        ind = "\t" * depth
        if sk.is_end_site[j]:
            out.extend([f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {' '.join(f'{v:.6f}' for v in sk.offsets[j] * units_per_metre)}", f"{ind}}}"])
            return
        out.append(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {' '.join(f'{v:.6f}' for v in sk.offsets[j] * units_per_metre)}")
        ch = ("Xposition Yposition Zposition " if has_pos[j] else "") + "Zrotation Yrotation Xrotation"
        out.append(f"{ind}\tCHANNELS {6 if has_pos[j] else 3} {ch}")
        order.append(j)
        for c in sk.children(j):
            emit(c, depth + 1)
        out.append(f"{ind}}}")

    emit(0, 0)
    out += ["MOTION", f"Frames: {motion.n_frames}", f"Frame Time: {1.0 / motion.fps:.8f}"]
    mats = quat_to_matrix(motion.rotations)
    cols = []
    for j in order:
        if has_pos[j]:
            cols.append(tr[:, j])
        eul = Rotation.from_matrix(mats[:, j]).as_euler("ZYX", degrees=True)
        cols.append(eul)
    data = np.concatenate(cols, axis=1)
    out.extend(" ".join(f"{v:.5f}" for v in row) for row in data)
    from motion_graph.atomic import atomic_write_text
    atomic_write_text(path, "\n".join(out) + "\n")
