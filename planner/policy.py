"""Policy tables: rewards from a style + min-max on a (prepared) graph, in one call."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from planner.search_graph import SearchGraph, NumbaThreads
from planner.select import edge_scores_local, roulette_select
from planner.styles import Style, load_style


@dataclass(eq=False)
class Policy:
    """Min-max policy table for the controlled fighter (original state / edge indices).

    Attributes:
        best_me: (S,) int64 edge the controlled fighter takes when it decides at s (-1: dead end).
        best_opp: (S,) int64 edge the opponent is expected to take when it decides at s.
        V_me, V_opp: (S,) float32 min-max values at depth ``depth`` (reward units).
        V_me_next, V_opp_next: (S,) float32 values at depth ``depth - 1`` (what the scores of
            the edges at depth ``depth`` add; zeros for depth 1).
        depth, gamma: search depth (decisions) and discount per decision.
        style: style name.
        compute_ms: wall time of this computation (rewards + search + unpacking), ms.
        timings_ms: its parts: "rewards", "search", "unpack" (and "prepare" when the search
            graph was built by this call).
        W2: (2E,) float32 rewards in the search graph's packed layout; ``W_me`` / ``W_opp``
            give them in original edge order (computed on first use).
        search_graph: the prepared graph the policy was computed on.
    """

    best_me: np.ndarray
    best_opp: np.ndarray
    V_me: np.ndarray
    V_opp: np.ndarray
    V_me_next: np.ndarray
    V_opp_next: np.ndarray
    depth: int
    gamma: float
    style: str
    compute_ms: float
    timings_ms: dict[str, float] = field(default_factory=dict)
    W2: np.ndarray | None = field(default=None, repr=False)
    search_graph: SearchGraph | None = field(default=None, repr=False)

    @cached_property
    def _weights(self) -> tuple[np.ndarray, np.ndarray]:
        if self.W2 is None or self.search_graph is None:
            raise ValueError("this Policy holds no rewards")
        return self.search_graph.unpack_weights(self.W2)

    @property
    def W_me(self) -> np.ndarray:
        """(E,) float32 W_me in original edge order."""
        return self._weights[0]

    @property
    def W_opp(self) -> np.ndarray:
        """(E,) float32 W_opp in original edge order."""
        return self._weights[1]

    def _local_weights(self, lo: int, hi: int, side: int) -> np.ndarray:
        assert self.W2 is not None and self.search_graph is not None
        return self.W2[2 * self.search_graph.edge_rank[lo:hi] + (1 if side else 0)]

    def scores(self, state: int, state_offsets: np.ndarray, edge_target: np.ndarray, edge_swap: np.ndarray,
               side: int = 0) -> np.ndarray:
        """Chooser-oriented scores of ``state``'s edges (planner.select.edge_scores); the best
        edge (best_me for side 0, best_opp for side 1) has the highest."""
        lo, hi = int(state_offsets[state]), int(state_offsets[state + 1])
        return edge_scores_local(lo, hi, edge_target, edge_swap, self._local_weights(lo, hi, side),
                                 self.V_me_next, self.V_opp_next, float(self.gamma), int(side))

    def select(self, state: int, state_offsets: np.ndarray, edge_target: np.ndarray, edge_swap: np.ndarray,
               rng: np.random.Generator | int, side: int = 0, *, temperature: float = 1.0, mode: str = "softmax",
               usage: np.ndarray | None = None, penalty: float = 0.0) -> int:
        """Roulette choice at ``state`` (planner.select): global edge id, -1 at a dead end.
        ``usage``: (E,) counts over all edges, only the state's slice is read."""
        lo, hi = int(state_offsets[state]), int(state_offsets[state + 1])
        if lo == hi:
            return -1
        q = self.scores(state, state_offsets, edge_target, edge_swap, side)
        u = None if usage is None else np.asarray(usage)[lo:hi]
        return lo + roulette_select(q, rng, temperature, mode, u, penalty)


#: Discount of the runtime controller's min-max (per decision). Values beyond the first move come
#: from clustered states whose error (measured ~2.9 reward units at depth 2 on the CMU boxing
#: graph) exceeds the spread between actions; undiscounted, deeper search made the fighter weaker
#: (mostly guard). With 0.5, strength grows with depth against the human proxy, the static boxer
#: and the depth-3 game tree (held-out seed 100, 6 bouts per cell; 0.3 and 0.7 behave alike, 1.0
#: does not): see the README's evaluation figures.
DEFAULT_GAMMA = 0.5


def compute_policy(graph_arrays: Mapping[str, np.ndarray], style: Style | str | Path, depth: int = 5,
                   gamma: float = 1.0, *, kinds_table: Sequence[str] | None = None,
                   search_graph: SearchGraph | None = None, ordering: str = "bfs",
                   dead_end_value: float = 0.0, n_threads: int | None = None) -> Policy:
    """Rewards for ``style`` (Eq. 4) and depth-``depth`` min-max (Algorithm 1) on a graph.

    Args:
        graph_arrays: the graph's plain arrays (docs/contracts.md): state_offsets, edge_target,
            edge_swap and the feat_* edge features; may hold ``kinds_table``.
        style: a Style, a preset name or a style file path.
        depth: search depth in decisions (paper: 1..5).
        gamma: discount per decision (1.0 for depth <= 5, as the paper; < 1 for deeper).
        kinds_table: kind names indexed by feat_kind (default graph_arrays["kinds_table"]).
        search_graph: the graph prepared once (SearchGraph.from_arrays); built here otherwise.
        ordering: state renumbering when building the search graph here.
        dead_end_value: value of states without edges.
        n_threads: numba threads for the search (None: numba's current setting). On a machine
            shared with other busy processes, fewer threads (and OMP_WAIT_POLICY=PASSIVE with
            the OpenMP threading layer) can be faster; see benchmarks/bench_planner.py.
    """
    t0 = time.perf_counter()
    timings: dict[str, float] = {}
    st = style if isinstance(style, Style) else load_style(style)
    if kinds_table is None:
        if "kinds_table" not in graph_arrays:
            raise KeyError("kinds_table: pass it or store it in graph_arrays['kinds_table']")
        kinds_table = [str(k) for k in graph_arrays["kinds_table"]]
    if search_graph is None:
        search_graph = SearchGraph.from_arrays(graph_arrays["state_offsets"], graph_arrays["edge_target"],
                                               graph_arrays["edge_swap"], ordering=ordering)
        timings["prepare"] = search_graph.prepare_ms
    t = time.perf_counter()
    with NumbaThreads(n_threads):
        W2 = search_graph.rewards(graph_arrays, st, kinds_table, np.float32)
    timings["rewards"] = (time.perf_counter() - t) * 1e3
    t = time.perf_counter()
    V2, V2prev, best2 = search_graph.minmax_packed(W2, depth, gamma, dead_end_value, n_threads)
    timings["search"] = (time.perf_counter() - t) * 1e3
    t = time.perf_counter()
    with NumbaThreads(n_threads):
        V_me, V_opp = search_graph.unpack_values(V2)
        if depth > 1:
            V_me_next, V_opp_next = search_graph.unpack_values(V2prev)
        else:
            V_me_next, V_opp_next = np.zeros_like(V_me), np.zeros_like(V_opp)
        best_me, best_opp = search_graph.unpack_best(best2)
    timings["unpack"] = (time.perf_counter() - t) * 1e3
    return Policy(best_me, best_opp, V_me, V_opp, V_me_next, V_opp_next, int(depth), float(gamma), st.name,
                  (time.perf_counter() - t0) * 1e3, timings, W2, search_graph)
