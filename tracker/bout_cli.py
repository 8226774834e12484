"""Command line of the physics bouts: `igraph-fight fight --physics ...` (cmd_physics_fight) and
`python -m tracker.bout_cli fight|series ...` (main)."""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from .bout_run import run_physics_fight, run_series
from .bout_setup import BoutConfig


def format_summary(s: dict) -> str:
    def pct(x):
        return "n/a" if x is None else f"{100 * x:.0f}%"
    lines = [
        f"{s['a']} (A) vs {s['b']} (B), {s['seconds']:.1f} s physics bout (seed {s['seed']}): hits A {s['hits_a']:.0f}, "
        f"hits B {s['hits_b']:.0f}, score {s['score']:+.0f}, mean distance {s['mean_distance_m']:.2f} m",
        f"  falls: A {s['falls_a']} ({s['falls_per_min_a']:.1f}/min), B {s['falls_b']} ({s['falls_per_min_b']:.1f}/min)",
        f"  planned hits {s['planned_hits']:.0f} (A {s['planned_hits_a']:.0f}, B {s['planned_hits_b']:.0f}), realised "
        f"{s['planned_realised']:.0f} ({pct(s['planned_realised_ratio'])}; while both stood: "
        f"{pct(s['planned_realised_ratio_standing'])}); unplanned hits {s['unplanned_hits']:.0f}; "
        f"touches A {s['touches_a']} B {s['touches_b']}",
        f"  clipped fist force given: A {s['damage_n_a']:.0f} N, B {s['damage_n_b']:.0f} N (sum over control steps)",
        f"  real-time factor {s['realtime_factor']:.2f}x (rendering excluded; load {s.get('machine_load')}); "
        f"tracker: {s['tracker']}",
    ]
    if s.get("root_assist"):
        lines.append("  ROOT ASSIST ON: pelvises held on the references by welds; not physics, falls impossible")
    for k, v in s["artifacts"].items():
        lines.append(f"  {k}: {v}")
    return "\n".join(lines)


