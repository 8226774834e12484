"""Virtual-force balance: stance-leg torques that steer the body's balance towards the reference's.

Why: PD tracking controls every joint angle but nothing controls where the body stands as a
whole; it topples like an inverted pendulum within ~1.4 s (docs/tracker.md). The classic
remedy of physics-based character control (SIMBICON's stance-hip torso control; Geijtenbeek et
al. 2012, "Simple data-driven control for simulated bipeds": virtual forces realised through the
stance legs by the Jacobian transpose) is added here as a layer under any controller:

- the centre of mass relative to the centroid of the feet that touch the floor, and its velocity,
  are compared with the reference's (same feet): a horizontal virtual force
  F = com_kp * (offset error) + com_kd * (velocity error)  [N];
- the pelvis orientation and angular velocity (world) are compared with the reference's: a
  virtual torque T = root_kp * (rotation error) + root_kd * (angular velocity error)  [N m];
- the wrench (F, T) on the pelvis is realised by the stance legs' hip, knee and ankle joints,
  tau = -J^T (F, T) with J the Jacobian of a point at the pelvis attached to the foot (the chain
  seen from the planted foot), split equally between the feet on the floor, clipped to
  +- torque_clip per joint axis [N m].

The torques go through the leg actuators' PD targets (target += tau / kp), updated after every
physics substep (so they act from the second of the control step's 8 substeps on; the first runs
on the controller's targets), and the actuators' torque limits still bound the total: internal
joint torques only, no force on the root. It is mostly an ankle strategy steered by the stance
legs (without the ankles the layer does nothing). The default gains come from a cross-entropy
search over them (research/probes/tracker_vforce_cem.py) that scores the time to fall and charges
foot sliding above 0.25 m/s (gains found on the time to fall alone balance by sliding the loaded
feet: a body under them skates, and physics bouts drift apart); the figures are in docs/tracker.md.
Steering (``layer.bias[k]``, six numbers per fighter, default zeros = the layer as described): shifts
of the targets in the fighter's facing frame (x along the hip line, right to left, y = z cross x,
the frame of TrackingEnv.observe), held for a control step: the centre of mass's offset from the stance feet
(dx, dy, m), its velocity (dvx, dvy, m/s) and the pelvis orientation (rx, ry, rad: a rotation
vector about the facing axes applied to the reference's). A learned balance head
(research/layer_head.py) sets them each control step.
An approximation: the quantities are one physics substep old (MuJoCo's mj_step leaves them so),
4 ms at 240 Hz.
"""
from __future__ import annotations

from dataclasses import astuple, dataclass

import mujoco
import numba
import numpy as np


@numba.njit(cache=True)
def _stance_mask(pairs: np.ndarray, floor: int, owner: np.ndarray) -> int:
    """Bit 2k+i set when foot i of fighter k touches the floor, from the contacts' geom pairs
    ((ncon, 2) ints; owner maps a geom to 2k+i or -1)."""
    mask = 0
    for c in range(pairs.shape[0]):
        a, b = pairs[c, 0], pairs[c, 1]
        other = b if a == floor else (a if b == floor else -1)
        code = owner[other]
        if code >= 0:
            mask |= 1 << code
    return mask


@numba.njit(cache=True)
def xy_mean(xpos: np.ndarray, geoms: np.ndarray) -> np.ndarray:
    """Mean ground position of the geoms (rows added in order, as numpy's sum over axis 0 does)."""
    out = np.zeros(2)
    for g in geoms:
        out[0] += xpos[g, 0]
        out[1] += xpos[g, 1]
    n = geoms.shape[0]
    out[0] /= n
    out[1] /= n
    return out


