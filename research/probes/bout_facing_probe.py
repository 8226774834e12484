"""Where standing fighters go in a physics bout: per action the reference's and the body's pelvis
ground displacement (towards the opponent) and yaw change, and the facing angle and off-graph share
of the decisions (research/notes/BOUTS.md). Hit-odds fighters (infighter+phys against
outboxer+phys), one bout:

    python -m research.probes.bout_facing_probe --graph G.igz --tracker search --seconds 20 --seed 1
    python -m research.probes.bout_facing_probe --graph G.igz --assist --seconds 40     # bodies on their references
"""
from __future__ import annotations

import argparse
import collections
import json
import sys
import time
from pathlib import Path

import numpy as np



def _wrap(a):
    return (a + np.pi) % (2 * np.pi) - np.pi


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--graph", required=True)
    ap.add_argument("--tracker", default=None, help="as tracker.bouts.agents.load_tracker (default: the shipped policy)")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--assist", action="store_true", help="root assist: NOT physics, the kinematic-equivalent bout")
    ap.add_argument("--decisions-out", default="", help="write the bout's decisions here (JSON)")
    a = ap.parse_args(argv)
    from igraph_fight.graph import load_graph
    from tracker.bouts.setup import BoutConfig, BoutSetup
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.loaders import load_tracker, make_agent
    g = load_graph(a.graph)
    lib = g.load_library()
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), root_assist=a.assist)
    bout = PhysicsBout(setup, [make_agent("infighter+phys", g, lib, 5), make_agent("outboxer+phys", g, lib, 5)],
                       load_tracker(a.tracker), BoutConfig(seconds=a.seconds))
    w0 = time.perf_counter()
    bout.start(a.seed)
    n = bout.n_steps
    P = np.zeros((n + 1, 2, 2))
    Y = np.zeros((n + 1, 2))
    down = np.zeros((n + 1, 2), bool)
    P[0] = [bout.pelvis_xy(0), bout.pelvis_xy(1)]
    Y[0] = [bout.physical_yaw(0), bout.physical_yaw(1)]
    for i in range(n):
        bout.step()
        P[i + 1] = [bout.pelvis_xy(0), bout.pelvis_xy(1)]
        Y[i + 1] = [bout.physical_yaw(0), bout.physical_yaw(1)]
        down[i + 1] = [f.down for f in bout.F]
    wall = time.perf_counter() - w0
    disp, yaw = collections.defaultdict(list), collections.defaultdict(list)
    for k in range(2):
        f = bout.F[k]
        for s in f.segments:
            t0, t1 = s.t0, s.t0 + int(bout.nf[s.action]) - 1
            if s.hold or t0 < 0 or t1 > n or down[t0:t1 + 1].any():
                continue
            u = P[t0, 1 - k] - P[t0, k]
            u /= np.linalg.norm(u) + 1e-9                     # towards the opponent
            dr, dp = f.ref.qpos[t1, :2] - f.ref.qpos[t0, :2], P[t1, k] - P[t0, k]
            lab = lib.labels[s.action]
            disp[lab].append((dr @ u, dp @ u))
            yaw[lab].append((_wrap(f.ref_yaw[t1] - f.ref_yaw[t0]), _wrap(Y[t1, k] - Y[t0, k])))
    print(f"{a.seconds:.0f} s bout of seed {a.seed}, tracker: {getattr(bout.tracker, 'describe', lambda: '?')()}"
          f"{' (ROOT ASSIST: not physics)' if a.assist else ''}; wall {wall:.0f} s ({a.seconds / wall:.2f}x real time)")
    print("action       n   towards the opponent, reference / body (cm)   yaw change, reference / body (deg)")
    for lab in sorted(disp):
        d, y = np.array(disp[lab]) * 100, np.degrees(np.array(yaw[lab]))
        print(f"{lab:11s} {len(d):3d}   {d[:, 0].mean():7.1f} / {d[:, 1].mean():7.1f}   "
              f"{y[:, 0].mean():7.1f} / {y[:, 1].mean():7.1f}")
    alld = np.concatenate([np.array(v) for v in disp.values()]) if disp else np.zeros((0, 2))
    ally = np.concatenate([np.array(v) for v in yaw.values()]) if yaw else np.zeros((0, 2))
    dist = np.linalg.norm(P[:, 0] - P[:, 1], axis=1)
    th = np.array([abs(x["theta_self"]) for x in bout.decisions])
    off = [getattr(ag, "off_graph", 0) / max(1, getattr(ag, "decisions", 1)) for ag in bout.agents]
    out = {"towards_opponent_cm_reference": float(alld[:, 0].sum() * 100),
           "towards_opponent_cm_body": float(alld[:, 1].sum() * 100),
           "yaw_error_rms_rad": float(np.sqrt(np.mean(np.square(_wrap(ally[:, 1] - ally[:, 0]))))) if len(ally) else None,
           "mean_abs_theta_self_rad": float(th.mean()), "off_graph_share": float(np.mean(off)),
           "mean_distance_m": float(dist.mean()), "falls": len(bout.fall_events), "realtime_factor": a.seconds / wall}
    print(json.dumps(out))
    if a.decisions_out:
        Path(a.decisions_out).write_text(json.dumps(bout.decisions))
    return 0


if __name__ == "__main__":
    sys.exit(main())
