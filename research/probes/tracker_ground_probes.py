"""Probes of static support and of a grounded reference (issue 7); not adopted.

    python -m research.probes.tracker_ground_probes statue [--frames 0,30,60,90,120]
    python -m research.probes.tracker_ground_probes ground [--walks N] [--controllers pd,layer,policy] [--no-com]
                                                      [--stance-height M]
    python -m research.probes.tracker_ground_probes recover [--walks N] [--threshold M]
    python -m research.probes.tracker_ground_probes guard --graph G.igz [--bouts N] [--plant]
    python -m research.probes.tracker_ground_probes speed [--walks N] [--speeds 1,0.8,0.6]
    python -m research.probes.tracker_ground_probes legs [--walks N]

Walks: random 20-action library walks of seed 100 (the tuning seed); no force on the root.
Controllers: PD, PD + the balance layer (tracker/track/vforce.py, default gains), the shipped policy
(over the layer). Results: research/notes/TRAINING.md.

- statue: frames of the first seed-100 walk, each held still for 10 s (the time tracked before the
  fall, 9.97 s = stood). ``raw``: the mocap frame as it is (grounded so its lowest foot point is
  on the floor); ``planted``: the same frame with both soles put flat on the floor and the centre
  of mass over the centroid of the sole contact points, by a damped least-squares IK over the root
  translation and rotation and the leg joints (the upper body untouched); ``rigid``: the planted
  pose as one rigid body (the fighter's joints removed from the MJCF, their rotations baked into
  the bodies), dropped on the floor.
- ground: the walk's reference made statically friendlier before tracking (``Grounder``): a foot
  whose lowest contact sphere is within ``stance_height`` of the floor is in stance; a stance run
  (split where the foot travels more than 8 cm) is planted at its mean position, flat, every sole
  sphere on the floor; swing frames follow the reference's foot path shifted by an offset blended
  between the neighbouring plants; the centre of mass is pulled into the hull of the stance feet's
  soles (3 cm margin, at most 12 cm, smoothed over 0.1 s); a per-frame leg + root-translation IK
  (40 damped least-squares iterations, warm-started from the previous frame) meets those targets.
  Mean time to fall on the reference as built against the grounded one.
- recover: PD + the layer on the walks; once the centre of mass's offset from the feet's sole
  points differs from the reference's by more than ``threshold`` (metres, horizontal), the
  reference becomes a planted statue of the current pose (feet flat where they are, root
  translation and legs by the IK, centre of mass over the soles) for 1 s, blended back over 8
  frames into the walk at the frame it left. Seconds up (a walk ends at 30 s or at its end),
  walk seconds covered, recoveries and seconds spent in them; ``--threshold 100`` never triggers.
- guard: physics bouts (60 s, seeds 0.., infighter+phys against the RL baseline); with ``--plant``
  every guard action of the library (both fighters play library actions) is replaced by a planted
  statue of its first frame (the statue probe's IK, root rotation free) held for the action's
  length. Falls per minute, score, hits, mean distance.
- speed: the walks played slower (the motion resampled to 30 / speed fps and tracked at 30 Hz):
  time to fall and the motion's seconds covered before it, PD + layer and the shipped policy.
- legs: the legs' PD gains and torque limits scaled per segment (the statue probe: softer ankles
  fall sooner); time to fall and the contact-force-weighted foot sliding
  (research/probes/tracker_vforce_cem.py's measure), PD + layer and the shipped policy.
"""
from __future__ import annotations

import argparse
import sys
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import mujoco
import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.spatial import ConvexHull


from tracker.track.controllers import make_controller
from tracker.track.evaluation import draw_walks, make_setup, track_reference, walk_reference
from tracker.track.pd import PDController
from tracker.track.reference import FootPenetration, Reference
from tracker.track.walks import walk_source
from research.probes.tracker_probes import rebuilt  # noqa: E402
from tracker.track.policy_net import DEFAULT_CKPT  # noqa: E402

SEED = 100
POLICY = str(DEFAULT_CKPT)


def controllers(names: list[str]) -> dict:
    make = {"pd": PDController, "layer": PDController.balanced, "policy": lambda: make_controller("learned", POLICY)}
    return {n: make[n]() for n in names}


