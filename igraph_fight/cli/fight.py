"""`igraph-fight fight` and `igraph-fight policy` (thin: parse, call, print)."""
from __future__ import annotations

import argparse
import json
import statistics
import sys

from igraph_fight.cli import check_swap, depth, gamma, non_negative_int, positive_float, positive_int, swap


def register(sub) -> None:
    p = sub.add_parser("fight", help="a bout between two Interaction Graph fighters, with artifacts to watch")
    p.add_argument("--graph", required=True, help="Interaction Graph file (.igz)")
    p.add_argument("--library", default=None, help="action library (default: the one embedded in the graph)")
    p.add_argument("--a", default="infighter", help="style of fighter A: preset name or style file (default infighter); "
                   "physics bouts also take STYLE+phys[:MODEL], STYLE+close[=R,THETA][:avoid=A,B,...] (turn and close in "
                   "by a geometric rule until engaged: igraph_fight.closing), both, and rl[:CKPT]")
    p.add_argument("--b", default="outboxer", help="style of fighter B (default outboxer)")
    p.add_argument("--depth-a", type=depth, default=5, help="min-max depth of A (default 5; 1..12)")
    p.add_argument("--depth-b", type=depth, default=5, help="min-max depth of B (default 5; 1..12)")
    p.add_argument("--swap-a", type=swap, default=None, metavar="T:STYLE",
                   help="switch A's style at T seconds (e.g. 30:outboxer), within the bout")
    p.add_argument("--first-ply-a", choices=("table", "exact", "exact2"), default="table",
                   help="A's decision rule: the policy table (default), one exact ply, or two exact plies over "
                        "the graph's values (stronger, about 1 ms a decision)")
    p.add_argument("--first-ply-b", choices=("table", "exact", "exact2"), default="table", help="B's decision rule")
    p.add_argument("--seconds", type=positive_float, default=60.0, help="bout length (default 60 s)")
    p.add_argument("--seed", type=non_negative_int, default=1)
    p.add_argument("--out", default="out/fight", help="output folder (default out/fight)")
    p.add_argument("--physics", action="store_true", help="run the bout in MuJoCo physics (tracker)")
    p.add_argument("--no-video", dest="video", action="store_false", default=None,
                   help="physics: no bout.mp4 (default: written unless $IGRAPH_FIGHT_VIDEO is 0)")
    p.add_argument("--reset-place", choices=("reference", "fall"), default="reference",
                   help="physics: where a fallen fighter gets up: on its reference pelvis (default; the topple "
                        "undone) or where its pelvis was when the fall was detected")
    p.add_argument("--reset-facing", choices=("fall", "opponent"), default="opponent",
                   help="physics: which way a fallen fighter faces when it gets up: towards the opponent "
                        "(default) or its fighting direction at the fall")
    p.add_argument("--tracker", default=None,
                   help="physics: tracking controller: assisted[:CKPT] (default, or $IGRAPH_FIGHT_TRACKER: the "
                        "shipped learned tracker, assisted physics with a bounded, reported balance wrench), "
                        "assisted-off[:CKPT] (plain physics), assisted+hold=H[:CKPT] (plus H times the fixed "
                        "pull to the reference root), pd-fixed[=CAP], pd-batch, legacy[:CKPT] or pd")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object")
    p.set_defaults(func=cmd_fight)

    p = sub.add_parser("policy", help="compute a policy table for a style and report its cost")
    p.add_argument("--graph", required=True)
    p.add_argument("--style", default="balanced", help="preset name or style file")
    p.add_argument("--depth", type=depth, default=5, help="min-max depth (default 5; 1..12)")
    p.add_argument("--gamma", type=gamma, default=None,
                   help="discount per decision, in (0, 1] (default planner.DEFAULT_GAMMA, 0.5)")
    p.add_argument("--repeat", type=positive_int, default=5, help="runs to take the median over (default 5)")
    p.add_argument("--out", default=None, help="save the policy table (.npz)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_policy)


def cmd_fight(args: argparse.Namespace) -> int:
    fp_a, fp_b = getattr(args, "first_ply_a", "table"), getattr(args, "first_ply_b", "table")
    if args.physics:
        if fp_a != "table" or fp_b != "table":
            print("igraph-fight: error: --first-ply-a/-b apply to kinematic bouts only (physics bouts decide from "
                  "the policy table)", file=sys.stderr)
            return 2
        from igraph_fight.cli import PHYSICS_GROUP, plugin
        physics_fight = plugin(PHYSICS_GROUP, "fight")
        if physics_fight is None:
            print("igraph-fight: error: physics bouts need the tracker package (not installed)", file=sys.stderr)
            return 2
        return physics_fight(args)
    if (getattr(args, "reset_place", "reference") != "reference" or getattr(args, "reset_facing", "opponent") != "opponent"
            or getattr(args, "tracker", None) or getattr(args, "video", None) is not None):
        print("igraph-fight: error: --reset-place / --reset-facing / --tracker / --no-video apply to physics bouts only "
              "(add --physics)", file=sys.stderr)
        return 2
    from igraph_fight.style_bout import run_style_bout

    swap_a = check_swap(args.swap_a, args.seconds)
    summary = run_style_bout(args.graph, args.a, args.b, args.depth_a, args.depth_b, args.seconds, args.seed,
                             args.out, library=args.library, swap_a=swap_a, progress=not args.json,
                             first_ply_a=fp_a, first_ply_b=fp_b)
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"{summary['a']} (A) vs {summary['b']} (B), {summary['seconds']:.1f} s: hits A {summary['hits_a']:.0f}, "
          f"hits B {summary['hits_b']:.0f}, score {summary['score']:+.0f}, mean distance "
          f"{summary['mean_distance_m']:.2f} m")
    for k, v in summary["artifacts"].items():
        print(f"  {k}: {v}")
    return 0


def cmd_policy(args: argparse.Namespace) -> int:
    import numpy as np

    from planner import compute_policy, load_style

    from igraph_fight.graph import load_graph

    g = load_graph(args.graph)
    from collections import ChainMap
    arrays = ChainMap({}, g.arrays)  # a compact file's arrays decode on first use: only those the policy reads
    from motion_graph.classify import KINDS
    arrays.setdefault("kinds_table", np.array(KINDS))
    style = load_style(args.style)
    from planner import DEFAULT_GAMMA
    gamma = args.gamma if args.gamma is not None else DEFAULT_GAMMA
    from planner import SearchGraph
    sg = SearchGraph.from_arrays(arrays["state_offsets"], arrays["edge_target"], arrays["edge_swap"])
    times, pol = [], None
    for _ in range(max(1, args.repeat)):
        pol = compute_policy(arrays, style, args.depth, gamma, search_graph=sg)
        times.append(pol.compute_ms)
    assert pol is not None
    if args.out:
        from motion_graph.atomic import atomic_write
        atomic_write(args.out, lambda fh: np.savez(fh, best_me=pol.best_me, best_opp=pol.best_opp, V_me=pol.V_me,
                                                  V_opp=pol.V_opp, depth=pol.depth, gamma=pol.gamma,
                                                  style=np.array(style.name)))
    out = {"n_states": g.n_states, "n_edges": g.n_edges, "style": style.name, "depth": args.depth, "gamma": gamma,
           "compute_ms": statistics.median(times), "compute_ms_runs": [round(t, 2) for t in times],
           "search_ms": pol.timings_ms.get("search"), "out": args.out}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"policy for {style.name} at depth {args.depth} on {g.n_states} states / {g.n_edges} edges: "
              f"{out['compute_ms']:.1f} ms (median of {len(times)}; search {out['search_ms']:.1f} ms)")
    return 0
