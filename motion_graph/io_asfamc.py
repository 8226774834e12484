"""CMU ASF (skeleton) + AMC (motion) reader.

Conventions (as in the CMU database and its common BVH conversions):
- ``:units length L``: one file length unit is 1/L inch, so metres per unit = 0.0254 / L
  (CMU: L = 0.45, about 5.64 cm per unit). Angles in degrees unless ``angle rad``.
- A joint is put at the start of every bone; its offset is the parent bone's
  ``direction * length`` (zero under the root); leaf bones get an end site at their tip.
- Local rotation of bone b: C_b M_b C_b^-1, with C_b the bone's ``axis`` rotation and M_b the
  AMC rotation, both composed so the first listed axis is applied first (order XYZ -> Rz Ry Rx).
- AMC files carry no frame rate; CMU captured at 120 fps, the default here.

Numbers follow an ASCII grammar, the hierarchy is walked without recursion (a cycle or a bone
under two parents is refused), and every problem is a MocapFormatError naming the file and line
(caps in motion_graph.errors).
"""
from __future__ import annotations

import math
import os
from array import array
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motion_graph.errors import (
    MAX_ABS_LENGTH, MAX_FRAME_JOINTS, MAX_FRAMES, MAX_JOINTS, MAX_NAME_CHARS, MocapFormatError,
    check_lengths, check_rate, check_scale, count_tokens, is_number_row, number_error, numbered_lines,
    parse_finite, parse_float, parse_whole, quote, read_mocap_text,
)
from motion_graph.motion import Motion
from motion_graph.rotations import euler_to_matrix, matrix_to_quat
from motion_graph.skeleton import Skeleton

CMU_FPS = 120.0
_DOF_ROT = {"rx": "X", "ry": "Y", "rz": "Z"}
_DOF_POS = {"tx": 0, "ty": 1, "tz": 2}
#: ``axis`` orders an ASF may give: each rotation axis once.
AXIS_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
#: Most values one ASF line (a ``limits`` line, a hierarchy line) is read for.
_MAX_LINE_VALUES = MAX_JOINTS + 1


@dataclass
class _Bone:
    name: str
    direction: np.ndarray = field(default_factory=lambda: np.zeros(3))
    length: float = 0.0
    axis: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axis_order: str = "XYZ"
    dofs: tuple[str, ...] = ()
    limits: list[tuple[float, float]] = field(default_factory=list)


@dataclass
class AsfSkeleton:
    """The parsed ASF: bones, hierarchy and units; ``skeleton`` is the joint tree in metres."""

    bones: dict[str, _Bone]
    order: list[str]          # joint order (root first), bone names
    skeleton: Skeleton
    angle_deg: bool
    root_order: tuple[str, ...]
    root_axis: str
    path: str


def _tokens(path: str, raw: str, ln: int) -> list[str]:
    """The whitespace-separated tokens of an ASF line (at most _MAX_LINE_VALUES + 1 are read)."""
    toks = raw.split(None, _MAX_LINE_VALUES + 1)
    if len(toks) > _MAX_LINE_VALUES + 1:
        raise MocapFormatError(path, f"line has more than {_MAX_LINE_VALUES + 1:,} values", ln)
    return toks


def _value(path: str, toks: list[str], ln: int, what: str) -> str:
    """The single value after a keyword."""
    if len(toks) != 2:
        raise MocapFormatError(path, f"{what} needs one value, got {len(toks) - 1}", ln)
    return toks[1]


def _dofs(path: str, toks: list[str], ln: int, what: str, allowed: tuple[str, ...] = ()) -> tuple[str, ...]:
    dofs = tuple(t.lower() for t in toks)
    bad = [t for t in dofs if t not in _DOF_ROT and t not in _DOF_POS and t not in allowed]
    if bad:
        raise MocapFormatError(path, f"unknown {what} {quote(bad[0])}", ln)
    if len(set(dofs)) != len(dofs):
        raise MocapFormatError(path, f"{what}s name a channel twice", ln)
    return dofs