@dataclass
class GroundConfig:
    stance_height_m: float = 0.05    # lowest sole sphere within this of the floor: the foot is in stance
    min_stance_frames: int = 3
    slide_split_m: float = 0.08      # a stance run is split where the foot has travelled this far
    com: bool = True                 # pull the centre of mass into the support
    com_margin_m: float = 0.03
    com_max_shift_m: float = 0.12
    com_sigma_frames: float = 3.0
    iters: int = 40
    w_z: float = 10.0
    w_xy: float = 4.0
    w_com: float = 2.0
    w_root_z: float = 0.1


class Grounder:
    """Leg IK that plants the feet flat and pulls the centre of mass into the support (module doc)."""

    def __init__(self, scene, fm, cfg: GroundConfig = GroundConfig(), free_root_rotation: bool = False) -> None:
        self.m, self.fm, self.cfg = scene.model, fm, cfg
        m = self.m
        self.d = mujoco.MjData(m)
        body = {mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, int(b)): int(b) for b in fm.body_ids}
        self.root = int(fm.body_ids[0])
        dofs = [fm.qvel_adr + i for i in range(6 if free_root_rotation else 3)]
        self.foot_body = {}
        for sd, side in (("l", "Left"), ("r", "Right")):
            for part in ("UpLeg", "Leg", "Foot", "ToeBase"):
                b = body[f"{fm.prefix}{side}{part}"]
                a = int(m.jnt_dofadr[m.body_jntadr[b]])
                dofs += [a, a + 1, a + 2]
            self.foot_body[sd] = body[f"{fm.prefix}{side}Foot"]
        self.dofs = np.array(dofs)
        self.leg_joints = sorted({int(m.dof_jntid[a]) for a in dofs[6 if free_root_rotation else 3:]})
        self.spheres = {}
        for sd in "lr":
            gs = [int(g) for g in fm.geom_label[f"{sd}_foot"] if (m.geom_contype[g] or m.geom_conaffinity[g])
                  and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_SPHERE]
            on_foot = [g for g in gs if m.geom_bodyid[g] == self.foot_body[sd]]
            r_max = max(m.geom_size[g, 0] for g in on_foot)
            self.spheres[sd] = dict(all=gs, heel=[g for g in on_foot if m.geom_size[g, 0] >= r_max - 1e-6],
                                    ball=[g for g in on_foot if m.geom_size[g, 0] < r_max - 1e-6])

    def _pose(self, q: np.ndarray) -> None:
        self.d.qpos[self.fm.qpos_slice] = q
        mujoco.mj_kinematics(self.m, self.d)
        mujoco.mj_comPos(self.m, self.d)

    def _jac(self, g: int) -> np.ndarray:
        jp = np.zeros((3, self.m.nv))
        mujoco.mj_jac(self.m, self.d, jp, None, self.d.geom_xpos[g], self.m.geom_bodyid[g])
        return jp

    def _points(self, sd: str) -> tuple[np.ndarray, np.ndarray, float]:
        S, d, m = self.spheres[sd], self.d, self.m
        low = min(d.geom_xpos[g, 2] - m.geom_size[g, 0] for g in S["all"])
        return d.geom_xpos[S["heel"]].mean(0), d.geom_xpos[S["ball"]].mean(0), low

    def plan(self, qpos: np.ndarray) -> dict:
        """Per frame and foot: stance flag, heel / ball targets (world); the centre-of-mass target."""
        cfg, T = self.cfg, len(qpos)
        heel, ball, low, com = {s: np.zeros((T, 3)) for s in "lr"}, {s: np.zeros((T, 3)) for s in "lr"}, \
            {s: np.zeros(T) for s in "lr"}, np.zeros((T, 2))
        for t, q in enumerate(qpos):
            self._pose(q)
            for sd in "lr":
                heel[sd][t], ball[sd][t], low[sd][t] = self._points(sd)
            com[t] = self.d.subtree_com[self.root][:2]
        plan = {}
        for sd in "lr":
            runs = _runs(low[sd] < cfg.stance_height_m, cfg.min_stance_frames)
            plants = []
            for a, b in runs:
                s0 = a
                for t in range(a, b):
                    if np.linalg.norm(heel[sd][t, :2] - heel[sd][s0, :2]) > cfg.slide_split_m and t - s0 >= cfg.min_stance_frames:
                        plants.append((s0, t))
                        s0 = t
                plants.append((s0, b))
            stance = np.zeros(T, bool)
            th, tb = heel[sd].copy(), ball[sd].copy()
            off, known = np.zeros((T, 2)), np.zeros(T, bool)
            for a, b in plants:
                stance[a:b] = True
                th[a:b, :2], tb[a:b, :2] = heel[sd][a:b, :2].mean(0), ball[sd][a:b, :2].mean(0)
                off[a:b], known[a:b] = th[a:b, :2] - heel[sd][a:b, :2], True
            if known.any() and not known.all():
                idx = np.arange(T)
                for k in range(2):
                    off[~known, k] = np.interp(idx[~known], idx[known], off[known, k])
                th[~stance, :2] += off[~stance]
                tb[~stance, :2] += off[~stance]
            plan[sd] = dict(stance=stance, heel=th, ball=tb)
        shift = np.zeros((T, 2))
        if cfg.com:
            for t in range(T):
                pts = []
                for sd in "lr":
                    if plan[sd]["stance"][t]:
                        h, b = plan[sd]["heel"][t, :2], plan[sd]["ball"][t, :2]
                        f = (b - h) / max(float(np.linalg.norm(b - h)), 1e-9)
                        lat = np.array([-f[1], f[0]])
                        pts += [h + 0.03 * lat, h - 0.03 * lat, b + 0.04 * lat, b - 0.04 * lat, b + 0.06 * f]
                if len(pts) >= 3:
                    shift[t] = _into_hull(np.array(pts), com[t], cfg.com_margin_m) - com[t]
            n = np.linalg.norm(shift, axis=1, keepdims=True)
            shift *= np.minimum(1.0, cfg.com_max_shift_m / np.maximum(n, 1e-9))
            shift = gaussian_filter1d(shift, cfg.com_sigma_frames, axis=0, mode="nearest")
        plan["com"], plan["com_shift"] = com + shift, shift
        return plan

    def solve(self, qpos: np.ndarray, plan: dict) -> np.ndarray:
        """The IK, frame by frame (warm start: the previous frame's legs and root offset)."""
        cfg, m, d, fm = self.cfg, self.m, self.d, self.fm
        out = qpos.copy()
        q = qpos[0].copy()
        for t in range(len(qpos)):
            prev = q
            q = qpos[t].copy()
            if t:
                q[:3] += prev[:3] - qpos[t - 1][:3]
                for j in self.leg_joints:
                    a = m.jnt_qposadr[j] - fm.qpos_adr
                    q[a:a + 4] = prev[a:a + 4]
            for _ in range(cfg.iters):
                self._pose(q)
                rows, errs = [], []
                for sd in "lr":
                    P, S = plan[sd], self.spheres[sd]
                    if P["stance"][t]:
                        for g in S["all"]:
                            rows.append(cfg.w_z * self._jac(g)[2])
                            errs.append(cfg.w_z * (m.geom_size[g, 0] - d.geom_xpos[g, 2]))
                    for key in ("heel", "ball"):
                        J = sum(self._jac(g) for g in S[key]) / len(S[key])
                        x = d.geom_xpos[S[key]].mean(0)
                        rows += [cfg.w_xy * J[0], cfg.w_xy * J[1]]
                        errs += list(cfg.w_xy * (P[key][t, :2] - x[:2]))
                        if not P["stance"][t]:
                            rows.append(cfg.w_xy * J[2])
                            errs.append(cfg.w_xy * (max(P[key][t, 2], 0.0) - x[2]))
                jc = np.zeros((3, m.nv))
                mujoco.mj_jacSubtreeCom(m, d, jc, self.root)
                rows += [cfg.w_com * jc[0], cfg.w_com * jc[1]]
                errs += list(cfg.w_com * (plan["com"][t] - d.subtree_com[self.root][:2]))
                rz = np.zeros(m.nv)
                rz[fm.qvel_adr + 2] = cfg.w_root_z
                rows.append(rz)
                errs.append(cfg.w_root_z * (qpos[t][2] - q[2]))
                J = np.array(rows)[:, self.dofs]
                dq = np.zeros(m.nv)
                dq[self.dofs] = np.linalg.solve(J.T @ J + 1e-3 * np.eye(len(self.dofs)), J.T @ np.array(errs))
                full = np.zeros(m.nq)
                full[fm.qpos_slice] = q
                mujoco.mj_integratePos(m, full, dq, 1.0)
                q = full[fm.qpos_slice].copy()
            out[t] = q
        return out


