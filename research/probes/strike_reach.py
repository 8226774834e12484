"""Why planned punches miss in physics bouts: per planned strike window (both fighters standing),
how close the physical strike fist came to the opponent's head, chest or belly, and how close the
reference fist re-rooted on the physical body came (the reference pose relative to the reference
pelvis, put on the physical pelvis: where a perfect tracker of the pose would put the fist). Also
the fist's peak extension from the shoulder against the reference's, and the time shift that best
aligns the physical fist with its reference.

    python -m research.probes.strike_reach --graph G.igz --seeds 1-10 [--tracker assisted[:CKPT]]
        [--arm-gain 2] [--arm-residual 0.5] [--arm-lead 2]

``--arm-gain``: the shoulder and elbow PD gains (and torque limits) times this; ``--arm-residual``:
the learned tracker's residuals on those joints times this (0: plain PD arms); ``--arm-lead``: the
shoulder and elbow PD targets taken this many control steps further ahead in the reference (the
policy's residuals added as before).
"""
from __future__ import annotations

import argparse
import json
import types

import numpy as np


def parse_seeds(s: str) -> list[int]:
    a, _, b = s.partition("-")
    return list(range(int(a), int(b) + 1)) if b else [int(x) for x in s.split(",")]


def wrap_arm_residual(trk, scale: float, act_class) -> None:
    """Scale the tracker's residuals on the shoulder and elbow actuators by ``scale``."""
    orig = trk.act
    arm = np.array([c in ("upper_arm", "forearm") for c in act_class])

    def act(self, env, obs):
        t, w = orig(env, obs)
        ref = env.reference_targets()
        t = np.array(t)
        t[:, arm] = ref[:, arm] + scale * (t[:, arm] - ref[:, arm])
        return t, w

    trk.act = types.MethodType(act, trk)


def wrap_arm_lead(trk, lead: int, act_class) -> None:
    """Shoulder and elbow PD targets from the reference ``lead`` more control steps ahead."""
    orig = trk.act
    arm = np.array([c in ("upper_arm", "forearm") for c in act_class])

    def act(self, env, obs):
        t, w = orig(env, obs)
        t = np.array(t)
        base = env.config.target_lead
        t[:, arm] += env.reference_targets(base + lead)[:, arm] - env.reference_targets(base)[:, arm]
        return t, w

    trk.act = types.MethodType(act, trk)


