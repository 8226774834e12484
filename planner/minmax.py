"""Depth-limited min-max on the Interaction Graph (paper Algorithm 1), two-perspective form.

Recursion (docs/contracts.md), for depth d = 1..D, with V(., 0) = 0:

    V_me(s, d)  = max_e  W_me[e]  + gamma * (V_opp if swap[e] else V_me)(t_e, d-1)
    V_opp(s, d) = min_e  W_opp[e] + gamma * (V_me if swap[e] else V_opp)(t_e, d-1)

V_me(s, d) is the controlled fighter's return when it decides at s, V_opp(s, d) when its
opponent does. Dead ends (states without edges) get ``dead_end_value`` (default 0) at every
depth: the search horizon simply ends there, neither good nor bad. Ties go to the first edge in
the kernel's edge order (a SearchGraph sorts each state's edges by target).

The kernel works on a *packed* layout (built once per graph by planner.SearchGraph):
``key[e] = 2*target + swap`` (int32) and ``W2[2e], W2[2e+1] = W_me[e], W_opp[e]`` (float32),
values interleaved ``V2[2s], V2[2s+1] = V_me(s), V_opp(s)``; then the value of the next state
for the maximiser is ``V2[key]`` and for the minimiser ``V2[key ^ 1]``: one cache line, no swap
branch. States are split into chunks of equal edge count, one per thread (static schedule).
Depths below D track values only (select-style max/min, no branches on the argmax); depth 1
reads no values (V = 0); depth D also records the best edges. Compiled with fastmath: rewards
must be finite.
"""
from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def pack_keys(edge_target: np.ndarray, edge_swap: np.ndarray) -> np.ndarray:
    """(E,) int32 key = 2*target + (swap != 0)."""
    n = edge_target.shape[0]
    key = np.empty(n, dtype=np.int32)
    for e in range(n):
        key[e] = 2 * edge_target[e] + (1 if edge_swap[e] != 0 else 0)
    return key


@nb.njit(cache=True)
def pack_weights(W_me: np.ndarray, W_opp: np.ndarray, edge_order: np.ndarray, out: np.ndarray) -> None:
    """out[2i], out[2i+1] = W_me[edge_order[i]], W_opp[edge_order[i]] (edge_order: new -> old edge)."""
    for i in range(edge_order.shape[0]):
        e = edge_order[i]
        out[2 * i] = W_me[e]
        out[2 * i + 1] = W_opp[e]


def balanced_chunks(state_offsets: np.ndarray, n_chunks: int, state_cost: int = 4) -> np.ndarray:
    """(C+1,) int64 state boundaries splitting the states into ``n_chunks`` ranges of about equal
    work (edges + ``state_cost`` per state)."""
    s = state_offsets.shape[0] - 1
    work = state_offsets.astype(np.int64) + state_cost * np.arange(s + 1, dtype=np.int64)
    targets = np.linspace(0, work[-1], n_chunks + 1)
    b = np.searchsorted(work, targets, side="left").astype(np.int64)
    b[0], b[-1] = 0, s
    return np.maximum.accumulate(b)


@nb.njit(inline="always", fastmath=True)
def _state_values(lo, hi, key, W2, Vp, g, gather):
    """(max_e W_me + g*V[key], min_e W_opp + g*V[key^1]) over edges [lo, hi); select-style
    max/min without index tracking (the hot loop). ``gather`` False: V = 0 (depth 1)."""
    if gather:
        k = key[lo]
        bm = W2[2 * lo] + g * Vp[k]
        bo = W2[2 * lo + 1] + g * Vp[k ^ 1]
        for e in range(lo + 1, hi):
            k = key[e]
            a = W2[2 * e] + g * Vp[k]
            b = W2[2 * e + 1] + g * Vp[k ^ 1]
            bm = bm if bm >= a else a
            bo = bo if bo <= b else b
    else:
        bm = W2[2 * lo]
        bo = W2[2 * lo + 1]
        for e in range(lo + 1, hi):
            a = W2[2 * e]
            b = W2[2 * e + 1]
            bm = bm if bm >= a else a
            bo = bo if bo <= b else b
    return bm, bo


