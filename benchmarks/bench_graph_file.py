"""Graph file size and load time: an old (version 1 to 3) file against its compact (version 4) copy.

    python benchmarks/bench_graph_file.py --graph graph.igz [--out graph_v3.igz] [--repeat 5] [--policies] [--floor]

Converts GRAPH to the compact format (igraph_fight.graph.convert_graph_file; skipped when OUT
exists and holds the same content hash), then prints both files' sizes, their load times
(InteractionGraph.load, validation included; the median of --repeat fresh processes, the files
in the page cache) and the time to load and touch every array (version 4 replays its edge
features then), the ratios, whether both load to bit-identical arrays and the same
content hash, and with --policies whether the policy tables (best_me, best_opp, V at depth D and
D-1) of three styles at depths 1, 3 and 5 are bit-identical. --floor: what the best lossless
compression this benchmark knows (bytes grouped by significance, then zlib level 9) would keep of
each memory-mapped float array, and of the same values rounded to float32 (a lossy format's).
--json: one JSON object.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from igraph_fight.graph import ALL_ARRAYS, InteractionGraph, convert_graph_file, header_summary


def load_seconds(path: str, repeat: int, decode: bool = False) -> float:
    """Median over ``repeat`` fresh processes of one InteractionGraph.load (what a command pays;
    imports excluded, the file in the page cache after a first read); with ``decode``, of the
    load and the first access to every array (what a policy computation adds: version 4's replay)."""
    import subprocess
    path = os.path.abspath(path)
    touch = "; [g.arrays[k] for k in list(g.arrays)]" if decode else ""
    code = ("import sys, time; from igraph_fight.graph import InteractionGraph; t = time.perf_counter(); "
            f"g = InteractionGraph.load(sys.argv[1]){touch}; print(time.perf_counter() - t)")
    times = []
    for i in range(repeat + 1):
        r = subprocess.run([sys.executable, "-c", code, path], capture_output=True, text=True, check=True,
                           cwd=str(Path(__file__).resolve().parent.parent))
        if i:  # the first run warms the page cache
            times.append(float(r.stdout.strip().splitlines()[-1]))
    return statistics.median(times)


def shuffled_deflate_bytes(a: np.ndarray) -> int:
    """zlib level 9 of ``a``'s bytes grouped by significance (byte 0 of every value, then byte 1...)."""
    import zlib
    b = np.ascontiguousarray(a).view(np.uint8).reshape(len(a), a.dtype.itemsize).T.copy()
    return len(zlib.compress(b.tobytes(), 9))


def floor_bytes(g: InteractionGraph) -> dict:
    from igraph_fight.graph import COMPACT_MAPPED

    out = {}
    for k in COMPACT_MAPPED:
        if k in g.arrays and g.arrays[k].dtype == np.float64:
            a = g.arrays[k]
            out[k] = {"stored": a.nbytes, "lossless": shuffled_deflate_bytes(a),
                      "float32_lossy": shuffled_deflate_bytes(a.astype(np.float32)),
                      "distinct": int(len(np.unique(a)))}
    return out


def policies_identical(a: InteractionGraph, b: InteractionGraph, styles: list[str], depths: list[int]) -> bool:
    from planner import SearchGraph, compute_policy
    from motion_graph.classify import KINDS

    out = True
    for g in (a, b):
        g.header.setdefault("kinds_table", list(KINDS))
    sga = SearchGraph.from_arrays(a.arrays["state_offsets"], a.arrays["edge_target"], a.arrays["edge_swap"])
    sgb = SearchGraph.from_arrays(b.arrays["state_offsets"], b.arrays["edge_target"], b.arrays["edge_swap"])
    for st in styles:
        for d in depths:
            pa = compute_policy(a, st, d, search_graph=sga)
            pb = compute_policy(b, st, d, search_graph=sgb)
            same = all(np.array_equal(getattr(pa, k), getattr(pb, k))
                       for k in ("best_me", "best_opp", "V_me", "V_opp", "V_me_next", "V_opp_next"))
            print(f"  policy {st} depth {d}: {'identical' if same else 'DIFFERENT'}", file=sys.stderr)
            out &= same
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--graph", required=True, help="a graph file (any version; an old one to compare)")
    p.add_argument("--out", default=None, help="the compact copy (default: GRAPH with .v3.igz)")
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--policies", action="store_true", help="also compare the policy tables")
    p.add_argument("--floor", action="store_true", help="compression floor of the memory-mapped floats")
    p.add_argument("--json", action="store_true")
    args = p.parse_args(argv)
    old = str(args.graph)
    new = args.out or str(Path(old).with_suffix("")) + ".v3.igz"
    want = header_summary(old).get("content_hash")
    if not (os.path.exists(new) and header_summary(new).get("content_hash") == want):
        t = time.perf_counter()
        convert_graph_file(old, new)
        print(f"converted {old} -> {new} in {time.perf_counter() - t:.1f} s", file=sys.stderr)
    ga, gb = InteractionGraph.load(old), InteractionGraph.load(new)
    same_arrays = all(ga.arrays[k].dtype == gb.arrays[k].dtype and np.array_equal(
        ga.arrays[k].view(np.uint8), gb.arrays[k].view(np.uint8)) for k in ALL_ARRAYS)
    ha, hb = ga.content_hash, gb.content_hash
    res = {
        "old": old, "new": new, "old_version": ga.header.get("version"), "new_version": gb.header.get("version"),
        "old_bytes": os.path.getsize(old), "new_bytes": os.path.getsize(new),
        "old_load_s": load_seconds(old, args.repeat), "new_load_s": load_seconds(new, args.repeat),
        "old_decode_s": load_seconds(old, args.repeat, True), "new_decode_s": load_seconds(new, args.repeat, True),
        "arrays_identical": bool(same_arrays), "content_hash_old": ha, "content_hash_new": hb,
        "content_hash_equal": ha == hb and hb == gb.header.get("content_hash"),
    }
    res["size_ratio"] = res["old_bytes"] / res["new_bytes"]
    res["load_ratio"] = res["old_load_s"] / res["new_load_s"]
    if args.policies:
        res["policies_identical"] = policies_identical(ga, gb, ["infighter", "outboxer", "balanced"], [1, 3, 5])
    if args.floor:
        res["floor"] = floor_bytes(gb)
    if args.json:
        print(json.dumps(res))
        return 0
    print(f"old  {old} (version {res['old_version']}): {res['old_bytes'] / 1e6:.1f} MB, "
          f"load {res['old_load_s']:.3f} s")
    print(f"new  {new} (version {res['new_version']}): {res['new_bytes'] / 1e6:.1f} MB, "
          f"load {res['new_load_s']:.3f} s")
    print(f"load and first access to every array: old {res['old_decode_s']:.3f} s, new {res['new_decode_s']:.3f} s")
    print(f"ratios: size {res['size_ratio']:.2f}x smaller, load {res['load_ratio']:.1f}x faster")
    print(f"arrays bit-identical: {res['arrays_identical']}; content hash {hb[:12]}... equal: {res['content_hash_equal']}")
    if args.policies:
        print(f"policy tables (3 styles x depths 1, 3, 5) bit-identical: {res['policies_identical']}")
    for k, f in res.get("floor", {}).items():
        print(f"  {k}: {f['distinct']} distinct values, stored {f['stored'] / 1e6:.1f} MB; shuffled deflate "
              f"{f['lossless'] / 1e6:.1f} MB lossless, {f['float32_lossy'] / 1e6:.1f} MB as float32 (lossy)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
