"""Benchmark the planner's min-max at the paper's scale (79,855 states, 3,392,297 edges).

Prints milliseconds (min and median over --reps runs, wall clock) for:
  A. depth 1/3/5/10 on an IG-like synthetic graph, per state renumbering and thread count;
  B. the effect of the input state order (natural / group / shuffled) and of reordering;
  C. a naive parallel kernel (float64, separate value tables, swap branch) for reference;
  D. depth 5 against graph size;
  E. a full style swap (rewards + packing + search) with compute_policy;
  F. a graph without locality (uniform random targets);
  G. with --graph PATH.npz: the same on a real graph (contract arrays, docs/contracts.md).

Usage: python benchmarks/bench_planner.py [--graph G.npz] [--quick] [--threads 1 2] [--reps 7]

OMP_WAIT_POLICY is set to PASSIVE (unless already set, or --no-passive): with numba's OpenMP
threading layer and other busy processes on the machine, spinning idle threads otherwise cost
2-4x. No timing is asserted; the figures depend on the machine's load (printed).
"""
from __future__ import annotations

import argparse
import os
import sys
import time

if "--no-passive" not in sys.argv:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba as nb  # noqa: E402
import numpy as np  # noqa: E402

from planner import SearchGraph, Style, compute_policy, synthetic_graph

PAPER_S, PAPER_E = 79_855, 3_392_297
KINDS = ("jab", "straight", "hook", "uppercut", "kick", "duck", "dodge", "step_forward", "step_back",
         "step_left", "step_right", "turn_left", "turn_right", "guard")


@nb.njit(parallel=True, cache=True)
def naive_minmax(offsets, target, swap, W_me, W_opp, depth, gamma):
    """Straightforward kernel: (2, S) float64 tables, swap branch, best edges at every depth."""
    n = offsets.shape[0] - 1
    V = np.zeros((2, n))
    Vn = np.zeros((2, n))
    best = np.full((2, n), -1, np.int64)
    for d in range(depth):
        for s in nb.prange(n):
            bm = -np.inf
            bo = np.inf
            for e in range(offsets[s], offsets[s + 1]):
                t = target[e]
                if swap[e]:
                    a = W_me[e] + gamma * V[1, t]
                    b = W_opp[e] + gamma * V[0, t]
                else:
                    a = W_me[e] + gamma * V[0, t]
                    b = W_opp[e] + gamma * V[1, t]
                if a > bm:
                    bm = a
                    best[0, s] = e
                if b < bo:
                    bo = b
                    best[1, s] = e
            if offsets[s] == offsets[s + 1]:
                bm = 0.0
                bo = 0.0
            Vn[0, s] = bm
            Vn[1, s] = bo
        V, Vn = Vn, V
    return V, best


def timed(fn, reps: int) -> tuple[float, float, float]:
    """(min wall, median wall, min CPU time of this process) in ms over ``reps`` runs."""
    fn()  # warm-up (compilation, caches)
    ts, cs = [], []
    for _ in range(reps):
        c = time.process_time()
        t = time.perf_counter()
        fn()
        ts.append((time.perf_counter() - t) * 1e3)
        cs.append((time.process_time() - c) * 1e3)
    return float(np.min(ts)), float(np.median(ts)), float(np.min(cs))


def fmt(t: tuple[float, float, float]) -> str:
    return f"{t[0]:6.1f} ({t[1]:6.1f}) {t[2]:6.1f}"


def gamma_for(depth: int) -> float:
    return 1.0 if depth <= 5 else 0.95