def _axis_order(path: str, token: str, ln: int) -> str:
    order = token.upper()
    if order not in AXIS_ORDERS:
        raise MocapFormatError(path, f"axis order {quote(token)} is not one of {', '.join(AXIS_ORDERS)}", ln)
    return order


def _three(path: str, toks: list[str], ln: int, what: str, limit: float | None = MAX_ABS_LENGTH) -> np.ndarray:
    if len(toks) != 4:
        raise MocapFormatError(path, f"{what} needs 3 numbers, got {len(toks) - 1}", ln)
    return np.array(parse_finite(path, toks[1:], what, ln, limit))


def _limit_values(path: str, toks: list[str], ln: int) -> list[float]:
    """Numbers of a ``limits`` line; ``inf`` / ``-inf`` stand for no limit, nan is refused."""
    out = []
    for t in toks:
        v = parse_float(t)
        if v is None or math.isnan(v):
            raise number_error(path, t, "limits", ln)
        out.append(v)
    return out


def load_asf(path: str | os.PathLike, metres_per_unit: float | None = None) -> AsfSkeleton:
    """Parse an ASF skeleton file (lengths converted to metres).

    Raises:
        MocapFormatError: naming the file and line of the first problem; hierarchies with a cycle,
            a bone under two parents or more than MAX_JOINTS joints are refused.
    """
    path = str(path)
    scale = None if metres_per_unit is None else check_scale(path, metres_per_unit)
    text = read_mocap_text(path)
    length_unit = 1.0
    angle_deg = True
    root_order: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz")
    root_axis = "XYZ"
    root_axis_line: tuple[list[str], int] | None = None
    root_orient = np.zeros(3)
    root_pos = np.zeros(3)
    bones: dict[str, _Bone] = {}
    hierarchy: list[tuple[str, list[str], int]] = []
    section = None
    cur: _Bone | None = None
    in_limits = False
    units_ln = None
    for ln, raw in numbered_lines(text):
        toks = _tokens(path, raw, ln)
        if not toks or toks[0].startswith("#"):
            continue
        if toks[0].startswith(":"):
            section = toks[0][1:]
            in_limits = False
            continue
        key = toks[0].lower()
        if section == "units":
            if key == "length" and len(toks) >= 2:
                length_unit = parse_finite(path, toks[1:2], "units length", ln)[0]
                if length_unit <= 0:
                    raise MocapFormatError(path, "units length must be positive", ln)
                units_ln = ln
            elif key == "angle" and len(toks) >= 2:
                angle_deg = toks[1].lower().startswith("deg")
        elif section == "root":
            if key == "order":
                root_order = _dofs(path, toks[1:], ln, "root channel")
            elif key == "axis":  # checked after the sections: a file lacking ":bonedata" has bone axes here
                root_axis_line = (toks, ln)
            elif key == "position":
                root_pos = _three(path, toks, ln, "root position")
            elif key == "orientation":
                root_orient = _three(path, toks, ln, "root orientation", None)
        elif section == "bonedata":
            if key == "begin":
                cur = _Bone(name="")
                in_limits = False
            elif key == "end":
                if cur is None or not cur.name:
                    raise MocapFormatError(path, "bone without a name", ln)
                if cur.name not in bones and len(bones) >= MAX_JOINTS:
                    raise MocapFormatError(path, f"more than {MAX_JOINTS:,} bones (motion_graph.errors.MAX_JOINTS)", ln)
                bones[cur.name] = cur
                cur = None
            elif cur is None:
                raise MocapFormatError(path, f"{quote(toks[0])} outside begin/end", ln)
            elif key == "name":
                cur.name = _value(path, toks, ln, "name")
                if len(cur.name) > MAX_NAME_CHARS:
                    raise MocapFormatError(path, f"bone name {quote(cur.name)} longer than {MAX_NAME_CHARS} characters", ln)
            elif key == "direction":
                cur.direction = _three(path, toks, ln, "direction")
            elif key == "length":
                cur.length = parse_finite(path, [_value(path, toks, ln, "length")], "length", ln)[0]
            elif key == "axis":
                if len(toks) != 5:
                    raise MocapFormatError(path, "axis needs 3 angles and an order", ln)
                cur.axis = np.array(parse_finite(path, toks[1:4], "axis", ln, None))
                cur.axis_order = _axis_order(path, toks[4], ln)
            elif key == "dof":
                cur.dofs = _dofs(path, toks[1:], ln, "dof", ("l",))
            elif key == "limits" or in_limits:
                in_limits = True
                vals = raw.replace("limits", " ").replace("(", " ").replace(")", " ").split(None, _MAX_LINE_VALUES)
                v = _limit_values(path, vals, ln)
                for k in range(0, len(v) - 1, 2):
                    cur.limits.append((v[k], v[k + 1]))
            elif key == "id":
                pass
        elif section == "hierarchy":
            if key in ("begin", "end"):
                continue
            hierarchy.append((toks[0], toks[1:], ln))
    if not bones:
        raise MocapFormatError(path, "no :bonedata section (is this an ASF file?)")
    if not hierarchy:
        raise MocapFormatError(path, "no :hierarchy section")
    if root_axis_line is not None:
        toks, ln = root_axis_line
        root_axis = _axis_order(path, _value(path, toks, ln, "root axis"), ln)
    children: dict[str, list[tuple[str, int]]] = {}  # parent -> (child, line)
    for parent, kids, ln in hierarchy:
        for k in kids:
            if k not in bones:
                raise MocapFormatError(path, f"hierarchy names unknown bone {quote(k)}", ln)
        if parent != "root" and parent not in bones:
            raise MocapFormatError(path, f"hierarchy names unknown bone {quote(parent)}", ln)
        children.setdefault(parent, []).extend((k, ln) for k in kids)

    s = scale if scale is not None else 0.0254 / length_unit
    if not (math.isfinite(s) and s > 0):
        raise MocapFormatError(path, f"units length {length_unit!r} gives no finite metres per unit", units_ln)
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[tuple[str, ...]] = []
    end_site: list[bool] = []
    order: list[str] = []
    # Depth-first, children in file order, a leaf bone's end site right after it; iterative, so
    # any depth is read, and a bone reached twice (a cycle, two parents) is refused.
    stack: list[tuple[str, int, np.ndarray, int | None]] = [("root", -1, root_pos, None)]
    reached: set[str] = set()
    while stack:
        name, parent_idx, offset, ln = stack.pop()
        if name in reached:
            raise MocapFormatError(path, f"bone {quote(name)} is reached twice in :hierarchy (a cycle or two parents)", ln)
        reached.add(name)
        kids = children.get(name, [])
        if len(names) + (0 if kids or name == "root" else 1) >= MAX_JOINTS:
            raise MocapFormatError(path, f"the hierarchy has more than {MAX_JOINTS:,} joints "
                                         "(motion_graph.errors.MAX_JOINTS)", ln)
        idx = len(names)
        names.append(name)
        parents.append(parent_idx)
        offsets.append(offset)
        end_site.append(False)
        order.append(name)
        if name == "root":
            channels.append(root_order)
            tip = np.zeros(3)
        else:
            b = bones[name]
            channels.append(b.dofs)
            tip = b.direction * b.length
            check_lengths(path, tip, f"bone {quote(name)} direction x length")
        if not kids and name != "root":
            names.append(f"{name}_End")
            parents.append(idx)
            offsets.append(tip)
            channels.append(())
            end_site.append(True)
            order.append(f"{name}_End")
        stack.extend((k, idx, tip, kln) for k, kln in reversed(kids))

    with np.errstate(over="ignore"):  # a huge metres_per_unit: refused just below
        offsets_m = np.array(offsets) * s
    check_lengths(path, offsets_m, f"bone offsets (x {s:g} metres per unit)")
    limits = {b.name: b.limits for b in bones.values() if b.limits}
    skel = Skeleton(tuple(names), np.array(parents), offsets_m, tuple(channels), np.array(end_site), s,
                    limits)
    root_bone = _Bone("root", axis=root_orient, axis_order=root_axis, dofs=root_order)
    bones = dict(bones)
    bones["root"] = root_bone
    return AsfSkeleton(bones, order, skel, angle_deg, root_order, root_axis, path)