def main(argv=None) -> int:
    import mujoco

    from igraph_fight.graph import load_graph
    from motion_graph.rotations import wrap_angle
    from tracker.body.frames import z_rotation
    from tracker.bouts.loaders import load_tracker, make_agent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.setup import BoutConfig, BoutSetup

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", required=True)
    ap.add_argument("--seeds", default="1-10")
    ap.add_argument("--tracker", default="assisted")
    ap.add_argument("--arm-gain", type=float, default=1.0)
    ap.add_argument("--arm-residual", type=float, default=1.0)
    ap.add_argument("--arm-lead", type=int, default=0)
    ap.add_argument("--out", default=None, help="write the figures as JSON")
    a = ap.parse_args(argv)
    g = load_graph(a.graph)
    lib = g.load_library()
    trk = load_tracker(a.tracker)
    if a.arm_gain != 1.0:
        trk.gain_scale = tuple(trk.gain_scale) + (("upper_arm", a.arm_gain), ("forearm", a.arm_gain))
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), tracker=trk)
    fm = setup.scene.fighters[0]
    if a.arm_residual != 1.0:
        wrap_arm_residual(trk, a.arm_residual, fm.act_class)
    if a.arm_lead:
        wrap_arm_lead(trk, a.arm_lead, fm.act_class)
    agents = [make_agent("infighter", g, lib, 5), make_agent("outboxer", g, lib, 5)]
    m = setup.scene.model
    scratch = mujoco.MjData(m)
    body_of = {int(j): int(b) for b, j in zip(fm.body_ids, fm.body_joints)}
    shoulder = [body_of[int(lib.parts["l_shoulder"])], body_of[int(lib.parts["r_shoulder"])]]
    fist_geom = [int(fm.geom_label["l_fist"][0]), int(fm.geom_label["r_fist"][0])]

    def ref_fist(q, side):
        scratch.qpos[fm.qpos_slice] = q
        mujoco.mj_kinematics(m, scratch)
        return scratch.geom_xpos[fist_geom[side]].copy(), scratch.xpos[shoulder[side]].copy()

    rows, shifts = [], {dl: [] for dl in range(-2, 5)}
    totals = {"planned": 0, "realised": 0}
    for seed in parse_seeds(a.seeds):
        bout = PhysicsBout(setup, agents, trk, BoutConfig(record_qpos=False))
        bout.start(seed)
        win: dict = {}
        track: dict = {}
        for _ in range(bout.n_steps):
            bout.step()
            t = bout.env.t
            d = bout.env.data
            for k in (0, 1):
                f = bout.F[k]
                adr = bout.fms[k].qpos_adr
                Rz = z_rotation(float(wrap_angle(f.ref_yaw[t] - bout.physical_yaw(k))))
                for side in (0, 1):
                    # the physical fist carried into the reference frame (re-rooted at t)
                    phys = d.geom_xpos[setup.scene.fighters[k].geom_label[("l_fist", "r_fist")[side]][0]]
                    rf, rs = ref_fist(f.ref.qpos[t], side)
                    track[(k, side, t)] = (Rz @ (phys - d.qpos[adr:adr + 3]) + f.ref.qpos[t, :3], rf, rs,
                                           Rz.T @ (rf - f.ref.qpos[t, :3]) + d.qpos[adr:adr + 3])
                if bout.F[0].down or bout.F[1].down:
                    continue
                for w0, w1, side in bout.planned_windows(k, t):
                    if side < 0 or not w0 <= t < w1:
                        continue
                    key = (k, w0, w1, side)
                    gp = bout.judge.fist_target_distance(d, k, 1 - k, side)
                    rr = track[(k, side, t)][3]
                    gr = float(np.linalg.norm(rr - bout.judge.target_point(d, bout.judge.nearest_target(d, 1 - k, rr),
                                                                         rr, 0.0))) - float(m.geom_size[fist_geom[side], 0])
                    s = win.setdefault(key, [np.inf, np.inf])
                    s[0], s[1] = min(s[0], gp), min(s[1], gr)
        r = bout.finish().summary()
        totals["planned"] += r["planned_hits"]
        totals["realised"] += r["planned_realised"]
        for (k, w0, w1, side), (gp, gr) in win.items():
            landed = any(h["attacker"] == k and w0 <= h["frame"] < w1 and h["fist"].startswith("lr"[side])
                         for h in bout.hit_events)
            ts = [tt for tt in range(w0, w1) if (k, side, tt) in track]
            ext_p = max(np.linalg.norm(track[(k, side, tt)][0] - track[(k, side, tt)][2]) for tt in ts)
            ext_r = max(np.linalg.norm(track[(k, side, tt)][1] - track[(k, side, tt)][2]) for tt in ts)
            rows.append((gp, gr, landed, ext_p / max(ext_r, 1e-9)))
            for dl in shifts:
                e = [np.linalg.norm(track[(k, side, tt)][0] - track[(k, side, tt - dl)][1]) for tt in ts
                     if (k, side, tt - dl) in track]
                if e:
                    shifts[dl].append(float(np.mean(e)))
        print(f"seed {seed}: {len(win)} planned strike windows", flush=True)
    R = np.array(rows, float).reshape(-1, 4)
    reach = R[:, 1] < 0.02
    far = R[:, 1] > 0.05
    out = {"seeds": a.seeds, "tracker": a.tracker, "arm_gain": a.arm_gain, "arm_residual": a.arm_residual, "arm_lead": a.arm_lead,
           "planned_hits": totals["planned"], "planned_realised": totals["realised"],
           "windows": int(len(R)), "windows_landed": int(R[:, 2].sum()),
           "closest_gap_m_median": float(np.median(R[:, 0])) if len(R) else None,
           "rerooted_reference_gap_m_median": float(np.median(R[:, 1])) if len(R) else None,
           "reference_reaches": int(reach.sum()), "reference_reaches_landed": int(R[reach, 2].sum()),
           "reference_out_of_reach": int(far.sum()), "reference_out_of_reach_landed": int(R[far, 2].sum()),
           "peak_extension_ratio_median": float(np.median(R[:, 3])) if len(R) else None,
           "fist_error_m_by_delay_frames": {dl: float(np.mean(v)) for dl, v in shifts.items() if v}}
    print(json.dumps(out, indent=1))
    if a.out:
        with open(a.out, "w") as fh:
            json.dump(out, fh, indent=1)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
