"""BVH reader and writer for any skeleton.

Reads the Euler channel order that each joint declares, position channels on any joint, the
frame time from the header (overridable: some CMU conversions declare 30 fps for 120 fps data),
and converts lengths to metres (unit detected from the performer's height unless given).
Numbers follow an ASCII grammar and every problem is a MocapFormatError naming the file and line;
memory stays proportional to the file (caps in motion_graph.errors), the hierarchy is read and
written without recursion.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field

import numpy as np

from motion_graph.errors import (
    MAX_ABS_LENGTH, MAX_CHANNELS, MAX_FRAME_JOINTS, MAX_FRAME_TIME_S, MAX_FRAMES, MAX_JOINTS, MAX_NAME_CHARS,
    MIN_FRAME_TIME_S, MocapFormatError, check_lengths, check_rate, check_scale, count_tokens,
    is_number_row, line_count, number_error, numbered_lines, parse_finite, parse_float, parse_whole,
    quote, read_mocap_text,
)
from motion_graph.motion import Motion, forward_kinematics
from motion_graph.rotations import euler_to_matrix, matrix_to_quat, quat_to_matrix
from motion_graph.skeleton import Skeleton
from motion_graph.units import guess_metres_per_unit, sample_step

_ROT = {"Xrotation": "X", "Yrotation": "Y", "Zrotation": "Z"}
_POS = {"Xposition": 0, "Yposition": 1, "Zposition": 2}
#: Most channels one joint may declare: each position and rotation channel once.
MAX_JOINT_CHANNELS = 6


@dataclass
class _Hierarchy:
    names: list[str] = field(default_factory=list)
    parents: list[int] = field(default_factory=list)
    offsets: list[list[float]] = field(default_factory=list)
    channels: list[tuple[str, ...]] = field(default_factory=list)
    end_site: list[bool] = field(default_factory=list)

    def add(self, name: str, parent: int, end_site: bool) -> int:
        self.names.append(name)
        self.parents.append(parent)
        self.offsets.append([0.0, 0.0, 0.0])
        self.channels.append(())
        self.end_site.append(end_site)
        return len(self.names) - 1


def _read_channels(path: str, rest: str, ln: int) -> tuple[str, ...]:
    """The channel names of a CHANNELS line (``rest``: the text after the keyword)."""
    parts = rest.split(None, 1)
    k = parse_whole(parts[0]) if parts else None
    if k is None:
        raise MocapFormatError(path, f"CHANNELS needs a count, got {quote(parts[0]) if parts else 'nothing'}", ln)
    if k > MAX_JOINT_CHANNELS:
        raise MocapFormatError(path, f"CHANNELS declares {k} channels; a joint has at most {MAX_JOINT_CHANNELS}", ln)
    names = parts[1].split(None, k) if len(parts) > 1 else []
    if len(names) != k:
        got = count_tokens(parts[1]) if len(names) > k else len(names)
        raise MocapFormatError(path, f"CHANNELS declares {k} channels but names {got}", ln)
    for c in names:
        if c not in _ROT and c not in _POS:
            raise MocapFormatError(path, f"unknown channel {quote(c)}", ln)
    if len(set(names)) != len(names):
        raise MocapFormatError(path, "CHANNELS names a channel twice", ln)
    return tuple(names)


def _read_hierarchy(path: str, lines) -> tuple[_Hierarchy, int]:
    """Parse up to and including the MOTION line; returns the joints and the MOTION line's number."""
    h = _Hierarchy()
    stack: list[int] = []
    pending: int | None = None  # joint declared, waiting for its "{"
    seen_root = False
    ln = 0
    for ln, raw in lines:
        parts = raw.split(None, 1)
        if not parts:
            continue
        key = parts[0]
        rest = parts[1] if len(parts) > 1 else ""
        if key == "HIERARCHY":
            continue
        if key in ("ROOT", "JOINT"):
            if not rest:
                raise MocapFormatError(path, f"{key} without a name", ln)
            if key == "ROOT" and seen_root:
                raise MocapFormatError(path, "more than one ROOT (only one skeleton per file is supported)", ln)
            if key == "JOINT" and not stack:
                raise MocapFormatError(path, "JOINT outside of ROOT", ln)
            if len(rest.strip()) > MAX_NAME_CHARS:
                raise MocapFormatError(path, f"joint name {quote(rest)} longer than {MAX_NAME_CHARS} characters", ln)
            if len(h.names) >= MAX_JOINTS:
                raise MocapFormatError(path, f"more than {MAX_JOINTS:,} joints (motion_graph.errors.MAX_JOINTS)", ln)
            seen_root = True
            pending = h.add(" ".join(rest.split()), stack[-1] if stack else -1, False)
        elif key == "End":
            if not stack:
                raise MocapFormatError(path, "End Site outside of a joint", ln)
            if len(h.names) >= MAX_JOINTS:
                raise MocapFormatError(path, f"more than {MAX_JOINTS:,} joints (motion_graph.errors.MAX_JOINTS)", ln)
            pending = h.add(f"{h.names[stack[-1]]}_End", stack[-1], True)
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
            vals = rest.split(None, 3)
            if len(vals) != 3:
                got = count_tokens(rest) if len(vals) > 3 else len(vals)
                raise MocapFormatError(path, f"OFFSET needs 3 numbers, got {got}", ln)
            h.offsets[stack[-1]] = parse_finite(path, vals, "OFFSET", ln)
        elif key == "CHANNELS":
            if not stack:
                raise MocapFormatError(path, "CHANNELS outside of a joint", ln)
            h.channels[stack[-1]] = _read_channels(path, rest, ln)
        elif key == "MOTION":
            break
        else:
            raise MocapFormatError(path, f"unexpected token {quote(key)} in HIERARCHY", ln)
    else:
        raise MocapFormatError(path, "no MOTION section" if h.names else "no HIERARCHY section", ln)
    if not h.names:
        raise MocapFormatError(path, "no ROOT joint before MOTION", ln)
    if stack:
        raise MocapFormatError(path, f"joint {quote(h.names[stack[-1]])} is not closed before MOTION", ln)
    return h, ln