def cmd_physics_fight(args: argparse.Namespace) -> int:
    """`igraph-fight fight --physics`: args of igraph_fight.cli_fight (graph, library, a, b, depth_a,
    depth_b, swap_a, seconds, seed, out, json); optional attributes tracker, video, video_fps,
    root_assist (python -m tracker.bout_cli fight sets them; IGRAPH_FIGHT_TRACKER and
    IGRAPH_FIGHT_VIDEO=0 are the environment defaults)."""
    swap = None
    if getattr(args, "swap_a", None):
        t, _, style = args.swap_a.partition(":")
        swap = (float(t), style)
    video = getattr(args, "video", None)
    if video is None:
        video = os.environ.get("IGRAPH_FIGHT_VIDEO", "1") not in ("0", "false", "no")
    try:
        summary = run_physics_fight(args.graph, args.a, args.b, args.depth_a, args.depth_b, args.seconds, args.seed,
                                    args.out, library=args.library, swap_a=swap,
                                    tracker=getattr(args, "tracker", None), video=video,
                                    video_fps=float(getattr(args, "video_fps", 15.0) or 15.0),
                                    root_assist=bool(getattr(args, "root_assist", False)),
                                    progress=not args.json, max_wall_s=getattr(args, "max_wall_s", None),
                                    config=BoutConfig(seconds=args.seconds,
                                                      reset_place=getattr(args, "reset_place", "reference"),
                                                      reset_facing=getattr(args, "reset_facing", "opponent")))
    except (FileNotFoundError, ValueError) as e:
        print(f"igraph-fight: error: {e}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(summary))
    else:
        print(format_summary(summary))
    return 0


TRACKER_HELP = ("tracking policy checkpoint, 'pd', or 'search[:C,L][:early|full][:heading=W][:aim=W][:touch=W][:lead=W][:spread=F][:duel]"
                "[:foresee][:CKPT]' (the policy steered by a run-time search: far fewer falls, 0.03-0.3x real time; "
                "aim/touch/lead/spread/duel: planned strikes aimed, in rollouts with the opponent; foresee: the agents' next actions "
                "guessed for the look-ahead; tracker/bout_search.py); "
                "default: the shipped policy")
FACING_HELP = ("which way a fallen fighter faces when it gets up: towards the opponent (default) or its "
               "fighting direction at the fall (the rule before)")
RESET_HELP = ("where a fallen fighter gets up: on its reference pelvis (default; the topple undone) or where "
              "its pelvis was when the fall was detected (the rule before)")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m tracker.bout_cli", description="physics bouts (tracker.bout)")
    sub = p.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fight", help="one physics bout with artifacts (igraph-fight fight --physics, more options)")
    f.add_argument("--graph", required=True)
    f.add_argument("--library", default=None)
    f.add_argument("--a", default="infighter", help="style, STYLE+phys[:MODEL] (physically measured hit odds, "
                   "tracker.hit_model), STYLE+close[=R,THETA][:avoid=A,B,...] (closes in by a geometric rule until "
                   "engaged within R m and THETA rad, never launching the avoided library actions: igraph_fight.closing), "
                   "both, or rl[:CKPT] for the physics RL baseline")
    f.add_argument("--b", default="outboxer")
    f.add_argument("--depth-a", type=int, default=5)
    f.add_argument("--depth-b", type=int, default=5)
    f.add_argument("--swap-a", default=None)
    f.add_argument("--seconds", type=float, default=60.0)
    f.add_argument("--seed", type=int, default=1)
    f.add_argument("--out", default="out/fight")
    f.add_argument("--tracker", default=None, help=TRACKER_HELP)
    f.add_argument("--no-video", dest="video", action="store_false", default=True)
    f.add_argument("--video-fps", type=float, default=15.0)
    f.add_argument("--root-assist", action="store_true", help="diagnostic, NOT physics: hold the pelvises on the references")
    f.add_argument("--reset-place", choices=("reference", "fall"), default="reference", help=RESET_HELP)
    f.add_argument("--reset-facing", choices=("fall", "opponent"), default="opponent", help=FACING_HELP)
    f.add_argument("--max-wall-s", type=float, default=None,
                   help="stop after this many wall-clock seconds (slow trackers); the summary covers the seconds "
                   "simulated by then (its 'seconds'), per-minute figures divide by them")
    f.add_argument("--json", action="store_true")
    r = sub.add_parser("series", help="N physics bouts between two agents, aggregated (no artifacts)")
    r.add_argument("--graph", required=True)
    r.add_argument("--a", default="infighter")
    r.add_argument("--b", default="outboxer")
    r.add_argument("--depth-a", type=int, default=5)
    r.add_argument("--depth-b", type=int, default=5)
    r.add_argument("--bouts", type=int, default=10)
    r.add_argument("--seconds", type=float, default=60.0)
    r.add_argument("--seed0", type=int, default=0)
    r.add_argument("--tracker", default=None, help=TRACKER_HELP)
    r.add_argument("--root-assist", action="store_true")
    r.add_argument("--reset-place", choices=("reference", "fall"), default="reference", help=RESET_HELP)
    r.add_argument("--reset-facing", choices=("fall", "opponent"), default="opponent", help=FACING_HELP)
    r.add_argument("--out", default=None, help="write the result (with every bout's summary) as JSON")
    a = p.parse_args(argv)
    if a.cmd == "fight":
        return cmd_physics_fight(a)
    if a.cmd == "series":
        res = run_series(a.graph, a.a, a.b, a.bouts, a.seconds, a.depth_a, a.depth_b, a.seed0, a.tracker,
                         a.root_assist, log=lambda x: print(x, flush=True),
                         config=BoutConfig(reset_place=a.reset_place, reset_facing=a.reset_facing))
        if a.out:
            from motion_graph.atomic import atomic_write_text
            Path(a.out).parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(Path(a.out), json.dumps(res, indent=1))
        print(json.dumps({k: v for k, v in res.items() if k != "bouts"}, indent=1))
        return 0
    return 2


if __name__ == "__main__":
    sys.exit(main())
