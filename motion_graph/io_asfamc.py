"""CMU ASF (skeleton) + AMC (motion) reader.

Conventions (as in the CMU database and its common BVH conversions):
- ``:units length L``: one file length unit is 1/L inch, so metres per unit = 0.0254 / L
  (CMU: L = 0.45, about 5.64 cm per unit). Angles in degrees unless ``angle rad``.
- A joint is put at the start of every bone; its offset is the parent bone's
  ``direction * length`` (zero under the root); leaf bones get an end site at their tip.
- Local rotation of bone b: C_b M_b C_b^-1, with C_b the bone's ``axis`` rotation and M_b the
  AMC rotation, both composed so the first listed axis is applied first (order XYZ -> Rz Ry Rx).
- AMC files carry no frame rate; CMU captured at 120 fps, the default here.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motion_graph.errors import MocapFormatError
from motion_graph.motion import Motion
from motion_graph.rotations import euler_to_matrix, matrix_to_quat
from motion_graph.skeleton import Skeleton

CMU_FPS = 120.0
_DOF_ROT = {"rx": "X", "ry": "Y", "rz": "Z"}
_DOF_POS = {"tx": 0, "ty": 1, "tz": 2}


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


def _lines(path: str) -> list[str]:
    try:
        text = Path(path).read_text(encoding="utf-8", errors="replace")
    except OSError as e:
        raise MocapFormatError(path, f"cannot read file: {e.strerror}") from None
    lines = text.splitlines()
    if not any(l.strip() for l in lines):
        raise MocapFormatError(path, "empty file")
    return lines


def _floats(path: str, toks: list[str], ln: int, what: str) -> list[float]:
    out = []
    for t in toks:
        try:
            out.append(float(t))
        except ValueError:
            raise MocapFormatError(path, f"non-numeric value {t!r} in {what}", ln) from None
    return out


def load_asf(path: str | os.PathLike, metres_per_unit: float | None = None) -> AsfSkeleton:
    """Parse an ASF skeleton file (lengths converted to metres)."""
    path = str(path)
    lines = _lines(path)
    length_unit = 1.0
    angle_deg = True
    root_order: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz")
    root_axis = "XYZ"
    root_orient = np.zeros(3)
    root_pos = np.zeros(3)
    bones: dict[str, _Bone] = {}
    hierarchy: list[tuple[str, list[str], int]] = []
    section = None
    cur: _Bone | None = None
    in_limits = False
    for i, raw in enumerate(lines):
        ln = i + 1
        toks = raw.split()
        if not toks or toks[0].startswith("#"):
            continue
        if toks[0].startswith(":"):
            section = toks[0][1:]
            in_limits = False
            continue
        key = toks[0].lower()
        if section == "units":
            if key == "length" and len(toks) >= 2:
                length_unit = _floats(path, toks[1:2], ln, "units length")[0]
                if length_unit <= 0:
                    raise MocapFormatError(path, "units length must be positive", ln)
            elif key == "angle" and len(toks) >= 2:
                angle_deg = toks[1].lower().startswith("deg")
        elif section == "root":
            if key == "order":
                root_order = tuple(t.lower() for t in toks[1:])
                bad = [t for t in root_order if t not in _DOF_ROT and t not in _DOF_POS]
                if bad:
                    raise MocapFormatError(path, f"unknown root channel {bad[0]!r}", ln)
            elif key == "axis":
                root_axis = toks[1].upper()
            elif key == "position":
                root_pos = np.array(_floats(path, toks[1:4], ln, "root position"))
            elif key == "orientation":
                root_orient = np.array(_floats(path, toks[1:4], ln, "root orientation"))
        elif section == "bonedata":
            if key == "begin":
                cur = _Bone(name="")
                in_limits = False
            elif key == "end":
                if cur is None or not cur.name:
                    raise MocapFormatError(path, "bone without a name", ln)
                bones[cur.name] = cur
                cur = None
            elif cur is None:
                raise MocapFormatError(path, f"{toks[0]!r} outside begin/end", ln)
            elif key == "name":
                cur.name = toks[1]
            elif key == "direction":
                if len(toks) != 4:
                    raise MocapFormatError(path, "direction needs 3 numbers", ln)
                cur.direction = np.array(_floats(path, toks[1:], ln, "direction"))
            elif key == "length":
                cur.length = _floats(path, toks[1:2], ln, "length")[0]
            elif key == "axis":
                if len(toks) != 5:
                    raise MocapFormatError(path, "axis needs 3 angles and an order", ln)
                cur.axis = np.array(_floats(path, toks[1:4], ln, "axis"))
                cur.axis_order = toks[4].upper()
            elif key == "dof":
                cur.dofs = tuple(t.lower() for t in toks[1:])
                bad = [t for t in cur.dofs if t not in _DOF_ROT and t not in _DOF_POS and t != "l"]
                if bad:
                    raise MocapFormatError(path, f"unknown dof {bad[0]!r}", ln)
            elif key == "limits" or in_limits:
                in_limits = True
                vals = raw.replace("limits", " ").replace("(", " ").replace(")", " ").split()
                v = _floats(path, vals, ln, "limits")
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
    children: dict[str, list[str]] = {}
    for parent, kids, ln in hierarchy:
        for k in kids:
            if k not in bones:
                raise MocapFormatError(path, f"hierarchy names unknown bone {k!r}", ln)
        if parent != "root" and parent not in bones:
            raise MocapFormatError(path, f"hierarchy names unknown bone {parent!r}", ln)
        children.setdefault(parent, []).extend(kids)

    s = float(metres_per_unit) if metres_per_unit is not None else 0.0254 / length_unit
    names: list[str] = []
    parents: list[int] = []
    offsets: list[np.ndarray] = []
    channels: list[tuple[str, ...]] = []
    end_site: list[bool] = []
    order: list[str] = []

    def visit(name: str, parent_idx: int, offset: np.ndarray) -> None:
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
        kids = children.get(name, [])
        for k in kids:
            visit(k, idx, tip)
        if not kids and name != "root":
            names.append(f"{name}_End")
            parents.append(idx)
            offsets.append(tip)
            channels.append(())
            end_site.append(True)
            order.append(f"{name}_End")

    visit("root", -1, root_pos)
    limits = {b.name: b.limits for b in bones.values() if b.limits}
    skel = Skeleton(tuple(names), np.array(parents), np.array(offsets) * s, tuple(channels), np.array(end_site), s,
                    limits)
    root_bone = _Bone("root", axis=root_orient, axis_order=root_axis, dofs=root_order)
    bones = dict(bones)
    bones["root"] = root_bone
    return AsfSkeleton(bones, order, skel, angle_deg, root_order, root_axis, path)


def _compose(angles_deg: np.ndarray, order: str) -> np.ndarray:
    """Rotation with the first axis of `order` applied first: R_{o[-1]} ... R_{o[0]}."""
    return euler_to_matrix(angles_deg[..., ::-1], order[::-1])


def load_amc(path: str | os.PathLike, asf: AsfSkeleton | str | os.PathLike, fps: float = CMU_FPS) -> Motion:
    """Load an AMC motion on its ASF skeleton (a parsed AsfSkeleton or the ASF path)."""
    if not isinstance(asf, AsfSkeleton):
        asf = load_asf(asf)
    path = str(path)
    lines = _lines(path)
    sk = asf.skeleton
    dof_bones = [n for n in asf.order if n in asf.bones and asf.bones[n].dofs]
    frames: list[dict[str, list[float]]] = []
    cur: dict[str, list[float]] | None = None
    degrees = asf.angle_deg
    last_num = 0
    for i, raw in enumerate(lines):
        ln = i + 1
        toks = raw.split()
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
        if len(toks) == 1 and toks[0].isdigit():
            num = int(toks[0])
            if num != last_num + 1:
                raise MocapFormatError(path, f"frame number {num} follows {last_num}", ln)
            last_num = num
            if cur is not None:
                _check_frame(path, cur, dof_bones, ln)
            cur = {}
            frames.append(cur)
            continue
        if cur is None:
            raise MocapFormatError(path, f"bone line {toks[0]!r} before the first frame number", ln)
        name = toks[0]
        if name not in asf.bones or (name != "root" and not asf.bones[name].dofs):
            raise MocapFormatError(path, f"unknown bone {name!r} (not a bone with dofs in {asf.path})", ln)
        want = len(asf.bones[name].dofs)
        if len(toks) - 1 != want:
            raise MocapFormatError(path, f"bone {name!r} has {len(toks) - 1} values, the ASF declares {want} dofs", ln)
        vals = _floats(path, toks[1:], ln, f"bone {name!r}")
        if not all(map(math.isfinite, vals)):
            raise MocapFormatError(path, f"non-finite value (nan/inf) in bone {name!r}", ln)
        cur[name] = vals
    if not frames:
        raise MocapFormatError(path, "no frames")
    _check_frame(path, frames[-1], dof_bones, len(lines), last=True)

    T, J = len(frames), sk.n_joints
    local = np.broadcast_to(np.eye(3), (T, J, 3, 3)).copy()
    root_pos = np.zeros((T, 3))
    conv = 1.0 if degrees else np.degrees(1.0)
    for j, name in enumerate(sk.names):
        b = asf.bones.get(name)
        if b is None or not b.dofs:
            continue
        vals = np.array([f[name] for f in frames])
        rot_idx = [k for k, d in enumerate(b.dofs) if d in _DOF_ROT]
        if name == "root":
            for k, d in enumerate(b.dofs):
                if d in _DOF_POS:
                    root_pos[:, _DOF_POS[d]] = vals[:, k] * sk.metres_per_unit
        if not rot_idx:
            continue
        order = "".join(_DOF_ROT[b.dofs[k]] for k in rot_idx)
        M = _compose(vals[:, rot_idx] * conv, order)
        C = _compose(b.axis * (1.0 if asf.angle_deg else np.degrees(1.0)), b.axis_order)
        local[:, j] = C @ M @ C.T
    root_pos += sk.offsets[0]
    return Motion(sk, matrix_to_quat(local), root_pos, float(fps), None, path)


def _check_frame(path: str, frame: dict, dof_bones: list[str], ln: int, last: bool = False) -> None:
    missing = [b for b in dof_bones if b not in frame]
    if missing:
        what = "file truncated: last frame" if last else "frame"
        raise MocapFormatError(path, f"{what} lacks bone {missing[0]!r}", ln)


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
