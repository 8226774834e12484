"""Probes of balance by changing the motion or the whole-body control (issue 7);
none adopted.

    python -m research.probes.tracker_stepping_probes step [--walks N]   # capture-point stepping over the layer
    python -m research.probes.tracker_stepping_probes idqp [--walks N]   # inverse-dynamics QP with contact forces
    python -m research.probes.tracker_stepping_probes feet [--walks N]   # box soles vs contact spheres under the layer

Random 20-action library walks of seed 100 (the tuning seed), mean time to fall, no force on the
root; each subcommand runs a fixed list of settings (what research/notes/TRAINING.md reports).

- step: a stepping rule on top of PD + the virtual-force layer (tracker/track/vforce.py, default gains).
  Once per control step the capture point xi = c + v sqrt(h / g) (centre of mass c, velocity v,
  h = 0.9 m) is compared with the support. Trigger ``hull``: xi outside the convex hull of the
  feet's floor contacts by more than ``margin``; trigger ``error``: the capture point's offset
  from the stance feet minus the reference's (same feet, as the layer compares) longer than
  ``margin``. A step: the swing foot (the one leading along the error, ``choose="near"``, or the
  other, ``"far"``; the foot in the air when only one touches) moves to its position plus the
  error (``error``) or to xi (``hull``), at most ``max_step`` away and never across the stance
  foot (``min_lat``), along a smooth path lifted ``lift`` at mid-swing over ``swing_s``; the leg's
  PD targets come from a damped least-squares inverse kinematics of the foot (hip, knee, ankle;
  position and the foot's orientation at lift-off) on the current body, the swing leg's gains
  times ``boost``; the foot is left out of the layer's wrench split during the swing. After the
  landing the leg's target offset is held ``hold_s`` and faded over ``hold_s``.
- idqp: the classic whole-body controller instead of the layer: once per control step (or every
  ``every`` substeps) a bounded least-squares problem over the joint accelerations and the
  contact forces (each foot-floor contact point's force in a 4-sided friction pyramid, mu 0.7):
  root dynamics rows of M a + h = J^T f as a heavily weighted equality; desired accelerations
  a_des = reference acceleration x ``ff`` + kp (reference - q) + kd (reference velocity - v) for the
  joints, and for the root's translation the feet-relative centre-of-mass error (the layer's); a
  damping term on the contact points' velocities. The joint torques M a + h - J^T f are applied
  through the PD servos (targets offset by (tau - tau_PD) / kp).
- feet: ``ModelOptions(foot="box")`` soles against the default contact spheres, PD and PD + layer.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, replace

import mujoco
import numpy as np
from scipy.optimize import lsq_linear
from scipy.spatial import ConvexHull, QhullError


from tracker.track.evaluation import draw_walks, make_setup, walk_reference
from tracker.body.humanoid import ModelOptions
from tracker.track.pd import PDController
from tracker.track.vforce import BalanceGains, VirtualForceBalance, LegMap, BalanceTarget
from tracker.track.walks import walk_source

G = 9.81
H_COM = 0.9          # m, the capture point's pendulum height


def _other(side: str) -> str:
    return "r" if side == "l" else "l"


# ------------------------------------------------------------------------------ stepping rule
@dataclass(frozen=True)
class StepConfig:
    trigger: str = "error"     # "error" (capture point vs the reference's) or "hull" (outside the contacts)
    margin: float = 0.35       # m
    choose: str = "near"       # swing foot: "near" (leading along the error) or "far"
    swing_s: float = 0.27
    lift: float = 0.05         # m
    max_step: float = 0.5      # m
    min_lat: float = 0.12      # m
    hold_s: float = 0.6
    cooldown_s: float = 0.1
    boost: float = 1.0         # swing leg PD gains multiplied during the swing
    ik_iters: int = 6


class SteppingBalance(VirtualForceBalance):
    """The layer plus the stepping rule (module doc), one fighter."""

    def __init__(self, env, cfg: StepConfig) -> None:
        super().__init__(env)
        self.cfg = cfg
        self.env_fighter = env.scene.fighters[0]
        self.scratch = mujoco.MjData(env.model)
        self.jp = np.zeros((3, env.model.nv))
        self.jr = np.zeros((3, env.model.nv))
        self.swing: dict | None = None
        self.plant: dict[str, dict] = {}
        self.saved = None
        self.t_last = -10 ** 9
        self.n_steps = 0
        self.landings: list[tuple[float, float]] = []   # (planned step length m, fraction covered)
        self.errors: list[tuple[int, float]] = []        # (control step, |capture-point error| m)

    def restore(self) -> None:
        if self.saved is not None:
            ids, g0, b0 = self.saved
            self.model.actuator_gainprm[ids, 0] = g0
            self.model.actuator_biasprm[ids, 1:3] = b0
            self.saved = None

    def split(self, d, k, feet, F, T):
        if self.swing is not None and self.swing["side"] in feet and len(feet) > 1:
            feet = [f for f in feet if f != self.swing["side"]]
        return super().split(d, k, feet, F, T)

    def substep(self, env, d, s) -> None:
        if s == 0:
            self._control(env, d)
        super().substep(env, d, s)

    def _contacts(self, d) -> dict[str, list[np.ndarray]]:
        pts = {"l": [], "r": []}
        for i in range(d.ncon):
            c = d.contact[i]
            o = (self.foot_of(c.geom2) if c.geom1 == self.floor else
                 self.foot_of(c.geom1) if c.geom2 == self.floor else None)
            if o is not None and o[0] == 0:
                pts[o[1]].append(c.pos[:2].copy())
        return pts

    @staticmethod
    def _outside(x: np.ndarray, P: np.ndarray) -> float:
        """Distance (m) of x outside the convex hull of the points P (<= 0 inside); a lower bound."""
        if len(P) >= 3:
            try:
                return float(max(a * x[0] + b * x[1] + c for a, b, c in ConvexHull(P).equations))
            except QhullError:
                pass
        a, b = P[0], P[-1]
        ab = b - a
        u = np.clip(np.dot(x - a, ab) / max(np.dot(ab, ab), 1e-12), 0.0, 1.0)
        return float(np.linalg.norm(x - (a + u * ab)))

    def _ik(self, d, side: str, pos: np.ndarray, quat: np.ndarray) -> np.ndarray:
        """Leg actuator targets placing the foot body at pos / quat, from the current body."""
        m, dd = self.model, self.scratch
        fi, f = self.fighters[0], self.env_fighter
        leg = fi.legs[side]
        dd.qpos[:] = d.qpos
        qv, qe, qc, rv = np.zeros(m.nv), np.zeros(4), np.zeros(4), np.zeros(3)
        for _ in range(self.cfg.ik_iters):
            mujoco.mj_kinematics(m, dd)
            mujoco.mj_comPos(m, dd)
            mujoco.mju_negQuat(qc, dd.xquat[leg["body"]])
            mujoco.mju_mulQuat(qe, quat, qc)
            mujoco.mju_quat2Vel(rv, qe if qe[0] >= 0 else -qe, 1.0)
            mujoco.mj_jac(m, dd, self.jp, self.jr, dd.xpos[leg["body"]], leg["body"])
            J = np.vstack([self.jp[:, leg["cols"]], 0.3 * self.jr[:, leg["cols"]]])
            e = np.r_[pos - dd.xpos[leg["body"]], 0.3 * rv]
            dq = J.T @ np.linalg.solve(J @ J.T + 1e-3 * np.eye(6), e)
            dq *= min(1.0, 0.3 / max(float(np.abs(dq).max()), 1e-12))
            qv[:] = 0.0
            qv[leg["cols"]] = dq
            mujoco.mj_integratePos(m, dd.qpos, qv, 1.0)
        out = np.zeros(len(leg["acts"]))
        for n, a in enumerate(leg["acts"]):
            i = a - f.act_adr
            adr = int(f.joint_qpos[int(f.act_joint[i])])
            q = dd.qpos[adr:adr + 4]
            mujoco.mju_quat2Vel(rv, q if q[0] >= 0 else -q, 1.0)
            out[n] = rv[int(f.act_axis[i])]
        return out

    def _control(self, env, d) -> None:
        cfg, fi, ref = self.cfg, self.fighters[0], env.refs[0]
        dt = 1.0 / env.config.control_hz
        t = env.t
        for side, pl in list(self.plant.items()):
            age = (t - pl["t0"]) * dt
            w = 1.0 if age < cfg.hold_s else 1.0 - (age - cfg.hold_s) / cfg.hold_s
            if w <= 0.0:
                del self.plant[side]
            else:
                d.ctrl[fi.legs[side]["acts"]] += w * pl["delta"]
        sw = self.swing
        if sw is not None:
            ph = min((t + 1 - sw["t0"]) * dt / cfg.swing_s, 1.0)
            sm = ph * ph * (3.0 - 2.0 * ph)
            pos = sw["p0"] + sm * (sw["p1"] - sw["p0"])
            pos[2] += cfg.lift * np.sin(np.pi * ph)
            leg = fi.legs[sw["side"]]
            tgt = self._ik(d, sw["side"], pos, sw["quat"])
            d.ctrl[leg["acts"]] = tgt
            if ph >= 1.0:
                want = sw["p1"][:2] - sw["p0"][:2]
                got = d.xpos[leg["body"], :2] - sw["p0"][:2]
                self.landings.append((float(np.linalg.norm(want)), float(got @ want) / max(float(want @ want), 1e-9)))
                kref = min(t + 1, env.t_end)
                self.plant[sw["side"]] = dict(t0=t, delta=tgt - ref.ctrl[kref][leg["acts"] - self.env_fighter.act_adr])
                self.swing = None
                self.restore()
                self.t_last = t
            return
        if (t - self.t_last) * dt < cfg.cooldown_s:
            return
        pts = self._contacts(d)
        sides = [s for s in ("l", "r") if pts[s]]
        if not sides:
            return
        mujoco.mj_subtreeVel(self.model, d)
        c, v = d.subtree_com[fi.pelvis][:2], d.subtree_linvel[fi.pelvis][:2]
        xi = c + v * np.sqrt(H_COM / G)
        if cfg.trigger == "hull":
            if self._outside(xi, np.array(pts["l"] + pts["r"])) < cfg.margin:
                return
            err = None
        else:
            tr = self._frames[0]
            tr.update(self.env_fighter, fi, ref, min(t + 1, env.t_end))
            fs = np.mean([d.geom_xpos[fi.legs[s]["geoms"], :2].mean(0) for s in sides], axis=0)
            fr = np.mean([tr.feet[s] for s in sides], axis=0)
            err = (c - fs) - (tr.com[:2] - fr) + np.sqrt(H_COM / G) * (v - tr.vel[:2])
            self.errors.append((t, float(np.linalg.norm(err))))
            if float(np.linalg.norm(err)) < cfg.margin:
                return
        if len(sides) == 2:
            aim = err if err is not None else xi - c
            centre = {s: d.geom_xpos[fi.legs[s]["geoms"], :2].mean(0) for s in sides}
            lead = max(sides, key=lambda s: float(centre[s] @ aim))
            swing = lead if cfg.choose == "near" else _other(lead)
        else:
            swing = _other(sides[0])
        stance = _other(swing)
        body = fi.legs[swing]["body"]
        p0 = d.xpos[body].copy()
        sc = d.xpos[fi.legs[stance]["body"], :2]
        if err is not None:
            goal = p0[:2] + err
        else:
            goal = xi + (p0[:2] - d.geom_xpos[fi.legs[swing]["geoms"], :2].mean(0))
        step = goal - p0[:2]
        n = float(np.linalg.norm(step))
        if n > cfg.max_step:
            goal = p0[:2] + step * cfg.max_step / n
        lat = (d.xmat[fi.pelvis].reshape(3, 3) @ env._cache[0].lateral)[:2]
        lat /= max(float(np.linalg.norm(lat)), 1e-9)
        sgn = 1.0 if swing == "l" else -1.0
        lc = float((goal - sc) @ lat) * sgn
        if lc < cfg.min_lat:
            goal = goal + (cfg.min_lat - lc) * sgn * lat
        p1 = p0.copy()
        p1[:2] = goal
        p1[2] = min(p0[2], d.xpos[fi.legs[stance]["body"], 2])
        self.swing = dict(side=swing, t0=t, p0=p0, p1=p1, quat=d.xquat[body].copy())
        self.plant.pop(swing, None)
        ids = fi.legs[swing]["acts"]
        self.saved = (ids, self.model.actuator_gainprm[ids, 0].copy(), self.model.actuator_biasprm[ids, 1:3].copy())
        self.model.actuator_gainprm[ids, 0] *= cfg.boost
        self.model.actuator_biasprm[ids, 1:3] *= cfg.boost
        self.n_steps += 1


# ------------------------------------------------------------------------------ inverse-dynamics QP
@dataclass(frozen=True)
class QPConfig:
    kp_c: float = 40.0     # 1/s^2: feet-relative centre-of-mass error -> root linear acceleration
    kd_c: float = 10.0
    kp_o: float = 100.0    # root orientation
    kd_o: float = 20.0
    kp_j: float = 200.0    # joints
    kd_j: float = 28.0
    w_root: float = 1.0
    w_joint: float = 0.05
    w_contact: float = 1.0
    contact_damping: float = 10.0   # 1/s
    w_force: float = 1e-5
    w_dynamics: float = 100.0
    mu: float = 0.7
    every: int = 8         # physics substeps between solves
    ff: float = 1.0        # reference accelerations' weight (finite differences of the mocap)


class InverseDynamicsQP:
    """Sits in the env's balance slot (module doc), one fighter."""

    active = True

    def __init__(self, env, cfg: QPConfig) -> None:
        m = env.model
        self.m, self.cfg = m, cfg
        f = env.scene.fighters[0]
        self.f, self.fi, self.frame = f, LegMap(m, f), BalanceTarget(m)
        self.side_of = {int(g): s for s, leg in self.fi.legs.items() for g in leg["geoms"]}
        self.cols = np.array([int(f.joint_qvel[int(j)]) + int(a) for j, a in zip(f.act_joint, f.act_axis)])
        self.ids = np.arange(f.ctrl_slice.start, f.ctrl_slice.stop)
        self.M = np.zeros((m.nv, m.nv))
        self.err = np.zeros(m.nv)
        self.jp = np.zeros((3, m.nv))
        self.base = np.zeros(m.nu)
        self.solve_s, self.n_solve = 0.0, 0

    def substep(self, env, d, s) -> None:
        if s == 0:
            self.base[:] = d.ctrl
        if s % self.cfg.every:
            return
        t0 = time.perf_counter()
        tau = self.solve(env, d)
        self.solve_s += time.perf_counter() - t0
        self.n_solve += 1
        m, ids = self.m, self.ids
        if tau is None:
            d.ctrl[ids] = self.base[ids]
            return
        kp, kd = m.actuator_gainprm[ids, 0], -m.actuator_biasprm[ids, 2]
        mujoco.mj_transmission(m, d)
        tau_pd = kp * (self.base[ids] - d.actuator_length[ids]) - kd * d.qvel[self.cols]
        tau = np.clip(tau, m.actuator_forcerange[ids, 0], m.actuator_forcerange[ids, 1])
        d.ctrl[ids] = self.base[ids] + (tau - tau_pd) / kp

    def solve(self, env, d) -> np.ndarray | None:
        cfg, m = self.cfg, self.m
        floor = env.scene.floor_geom
        cols_g, rows_j, feet = [], [], set()
        for i in range(d.ncon):
            c = d.contact[i]
            g = int(c.geom2) if c.geom1 == floor else int(c.geom1) if c.geom2 == floor else -1
            if g not in self.side_of:
                continue
            feet.add(self.side_of[g])
            fr = c.frame.reshape(3, 3)
            n = fr[0] if c.geom1 == floor else -fr[0]      # floor -> foot
            mujoco.mj_jac(m, d, self.jp, None, c.pos, int(m.geom_bodyid[g]))
            B = np.stack([n + cfg.mu * fr[1], n - cfg.mu * fr[1], n + cfg.mu * fr[2], n - cfg.mu * fr[2]], axis=1)
            cols_g.append(self.jp.T @ B)
            rows_j.append(self.jp.copy())
        if not cols_g:
            return None
        Gm, Jc = np.concatenate(cols_g, axis=1), np.concatenate(rows_j, axis=0)
        nv, nl = m.nv, Gm.shape[1]
        mujoco.mj_fullM(m, d, self.M)
        h = d.qfrc_bias - d.qfrc_passive
        ref = env.refs[0]
        t = min(env.t + 1, env.t_end)
        a_ref = (ref.qvel[t] - ref.qvel[max(t - 1, 0)]) * ref.fps * cfg.ff
        mujoco.mj_differentiatePos(m, self.err, 1.0, d.qpos, ref.qpos[t])
        a_des = a_ref + cfg.kp_j * self.err + cfg.kd_j * (ref.qvel[t] - d.qvel)
        a_des[3:6] = a_ref[3:6] + cfg.kp_o * self.err[3:6] + cfg.kd_o * (ref.qvel[t, 3:6] - d.qvel[3:6])
        tr = self.frame
        tr.update(self.f, self.fi, ref, t)
        mujoco.mj_subtreeVel(m, d)
        c, v = d.subtree_com[self.fi.pelvis], d.subtree_linvel[self.fi.pelvis]
        sides = sorted(feet)
        fs = np.mean([d.geom_xpos[self.fi.legs[s]["geoms"], :2].mean(0) for s in sides], axis=0)
        fr_ = np.mean([tr.feet[s] for s in sides], axis=0)
        e = np.r_[(tr.com[:2] - fr_) - (c[:2] - fs), ref.qpos[t, 2] - d.qpos[2]]
        a_des[0:3] = cfg.kp_c * e + cfg.kd_c * (tr.vel - v)
        Z = np.zeros
        blocks, rhs = [], []

        def add(A, b, w):
            blocks.append(A * np.sqrt(w))
            rhs.append(b * np.sqrt(w))
        A = Z((nv, nv + nl))
        A[:, :nv] = np.eye(nv)
        add(A[:6], a_des[:6], cfg.w_root)
        add(A[6:], a_des[6:], cfg.w_joint)
        add(np.concatenate([self.M[:6], -Gm[:6]], axis=1), -h[:6], cfg.w_dynamics)
        add(np.concatenate([Jc, Z((len(Jc), nl))], axis=1), -cfg.contact_damping * (Jc @ d.qvel), cfg.w_contact)
        A = Z((nl, nv + nl))
        A[:, nv:] = np.eye(nl)
        add(A, Z(nl), cfg.w_force)
        res = lsq_linear(np.concatenate(blocks), np.concatenate(rhs),
                         bounds=(np.r_[np.full(nv, -np.inf), Z(nl)], np.full(nv + nl, np.inf)), method="bvls")
        a, lam = res.x[:nv], res.x[nv:]
        return (self.M @ a + h - Gm @ lam)[self.cols]


