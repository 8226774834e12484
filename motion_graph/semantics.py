"""Map joint names of common skeletons to semantic body parts.

Parts: pelvis, belly, chest, neck, head, head_top, and per side (l_/r_) shoulder (upper arm joint),
elbow, wrist, fist, hip, knee, ankle, toe. Names are matched case-insensitively after removing
'_', '-', ':' and spaces, and any 'mixamorig' style prefix. An override file (JSON object
``{"part": "JointName"}``) fixes or completes the map for unknown skeletons.
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

from motion_graph.errors import MocapFormatError, shorten
from motion_graph.skeleton import Skeleton

PARTS = ("pelvis", "belly", "chest", "neck", "head", "head_top",
         "l_shoulder", "l_elbow", "l_wrist", "l_fist", "l_hip", "l_knee", "l_ankle", "l_toe",
         "r_shoulder", "r_elbow", "r_wrist", "r_fist", "r_hip", "r_knee", "r_ankle", "r_toe")

#: Candidate names per part, most specific first (normalised: lower case, no separators).
_CANDIDATES: dict[str, tuple[str, ...]] = {
    "pelvis": ("hips", "pelvis", "hip", "root"),
    "belly": ("lowerback", "spine", "spine01", "abdomen", "waist"),
    "chest": ("spine1", "chest", "thorax", "upperback", "spine2", "spine02", "upperchest"),
    "neck": ("neck", "lowerneck", "neck1"),
    "head": ("head",),
    "head_top": ("headend", "headtopend", "headtop", "headsiteend"),
    "shoulder": ("{s}arm", "upperarm{s}", "{s}upperarm", "{s}humerus", "{x}humerus", "{s}shoulder"),
    "elbow": ("{s}forearm", "lowerarm{s}", "{s}lowerarm", "{s}elbow", "{x}radius", "forearm{s}"),
    "wrist": ("{x}wrist", "{s}hand", "hand{s}", "{s}wrist", "wrist{s}"),
    "fist": ("{s}fingerbase", "{x}hand", "hand{s}end", "{s}handend", "{s}handindex1", "{s}hand"),
    "hip": ("{s}upleg", "upperleg{s}", "{s}upperleg", "{x}femur", "{s}thigh", "{s}hip"),
    "knee": ("{s}leg", "lowerleg{s}", "{s}lowerleg", "{x}tibia", "{s}shin", "{s}knee"),
    "ankle": ("{s}foot", "foot{s}", "{x}foot", "{s}ankle"),
    "toe": ("{s}toebase", "toes{s}", "{x}toes", "{s}toe", "{s}toes", "toe{s}", "{s}footend"),
}


def normalise(name: str) -> str:
    n = name.lower()
    n = re.sub(r"^.*:", "", n)
    return re.sub(r"[\s_\-:.]", "", n)


def resolve_parts(skeleton: Skeleton, overrides: dict[str, str] | None = None) -> dict[str, int]:
    """Semantic part -> joint index for a skeleton. Missing parts are absent from the result."""
    norm = {normalise(n): i for i, n in enumerate(skeleton.names)}
    out: dict[str, int] = {}
    for part in PARTS:
        if "_" in part and part[1] == "_":
            side, base = part[0], part[2:]
            words = {"s": "left" if side == "l" else "right", "x": side}
            cands = []
            for c in _CANDIDATES[base]:
                cands.append(c.format(s=words["s"], x=words["x"]))
                if "{s}" in c:  # short side markers: LArm, ArmL, l_arm
                    cands.append(c.format(s=side, x=side))
        else:
            cands = list(_CANDIDATES[part])
        for c in cands:
            if c in norm:
                out[part] = norm[c]
                break
    # Head top: the end site under the head when nothing else matched.
    if "head_top" not in out and "head" in out:
        kids = [k for k in skeleton.children(out["head"]) if skeleton.is_end_site[k]]
        if kids:
            out["head_top"] = kids[0]
    for side in "lr":
        # Fist: prefer a point past the wrist (hand end site) when no finger joint matched.
        if f"{side}_fist" not in out and f"{side}_wrist" in out:
            kids = skeleton.children(out[f"{side}_wrist"])
            out[f"{side}_fist"] = kids[0] if kids else out[f"{side}_wrist"]
        if f"{side}_toe" not in out and f"{side}_ankle" in out:
            kids = skeleton.children(out[f"{side}_ankle"])
            if kids:
                out[f"{side}_toe"] = kids[0]
    if overrides:
        for part, jname in overrides.items():
            if part not in PARTS:
                raise KeyError(f"unknown semantic part {part!r}; known: {', '.join(PARTS)}")
            out[part] = skeleton.index(jname)
    return out


#: Most characters of the joint list require_parts' message shows.
JOINT_LIST_CHARS = 400

#: Parts every pipeline stage needs.
REQUIRED_PARTS = ("pelvis", "chest", "head", "l_shoulder", "r_shoulder", "l_fist", "r_fist",
                  "l_ankle", "r_ankle", "l_toe", "r_toe", "l_hip", "r_hip")


def load_part_overrides(path: str | os.PathLike) -> dict[str, str]:
    """Read a JSON override file ``{"part": "JointName", ...}``."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise MocapFormatError(str(path), f"cannot read joint-map override: {e}") from None
    if not isinstance(data, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
        raise MocapFormatError(str(path), 'joint-map override must be a JSON object {"part": "JointName"}')
    return data


def require_parts(skeleton: Skeleton, parts: dict[str, int], source: str) -> None:
    """Raise a clear error listing semantic parts that could not be found."""
    missing = [p for p in REQUIRED_PARTS if p not in parts]
    if missing:
        joints = shorten(", ".join(skeleton.names), JOINT_LIST_CHARS)
        raise MocapFormatError(source, f"cannot find joints for {', '.join(missing)}; give a joint-map override "
                                       f"file (JSON {{\"part\": \"JointName\"}}). Joints ({skeleton.n_joints}): {joints}")