def _runs(flags: np.ndarray, min_len: int) -> list[tuple[int, int]]:
    out, t, T = [], 0, len(flags)
    while t < T:
        if flags[t]:
            u = t
            while u < T and flags[u]:
                u += 1
            if u - t >= min_len or t == 0 or u == T:
                out.append((t, u))
            t = u
        else:
            t += 1
    return out


def _into_hull(pts: np.ndarray, c: np.ndarray, margin: float) -> np.ndarray:
    eq = ConvexHull(pts).equations          # n . x + off <= 0 inside
    x = c.copy()
    for _ in range(20):
        viol = eq[:, :2] @ x + eq[:, 2] + margin
        k = int(np.argmax(viol))
        if viol[k] <= 0:
            break
        x = x - viol[k] * eq[k, :2]
    return x


def rigid_stands(scene, fm, q: np.ndarray, seconds: float = 10.0) -> float:
    """The pose as one rigid body (joints removed, rotations baked): seconds before the pelvis drops 30 cm."""
    m = scene.model
    root = ET.fromstring(scene.xml)
    for b in root.iter("body"):
        j = b.find("joint")
        if j is None or not b.get("name", "").startswith(fm.prefix):
            continue
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, j.get("name"))
        a = m.jnt_qposadr[jid] - fm.qpos_adr
        qb = np.array([float(x) for x in b.get("quat", "1 0 0 0").split()])
        out = np.zeros(4)
        mujoco.mju_mulQuat(out, qb, q[a:a + 4])
        b.set("quat", " ".join(f"{x:.9g}" for x in out))
        b.remove(j)
    act = root.find("actuator")
    if act is not None:
        root.remove(act)
    mr = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    d = mujoco.MjData(mr)
    d.qpos[:7] = q[:7]
    mujoco.mj_forward(mr, d)
    z0 = d.qpos[2]
    while d.time < seconds:
        mujoco.mj_step(mr, d)
        if d.qpos[2] < z0 - 0.3:
            return float(d.time)
    return seconds


