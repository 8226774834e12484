"""`igraph-fight play`: the browser game against the NPC and the network NPC service (thin)."""
from __future__ import annotations

import argparse
import sys


def register(sub) -> None:
    p = sub.add_parser("play", help="play against the NPC in the browser; the NPC service for game engines")
    p.add_argument("--graph", default=None,
                   help="Interaction Graph file (.igz); default: a demo graph of the default mocap, built on the first "
                        "start (30-70 s on 2 cores) and cached under ~/.cache/igraph-fight/play/")
    p.add_argument("--mocap", default=None, help="mocap folder for the demo graph (default: see README, Mocap)")
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)")
    p.add_argument("--port", type=int, default=8765, help="port (default 8765; 0: any free port)")
    p.add_argument("--style", default="balanced", help="the NPC's initial style: preset name or style file (default balanced)")
    p.add_argument("--depth", type=int, default=3, help="the NPC's initial min-max depth, its strength (1-5 in the page; default 3)")
    p.add_argument("--seconds", type=float, default=60.0, help="bout length (default 60 s, the Table 1 protocol)")
    p.add_argument("--player-style", default="balanced",
                   help="style by which the graph rates your fighter's menu when it turns a command into an action")
    p.add_argument("--idle", choices=("guard", "best"), default="guard",
                   help="what your fighter does without a command: guard (default) or the graph's best action")
    p.add_argument("--save-dir", default="out/play", help="where bouts are saved (default out/play; the human logs "
                   "of `igraph-fight evaluate --human-logs`)")
    p.add_argument("--physics", action="store_true",
                   help="both fighters simulated in MuJoCo on the server, tracked by the default physics tracker "
                        "(the learned assisted tracker: assisted physics, its cap and measured assist in the HUD); "
                        "physics bouts are not saved")
    p.add_argument("--tracker", default=None, help="with --physics: the tracking controller (as `fight --physics`)")
    p.set_defaults(func=cmd_play)


def cmd_play(args: argparse.Namespace) -> int:
    physics = None
    if args.physics:
        from igraph_fight.cli import PHYSICS_GROUP, plugin
        factory = plugin(PHYSICS_GROUP, "play")
        if factory is None:
            print("igraph-fight: error: play --physics needs the tracker package (not installed)", file=sys.stderr)
            return 2
        physics = (lambda lib, sp: factory(lib, sp, args.tracker))  # noqa: E731
    elif args.tracker is not None:
        print("igraph-fight: error: --tracker applies to --physics only", file=sys.stderr)
        return 2
    from igraph_fight.play.server import web_assets_missing
    missing = web_assets_missing()
    if missing:
        print(f"igraph-fight: error: {missing}", file=sys.stderr)
        return 2
    if not 1 <= args.depth <= 5:
        print("igraph-fight: error: --depth must lie in 1..5", file=sys.stderr)
        return 2
    if not 1.0 <= args.seconds <= 600.0:
        print("igraph-fight: error: --seconds must lie in 1..600", file=sys.stderr)
        return 2
    import asyncio

    from igraph_fight.play.server import PlayServer, serve
    graph = args.graph
    if graph is None:
        from igraph_fight.play.demo_graph import ensure_demo_graph
        graph = str(ensure_demo_graph(args.mocap))
    print(f"igraph-fight play: loading {graph}", file=sys.stderr, flush=True)
    try:
        server = PlayServer(graph, style=args.style, depth=args.depth, seconds=args.seconds,
                            player_style=args.player_style, idle=args.idle, save_dir=args.save_dir, physics=physics)
    except ValueError as e:  # a style that does not load, a graph file refused
        print(f"igraph-fight: error: {e}", file=sys.stderr)
        return 2

    import gc
    gc.collect()
    gc.freeze()  # what loading made (graph, library, tables) stays out of the collector's passes while serving

    def ready(url: str) -> None:
        print(f"igraph-fight play: open {url} in a browser (NPC service: {url.replace('http', 'ws')}ws, "
              f"POST {url}decide; Ctrl-C stops)", flush=True)
    try:
        asyncio.run(serve(server, args.host, args.port, ready))
    except OSError as e:
        print(f"igraph-fight: error: cannot listen on {args.host}:{args.port}: {e.strerror or e}", file=sys.stderr)
        return 2
    return 0
