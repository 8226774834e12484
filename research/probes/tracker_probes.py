"""Probes of why PD tracking falls, and of three cheap fixes that did not work (issue 7).

Random 20-action library walks of seed 100 (the tuning seed; the reported evaluation uses seed 0),
PD tracking with the default gains, no force on the root. Results: research/notes/TRAINING.md.

    python -m research.probes.tracker_probes held      [--walks N]   # one frame held still: does it stand?
    python -m research.probes.tracker_probes reference [--walks N]   # PD on cleaned-up references
    python -m research.probes.tracker_probes tvlqr     [--walks N]   # time-varying LQR around the reference
    python -m research.probes.tracker_probes friction  [--walks N]   # PD with other floor / foot friction
    python -m research.probes.tracker_probes stiff-feet [--walks N]  # held frames with stiffer feet and toes
    python -m research.probes.tracker_probes support   [--walks N]   # foot clearance, fall direction, mean pose

- held: a random frame of each walk held still (reference velocity 0, lowest foot point on the
  floor). Reports the time to fall and whether the centre of mass (ground projection) lies inside
  the convex hull of the floor contacts after 0.2 s, once the body has settled on its feet.
- reference: the walk's reference (a) as built, (b) with feet (and toes) turned flat when the foot
  is within 6 cm of the floor (fully below 2 cm): the sole parallel to the floor, (c) with the
  whole body moved down every frame so that its lowest foot point is on the floor (no flight
  phases), (d) both.
- friction: PD on the walks with the sliding friction of the floor and the feet set to 0.25-2.0.
- stiff-feet: the held frames with the toe gains and torque limits x10 and the ankles' x5.
- support: (a) the reference's foot clearance: per frame, the height of each foot's lowest contact
  sphere above the floor (fractions of frames within 1 / 2 / 3 cm, one foot, both, none); (b) the
  direction of PD's falls: the centre of mass minus the centroid of the foot contact spheres, in
  the pelvis's facing frame, 10 control steps (0.33 s) before the fall; (c) the calibration's
  mean pose (every joint at its rest rotation, the stance the model is built around) held still
  under PD with the default gains and with every gain and torque limit x5 (a near-rigid statue).
- tvlqr: the dynamics linearised around every reference frame (mujoco.mjd_transitionFD, one
  physics step, composed over the control step's substeps), an affine finite-horizon LQR
  (deviation from the reference, drift term included), its feedback added to the PD targets.
"""
from __future__ import annotations

import argparse
import sys
import time

import mujoco
import numpy as np
from scipy.spatial import Delaunay
from scipy.spatial.transform import Rotation


from tracker.track.evaluation import draw_walks, make_setup
from tracker.track.pd import PDController
from tracker.track.reference import (
    FootPenetration, Reference, build_reference, ctrl_targets, qpos_velocity, site_positions)
from tracker.track.walks import walk_source


# ---------------------------------------------------------------------------------------------- feet
def foot_bodies(m: mujoco.MjModel, f) -> list[dict]:
    """Per foot: body id, its contact spheres, the sole normal in the body frame, the ankle's qpos
    address and the toe joints' qpos addresses."""
    out = []
    for side in ("l_foot", "r_foot"):
        bodies: dict[int, list[int]] = {}
        for g in f.geom_label[side]:
            if m.geom_contype[g] or m.geom_conaffinity[g]:
                bodies.setdefault(int(m.geom_bodyid[g]), []).append(int(g))
        b = next(b for b in bodies if int(m.body_parentid[b]) not in bodies)
        c = m.geom_pos[bodies[b]]
        n = np.linalg.svd(c - c.mean(0))[2][-1]
        n = n if n @ (-c.mean(0)) > 0 else -n            # pointing from the sole towards the ankle
        toes = [int(m.jnt_qposadr[int(m.body_jntadr[t])]) - f.qpos_adr for t in bodies if t != b and m.body_jntnum[t]]
        out.append(dict(body=b, geoms=bodies[b], normal=n, ankle=int(m.jnt_qposadr[int(m.body_jntadr[b])]) - f.qpos_adr,
                        toes=toes))
    return out


def _wxyz(r: Rotation) -> np.ndarray:
    x, y, z, w = r.as_quat()
    return np.array([w, x, y, z])


