"""Roulette ("Russian roulette") selection among a state's edges (paper section 8, after Lee & Lee 2004).

Scores Q[e] = W[e] + gamma * V_next(t_e), oriented so that higher is better for the chooser
(the opponent, which minimises, gets -Q). Probabilities:

- ``"softmax"``: p_e ∝ exp((Q_e - max Q) / temperature)              (temperature > 0, reward units)
- ``"linear"``:  p_e ∝ Q_e - min Q + temperature                      (score-proportional after
  shifting; temperature >= 0 is the weight of the worst edge, larger = more uniform)

times an optional usage penalty 1 / (1 + penalty * usage_e), usage_e = how often edge e was
already chosen (the caller keeps the counts). Deterministic given the numpy Generator / seed.
"""
from __future__ import annotations

import numba as nb
import numpy as np

MODES: dict[str, int] = {"softmax": 0, "linear": 1}


@nb.njit(cache=True)
def roulette_probabilities_kernel(scores: np.ndarray, temperature: float, mode: int, usage: np.ndarray,
                                  penalty: float) -> np.ndarray:
    """(k,) float64 probabilities (see module docstring); usage (k,) or (0,) for none."""
    k = scores.shape[0]
    p = np.empty(k, dtype=np.float64)
    if k == 0:
        return p
    if mode == 0:
        m = scores.max()
        for i in range(k):
            p[i] = np.exp((scores[i] - m) / temperature)
    else:
        m = scores.min()
        for i in range(k):
            p[i] = scores[i] - m + temperature
    if usage.shape[0] == k and penalty > 0.0:
        for i in range(k):
            p[i] /= 1.0 + penalty * usage[i]
    tot = p.sum()
    if not tot > 0.0:
        p[:] = 1.0 / k
    else:
        p /= tot
    return p


@nb.njit(cache=True)
def roulette_pick(probs: np.ndarray, u: float) -> int:
    """Index i with cumulative probability first exceeding u in [0, 1)."""
    c = 0.0
    k = probs.shape[0]
    for i in range(k):
        c += probs[i]
        if u < c:
            return i
    for i in range(k - 1, -1, -1):  # rounding: the last edge with non-zero probability
        if probs[i] > 0.0:
            return i
    return k - 1


@nb.njit(cache=True)
def edge_scores_local(lo: int, hi: int, edge_target: np.ndarray, edge_swap: np.ndarray, w: np.ndarray,
                      V_me_next: np.ndarray, V_opp_next: np.ndarray, gamma: float, side: int) -> np.ndarray:
    """Chooser-oriented scores of edges [lo, hi) whose rewards are w (hi - lo,) (see edge_scores)."""
    q = np.empty(hi - lo, dtype=np.float64)
    for e in range(lo, hi):
        t = edge_target[e]
        nxt_me = (edge_swap[e] != 0) == (side != 0)
        v = V_me_next[t] if nxt_me else V_opp_next[t]
        x = w[e - lo] + gamma * v
        q[e - lo] = x if side == 0 else -x
    return q


def _mode(mode: str) -> int:
    if mode not in MODES:
        raise ValueError(f"mode must be one of {tuple(MODES)}, got {mode!r}")
    return MODES[mode]


def edge_scores(state: int, state_offsets: np.ndarray, edge_target: np.ndarray, edge_swap: np.ndarray,
                W: np.ndarray, V_me_next: np.ndarray, V_opp_next: np.ndarray, gamma: float = 1.0,
                side: int = 0) -> np.ndarray:
    """Scores of ``state``'s edges for the fighter deciding there, higher = better for it.

    Args:
        side: 0 when the controlled fighter decides (W = W_me, Q = W + gamma*V_next), 1 when its
            opponent does (W = W_opp, the score is -Q since the opponent minimises).
        V_me_next, V_opp_next: values one depth shallower than the search (Policy.V_me_next ...).

    Returns:
        (k,) float64, in the order of the state's edges state_offsets[state]..state_offsets[state+1].
    """
    lo, hi = int(state_offsets[state]), int(state_offsets[state + 1])
    return edge_scores_local(lo, hi, edge_target, edge_swap, np.ascontiguousarray(W[lo:hi]), V_me_next, V_opp_next,
                             float(gamma), int(side))


def roulette_probabilities(scores: np.ndarray, temperature: float = 1.0, mode: str = "softmax",
                           usage: np.ndarray | None = None, penalty: float = 0.0) -> np.ndarray:
    """Selection probabilities of ``scores`` (module docstring); ``usage`` (k,) counts."""
    if mode == "softmax" and not temperature > 0:
        raise ValueError(f"softmax temperature must be > 0, got {temperature!r}")
    if mode == "linear" and not temperature >= 0:
        raise ValueError(f"linear temperature must be >= 0, got {temperature!r}")
    if penalty < 0:
        raise ValueError(f"penalty must be >= 0, got {penalty!r}")
    s = np.ascontiguousarray(scores, dtype=np.float64)
    u = np.zeros(0) if usage is None else np.ascontiguousarray(usage, dtype=np.float64)
    if usage is not None and u.shape != s.shape:
        raise ValueError(f"usage must have shape {s.shape}, got {u.shape}")
    return roulette_probabilities_kernel(s, float(temperature), _mode(mode), u, float(penalty))


def roulette_select(scores: np.ndarray, rng: np.random.Generator | int, temperature: float = 1.0,
                    mode: str = "softmax", usage: np.ndarray | None = None, penalty: float = 0.0) -> int:
    """Draw one index into ``scores`` (one ``rng.random()`` per call); -1 when empty."""
    if len(scores) == 0:
        return -1
    g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
    p = roulette_probabilities(scores, temperature, mode, usage, penalty)
    return int(roulette_pick(p, float(g.random())))


def select_edge(state: int, state_offsets: np.ndarray, edge_target: np.ndarray, edge_swap: np.ndarray,
                W: np.ndarray, V_me_next: np.ndarray, V_opp_next: np.ndarray,
                rng: np.random.Generator | int, *, gamma: float = 1.0, side: int = 0,
                temperature: float = 1.0, mode: str = "softmax", usage: np.ndarray | None = None,
                penalty: float = 0.0) -> int:
    """Roulette choice of an edge at ``state`` (global edge id, -1 at a dead end).

    ``usage`` is an (E,) count array over all edges (the caller increments usage[e] after using
    e); only the state's slice is read.
    """
    lo, hi = int(state_offsets[state]), int(state_offsets[state + 1])
    if lo == hi:
        return -1
    q = edge_scores(state, state_offsets, edge_target, edge_swap, W, V_me_next, V_opp_next, gamma, side)
    u = None if usage is None else np.asarray(usage)[lo:hi]
    return lo + roulette_select(q, rng, temperature, mode, u, penalty)
