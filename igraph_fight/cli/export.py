"""`igraph-fight export`: the table decision of NPCController for engines, in one file (thin)."""
from __future__ import annotations

import argparse
import json


def register(sub) -> None:
    from igraph_fight.cli import depth_list

    p = sub.add_parser("export", help="the nearest-state index and best-action tables of styles and depths, "
                                      "for an engine (docs/npc_export.md)",
                       description="Write the nearest-state index of a graph and, for every style and depth, the "
                                   "action of each state's best edge (and the fallbacks for Next-sets the graph "
                                   "lacks) in one binary file (docs/npc_export.md). A reader that follows the "
                                   "document (examples/npc_export_reader.py, numpy only) answers what "
                                   "NPCController(offgraph='nearest', first_ply='table') answers.")
    p.add_argument("--graph", required=True, help="graph file (.igz)")
    p.add_argument("--styles", default="infighter,outboxer,balanced", help="comma-separated presets or style files")
    p.add_argument("--depths", type=depth_list, default="1,3,5", help="comma-separated depths (1..12)")
    p.add_argument("--out", required=True, help="export file to write (e.g. npc.bin)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.set_defaults(func=cmd_export)


def cmd_export(args: argparse.Namespace) -> int:
    from planner import load_style

    from igraph_fight.export import export_npc

    styles = [s.strip() for s in args.styles.split(",") if s.strip()]
    depths = sorted({int(d) for d in args.depths.split(",") if d.strip()})
    for s in styles:
        load_style(s)  # an unknown style: one line before the graph is read
    info = export_npc(args.graph, styles, depths, args.out)
    if args.json:
        print(json.dumps(info))
        return 0
    print(f"{info['n_states']} states, {info['tables']} tables ({', '.join(styles)} x depths "
          f"{', '.join(map(str, depths))}) written to {info['out']}: {info['bytes'] / 1e6:.2f} MB")
    for k, v in info["section_bytes"].items():
        print(f"  {k}: {v / 1e6:.2f} MB")
    return 0