def flatten_feet(qpos: np.ndarray, m: mujoco.MjModel, f, feet: list[dict], full_m: float = 0.02,
                 none_m: float = 0.06) -> np.ndarray:
    """Turn each foot so its sole is parallel to the floor, fully when its lowest contact sphere is
    below ``full_m``, blended to nothing at ``none_m``; toes straightened with the same weight."""
    qpos = qpos.copy()
    d = mujoco.MjData(m)
    for t in range(len(qpos)):
        d.qpos[f.qpos_slice] = qpos[t]
        mujoco.mj_kinematics(m, d)
        for ft in feet:
            b = ft["body"]
            Rf = d.xmat[b].reshape(3, 3)
            nw = Rf @ ft["normal"]
            low = min(d.geom_xpos[g][2] - m.geom_size[g][0] for g in ft["geoms"])
            w = float(np.clip((none_m - low) / (none_m - full_m), 0.0, 1.0))
            axis = np.cross(nw, [0.0, 0.0, 1.0])
            s = np.linalg.norm(axis)
            if w == 0.0 or s < 1e-9:
                continue
            Rc = Rotation.from_rotvec(axis / s * np.arctan2(s, nw[2]) * w).as_matrix()
            p = int(m.body_parentid[b])
            Rbody = Rotation.from_quat(np.r_[m.body_quat[b][1:], m.body_quat[b][0]]).as_matrix()
            Rj = (d.xmat[p].reshape(3, 3) @ Rbody).T @ Rc @ Rf
            qpos[t, ft["ankle"]:ft["ankle"] + 4] = _wxyz(Rotation.from_matrix(Rj))
            for a in ft["toes"]:
                rv = Rotation.from_quat(np.r_[qpos[t, a + 1:a + 4], qpos[t, a]]).as_rotvec() * (1.0 - w)
                qpos[t, a:a + 4] = _wxyz(Rotation.from_rotvec(rv))
    return qpos


def rebuilt(ref: Reference, scene, f, qpos: np.ndarray, ground_every_frame: bool = False,
            lift: bool = True) -> Reference:
    """A Reference from edited qpos: lifted like build_reference's "auto", or (ground_every_frame)
    moved down per frame so the lowest foot point is on the floor, or (``lift=False``) left where
    it is."""
    qpos = qpos.copy()
    sites, low = site_positions(scene, f, qpos)
    shift = (low if ground_every_frame else np.full(len(low), float(np.percentile(low, 10)))) if lift \
        else np.zeros(len(low))
    qpos[:, 2] -= shift
    sites = sites - np.c_[np.zeros((len(low), 2)), shift][:, None, :]
    qvel = qpos_velocity(qpos, f, ref.fps)
    ctrl, ctrl_vel = ctrl_targets(qpos, qvel, f)
    return Reference(ref.fps, qpos, qvel, ctrl, ctrl_vel, sites, FootPenetration.from_depths(-(low - shift)),
                     ref.source, {})


def held(ref: Reference, scene, f, k: int, frames: int = 150) -> Reference:
    """Frame k held still for ``frames`` control steps, its lowest foot point on the floor."""
    return rebuilt(ref, scene, f, np.repeat(ref.qpos[k:k + 1], frames, 0), ground_every_frame=True)


# ---------------------------------------------------------------------------------------------- runs
def track(env, ref: Reference, pd: PDController, feedback=None, probe_at: int | None = None, after_step=None):
    """PD tracking (plus ``feedback(t, data) -> target offsets``; ``after_step(env)`` called after
    every control step); returns (time tracked s, probe)."""
    obs = env.reset(ref, 0)
    pd.reset(env)
    probe = None
    for t in range(ref.n_frames - 1):
        u = env.reference_targets()
        if feedback is not None:
            u = u + feedback(t, env.data)
        obs, _, done, info = env.step(u)
        if after_step is not None:
            after_step(env)
        if probe_at is not None and t + 1 == probe_at:
            probe = com_inside_contacts(env)
        if done:
            break
    return env.sim_time, probe


def com_inside_contacts(env) -> bool | None:
    """Whether the centre of mass's ground projection is inside the hull of the floor contacts."""
    d, sc = env.data, env.scene
    pts = [d.contact[i].pos[:2].copy() for i in range(d.ncon) if sc.floor_geom in (d.contact[i].geom1, d.contact[i].geom2)]
    if len(pts) < 3:
        return False if pts else None
    com = d.subtree_com[sc.fighters[0].pelvis_body][:2]
    try:
        return bool(Delaunay(np.array(pts)).find_simplex(com) >= 0)
    except Exception:      # collinear contacts: a hull of zero area
        return False