def statue(frames: list[int]) -> None:
    setup = make_setup(walk_source(None))
    fm, env = setup.scene.fighters[0], setup.env
    _, ref = walk_reference(setup, draw_walks(setup.source, 1, 20, SEED)[0])
    ik = Grounder(setup.scene, fm, GroundConfig(com=False), free_root_rotation=True)
    ctrls = controllers(["pd", "layer", "policy"])
    print("frame | rigid planted | " + " | ".join(f"{n} raw / planted" for n in ctrls) + "  (s tracked of 10)")
    for k in frames:
        q0 = ref.qpos[k]
        q = _plant(ik, q0)
        planted = rebuilt(ref, setup.scene, fm, np.repeat(q[None], 300, 0), lift=False)
        raw = rebuilt(ref, setup.scene, fm, np.repeat(q0[None], 300, 0), ground_every_frame=True)
        row = [f"{rigid_stands(setup.scene, fm, q):.2f}"]
        for c in ctrls.values():
            times = []
            for r in (raw, planted):
                track_reference(env, c, r)
                times.append(f"{env.sim_time:.2f}")
            row.append(" / ".join(times))
        print(f"{k:5d} | " + " | ".join(row), flush=True)


def ground(walks: int, names: list[str], cfg: GroundConfig) -> None:
    setup = make_setup(walk_source(None))
    fm, env = setup.scene.fighters[0], setup.env
    ctrls = controllers(names)
    res = {f"{n}/{v}": [] for n in ctrls for v in ("as built", "grounded")}
    disp, shift, wall = [], [], []
    for w in draw_walks(setup.source, walks, 20, SEED):
        _, ref = walk_reference(setup, w)
        t0 = time.perf_counter()
        g = Grounder(setup.scene, fm, cfg)
        plan = g.plan(ref.qpos)
        gref = rebuilt(ref, setup.scene, fm, g.solve(ref.qpos, plan), lift=False)
        wall.append(time.perf_counter() - t0)
        disp.append(float(np.linalg.norm(gref.sites[:, fm.tracked] - ref.sites[:, fm.tracked], axis=-1).mean()))
        shift.append(float(np.linalg.norm(plan["com_shift"], axis=1).mean()))
        row = []
        for n, c in ctrls.items():
            for v, r in (("as built", ref), ("grounded", gref)):
                track_reference(env, c, r)
                res[f"{n}/{v}"].append(env.sim_time)
                row.append(f"{n}/{v} {env.sim_time:.2f}")
        print(f"walk {ref.duration:.1f} s: joints moved {disp[-1] * 100:.1f} cm, com shift {shift[-1] * 100:.1f} cm | "
              + ", ".join(row), flush=True)
    print(f"mean time to fall over {walks} walks: " + ", ".join(f"{k} {np.mean(v):.3f} s" for k, v in res.items()))
    print(f"grounding: joints moved {np.mean(disp) * 100:.1f} cm on average, centre of mass shifted "
          f"{np.mean(shift) * 100:.1f} cm, {np.mean(wall):.1f} s per walk")