# ------------------------------------------------------------------------------ runs
def run(env, ctrl, ref, make=None) -> float:
    """Seconds tracked from frame 0 until the fall or the reference's end, with ``make(env)``'s
    object in the env's balance slot (wrapping the controller's layer gains) when given."""
    obs = env.reset(ref, 0)
    ctrl.reset(env)
    inner = env.balance
    if make is not None:
        obj = make(env)
        if isinstance(obj, VirtualForceBalance) and inner is not None:
            obj.gains = list(inner.gains)
        env.balance = obj
    try:
        while True:
            obs, _, done, _ = env.step(ctrl.act(env, obs))
            if done:
                return env.sim_time
    finally:
        if make is not None:
            if hasattr(env.balance, "restore"):
                env.balance.restore()
            env.balance = inner


def _runs(env, ctrl, refs, cls, cfg) -> tuple[list[float], list]:
    """Times to fall over the walks with a fresh ``cls(env, cfg)`` in the balance slot for each walk,
    and those objects (their counters)."""
    made: list = []

    def make(e):
        made.append(cls(e, cfg))
        return made[-1]
    return [run(env, ctrl, r, make) for r in refs], made


def _walks(walks: int, options: ModelOptions = ModelOptions()):
    setup = make_setup(walk_source(None), options=options)
    return setup, [walk_reference(setup, w)[1] for w in draw_walks(setup.source, walks, 20, 100)]