class TVLQR:
    """Affine finite-horizon LQR around a reference; see the module doc."""

    def __init__(self, env, ref: Reference, pd: PDController, frames: int, q_diag: dict, r: float) -> None:
        m = env.model
        nv, nu = m.nv, m.nu
        self.m, self.ref = m, ref
        pd.reset(env)                                  # the PD gains the linearisation sees
        d = mujoco.MjData(m)
        A, B = np.zeros((2 * nv, 2 * nv)), np.zeros((2 * nv, nu))
        As, Bs, cs = [], [], []
        for t in range(frames):
            u = ref.ctrl[min(t + 1, ref.n_frames - 1)]
            mujoco.mj_resetData(m, d)
            d.qpos[:], d.qvel[:], d.ctrl[:] = ref.qpos[t], ref.qvel[t], u
            mujoco.mj_forward(m, d)
            mujoco.mjd_transitionFD(m, d, 1e-6, True, A, B, None, None)
            Ac, Bc = np.eye(2 * nv), np.zeros((2 * nv, nu))
            for _ in range(env.substeps):
                Bc = A @ Bc + B
                Ac = A @ Ac
            mujoco.mj_resetData(m, d)
            d.qpos[:], d.qvel[:], d.ctrl[:] = ref.qpos[t], ref.qvel[t], u
            mujoco.mj_step(m, d, nstep=env.substeps)
            As.append(Ac)
            Bs.append(Bc)
            cs.append(self.deviation(d, t + 1))
        q = np.zeros(2 * nv)
        q[0:2], q[2], q[3:6], q[6:nv], q[nv:] = (q_diag["root_xy"], q_diag["root_z"], q_diag["root_rot"],
                                                 q_diag["joints"], q_diag["vel"])
        Q, R = np.diag(q), np.eye(nu) * r
        P, p = Q.copy(), np.zeros(2 * nv)
        self.K, self.k = [None] * frames, [None] * frames
        for t in reversed(range(frames)):
            A, B, c = As[t], Bs[t], cs[t]
            H = R + B.T @ P @ B
            K = -np.linalg.solve(H, B.T @ P @ A)
            k = -np.linalg.solve(H, B.T @ (P @ c + p))
            Acl = A + B @ K
            p = K.T @ R @ k + Acl.T @ (P @ (B @ k + c) + p)
            P = Q + K.T @ R @ K + Acl.T @ P @ Acl
            P = 0.5 * (P + P.T)
            self.K[t], self.k[t] = K, k

    def deviation(self, d: mujoco.MjData, t: int) -> np.ndarray:
        dq = np.zeros(self.m.nv)
        mujoco.mj_differentiatePos(self.m, dq, 1.0, self.ref.qpos[t], d.qpos)
        return np.r_[dq, d.qvel - self.ref.qvel[t]]

    def __call__(self, t: int, d: mujoco.MjData) -> np.ndarray:
        if t >= len(self.K):
            return 0.0
        return self.k[t] + self.K[t] @ self.deviation(d, t)


# ---------------------------------------------------------------------------------------------- main
FRICTIONS = (0.25, 0.4, 0.6, 1.0, 2.0)


class ScaledPD(PDController):
    """PD with the gains and torque limits of some segment classes scaled ({class: factor})."""

    def __init__(self, scale: dict[str, float]) -> None:
        super().__init__()
        self.scale = scale

    def gains(self, env):
        out = []
        for k, (kp, kd, tq) in enumerate(super().gains(env)):
            s = np.array([self.scale.get(c, 1.0) for c in env.scene.fighters[k].act_class])
            out.append((kp * s, kd * s, tq * s))
        return out