def _nlerp(q0: np.ndarray, q1: np.ndarray, s: float) -> np.ndarray:
    q1 = -q1 if np.dot(q0, q1) < 0 else q1
    q = (1 - s) * q0 + s * q1
    return q / np.linalg.norm(q)


def _blend(qa: np.ndarray, qb: np.ndarray, s: float, m, fm) -> np.ndarray:
    q = (1 - s) * qa + s * qb
    q[3:7] = _nlerp(qa[3:7], qb[3:7], s)
    for j in range(m.njnt):
        a = m.jnt_qposadr[j] - fm.qpos_adr
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL and 0 <= a < fm.nq:
            q[a:a + 4] = _nlerp(qa[a:a + 4], qb[a:a + 4], s)
    return q


def _com_from_soles(g: Grounder, q: np.ndarray) -> np.ndarray:
    g._pose(q)
    pts = np.array([g.d.geom_xpos[x][:2] for sd in "lr" for x in g.spheres[sd]["all"]])
    return g.d.subtree_com[g.root][:2] - pts.mean(0)


def _plant(g: Grounder, q: np.ndarray) -> np.ndarray:
    """The pose with both soles flat where they are and the centre of mass over them."""
    g._pose(q)
    plan = {}
    for sd in "lr":
        h, b, _ = g._points(sd)
        plan[sd] = dict(stance=np.ones(1, bool), heel=h[None], ball=b[None])
    plan["com"] = np.array([g.d.geom_xpos[x][:2] for sd in "lr" for x in g.spheres[sd]["all"]]).mean(0)[None]
    return g.solve(q[None], plan)[0]


def recover_walk(setup, ctrl, ref: Reference, g: Grounder, threshold: float, hold: int = 30, blend: int = 8,
                 max_s: float = 30.0) -> tuple[float, bool, float, int, float]:
    """(seconds up, fell, walk seconds covered, recoveries, seconds in recovery) of one walk."""
    env, fm, m = setup.env, setup.scene.fighters[0], setup.scene.model
    obs = env.reset(ref, 0)
    ctrl.reset(env)
    left, t_walk, n_rec, rec_steps, fell = 0, 0, 0, 0, False
    while env.sim_time < max_s:
        if env.refs[0] is ref:
            q_sim = env.data.qpos[fm.qpos_slice].copy()
            if np.linalg.norm(_com_from_soles(g, q_sim) - _com_from_soles(g, ref.qpos[env.t])) > threshold:
                qp = _plant(g, q_sim)
                t_walk = env.t
                frames = [q_sim] + [qp] * hold + [_blend(qp, ref.qpos[t_walk], (i + 1) / blend, m, fm)
                                                  for i in range(blend)]
                rref = rebuilt(ref, setup.scene, fm, np.array(frames), lift=False)
                env.refs, env.t, env.t_end, env.done = [rref], 0, rref.n_frames - 1, False   # probe: swap in place
                left, n_rec = rref.n_frames - 1, n_rec + 1
        obs, _, done, info = env.step(ctrl.act(env, obs))
        fell = info.fall[0] is not None
        if env.refs[0] is not ref:
            rec_steps, left = rec_steps + 1, left - 1
            if fell:
                break
            if left <= 0:
                env.refs, env.t, env.t_end, env.done = [ref], t_walk, ref.n_frames - 1, False
                obs = env.observe(0)
        elif done:
            break
    covered = (env.t if env.refs[0] is ref else t_walk) / ref.fps
    return env.sim_time, fell, covered, n_rec, rec_steps / ref.fps