def step(walks: int) -> None:
    setup, refs = _walks(walks)
    env = setup.env
    layer = PDController(balance=BalanceGains().as_tuple())
    # the relative trigger's error before the layer's falls (a margin that never triggers)
    spans = [(1.2, 99.0), (0.6, 1.2), (0.4, 0.6), (0.2, 0.4), (0.0, 0.2)]
    prof: dict = {sp: [] for sp in spans}
    ts, made = _runs(env, layer, refs, SteppingBalance, StepConfig(margin=np.inf))
    for t_end, sb in zip(ts, made):
        for t, e in sb.errors:
            before = t_end - t / 30.0
            for sp in spans:
                if sp[0] <= before < sp[1]:
                    prof[sp].append(e)
    print(f"PD + layer, no stepping: {np.mean(ts):.3f} s; capture-point error vs the reference (median) by time "
          "before the end: " + ", ".join(f"{lo:.1f}-{hi:.1f} s {100 * np.median(prof[(lo, hi)]):.0f} cm"
                                          for lo, hi in spans), flush=True)
    base = StepConfig()
    settings = [("hull", dict(trigger="hull", margin=m, choose="far")) for m in (0.03, 0.08, 0.15, 0.25)]
    settings += [("error", dict(margin=m)) for m in (0.3, 0.35, 0.45)]
    settings += [("error", dict(choose="far")), ("error", dict(hold_s=0.2)), ("error", dict(boost=3.0)),
                 ("error", dict(boost=6.0)), ("error", dict(swing_s=0.4))]
    for label, kw in settings:
        ts, holder = _runs(env, layer, refs, SteppingBalance, replace(base, **kw))
        n = sum(h.n_steps for h in holder)
        land = np.array([x for h in holder for x in h.landings]).reshape(-1, 2)
        print(f"PD + layer + stepping ({label}: {kw}): {np.mean(ts):.3f} s, {n / sum(ts):.2f} steps per second; "
              f"completed swings: planned step {np.median(land[:, 0]) * 100:.0f} cm (median), "
              f"covered {np.median(land[:, 1]) * 100:.0f}% of it", flush=True)


