"""MJCF builder: a physics humanoid generated from any mocap skeleton, one or two per ring scene.

Design (measurements behind it in docs/tracker.md):
- Generated from the skeleton, not a retargeted dm_control CMU humanoid: the model then matches the
  kinematic skeleton exactly (joint sites sit where forward kinematics puts the joints), for every
  skeleton in ../shared/mocap, with no retargeting error to explain away.
- One body per joint that moves (FighterSpec.dof); static joints (CMU hip joints, clavicles) and the
  fingers/thumbs are welded into their parent body at their rest rotation.
- Ball joints (quaternions) by default; ``joint_type="hinge3"`` gives three hinges (Z, Y, X) for comparison.
  The joint's qpos is the rotation relative to the rest rotation baked into the body.
- Geometry: capsules along bones with radii per body segment, a sphere head, sphere fists, contact
  spheres under heel, ball of the foot and toe tips (a toe joint lets the fighter stand on the balls
  of the feet); the body is scaled to ``spec.mass_kg`` (default 70 kg) with uniform density.
- PD lives in MuJoCo: per actuated axis a ``general`` actuator with force = kp (ctrl - q) - kd qdot,
  torque-limited; with the implicitfast integrator the damping is implicit (stable at high kd).
  For a ball joint the actuated "q" of axis k is the k-th component of the joint's rotation vector.
- MuJoCo world is Z up; the mocap is Y up: world_mj = C @ world_mocap with C mapping (x, y, z) to
  (x, -z, y). Only the free joint carries C; body-local frames are the skeleton's.
- Collisions: a fighter does not collide with itself; it collides with the floor and the other fighter.

Public: ModelOptions, BodyMap, FighterScene, build_fighter_scene, build_fighter_xml, leg_mask.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from tracker.body.spec import FighterSpec

#: Mocap (Y up) to MuJoCo (Z up) world rotation.
C_MOCAP_TO_MJ = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])

#: Segment radii (metres) for a 1.7 m body; scaled with the fighter's height.
RADIUS = dict(pelvis=0.09, belly=0.10, chest=0.11, neck=0.05, head=0.10, clavicle=0.045,
              upper_arm=0.045, forearm=0.04, hand=0.035, fist=0.05, thigh=0.08, shin=0.055,
              foot=0.03, toe=0.02, other=0.04)
#: PD stiffness per segment (N m / rad) for a 70 kg body, at kp_scale 1.
KP = dict(belly=1000.0, chest=800.0, neck=200.0, head=100.0, clavicle=400.0, upper_arm=400.0,
          forearm=300.0, hand=60.0, fist=30.0, thigh=1000.0, shin=800.0, foot=400.0, toe=60.0,
          other=100.0, pelvis=1000.0)
#: Torque limits per segment (N m), at torque_scale 1.
TORQUE = dict(belly=500.0, chest=400.0, neck=100.0, head=60.0, clavicle=200.0, upper_arm=250.0,
              forearm=150.0, hand=50.0, fist=30.0, thigh=500.0, shin=450.0, foot=250.0, toe=60.0,
              other=100.0, pelvis=500.0)

#: Labels of geoms that count as striking effectors and as targets (tracker.bouts.judging).
EFFECTOR_LABELS = ("l_fist", "r_fist")
TARGET_LABELS = ("head", "chest", "belly")

_SEGMENT_OF_PART = {"pelvis": "pelvis", "belly": "belly", "chest": "chest", "neck": "neck", "head": "head",
                    "shoulder": "upper_arm", "elbow": "forearm", "wrist": "hand", "fist": "fist",
                    "hip": "thigh", "knee": "shin", "ankle": "foot", "toe": "toe"}
_FIGHTER_RGBA = ((0.80, 0.30, 0.25, 1.0), (0.25, 0.40, 0.80, 1.0), (0.35, 0.70, 0.35, 1.0))


@dataclass(frozen=True)
class ModelOptions:
    """Knobs of the generated model.

    Attributes:
        joint_type: "ball" (default) or "hinge3" (Z, Y, X hinges per joint).
        physics_hz: physics rate (timestep = 1 / physics_hz).
        foot: "spheres" (contact spheres under heel, ball and toes; default) or "box".
        armature: joint armature (kg m^2), stabilises light links at high gains.
        joint_damping: passive joint damping (N m s / rad), on top of the PD's kd.
        friction: sliding friction of the floor and bodies.
        kp_scale: multiplies the KP table.
        kd_ratio: kd = kd_ratio * kp (seconds).
        torque_scale: multiplies the TORQUE table.
        solver_iterations: constraint solver iterations.
        ring_size_m: side of the (visual only, non-colliding) ring of posts and ropes; 0 for none.
        root_assist: add, per fighter, a mocap body and an (inactive) weld from it to the pelvis, so
            a diagnostic or a curriculum can hold the root on the reference (TrackingEnv.set_root_assist).
            Not physics: never on in an evaluation that reports falls.
    """

    joint_type: str = "ball"
    physics_hz: float = 240.0
    foot: str = "spheres"
    armature: float = 0.02
    joint_damping: float = 0.5
    friction: float = 1.0
    kp_scale: float = 1.0
    kd_ratio: float = 0.2
    torque_scale: float = 1.0
    solver_iterations: int = 20
    root_assist: bool = False
    ring_size_m: float = 6.0


@dataclass
class BodyMap:
    """Addresses of one fighter inside a compiled scene (all numpy int arrays are model ids).

    Attributes:
        index: fighter number (0, 1, ...); prefix: name prefix ("f0_").
        spec: the FighterSpec it was built from.
        joint_type: "ball" or "hinge3".
        dof_joints: (D,) skeleton joint index of each actuated joint, in qpos order.
        body_ids: (D + 1,) model body ids: pelvis first, then dof_joints order.
        body_joints: (D + 1,) skeleton joint index of each body in body_ids.
        qpos_adr: first qpos address of this fighter (free joint: 7 numbers, then joints).
        nq, nv: qpos / qvel sizes of this fighter; qvel_adr: first qvel address.
        joint_qpos: (D,) qpos address of each dof joint; joint_qvel: (D,) qvel address (3 each).
        act_adr: first actuator id; n_act: actuators (3 per joint).
        act_joint: (n_act,) index into dof_joints; act_axis: (n_act,) axis 0..2.
        act_class: segment class per actuator (for gain tables).
        site_ids: (S,) model site id per skeleton joint in site_joints (joints inside the model).
        site_joints: (S,) skeleton joint index of each site.
        tracked: (S,) True where the site's position is reproduced exactly from qpos.
        geom_label: {label: (k,) geom ids}; labels: head, chest, belly, pelvis, l_fist, r_fist,
            l_foot, r_foot (all foot/toe collision geoms), ...
        foot_geoms: collision geom ids of feet and toes; fall_geoms: every other collision geom.
        kp, kd, torque: (n_act,) PD gains and torque limits as built.
    """

    index: int
    prefix: str
    spec: FighterSpec
    joint_type: str
    dof_joints: np.ndarray
    body_ids: np.ndarray
    body_joints: np.ndarray
    qpos_adr: int
    qvel_adr: int
    nq: int
    nv: int
    joint_qpos: np.ndarray
    joint_qvel: np.ndarray
    act_adr: int
    n_act: int
    act_joint: np.ndarray
    act_axis: np.ndarray
    act_class: tuple[str, ...]
    site_ids: np.ndarray
    site_joints: np.ndarray
    tracked: np.ndarray
    geom_label: dict[str, np.ndarray]
    foot_geoms: np.ndarray
    fall_geoms: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    torque: np.ndarray

    @property
    def qpos_slice(self) -> slice:
        return slice(self.qpos_adr, self.qpos_adr + self.nq)

    @property
    def qvel_slice(self) -> slice:
        return slice(self.qvel_adr, self.qvel_adr + self.nv)

    @property
    def ctrl_slice(self) -> slice:
        return slice(self.act_adr, self.act_adr + self.n_act)

    @property
    def pelvis_body(self) -> int:
        return int(self.body_ids[0])


@dataclass
class FighterScene:
    """A compiled ring scene: the MJCF text, the model, one BodyMap per fighter, the floor geom."""

    xml: str
    model: mujoco.MjModel
    fighters: list[BodyMap]
    floor_geom: int
    options: ModelOptions
    specs: tuple = field(default=(), repr=False, compare=False)   # each fighter's FighterSpec (research/bout_search.py)
    _geom_table: tuple | None = field(default=None, repr=False, compare=False)  # contacts.geom_table cache

    def new_data(self) -> mujoco.MjData:
        return mujoco.MjData(self.model)


# ----------------------------------------------------------------------------------------------
# Skeleton geometry in the model's bodies


@dataclass
class _Layout:
    """Where every skeleton joint of one fighter sits in the model's bodies (rest pose)."""

    owner: np.ndarray          # (J,) skeleton index of the body that holds joint j (-1 outside)
    pos: np.ndarray            # (J, 3) joint position in its owner's frame
    rot: np.ndarray            # (J, 3, 3) joint frame (after its rest rotation) in owner's frame
    body_pos: dict[int, np.ndarray] = field(default_factory=dict)   # dof joint -> pos in parent body
    body_rot: dict[int, np.ndarray] = field(default_factory=dict)   # dof joint -> rot in parent body
    segment: list[str] = field(default_factory=list)
    side: list[str] = field(default_factory=list)