def _read_motion_header(path: str, lines, ln: int) -> tuple[int, float, int, int]:
    """The ``Frames:`` and ``Frame Time:`` lines: (frames, frame time, Frames line, last line read)."""
    n_frames = frame_time = None
    frames_ln = ln
    for ln, raw in lines:
        raw = raw.strip()
        if not raw:
            continue
        if raw.startswith("Frames:"):
            v = raw.split(":", 1)[1].strip()
            n_frames = parse_whole(v)
            if n_frames is None:
                raise MocapFormatError(path, f"Frames: expects a whole number, got {quote(v)}", ln)
            if n_frames > MAX_FRAMES:
                raise MocapFormatError(path, f"Frames: {quote(v)} is more than {MAX_FRAMES:,} "
                                             "(motion_graph.errors.MAX_FRAMES)", ln)
            frames_ln = ln
        elif raw.startswith("Frame Time:"):
            v = raw.split(":", 1)[1].strip()
            frame_time = parse_float(v)
            if frame_time is None or not frame_time > 0 or not math.isfinite(frame_time):
                raise MocapFormatError(path, f"Frame Time: expects a positive number, got {quote(v)}", ln)
            if not MIN_FRAME_TIME_S <= frame_time <= MAX_FRAME_TIME_S:
                raise MocapFormatError(path, f"Frame Time: {quote(v)} is outside {MIN_FRAME_TIME_S:g}..{MAX_FRAME_TIME_S:g} s "
                                             "(motion_graph.errors.MIN_FRAME_TIME_S, MAX_FRAME_TIME_S)", ln)
        else:
            raise MocapFormatError(path, f"expected 'Frames:' and 'Frame Time:' lines, got {quote(raw)}", ln)
        if n_frames is not None and frame_time is not None:
            return n_frames, frame_time, frames_ln, ln
    raise MocapFormatError(path, "MOTION section lacks 'Frames:' or 'Frame Time:' (file truncated?)", ln)


