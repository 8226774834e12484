"""Benchmark the runtime controller (igraph_fight.controller.NPCController) on a real graph.

    python benchmarks/bench_controller.py --graph G.igz [--bouts 6] [--reps 3] [--threads 1 2]

Prints:
  A. single-decision latency of NPCController.act from Python on live observations recorded in
     bouts (IG vs IG): p50 / p90 / p99 / max, for table decisions (on the graph), off-graph
     decisions (simulated lookahead) and overall; the same observations answered from the table
     only (offgraph="nearest"); wall clock, and the thread's CPU time (preemption excluded);
  B. batch throughput of act_batch (decisions/s) for 1e4 .. 1e6 observations resampled from the
     live ones, table answers and with the off-graph lookahead, per numba thread count;
  C. style swap: set_style request -> new policy live (ms), and its parts;
  D. min-max compute time (compute_policy: rewards + search) at depth 1 / 3 / 5 / 10 at this
     graph's scale, per thread count.
Targets (issue 4): a single decision <= 20 us at p99 from Python; a batch >= 1M decisions/s.
No timing is asserted anywhere. The machine's state (load, CPU pressure, memory latency) is
printed first: on a shared 2-core VM the wall-clock figures mostly measure the neighbours.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba as nb  # noqa: E402
import numpy as np  # noqa: E402


def machine() -> str:
    out = []
    try:
        out.append("load " + " ".join(open("/proc/loadavg").read().split()[:3]))
    except OSError:
        pass
    try:
        line = open("/proc/pressure/cpu").readline().split()
        out.append("cpu pressure " + line[1])
    except OSError:
        pass
    out.append(f"cores {len(os.sched_getaffinity(0)) if hasattr(os, 'sched_getaffinity') else os.cpu_count()}")

    @nb.njit(cache=True)
    def chase(nxt, n):
        i = 0
        for _ in range(n):
            i = nxt[i]
        return i

    size = 4_000_000  # 32 MB
    p = np.random.default_rng(0).permutation(size)
    nxt = np.empty(size, np.int64)
    nxt[p] = np.roll(p, -1)
    chase(nxt, 10)
    t = time.perf_counter()
    chase(nxt, 200_000)
    out.append(f"DRAM latency {(time.perf_counter() - t) / 200_000 * 1e9:.0f} ns (pointer chase, 32 MB)")
    return ", ".join(out)


def pct(a, qs=(50, 90, 99, 100)) -> str:
    a = np.asarray(a)
    return " / ".join(f"{np.percentile(a, q):7.1f}" for q in qs)


def record_observations(graph, lib, bouts: int, seconds: float):
    """Observations at every decision of IG-vs-IG bouts (infighter vs outboxer, both snapping)."""
    from igraph_fight.agents import IGAgent
    from igraph_fight.controller import NPCController, observe
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.match import run_bout

    ca = NPCController(graph, lib, style="infighter", depth=5)
    cb = NPCController(graph, lib, style="outboxer", depth=5)
    game = FightGame(lib, GameConfig(max_seconds=seconds, sim=graph.sim_params()),
                     tables=ca.tables)
    obs = []

    class Rec(IGAgent):
        def step(self, state, player):
            obs.append(observe(state, player))
            return super().step(state, player)

    for seed in range(bouts):
        run_bout(game, [Rec(ca, snap=True), Rec(cb, snap=True)], seconds, np.random.default_rng(seed))
    ca.close()
    cb.close()
    return obs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", required=True)
    ap.add_argument("--bouts", type=int, default=6, help="bouts to record live observations from (default 6)")
    ap.add_argument("--bout-seconds", type=float, default=30.0)
    ap.add_argument("--reps", type=int, default=3, help="repetitions (median) of the batch / min-max timings")
    ap.add_argument("--threads", type=int, nargs="+", default=None, help="numba thread counts (default 1 and all)")
    ap.add_argument("--depths", type=int, nargs="+", default=[1, 3, 5, 10])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    args = ap.parse_args(argv)
    threads = args.threads or sorted({1, nb.config.NUMBA_NUM_THREADS})

    from igraph_fight.controller import PARALLEL_MIN, NPCController, Observation
    from igraph_fight.graph import load_graph
    from planner import compute_policy, load_style

    print(f"machine: {machine()}")
    t = time.perf_counter()
    graph = load_graph(args.graph)
    lib = graph.load_library()
    t_load = time.perf_counter() - t
    t = time.perf_counter()
    ctrl = NPCController(graph, lib, style="balanced", depth=5)
    t_init = time.perf_counter() - t
    print(f"graph {args.graph}: {graph.n_states} states, {graph.n_edges} edges; load {t_load:.1f} s, controller "
          f"init {t_init:.1f} s (index + policy + kernels)")
    obs = record_observations(graph, lib, args.bouts, args.bout_seconds)
    rng = np.random.default_rng(0)
    order = rng.permutation(len(obs))
    obs = [obs[i] for i in order]
    for o in obs[:50]:
        ctrl.act(o)  # compile / warm

    # ---- A. single decisions --------------------------------------------------------------------
    nearest = NPCController(graph, lib, style="balanced", depth=5, offgraph="nearest")
    for o in obs[:50]:
        nearest.act(o)
    print(f"\nA. single decision, NPCController.act from Python, {len(obs)} live observations from {args.bouts} "
          f"bouts of {args.bout_seconds:.0f} s (us: p50 / p90 / p99 / max)")
    for name, c in (("lookahead (default)", ctrl), ("table only (offgraph='nearest')", nearest)):
        wall, cpu, off = [], [], []
        for o in obs:
            t0 = time.perf_counter_ns()
            d = c.act(o)
            wall.append((time.perf_counter_ns() - t0) / 1e3)
            off.append(d.off_graph)
        for o in obs:
            t0 = time.thread_time_ns()
            c.act(o)
            cpu.append((time.thread_time_ns() - t0) / 1e3)
        wall, cpu, off = np.array(wall), np.array(cpu), np.array(off)
        print(f"  {name}: {100 * off.mean():.0f}% of the decisions off the graph")
        for label, sel in (("on-graph (table)", ~off), ("off-graph", off), ("overall", np.ones_like(off))):
            if sel.any():
                print(f"    {label:<17} wall {pct(wall[sel])}   thread CPU {pct(cpu[sel])}   (n={int(sel.sum())})")

    # ---- B. batch throughput -------------------------------------------------------------------
    arr = [np.array([getattr(o, f) for o in obs]) for f in Observation._fields]
    print(f"\nB. act_batch throughput (decisions/s; batches under {PARALLEL_MIN} run on the calling thread; "
          f"median of {args.reps})")
    for la in (False, True):
        for th in threads:
            nb.set_num_threads(th)
            for n in args.sizes:
                if la and n > 100_000:
                    continue
                idx = rng.integers(0, len(obs), n)
                b = [x[idx] for x in arr]
                ctrl.act_batch(*[x[:PARALLEL_MIN + 1] for x in b], lookahead=la)  # compile both kernels
                ctrl.act_batch(*[x[:10] for x in b], lookahead=la)
                walls, cpus = [], []
                for _ in range(args.reps):
                    c0, w0 = time.process_time(), time.perf_counter()
                    _, _, off = ctrl.act_batch(*b, lookahead=la)
                    walls.append(time.perf_counter() - w0)
                    cpus.append(time.process_time() - c0)
                w, cp = statistics.median(walls), statistics.median(cpus)
                print(f"  {'lookahead' if la else 'table':>9}  threads {th}  n={n:>9,}: {n / w / 1e6:6.3f} M/s wall, "
                      f"{n / cp / 1e6:6.3f} M per CPU-second ({1e6 * cp / n:6.2f} us CPU each; "
                      f"{100 * off.mean():.0f}% off-graph)")
    nb.set_num_threads(nb.config.NUMBA_NUM_THREADS)

    # ---- C. style swap -------------------------------------------------------------------------
    print("\nC. style swap: set_style(...) request -> new policy live (ms), a reader thread calling act meanwhile")
    stop = threading.Event()
    reads = [0]

    def reader():
        k = 0
        while not stop.is_set():
            ctrl.act(obs[k % len(obs)])
            k += 1
        reads[0] = k

    th_r = threading.Thread(target=reader)
    th_r.start()
    swaps = []
    for st in ["outboxer", "infighter", "balanced"] * max(1, args.reps // 2 + 1):
        ctrl.set_style(st, wait=True)
        swaps.append((st, ctrl.last_swap_ms, dict(ctrl.policy.timings_ms)))
    stop.set()
    th_r.join()
    ms = [s[1] for s in swaps]
    print(f"  {len(ms)} swaps: median {statistics.median(ms):.0f} ms, min {min(ms):.0f}, max {max(ms):.0f} "
          f"(reader made {reads[0]} decisions meanwhile); parts of the last: "
          + ", ".join(f"{k} {v:.0f} ms" for k, v in swaps[-1][2].items()))
    for th in threads:
        nb.set_num_threads(th)
        ctrl.set_style("outboxer", wait=True)
        print(f"  threads {th}: swap {ctrl.last_swap_ms:.0f} ms")
    nb.set_num_threads(nb.config.NUMBA_NUM_THREADS)

    # ---- D. min-max ----------------------------------------------------------------------------
    print(f"\nD. min-max compute time at this graph's scale ({graph.n_states} states, {graph.n_edges} edges): "
          f"compute_policy = rewards + search, ms, median of {args.reps}")
    arrays = ctrl._arrays
    style = load_style("balanced")
    for th in threads:
        for depth in args.depths:
            gamma = 1.0 if depth <= 5 else 0.95
            tot, search = [], []
            for _ in range(args.reps):
                pol = compute_policy(arrays, style, depth, gamma, search_graph=ctrl._search_graph, n_threads=th)
                tot.append(pol.compute_ms)
                search.append(pol.timings_ms["search"])
            print(f"  threads {th}  depth {depth:>2}: {statistics.median(tot):8.1f} ms (search "
                  f"{statistics.median(search):7.1f} ms)")
    ctrl.close()
    nearest.close()
    print(f"\nmachine after: {machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
