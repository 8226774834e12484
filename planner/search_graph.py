"""A graph prepared once for fast repeated searches: states renumbered for locality, packed edges.

The kernels read, for each state, the values of its edges' targets; renumbering the states so
that the targets of consecutive states lie close together (BFS / reverse Cuthill-McKee) keeps
those reads in cache. Everything the caller sees stays in the *original* state and edge indices.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Mapping, Sequence

import numba as nb
import numpy as np

from planner.dp import check_dp_args, dp_packed
from planner.minmax import balanced_chunks, minmax_packed, pack_keys, pack_weights
from planner.rewards import fight_kernel_args, fight_rewards_packed
from planner.styles import Style

ORDERINGS: tuple[str, ...] = ("none", "bfs", "rcm")


class NumbaThreads:
    """Run with ``n`` numba threads (None: leave as is), restoring the previous count after."""

    def __init__(self, n: int | None) -> None:
        self.n = n
        self.prev = 0

    def __enter__(self) -> int:
        self.prev = nb.get_num_threads()
        if self.n is not None:
            nb.set_num_threads(max(1, min(int(self.n), nb.config.NUMBA_NUM_THREADS)))
        return nb.get_num_threads()

    def __exit__(self, *exc: object) -> None:
        nb.set_num_threads(self.prev)


@nb.njit(cache=True)
def _bfs_order(nbr_offsets: np.ndarray, nbr: np.ndarray, by_degree: bool) -> np.ndarray:
    """Visit order (new -> old) of a BFS over the neighbour CSR; roots in increasing degree order
    when ``by_degree`` (Cuthill-McKee) else in index order; neighbours in increasing degree when
    ``by_degree`` else in edge order."""
    n = nbr_offsets.shape[0] - 1
    deg = np.empty(n, dtype=np.int64)
    for s in range(n):
        deg[s] = nbr_offsets[s + 1] - nbr_offsets[s]
    roots = np.argsort(deg, kind="mergesort") if by_degree else np.arange(n)
    seen = np.zeros(n, dtype=np.bool_)
    order = np.empty(n, dtype=np.int64)
    head = 0
    tail = 0
    for r in roots:
        if seen[r]:
            continue
        seen[r] = True
        order[tail] = r
        tail += 1
        while head < tail:
            s = order[head]
            head += 1
            lo = nbr_offsets[s]
            hi = nbr_offsets[s + 1]
            start = tail
            for j in range(lo, hi):
                t = nbr[j]
                if not seen[t]:
                    seen[t] = True
                    order[tail] = t
                    tail += 1
            if by_degree and tail - start > 1:
                seg = order[start:tail].copy()
                idx = np.argsort(deg[seg], kind="mergesort")
                for i in range(seg.shape[0]):
                    order[start + i] = seg[idx[i]]
    return order


@nb.njit(cache=True)
def _symmetrise(offsets: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR of the undirected neighbour lists (out + in edges, duplicates kept)."""
    n = offsets.shape[0] - 1
    cnt = np.zeros(n + 1, dtype=np.int64)
    for s in range(n):
        cnt[s + 1] += offsets[s + 1] - offsets[s]
        for e in range(offsets[s], offsets[s + 1]):
            cnt[target[e] + 1] += 1
    for s in range(n):
        cnt[s + 1] += cnt[s]
    pos = cnt[:-1].copy()
    nbr = np.empty(cnt[-1], dtype=np.int64)
    for s in range(n):
        for e in range(offsets[s], offsets[s + 1]):
            t = target[e]
            nbr[pos[s]] = t
            pos[s] += 1
            nbr[pos[t]] = s
            pos[t] += 1
    return cnt, nbr


@nb.njit(cache=True)
def _permute_csr(offsets: np.ndarray, target: np.ndarray, swap: np.ndarray, state_order: np.ndarray,
                 rank: np.ndarray, new_offsets: np.ndarray, sort_edges: bool) -> tuple[np.ndarray, np.ndarray]:
    """Edge order (new -> old) and packed keys of the renumbered graph."""
    n = state_order.shape[0]
    E = target.shape[0]
    edge_order = np.empty(E, dtype=np.int64)
    key = np.empty(E, dtype=np.int32)
    for i in range(n):
        s = state_order[i]
        lo = offsets[s]
        m = offsets[s + 1] - lo
        base = new_offsets[i]
        k = np.empty(m, dtype=np.int32)
        for j in range(m):
            e = lo + j
            k[j] = 2 * rank[target[e]] + (1 if swap[e] != 0 else 0)
        idx = np.argsort(k, kind="mergesort") if sort_edges else np.arange(m)
        for j in range(m):
            edge_order[base + j] = lo + idx[j]
            key[base + j] = k[idx[j]]
    return edge_order, key


