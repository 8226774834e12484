"""Throughput of the coupled kinematic simulator (avatar-frames per second per core).

Usage: python benchmarks/bench_sim.py [--mocap DIR] [--events N] [--workers K]

Random coupled states (both avatars in random actions and frames, 0.3-1.5 m apart, random
headings) are advanced to their next decision event; an avatar-frame is one avatar advanced by
one frame with the push-apart and the hit tests of that frame. Two kernels are timed: the batch
kernel behind the sampler and the edges (canonical samples, one action each) and the world-state
kernel behind the game API. Prints the figures; asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mocap", default=None, help="mocap folder (default: the shared CMU boxing takes)")
    ap.add_argument("--events", type=int, default=400_000)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    from igraph_fight import sim
    from motion_graph.library import build_library
    from motion_graph.paths import find_mocap_root

    root = args.mocap or str(find_mocap_root() / "cmu" / "boxing")
    lib = build_library([root])
    tab = sim.SimTables.from_library(lib)
    T = tab.kernel_tuple()
    rng = np.random.default_rng(0)
    N = args.events
    A = tab.n_actions
    si = np.zeros((N, sim.N_SI), dtype=np.int64)
    si[:, sim.SI_MSELF] = rng.integers(0, A, N)
    si[:, sim.SI_MOTHER] = rng.integers(0, A, N)
    si[:, sim.SI_FOTHER] = np.floor(rng.random(N) * (tab.n_frames[si[:, sim.SI_MOTHER]] - 1))
    sf = np.stack([rng.uniform(0.3, 1.5, N), rng.uniform(-np.pi, np.pi, N), rng.uniform(-np.pi, np.pi, N)], 1)
    parent = np.arange(N)
    action = rng.integers(0, A, N)
    sim.expand_samples(T, si[:8], sf[:8], parent[:8], action[:8])  # compile
    best = np.inf
    for _ in range(args.repeat):
        t = time.perf_counter()
        _, _, feat, _ = sim.expand_samples(T, si, sf, parent, action, args.workers)
        best = min(best, time.perf_counter() - t)
    frames = float(feat[:, sim.FT_FRAMES].sum())
    out = {"events": N, "workers": args.workers, "mean_event_frames": frames / N,
           "samples_kernel_s": best, "samples_avatar_frames_per_s": 2 * frames / best,
           "samples_events_per_s": N / best}
    from igraph_fight.state import samples_to_worlds
    pose, act, frm, mask = samples_to_worlds(tab, si, sf)
    act[:, 0] = action
    frm[:, 0] = 0
    sim.advance_worlds(T, pose[:8].copy(), act[:8].copy(), frm[:8].copy(), mask[:8].copy())
    best = np.inf
    for _ in range(args.repeat):
        p, a, f, m = pose.copy(), act.copy(), frm.copy(), mask.copy()
        t = time.perf_counter()
        st = sim.advance_worlds(T, p, a, f, m)
        best = min(best, time.perf_counter() - t)
    frames = float(st[:, sim.ST_FRAMES].sum())
    out.update({"worlds_kernel_s (1 thread)": best, "worlds_avatar_frames_per_s": 2 * frames / best,
                "hit_events_share": float(np.mean(feat[:, sim.FT_HITS_SELF] + feat[:, sim.FT_HITS_OTHER] > 0)),
                "push_events_share": float(np.mean(feat[:, sim.FT_PUSH] > 0))})
    if args.json:
        print(json.dumps(out))
        return
    print(f"{N} events, mean {out['mean_event_frames']:.1f} frames each, {args.workers} worker(s)")
    print(f"  batch kernel (samples): {out['samples_avatar_frames_per_s'] / 1e6:.1f} M avatar-frames/s, "
          f"{out['samples_events_per_s'] / 1e3:.0f} k events/s")
    print(f"  world-state kernel (1 thread): {out['worlds_avatar_frames_per_s'] / 1e6:.1f} M avatar-frames/s")
    print(f"  events with a hit {100 * out['hit_events_share']:.2f}%, with a push {100 * out['push_events_share']:.1f}%")
    print("  target: >= 1 M avatar-frames/s per core")


if __name__ == "__main__":
    main()