def _segments(spec: FighterSpec) -> tuple[list[str], list[str]]:
    """Segment class and side ('l', 'r' or '') of every skeleton joint."""
    sk = spec.skeleton
    J = sk.n_joints
    start: dict[int, tuple[str, str]] = {}
    for part, j in spec.parts.items():
        if part[:2] in ("l_", "r_"):
            side, base = part[0], part[2:]
        else:
            side, base = "", part
        if base in _SEGMENT_OF_PART and j not in start:
            start[j] = (_SEGMENT_OF_PART[base], side)
    shoulders = {spec.parts[p] for p in ("l_shoulder", "r_shoulder") if p in spec.parts}
    anc_of_shoulder: dict[int, str] = {}
    for s in ("l", "r"):
        if f"{s}_shoulder" in spec.parts:
            for k in sk.chain(spec.parts[f"{s}_shoulder"]):
                anc_of_shoulder[k] = s
    seg, side = ["other"] * J, [""] * J
    for j in range(J):
        k = j
        while k >= 0 and k not in start:
            k = int(sk.parents[k])
        if k >= 0:
            seg[j], side[j] = start[k]
        if seg[j] == "chest" and j in anc_of_shoulder and j not in shoulders and j != k:
            seg[j], side[j] = "clavicle", anc_of_shoulder[j]
    return seg, side


