"""Graph build scaling: time and peak memory per process against backend, workers and graph size,
and a projection of a 10 M-state build on a Ray cluster from the measured per-item costs.

Usage:
    python benchmarks/bench_build_scaling.py                        # workers sweep + size sweep
    python benchmarks/bench_build_scaling.py --workers-at 150000 --sizes 150000,600000,3000000 \\
        --size-workers 1 --out scaling.json

Every build runs in its own process (peak RSS is per process: the driver's; a Ray build also
reports each actor's), with the default build options at ``max_samples`` = the size, numba kernels
compiled by an untimed warm-up build first. Part 1: local and ray backends with 1 and 2 workers
at one size (the same content hash is checked). Part 2: the local backend at growing archive
sizes. Part 3: the projection (printed, and in the JSON): per-item costs of the parallel ops
(core-seconds per sample, per state, per edge) and of the driver's serial share, fitted as powers
of the archive size over the local runs and extrapolated; memory per state of the driver and per
sample of a worker's index replica. ``--project-only FILE`` recomputes it from a saved JSON.
Prints the figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time


def _child(cfg: dict) -> dict:  # runs in the child process (see _run)
    import dataclasses

    from igraph_fight.build.pipeline import BuildOptions, build_graph, peak_rss_mb
    from motion_graph.library import load_library

    lib = load_library(cfg["library"])
    opts = dataclasses.replace(BuildOptions(), max_samples=int(cfg["size"]))
    kw = {"backend": cfg["backend"], "workers": cfg["workers"]}
    if cfg["backend"] == "ray":
        import ray
        ray.init(num_cpus=max(2, cfg["workers"]), include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    build_graph(lib, dataclasses.replace(opts, max_samples=2000, seed_bouts=8), seed=0, **kw)
    rss0 = peak_rss_mb()
    t = time.perf_counter()
    g, rep = build_graph(lib, opts, seed=0, **kw)
    wall = time.perf_counter() - t
    keep = ("n_samples", "n_states", "n_edges", "timings", "backend", "content_hash")
    out = {"size": int(cfg["size"]), "wall_s": wall, "driver_peak_rss_mb": peak_rss_mb(),
           "driver_rss_after_warmup_mb": rss0, **{k: rep[k] for k in keep}}
    out["n_landings"] = int(g.header["report"].get("n_edges_before_pruning", 0))
    out["n_children"] = int(rep["n_samples"])
    return out


def _run(cfg: dict) -> dict:
    from bench_build import run_child  # the sibling script: the running script's folder is importable
    return run_child(__file__, cfg)


def _line(r: dict) -> str:
    b = r["backend"]
    t = r["timings"]
    w = f", worker peak {max(b['worker_peak_rss_mb']):.0f} MiB" if b["backend"] == "ray" else ""
    return (f"{b['backend']:5s} x{b['workers']}: {r['size']} samples -> {r['n_states']} states, {r['n_edges']} edges "
            f"in {r['wall_s']:.1f} s (seed bouts {t['seed_bouts_s']:.1f}, explore {t['explore_s']:.1f}, cluster "
            f"{t['cluster_s']:.1f}, edges {t['edges_s']:.1f}), driver peak {r['driver_peak_rss_mb']:.0f} MiB{w}; "
            f"hash {r['content_hash'][:12]}")


def item_costs(r: dict) -> dict:
    """Seconds per item and per core of each part of one build (parallel ops: the op's wall time
    times its workers; the driver's share: the rest of the stage)."""
    par = r["backend"]["parallel_s"]
    w = r["backend"]["workers"]
    t = r["timings"]
    S, N, E = r["n_states"], r["n_samples"], max(r["n_edges"], 1)
    return {
        "sampler_core_s_per_sample": par.get("sampler_expand", 0.0) * w / N,
        "sampler_driver_s_per_sample": max(0.0, t["explore_s"] - par.get("sampler_expand", 0.0)) / N,
        "cluster_core_s_per_sample": par.get("cluster", t["cluster_s"]) / N,
        "link_core_s_per_state": par.get("link_candidates", 0.0) * w / S,
        "link_features_core_s_per_edge": par.get("link_features", 0.0) * w / E,
        "link_driver_s_per_state": max(0.0, t["edges_s"] - par.get("link_candidates", 0.0)
                                       - par.get("link_features", 0.0)) / S,
    }


def projection(runs: list[dict], target_states: float = 10e6, nodes: int = 8, cores: int = 16) -> dict:
    """A ``target_states`` build on ``nodes`` x ``cores`` Ray workers, from the local runs of the
    size sweep: each per-item cost is fitted as a power of the archive size (the costs grow with
    size: denser hash cells, longer chains) and extrapolated; samples and edges per state, and the
    driver's memory per state, are taken from the largest run (memory: a straight-line fit)."""
    import numpy as np
    loc = sorted([x for x in runs if x["backend"]["backend"] == "local"], key=lambda x: x["n_samples"])
    by_size: dict[int, dict] = {}
    for x in loc:
        by_size[x["n_samples"]] = x  # one run per size (the last)
    pts = sorted(by_size.values(), key=lambda x: x["n_samples"])
    if len(pts) < 2:
        return {}
    big = pts[-1]
    samples_per_state = big["n_samples"] / big["n_states"]
    edges_per_state = big["n_edges"] / big["n_states"]
    n_samp = target_states * samples_per_state
    n_edge = target_states * edges_per_state
    logn = np.log([x["n_samples"] for x in pts])
    fitted, at_target = {}, {}
    for k in item_costs(big):
        y = np.array([max(item_costs(x)[k], 1e-12) for x in pts])
        b, a = np.polyfit(logn, np.log(y), 1)
        fitted[k] = {"exponent": float(b), "at_largest_run": float(y[-1])}
        at_target[k] = float(np.exp(a + b * np.log(n_samp)))
    W = nodes * cores
    par_s = (at_target["sampler_core_s_per_sample"] * n_samp + at_target["cluster_core_s_per_sample"] * n_samp
             + at_target["link_core_s_per_state"] * target_states
             + at_target["link_features_core_s_per_edge"] * n_edge) / W
    ser_s = at_target["sampler_driver_s_per_sample"] * n_samp + at_target["link_driver_s_per_state"] * target_states
    slope, icpt = np.polyfit([x["n_states"] for x in pts], [x["driver_peak_rss_mb"] for x in pts], 1)
    index_bytes_per_sample = 128  # hash slots (2-4 per point x 16 B) + chain 8 B + key 32 B + floats 24 B
    return {"sizes": [x["n_samples"] for x in pts], "fitted": fitted, "at_target": at_target,
            "samples_per_state": samples_per_state, "edges_per_state": edges_per_state,
            "driver_mb_per_1k_states": 1000 * slope, "driver_mb_intercept": icpt,
            "target_states": target_states, "nodes": nodes, "cores_per_node": cores,
            "projected_parallel_s": par_s, "projected_driver_serial_s": ser_s,
            "projected_total_s": par_s + ser_s,
            "projected_driver_gb": (icpt + slope * target_states) / 1024,
            "projected_worker_index_gb": index_bytes_per_sample * n_samp / 2**30,
            "projected_samples": n_samp, "projected_edges": n_edge}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", default=None, help="boxing mocap folder (default: the shared CMU takes)")
    ap.add_argument("--workers-at", type=int, default=150_000, help="archive size of the workers sweep (0: skip)")
    ap.add_argument("--sizes", default="150000,600000,1500000", help="archive sizes of the size sweep ('' to skip)")
    ap.add_argument("--size-workers", type=int, default=1, help="local threads in the size sweep (default 1)")
    ap.add_argument("--out", default=None, help="write every run and the projection as JSON here")
    ap.add_argument("--project-only", default=None, metavar="JSON", help="only the projection, from a saved --out")
    args = ap.parse_args()
    if args.project_only:
        with open(args.project_only) as f:
            _print_projection(projection(json.load(f)["runs"]))
        return
    from motion_graph.library import build_library
    from motion_graph.paths import find_mocap_root
    root = args.mocap or str(find_mocap_root() / "cmu" / "boxing")
    runs: list[dict] = []
    with tempfile.TemporaryDirectory() as folder:
        lib = os.path.join(folder, "lib.npz")
        build_library([root]).save(lib)
        if args.workers_at:
            for backend in ("local", "ray"):
                for w in (1, 2):
                    runs.append(_run({"library": lib, "size": args.workers_at, "backend": backend, "workers": w}))
                    print(_line(runs[-1]), flush=True)
            hashes = {r["content_hash"] for r in runs}
            print(f"same content hash across backends and workers: {len(hashes) == 1}", flush=True)
        for n in [int(x) for x in args.sizes.split(",") if x]:
            runs.append(_run({"library": lib, "size": n, "backend": "local", "workers": args.size_workers}))
            print(_line(runs[-1]), flush=True)
    proj = projection(runs)
    _print_projection(proj)
    if args.out:
        from motion_graph.atomic import atomic_write_text
        atomic_write_text(args.out, json.dumps({"runs": runs, "projection": proj}, indent=1))


def _print_projection(proj: dict) -> None:
    if not proj:
        print("projection: needs local runs at two or more sizes")
        return
    ex = ", ".join(f"{k} x N^{v['exponent']:.2f}" for k, v in proj["fitted"].items())
    print(f"cost growth with archive size N: {ex}")
    print(f"projection, {proj['target_states'] / 1e6:.0f} M states ({proj['projected_samples'] / 1e6:.1f} M samples, "
          f"{proj['projected_edges'] / 1e6:.0f} M edges) on {proj['nodes']} nodes x {proj['cores_per_node']} cores: "
          f"{proj['projected_total_s'] / 60:.0f} min ({proj['projected_parallel_s'] / 60:.1f} min parallel, "
          f"{proj['projected_driver_serial_s'] / 60:.0f} min on the driver), driver memory "
          f"{proj['projected_driver_gb']:.0f} GB, index replica per worker {proj['projected_worker_index_gb']:.1f} GB",
          flush=True)


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--child":
        print("RESULT " + json.dumps(_child(json.loads(sys.argv[2]))), flush=True)
    else:
        main()
