"""Interaction Graph build time and peak memory against the archive size, up to the paper's scale.

Usage:
    python benchmarks/bench_build.py                    # default options at several archive sizes
    python benchmarks/bench_build.py --paper            # the paper-scale configuration only
    python benchmarks/bench_build.py --compare-sklearn  # clustering: numba kernel vs scikit-learn

The paper (Shum, Komura & Yamazaki 2008): 79,855 states and 3,392,297 edges in about 180 minutes
on a Pentium IV 3.0 GHz dual core. Our target: that scale in at most 3 minutes on 2 cores with at
most 4 GiB. A mean of 42.5 edges per state needs menus larger than the default library's (mean
Next(a) about 19 at the 0.15 m threshold), so the paper-scale configuration uses a library built
with ``next_threshold_m=0.30`` (mean Next(a) about 60) and a coarser linking tolerance (0.25 m,
45 degrees, F0 = 10 frames; the clustering tolerance stays 5 cm / 10 degrees): with our two boxing
takes the default linking tolerance (0.10 m, 20 degrees, F0 = 3) links about a third of the menu
actions, far from the 42 edges per state of the paper (see the printed ``menu_actions_linked``). Each size runs in its own
process (peak RSS is per process); numba kernels are compiled (or loaded from the cache) by a small
warm-up build that is not timed. Prints the figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

PAPER_STATES = 79_855
PAPER_EDGES = 3_392_297

PAPER_CONFIG = {"next_threshold_m": 0.30, "options": {
    "max_samples": 200_000, "link_tol_r_m": 0.25, "link_tol_theta_rad": math.radians(45), "f0": 10}}


def _child(cfg: dict) -> dict:  # runs in the child process (see _run)
    """One build in this process (called through a subprocess)."""
    import dataclasses

    from igraph_fight.build.pipeline import BuildOptions, build_graph, peak_rss_mb
    from motion_graph.library import load_library

    lib = load_library(cfg["library"])
    opts = dataclasses.replace(BuildOptions(), **cfg["options"])
    t = time.perf_counter()
    build_graph(lib, dataclasses.replace(opts, max_samples=2000), seed=cfg["seed"], workers=cfg["workers"])
    warm = time.perf_counter() - t
    rss0 = peak_rss_mb()
    t = time.perf_counter()
    g, rep = build_graph(lib, opts, seed=cfg["seed"], workers=cfg["workers"])
    t_build = time.perf_counter() - t
    with tempfile.TemporaryDirectory() as d:
        t = time.perf_counter()
        g.save(os.path.join(d, "g.igz"))
        t_save = time.perf_counter() - t
        size_mb = os.path.getsize(os.path.join(d, "g.igz")) / 2**20
    keep = ("n_samples", "n_states", "n_edges", "mean_out_degree", "menu_actions_linked", "n_states_before_pruning",
            "dead_end_fraction", "snap_mean_cm", "snap_max_cm", "edge_snap_mean_cm", "edge_snap_max_cm",
            "edges_with_damage_given", "timings")
    return {"max_samples": opts.max_samples, "build_s": t_build, "save_s": t_save, "total_s": t_build + t_save,
            "file_mb": size_mb, "peak_rss_mb": peak_rss_mb(), "peak_rss_after_warmup_mb": rss0, "warmup_s": warm,
            **{k: rep[k] for k in keep}}


def run_child(script: str, cfg: dict) -> dict:
    """``python script --child CFG`` in a fresh process (so peak memory is its own); its RESULT line."""
    p = subprocess.run([sys.executable, os.path.abspath(script), "--child", json.dumps(cfg)], capture_output=True,
                       text=True)
    for line in p.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"benchmark child failed:\n{p.stderr[-3000:]}")


def _run(cfg: dict) -> dict:
    """One build in a fresh process (this script with --child)."""
    return run_child(__file__, cfg)


def _library(root: str, threshold: float, folder: str) -> str:
    from motion_graph.library import LibraryParams, build_library
    path = os.path.join(folder, f"lib_{threshold:.2f}.npz")
    if not os.path.exists(path):
        lib = build_library([root], LibraryParams(next_threshold_m=threshold))
        lib.save(path)
    return path


def compare_sklearn(root: str, folder: str, n_samples: int = 100_000) -> dict:
    """Time the numba clustering against scikit-learn KMeans doing the same bisection."""
    import numpy as np
    from sklearn.cluster import KMeans

    from igraph_fight.build import cluster, explore
    from igraph_fight.build.pipeline import BuildOptions
    from igraph_fight.sim import SimTables
    from motion_graph.library import load_library

    lib = load_library(_library(root, 0.15, folder))
    tab = SimTables.from_library(lib)
    o = BuildOptions(max_samples=n_samples)
    arc = explore.explore(tab, o.explore_options(), seed=0)
    G = explore.group_rows(tab.nextset, arc.si, o.f0)
    copt = o.cluster_options()
    cluster.cluster_samples(G[:100], arc.si[:100], arc.sf[:100], copt)
    t = time.perf_counter()
    cl = cluster.cluster_samples(G, arc.si, arc.sf, copt)
    t_numba = time.perf_counter() - t
    # scikit-learn: the same bisection, one KMeans(2) call per split, on the first groups
    _, inv = np.unique(G, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    groups = [np.nonzero(inv == g)[0] for g in range(min(inv.max() + 1, 400))]
    X = np.stack([arc.sf[:, 0] / copt.s_r_m, np.cos(arc.sf[:, 1]) / copt.s_theta_rad,
                  np.sin(arc.sf[:, 1]) / copt.s_theta_rad, np.cos(arc.sf[:, 2]) / copt.s_theta_rad,
                  np.sin(arc.sf[:, 2]) / copt.s_theta_rad], 1)

    def ok(idx):
        r = arc.sf[idx, 0]
        t1 = np.arctan2(np.sin(arc.sf[idx, 1]).mean(), np.cos(arc.sf[idx, 1]).mean())
        t2 = np.arctan2(np.sin(arc.sf[idx, 2]).mean(), np.cos(arc.sf[idx, 2]).mean())
        w = lambda a: (a + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
        return (np.all(np.abs(r - r.mean()) <= copt.tol_r_m) and np.all(np.abs(w(arc.sf[idx, 1] - t1)) <= copt.tol_theta_rad)
                and np.all(np.abs(w(arc.sf[idx, 2] - t2)) <= copt.tol_theta_rad))

    t = time.perf_counter()
    n_sk = 0
    members = 0
    for idx in groups:
        members += len(idx)
        stack = [idx]
        while stack:
            c = stack.pop()
            if len(c) <= 1 or ok(c):
                n_sk += 1
                continue
            lab = KMeans(2, n_init=1, random_state=0).fit_predict(X[c])
            if lab.min() == lab.max():
                n_sk += len(c)
                continue
            stack += [c[lab == 0], c[lab == 1]]
    t_sk = time.perf_counter() - t
    return {"samples": len(arc), "groups": int(inv.max() + 1), "states": len(cl.si), "numba_s": t_numba,
            "sklearn_groups_timed": len(groups), "sklearn_members_timed": members, "sklearn_s": t_sk,
            "sklearn_extrapolated_s": t_sk * len(arc) / max(members, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", default=None, help="boxing mocap folder (default: the shared CMU takes)")
    ap.add_argument("--sizes", default="50000,150000,300000,600000", help="archive sizes with default options")
    ap.add_argument("--paper", action="store_true", help="only the paper-scale configuration")
    ap.add_argument("--no-paper", action="store_true", help="skip the paper-scale configuration")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--compare-sklearn", action="store_true")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    from motion_graph.paths import find_mocap_root
    root = args.mocap or str(find_mocap_root() / "cmu" / "boxing")
    results = []
    with tempfile.TemporaryDirectory() as folder:
        if args.compare_sklearn:
            r = compare_sklearn(root, folder)
            print(json.dumps(r) if args.json else
                  f"clustering {r['samples']} samples in {r['groups']} groups -> {r['states']} states: numba "
                  f"{r['numba_s']:.2f} s; scikit-learn KMeans bisection {r['sklearn_s']:.1f} s for "
                  f"{r['sklearn_groups_timed']} groups ({r['sklearn_members_timed']} samples), about "
                  f"{r['sklearn_extrapolated_s']:.0f} s extrapolated to all")
            return
        if not args.paper:
            lib = _library(root, 0.15, folder)
            for n in [int(x) for x in args.sizes.split(",") if x]:
                results.append({"config": "default", **_run({"library": lib, "options": {"max_samples": n},
                                                             "seed": args.seed, "workers": args.workers})})
                _print(results[-1], args.json)
        if not args.no_paper:
            lib = _library(root, PAPER_CONFIG["next_threshold_m"], folder)
            r = {"config": "paper-scale", **_run({"library": lib, "options": PAPER_CONFIG["options"],
                                                  "seed": args.seed, "workers": args.workers})}
            r["reaches_paper_scale"] = r["n_states"] >= PAPER_STATES and r["n_edges"] >= PAPER_EDGES
            r["within_target"] = r["total_s"] <= 180 and r["peak_rss_mb"] <= 4096
            results.append(r)
            _print(r, args.json)


def _print(r: dict, as_json: bool) -> None:
    if as_json:
        print(json.dumps(r), flush=True)
        return
    print(f"[{r['config']}] {r['max_samples']} samples -> {r['n_states']} states, {r['n_edges']} edges "
          f"(mean degree {r['mean_out_degree']:.1f}, {100 * r['menu_actions_linked']:.0f}% of menu actions linked): "
          f"build {r['build_s']:.1f} s + save {r['save_s']:.1f} s, peak RSS {r['peak_rss_mb']:.0f} MiB, "
          f"file {r['file_mb']:.0f} MiB; phases {r['timings']}", flush=True)
    if "reaches_paper_scale" in r:
        print(f"  paper scale (>= {PAPER_STATES} states, >= {PAPER_EDGES} edges): {r['reaches_paper_scale']}; "
              f"within 3 min / 4 GiB: {r['within_target']} (paper: about 180 min)", flush=True)


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        print("RESULT " + json.dumps(_child(json.loads(sys.argv[2]))), flush=True)
    else:
        main()