@nb.njit(inline="always", fastmath=True)
def _state_best(lo, hi, key, W2, Vp, g, gather):
    """As _state_values, plus the first edge reaching the max / the min."""
    k = key[lo]
    bm = W2[2 * lo] + (g * Vp[k] if gather else 0.0)
    bo = W2[2 * lo + 1] + (g * Vp[k ^ 1] if gather else 0.0)
    im = lo
    io = lo
    for e in range(lo + 1, hi):
        k = key[e]
        a = W2[2 * e]
        b = W2[2 * e + 1]
        if gather:
            a += g * Vp[k]
            b += g * Vp[k ^ 1]
        if a > bm:
            bm = a
            im = e
        if b < bo:
            bo = b
            io = e
    return bm, bo, im, io


@nb.njit(parallel=True, fastmath=True, cache=True)
def minmax_packed(state_offsets: np.ndarray, key: np.ndarray, W2: np.ndarray, depth: int, gamma: float,
                  chunks: np.ndarray, dead_end_value: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Min-max kernel on the packed layout (weights must be finite: compiled with fastmath).

    Args:
        state_offsets: (S+1,) int64 CSR.
        key: (E,) int32, 2*target + swap.
        W2: (2E,) float32 or float64, interleaved [W_me, W_opp] per edge.
        depth: D >= 1.
        gamma: discount per decision.
        chunks: (C+1,) int64 state boundaries, one range per parallel task.
        dead_end_value: value of a state without edges.

    Returns:
        V2 (2S,) interleaved values at depth D, V2prev (2S,) at depth D-1, best2 (2S,) int32
        interleaved best edges (index into the packed edge order; -1 at dead ends).
    """
    n_states = state_offsets.shape[0] - 1
    Vp = np.zeros(2 * n_states, dtype=W2.dtype)
    Vc = np.zeros(2 * n_states, dtype=W2.dtype)
    best = np.full(2 * n_states, -1, dtype=np.int32)
    g = W2.dtype.type(gamma)
    dead = W2.dtype.type(dead_end_value)
    n_chunks = chunks.shape[0] - 1
    for d in range(1, depth + 1):
        gather = d > 1
        last = d == depth
        for c in nb.prange(n_chunks):
            for s in range(chunks[c], chunks[c + 1]):
                lo = state_offsets[s]
                hi = state_offsets[s + 1]
                if lo == hi:
                    Vc[2 * s] = dead
                    Vc[2 * s + 1] = dead
                elif last:
                    bm, bo, im, io = _state_best(lo, hi, key, W2, Vp, g, gather)
                    Vc[2 * s] = bm
                    Vc[2 * s + 1] = bo
                    best[2 * s] = im
                    best[2 * s + 1] = io
                else:
                    bm, bo = _state_values(lo, hi, key, W2, Vp, g, gather)
                    Vc[2 * s] = bm
                    Vc[2 * s + 1] = bo
        Vp, Vc = Vc, Vp
    return Vp, Vc, best


def minmax(state_offsets: np.ndarray, edge_target: np.ndarray, edge_swap: np.ndarray,
           W_me: np.ndarray, W_opp: np.ndarray, depth: int, gamma: float = 1.0,
           dead_end_value: float = 0.0, dtype: type = np.float32, n_chunks: int | None = None,
           ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Depth-``depth`` min-max on plain contract arrays (packs them on every call; for repeated
    searches on one graph use :class:`planner.SearchGraph`).

    Returns:
        V_me, V_opp (S,) ``dtype`` values at depth D; best_me, best_opp (S,) int64 edge indices
        (-1 at dead ends).
    """
    if depth < 1:
        raise ValueError(f"depth must be >= 1, got {depth}")
    offsets = np.ascontiguousarray(state_offsets, dtype=np.int64)
    E = offsets[-1]
    key = pack_keys(np.ascontiguousarray(edge_target), np.ascontiguousarray(edge_swap))
    W2 = np.empty(2 * E, dtype=dtype)
    pack_weights(np.ascontiguousarray(W_me), np.ascontiguousarray(W_opp), np.arange(E, dtype=np.int64), W2)
    chunks = balanced_chunks(offsets, n_chunks or nb.get_num_threads())
    V2, _, best2 = minmax_packed(offsets, key, W2, int(depth), float(gamma), chunks, float(dead_end_value))
    return V2[0::2].copy(), V2[1::2].copy(), best2[0::2].astype(np.int64), best2[1::2].astype(np.int64)
