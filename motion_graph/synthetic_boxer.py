"""A tiny procedural boxer, for fast unit tests only.

Not mocap: a stick figure whose arms and legs are driven by simple joint-angle curves (guard,
a rear-hand straight punch, a knee lift). Every figure, benchmark and demo uses real mocap;
this exists so that parsers, contacts, strike detection and library plumbing can be tested in
milliseconds.
"""
from __future__ import annotations

import numpy as np

from motion_graph.motion import Motion
from motion_graph.rotations import euler_to_matrix, matrix_to_quat
from motion_graph.skeleton import Skeleton

_JOINTS = [  # name, parent, offset (m) in a rest pose with arms and legs hanging straight down
    ("Hips", -1, (0.0, 0.0, 0.0)),
    ("Spine", 0, (0.0, 0.12, 0.0)),
    ("Spine1", 1, (0.0, 0.22, 0.0)),
    ("Neck", 2, (0.0, 0.20, 0.0)),
    ("Head", 3, (0.0, 0.10, 0.0)),
    ("Head_End", 4, (0.0, 0.15, 0.0)),
    ("LeftArm", 2, (0.19, 0.16, 0.0)),
    ("LeftForeArm", 6, (0.0, -0.29, 0.0)),
    ("LeftHand", 7, (0.0, -0.26, 0.0)),
    ("LeftHand_End", 8, (0.0, -0.08, 0.0)),
    ("RightArm", 2, (-0.19, 0.16, 0.0)),
    ("RightForeArm", 10, (0.0, -0.29, 0.0)),
    ("RightHand", 11, (0.0, -0.26, 0.0)),
    ("RightHand_End", 12, (0.0, -0.08, 0.0)),
    ("LeftUpLeg", 0, (0.10, -0.05, 0.0)),
    ("LeftLeg", 14, (0.0, -0.42, 0.0)),
    ("LeftFoot", 15, (0.0, -0.42, 0.0)),
    ("LeftToeBase", 16, (0.0, -0.07, 0.12)),
    ("LeftToeBase_End", 17, (0.0, 0.0, 0.06)),
    ("RightUpLeg", 0, (-0.10, -0.05, 0.0)),
    ("RightLeg", 19, (0.0, -0.42, 0.0)),
    ("RightFoot", 20, (0.0, -0.42, 0.0)),
    ("RightToeBase", 21, (0.0, -0.07, 0.12)),
    ("RightToeBase_End", 22, (0.0, 0.0, 0.06)),
]
PELVIS_HEIGHT_M = 0.96


def synthetic_skeleton() -> Skeleton:
    """The stick figure's skeleton (metres, Y up, facing +Z)."""
    names = tuple(j[0] for j in _JOINTS)
    end = np.array([n.endswith("_End") for n in names])
    channels = tuple(() if e else (("Xposition", "Yposition", "Zposition") if i == 0 else ()) +
                     ("Zrotation", "Yrotation", "Xrotation") for i, e in enumerate(end))
    return Skeleton(names, np.array([j[1] for j in _JOINTS]), np.array([j[2] for j in _JOINTS], float),
                    channels, end, 1.0)


def _bump(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 outside [t0, t1], a smooth 0 -> 1 -> 0 hump inside."""
    u = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    return np.sin(np.pi * u) ** 2


def synthetic_boxer(duration_s: float = 4.0, fps: float = 120.0, punch_at_s: tuple[float, ...] = (1.0,),
                    knee_lift_at_s: tuple[float, ...] = (2.6,), step_at_s: tuple[float, ...] = (),
                    step_m: float = 0.3) -> Motion:
    """Guard stance, rear-hand (right) straight punches peaking at the given times (0.4 s each),
    left knee lifts (0.5 s each) and forward steps of step_m metres (the body glides, 0.6 s each)."""
    sk = synthetic_skeleton()
    T = int(round(duration_s * fps)) + 1
    t = np.arange(T) / fps
    J = sk.n_joints
    eul = np.zeros((T, J, 3))  # X, Y, Z angles in degrees, applied as Rz Ry Rx (ZYX channel order)
    idx = {n: i for i, n in enumerate(sk.names)}
    punch = np.zeros(T)
    for p in punch_at_s:
        punch = np.maximum(punch, _bump(t, p - 0.2, p + 0.2))
    # Guard: upper arms 45 degrees forward-down, forearms bent up; a punch straightens the right arm.
    for side, sgn in (("Left", 1.0), ("Right", 1.0)):
        sh = -40.0 * np.ones(T)
        el = -110.0 * np.ones(T)
        if side == "Right":
            sh = sh + (-90.0 + 40.0) * punch
            el = el * (1.0 - punch)
        eul[:, idx[f"{side}Arm"], 0] = sh
        eul[:, idx[f"{side}ForeArm"], 0] = el
    knee = np.zeros(T)
    for k in knee_lift_at_s:
        knee = np.maximum(knee, _bump(t, k - 0.25, k + 0.25))
    # Orthodox stance: left foot a little forward, right foot back.
    eul[:, idx["LeftUpLeg"], 0] = -10.0 - 50.0 * knee
    eul[:, idx["RightUpLeg"], 0] = 10.0
    eul[:, idx["LeftLeg"], 0] = 90.0 * knee
    root = np.zeros((T, 3))
    root[:, 1] = PELVIS_HEIGHT_M
    for s in step_at_s:
        u = np.clip((t - (s - 0.3)) / 0.6, 0.0, 1.0)
        root[:, 2] += step_m * (3 * u ** 2 - 2 * u ** 3)
    rot = euler_to_matrix(eul[..., ::-1], "ZYX")
    return Motion(sk, matrix_to_quat(rot), root, float(fps), None, "synthetic_boxer")
