"""More probes of why tracking falls (issue 7); none found a lever.

    python -m research.probes.tracker_probes_more contacts [--walks N]   # floor-contact stiffness vs time to fall
    python -m research.probes.tracker_probes_more pin      [--walks N]   # reference with the stance foot's sliding removed
    python -m research.probes.tracker_probes_more hazard   [--walks N] [--seed S] [--ckpt CKPT|pd]   # falls per action kind

Walks: 20-action library walks, seed 100 (the tuning seed) unless --seed; controllers: PD-only and
the shipped policy (tracker/checkpoints/boxing_cmu13.pt). Results: research/notes/TRAINING.md.

- contacts: every geom's solref time constant 0.02 s (MuJoCo's default, the model's) / 0.01 /
  0.005 s, or solimp (0.99, 0.99) instead of (0.9, 0.95): stiffer, harder floor contacts.
- pin: the reference's root moved, frame by frame, against the horizontal motion of the lower
  foot while it is within 2 cm of the floor (in this and the previous frame), so the stance foot
  does not slide (the data's feet slide at a median 20-24 cm/s, DESIGN section 9; simulated feet
  stick). Velocities and PD targets are recomputed from the moved root.
- hazard: each fall attributed to the action playing 0.3 s before it was detected (the topple
  takes about that long); per action kind, seconds executed, falls, falls per second.
"""
from __future__ import annotations

import argparse
import sys
import time

import mujoco
import numpy as np

from motion_graph.classify import KINDS
from tracker.track.evaluation import draw_walks, make_setup, run_walk, track_reference, walk_reference
from tracker.track.pd import PDController
from tracker.track.policy_net import load_policy
from tracker.track.grounding import lowest_point
from tracker.track.reference import Reference
from tracker.track.walks import walk_source
from research.probes.tracker_probes import rebuilt   # research/probes/tracker_probes.py: a Reference from edited qpos

SHIPPED = "tracker/checkpoints/boxing_cmu13.pt"


def track(env, ctrl, ref) -> float:
    """Seconds tracked from frame 0 until the fall (or the reference's end): the evaluation's loop."""
    track_reference(env, ctrl, ref)
    return env.sim_time


def pinned(ref: Reference, scene, contact_m: float = 0.02) -> tuple[Reference, float]:
    """The reference with the root moved so the lower foot does not slide while on the floor; also
    the mean speed of the root correction (m/s)."""
    fm = scene.fighters[0]
    m = scene.model
    d = mujoco.MjData(m)
    feet = [np.asarray(fm.geom_label[s], int) for s in ("l_foot", "r_foot")]
    T = ref.qpos.shape[0]
    low = np.zeros((T, 2))
    xy = np.zeros((T, 2, 2))
    for t in range(T):
        d.qpos[fm.qpos_slice] = ref.qpos[t]
        mujoco.mj_kinematics(m, d)
        for i, g in enumerate(feet):
            lp = lowest_point(m, d, g)
            low[t, i] = lp.min()
            xy[t, i] = d.geom_xpos[g[np.argmin(lp)], :2]
    off = np.zeros((T, 2))
    o = np.zeros(2)
    for t in range(1, T):
        i = int(np.argmin(low[t]))
        if low[t, i] < contact_m and low[t - 1, i] < contact_m:
            o = o - (xy[t, i] - xy[t - 1, i])
        off[t] = o
    q = ref.qpos.copy()
    q[:, :2] += off
    speed = float(np.abs(np.diff(off, axis=0)).sum() / max(T - 1, 1) * ref.fps)
    return rebuilt(ref, scene, fm, q), speed     # a horizontal move keeps the lift: velocities, targets, sites


def contacts(src, setup, walks, ctrls) -> None:
    m = setup.scene.model
    sr0, si0 = m.geom_solref.copy(), m.geom_solimp.copy()
    refs = [walk_reference(setup, w)[1] for w in walks]
    for name, tc, imp in (("default", None, None), ("solref 0.01 s", 0.01, None), ("solref 0.005 s", 0.005, None),
                          ("solimp 0.99", None, 0.99)):
        m.geom_solref[:] = sr0
        m.geom_solimp[:] = si0
        if tc:
            m.geom_solref[:, 0] = tc
        if imp:
            m.geom_solimp[:, :2] = imp
        row = "  ".join(f"{cn} {np.mean([track(setup.env, c, r) for r in refs]):.3f} s" for cn, c in ctrls.items())
        print(f"{name:15s} mean time to fall: {row}", flush=True)
    m.geom_solref[:] = sr0
    m.geom_solimp[:] = si0


def pin(src, setup, walks, ctrls) -> None:
    res = {f"{cn} {k}": [] for cn in ctrls for k in ("as built", "stance foot pinned")}
    speeds = []
    for w in walks:
        ref = walk_reference(setup, w)[1]
        pref, sp = pinned(ref, setup.scene)
        speeds.append(sp)
        for cn, c in ctrls.items():
            res[f"{cn} as built"].append(track(setup.env, c, ref))
            res[f"{cn} stance foot pinned"].append(track(setup.env, c, pref))
    print(f"root correction: mean {np.mean(speeds):.2f} m/s")
    for k, v in res.items():
        print(f"{k:28s} mean time to fall {np.mean(v):.3f} s")


def hazard(src, setup, walks, ctrl) -> None:
    lib = src.library
    n = lib.n_actions
    expo, falls = np.zeros(n), np.zeros(n)
    for w in walks:
        r = run_walk(setup, ctrl, w)
        lens = [lib.frames(a).stop - lib.frames(a).start for a in w]
        ends = np.cumsum([lens[0]] + [x - 1 for x in lens[1:]])     # boundary frames are shared
        t_f = r.time_s * 30.0
        s = 0
        for a, e in zip(w, ends):
            if s >= t_f:
                break
            expo[a] += (min(e, t_f) - s) / 30.0
            s = e
        if r.fell:
            i = int(np.searchsorted(ends, max(0.0, t_f - 9.0), side="right"))
            falls[w[min(i, len(w) - 1)]] += 1
    kinds = np.asarray(lib.kinds)
    print(f"{'kind':12s} {'seconds':>8s} {'falls':>6s} {'per s':>6s}")
    rows = [(KINDS[k], expo[kinds == k].sum(), falls[kinds == k].sum()) for k in np.unique(kinds)]
    for name, e, f in sorted(rows, key=lambda r: -r[2] / max(r[1], 1e-9)):
        print(f"{name:12s} {e:8.1f} {f:6.0f} {f / max(e, 1e-9):6.2f}")
    print(f"{'all':12s} {expo.sum():8.1f} {falls.sum():6.0f} {falls.sum() / expo.sum():6.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("contacts", "pin", "hazard"))
    ap.add_argument("--walks", type=int, default=20)
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--ckpt", default=SHIPPED, help="hazard: the controller (a checkpoint, or pd)")
    a = ap.parse_args(argv)
    t0 = time.time()
    src = walk_source(None)
    setup = make_setup(src)
    walks = draw_walks(src, a.walks, 20, a.seed)
    ctrls = {"PD": PDController(), "policy": load_policy(SHIPPED)}
    if a.what == "contacts":
        contacts(src, setup, walks, ctrls)
    elif a.what == "pin":
        pin(src, setup, walks, ctrls)
    else:
        hazard(src, setup, walks, PDController() if a.ckpt == "pd" else load_policy(a.ckpt))
    print(f"{a.walks} walks of seed {a.seed}, {time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