def idqp(walks: int) -> None:
    setup, refs = _walks(walks)
    env = setup.env
    pd = PDController()
    print(f"PD: {np.mean([run(env, pd, r) for r in refs]):.3f} s", flush=True)
    layer = PDController(balance=BalanceGains().as_tuple())
    print(f"PD + layer: {np.mean([run(env, layer, r) for r in refs]):.3f} s", flush=True)
    base = QPConfig()
    for kw in ({}, dict(every=4), dict(every=2), dict(w_joint=0.005), dict(w_joint=0.5), dict(kp_c=100.0, kd_c=20.0),
               dict(kp_c=15.0, kd_c=6.0), dict(ff=0.0), dict(ff=0.0, w_joint=0.5)):
        ts, holder = _runs(env, pd, refs, InverseDynamicsQP, replace(base, **kw))
        ms = 1000.0 * sum(q.solve_s for q in holder) / max(sum(q.n_solve for q in holder), 1)
        print(f"PD + inverse-dynamics QP {kw}: {np.mean(ts):.3f} s ({ms:.1f} ms per solve)", flush=True)


def feet(walks: int) -> None:
    for foot in ("spheres", "box"):
        setup, refs = _walks(walks, ModelOptions(foot=foot))
        env = setup.env
        for name, c in (("PD", PDController()), ("PD + layer", PDController(balance=BalanceGains().as_tuple()))):
            print(f"feet {foot:7s} {name:10s}: {np.mean([run(env, c, r) for r in refs]):.3f} s", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("probe", choices=("step", "idqp", "feet"))
    ap.add_argument("--walks", type=int, default=24)
    a = ap.parse_args(argv)
    t0 = time.time()
    {"step": step, "idqp": idqp, "feet": feet}[a.probe](a.walks)
    print(f"({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
