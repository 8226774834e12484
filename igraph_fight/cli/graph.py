"""`igraph-fight build` and `igraph-fight graph info|convert|export` commands (thin: parse, call, print)."""
from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from pathlib import Path


def _pair(text: str) -> tuple[float, float]:
    """'R,DEG' -> (metres, radians)."""
    try:
        r, d = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected R_M,DEGREES (e.g. 0.05,10), got {text!r}") from None
    if r <= 0 or d <= 0:
        raise argparse.ArgumentTypeError("tolerances must be positive")
    return r, math.radians(d)


def _share_deg(text: str) -> tuple[float, float]:
    """'SHARE,DEG' -> (share in [0, 1], degrees in (0, 180])."""
    try:
        share, deg = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected SHARE,DEGREES (e.g. 0.75,30), got {text!r}") from None
    if not 0 <= share <= 1 or not 0 < deg <= 180:
        raise argparse.ArgumentTypeError("the share must be in [0, 1] and the angle in (0, 180] degrees")
    return share, deg


def _target_radii(text: str) -> dict:
    """'HEAD,CHEST,BELLY' -> the kinematic simulator's target radii (metres)."""
    try:
        vals = [float(x) for x in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != 3 or not all(0 < v <= 1 for v in vals):
        raise argparse.ArgumentTypeError(f"expected three radii in metres, HEAD,CHEST,BELLY in (0, 1] "
                                         f"(e.g. 0.10,0.15,0.15), got {text!r}")
    return dict(zip(("head", "chest", "belly"), vals))


def register(sub) -> None:
    p = sub.add_parser("build", help="explore, cluster and link an Interaction Graph from mocap or a library",
                       description="Build an Interaction Graph. The sampler's archive is checkpointed to "
                                   "OUT.ckpt/ after every chunk, and removed only once OUT is written: rerunning "
                                   "an interrupted command (killed at any point) resumes it and gives the same graph.")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--mocap", nargs="+", metavar="DIR_OR_FILE", help="mocap folder(s) or .bvh/.amc files, of one or several skeletons (retargeted onto the first take's body; default: the shared boxing takes 13_17, 13_18 and 14_02)")
    src.add_argument("--library", metavar="LIB", help="a saved action library (.npz) instead of --mocap")
    p.add_argument("--target-skeleton", default=None, metavar="FILE",
                   help="with --mocap: the mocap file whose skeleton is the library's body (default: the first take's)")
    p.add_argument("--out", required=True, help="graph file to write (.igz)")
    p.add_argument("--max-samples", type=int, default=None, help="sampler archive size (default 600000)")
    p.add_argument("--min-new", type=int, default=None,
                   help="stop when a sampler round adds fewer new samples than this (default 0: off)")
    p.add_argument("--tolerance", type=_pair, default=None, metavar="R_M,DEG",
                   help="snapping tolerance of the clustering (default 0.05,10)")
    p.add_argument("--link-tolerance", type=_pair, default=None, metavar="R_M,DEG",
                   help="landing tolerance of an edge around its target state (default 0.15,30)")
    p.add_argument("--f0", type=int, default=None, help="frame window F0 of the other's clip (default 10)")
    p.add_argument("--n-initial", type=int, default=None, help="initial states of the sampler (default 64)")
    p.add_argument("--initial-facing", type=_share_deg, default=None, metavar="SHARE,DEG",
                   help="share of the sampler's initial states with both fighters within +-DEG of facing "
                        "each other (default 0.75,30; the rest take any angle)")
    p.add_argument("--seed-bouts", type=int, default=None, metavar="N",
                   help="also start the sampler from the decision states of N reward-free bouts "
                        "(30 s each; igraph_fight.seeding; default 1024)")
    p.add_argument("--seed-pairing", choices=("human", "random"), default=None,
                   help="seed bouts between two human proxies (default) or a human proxy and a random fighter")
    p.add_argument("--next-threshold", type=float, default=None,
                   help="with --mocap: Next(a) pose threshold of the library (m, default 0.20)")
    p.add_argument("--no-prune", action="store_true", help="keep dead-end states")
    p.add_argument("--guard", type=float, default=None, metavar="RADIUS_M",
                   help="block strikes at the other's forearms (capsules of this radius, e.g. 0.05; default: no guard)")
    p.add_argument("--target-radius", type=_target_radii, default=None, metavar="HEAD,CHEST,BELLY",
                   help="radii of the target spheres a fist must touch for a predicted hit (m; default "
                        "0.10,0.15,0.15); smaller radii plan only deeper hits")
    p.add_argument("--seed", type=int, default=0, help="seed of the sampler's initial states (default 0)")
    p.add_argument("--workers", type=int, default=1,
                   help="threads of the local backend, Ray actors of the ray backend (0: all cores); "
                        "the result does not depend on it")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="where the sampler, clustering and linking run: this process (default) or Ray actors "
                        "(needs: pip install 'igraph-fight[ray]'); the same graph and content hash")
    p.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="with --backend ray: join this running Ray cluster (default: start Ray on this machine)")
    p.add_argument("--checkpoint", default=None, help="checkpoint folder (default OUT.ckpt)")
    p.add_argument("--restart", action="store_true", help="discard an existing checkpoint and start over")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_build)

    g = sub.add_parser("graph", help="inspect or export an Interaction Graph file")
    gsub = g.add_subparsers(dest="graph_command", metavar="SUBCOMMAND")
    gsub.required = True
    q = gsub.add_parser("info", help="states, edges, groups, degrees, snapping, dead ends, content hash")
    q.add_argument("file")
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q.set_defaults(func=cmd_info)
    q = gsub.add_parser("convert", help="rewrite a graph file in the compact format (version 4), or as 3 or 2",
                        description="Load a graph file of any version (validated) and write it as version 4 (the "
                                    "compact format `igraph-fight build` writes: edge features replayed from the "
                                    "states), with --version 3 as the compact format that stores every array, or "
                                    "with --version 2 as the old .npz format. The content hash stays.")
    q.add_argument("src", help="graph file to read")
    q.add_argument("dst", help="graph file to write (may be SRC: replaced atomically)")
    q.add_argument("--version", type=int, choices=(2, 3, 4), default=4, help="version to write (default 4)")
    q.add_argument("--json", action="store_true", help="print one JSON object")
    q.set_defaults(func=cmd_convert)
    q = gsub.add_parser("export", help="export to GraphML (networkx) for analysis")
    q.add_argument("file")
    q.add_argument("--out", required=True, help="output file (.graphml)")
    q.set_defaults(func=cmd_export)