def header() -> None:
    load = os.getloadavg()
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "?")
    print(f"# cpu: {cpu}, {os.cpu_count()} cpus; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}")
    print(f"# numba {nb.__version__}, threads max {nb.config.NUMBA_NUM_THREADS}, "
          f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', '(unset)')}")
    print("# times: ms, 'min (median) cpu': wall-clock min and median over the repetitions, then the")
    print("# least CPU time used by all threads (with 1 thread, about what an idle machine gives)\n")


def bench_depths(name: str, arrays: dict, orderings: list, threads: list[int], depths: list[int],
                 reps: int) -> None:
    """``orderings``: names (SearchGraph.from_arrays) or (label, permutation) pairs."""
    rng = np.random.default_rng(0)
    E = int(arrays["state_offsets"][-1])
    W_me, W_opp = rng.normal(size=E), rng.normal(size=E)
    print(f"## {name}: S={len(arrays['state_offsets']) - 1:,} E={E:,}")
    print(f"{'ordering':9s} {'prep':>6s} {'thr':>3s} " + " ".join(f"{'D=' + str(d):>22s}" for d in depths))
    for ordering in orderings:
        label, ordering = ordering if isinstance(ordering, tuple) else (ordering, ordering)
        sg = SearchGraph.from_arrays(arrays["state_offsets"], arrays["edge_target"], arrays["edge_swap"], ordering)
        W2 = sg.pack(W_me, W_opp)
        for nt in threads:
            row = [timed(lambda: sg.minmax_packed(W2, d, gamma_for(d), n_threads=nt), reps) for d in depths]
            print(f"{label:9s} {sg.prepare_ms:6.0f} {nt:3d} " + " ".join(f"{fmt(r):>22s}" for r in row), flush=True)
    print()


def bench_input_orders(S: int, E: int, threads: list[int], reps: int, seed: int) -> None:
    print("## B. input state order x renumbering, depth 5")
    print(f"{'input':9s} {'ordering':9s} " + " ".join(f"{'thr=' + str(t):>22s}" for t in threads))
    rng = np.random.default_rng(1)
    for order in ("natural", "group", "shuffled"):
        g = synthetic_graph(S, E / S, seed, state_order=order, features=False)
        n_e = int(g["state_offsets"][-1])
        W_me, W_opp = rng.normal(size=n_e), rng.normal(size=n_e)
        for ordering in ("none", "bfs", "rcm"):
            sg = SearchGraph.from_arrays(g["state_offsets"], g["edge_target"], g["edge_swap"], ordering)
            W2 = sg.pack(W_me, W_opp)
            row = [timed(lambda: sg.minmax_packed(W2, 5, n_threads=t), reps) for t in threads]
            print(f"{order:9s} {ordering:9s} " + " ".join(f"{fmt(r):>22s}" for r in row), flush=True)
    print()


def bench_naive(arrays: dict, threads: list[int], reps: int) -> None:
    print("## C. naive parallel kernel (float64, (2,S) tables, swap branch), input order, depth 5")
    rng = np.random.default_rng(0)
    E = int(arrays["state_offsets"][-1])
    W_me, W_opp = rng.normal(size=E), rng.normal(size=E)
    off, tgt, swap = arrays["state_offsets"], arrays["edge_target"], arrays["edge_swap"]
    prev = nb.get_num_threads()
    for t in threads:
        nb.set_num_threads(t)
        print(f"naive thr={t}: {fmt(timed(lambda: naive_minmax(off, tgt, swap, W_me, W_opp, 5, 1.0), reps))}",
              flush=True)
    nb.set_num_threads(prev)
    print()


def bench_sizes(E_per_S: float, threads: list[int], reps: int, seed: int, scales: list[float]) -> None:
    print("## D. depth 5 against graph size (input order 'group', bfs renumbering)")
    print(f"{'states':>9s} {'edges':>11s} " + " ".join(f"{'thr=' + str(t):>22s}" for t in threads))
    rng = np.random.default_rng(2)
    for sc in scales:
        S = int(PAPER_S * sc)
        g = synthetic_graph(S, E_per_S, seed, state_order="group", features=False)
        n_e = int(g["state_offsets"][-1])
        sg = SearchGraph.from_arrays(g["state_offsets"], g["edge_target"], g["edge_swap"], "bfs")
        W2 = sg.pack(rng.normal(size=n_e), rng.normal(size=n_e))
        row = [timed(lambda: sg.minmax_packed(W2, 5, n_threads=t), reps) for t in threads]
        print(f"{S:9,d} {n_e:11,d} " + " ".join(f"{fmt(r):>22s}" for r in row), flush=True)
    print()


def bench_style_swap(arrays: dict, threads: list[int], reps: int, kinds: tuple[str, ...]) -> None:
    print("## E. style swap: compute_policy (rewards + pack + min-max depth 5 + unpack), prepared graph")
    sg = SearchGraph.from_arrays(arrays["state_offsets"], arrays["edge_target"], arrays["edge_swap"], "bfs")
    styles = [Style(name="a", d_p=0.7, kind_pref={"hook": 2.0}), Style(name="b", d_p=1.4, kind_pref={"jab": 2.0})]
    for t in threads:
        last: dict = {}
        i = [0]

        def run() -> None:
            pol = compute_policy(arrays, styles[i[0] % 2], 5, 1.0, kinds_table=kinds, search_graph=sg, n_threads=t)
            i[0] += 1
            last.update(pol.timings_ms, total=pol.compute_ms)

        tt = timed(run, reps)
        parts = ", ".join(f"{k} {v:.1f}" for k, v in last.items() if k != "total")
        print(f"thr={t}: total {fmt(tt)}   last run: {parts}", flush=True)
    print()


def load_graph(path: str) -> dict:
    with np.load(path, allow_pickle=False) as z:
        g = {k: z[k] for k in z.files}
    for k in ("state_offsets", "edge_target", "edge_swap"):
        if k not in g:
            raise SystemExit(f"{path}: missing array {k!r} (docs/contracts.md)")
    return g


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--graph", help="a real graph: .npz / .igz (uncompressed npz) with the contract arrays")
    ap.add_argument("--states", type=int, default=PAPER_S)
    ap.add_argument("--edges", type=int, default=PAPER_E)
    ap.add_argument("--depths", type=int, nargs="+", default=[1, 3, 5, 10])
    ap.add_argument("--threads", type=int, nargs="+", default=sorted({1, nb.config.NUMBA_NUM_THREADS}))
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="sections A and E only")
    ap.add_argument("--graph-only", action="store_true", help="only section G (needs --graph)")
    ap.add_argument("--no-passive", action="store_true", help="leave OMP_WAIT_POLICY unset")
    a = ap.parse_args(argv)
    header()
    S, E = a.states, a.edges
    if a.graph_only:
        a.quick = True
    g = synthetic_graph(S, E / S, a.seed, state_order="group") if not a.graph_only else {}
    if not a.graph_only:
        bench_depths("A. synthetic IG-like graph, input order 'group' (per-group k-means output)", g,
                     ["none", "bfs", "rcm"], a.threads, a.depths, a.reps)
    if not a.quick:
        bench_input_orders(S, E, a.threads, a.reps, a.seed)
        bench_naive(g, a.threads, a.reps)
        bench_sizes(E / S, a.threads, a.reps, a.seed, [0.25, 0.5, 1.0, 2.0])
    if not a.graph_only:
        bench_style_swap(g, a.threads, a.reps, KINDS)
    if not a.quick:
        r = synthetic_graph(S, E / S, a.seed, locality=False, state_order="shuffled", features=False)
        bench_depths("F. no locality (uniform random targets)", r, ["none", "bfs"], a.threads, [5], a.reps)
    if a.graph:
        rg = load_graph(a.graph)
        orderings: list = ["none", "bfs", "rcm"]
        keys = ("state_m_other", "state_nextset", "state_f_other", "state_r", "state_theta_self")
        if all(k in rg for k in keys):  # the builder's state arrays: sort by group, then continuous state
            orderings.append(("sorted", np.lexsort(tuple(rg[k] for k in reversed(keys)))))
        bench_depths(f"G. real graph {a.graph}", rg, orderings, a.threads, a.depths, a.reps)
        if "feat_r" in rg:
            kinds = tuple(str(k) for k in rg["kinds_table"]) if "kinds_table" in rg else KINDS
            bench_style_swap(rg, a.threads, a.reps, kinds)


if __name__ == "__main__":
    main()