def recover(walks: int, threshold: float) -> None:
    setup = make_setup(walk_source(None))
    g = Grounder(setup.scene, setup.scene.fighters[0], GroundConfig(com=False))
    ctrl = controllers(["layer"])["layer"]
    rows = []
    for w in draw_walks(setup.source, walks, 20, SEED):
        _, ref = walk_reference(setup, w)
        rows.append(recover_walk(setup, ctrl, ref, g, threshold))
        r = rows[-1]
        print(f"walk {ref.duration:.1f} s: up {r[0]:.2f} s ({'fell' if r[1] else 'up'}), walk covered {r[2]:.2f} s, "
              f"{r[3]} recoveries ({r[4]:.2f} s)", flush=True)
    v = np.array(rows, dtype=float)
    print(f"threshold {threshold} m, {walks} walks: up {v[:, 0].mean():.3f} s, fell {v[:, 1].mean():.0%}, walk covered "
          f"{v[:, 2].mean():.2f} s, {v[:, 3].mean():.1f} recoveries, {v[:, 4].mean():.2f} s in recovery")


def guard(graph: str, bouts: int, plant: bool) -> None:
    from igraph_fight.graph import load_graph
    from motion_graph.classify import KINDS
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.loaders import load_tracker, make_agent
    from tracker.bouts.setup import BoutConfig, BoutSetup
    from tracker.body.frames import ground_yaws
    from tracker.track.policy_net import reference_balance
    g = load_graph(graph)
    lib = g.load_library()
    setup = BoutSetup.create(lib)
    trk = load_tracker(None)
    if plant:
        fm = setup.scene.fighters[0]
        ik = Grounder(setup.scene, fm, GroundConfig(com=False), free_root_rotation=True)
        for a in np.nonzero(np.asarray(lib.kinds) == KINDS.index("guard"))[0]:
            c = setup.action_reference(int(a))
            q = np.repeat(_plant(ik, c["qpos"][0])[None], len(c["qpos"]), 0)
            r = rebuilt(Reference(30.0, c["qpos"], c["qvel"], c["ctrl"], c["ctrl_vel"], c["sites"],
                                  FootPenetration.from_depths(np.zeros(1))), setup.scene, fm, q, lift=False)
            setup._refs[int(a)] = {"qpos": r.qpos, "qvel": r.qvel, "ctrl": r.ctrl, "ctrl_vel": r.ctrl_vel,
                                   "sites": r.sites, "balance": reference_balance(setup.env, 0, r),
                                   "yaw": ground_yaws(r.qpos[:, 3:7], setup.env._cache[0].lateral)}
    rows = []
    for seed in range(bouts):
        agents = [make_agent("infighter+phys", g, lib, 5), make_agent("rl", g, lib, 5)]
        s = PhysicsBout(setup, agents, trk, BoutConfig(seconds=60, record_qpos=False)).run(seed=seed).summary()
        rows.append(s)
        print(f"seed {seed}: score {s['score']:+.0f} ({s['hits_a']:.0f}-{s['hits_b']:.0f}), falls {s['falls_a']}-{s['falls_b']}, "
              f"distance {s['mean_distance_m']:.2f} m", flush=True)
    mean = lambda k: float(np.mean([r[k] for r in rows]))  # noqa: E731
    print(f"{'planted' if plant else 'mocap'} guard, {bouts} bouts: falls per minute IG {mean('falls_a'):.2f}, "
          f"RL {mean('falls_b'):.2f}; score {mean('score'):+.2f}; hits {sum(r['hits_a'] for r in rows):.0f} - "
          f"{sum(r['hits_b'] for r in rows):.0f}; distance {mean('mean_distance_m'):.2f} m")


