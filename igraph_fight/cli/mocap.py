"""`igraph-fight mocap ...` and `igraph-fight data ...` commands."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from igraph_fight.cli import non_negative_int, positive_float


def register(sub) -> None:
    mocap = sub.add_parser("mocap", help="inspect and segment motion-capture files")
    msub = mocap.add_subparsers(dest="mocap_command", metavar="SUBCOMMAND")
    msub.required = True

    p = msub.add_parser("inspect", help="frames, fps, duration, skeleton, units and foot contacts of mocap files")
    p.add_argument("files", nargs="+", help=".bvh or .amc files (or folders)")
    p.add_argument("--fps", type=positive_float, default=None, help="override the frame rate (frames/s)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_inspect)

    p = msub.add_parser("segment", help="cut mocap into labelled actions and write an action library")
    p.add_argument("files", nargs="*", help=".bvh/.amc files or folders (default: the shared boxing takes 13_17, 13_18 and 14_02, on 13_17's body)")
    p.add_argument("--mocap", default=None, help="mocap folder used when no files are given")
    p.add_argument("--out", default=None, help="action-library file to write (.npz)")
    p.add_argument("--labels", default=None, help="user label file overriding automatic labels")
    p.add_argument("--plot", default=None, help="write a segmentation timeline (PNG)")
    p.add_argument("--fps", type=positive_float, default=None, help="override the source frame rate")
    p.add_argument("--library-fps", type=positive_float, default=30.0, help="frame rate of the library (default 30)")
    p.add_argument("--next-threshold", type=positive_float, default=None,
                   help="pose-hub size (m): boundary poses within this mean joint distance share a hub, and a -> b when b starts in the hub where a ends (default 0.20)")
    p.add_argument("--retarget", action="store_true",
                   help="map takes of different skeletons onto one body (the first take's) before segmenting (always done for the default takes)")
    p.add_argument("--target-skeleton", default=None, metavar="FILE",
                   help="with --retarget (implied): the mocap file whose skeleton and frame rate are the target")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_segment)

    p = sub.add_parser("demo", help="run the whole kinematic chain on the shared boxing takes and write its artifacts")
    p.add_argument("--mocap", default=None, help="mocap folder (default: $IGRAPH_FIGHT_MOCAP or ../shared/mocap)")
    p.add_argument("--out", default="out/demo", help="output folder (default out/demo)")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.set_defaults(func=cmd_demo)

    data = sub.add_parser("data", help="download public mocap")
    dsub = data.add_subparsers(dest="data_command", metavar="SUBCOMMAND")
    dsub.required = True
    p = dsub.add_parser("fetch-cmu", help="download CMU subject 13 boxing takes (ASF/AMC) into the user cache")
    p.add_argument("--dest", default=None, help="target folder (default: ~/.cache/igraph-fight/mocap/cmu/asf_amc)")
    p.add_argument("--url", default=None, help="base URL (default: the CMU mocap site, or $IGRAPH_FIGHT_CMU_URL)")
    p.set_defaults(func=cmd_fetch)


def cmd_inspect(args: argparse.Namespace) -> int:
    from motion_graph.contacts import contact_summary, foot_contacts
    from motion_graph.errors import MocapFormatError
    from motion_graph.features import clip_features
    from motion_graph.io import find_mocap_files, load_motion
    from motion_graph.semantics import resolve_parts

    files = find_mocap_files(args.files)
    if not files:
        raise MocapFormatError(", ".join(args.files), "no .bvh or .amc files found")
    rows = []
    for f in files:
        m = load_motion(f, fps=args.fps)
        parts = resolve_parts(m.skeleton)
        row = {
            "file": str(f), "frames": m.n_frames, "fps": m.fps, "duration_s": round(m.duration, 3),
            "joints": m.skeleton.n_joints - int(m.skeleton.is_end_site.sum()),
            "end_sites": int(m.skeleton.is_end_site.sum()), "root": m.skeleton.names[0],
            "metres_per_unit": m.skeleton.metres_per_unit,
            "parts_found": len(parts),
        }
        try:
            feat = clip_features(m)
            row["contacts"] = {k: round(v, 3) for k, v in contact_summary(foot_contacts(feat), m.fps).items()}
            row["pelvis_height_m"] = round(float(feat.positions[:, parts["pelvis"], 1].mean()), 3)
        except Exception as e:  # unknown skeleton: report what is missing, keep going
            row["contacts"] = f"unavailable: {e}"
        rows.append(row)
    if args.json:
        print(json.dumps({"files": rows}, indent=1))
        return 0
    for r in rows:
        print(f"{r['file']}")
        print(f"  {r['frames']} frames at {r['fps']:g} fps = {r['duration_s']:.2f} s; skeleton: {r['joints']} joints "
              f"+ {r['end_sites']} end sites, root {r['root']!r}; units: {r['metres_per_unit']:.5g} m per file unit")
        c = r["contacts"]
        if isinstance(c, dict):
            print(f"  pelvis height {r['pelvis_height_m']:.2f} m; double support {100 * c['double_support_share']:.0f}% "
                  f"single {100 * c['single_support_share']:.0f}% flight {100 * c['flight_share']:.0f}% of frames; "
                  f"{c['double_support_intervals']} double-support intervals "
                  f"({c['double_support_per_s']:.2f}/s, median {c['double_support_median_s']:.3f} s)")
        else:
            print(f"  contacts {c}")
    return 0


def cmd_segment(args: argparse.Namespace) -> int:
    import dataclasses

    from motion_graph.library import LibraryParams, library_from_clips, segment_files
    from motion_graph.paths import boxing_files

    t0 = time.perf_counter()
    files = args.files or boxing_files(args.mocap)
    params = LibraryParams(fps=args.library_fps)
    if args.next_threshold is not None:
        params = dataclasses.replace(params, next_threshold_m=args.next_threshold)
    progress = not args.json and sys.stderr.isatty()
    retarget_report = None
    if args.retarget or args.target_skeleton or not args.files:
        from motion_graph.retarget import segment_retargeted
        clips, target, takes = segment_retargeted(files, params, args.target_skeleton, progress, args.fps)
        retarget_report = {"target": target.source, "target_fps": target.fps, "takes": takes}
    else:
        clips = segment_files(files, params, progress=progress, fps_override=args.fps)
    lib = library_from_clips(clips, params, args.labels)
    if retarget_report is not None:
        lib.meta["retarget"] = retarget_report
    if args.out:
        lib.save(args.out)
    if args.plot:
        from motion_graph.plot import plot_timelines
        plot_timelines([{
            "name": Path(c.path).name, "fps": c.motion.fps, "contacts": c.segmentation.contacts,
            "quietness": c.segmentation.quietness, "reach": c.features.reach, "cuts": c.segmentation.cuts,
            "labels": [lib.labels[i] for i in range(lib.n_actions) if lib.sources[i] == c.path],
            "strikes": c.strikes} for c in clips], args.plot)
    rep = lib.graph_report()
    seconds = time.perf_counter() - t0
    actions = []
    for a in range(lib.n_actions):
        row = {"id": a, "label": lib.labels[a], "source": lib.sources[a], "start_frame": int(lib.src_start[a]),
               "end_frame": int(lib.src_end[a]), "duration_s": round(float(lib.duration[a]), 3),
               "dx": round(float(lib.dx[a]), 3), "dz": round(float(lib.dz[a]), 3),
               "dheading": round(float(lib.dheading[a]), 3)}
        st = list(lib.strikes(a))
        if st:
            from motion_graph.classify import KINDS
            row["attacks"] = [{"kind": KINDS[lib.strike_kind[s]], "effector": lib.skeleton.names[lib.strike_joint[s]],
                               "hit_window": [int(lib.strike_w0[s]), int(lib.strike_w1[s])],
                               "reach_m": round(float(lib.strike_reach[s]), 3)} for s in st]
        if lib.defence_w0[a] >= 0:
            row["defence_window"] = [int(lib.defence_w0[a]), int(lib.defence_w1[a])]
        actions.append(row)
    summary = {
        "n_actions": lib.n_actions, "label_counts": lib.label_counts(),
        "n_attacks": int(sum(lib.is_attack(a) for a in range(lib.n_actions))),
        "n_defences": int(sum(lib.is_defence(a) for a in range(lib.n_actions))),
        "largest_scc_fraction": rep["largest_scc_fraction"], "mean_out_degree": rep["mean_out_degree"],
        "worst_transition_residual_m": rep["worst_transition_residual_m"],
        "duration_s": sum(c.motion.duration for c in clips), "seconds": round(seconds, 2),
        "library": args.out, "plot": args.plot, "actions": actions,
    }
    if retarget_report is not None:
        summary["retarget"] = retarget_report
        summary["largest_scc_size"] = rep["largest_scc_size"]
    if args.json:
        print(json.dumps(summary))
        return 0
    print(f"{lib.n_actions} actions from {len(clips)} file(s), {summary['duration_s']:.1f} s of mocap "
          f"({lib.n_actions / max(summary['duration_s'], 1e-9):.2f} actions/s) in {seconds:.1f} s")
    print("labels: " + ", ".join(f"{k} {v}" for k, v in summary["label_counts"].items()))
    print(f"attacks {summary['n_attacks']}, defences {summary['n_defences']}; action graph: "
          f"mean out-degree {rep['mean_out_degree']:.1f}, largest SCC {100 * rep['largest_scc_fraction']:.0f}%, "
          f"worst transition residual {100 * rep['worst_transition_residual_m']:.1f} cm")
    if retarget_report is not None:
        print(f"retargeted onto {retarget_report['target']} ({retarget_report['target_fps']:g} fps): " + "; ".join(
            f"{Path(k).name} leg scale {v['leg_scale']:.3f}" + (f", identity for {', '.join(v['unmatched'])}"
                                                               if v["unmatched"] else "")
            for k, v in retarget_report["takes"].items()))
    print(f"{'id':>3} {'label':<13} {'source':<12} {'frames':>11} {'dur':>5} {'dx':>6} {'dz':>6} {'dhead':>6}")
    for r in actions:
        print(f"{r['id']:>3} {r['label']:<13} {Path(r['source']).name:<12} {r['start_frame']:>5}-{r['end_frame']:<5} "
              f"{r['duration_s']:5.2f} {r['dx']:6.2f} {r['dz']:6.2f} {r['dheading']:6.2f}")
    if args.out:
        print(f"library written to {args.out}")
    if args.plot:
        print(f"timeline plot written to {args.plot}")
    return 0


def cmd_fetch(args: argparse.Namespace) -> int:
    from motion_graph.fetch import CMU_BASE_URL, FetchError, fetch_cmu

    try:
        files = fetch_cmu(Path(args.dest) if args.dest else None, base_url=args.url or CMU_BASE_URL, progress=True)
    except FetchError as e:
        print(f"igraph-fight: error: {e}", file=sys.stderr)
        return 2
    for f in files:
        print(f)
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    from igraph_fight.demo import run_demo

    summary = run_demo(args.mocap, args.out, args.seed, progress=sys.stderr.isatty())
    g, b = summary["graph"], summary["bout"]
    print(f"demo finished in {summary['seconds']:.1f} s")
    print(f"  actions: {summary['n_actions']} ({', '.join(f'{k} {v}' for k, v in summary['label_counts'].items())})")
    print(f"  interaction graph: {g['n_states']} states, {g['n_edges']} edges")
    print(f"  bout: {b['a']} (A) vs {b['b']} (B): hits {b['hits_a']:.0f} : {b['hits_b']:.0f}, "
          f"mean distance {b['mean_distance_m']:.2f} m")
    print("  open the animation in a browser: " + summary["artifacts"].get("bout_animation", "-"))
    for name, path in summary["artifacts"].items():
        print(f"  {name}: {path}")
    return 0
