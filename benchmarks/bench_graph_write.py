"""Writing a graph file: time and peak memory of InteractionGraph.save against states and edges.

    python benchmarks/bench_graph_write.py --graph graph.igz [--copies 1,3] [--json]

A build leaves its edge columns as memory-mapped files (igraph_fight.build.columns) and saves the
graph from them. This benchmark does the same for GRAPH's arrays and for larger graphs made of
``copies`` disjoint copies of it (targets shifted: a valid graph with ``copies`` times the states
and edges, the same library): the arrays are written to files in a temporary folder, mapped again
read-only, and a fresh process saves the graph from those maps (validation, the edge replay of
the version 4 file, the encoding, the write). Printed per size: states, edges, wall seconds, the
peak of the process's anonymous resident memory during the save (RssAnon sampled every 5 ms: the
memory the process owns, not the file pages the kernel may reclaim) above what it held before,
that peak per 1,000 states and per edge, and the file's size. The graph written is loaded back
and its content hash compared with the source's.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent

CHILD = r"""
import json, sys, threading, time
import numpy as np
from igraph_fight.graph import InteractionGraph

def anon_kb():
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith("RssAnon:"):
                return int(line.split()[1])
    return 0

folder, out = sys.argv[1], sys.argv[2]
meta = json.load(open(folder + "/meta.json"))
arrays = {k: np.memmap(f"{folder}/{k}.bin", dtype=dt, mode="r", shape=(n,)) for k, (dt, n) in meta["arrays"].items()}
g = InteractionGraph(arrays, meta["header"])
base = anon_kb()
peak = [base]
stop = threading.Event()
def sample():
    while not stop.is_set():
        peak[0] = max(peak[0], anon_kb())
        time.sleep(0.005)
th = threading.Thread(target=sample, daemon=True)
th.start()
t = time.perf_counter()
g.save(out)
wall = time.perf_counter() - t
stop.set(); th.join()
print(json.dumps({"wall_s": wall, "base_anon_mb": base / 1024, "peak_anon_mb": peak[0] / 1024,
                  "save_anon_mb": (peak[0] - base) / 1024}))
"""


def tiled(g, copies: int) -> dict[str, np.ndarray]:
    """``copies`` disjoint copies of graph ``g``'s arrays (state ids shifted in edge_target)."""
    from igraph_fight.graph import ALL_ARRAYS, STATE_ARRAYS
    S, E = g.n_states, g.n_edges
    out = {}
    for k in ALL_ARRAYS:
        a = np.asarray(g.arrays[k])
        if k == "state_offsets":
            out[k] = np.concatenate([[0]] + [a[1:] + c * E for c in range(copies)]).astype(a.dtype)
        elif k == "edge_target":
            out[k] = np.concatenate([a + c * S for c in range(copies)]).astype(a.dtype)
        elif k in STATE_ARRAYS or k.startswith(("edge_", "feat_")):
            out[k] = np.concatenate([a] * copies)
    out["library_npz"] = np.asarray(g.arrays["library_npz"])
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--graph", required=True)
    p.add_argument("--copies", default="1,3", help="sizes, as copies of GRAPH (comma-separated)")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    from igraph_fight.graph import InteractionGraph, load_graph
    src = load_graph(a.graph)
    header = {k: v for k, v in src.header.items() if k not in ("path", "checksum", "members", "content_hash",
                                                                 "shapes", "version")}
    rows = []
    for copies in [int(x) for x in a.copies.split(",")]:
        arrays = tiled(src, copies)
        with tempfile.TemporaryDirectory(dir=os.path.dirname(os.path.abspath(a.graph))) as tmp:
            meta = {"arrays": {}, "header": header}
            for k, v in arrays.items():
                mm = np.memmap(f"{tmp}/{k}.bin", dtype=v.dtype, mode="w+", shape=v.shape)
                mm[:] = v
                mm.flush()
                meta["arrays"][k] = (v.dtype.str, int(len(v)))
                del mm
            want = InteractionGraph(arrays).content_hash
            S, E = len(arrays["state_r"]), len(arrays["edge_target"])
            del arrays
            Path(tmp, "meta.json").write_text(json.dumps(meta))
            out = f"{tmp}/out.igz"
            r = subprocess.run([sys.executable, "-c", CHILD, tmp, out], capture_output=True, text=True, cwd=str(ROOT))
            if r.returncode:
                print(r.stderr, file=sys.stderr)
                return 1
            m = json.loads(r.stdout.strip().splitlines()[-1])
            same = load_graph(out).content_hash == want
            m.update(copies=copies, n_states=S, n_edges=E, file_mb=os.path.getsize(out) / 2**20, same_hash=same,
                     anon_bytes_per_edge=m["save_anon_mb"] * 2**20 / max(E, 1),
                     anon_mb_per_1000_states=m["save_anon_mb"] * 1000 / max(S, 1))
        rows.append(m)
        if not a.json:
            print(f"{S:>10,} states {E:>12,} edges: save {m['wall_s']:.1f} s, anonymous memory +{m['save_anon_mb']:.0f} MiB "
                  f"({m['anon_bytes_per_edge']:.1f} B per edge), file {m['file_mb']:.0f} MiB, same hash: {same}")
    if a.json:
        print(json.dumps(rows, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