@dataclass(frozen=True)
class BalanceGains:
    """Gains of the virtual-force balance (module doc). Units: N/m, N s/m, N m/rad, N m s/rad, N m."""

    com_kp: float = 3200.0
    com_kd: float = 500.0
    root_kp: float = 280.0
    root_kd: float = 100.0
    torque_clip: float = 58.0
    drift_kp: float = 0.0             # N/m: pulls the centre of mass towards the reference's world position
                                      # (measured: 300 / 1000 shorten the time to fall, 2.65 / 2.46 s vs 2.82 s)

    @classmethod
    def parse(cls, values) -> "BalanceGains | None":
        """None for an empty sequence / None; else five numbers in field order, or a dict of fields."""
        if values is None:
            return None
        if isinstance(values, BalanceGains):
            return values
        if isinstance(values, dict):
            return cls(**{k: float(v) for k, v in values.items()})
        vals = tuple(float(v) for v in values)
        if not vals:
            return None
        if len(vals) not in (5, 6):
            raise ValueError("balance gains: 5 or 6 numbers (com_kp, com_kd, root_kp, root_kd, torque_clip[, drift_kp]), "
                             f"got {len(vals)}")
        return cls(*vals)

    def as_tuple(self) -> tuple[float, ...]:
        return tuple(float(v) for v in astuple(self))


class LegMap:
    """Model addresses of one fighter's legs and feet."""

    def __init__(self, model: mujoco.MjModel, f) -> None:
        dof = {int(j): i for i, j in enumerate(f.dof_joints)}
        parts = f.spec.parts
        self.pelvis = f.pelvis_body
        self.qvel0 = f.qvel_adr
        self.legs = {}
        for side in ("l", "r"):
            acts, cols = [], []
            for p in ("hip", "knee", "ankle"):
                i = dof[parts[f"{side}_{p}"]]
                ids = np.nonzero(f.act_joint == i)[0]
                ids = ids[np.argsort(f.act_axis[ids])]
                acts += list(f.act_adr + ids)
                a = int(f.joint_qvel[i])
                cols += [a + int(x) for x in f.act_axis[ids]]
            geoms = np.array([g for g in f.geom_label[f"{side}_foot"]
                              if model.geom_contype[g] or model.geom_conaffinity[g]], int)
            self.legs[side] = dict(acts=np.array(acts), cols=np.array(cols), geoms=geoms,
                                   body=int(model.geom_bodyid[geoms[0]]))


class BalanceTarget:
    """The reference's balance quantities at one control step, computed when needed (a physics bout
    writes its reference while it plays, so nothing is precomputed): COM and its velocity (central
    difference over the neighbouring frames), foot centroids, pelvis orientation and angular velocity."""

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self.data = mujoco.MjData(model)
        self.feet = {}
        self.com = np.zeros(3)
        self.vel = np.zeros(3)
        self.quat = np.zeros(4)
        self.omega = np.zeros(3)
        self._R = np.zeros(9)

    def _pose(self, fighter, fi: LegMap, qpos: np.ndarray, feet: bool) -> np.ndarray:
        m, d = self.model, self.data
        d.qpos[fighter.qpos_slice] = qpos
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        if feet:
            for s, leg in fi.legs.items():
                self.feet[s] = d.geom_xpos[leg["geoms"], :2].mean(0)
        return d.subtree_com[fi.pelvis].copy()

    def update(self, fighter, fi: LegMap, ref, t: int) -> None:
        T = ref.n_frames
        self.com = self._pose(fighter, fi, ref.qpos[t], True)
        lo, hi = max(t - 1, 0), min(t + 1, T - 1)
        if hi > lo:
            a = self.com if lo == t else self._pose(fighter, fi, ref.qpos[lo], False)
            b = self.com if hi == t else self._pose(fighter, fi, ref.qpos[hi], False)
            self.vel = (b - a) * ref.fps / (hi - lo)
        else:
            self.vel = np.zeros(3)
        self.quat = ref.qpos[t, 3:7]
        mujoco.mju_quat2Mat(self._R, self.quat)
        self.omega = self._R.reshape(3, 3) @ ref.qvel[t, 3:6]