def _options(args: argparse.Namespace):
    import dataclasses

    from igraph_fight.build.pipeline import BuildOptions
    from igraph_fight.sim import SimParams

    kw = {}
    if args.max_samples is not None:
        kw["max_samples"] = args.max_samples
    if args.min_new is not None:
        kw["min_new_per_round"] = args.min_new
    if args.tolerance is not None:
        kw["tol_r_m"], kw["tol_theta_rad"] = args.tolerance
    if args.link_tolerance is not None:
        kw["link_tol_r_m"], kw["link_tol_theta_rad"] = args.link_tolerance
        d = BuildOptions()
        kw["dedup_r_m"] = min(d.dedup_r_m, kw["link_tol_r_m"])
        kw["dedup_theta_rad"] = min(d.dedup_theta_rad, kw["link_tol_theta_rad"])
    if args.f0 is not None:
        kw["f0"] = args.f0
    if args.n_initial is not None:
        kw["n_initial"] = args.n_initial
    if args.seed_bouts is not None:
        kw["seed_bouts"] = args.seed_bouts
    if args.seed_pairing is not None:
        kw["seed_pairing"] = args.seed_pairing
    if args.initial_facing is not None:
        kw["initial_facing_share"], kw["initial_facing_deg"] = float(args.initial_facing[0]), float(args.initial_facing[1])
    if args.no_prune:
        kw["prune_dead_ends"] = False
    sim = {}
    if getattr(args, "guard", None) is not None:
        sim["guard_radius_m"] = args.guard
    if getattr(args, "target_radius", None) is not None:
        sim["target_radius_m"] = args.target_radius
    if sim:
        kw["sim"] = SimParams(**sim)
    opts = dataclasses.replace(BuildOptions(), **kw)
    opts.validate()
    return opts


