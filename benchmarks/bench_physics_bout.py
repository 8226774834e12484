"""Real-time factor of a full physics bout on one core (tracker.bouts.physics_bout), rendering excluded.

    python benchmarks/bench_physics_bout.py --graph G.igz [--tracker CKPT|pd] [--seconds 60] [--seed 1]
        [--a infighter --b outboxer] [--core 0] [--repeat 1] [--json]

Pins itself to one core (os.sched_setaffinity, ``--core``; -1 leaves the affinity alone) and limits
BLAS/OpenMP to one thread, builds the setup and the controllers (not timed), then times
PhysicsBout.run: decisions, reference building, the tracking policy, physics (240 Hz, 8 substeps per
30 Hz control step), contact judging and the planned-hit simulation. Reports the real-time factor
(simulated / wall seconds), the share of the loop spent in mj_step alone, and the machine's load
average (the machine is shared: the figure is only comparable at similar load).
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")



def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--graph", required=True)
    p.add_argument("--tracker", default=None, help="checkpoint or 'pd' (default: the shipped learned policy)")
    p.add_argument("--a", default="infighter")
    p.add_argument("--b", default="outboxer")
    p.add_argument("--depth", type=int, default=5)
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--core", type=int, default=0)
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    if a.core >= 0 and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {a.core})
    import mujoco
    import torch
    torch.set_num_threads(1)
    from igraph_fight.graph import load_graph
    from tracker.bouts.setup import BoutConfig, BoutSetup
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.loaders import load_tracker, make_agent

    g = load_graph(a.graph)
    lib = g.load_library()
    setup = BoutSetup.create(lib)
    agents = [make_agent(a.a, g, lib, a.depth), make_agent(a.b, g, lib, a.depth)]
    trk = load_tracker(a.tracker)
    for act in range(lib.n_actions):   # warm the per-action reference cache (a one-off per process)
        setup.action_reference(act)
    runs = []
    for r in range(a.repeat):
        bout = PhysicsBout(setup, agents, trk, BoutConfig(seconds=a.seconds, record_qpos=False))
        step_s = [0.0]
        orig = mujoco.mj_step

        def timed(*args, **kw):   # time spent in MuJoCo's integrator alone
            t0 = time.perf_counter()
            orig(*args, **kw)
            step_s[0] += time.perf_counter() - t0

        import tracker.track.env as tenv
        tenv.mujoco.mj_step = timed
        try:
            load0 = os.getloadavg()
            res = bout.run(seed=a.seed + r)
        finally:
            tenv.mujoco.mj_step = orig
        runs.append({"seed": a.seed + r, "realtime_factor": res.realtime_factor, "wall_s": res.wall_s,
                     "sim_s": res.sim_s, "mj_step_share": step_s[0] / res.wall_s,
                     "physics_only_rtf": res.sim_s / step_s[0] if step_s[0] else None,
                     "falls": res.falls.tolist(), "load_before": [round(x, 2) for x in load0],
                     "load_after": [round(x, 2) for x in os.getloadavg()]})
    out = {"graph": a.graph, "tracker": getattr(trk, "describe", lambda: trk.name)(), "seconds": a.seconds,
           "core": a.core, "runs": runs,
           "realtime_factor_median": sorted(x["realtime_factor"] for x in runs)[len(runs) // 2]}
    if a.json:
        print(json.dumps(out))
    else:
        for x in runs:
            print(f"seed {x['seed']}: {x['sim_s']:.0f} s simulated in {x['wall_s']:.1f} s -> {x['realtime_factor']:.2f}x "
                  f"real time (mj_step {100 * x['mj_step_share']:.0f}% of the loop; physics alone "
                  f"{x['physics_only_rtf']:.1f}x); load {x['load_before']} -> {x['load_after']}")
        print(f"tracker: {out['tracker']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