def _layout(spec: FighterSpec) -> _Layout:
    sk = spec.skeleton
    J = sk.n_joints
    inside = spec.subtree
    owner = np.full(J, -1)
    pos = np.zeros((J, 3))
    rot = np.tile(np.eye(3), (J, 1, 1))
    lay = _Layout(owner, pos, rot)
    rest = Rotation.from_quat(spec.rest).as_matrix()
    for j in range(J):
        if not inside[j]:
            continue
        if j == spec.pelvis:
            owner[j] = j
            continue
        p = int(sk.parents[j])
        pj = pos[p] + rot[p] @ sk.offsets[j]
        rj = rot[p] @ rest[j]
        if spec.dof[j]:
            owner[j] = j
            lay.body_pos[j] = pj
            lay.body_rot[j] = rj
        else:
            owner[j] = owner[p]
            pos[j] = pj
            rot[j] = rj
    lay.segment, lay.side = _segments(spec)
    return lay


def _incoming_dir(spec: FighterSpec, j: int) -> np.ndarray:
    """Unit direction of the bone arriving at joint j, in j's own (post-rest-rotation) frame."""
    sk = spec.skeleton
    off = sk.offsets[j]
    r = Rotation.from_quat(spec.rest[j])
    if np.linalg.norm(off) > 1e-4 or sk.parents[j] < 0:
        d = r.inv().apply(off) if np.linalg.norm(off) > 1e-4 else np.array([0.0, 1.0, 0.0])
    else:
        d = r.inv().apply(_incoming_dir(spec, int(sk.parents[j])))
    return d / np.linalg.norm(d)


def _frame_in(lay: _Layout, spec: FighterSpec, j: int, b: int) -> tuple[np.ndarray, np.ndarray]:
    """Position and rotation of joint j's frame in body b's frame, for j owned by b or j a dof child
    whose parent is owned by b."""
    if lay.owner[j] == b and j != b:
        return lay.pos[j], lay.rot[j]
    if j == b:
        return np.zeros(3), np.eye(3)
    return lay.body_pos[j], lay.body_rot[j]


# ----------------------------------------------------------------------------------------------
# XML generation


def _fmt(v) -> str:
    return " ".join(f"{float(x):.6g}" for x in np.ravel(v))


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    q = Rotation.from_matrix(R).as_quat()
    return np.array([q[3], q[0], q[1], q[2]])


@dataclass
class _Geom:
    kind: str                 # sphere | capsule | box
    label: str
    size: np.ndarray
    pos: np.ndarray | None = None
    fromto: np.ndarray | None = None
    quat: np.ndarray | None = None
    collide: bool = True
    is_foot: bool = False

    def volume(self) -> float:
        if self.kind == "sphere":
            return 4.0 / 3.0 * np.pi * self.size[0] ** 3
        if self.kind == "capsule":
            L = float(np.linalg.norm(self.fromto[3:] - self.fromto[:3]))
            r = self.size[0]
            return np.pi * r * r * L + 4.0 / 3.0 * np.pi * r ** 3
        return 8.0 * float(np.prod(self.size))