def foot_clearance(scene, f, refs: list[Reference]) -> tuple[np.ndarray, np.ndarray]:
    """(frames,) heights (m) of the left and the right foot's lowest contact sphere above the floor."""
    m = scene.model
    d = mujoco.MjData(m)
    sides = [np.array([g for g in f.geom_label[sd] if m.geom_contype[g] or m.geom_conaffinity[g]]) for sd in ("l_foot", "r_foot")]
    out = []
    for ref in refs:
        for t in range(ref.n_frames):
            d.qpos[f.qpos_slice] = ref.qpos[t]
            mujoco.mj_kinematics(m, d)
            out.append([float((d.geom_xpos[g, 2] - m.geom_size[g, 0]).min()) for g in sides])
    h = np.array(out)
    return h[:, 0], h[:, 1]


def fall_direction(env, ref: Reference, pd: PDController, before: int = 10) -> tuple[float, np.ndarray]:
    """PD on ref; (time tracked s, centre of mass minus foot-sphere centroid in the facing frame
    (x: right-to-left hip line, y: backwards) ``before`` control steps before the fall)."""
    from tracker.body.frames import ground_yaw
    f, d = env.scene.fighters[0], env.data
    lateral = env._cache[0].lateral
    hist = []

    def record(env) -> None:
        yaw = ground_yaw(d.xmat[f.pelvis_body].reshape(3, 3), lateral)
        v = d.subtree_com[f.pelvis_body][:2] - d.geom_xpos[f.foot_geoms, :2].mean(0)
        cy, sy = np.cos(yaw), np.sin(yaw)
        hist.append((cy * v[0] + sy * v[1], -sy * v[0] + cy * v[1]))

    t, _ = track(env, ref, pd, after_step=record)
    return t, np.array(hist[max(0, len(hist) - before)])


def rest_pose(ref: Reference, scene, f, frames: int = 300) -> Reference:
    """The calibration's mean pose (every ball joint at its rest rotation) held still, grounded."""
    m = scene.model
    q = ref.qpos[:1].copy()
    for j in range(m.njnt):
        a = int(m.jnt_qposadr[j]) - f.qpos_adr
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_BALL and 0 <= a < q.shape[1]:
            q[0, a:a + 4] = (1.0, 0.0, 0.0, 0.0)
    return rebuilt(ref, scene, f, np.repeat(q, frames, 0), ground_every_frame=True)