def _read_frames(path: str, lines, ln: int, n_frames: int, h: _Hierarchy, max_rows: int) -> np.ndarray:
    """The (n_frames, channels) MOTION data; at most max_rows rows are allocated (the most the file can hold)."""
    columns = [(name, c) for name, ch in zip(h.names, h.channels) for c in ch]
    n_ch = len(columns)
    rows = min(n_frames, max_rows)
    data = np.empty((rows, n_ch))
    row_line = np.empty(rows, np.int64)
    f = 0
    for ln, raw in lines:
        toks = raw.split(None, n_ch)
        if not toks:
            continue
        if len(toks) != n_ch:
            got = count_tokens(raw) if len(toks) > n_ch else len(toks)
            raise MocapFormatError(path, f"frame {f + 1} has {got} values, the hierarchy declares {n_ch} channels", ln)
        if f >= rows:  # cannot happen: rows bounds what the file's lines can hold
            raise MocapFormatError(path, f"more frames than the file can hold ({rows})", ln)
        if is_number_row(raw):
            data[f] = list(map(float, toks))
        else:
            vals = [parse_float(t) for t in toks]
            bad = next((t for t, v in zip(toks, vals) if v is None or not math.isfinite(v)), None)
            if bad is not None:
                raise number_error(path, bad, f"frame {f + 1}", ln)
            data[f] = vals
        row_line[f] = ln
        f += 1
        if f == n_frames:
            break
    if f < n_frames:
        raise MocapFormatError(path, f"file truncated: header says {n_frames} frames, found {f}", ln)
    finite = np.isfinite(data).all(axis=1)
    if not finite.all():
        r = int(np.argmin(finite))
        raise MocapFormatError(path, f"value in frame {r + 1} overflows (beyond 1.8e308)", int(row_line[r]))
    positions = [k for k, (_, c) in enumerate(columns) if c in _POS]
    if positions:
        far = (np.abs(data[:, positions]) > MAX_ABS_LENGTH).any(axis=1)
        if far.any():
            r = int(np.argmax(far))
            k = positions[int(np.argmax(np.abs(data[r, positions]) > MAX_ABS_LENGTH))]
            raise MocapFormatError(path, f"{columns[k][1]} of joint {quote(columns[k][0])} in frame {r + 1} exceeds "
                                         f"{MAX_ABS_LENGTH:g} (motion_graph.errors.MAX_ABS_LENGTH)", int(row_line[r]))
    return data


