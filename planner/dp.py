"""Dynamic programming (value iteration with discount) for cooperative rewards (paper section 6.3).

Both fighters maximise one common reward. With the two-perspective graph (docs/contracts.md),
the reward may depend on who decides (e.g. a travel direction in the decider's pair frame, see
:func:`planner.rewards.cooperative_rewards`), so there are two value tables:

    V_a(s) = max_e W_a[e] + gamma * (V_b if swap[e] else V_a)(t_e)     (fighter A decides at s)
    V_b(s) = max_e W_b[e] + gamma * (V_a if swap[e] else V_b)(t_e)     (fighter B decides at s)

:func:`value_iteration` is the one-table case V(s) = max_e W[e] + gamma*V(t_e). Dead ends are
terminal with value ``dead_end_value`` (default 0). Jacobi sweeps from V = 0; iteration stops
when the bound on the distance to the fixed point, gamma/(1-gamma) * max|V_k+1 - V_k|, is below
``tol`` (same units as the rewards), or after ``max_iter`` sweeps.
"""
from __future__ import annotations

import numba as nb
import numpy as np

from planner.minmax import balanced_chunks, pack_keys, pack_weights


@nb.njit(parallel=True, cache=True)
def dp_packed(state_offsets: np.ndarray, key: np.ndarray, W2: np.ndarray, gamma: float, tol: float,
              max_iter: int, chunks: np.ndarray, dead_end_value: float
              ) -> tuple[np.ndarray, np.ndarray, int, float]:
    """Two-table value iteration on the packed layout (see planner.minmax).

    Args:
        state_offsets: (S+1,) int64; key: (E,) int32 = 2*target + swap; W2: (2E,) float64
            interleaved [W_a, W_b]; gamma in [0, 1); tol: bound on |V - V*|; max_iter: sweeps;
            chunks: (C+1,) state ranges; dead_end_value: value of states without edges.

    Returns:
        V2 (2S,) interleaved [V_a, V_b], best2 (2S,) int32 (packed edge index, -1 at dead ends),
        number of sweeps, error bound reached.
    """
    n = state_offsets.shape[0] - 1
    n_chunks = chunks.shape[0] - 1
    V = np.zeros(2 * n, dtype=W2.dtype)
    Vn = np.zeros(2 * n, dtype=W2.dtype)
    res = np.zeros(n_chunks, dtype=np.float64)
    g = W2.dtype.type(gamma)
    factor = gamma / (1.0 - gamma) if gamma > 0.0 else 0.0
    err = np.inf
    it = 0
    while it < max_iter:
        for c in nb.prange(n_chunks):
            r = 0.0
            for s in range(chunks[c], chunks[c + 1]):
                lo = state_offsets[s]
                hi = state_offsets[s + 1]
                if lo == hi:
                    va = dead_end_value
                    vb = dead_end_value
                else:
                    k = key[lo]
                    va = W2[2 * lo] + g * V[k]
                    vb = W2[2 * lo + 1] + g * V[k ^ 1]
                    for e in range(lo + 1, hi):
                        k = key[e]
                        a = W2[2 * e] + g * V[k]
                        b = W2[2 * e + 1] + g * V[k ^ 1]
                        va = va if va >= a else a
                        vb = vb if vb >= b else b
                da = abs(va - V[2 * s])
                db = abs(vb - V[2 * s + 1])
                r = max(r, max(da, db))
                Vn[2 * s] = va
                Vn[2 * s + 1] = vb
            res[c] = r
        V, Vn = Vn, V
        it += 1
        err = factor * res.max()
        if err < tol:
            break
    best = np.full(2 * n, -1, dtype=np.int32)
    for c in nb.prange(n_chunks):
        for s in range(chunks[c], chunks[c + 1]):
            lo = state_offsets[s]
            hi = state_offsets[s + 1]
            if lo == hi:
                continue
            k = key[lo]
            ba = W2[2 * lo] + g * V[k]
            bb = W2[2 * lo + 1] + g * V[k ^ 1]
            ia = lo
            ib = lo
            for e in range(lo + 1, hi):
                k = key[e]
                a = W2[2 * e] + g * V[k]
                b = W2[2 * e + 1] + g * V[k ^ 1]
                if a > ba:
                    ba = a
                    ia = e
                if b > bb:
                    bb = b
                    ib = e
            best[2 * s] = ia
            best[2 * s + 1] = ib
    return V, best, it, err


def check_dp_args(gamma: float, tol: float, max_iter: int) -> None:
    if not 0.0 <= gamma < 1.0:
        raise ValueError(f"gamma must be in [0, 1) for value iteration, got {gamma!r}")
    if not tol > 0:
        raise ValueError(f"tol must be > 0, got {tol!r}")
    if max_iter < 1:
        raise ValueError(f"max_iter must be >= 1, got {max_iter!r}")


def value_iteration_pair(state_offsets: np.ndarray, edge_target: np.ndarray, edge_swap: np.ndarray,
                         W_a: np.ndarray, W_b: np.ndarray, gamma: float = 0.95, tol: float = 1e-6,
                         max_iter: int = 10_000, dead_end_value: float = 0.0,
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, float]:
    """Two-table value iteration (module docstring) on plain contract arrays, float64.

    Returns:
        V_a, V_b (S,) float64; best_a, best_b (S,) int64 edge ids (-1 at dead ends); sweeps done;
        error bound on |V - V*| reached (> tol when max_iter stopped it).
    """
    check_dp_args(gamma, tol, max_iter)
    offsets = np.ascontiguousarray(state_offsets, dtype=np.int64)
    E = int(offsets[-1])
    key = pack_keys(np.ascontiguousarray(edge_target), np.ascontiguousarray(edge_swap))
    W2 = np.empty(2 * E, dtype=np.float64)
    pack_weights(np.ascontiguousarray(W_a), np.ascontiguousarray(W_b), np.arange(E, dtype=np.int64), W2)
    chunks = balanced_chunks(offsets, nb.get_num_threads())
    V2, best2, it, err = dp_packed(offsets, key, W2, float(gamma), float(tol), int(max_iter), chunks,
                                   float(dead_end_value))
    return (V2[0::2].copy(), V2[1::2].copy(), best2[0::2].astype(np.int64), best2[1::2].astype(np.int64),
            int(it), float(err))


def value_iteration(state_offsets: np.ndarray, edge_target: np.ndarray, W: np.ndarray,
                    gamma: float = 0.95, tol: float = 1e-6, max_iter: int = 10_000,
                    dead_end_value: float = 0.0) -> tuple[np.ndarray, np.ndarray, int, float]:
    """One-table value iteration V(s) = max_e W[e] + gamma*V(t_e), float64.

    Returns:
        V (S,) float64, best (S,) int64 edge ids (-1 at dead ends), sweeps done, error bound.
    """
    swap = np.zeros(np.asarray(edge_target).shape[0], dtype=np.uint8)
    V, _, best, _, it, err = value_iteration_pair(state_offsets, edge_target, swap, W, W, gamma, tol,
                                                  max_iter, dead_end_value)
    return V, best, it, err