def cmd_build(args: argparse.Namespace) -> int:
    from motion_graph.library import LibraryParams, load_library

    from igraph_fight.build.pipeline import build_fingerprint, build_graph
    from igraph_fight.build.explore import read_checkpoint_header
    from igraph_fight.graph import library_fingerprint

    t0 = time.perf_counter()
    try:
        options = _options(args)
    except ValueError as e:
        print(f"igraph-fight: error: {e}", file=sys.stderr)
        return 2
    if args.target_skeleton and args.library:
        print("igraph-fight: error: --target-skeleton applies to mocap takes, not to --library", file=sys.stderr)
        return 2
    if args.address is not None and args.backend != "ray":
        print("igraph-fight: error: --address needs --backend ray", file=sys.stderr)
        return 2
    if args.backend == "ray":
        from igraph_fight.build.backend import BackendUnavailable, require_ray
        try:
            require_ray()
        except BackendUnavailable as e:
            print(f"igraph-fight: error: {e}", file=sys.stderr)
            return 2
    show = not args.quiet and sys.stderr.isatty()
    if args.library:
        lib = load_library(args.library)
    else:
        params = LibraryParams()
        if args.next_threshold is not None:
            params = LibraryParams(next_threshold_m=args.next_threshold)
        from motion_graph.paths import boxing_files
        from motion_graph.retarget import build_retargeted_library
        lib = build_retargeted_library(args.mocap or boxing_files(None), params, args.target_skeleton, progress=show)
    ckpt = Path(args.checkpoint) if args.checkpoint else Path(str(args.out) + ".ckpt")
    if args.restart and ckpt.exists():
        shutil.rmtree(ckpt)
    archive = ckpt / "archive.npz"
    if archive.exists():
        header = read_checkpoint_header(archive)
        if header.get("fingerprint") != build_fingerprint(library_fingerprint(lib), options, args.seed):
            print(f"igraph-fight: error: {ckpt} holds an interrupted build with other inputs or options; "
                  f"rerun the same command to resume it, or add --restart to discard it", file=sys.stderr)
            return 2
        if show and not args.json:
            print(f"resuming from {ckpt} ({header.get('n')} samples)", file=sys.stderr)
    # the graph file is in place before the checkpoint goes: a kill at any point, then the same command, resumes
    _, rep = build_graph(lib, options, seed=args.seed, workers=args.workers, checkpoint_dir=ckpt, progress=show,
                         out=args.out, backend=args.backend, address=args.address)
    rep["graph_seconds"] = rep["build_seconds"]
    rep["build_seconds"] = time.perf_counter() - t0
    rep["out"] = str(args.out)
    if args.json:
        print(json.dumps(rep))
        return 0
    print(f"{rep['n_states']} states, {rep['n_edges']} edges (mean out-degree {rep['mean_out_degree']:.1f}) "
          f"from {rep['n_samples']} samples in {rep['build_seconds']:.1f} s, peak memory {rep['peak_rss_mb']:.0f} MiB")
    print(f"dead ends {100 * rep['dead_end_fraction']:.1f}% (pruned {rep['pruned_states']} of "
          f"{rep['n_states_before_pruning']} states); snapping mean {rep['snap_mean_cm']:.1f} cm / "
          f"{rep['snap_mean_deg']:.1f} deg, max {rep['snap_max_cm']:.1f} cm / {rep['snap_max_deg']:.1f} deg; "
          f"edge landing mean {rep['edge_snap_mean_cm']:.1f} cm / {rep['edge_snap_mean_deg']:.1f} deg")
    b = rep["backend"]
    if b["backend"] == "ray":
        print(f"ray backend: {b['workers']} workers on {b['nodes']} node(s), worker peak memory "
              f"{max(b['worker_peak_rss_mb']):.0f} MiB")
    print(f"content hash {rep['content_hash']}")
    print(f"graph written to {args.out}")
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    from igraph_fight.graph import InteractionGraph

    info = InteractionGraph.load(args.file).info()
    if args.json:
        print(json.dumps(info))
        return 0
    print(f"{info['path']}: {info['format']} v{info['version']} (package {info['package_version']}, "
          f"created {info['created']}, seed {info['seed']})")
    size = f", {info['file_bytes'] / 1e6:.1f} MB" if info.get("file_bytes") is not None else ""
    print(f"  file: {info['storage']}{size}")
    print(f"  {info['n_states']} states in {info['n_groups']} groups, {info['n_edges']} edges "
          f"(mean out-degree {info['mean_out_degree']:.2f}), dead ends {100 * info['dead_end_fraction']:.1f}%")
    hist = info["degree_histogram"]
    print("  out-degree histogram: " + ", ".join(f"{k}:{v}" for k, v in list(hist.items())[:25])
          + (" ..." if len(hist) > 25 else ""))
    if info["snap_mean_cm"] is not None:
        print(f"  snapping sample->state: mean {info['snap_mean_cm']:.2f} cm / {info['snap_mean_deg']:.2f} deg, "
              f"max {info['snap_max_cm']:.2f} cm / {info['snap_max_deg']:.2f} deg")
    print(f"  edge landing -> target: mean {info['edge_snap_mean_cm']:.2f} cm / {info['edge_snap_mean_deg']:.2f} deg, "
          f"max {info['edge_snap_max_cm']:.2f} cm / {info['edge_snap_max_deg']:.2f} deg")
    print(f"  edges by action kind: {info['edges_by_kind']}; with damage given {info['edges_with_damage_given']}, "
          f"received {info['edges_with_damage_received']}")
    print(f"  library {info['library_fingerprint'][:16]}..., content hash {info['content_hash']}")
    return 0


def cmd_convert(args: argparse.Namespace) -> int:
    import os

    from igraph_fight.graph import convert_graph_file, header_summary

    t = time.perf_counter()
    before = os.path.getsize(args.src)
    old = header_summary(args.src).get("version")
    g = convert_graph_file(args.src, args.dst, version=args.version)
    rep = {"src": str(args.src), "dst": str(args.dst), "src_version": old, "dst_version": args.version,
           "src_bytes": before, "dst_bytes": os.path.getsize(args.dst), "content_hash": g.header["content_hash"],
           "seconds": time.perf_counter() - t}
    if args.json:
        print(json.dumps(rep))
        return 0
    print(f"{args.src} (version {old}, {before / 1e6:.1f} MB) -> {args.dst} (version {args.version}, "
          f"{rep['dst_bytes'] / 1e6:.1f} MB) in {rep['seconds']:.1f} s; content hash {rep['content_hash']}")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from igraph_fight.graph import InteractionGraph, export_graphml

    g = InteractionGraph.load(args.file)
    export_graphml(g, args.out)
    print(f"{g.n_states} nodes, {g.n_edges} edges written to {args.out}")
    return 0
