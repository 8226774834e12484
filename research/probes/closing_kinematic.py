"""The closing rule (igraph_fight.closing) in kinematic bouts: score, hits, the share of fighter A's
decisions facing more than 1 rad away from the opponent and the mean distance, for the policy-table
fighters with and without the rule on A (the same seeds, so the difference is paired); and how
long the rule takes to engage a fighter from 3 m facing away, the opponent standing still
(research/notes/BOUTS.md).

    python -m research.probes.closing_kinematic --graph G.igz --a infighter --b outboxer --bouts 40 [--both] [--avoid 7,60]

--both adds a row with the rule on both fighters (as in the physics bouts `--a infighter+close --b
outboxer+close`); --avoid gives the rule's ClosingRule.avoid (library ids it does not launch).
"""
from __future__ import annotations

import argparse
import time

import numpy as np



class _Closing:
    """A game-API agent: the closing rule while disengaged, ``inner`` otherwise."""

    def __init__(self, inner, rule, library) -> None:
        self.inner, self.rule, self.library = inner, rule, library

    def reset(self, game, player, rng) -> None:
        self.inner.reset(game, player, rng)

    def step(self, state, player: int) -> int:
        from igraph_fight.controller import observe
        o = observe(state, player)
        a = self.rule.choose(self.library.next(o.m_self), o.r, o.theta_self, self.library)
        return self.inner.step(state, player) if a is None else a


def _bouts(game, agents, seeds, seconds: float) -> dict:
    scores, away, dist, hits = [], [], [], np.zeros(2)
    for seed in seeds:
        rng = np.random.default_rng(seed)
        s = game.new_initial_state(rng)
        s.game = game
        for p, ag in enumerate(agents):
            ag.reset(game, p, rng)
        th = []
        while s.time_s < seconds:
            p = s.current_player()
            if p < 0:
                break
            if p == 0:
                r, ts, _ = s.relative(0)
                th.append(abs(ts))
                dist.append(r)
            s.apply_action(int(agents[p].step(s, p)))
        scores.append(float(s.returns()[0]))
        away.append(float(np.mean(np.array(th) > 1.0)))
        hits += np.array(s.hits, dtype=float)
    return {"scores": np.array(scores), "away": float(np.mean(away)), "r": float(np.mean(dist)), "hits": hits}


def _ci(x: np.ndarray) -> float:
    """Half-width of the 95% interval (normal approximation)."""
    from igraph_fight.stats import mean_ci
    c = mean_ci(x, normal=True)
    return c["ci_high"] - c["mean"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--graph", required=True)
    ap.add_argument("--a", default="infighter")
    ap.add_argument("--b", default="outboxer")
    ap.add_argument("--bouts", type=int, default=40)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed0", type=int, default=1)
    ap.add_argument("--both", action="store_true", help="also a row with the rule on both fighters")
    ap.add_argument("--avoid", default="", help="comma-separated library ids the rule does not launch")
    args = ap.parse_args(argv)

    from igraph_fight.agents import IGAgent
    from igraph_fight.closing import ClosingRule
    from igraph_fight.controller import NPCController
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.graph import load_graph
    g = load_graph(args.graph)
    lib = g.load_library()
    rule = ClosingRule(avoid=tuple(int(v) for v in args.avoid.split(",") if v))
    ca = NPCController(g, lib, style=args.a, depth=5)
    cb = NPCController(g, lib, style=args.b, depth=5)
    game = FightGame(lib, GameConfig(max_seconds=args.seconds, sim=g.sim_params()), tables=ca.tables)
    seeds = range(args.seed0, args.seed0 + args.bouts)
    rows = {}
    runs = [("policy table", IGAgent(ca, "a"), IGAgent(cb, "b")),
            ("closing rule, then the table", _Closing(IGAgent(ca, "a"), rule, lib), IGAgent(cb, "b"))]
    if args.both:
        runs.append(("the rule on both fighters", _Closing(IGAgent(ca, "a"), rule, lib),
                     _Closing(IGAgent(cb, "b"), rule, lib)))
    for name, a, b in runs:
        t0 = time.perf_counter()
        rows[name] = _bouts(game, [a, b], seeds, args.seconds)
        rows[name]["wall"] = time.perf_counter() - t0
    print(f"{args.a} (A) vs {args.b}, {args.bouts} kinematic bouts of {args.seconds:.0f} s, seeds {seeds.start}-{seeds.stop - 1}")
    print("| A | score per bout (95%) | hits A - B | A's decisions facing > 1 rad away | mean distance |")
    print("|---|---|---|---|---|")
    for name, r in rows.items():
        print(f"| {name} | {r['scores'].mean():+.2f} ({_ci(r['scores']):.2f}) | {r['hits'][0]:.0f} - {r['hits'][1]:.0f} | "
              f"{r['away']:.0%} | {r['r']:.2f} m |")
    d = rows["closing rule, then the table"]["scores"] - rows["policy table"]["scores"]
    print(f"paired difference {d.mean():+.2f} (95% {d.mean() - _ci(d):+.2f} .. {d.mean() + _ci(d):+.2f})")

    # engaging from 3 m facing away, the opponent standing still, from every action
    times = [rule.rollout(lib, m0, 3.0, th0)[0] for m0 in range(lib.n_actions) for th0 in (-2.8, -1.5, 1.5, 2.8)]
    times = np.array(times)
    print(f"seconds to engage from 3 m, |theta| 1.5 or 2.8 rad, {len(times)} starts: mean {times.mean():.1f}, "
          f"95th percentile {np.percentile(times, 95):.1f}, max {times.max():.1f}")
    ca.close()
    cb.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