class VirtualForceBalance:
    """The balance layer of a TrackingEnv (TrackingEnv.set_balance); one gain set per fighter."""

    def __init__(self, env) -> None:
        self.model = env.model
        self.fighters = [LegMap(env.model, f) for f in env.scene.fighters]
        self.gains: list[BalanceGains | None] = [None] * len(self.fighters)
        self.floor = env.scene.floor_geom
        # geom id -> 2 * fighter + side (0 left, 1 right) of a foot geom, -1 for any other geom
        self._owner = np.full(env.model.ngeom + 1, -1, dtype=np.int64)
        for k, fi in enumerate(self.fighters):
            for i, (s, leg) in enumerate(fi.legs.items()):
                self._owner[leg["geoms"]] = 2 * k + i
        self._sides = [tuple(fi.legs) for fi in self.fighters]
        # per fighter, the stance sides for each pair of its two bits in _stance_mask (codes ascending)
        self._stance_of = [[[sd[i] for i in range(2) if b >> i & 1] for b in range(4)] for sd in self._sides]
        self._leg_acts = [np.concatenate([leg["acts"] for leg in fi.legs.values()]) for fi in self.fighters]
        self._frames = [BalanceTarget(env.model) for _ in self.fighters]
        self._base = np.zeros(env.model.nu)
        self._jp = np.zeros((3, env.model.nv))
        self._jr = np.zeros((3, env.model.nv))
        self._qerr = np.zeros(4)
        self._qc = np.zeros(4)
        self._rv = np.zeros(3)
        self.bias = np.zeros((len(self.fighters), 6))        # steering, module doc
        self._bw = np.zeros((len(self.fighters), 4))         # this step's bias: offset, velocity (world)
        self._bq: list[np.ndarray | None] = [None] * len(self.fighters)   # biased pelvis target
        self._lateral = [c.lateral for c in env._cache]

    @property
    def active(self) -> bool:
        return any(g is not None for g in self.gains)

    def split(self, d: mujoco.MjData, k: int, feet: list[str], F: np.ndarray, T: np.ndarray):
        """[(side, force, torque)]: fighter k's virtual wrench shared among its stance feet; equally
        (measured best: a split by the feet's contact forces, or one capped by each foot's friction
        cone, keeps the body up for less time at the same sliding, research/probes/tracker_balance_probes.py)."""
        share = 1.0 / len(feet)
        return [(side, F * share, T * share) for side in feet]

    def foot_of(self, geom: int) -> tuple[int, str] | None:
        """(fighter, side) of a foot geom, None for any other geom."""
        code = int(self._owner[geom])
        return None if code < 0 else (code // 2, self._sides[code // 2][code % 2])

    def stance_feet(self, d: mujoco.MjData) -> list[list[str]]:
        """Per fighter, the sides ("l", "r", sorted) whose foot geoms touch the floor now."""
        mask = _stance_mask(d.contact.geom, self.floor, self._owner)     # (ncon, 2): MuJoCo's live contacts
        return [list(self._stance_of[k][mask >> 2 * k & 3]) for k in range(len(self.fighters))]

    def _steer(self, d: mujoco.MjData, k: int) -> None:
        """This control step's world-frame bias of fighter k (``bias`` turned by the pelvis's heading)."""
        b = self.bias[k]
        if not b.any():
            self._bq[k] = None
            return
        w = d.xmat[self.fighters[k].pelvis].reshape(3, 3) @ self._lateral[k]
        yaw = float(np.arctan2(w[1], w[0]))
        cy, sy = np.cos(yaw), np.sin(yaw)
        turn = np.array([[cy, -sy], [sy, cy]])          # facing -> world (the transpose of observe's)
        self._bw[k, :2] = turn @ b[:2]
        self._bw[k, 2:] = turn @ b[2:4]
        rv = np.zeros(3)
        rv[:2] = turn @ b[4:6]
        ang = float(np.linalg.norm(rv))
        dq, q = np.array([1.0, 0.0, 0.0, 0.0]), np.zeros(4)
        if ang > 0:
            mujoco.mju_axisAngle2Quat(dq, rv / ang, ang)
        mujoco.mju_mulQuat(q, dq, self._frames[k].quat)
        self._bq[k] = q

    def substep(self, env, d: mujoco.MjData, s: int) -> None:
        """After physics substep ``s`` of a control step: set the leg targets for the next substep."""
        m = self.model
        if s == 0:
            self._base[:] = d.ctrl
            t = min(env.t + 1, env.t_end)
            for k, g in enumerate(self.gains):
                if g is not None:
                    self._frames[k].update(env.scene.fighters[k], self.fighters[k], env.refs[k], t)
                    self._steer(d, k)
        stance = self.stance_feet(d)
        need = [k for k, g in enumerate(self.gains) if g is not None and stance[k]]
        for k in range(len(self.fighters)):
            if self.gains[k] is not None:
                ids = self._leg_acts[k]
                d.ctrl[ids] = self._base[ids]
        if not need:
            return
        mujoco.mj_subtreeVel(m, d)
        for k in need:
            g, fi, tr = self.gains[k], self.fighters[k], self._frames[k]
            feet = stance[k]
            c = d.subtree_com[fi.pelvis]
            v = d.subtree_linvel[fi.pelvis]
            # (the same arithmetic as np.mean over the geoms, then over the feet, without its overhead;
            # the wrench below in scalars, the same operations in the same order as on the 2-vectors)
            cen = [xy_mean(d.geom_xpos, fi.legs[side]["geoms"]) for side in feet]
            fs = cen[0] if len(feet) == 1 else (cen[0] + cen[1]) / 2
            fr = tr.feet[feet[0]] if len(feet) == 1 else (tr.feet[feet[0]] + tr.feet[feet[1]]) / 2
            F = np.zeros(3)
            kp, kd = g.com_kp, g.com_kd
            if self._bq[k] is None:
                for i in (0, 1):
                    F[i] = kp * ((tr.com[i] - fr[i]) - (c[i] - fs[i])) + kd * (tr.vel[i] - v[i])
                target = tr.quat
            else:
                bw = self._bw[k]
                for i in (0, 1):
                    F[i] = kp * ((tr.com[i] + bw[i] - fr[i]) - (c[i] - fs[i])) + kd * (tr.vel[i] + bw[2 + i] - v[i])
                target = self._bq[k]
            if g.drift_kp:
                F[:2] += g.drift_kp * (tr.com[:2] - c[:2])
            mujoco.mju_negQuat(self._qc, d.xquat[fi.pelvis])
            mujoco.mju_mulQuat(self._qerr, target, self._qc)
            if self._qerr[0] < 0.0:
                self._qerr *= -1.0
            mujoco.mju_quat2Vel(self._rv, self._qerr, 1.0)
            w = d.xmat[fi.pelvis].reshape(3, 3) @ d.qvel[fi.qvel0 + 3:fi.qvel0 + 6]
            T = g.root_kp * self._rv + g.root_kd * (tr.omega - w)
            for side, Fs, Ts in self.split(d, k, feet, F, T):
                leg = fi.legs[side]
                mujoco.mj_jac(m, d, self._jp, self._jr, d.xpos[fi.pelvis], leg["body"])
                cols = leg["cols"]
                tau = -(self._jp[:, cols].T @ Fs + self._jr[:, cols].T @ Ts)
                np.minimum(np.maximum(tau, -g.torque_clip, out=tau), g.torque_clip, out=tau)   # np.clip's arithmetic
                ids = leg["acts"]
                # the gains as they are now: the layer outlives a controller's set_gains
                d.ctrl[ids] = self._base[ids] + tau / np.maximum(m.actuator_gainprm[ids, 0], 1e-9)