def _body_geoms(spec: FighterSpec, lay: _Layout, b: int, opts: ModelOptions) -> list[_Geom]:
    """Geoms of the body that holds skeleton joint b (b is the pelvis or a dof joint)."""
    sk = spec.skeleton
    s = spec.height_m / 1.7
    seg, side = lay.segment, lay.side
    own = [j for j in range(sk.n_joints) if lay.owner[j] == b]
    out: list[_Geom] = []
    cls = seg[b]
    lab_side = f"{side[b]}_" if side[b] else ""
    P = spec.parts

    def cap(a: np.ndarray, c: np.ndarray, r: float, label: str, collide: bool = True) -> None:
        if np.linalg.norm(c - a) > 1e-3:
            out.append(_Geom("capsule", label, np.array([r]), fromto=np.concatenate([a, c]), collide=collide))

    if cls == "pelvis" and b == spec.pelvis:
        # Cross-hip capsule between the hip joints at rest (in the pelvis frame).
        pl = rest_frame(spec, b, P["l_hip"])[0]
        pr = rest_frame(spec, b, P["r_hip"])[0]
        cap(pl, pr, RADIUS["pelvis"] * s, "pelvis")
    for k in own:
        if sk.is_end_site[k] and cls not in ("foot", "toe"):
            continue
        pk, Rk = _frame_in(lay, spec, k, b)
        if spec.forced_weld[k]:
            continue  # fingers and thumbs: covered by the fist sphere
        for c in sk.children(k):
            if not spec.subtree[c] or spec.forced_weld[c]:
                continue
            pc = pk + Rk @ sk.offsets[c]
            ccls = seg[c]
            if cls in ("head", "foot", "toe"):
                continue
            if cls == "pelvis":
                if ccls == "thigh" or (ccls == "pelvis" and c != b):
                    continue  # hip joints: the cross-hip capsule covers them
                cap(pk, pc, RADIUS["pelvis"] * s, "pelvis")
                continue
            if cls == "fist" or (cls == "hand" and ccls == "fist" and sk.is_end_site[c]):
                continue
            if cls == "chest" and ccls in ("clavicle", "upper_arm"):
                cap(pk, pc, 0.065 * s, "chest")
                continue
            label = cls if cls in ("belly", "chest", "neck") else f"{lab_side}{cls}"
            r = RADIUS.get(cls, RADIUS["other"]) * s
            if ccls == "foot":
                # The shin ends above the ankle: its rounded end must not reach the floor when the
                # foot is flat (ankle heights are 5-12 cm, shin radius about 5 cm).
                L = float(np.linalg.norm(pc - pk))
                pc = pk + (pc - pk) * max(0.0, (L - r) / L)
            cap(pk, pc, r, label)
    # Head sphere.
    if cls == "head" and b == lay.owner[P["head"]]:
        h = P["head"]
        ph, Rh = _frame_in(lay, spec, h, b)
        top = P.get("head_top")
        dist = 0.0
        if top is not None and spec.subtree[top]:
            pt = _frame_in(lay, spec, top, b)[0] if lay.owner[top] == b else ph + Rh @ sk.offsets[top]
            dist = float(np.linalg.norm(pt - ph))
        if dist > 0.04 * s:
            centre = ph + 0.5 * (pt - ph)
            r = max(RADIUS["head"] * s, 0.55 * dist)
        else:
            centre = ph + Rh @ _incoming_dir(spec, h) * 0.09 * s
            r = RADIUS["head"] * s
        out.append(_Geom("sphere", "head", np.array([r]), pos=centre))
    # Fist spheres.
    for sd in "lr":
        f = P.get(f"{sd}_fist")
        if f is None or lay.owner[f] != b:
            continue
        pf, Rf = _frame_in(lay, spec, f, b)
        w = P[f"{sd}_wrist"]
        at_wrist = float(np.linalg.norm(sk.offsets[f])) < 0.02 * s or f == w
        ahead = (0.08 if at_wrist else 0.02) * s
        d = Rf @ _incoming_dir(spec, f)
        out.append(_Geom("sphere", f"{sd}_fist", np.array([RADIUS["fist"] * s]), pos=pf + d * ahead))
    # Feet.
    for sd in "lr":
        a, t = P[f"{sd}_ankle"], P[f"{sd}_toe"]
        if lay.owner[a] == b:
            out.extend(_foot_geoms(spec, lay, b, sd, a, t, s, opts))
        if lay.owner[t] == b and t != a and lay.owner[a] != b:
            out.extend(_toe_geoms(spec, lay, b, sd, a, t, s, opts))
    if not out:
        # A body without a bone of its own (e.g. a zero-length hip joint given degrees of freedom):
        # a small mass-only sphere keeps its inertia positive.
        out.append(_Geom("sphere", f"{lab_side}{cls}", np.array([0.02 * s]), pos=np.zeros(3), collide=False))
    return out