def load_bvh(path: str | os.PathLike, fps: float | None = None, metres_per_unit: float | None = None) -> Motion:
    """Load a BVH file.

    Args:
        path: the file (UTF-8 or ASCII, an optional BOM; lines end in LF, CRLF or CR).
        fps: override the header's frame rate (frames per second; finite, MIN_FPS..MAX_FPS of
            motion_graph.errors).
        metres_per_unit: override the length unit (finite, positive); by default it is detected
            from the performer's height (m, cm, mm, inch or CMU ASF units).
    Raises:
        MocapFormatError: naming the file and line of the first problem, or a bad fps /
            metres_per_unit (a MocapFormatError is a ValueError). Files beyond the caps of
            motion_graph.errors (joints, channels, frames, frames x joints, bytes, lengths) are refused.
    """
    path = str(path)
    rate = None if fps is None else check_rate(path, fps)
    scale = None if metres_per_unit is None else check_scale(path, metres_per_unit)
    text = read_mocap_text(path)
    lines = numbered_lines(text)
    h, ln = _read_hierarchy(path, lines)
    J = len(h.names)
    n_ch = sum(len(c) for c in h.channels)
    if n_ch > MAX_CHANNELS:
        raise MocapFormatError(path, f"the hierarchy declares {n_ch:,} channels, more than {MAX_CHANNELS:,} "
                                     "(motion_graph.errors.MAX_CHANNELS)", ln)
    n_frames, frame_time, frames_ln, ln = _read_motion_header(path, lines, ln)
    if n_frames == 0:
        raise MocapFormatError(path, "MOTION section has 0 frames", ln)
    if n_frames * J > MAX_FRAME_JOINTS:
        raise MocapFormatError(path, f"{n_frames:,} frames x {J:,} joints is more than {MAX_FRAME_JOINTS:,} "
                                     "(motion_graph.errors.MAX_FRAME_JOINTS)", frames_ln)
    if n_ch == 0:
        raise MocapFormatError(path, "the hierarchy declares no channels", frames_ln)
    # A frame line holds n_ch numbers and n_ch - 1 separators: the text bounds the rows it can hold.
    max_rows = min(line_count(text) - ln, len(text) // (2 * n_ch) + 1)
    data = _read_frames(path, lines, ln, n_frames, h, max_rows)
    del text, lines

    T = n_frames
    parents_a = np.array(h.parents)
    offsets_a = np.array(h.offsets, dtype=np.float64)
    local_tr = np.broadcast_to(offsets_a, (T, J, 3)).copy()
    rotations = np.empty((T, J, 4))
    rotations[:] = matrix_to_quat(np.eye(3)[None])[0]
    sample = slice(None, None, sample_step(T))
    sample_rot = None if scale is not None else np.broadcast_to(np.eye(3), (len(range(T)[sample]), J, 3, 3)).copy()
    animated_tr = np.zeros(J, bool)
    col = 0
    for j, ch in enumerate(h.channels):
        rot_order = "".join(_ROT[c] for c in ch if c in _ROT)
        rot_cols = [col + k for k, c in enumerate(ch) if c in _ROT]
        for k, c in enumerate(ch):
            if c in _POS:
                local_tr[:, j, _POS[c]] = data[:, col + k]
                animated_tr[j] = True
        if rot_order:
            mats = euler_to_matrix(data[:, rot_cols], rot_order)
            rotations[:, j] = matrix_to_quat(mats)
            if sample_rot is not None:
                sample_rot[:, j] = mats[sample]
        col += len(ch)
    del data

    if scale is None:
        _, pos = forward_kinematics(parents_a, sample_rot, np.ascontiguousarray(local_tr[sample]))
        _, scale = guess_metres_per_unit(pos, step=1)
    s = float(scale)
    non_root_anim = animated_tr.copy()
    non_root_anim[0] = False
    with np.errstate(over="ignore"):  # a huge metres_per_unit: refused just below
        offsets_m = offsets_a * s
        root = local_tr[:, 0] * s
        lt = local_tr * s if non_root_anim.any() else None
    check_lengths(path, offsets_m, f"joint offsets (x {s:g} metres per unit)")
    check_lengths(path, root, f"root positions (x {s:g} metres per unit)")
    if lt is not None:
        check_lengths(path, lt, f"joint positions (x {s:g} metres per unit)")
    if not np.isfinite(rotations).all():
        raise MocapFormatError(path, "rotations are not finite")
    skel = Skeleton(tuple(h.names), parents_a, offsets_m, tuple(h.channels), np.array(h.end_site), s)
    return Motion(skel, rotations, root, rate if rate is not None else rate_from_frame_time(frame_time), lt, path)


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
    kids: list[list[int]] = [[] for _ in range(J)]
    for c in range(1, J):
        kids[int(sk.parents[c])].append(c)
    out: list[str] = ["HIERARCHY"]
    order: list[int] = []
    stack: list[tuple[int, int, bool]] = [(0, 0, False)]  # (joint, depth, closing brace)
    while stack:
        j, depth, closing = stack.pop()
        ind = "\t" * depth
        if closing:
            out.append(f"{ind}}}")
        elif sk.is_end_site[j]:
            out.extend([f"{ind}End Site", f"{ind}{{", f"{ind}\tOFFSET {' '.join(f'{v:.6f}' for v in sk.offsets[j] * units_per_metre)}", f"{ind}}}"])
        else:
            out.append(f"{ind}{'ROOT' if j == 0 else 'JOINT'} {sk.names[j]}")
            out.append(f"{ind}{{")
            out.append(f"{ind}\tOFFSET {' '.join(f'{v:.6f}' for v in sk.offsets[j] * units_per_metre)}")
            ch = ("Xposition Yposition Zposition " if has_pos[j] else "") + "Zrotation Yrotation Xrotation"
            out.append(f"{ind}\tCHANNELS {6 if has_pos[j] else 3} {ch}")
            order.append(j)
            stack.append((j, depth, True))
            stack.extend((c, depth + 1, False) for c in reversed(kids[j]))
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