def _compose(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """Rotation with the first axis of `order` applied first: R_{o[-1]} ... R_{o[0]}."""
    return euler_to_matrix(angles_deg[..., ::-1], order[::-1])


def load_amc(path: str | os.PathLike, asf: AsfSkeleton | str | os.PathLike, fps: float = CMU_FPS) -> Motion:
    """Load an AMC motion on its ASF skeleton (a parsed AsfSkeleton or the ASF path).

    Args:
        fps: the frame rate (finite, MIN_FPS..MAX_FPS of motion_graph.errors); CMU's 120 by default.
    Raises:
        MocapFormatError: naming the file and line of the first problem, or a bad fps.
    """
    path = str(path)
    rate = check_rate(path, fps)
    if not isinstance(asf, AsfSkeleton):
        asf = load_asf(asf)
    text = read_mocap_text(path)
    sk = asf.skeleton
    dof_bones = [n for n in asf.order if n in asf.bones and asf.bones[n].dofs]
    values = {n: array("d") for n in dof_bones}  # per bone, its values of all frames
    position_dofs = {n: [k for k, d in enumerate(b.dofs) if d in _DOF_POS] for n, b in asf.bones.items()
                     if any(d in _DOF_POS for d in b.dofs)}
    n_frames = 0
    cur: dict[str, list[float]] | None = None
    degrees = asf.angle_deg
    ln = 0
    for ln, raw in numbered_lines(text):
        toks = raw.split(None, 1)
        if not toks:
            continue
        if toks[0].startswith("#"):
            continue
        if toks[0].startswith(":"):
            if toks[0].upper() == ":RADIANS":
                degrees = False
            elif toks[0].upper() == ":DEGREES":
                degrees = True
            continue
        num = parse_whole(toks[0]) if len(toks) == 1 else None
        if num is not None:
            if num != n_frames + 1:
                raise MocapFormatError(path, f"frame number {quote(toks[0])} follows {n_frames}", ln)
            if num > MAX_FRAMES or num * sk.n_joints > MAX_FRAME_JOINTS:
                raise MocapFormatError(path, f"more than {min(MAX_FRAMES, MAX_FRAME_JOINTS // sk.n_joints):,} frames "
                                             "(motion_graph.errors.MAX_FRAMES, MAX_FRAME_JOINTS)", ln)
            if cur is not None:
                _store_frame(path, cur, values, ln)
            n_frames = num
            cur = {}
            continue
        name = toks[0]
        if cur is None:
            raise MocapFormatError(path, f"bone line {quote(name)} before the first frame number", ln)
        if name not in asf.bones or (name != "root" and not asf.bones[name].dofs):
            raise MocapFormatError(path, f"unknown bone {quote(name)} (not a bone with dofs in {asf.path})", ln)
        dofs = asf.bones[name].dofs
        want = len(dofs)
        rest = toks[1] if len(toks) > 1 else ""
        vals_t = rest.split(None, want)
        if len(vals_t) != want:
            got = count_tokens(rest) if len(vals_t) > want else len(vals_t)
            raise MocapFormatError(path, f"bone {quote(name)} has {got} values, the ASF declares {want} dofs", ln)
        vals = list(map(float, vals_t)) if is_number_row(rest) else None
        if vals is None or not all(map(math.isfinite, vals)):
            vals = parse_finite(path, vals_t, f"bone {quote(name)}", ln, None)
        for k in position_dofs.get(name, ()):
            if abs(vals[k]) > MAX_ABS_LENGTH:
                raise MocapFormatError(path, f"{dofs[k]} of bone {quote(name)} exceeds {MAX_ABS_LENGTH:g} "
                                             "(motion_graph.errors.MAX_ABS_LENGTH)", ln)
        cur[name] = vals
    if cur is None:
        raise MocapFormatError(path, "no frames")
    _store_frame(path, cur, values, ln, last=True)
    del text

    T, J = n_frames, sk.n_joints
    rotations = np.empty((T, J, 4))
    rotations[:] = matrix_to_quat(np.eye(3)[None])[0]
    root_pos = np.zeros((T, 3))
    conv = 1.0 if degrees else np.degrees(1.0)
    for j, name in enumerate(sk.names):
        b = asf.bones.get(name)
        if b is None or not b.dofs:
            continue
        vals = np.frombuffer(values[name], dtype=np.float64).reshape(T, len(b.dofs))
        rot_idx = [k for k, d in enumerate(b.dofs) if d in _DOF_ROT]
        if name == "root":
            with np.errstate(over="ignore"):  # a huge metres_per_unit: refused below
                for k, d in enumerate(b.dofs):
                    if d in _DOF_POS:
                        root_pos[:, _DOF_POS[d]] = vals[:, k] * sk.metres_per_unit
        if not rot_idx:
            continue
        order = "".join(_DOF_ROT[b.dofs[k]] for k in rot_idx)
        with np.errstate(over="ignore", invalid="ignore"):  # overflowing angles are refused below
            M = _compose(vals[:, rot_idx] * conv, order)
            C = _compose(b.axis * (1.0 if asf.angle_deg else np.degrees(1.0)), b.axis_order)
            local = C @ M @ C.T
        if not np.isfinite(local).all():
            raise MocapFormatError(path, f"rotation of bone {quote(name)} is not finite (angles too large)")
        rotations[:, j] = matrix_to_quat(local)
    root_pos += sk.offsets[0]
    check_lengths(path, root_pos, f"root positions (x {sk.metres_per_unit:g} metres per unit)")
    return Motion(sk, rotations, root_pos, rate, None, path)


def _store_frame(path: str, frame: dict[str, list[float]], values: dict[str, array], ln: int,
                 last: bool = False) -> None:
    """Append a complete frame's values to the per-bone arrays."""
    missing = [b for b in values if b not in frame]
    if missing:
        what = "file truncated: last frame" if last else "frame"
        raise MocapFormatError(path, f"{what} lacks bone {quote(missing[0])}", ln)
    for b, arr in values.items():
        arr.extend(frame[b])


def load_asf_amc(amc_path: str | os.PathLike, asf_path: str | os.PathLike | None = None, fps: float = CMU_FPS) -> Motion:
    """Load an AMC file; the ASF is found beside it (``13_17.amc`` -> ``13.asf``) unless given."""
    amc_path = Path(amc_path)
    if asf_path is None:
        asf_path = find_asf_for(amc_path)
    return load_amc(amc_path, asf_path, fps)


def find_asf_for(amc_path: Path) -> Path:
    """The ASF beside an AMC: same stem, or the subject prefix before '_' (CMU naming)."""
    cands = [amc_path.with_suffix(".asf"), amc_path.parent / (amc_path.stem.split("_")[0] + ".asf")]
    for c in cands:
        if c.exists():
            return c
    asfs = sorted(amc_path.parent.glob("*.asf"))
    if len(asfs) == 1:
        return asfs[0]
    raise MocapFormatError(str(amc_path), f"no ASF skeleton found beside it (looked for {', '.join(c.name for c in cands)})")