def _sole(spec: FighterSpec, sd: str, a: int, t: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Sole frame in the ankle frame: up u, forward f, lateral l (units) and ankle height h."""
    cal = spec.feet[sd]
    u = cal.up / np.linalg.norm(cal.up)
    pt = rest_frame(spec, a, t)[0]
    f = pt - u * (pt @ u)
    if np.linalg.norm(f) < 1e-6:
        f = np.cross(u, [1.0, 0.0, 0.0])
    f /= np.linalg.norm(f)
    return u, f, np.cross(u, f), cal.ankle_height_m


def rest_frame(spec: FighterSpec, a: int, t: int) -> tuple[np.ndarray, np.ndarray]:
    """Rest frame of joint t (pos, rot) in joint a's frame, a an ancestor of t."""
    sk = spec.skeleton
    chain = sk.chain(t)
    i = chain.index(a)
    p, R = np.zeros(3), np.eye(3)
    for j in chain[i + 1:]:
        p = p + R @ sk.offsets[j]
        R = R @ Rotation.from_quat(spec.rest[j]).as_matrix()
    return p, R


def _toe_end(spec: FighterSpec, t: int, s: float) -> np.ndarray:
    """Toe tip in the toe frame."""
    sk = spec.skeleton
    kids = sk.children(t)
    if kids and np.linalg.norm(sk.offsets[kids[0]]) > 0.02 * s:
        return sk.offsets[kids[0]].copy()
    return _incoming_dir(spec, t) * 0.05 * s


def _foot_geoms(spec, lay, b, sd, a, t, s, opts) -> list[_Geom]:
    pa, Ra = _frame_in(lay, spec, a, b)
    u, f, l, h = _sole(spec, sd, a, t)
    pt = rest_frame(spec, a, t)[0]
    out: list[_Geom] = []
    lab = f"{sd}_foot"
    to_b = lambda x: pa + Ra @ x  # noqa: E731
    heel_back = 0.035 * s
    ball = pt - u * ((pt @ u) + h)   # ball of the foot on the sole plane
    heel = -u * h - f * heel_back
    # Mass-only foot capsule (no collision), ankle to ball, above the sole.
    r_m = 0.035 * s
    cap_from = heel + u * (r_m + 0.005)
    cap_to = ball + u * (r_m + 0.005)
    out.append(_Geom("capsule", lab, np.array([r_m]), fromto=np.concatenate([to_b(cap_from), to_b(cap_to)]),
                     collide=False))
    if opts.foot == "box":
        half_w = 0.045 * s
        centre = 0.5 * (heel + ball) + u * 0.02
        half = np.array([half_w, 0.02, 0.5 * float(np.linalg.norm(ball - heel)) + 0.01])
        R = np.stack([l, u, f], axis=1)
        out.append(_Geom("box", lab, half, pos=to_b(centre), quat=_quat_wxyz(Ra @ R), is_foot=True))
        return out
    r_h, r_b = 0.03 * s, 0.025 * s
    for sign in (-1.0, 1.0):
        out.append(_Geom("sphere", lab, np.array([r_h]), pos=to_b(heel + u * r_h + f * r_h + l * sign * 0.02 * s),
                         is_foot=True))
        out.append(_Geom("sphere", lab, np.array([r_b]), pos=to_b(ball + u * r_b + l * sign * 0.03 * s),
                         is_foot=True))
    if lay.owner[t] == b:   # toe welded into the foot: tip spheres here too
        out.extend(_toe_geoms(spec, lay, b, sd, a, t, s, opts, include_mass=False))
    return out


def _toe_geoms(spec, lay, b, sd, a, t, s, opts, include_mass: bool = True) -> list[_Geom]:
    pt_b, Rt_b = _frame_in(lay, spec, t, b)
    u, f, l, h = _sole(spec, sd, a, t)
    p_at, R_at = rest_frame(spec, a, t)
    # Sole plane in the toe frame: normal ut, the toe joint is h_m above it.
    ut, ft, lt = R_at.T @ u, R_at.T @ f, R_at.T @ l
    h_m = h + p_at @ u
    tip = _toe_end(spec, t, s)
    tip_sole = tip - ut * ((tip @ ut) + h_m)
    lab = f"{sd}_foot"
    out: list[_Geom] = []
    to_b = lambda x: pt_b + Rt_b @ x  # noqa: E731
    r = 0.02 * s
    if include_mass:
        m_from = -ut * (h_m - 0.02 * s)
        m_to = tip_sole + ut * 0.02 * s
        out.append(_Geom("capsule", lab, np.array([0.02 * s]), fromto=np.concatenate([to_b(m_from), to_b(m_to)]),
                         collide=False))
    if opts.foot == "box":
        base = -ut * h_m
        centre = 0.5 * (base + tip_sole) + ut * 0.015
        half = np.array([0.04 * s, 0.015, 0.5 * float(np.linalg.norm(tip_sole - base)) + 0.005])
        R = np.stack([lt, ut, ft], axis=1)
        out.append(_Geom("box", lab, half, pos=to_b(centre), quat=_quat_wxyz(Rt_b @ R), is_foot=True))
        return out
    for sign in (-1.0, 1.0):
        out.append(_Geom("sphere", lab, np.array([r]), pos=to_b(tip_sole + ut * r - ft * r + lt * sign * 0.025 * s),
                         is_foot=True))
    return out


def build_fighter_xml(spec: FighterSpec, index: int = 0, options: ModelOptions = ModelOptions(),
                      density: float | None = None) -> tuple[str, str, dict]:
    """MJCF fragments for one fighter: (worldbody xml, actuator xml, info for the BodyMap)."""
    sk = spec.skeleton
    lay = _layout(spec)
    prefix = f"f{index}_"
    rgba = _FIGHTER_RGBA[index % len(_FIGHTER_RGBA)]
    bodies = [spec.pelvis] + [j for j in range(sk.n_joints) if spec.dof[j]]
    geoms = {b: _body_geoms(spec, lay, b, options) for b in bodies}
    if density is None:
        vol = sum(g.volume() for gs in geoms.values() for g in gs)
        density = spec.mass_kg / vol
    s = spec.height_m / 1.7
    names = [_safe(n) for n in sk.names]
    children_bodies: dict[int, list[int]] = {b: [] for b in bodies}
    for j in bodies[1:]:
        children_bodies[int(lay.owner[int(sk.parents[j])])].append(j)
    act_lines: list[str] = []
    info = dict(prefix=prefix, bodies=bodies, act_joint=[], act_axis=[], act_class=[], kp=[], kd=[], torque=[],
                geoms=[])
    lines: list[str] = []

    def emit(b: int, depth: int) -> None:
        ind = "  " * depth
        n = prefix + names[b]
        if b == spec.pelvis:
            lines.append(f'{ind}<body name="{n}" pos="0 0 1" childclass="fighter{index}">')
            lines.append(f'{ind}  <freejoint name="{n}"/>')
        else:
            q = _quat_wxyz(lay.body_rot[b])
            lines.append(f'{ind}<body name="{n}" pos="{_fmt(lay.body_pos[b])}" quat="{_fmt(q)}">')
            rng = float(spec.range_rad[b])
            cls = lay.segment[b]
            kp = KP.get(cls, KP["other"]) * options.kp_scale * s ** 2
            kd = kp * options.kd_ratio
            tq = TORQUE.get(cls, TORQUE["other"]) * options.torque_scale * s ** 2
            if options.joint_type == "ball":
                lines.append(f'{ind}  <joint name="{n}" type="ball" range="0 {rng:.4f}"/>')
                for ax in range(3):
                    gear = ["0", "0", "0"]
                    gear[ax] = "1"
                    act_lines.append(_actuator(f"{n}_{'xyz'[ax]}", n, " ".join(gear), kp, kd, tq))
                    _add_act(info, b, ax, cls, kp, kd, tq)
            elif options.joint_type == "hinge3":
                for ax, axis in zip((2, 1, 0), ("0 0 1", "0 1 0", "1 0 0")):
                    jn = f"{n}_{'xyz'[ax]}"
                    lines.append(f'{ind}  <joint name="{jn}" type="hinge" axis="{axis}" range="{-rng:.4f} {rng:.4f}"/>')
                    act_lines.append(_actuator(jn, jn, "1", kp, kd, tq))
                    _add_act(info, b, ax, cls, kp, kd, tq)
            else:
                raise ValueError(f"unknown joint_type {options.joint_type!r} (ball or hinge3)")
        for j in range(sk.n_joints):
            if lay.owner[j] == b and spec.subtree[j]:
                p = lay.pos[j] if j != b else np.zeros(3)
                lines.append(f'{ind}  <site name="{prefix}{names[j]}" pos="{_fmt(p)}" class="jsite"/>')
        for gi, g in enumerate(geoms[b]):
            lines.append(ind + "  " + _geom_xml(g, f"{n}_g{gi}", density, rgba, index))
            info["geoms"].append((f"{n}_g{gi}", g.label, g.is_foot, g.collide))
        for c in children_bodies[b]:
            emit(c, depth + 1)
        lines.append(f"{ind}</body>")

    emit(spec.pelvis, 2)
    info["density"] = density
    return "\n".join(lines), "\n".join(act_lines), info


def _add_act(info: dict, b: int, ax: int, cls: str, kp: float, kd: float, tq: float) -> None:
    info["act_joint"].append(b)
    info["act_axis"].append(ax)
    info["act_class"].append(cls)
    info["kp"].append(kp)
    info["kd"].append(kd)
    info["torque"].append(tq)


def _actuator(name: str, joint: str, gear: str, kp: float, kd: float, tq: float) -> str:
    return (f'    <general name="{name}" joint="{joint}" gear="{gear}" gaintype="fixed" biastype="affine" '
            f'gainprm="{kp:.6g}" biasprm="0 {-kp:.6g} {-kd:.6g}" forcelimited="true" forcerange="{-tq:.6g} {tq:.6g}"/>')


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "_-." else "_" for c in name)


