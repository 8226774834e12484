"""Decision cost of the physically calibrated IG fighter (tracker.bouts.hit_model) inside a physics bout.

    python benchmarks/bench_hit_model.py --graph G.igz [--seconds 60 --seed 1 --core 0]

Plays the same bout (A against the physics RL baseline) with A = the plain IG fighter
(`infighter`, the policy table) and A = `infighter+phys` (exact one-step terms of every legal
action, the hit model's odds, the calibrated table's values), timing every decide() call of A;
prints p50 / p99 / mean milliseconds per decision and each bout's real-time factor.

    python benchmarks/bench_hit_model.py --graph G.igz --spread [--seconds 30 --seed 3]

instead plays A = the hit-odds fighter with kinematic, then calibrated, later plies and prints how
much each term of its score varies across a decision's menu (max - min; median and 90th
percentile over the bout's decisions): the later plies' values against the measured hit terms.
"""
from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--graph", required=True)
    p.add_argument("--style", default="infighter")
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--core", type=int, default=None, help="pin to this CPU core")
    p.add_argument("--spread", action="store_true", help="term spreads instead of timings (see above)")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    if a.core is not None and hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {a.core})
    import torch
    torch.set_num_threads(1)
    from igraph_fight.graph import load_graph
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.loaders import load_tracker, make_agent
    from tracker.bouts.setup import BoutConfig, BoutSetup
    g = load_graph(a.graph)
    lib = g.load_library()
    setup = BoutSetup.create(lib)
    trk = load_tracker(None)
    if a.spread:
        return _spread(a, g, lib, setup, trk)
    out = {}
    for spec in (a.style, f"{a.style}+phys"):
        agent = make_agent(spec, g, lib, 5)
        times: list[float] = []
        inner = agent.decide

        def timed(ctx, inner=inner, times=times):
            t0 = time.perf_counter()
            r = inner(ctx)
            times.append(time.perf_counter() - t0)
            return r

        agent.decide = timed
        bout = PhysicsBout(setup, [agent, make_agent("rl", g, lib, 5)], trk,
                           BoutConfig(seconds=a.seconds, record_qpos=False))
        s = bout.run(seed=a.seed).summary()
        ms = np.array(times) * 1e3
        out[spec] = {"decisions": len(ms), "p50_ms": float(np.median(ms)), "p99_ms": float(np.percentile(ms, 99)),
                     "mean_ms": float(ms.mean()), "realtime_factor": float(s["realtime_factor"])}
        print(f"{spec:>18}: {len(ms)} decisions, p50 {out[spec]['p50_ms']:.2f} ms, p99 {out[spec]['p99_ms']:.2f} ms, "
              f"mean {out[spec]['mean_ms']:.2f} ms; bout {s['realtime_factor']:.1f}x real time", flush=True)
        agent.controller.close()
    base, phys = out[a.style], out[f"{a.style}+phys"]
    print(f"ratio phys / table: {phys['mean_ms'] / base['mean_ms']:.1f}x per decision (mean); "
          f"decision time per simulated second {phys['mean_ms'] * phys['decisions'] / a.seconds:.2f} ms")
    if a.json:
        print(json.dumps(out))
    return 0


def _spread(a, g, lib, setup, trk) -> int:
    from igraph_fight.controller import MT_POS, MT_VALUE
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.loaders import make_agent
    from tracker.bouts.setup import BoutConfig
    from tracker.bouts.hit_model import phys_fighter
    out = {}
    for future in ("kinematic", "calibrated"):
        agent = phys_fighter(g, lib, a.style, 5, None, future)
        rows: list[tuple] = []
        inner = agent.scores

        def rec(ctx, inner=inner, rows=rows):
            mt, pr, q = inner(ctx)
            rows.append((mt, pr))
            return mt, pr, q

        agent.scores = rec
        PhysicsBout(setup, [agent, make_agent("rl", g, lib, 5)], trk,
                    BoutConfig(seconds=a.seconds, record_qpos=False)).run(seed=a.seed)
        st = agent.style
        spreads = {"positional": [np.ptp(mt[:, MT_POS]) for mt, _ in rows],
                   "later plies (gamma V)": [np.ptp(mt[:, MT_VALUE]) for mt, _ in rows],
                   "hit odds given (w P)": [np.ptp(st.w_dmg_given * pr[:, 0]) for _, pr in rows],
                   "hit odds received (w P)": [np.ptp(st.w_dmg_received * pr[:, 1]) for _, pr in rows]}
        out[future] = {k: {"median": float(np.median(v)), "p90": float(np.percentile(v, 90))} for k, v in spreads.items()}
        print(f"{a.style}+phys, {future} later plies, {len(rows)} decisions (seed {a.seed}, {a.seconds:.0f} s):")
        for k, v in out[future].items():
            print(f"  {k:>24}: median {v['median']:.3f}, p90 {v['p90']:.3f}")
        agent.controller.close()
    if a.json:
        print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
