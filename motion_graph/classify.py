"""Label actions from arm and foot trajectories, relative to the action's start frame.

Labels (``KINDS``): attacks ``jab`` (lead-hand straight), ``straight`` (rear-hand straight),
``hook``, ``uppercut``, ``kick``; defences ``duck`` (head drops), ``dodge`` (head slips sideways
or sways back); movement ``step_forward``, ``step_back``, ``step_left``, ``step_right``,
``turn_left``, ``turn_right``; and ``guard`` (near-still). A user label file overrides them.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from motion_graph.errors import LibraryFormatError
from motion_graph.features import ClipFeatures, to_local
from motion_graph.rotations import wrap_angle
from motion_graph.strikes import Strike

ATTACK_KINDS = ("jab", "straight", "hook", "uppercut", "kick")
DEFENCE_KINDS = ("duck", "dodge")
MOVE_KINDS = ("step_forward", "step_back", "step_left", "step_right", "turn_left", "turn_right")
KINDS = ATTACK_KINDS + DEFENCE_KINDS + MOVE_KINDS + ("guard",)


@dataclass(frozen=True)
class ClassifyParams:
    """Thresholds in metres and radians."""

    step_m: float = 0.15            # root displacement that makes a step
    turn_rad: float = np.radians(35.0)
    duck_m: float = 0.10            # head drop below its start height (relative to the pelvis path)
    dodge_m: float = 0.12           # sideways / backward head shift relative to the root path
    uppercut_rise_m: float = 0.25
    hook_lateral_m: float = 0.35


@dataclass
class Annotation:
    """What one action is and does, in its start frame (metres, radians, frames of the clip rate).

    dx, dz, dheading: root displacement at the end (+z forward, +x left) and heading change.
    strikes: (limb, kind, w0, w1, peak, reach_m) per strike, frames relative to the action start;
        reach_m is the horizontal distance of the striking point from the root at the peak.
    defence: (w0, w1) frames of the defence window, or None.
    """

    label: str
    dx: float
    dz: float
    dheading: float
    strikes: list[tuple[str, str, int, int, int, float]]
    defence: tuple[int, int] | None


def punch_kind(feat: ClipFeatures, s: Strike, heading: float, params: ClassifyParams) -> str:
    """straight/jab, hook or uppercut from the fist path (start -> peak) relative to the shoulder."""
    side = s.limb[0]
    P, p = feat.positions, feat.parts
    L = to_local(P[[s.start, s.peak]], P[s.start, p["pelvis"]], heading)
    rel = L[:, p[f"{side}_fist"]] - L[:, p[f"{side}_shoulder"]]
    rise = rel[1, 1] - rel[0, 1]
    fwd = rel[1, 2] - rel[0, 2]
    toward_mid = (rel[1, 0] - rel[0, 0]) * (-1.0 if side == "l" else 1.0)
    if rise >= params.uppercut_rise_m and rise >= 1.2 * max(fwd, 0.0) and toward_mid < rise:
        return "uppercut"
    if toward_mid >= params.hook_lateral_m and toward_mid >= 1.5 * max(fwd, 0.0):
        return "hook"
    lead_left = L[0, p["l_ankle"], 2] > L[0, p["r_ankle"], 2]
    return "jab" if (side == "l") == lead_left else "straight"


def annotate(feat: ClipFeatures, strikes: list[Strike], a: int, b: int, offset: float,
             params: ClassifyParams = ClassifyParams()) -> Annotation:
    """Label and annotate the action spanning frames [a, b] of a clip.

    offset: the clip's stance offset (fighting direction minus head facing, radians).
    Displacements are measured in the fighting frame at the start; turns from the hip heading.
    """
    P, p = feat.positions, feat.parts
    h0 = feat.facing[a] + offset
    origin = P[a, p["pelvis"]]
    L = to_local(P[a:b + 1], origin, h0)
    end = L[-1, p["pelvis"]]
    dx, dz = float(end[0]), float(end[2])
    dheading = float(wrap_angle(feat.heading[b] - feat.heading[a]))
    mine = [s for s in strikes if a <= s.peak <= b]
    ann_strikes = []
    for s in mine:
        kind = "kick" if s.limb.endswith("toe") else punch_kind(feat, s, feat.facing[s.start] + offset, params)
        tip = L[s.peak - a, p[s.limb]]
        root = L[s.peak - a, p["pelvis"]]
        reach = float(np.hypot(tip[0] - root[0], tip[2] - root[2]))
        ann_strikes.append((s.limb, kind, max(0, s.w0 - a), min(b - a + 1, s.w1 - a), s.peak - a, reach))
    if ann_strikes:
        main = max(ann_strikes, key=lambda st: st[5])
        return Annotation(main[1], dx, dz, dheading, ann_strikes, None)

    # Defences: the head leaves its place above the pelvis (in the body's own turning frame)
    # and the body does not travel far.
    hd = feat.facing[a:b + 1] + offset  # the fighting frame turning with the head
    d = P[a:b + 1, p["head"]] - P[a:b + 1, p["pelvis"]]
    c, sn = np.cos(hd), np.sin(hd)
    lateral = c * d[:, 0] - sn * d[:, 2]
    forward = sn * d[:, 0] + c * d[:, 2]
    drop = P[a, p["head"], 1] - P[a:b + 1, p["head"], 1]
    side = np.abs(lateral - lateral[0])
    back = forward[0] - forward
    disp = np.maximum.reduce([drop / params.duck_m, side / params.dodge_m, back / params.dodge_m])
    moved = float(np.hypot(dx, dz))
    if disp.max() >= 1.0 and moved < 2 * params.step_m and abs(dheading) < params.turn_rad:
        k = int(np.argmax(disp))
        w = np.nonzero(disp >= 0.6 * disp.max())[0]
        label = "duck" if drop[k] / params.duck_m >= max(side[k], back[k]) / params.dodge_m else "dodge"
        return Annotation(label, dx, dz, dheading, [], (int(w[0]), int(w[-1]) + 1))
    if abs(dheading) >= params.turn_rad:
        return Annotation("turn_left" if dheading > 0 else "turn_right", dx, dz, dheading, [], None)
    if moved >= params.step_m:
        ang = np.degrees(np.arctan2(dx, dz))
        if -45 <= ang <= 45:
            label = "step_forward"
        elif ang >= 135 or ang <= -135:
            label = "step_back"
        else:
            label = "step_left" if ang > 0 else "step_right"
        return Annotation(label, dx, dz, dheading, [], None)
    return Annotation("guard", dx, dz, dheading, [], None)


def load_label_file(path: str | os.PathLike) -> dict[tuple[str, int], str]:
    """Read user labels: JSON list of {"source": file name or path, "start": frame, "label": kind}
    or a text file with lines ``source start label`` ('#' comments). Frames are source frames."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise LibraryFormatError(str(path), f"cannot read label file: {e.strerror}") from None
    out: dict[tuple[str, int], str] = {}
    if path.suffix.lower() == ".json":
        try:
            rows = json.loads(text)
        except json.JSONDecodeError as e:
            raise LibraryFormatError(str(path), f"invalid JSON: {e}") from None
        if not isinstance(rows, list):
            raise LibraryFormatError(str(path), "expected a JSON list of {source, start, label}")
        for i, r in enumerate(rows):
            try:
                out[(Path(r["source"]).name, int(r["start"]))] = _check_label(str(r["label"]), path, i + 1)
            except (KeyError, TypeError, ValueError):
                raise LibraryFormatError(str(path), f"entry {i + 1}: needs source, start (int) and label") from None
    else:
        for i, line in enumerate(text.splitlines()):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            parts = line.split()
            if len(parts) != 3 or not parts[1].lstrip("-").isdigit():
                raise LibraryFormatError(str(path), f"line {i + 1}: expected 'source start_frame label'")
            out[(Path(parts[0]).name, int(parts[1]))] = _check_label(parts[2], path, i + 1)
    return out


def _check_label(label: str, path: Path, where: int) -> str:
    if label not in KINDS:
        raise LibraryFormatError(str(path), f"line/entry {where}: unknown label {label!r}; known: {', '.join(KINDS)}")
    return label
