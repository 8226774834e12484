"""How many planned hits can land at all with the physical bodies? (issue 8 diagnostic)

Physics bouts in which both bodies are put on their references at every control step (qpos and
qvel written before the physics, like a perfect tracker that never falls; NOT physics, a
diagnostic): planned hits (the kinematic simulator's, judged on mocap joint spheres: fist 5 cm
against head 10 cm, chest and belly 15 cm around joint points) against hits realised by the
physical geoms' contacts (fist spheres on the head sphere and the chest / belly capsules). The
ratio bounds what any tracker can reach with this body model.

    python -m research.probes.hit_geometry --graph G.igz [--bouts 6] [--seconds 60] [--seed0 1]
"""
from __future__ import annotations

import argparse
import json
import sys

import mujoco


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--graph", required=True)
    ap.add_argument("--a", default="infighter")
    ap.add_argument("--b", default="outboxer")
    ap.add_argument("--bouts", type=int, default=6)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed0", type=int, default=1)
    a = ap.parse_args(argv)
    from igraph_fight.graph import load_graph
    from tracker.bouts.setup import BoutConfig, BoutSetup
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.loaders import make_agent
    from tracker.track.pd import PDController
    g = load_graph(a.graph)
    lib = g.load_library()
    setup = BoutSetup.create(lib)
    agents = [make_agent(a.a, g, lib, 5), make_agent(a.b, g, lib, 5)]
    tot = {"planned": 0, "realised": 0, "unplanned": 0}

    def on_reference(bout) -> None:
        d, t = bout.env.data, bout.env.t
        for k, fm in enumerate(bout.fms):
            d.qpos[fm.qpos_slice] = bout.F[k].ref.qpos[t]
            d.qvel[fm.qvel_slice] = bout.F[k].ref.qvel[t]
        mujoco.mj_forward(bout.model, d)

    for i in range(a.bouts):
        bout = PhysicsBout(setup, agents, PDController(), BoutConfig(seconds=a.seconds, record_qpos=False))
        bout.start(seed=a.seed0 + i)
        for _ in range(bout.n_steps):
            bout.step(before_physics=on_reference)
        s = bout.finish().summary()
        tot["planned"] += s["planned_hits"]
        tot["realised"] += s["planned_realised"]
        tot["unplanned"] += s["unplanned_hits"]
        print(f"seed {a.seed0 + i}: planned {s['planned_hits']:.0f}, realised {s['planned_realised']:.0f}, unplanned "
              f"{s['unplanned_hits']:.0f}, falls {s['falls_a']}-{s['falls_b']}, distance {s['mean_distance_m']:.2f} m",
              flush=True)
    tot["ratio"] = tot["realised"] / tot["planned"] if tot["planned"] else None
    print(json.dumps(tot))
    return 0


if __name__ == "__main__":
    sys.exit(main())