def _geom_xml(g: _Geom, name: str, density: float, rgba, index: int) -> str:
    col = list(rgba)
    if g.label in ("head",):
        col = [0.93, 0.78, 0.65, 1.0]
    elif g.label.endswith("fist"):
        col = [0.15, 0.15, 0.15, 1.0] if index == 0 else [0.95, 0.95, 0.95, 1.0]
    elif g.label.endswith("foot"):
        col = [0.2, 0.2, 0.2, 1.0]
    attrs = [f'name="{name}"', f'type="{g.kind}"', f'size="{_fmt(g.size)}"']
    if g.fromto is not None:
        attrs.append(f'fromto="{_fmt(g.fromto)}"')
    if g.pos is not None:
        attrs.append(f'pos="{_fmt(g.pos)}"')
    if g.quat is not None:
        attrs.append(f'quat="{_fmt(g.quat)}"')
    attrs.append(f'density="{density:.6g}"')
    attrs.append(f'rgba="{_fmt(col)}"')
    if not g.collide:
        attrs.append('contype="0" conaffinity="0" group="1"')
    return "<geom " + " ".join(attrs) + "/>"


def build_fighter_scene(spec: FighterSpec | list[FighterSpec], n_fighters: int = 1,
                        options: ModelOptions = ModelOptions()) -> FighterScene:
    """Compile a ring scene with n_fighters copies of a fighter (or one per spec in a list).

    Collision filtering: fighter k's geoms have contype 2**(k+1) and conaffinity 1 | (other fighters'
    bits), the floor contype 1 and conaffinity all fighter bits: no self-collision, fighters collide
    with the floor and each other.
    """
    specs = list(spec) if isinstance(spec, (list, tuple)) else [spec] * n_fighters
    if not 1 <= len(specs) <= 3:
        raise ValueError("build_fighter_scene: 1 to 3 fighters")
    bits = [2 ** (k + 1) for k in range(len(specs))]
    all_bits = sum(bits)
    bodies, acts, infos, defaults = [], [], [], []
    for k, sp in enumerate(specs):
        b, a, info = build_fighter_xml(sp, k, options)
        bodies.append(b)
        acts.append(a)
        infos.append(info)
        defaults.append(f'    <default class="fighter{k}"><geom contype="{bits[k]}" conaffinity="{1 | (all_bits - bits[k])}" '
                        f'condim="3" friction="{options.friction} 0.005 0.0001"/>'
                        f'<joint armature="{options.armature}" damping="{options.joint_damping}"/></default>')
    assist_bodies, assist_eq = [], ""
    if options.root_assist:
        eqs = []
        for k, sp in enumerate(specs):
            pel = f"f{k}_" + _safe(sp.skeleton.names[sp.pelvis])
            assist_bodies.append(f'    <body name="f{k}_root_target" mocap="true" pos="0 0 1"/>')
            eqs.append(f'    <weld name="f{k}_root_assist" body1="f{k}_root_target" body2="{pel}" active="false" '
                       f'solref="0.02 1"/>')
        assist_eq = "  <equality>\n" + "\n".join(eqs) + "\n  </equality>"
    ring = _ring_xml(options.ring_size_m)
    dt = 1.0 / options.physics_hz
    xml = f"""<mujoco model="igraph-fight ring">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{dt:.8g}" integrator="implicitfast" iterations="{options.solver_iterations}" ls_iterations="10"
          cone="pyramidal"/>
  <visual><global offwidth="1280" offheight="720"/><quality shadowsize="1024"/>
    <headlight ambient=".35 .35 .35" diffuse=".5 .5 .5"/></visual>
  <asset>
    <texture name="sky" type="skybox" builtin="gradient" rgb1=".55 .65 .8" rgb2=".15 .15 .2" width="64" height="64"/>
    <texture name="canvas" type="2d" builtin="checker" rgb1=".82 .78 .70" rgb2=".76 .72 .64" width="256" height="256" mark="edge" markrgb=".6 .55 .5"/>
    <material name="canvas" texture="canvas" texrepeat="8 8" reflectance="0"/>
  </asset>
  <default>
    <site size="0.01" rgba="1 1 0 0" group="4"/>
    <default class="jsite"><site size="0.012" rgba="1 1 0 0.8" group="4"/></default>
{chr(10).join(defaults)}
  </default>
  <worldbody>
    <light name="key" pos="2 -3 5" dir="-0.3 0.5 -1" diffuse=".6 .6 .6" castshadow="true"/>
    <geom name="floor" type="plane" size="0 0 0.05" material="canvas" contype="1" conaffinity="{all_bits}"
          friction="{options.friction} 0.005 0.0001" condim="3"/>
{ring}
{chr(10).join(bodies)}
{chr(10).join(assist_bodies)}
  </worldbody>
{assist_eq}
  <actuator>
{chr(10).join(acts)}
  </actuator>
</mujoco>
"""
    model = mujoco.MjModel.from_xml_string(xml)
    fighters = [_body_map(model, sp, k, infos[k], options) for k, sp in enumerate(specs)]
    floor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor")
    return FighterScene(xml, model, fighters, floor, options, tuple(specs))