@nb.njit(cache=True)
def _unpack_values(V2, state_order, V_me, V_opp):
    for i in range(state_order.shape[0]):
        s = state_order[i]
        V_me[s] = V2[2 * i]
        V_opp[s] = V2[2 * i + 1]


@nb.njit(cache=True)
def _unpack_best(best2, state_order, edge_order, b_me, b_opp):
    for i in range(state_order.shape[0]):
        s = state_order[i]
        b = best2[2 * i]
        b_me[s] = edge_order[b] if b >= 0 else -1
        b = best2[2 * i + 1]
        b_opp[s] = edge_order[b] if b >= 0 else -1


@dataclass
class SearchGraph:
    """Plain-array graph prepared for the search kernels (build with :meth:`from_arrays`).

    Attributes:
        n_states, n_edges: S, E.
        ordering: the state renumbering used ("none", "bfs", "rcm").
        state_order: (S,) int64, new -> original state.
        state_rank: (S,) int64, original -> new state.
        edge_order: (E,) int64, new -> original edge.
        edge_rank: (E,) int64, original -> new edge.
        offsets: (S+1,) int64 CSR in the new numbering.
        key: (E,) int32, 2*new_target + swap in the new edge order.
        prepare_ms: time spent preparing.
    """

    n_states: int
    n_edges: int
    ordering: str
    state_order: np.ndarray
    state_rank: np.ndarray
    edge_order: np.ndarray
    edge_rank: np.ndarray
    offsets: np.ndarray
    key: np.ndarray
    prepare_ms: float = 0.0
    _chunks: dict[int, np.ndarray] = field(default_factory=dict, repr=False)

    def chunks(self, n_threads: int) -> np.ndarray:
        """(C+1,) int64 state ranges of equal work, one per thread (cached per thread count)."""
        if n_threads not in self._chunks:
            self._chunks[n_threads] = balanced_chunks(self.offsets, n_threads)
        return self._chunks[n_threads]

    @classmethod
    def from_arrays(cls, state_offsets: np.ndarray, edge_target: np.ndarray, edge_swap: np.ndarray,
                    ordering: str | np.ndarray = "bfs", sort_edges: bool = True) -> "SearchGraph":
        """Renumber the states, sort each state's edges by target (``sort_edges``) and pack the
        keys. A few hundred ms at the paper's scale: do it once per graph.

        ``ordering``: "bfs" (breadth-first over the edges from state 0 and each unvisited state in
        turn; the default, best or level with the best on the synthetic benchmarks), "rcm"
        (reverse Cuthill-McKee on the symmetrised graph), "none" (keep the given order: right
        when the builder already writes states sorted by group and continuous state), or an
        explicit (S,) permutation new -> original state.
        """
        t0 = time.perf_counter()
        explicit = not isinstance(ordering, str)
        if not explicit and ordering not in ORDERINGS:
            raise ValueError(f"ordering must be one of {ORDERINGS} or a permutation array, got {ordering!r}")
        offsets = np.ascontiguousarray(state_offsets, dtype=np.int64)
        target = np.ascontiguousarray(edge_target)
        swap = np.ascontiguousarray(edge_swap)
        n = offsets.shape[0] - 1
        E = int(offsets[-1])
        if target.shape != (E,) or swap.shape != (E,):
            raise ValueError(f"edge arrays must have shape ({E},), got {target.shape} and {swap.shape}")
        if E and (target.min() < 0 or target.max() >= n):
            raise ValueError("edge_target out of range [0, S)")
        if explicit:
            order = np.asarray(ordering, dtype=np.int64)
            if order.shape != (n,) or not np.array_equal(np.sort(order), np.arange(n)):
                raise ValueError(f"an explicit ordering must be a permutation of range({n})")
        if not explicit and ordering == "none" and not sort_edges:
            order = np.arange(n, dtype=np.int64)
            rank = order
            edge_order = np.arange(E, dtype=np.int64)
            key = pack_keys(target, swap)
            new_offsets = offsets
        else:
            if explicit:
                pass
            elif ordering == "none":
                order = np.arange(n, dtype=np.int64)
            elif ordering == "bfs":
                order = _bfs_order(offsets, target.astype(np.int64), False)
            else:
                so, nbr = _symmetrise(offsets, target.astype(np.int64))
                order = _bfs_order(so, nbr, True)[::-1].copy()
            rank = np.empty(n, dtype=np.int64)
            rank[order] = np.arange(n, dtype=np.int64)
            deg = np.diff(offsets)[order]
            new_offsets = np.zeros(n + 1, dtype=np.int64)
            np.cumsum(deg, out=new_offsets[1:])
            edge_order, key = _permute_csr(offsets, target, swap, order, rank, new_offsets, sort_edges)
        edge_rank = np.empty(E, dtype=np.int64)
        edge_rank[edge_order] = np.arange(E, dtype=np.int64)
        return cls(n, E, "explicit" if explicit else str(ordering), order, rank, edge_order, edge_rank, new_offsets, key,
                   (time.perf_counter() - t0) * 1e3)

    def pack(self, W_me: np.ndarray, W_opp: np.ndarray, dtype: type = np.float32) -> np.ndarray:
        """(2E,) interleaved weights in the packed edge order."""
        W2 = np.empty(2 * self.n_edges, dtype=dtype)
        pack_weights(np.ascontiguousarray(W_me), np.ascontiguousarray(W_opp), self.edge_order, W2)
        return W2

    def minmax_packed(self, W2: np.ndarray, depth: int, gamma: float = 1.0, dead_end_value: float = 0.0,
                      n_threads: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Run the kernel on packed weights; results in the *new* numbering (see minmax_packed).
        ``n_threads``: numba threads for this call (None: the current setting)."""
        if depth < 1:
            raise ValueError(f"depth must be >= 1, got {depth}")
        with NumbaThreads(n_threads) as nt:
            return minmax_packed(self.offsets, self.key, W2, int(depth), float(gamma), self.chunks(nt),
                                 float(dead_end_value))

    def rewards(self, features: Mapping[str, np.ndarray], style: Style, kinds_table: Sequence[str],
                dtype: type = np.float32) -> np.ndarray:
        """Eq. 4 rewards (planner.rewards.edge_rewards) written straight into the packed layout
        (2E,) ``dtype``. Raises ValueError when a reward is not finite."""
        args = fight_kernel_args(features, style, kinds_table)
        if args[0].shape[0] != self.n_edges:
            raise ValueError(f"edge features have {args[0].shape[0]} edges, the graph {self.n_edges}")
        W2 = np.empty(2 * self.n_edges, dtype=dtype)
        bad = fight_rewards_packed(self.edge_rank, *args, W2)
        if bad:
            raise ValueError(f"{bad} edge rewards are NaN/inf (check the edge features)")
        return W2

    def unpack_values(self, V2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interleaved new-order values -> (V_me, V_opp) (S,) in original state order."""
        V_me = np.empty(self.n_states, dtype=V2.dtype)
        V_opp = np.empty(self.n_states, dtype=V2.dtype)
        _unpack_values(V2, self.state_order, V_me, V_opp)
        return V_me, V_opp

    def unpack_best(self, best2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Interleaved new-order best edges -> (best_me, best_opp) (S,) int64 original edge ids."""
        b_me = np.empty(self.n_states, dtype=np.int64)
        b_opp = np.empty(self.n_states, dtype=np.int64)
        _unpack_best(best2, self.state_order, self.edge_order, b_me, b_opp)
        return b_me, b_opp

    def unpack_weights(self, W2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Packed (2E,) weights -> (W_me, W_opp) (E,) in original edge order."""
        return W2[0::2][self.edge_rank], W2[1::2][self.edge_rank]

    def minmax(self, W_me: np.ndarray, W_opp: np.ndarray, depth: int, gamma: float = 1.0,
               dead_end_value: float = 0.0, dtype: type = np.float32, n_threads: int | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Min-max with original-order inputs and outputs: (V_me, V_opp, best_me, best_opp)."""
        V2, _, best2 = self.minmax_packed(self.pack(W_me, W_opp, dtype), depth, gamma, dead_end_value, n_threads)
        return (*self.unpack_values(V2), *self.unpack_best(best2))

    def value_iteration_pair(self, W_a: np.ndarray, W_b: np.ndarray, gamma: float = 0.95, tol: float = 1e-6,
                             max_iter: int = 10_000, dead_end_value: float = 0.0, n_threads: int | None = None
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, float]:
        """planner.dp.value_iteration_pair on the prepared layout (float64); original indices."""
        check_dp_args(gamma, tol, max_iter)
        W2 = self.pack(W_a, W_b, np.float64)
        with NumbaThreads(n_threads) as nt:
            V2, best2, it, err = dp_packed(self.offsets, self.key, W2, float(gamma), float(tol), int(max_iter),
                                           self.chunks(nt), float(dead_end_value))
        return (*self.unpack_values(V2), *self.unpack_best(best2), int(it), float(err))
