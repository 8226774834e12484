"""What the page draws of a fighter: which joints, the bones between them as capsules (with radii),
the head sphere and the gloves; and the joints' world positions at a frame of a bout.

A bone is drawn between a joint and its parent when it is at least MIN_BONE_M long in the
library's first frame (zero-length helper joints of the CMU skeleton drop out); end sites and
finger joints are left out. The trunk (the chain from the pelvis to the head) gets thick
capsules, the limbs thinner ones by their length.
"""
from __future__ import annotations

import numpy as np

MIN_BONE_M = 0.03
#: joint names containing these (case-insensitive) are not drawn
SKIP_NAMES = ("_end", "end site", "finger", "index", "thumb", "toe_end")


def body_drawing(lib) -> dict:
    """{"joints": library joint indices sent per frame, "bones": [[i, j], ...] indices into joints,
    "radii": capsule radius (m) per bone, "pelvis", "neck", "head": indices into joints (-1: none),
    "head_radius", "fists": [left, right] indices into joints (or -1), "fist_radius", "names"}."""
    names = [str(n) for n in lib.skeleton.names]
    parents = np.asarray(lib.skeleton.parents)
    pos0 = np.asarray(lib.positions[0])
    keep = [j for j, n in enumerate(names) if not any(s in n.lower() for s in SKIP_NAMES)]
    for part in ("head", "l_fist", "r_fist", "pelvis"):
        j = lib.parts.get(part)
        if j is not None and j not in keep:
            keep.append(int(j))
    keep.sort()
    index = {j: k for k, j in enumerate(keep)}
    trunk = set()
    j = lib.parts.get("head")
    while j is not None and j >= 0:
        trunk.add(int(j))
        j = int(parents[j]) if parents[j] >= 0 else None
    bones, radii = [], []
    for j in keep:
        p = int(parents[j])
        while p >= 0 and p not in index:  # skip joints not drawn
            p = int(parents[p])
        if p < 0:
            continue
        length = float(np.linalg.norm(pos0[j] - pos0[p]))
        if length < MIN_BONE_M:
            continue
        bones.append([index[p], index[j]])
        if j in trunk and p in trunk:
            radii.append(0.11)
        else:
            radii.append(float(np.clip(0.16 * length, 0.035, 0.075)))
    head = lib.parts.get("head")
    neck = lib.parts.get("neck")
    pelvis = lib.parts.get("pelvis", 0)
    fists = [lib.parts.get("l_fist"), lib.parts.get("r_fist")]
    return {"joints": keep, "bones": bones, "radii": radii, "names": [names[j] for j in keep],
            "pelvis": index.get(pelvis, 0), "neck": index.get(neck, -1) if neck is not None else -1,
            "head": index.get(head, -1) if head is not None else -1, "head_radius": 0.11,
            "fists": [index.get(f, -1) if f is not None else -1 for f in fists], "fist_radius": 0.06}


def world_positions(lib, world, joints) -> np.ndarray:
    """(2, len(joints), 3) world positions (m, Y up) of both fighters' ``joints`` in a
    WorldState: each fighter's library frame placed by the start transform that puts the
    library path's pelvis and heading at the fighter's (x, z, heading) (as match.fighter_motion)."""
    offs = np.asarray(lib.frame_offsets)
    g = offs[np.asarray(world.action)] + np.asarray(world.frame)
    path = np.asarray(lib.path)[g]
    sh = np.asarray(world.heading) - path[:, 2]
    c, s = np.cos(sh), np.sin(sh)
    sx = np.asarray(world.x) - (c * path[:, 0] + s * path[:, 1])
    sz = np.asarray(world.z) - (-s * path[:, 0] + c * path[:, 1])
    p = np.asarray(lib.positions)[g][:, joints]          # (2, J, 3) in each action's frame
    out = np.empty_like(p)
    out[..., 0] = c[:, None] * p[..., 0] + s[:, None] * p[..., 2] + sx[:, None]
    out[..., 1] = p[..., 1]
    out[..., 2] = -s[:, None] * p[..., 0] + c[:, None] * p[..., 2] + sz[:, None]
    return out