def _ring_xml(size: float) -> str:
    """Visual ring: four corner posts and three ropes per side (no collision, no mass)."""
    if size <= 0:
        return ""
    h = size / 2.0
    corners = [(-h, -h), (h, -h), (h, h), (-h, h)]
    out = []
    for i, (x, y) in enumerate(corners):
        out.append(f'    <geom name="ring_post{i}" type="cylinder" pos="{x:g} {y:g} 0.65" size="0.06 0.65" '
                   f'rgba=".25 .25 .3 1" contype="0" conaffinity="0" group="1" mass="0"/>')
    for i in range(4):
        (x0, y0), (x1, y1) = corners[i], corners[(i + 1) % 4]
        for k, z in enumerate((0.5, 0.85, 1.2)):
            out.append(f'    <geom name="ring_rope{i}_{k}" type="capsule" fromto="{x0:g} {y0:g} {z} {x1:g} {y1:g} {z}" '
                       f'size="0.015" rgba=".85 .15 .15 1" contype="0" conaffinity="0" group="1" mass="0"/>')
    return "\n".join(out)


def _body_map(model: mujoco.MjModel, spec: FighterSpec, k: int, info: dict, opts: ModelOptions) -> BodyMap:
    sk = spec.skeleton
    prefix = info["prefix"]
    names = [_safe(n) for n in sk.names]
    bodies = info["bodies"]
    body_ids = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, prefix + names[b]) for b in bodies])
    dof_joints = np.array(bodies[1:], dtype=int)
    free_j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, prefix + names[spec.pelvis])
    qpos_adr, qvel_adr = int(model.jnt_qposadr[free_j]), int(model.jnt_dofadr[free_j])
    jq, jv = [], []
    for b in dof_joints:
        jname = prefix + names[b] + ("" if opts.joint_type == "ball" else "_z")
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, jname)
        jq.append(int(model.jnt_qposadr[jid]))
        jv.append(int(model.jnt_dofadr[jid]))
    per_q = 4 if opts.joint_type == "ball" else 3
    nq = 7 + per_q * len(dof_joints)
    nv = 6 + 3 * len(dof_joints)
    act_names = []
    for b, ax in zip(info["act_joint"], info["act_axis"]):
        act_names.append(f"{prefix}{names[b]}_{'xyz'[ax]}")
    act_ids = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in act_names])
    if len(act_ids) and not np.all(np.diff(act_ids) == 1):
        raise RuntimeError("actuators of a fighter are not contiguous")
    joint_index = {int(b): i for i, b in enumerate(dof_joints)}
    inside = spec.subtree
    site_joints = np.nonzero(inside)[0]
    site_ids = np.array([mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, prefix + names[j]) for j in site_joints])
    tracked = spec.tracked()[site_joints]
    labels: dict[str, list[int]] = {}
    foot, fall = [], []
    for gname, lab, is_foot, collide in info["geoms"]:
        g = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, gname)
        if not collide:
            continue
        labels.setdefault(lab, []).append(g)
        (foot if is_foot else fall).append(g)
    return BodyMap(k, prefix, spec, opts.joint_type, dof_joints, body_ids, np.array(bodies), qpos_adr, qvel_adr,
                   nq, nv, np.array(jq), np.array(jv), int(act_ids[0]) if len(act_ids) else 0, len(act_ids),
                   np.array([joint_index[b] for b in info["act_joint"]]), np.array(info["act_axis"]),
                   tuple(info["act_class"]), site_ids, site_joints, tracked, {k2: np.array(v) for k2, v in labels.items()},
                   np.array(foot, dtype=int), np.array(fall, dtype=int),
                   np.array(info["kp"]), np.array(info["kd"]), np.array(info["torque"]))


def leg_mask(scene: FighterScene) -> np.ndarray:
    """(n_act,) True for fighter 0's hip / knee / ankle / toe and spine actuators (the segments a
    search perturbs with its larger leg sigma)."""
    f = scene.fighters[0]
    legs = {"thigh", "shin", "foot", "toe", "hip", "knee", "ankle", "spine", "pelvis", "belly", "chest", "torso"}
    return np.array([c in legs for c in f.act_class])
