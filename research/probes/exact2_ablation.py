"""Where the strength of NPCController(first_ply="exact2") comes from: an ablation in bouts.

    python -m research.probes.exact2_ablation --graph G.igz [--bouts 10] [--seed 0] [--depth 5]
        [--opponents gametree2,gametree3]

IG fighters of one depth and style (infighter, the evaluation's) deciding four ways, against the
exact game-tree fighters, with the evaluation's protocol (igraph_fight.evaluate: bout i starts
from the same random state for every row, slots alternate, score = own hits - opponent's):

  table          the policy table (the paper's runtime, the default)
  exact          one exact ply over the graph's values (first_ply="exact")
  exact2         two exact plies over the graph's values (first_ply="exact2")
  exact2-zero    two exact plies with zero leaf values: a depth-2 game tree with the planner's
                 discount, i.e. exact2 without the Interaction Graph

Prints the mean score per bout with its 95% interval. Bouts run in this process, one after
another (about 1 minute for 10 bouts per cell on the CMU graph). Measured 2026-11-26 on the
development VM, default CMU graph, 10 bouts, seed 0 (gametree2 / gametree3): table -4.7 / -8.6,
exact +0.3 / -5.6, exact2 +6.0 / -0.1, exact2-zero +1.3 / -6.6.
"""
from __future__ import annotations

import argparse
import copy
import dataclasses
import sys

import numpy as np


VARIANTS = ("table", "exact", "exact2", "exact2-zero")


def variant_controller(base, name: str):
    """A copy of ``base`` (sharing its graph, index and policy) deciding the ``name`` way."""
    c = copy.copy(base)
    c.first_ply = "exact2" if name.startswith("exact2") else name
    if name == "exact2-zero":
        t = c._table
        zero = np.zeros_like(t.la[0])
        c._table = dataclasses.replace(t, la=(zero, zero, *t.la[2:]))
    return c


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", required=True)
    ap.add_argument("--bouts", type=int, default=10)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--depth", type=int, default=5)
    ap.add_argument("--opponents", default="gametree2,gametree3")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    args = ap.parse_args(argv)

    from igraph_fight.agents import IGAgent
    from igraph_fight.evaluate.config import EvalConfig
    from igraph_fight.evaluate.runner import build_context, make_agent
    from igraph_fight.stats import mean_ci
    from igraph_fight.match import run_bout

    cfg = EvalConfig(graph=args.graph, depths=(args.depth,), exact2_depths=(), seed=args.seed, regret_every=0)
    ctx = build_context(cfg)
    base = ctx["controllers"][args.depth]
    game = ctx["game"]
    print(f"graph {args.graph}: {ctx['graph'].n_states} states; IG({args.depth}) {cfg.style}, {args.bouts} bouts of "
          f"{args.seconds:.0f} s per cell, seed {args.seed}")
    for v in args.variants.split(","):
        ctrl = variant_controller(base, v)
        cells = []
        for opp in args.opponents.split(","):
            scores = []
            for i in range(args.bouts):
                ig = IGAgent(ctrl, name=f"IG({args.depth}) {v}")
                agents = [ig, make_agent(ctx, opp)]
                slot = i % 2
                if slot:
                    agents.reverse()
                res = run_bout(game, agents, args.seconds, np.random.default_rng([args.seed, i, 1]),
                               initial=game.new_initial_state(np.random.default_rng([args.seed, i])))
                scores.append(float(res.hits[slot] - res.hits[1 - slot]))
            c = mean_ci(scores)
            cells.append(f"{opp} {c['mean']:+.1f} ({c['ci_low']:+.1f}, {c['ci_high']:+.1f})")
        print(f"  {v:<12} " + "   ".join(cells))
    return 0


if __name__ == "__main__":
    sys.exit(main())