def speed(walks: int, speeds: list[float]) -> None:
    from motion_graph.motion import Motion
    from tracker.track.reference import build_reference
    setup = make_setup(walk_source(None))
    ctrls = controllers(["layer", "policy"])
    res = {(n, s): [] for n in ctrls for s in speeds}
    for w in draw_walks(setup.source, walks, 20, SEED):
        mo = setup.source.sequence_motion(w, 4)
        for s in speeds:
            slow = mo.resample(30.0 / s)
            ref = build_reference(Motion(slow.skeleton, slow.rotations, slow.root_positions, 30.0,
                                         slow.local_translations, slow.source), setup.scene, 0, lift="auto")
            for n, c in ctrls.items():
                track_reference(setup.env, c, ref)
                res[(n, s)].append(setup.env.sim_time)
    for (n, s), v in res.items():
        print(f"{n}, speed {s}: time to fall {np.mean(v):.3f} s, motion covered {np.mean(v) * s:.3f} s")


def legs(walks: int) -> None:
    from research.probes import tracker_vforce_cem as cem
    from tracker.body.humanoid import KP, TORQUE
    cem._SETUP = make_setup(walk_source(None))
    cem._WALKS = draw_walks(cem._SETUP.source, walks, 20, SEED)
    ctrls = controllers(["layer", "policy"])
    kp0, tq0 = dict(KP), dict(TORQUE)
    try:
        for scale in ({}, {"foot": 2}, {"foot": 2, "toe": 3}, {"toe": 3},
                      {"foot": 2, "toe": 3, "shin": 1.5, "thigh": 1.5}, {"foot": 2, "toe": 3, "shin": 2, "thigh": 2}):
            KP.update({k: kp0[k] * v for k, v in scale.items()})      # the tables PDController reads
            TORQUE.update({k: tq0[k] * v for k, v in scale.items()})
            row = [f"{n} {t:.3f} s, sliding {sl:.3f} m/s" for n, (t, sl) in ((n, cem.sliding(c)) for n, c in ctrls.items())]
            print(f"{scale or 'as built'}: " + "; ".join(row), flush=True)
            KP.update(kp0)
            TORQUE.update(tq0)
    finally:
        KP.update(kp0)
        TORQUE.update(tq0)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("probe", choices=("statue", "ground", "recover", "guard", "speed", "legs"))
    ap.add_argument("--frames", default="0,30,60,90,120")
    ap.add_argument("--walks", type=int, default=24)
    ap.add_argument("--controllers", default="pd,layer,policy")
    ap.add_argument("--no-com", action="store_true", help="plant the feet only (no centre-of-mass shift)")
    ap.add_argument("--stance-height", type=float, default=GroundConfig.stance_height_m)
    ap.add_argument("--threshold", type=float, default=0.18, help="recover: trigger (metres)")
    ap.add_argument("--graph", default=None, help="guard: the graph file")
    ap.add_argument("--bouts", type=int, default=6, help="guard: bouts")
    ap.add_argument("--plant", action="store_true", help="guard: plant the guard actions")
    ap.add_argument("--speeds", default="1,0.8,0.6", help="speed: playback speeds")
    a = ap.parse_args(argv)
    t0 = time.time()
    if a.probe == "statue":
        statue([int(x) for x in a.frames.split(",")])
    elif a.probe == "guard":
        if not a.graph:
            ap.error("guard needs --graph")
        guard(a.graph, a.bouts, a.plant)
    elif a.probe == "legs":
        legs(a.walks)
    elif a.probe == "speed":
        speed(a.walks, [float(x) for x in a.speeds.split(",")])
    elif a.probe == "recover":
        recover(a.walks, a.threshold)
    else:
        ground(a.walks, a.controllers.split(","), GroundConfig(com=not a.no_com, stance_height_m=a.stance_height))
    print(f"({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
