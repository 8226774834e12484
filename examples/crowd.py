"""Crowd demo: N Interaction Graph fighters in two teams, each fighting the nearest fighter of the
other team and switching when another comes closer (paper section 7.1; igraph_fight.crowd).

    python examples/crowd.py --graph G.igz --n 10 100 1000 --seconds 10 [--out DIR]

Team 0 plays ``--styles``'s first style, team 1 its second (one NPCController per team; all
decisions of a frame in one act_batch call per team). Prints the real-time factor (simulated
seconds / wall seconds, after a warm-up that compiles the kernels) for each N, with the
off-graph lookahead (the controller's default for act()) and with table answers only, and writes
a top-down PNG per N (tracks and final positions) and a GIF for the runs with N <= --gif-max.
The approximations of a crowd on a two-fighter simulator are listed in igraph_fight/crowd.py.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", required=True, help="Interaction Graph file (.igz, library embedded)")
    ap.add_argument("--n", type=int, nargs="+", default=[10, 100, 1000], help="crowd sizes (default 10 100 1000)")
    ap.add_argument("--seconds", type=float, default=10.0, help="simulated seconds per run (default 10)")
    ap.add_argument("--styles", default="infighter,outboxer", help="team styles, comma separated")
    ap.add_argument("--depth", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--mode", choices=("both", "lookahead", "table"), default="both",
                    help="off-graph deciders: simulated lookahead, nearest state's table entry, or both runs")
    ap.add_argument("--gif-max", type=int, default=100, help="write a GIF for N up to this (default 100)")
    ap.add_argument("--out", default="out/crowd")
    args = ap.parse_args(argv)

    from igraph_fight.controller import NPCController
    from igraph_fight.crowd import Crowd, animate_crowd, plot_crowd
    from igraph_fight.graph import load_graph

    graph = load_graph(args.graph)
    lib = graph.load_library()
    styles = [s.strip() for s in args.styles.split(",")]
    if len(styles) == 1:
        styles *= 2
    ctrl = [NPCController(graph, lib, style=s, depth=args.depth) for s in styles[:2]]
    modes = {"both": [True, False], "lookahead": [True], "table": [False]}[args.mode]
    for la in modes:  # warm-up: compile (or load) every kernel outside the timed runs
        Crowd(ctrl, 4, seed=args.seed, lookahead=la).run(0.5)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    print(f"graph {args.graph}: {graph.n_states} states; teams {styles[0]} (red) vs {styles[1]} (blue); "
          f"{args.seconds:.0f} s simulated per run")
    print(f"{'N':>6} {'off-graph':>10} {'RTF':>8} {'CPU RTF':>8} {'decisions/s':>12} {'off-graph %':>11} "
          f"{'hits 0:1':>10} {'switches':>9} {'max att.':>8}  time: decisions / frames / opponents (s)")
    for n in args.n:
        for la in modes:
            record = 3 if la == modes[0] else 0
            crowd = Crowd(ctrl, n, seed=args.seed, lookahead=la, record_every=record)
            c0 = time.process_time()
            rep = crowd.run(args.seconds)
            cpu = time.process_time() - c0
            s = rep.summary()
            s.update(mode="lookahead" if la else "table", cpu_s=round(cpu, 3), cpu_rtf=round(rep.seconds / cpu, 2))
            rows.append(s)
            t = s["timings_s"]
            print(f"{n:>6} {s['mode']:>10} {s['rtf']:>8.1f} {s['cpu_rtf']:>8.1f} {s['decisions_per_s']:>12.0f} "
                  f"{100 * s['off_graph_fraction']:>10.0f}% {s['hits_team0']:>4.0f}:{s['hits_team1']:<5.0f} "
                  f"{s['switches']:>9} {s['max_attackers']:>8}  {t['decisions']:.2f} / {t['frames']:.2f} / "
                  f"{t['opponents']:.2f}")
            if record:
                plot_crowd(rep, crowd.team, out / f"crowd_{n}.png",
                           f"{n} fighters, {rep.seconds:.0f} s ({styles[0]} red vs {styles[1]} blue)")
                if n <= args.gif_max:
                    animate_crowd(rep, crowd.team, out / f"crowd_{n}.gif")
    (out / "summary.json").write_text(json.dumps({"graph": str(args.graph), "styles": styles, "runs": rows}, indent=1))
    print("RTF = simulated seconds / wall seconds (this machine is shared: the CPU RTF divides by the process's "
          "CPU time instead)")
    print(f"wrote {out}/crowd_N.png" + (f", crowd_N.gif (N <= {args.gif_max})" if args.gif_max else "")
          + f" and {out}/summary.json")
    for c in ctrl:
        c.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