def support(scene, env, f, refs: list[Reference], pd: PDController) -> None:
    """Print the reference foot clearance, the direction of PD's falls and the mean pose held still."""
    hl, hr = foot_clearance(scene, f, refs)
    for th in (0.01, 0.02, 0.03):
        lo, ro = hl < th, hr < th
        print(f"reference frames with the foot's lowest point within {th * 100:.0f} cm of the floor: left {lo.mean():.0%}, "
              f"right {ro.mean():.0%}, both {(lo & ro).mean():.0%}, neither {(~lo & ~ro).mean():.0%}")
    print(f"median height of the lower foot's lowest point: {np.median(np.minimum(hl, hr)) * 100:.1f} cm "
          f"({len(hl)} frames)")
    rows = [fall_direction(env, ref, pd) for ref in refs]
    v = np.array([r[1] for r in rows])
    fwd = v[:, 1] < 0
    print(f"PD falls ({len(rows)} walks, mean time to fall {np.mean([r[0] for r in rows]):.2f} s): 0.33 s before the fall "
          f"the centre of mass is ahead of the feet in {fwd.mean():.0%} (mean {-v[fwd, 1].mean() * 100:.0f} cm ahead), "
          f"mean |sideways| {np.abs(v[:, 0]).mean() * 100:.0f} cm")
    rest = rest_pose(refs[0], scene, f)
    stiff = ScaledPD({c: 5.0 for c in set(f.act_class)})
    print(f"mean pose held still: default gains {track(env, rest, pd)[0]:.2f} s, every gain and torque limit x5 "
          f"{track(env, rest, stiff)[0]:.2f} s (of {rest.n_frames / 30:.0f} s)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("held", "reference", "tvlqr", "friction", "stiff-feet", "support"))
    ap.add_argument("--walks", type=int, default=12)
    ap.add_argument("--seed", type=int, default=100)
    a = ap.parse_args(argv)
    src = walk_source(None)
    setup = make_setup(src)
    scene, env = setup.scene, setup.env
    f = scene.fighters[0]
    m = scene.model
    feet = foot_bodies(m, f)
    pd = PDController()
    rng = np.random.default_rng(a.seed)
    rows = []
    t0 = time.time()
    if a.what == "support":
        support(scene, env, f, [build_reference(src.sequence_motion(w), scene, 0) for w in draw_walks(src, a.walks, 20, a.seed)], pd)
        print(f"{a.walks} walks, {time.time() - t0:.0f} s")
        return 0
    for w in draw_walks(src, a.walks, 20, a.seed):
        ref = build_reference(src.sequence_motion(w), scene, 0)
        if a.what == "friction":
            base = m.geom_friction.copy()
            row = []
            for mu in FRICTIONS:
                m.geom_friction[scene.floor_geom, 0] = m.geom_friction[f.foot_geoms, 0] = mu
                row.append(track(env, ref, pd)[0])
            m.geom_friction[:] = base
            rows.append(row)
            print("walk: " + "  ".join(f"mu {mu}: {x:.2f}" for mu, x in zip(FRICTIONS, row)), flush=True)
        elif a.what == "stiff-feet":
            k = int(rng.integers(0, ref.n_frames - 1))
            h = held(ref, scene, f, k)
            rows.append([track(env, h, pd)[0], track(env, h, ScaledPD({"toe": 10.0, "foot": 5.0}))[0]])
            print(f"frame {k:4d}: default gains {rows[-1][0]:.2f} s, toes x10 and ankles x5 {rows[-1][1]:.2f} s", flush=True)
        elif a.what == "held":
            k = int(rng.integers(0, ref.n_frames - 1))
            flat = rebuilt(ref, scene, f, flatten_feet(ref.qpos, m, f, feet))
            (t_a, in_a), (t_b, in_b) = (track(env, held(r, scene, f, k), pd, probe_at=6) for r in (ref, flat))
            rows.append((t_a, t_b, in_a is True, in_b is True))
            print(f"frame {k:4d}: as built {t_a:.2f} s (CoM inside contacts at 0.2 s: {in_a}), "
                  f"feet flattened {t_b:.2f} s ({in_b})", flush=True)
        elif a.what == "reference":
            fl = flatten_feet(ref.qpos, m, f, feet)
            refs = (ref, rebuilt(ref, scene, f, fl), rebuilt(ref, scene, f, ref.qpos, True), rebuilt(ref, scene, f, fl, True))
            rows.append([track(env, r, pd)[0] for r in refs])
            print("walk: " + "  ".join(f"{x:.2f}" for x in rows[-1]), flush=True)
        else:
            frames = min(150, ref.n_frames - 2)
            row = [track(env, ref, pd)[0]]
            for qd, r in ((dict(root_xy=1.0, root_z=10.0, root_rot=30.0, joints=3.0, vel=0.1), 0.3),
                          (dict(root_xy=1.0, root_z=10.0, root_rot=30.0, joints=3.0, vel=0.1), 30.0),
                          (dict(root_xy=0.3, root_z=10.0, root_rot=100.0, joints=1.0, vel=0.03), 1.0)):
                row.append(track(env, ref, pd, TVLQR(env, ref, pd, frames, qd, r))[0])
            rows.append(row)
            print("walk: PD %.2f  TVLQR %s" % (row[0], "  ".join(f"{x:.2f}" for x in row[1:])), flush=True)
    R = np.array(rows, float)
    if a.what == "friction":
        print("mean time to fall (s): " + ", ".join(f"friction {mu}: {x:.2f}" for mu, x in zip(FRICTIONS, R.mean(0))))
    elif a.what == "stiff-feet":
        print(f"held frames, mean time to fall: default gains {R[:, 0].mean():.2f} s, toes x10 and ankles x5 "
              f"{R[:, 1].mean():.2f} s")
    elif a.what == "held":
        print(f"held frames, mean time to fall: as built {R[:, 0].mean():.2f} s, feet flattened {R[:, 1].mean():.2f} s; "
              f"CoM inside the contacts at 0.2 s: {R[:, 2].mean():.0%} / {R[:, 3].mean():.0%}")
    elif a.what == "reference":
        print("mean time to fall (s): as built %.2f, feet flattened %.2f, grounded every frame %.2f, both %.2f" % tuple(R.mean(0)))
    else:
        print("mean time to fall (s): PD %.2f; PD + TVLQR over the first 5 s (R 0.3) %.2f, (R 30) %.2f, (root-heavy) %.2f"
              % tuple(R.mean(0)))
    print(f"{len(rows)} walks, {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
