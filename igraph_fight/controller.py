"""NPCController: the runtime API a game calls to get an Interaction Graph fighter's next action.

    npc = NPCController.load("boxing.igz", style="outboxer", depth=5)
    d = npc.act(Observation(r=1.4, theta_self=0.1, theta_other=-0.2, m_self=12, m_other=40, f_other=7))
    d.action            # library action id to launch (always in Next(m_self))
    d.off_graph         # True when the live state is not within tolerance of a graph state
    npc.set_style("infighter")   # recomputed in a background thread, swapped in atomically

A live state (the NPC about to choose: the action it just finished, the opponent's action and
frame, distance and angles) is mapped to the nearest Interaction Graph state of its compatible
group (same Next(M_self), M_other and open strike bits, |F_other difference| < F0; the paper's
normalised distance with s_r = 0.5 m, s_theta = pi/6). Without a compatible state it falls back to
the nearest state with the same menu, then the nearest state at all, and flags ``off_graph``.
The answer is the policy's best edge there; if that action is not legal for the live menu (a
fallback state), the best-scoring legal edge, else the first legal action.

Off the graph (``offgraph="lookahead"``, the default) the controller does not trust a distant
state's table entry: it simulates every legal action once from the live state with the exact
kinematic simulator, scores each by its Eq. 4 reward plus the policy's depth-(D-1) value of the
graph state nearest to where it lands, and takes the best. This is an addition to the paper's
runtime (which only looks the table up: ``offgraph="nearest"``); it costs one simulated event per
legal action and runs only for off-graph decisions.

``first_ply="exact"`` (opt-in) runs that lookahead for *every* decision, on the graph too: the
first ply is then exact from the live state over the whole legal menu, and the graph only supplies
the depth-(D-1) values where each action lands. Measured on the default CMU boxing graph (see
tests/test_ig_consistency.py for the consistency checks): the graph's edges reproduce the
simulator exactly from each state's centroid, but a live state within the linking tolerance
(15 cm, 30 degrees, |F_other difference| < F0) of a state often has another best action than the
centroid (the exact depth-1 best agrees with the state's table answer about 30% of the time), and
a state has edges for only part of its menu. The table answer also presumes the live state is
snapped onto the state; an IGAgent snaps only after table answers (``Decision.edge >= 0``).

``first_ply="exact2"`` (opt-in) searches the first *two* plies exactly (every legal action, then
every answer of whoever decides next, the opponent minimising) and uses the graph's values only
at the leaves (agents.gametree._search_graph_leaves): a game-tree search of depth 2 with the
Interaction Graph as its evaluation function. Measured on the default CMU boxing graph with
``igraph-fight evaluate`` (infighter, 20 bouts of 60 s, seed 0): IG(5)+exact2 scores +7.2 per
bout against the exact depth-2 game tree and -0.6 (interval -2.1 to +0.9) against depth 3
(held-out seed 100, 10 bouts: +5.0 and -0.8), where IG(5)'s table answer scores -3.4 and -7.3.
benchmarks/exact2_ablation.py (10 bouts, the graph of 512 seed bouts): the same two exact plies
with zero leaf values score +1.3 and -6.6 against exact2's +6.0 and -0.1: the graph's values
carry the gain. It costs 0.4 ms (p50) to 2 ms (p99) of CPU a decision instead of microseconds
(the depth-3 game tree: 3-4 ms).

The policy table is an immutable object; ``set_style``/``set_depth`` build a new one in a worker
thread while the old one keeps answering, then replace the reference in one assignment, so a
reader sees either the old or the new table, never a mix.
"""
from __future__ import annotations

import threading
import time
import types
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from motion_graph.classify import KINDS
from planner import Policy, SearchGraph, Style, compute_policy, load_style

from .graph import InteractionGraph, load_graph
from .sim import _expand_one


#: NPCController's first_ply choices (see the module docstring)
FIRST_PLY = ("table", "exact", "exact2")


class Observation(NamedTuple):
    """The live coupled state from the NPC's side, at the instant it must choose.

    r: pelvis ground distance (m); theta_self / theta_other: angle between the NPC's (the
    opponent's) facing and the line to the other (rad); m_self: the action the NPC just finished;
    m_other, f_other: the opponent's action and frame; mask_other: bits of the opponent's strikes
    already resolved whose window is still open (0 if unknown).
    """

    r: float
    theta_self: float
    theta_other: float
    m_self: int
    m_other: int
    f_other: int
    mask_other: int = 0


class Decision(NamedTuple):
    """The controller's answer: action to launch, the graph state used, its normalised distance
    to the live state, whether the live state is off the graph, and the chosen edge (-1 if none)."""

    action: int
    state: int
    distance: float
    off_graph: bool
    edge: int


@dataclass(frozen=True)
class _Table:
    """An immutable policy snapshot: what act() reads."""

    policy: Policy
    best_ea: np.ndarray      # (S, 2) int64: best edge (-1: none) and its action
    q_me: np.ndarray         # (E,) float32 edge score for the controlled fighter deciding
    style: str
    depth: int
    version: int
    style_obj: Style
    la: tuple = ()           # what the off-graph lookahead kernel reads (values, kind preferences, weights)
    style_params: np.ndarray | None = None  # the style as the game-tree kernels read it (exact2)


# ----- nearest-state index -------------------------------------------------------------------
# The index (built by _build_index), with key = (Next-set id * (A+1) + M_other) * mask_mod + mask
# and kidx the rank of the key among the sorted ``ukeys``:
#   level 0 (the compatible group): a state with frame F_other is copied into the slots
#     (kidx, F) of every frame F with |F - F_other| < f0 (slot kidx * fw + F + f0 - 1), so a query
#     reads one slot (states of frames that are not compatible are skipped by the scan); a slot
#     is split into _NB2 angle bins (theta_self x theta_other); ``rowsw`` (rows, 4) float64 =
#     (r, theta_self, theta_other, F_other * 2^32 + state id) sorted by (slot, bin, r) (two rows
#     per cache line); ``ctabw[slot * _NB2 + bin, c]`` is the bin's first row with r >= c * cell_w
#     (c = 0..ncell-1) and ``ctabw[., ncell]`` its end: one table read and a short walk find the
#     query's place instead of a binary search (this machine's memory is slow: a cache miss
#     costs ~0.4 us, a binary search ~10 of them). The query's own bin is read first, then only
#     the bins whose angle distance alone can still beat the best so far;
#   level 1 (same key, any frame): ``rowsk`` / ``ctabk`` likewise with one slot per key;
#   level 2 (same Next-set): SoA rows sorted by (Next-set id, angle bin, r), bucket starts ``bst2``
#     (per Next-set id of ``nkeys``, _NB2 bins of (theta_self, theta_other));
#   level 3 (anywhere): SoA rows sorted by (angle bin, r), bucket starts ``bst3``; the query's own
#     bin is read first, then only the bins whose angle distance alone can still beat the best.
# ``xf`` (6, S) float64 = (r, theta_self, theta_other) in the level-2 order, then the level-3
# order; ``xi`` (3, S) int64 = their state ids and each state's position in key order;
# ``strt`` (S, 3) = (r, theta_self, theta_other) by state id (the tolerance test).
# Nearest = smallest squared normalised distance dr^2/s_r^2 + (dts^2 + dto^2)/s_theta^2 (angle
# differences wrapped). Rows are visited outwards from the query's r in order of |dr| and the
# walk stops when dr^2/s_r^2 alone exceeds the best so far: the result is the exact minimum.
# Ties go to the smaller state id (levels 0-2) or the earlier in key order (level 3), i.e. what
# a linear scan of the states in key order finds.

@njit(cache=True, inline="always")
def _wrap(a):
    return a - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))


@njit(cache=True)
def _scan_rows(rows, lo, hi, p, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi, lbt):
    """Nearest among rows[lo:hi] (sorted by r; p = about the first row with r >= the query's r)
    whose F_other lies in [flo, fhi]; rows = (r, theta_self, theta_other, F_other * 2^32 + id);
    ``lbt`` a lower bound of the rows' angle term (their angle bin's distance)."""
    while p > lo and rows[p - 1, 0] >= r:
        p -= 1
    while p < hi and rows[p, 0] < r:
        p += 1
    dn = p - 1
    up = p
    while dn >= lo or up < hi:
        if up >= hi or (dn >= lo and r - rows[dn, 0] <= rows[up, 0] - r):
            k = dn
            dn -= 1
        else:
            k = up
            up += 1
        dr = rows[k, 0] - r
        d0 = dr * dr * inv_sr2
        if d0 + lbt > bd:
            break  # every row left is at least this far
        tag = np.int64(rows[k, 3])
        f = tag >> 32
        if f < flo or f > fhi:
            continue
        d1 = _wrap(rows[k, 1] - ts)
        d2 = _wrap(rows[k, 2] - to)
        d = d0 + (d1 * d1 + d2 * d2) * inv_st2
        s = tag & 0xFFFFFFFF
        if d < bd or (d == bd and s < best):
            bd = d
            best = s
    return best, bd


@njit(cache=True)
def _scan_soa(st, sr, sts, sto, rank, use_rank, lo, hi, r, ts, to, inv_sr2, inv_st2, best, bd, bt, lbt):
    """Nearest among SoA rows [lo, hi) sorted by r (levels 2 and 3); ties to the smaller tie value
    (the state id, or ``rank[state]`` with ``use_rank``). ``lbt``: a lower bound of the angle
    term of every row (their angle bin's distance). Returns (state, distance, tie value)."""
    a = lo
    b = hi
    while a < b:
        m = (a + b) >> 1
        if sr[m] < r:
            a = m + 1
        else:
            b = m
    dn = a - 1
    up = a
    while dn >= lo or up < hi:
        if up >= hi or (dn >= lo and r - sr[dn] <= sr[up] - r):
            k = dn
            dn -= 1
        else:
            k = up
            up += 1
        dr = sr[k] - r
        d0 = dr * dr * inv_sr2
        if d0 + lbt > bd:
            break
        d1 = _wrap(sts[k] - ts)
        d2 = _wrap(sto[k] - to)
        d = d0 + (d1 * d1 + d2 * d2) * inv_st2
        s = st[k]
        t = rank[s] if use_rank else s
        if d < bd or (d == bd and t < bt):
            bd = d
            best = s
            bt = t
    return best, bd, bt


#: Angle bins of the level-2/3 rows: (theta_self, theta_other) in _NBA x _NBA bins of 2 pi / _NBA.
_NBA = 8
_NB2 = _NBA * _NBA


@njit(cache=True, inline="always")
def _angle_bin(a):
    w = 2.0 * np.pi / _NBA
    b = int(np.floor((a + np.pi - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))) / w))
    return min(max(b, 0), _NBA - 1)


@njit(cache=True, inline="always")
def _bin_gap(a, b):
    """Lower bound of |wrapped difference| between angle a and any angle of bin b (rad)."""
    w = 2.0 * np.pi / _NBA
    lo = b * w - np.pi
    d = _wrap(a - lo)
    if 0.0 <= d < w:
        return 0.0
    g = min(abs(d), abs(_wrap(a - lo - w)))
    return max(g - 1e-9, 0.0)


@njit(cache=True)
def _scan_bins(st, sr, sts, sto, rank, use_rank, bst, base, r, ts, to, inv_sr2, inv_st2, best, bd, bt):
    """Nearest among the rows of the _NB2 angle bins bst[base:base + _NB2 + 1] (each sorted by
    r): the query's own bin first, then every bin whose angle distance alone does not exceed
    the best so far."""
    qs = _angle_bin(ts)
    qo = _angle_bin(to)
    own = qs * _NBA + qo
    best, bd, bt = _scan_soa(st, sr, sts, sto, rank, use_rank, bst[base + own], bst[base + own + 1], r, ts, to,
                             inv_sr2, inv_st2, best, bd, bt, 0.0)
    for bs in range(_NBA):
        gs = _bin_gap(ts, bs)
        gs2 = gs * gs * inv_st2
        if gs2 > bd:
            continue
        for bo in range(_NBA):
            b = bs * _NBA + bo
            if b == own or bst[base + b] == bst[base + b + 1]:
                continue
            go = _bin_gap(to, bo)
            lbt = gs2 + go * go * inv_st2
            if lbt > bd:
                continue
            best, bd, bt = _scan_soa(st, sr, sts, sto, rank, use_rank, bst[base + b], bst[base + b + 1], r, ts, to,
                                     inv_sr2, inv_st2, best, bd, bt, lbt)
    return best, bd, bt


@njit(cache=True, inline="always")
def _lower(a, x, lo, hi):
    """First index in [lo, hi) of sorted ``a`` with a[i] >= x."""
    while lo < hi:
        m = (lo + hi) >> 1
        if a[m] < x:
            lo = m + 1
        else:
            hi = m
    return lo


@njit(cache=True, inline="always")
def _cell_scan(rows, ctab, slot, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi, lbt):
    lo = ctab[slot, 0]
    hi = ctab[slot, ncell]
    if lo == hi:
        return best, bd
    c = int(r / cell_w) if r > 0.0 else 0
    if c >= ncell:
        p = hi
    else:
        p = ctab[slot, c]
        e = ctab[slot, c + 1]
        while p < e and rows[p, 0] < r:
            p += 1
    return _scan_rows(rows, lo, hi, p, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi, lbt)


@njit(cache=True)
def _slot_scan(rows, ctab, slot, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi):
    """Nearest in a slot's _NB2 angle bins (ctab rows slot * _NB2 + bin): the query's own bin
    first, then only the bins whose angle distance alone can still beat the best."""
    qs = _angle_bin(ts)
    qo = _angle_bin(to)
    base = slot * _NB2
    own = qs * _NBA + qo
    best, bd = _cell_scan(rows, ctab, base + own, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi,
                          0.0)
    for bs in range(_NBA):
        gs = _bin_gap(ts, bs)
        gs2 = gs * gs * inv_st2
        if gs2 > bd:
            continue
        for bo in range(_NBA):
            b = bs * _NBA + bo
            if b == own:
                continue
            go = _bin_gap(to, bo)
            lbt = gs2 + go * go * inv_st2
            if lbt > bd or ctab[base + b, 0] == ctab[base + b, ncell]:
                continue
            best, bd = _cell_scan(rows, ctab, base + b, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi,
                                  lbt)
    return best, bd


@njit(cache=True)
def _nearest(rowsw, ctabw, rowsk, ctabk, ukeys, nblock, ncell, cell_w, xf, xi, nkeys, bst2, bst3, key, nextset,
             f_other, f0, r, ts, to, inv_sr2, inv_st2):
    """Nearest state: compatible group first (same key, |F_other difference| < f0), then same
    key any frame, same menu, anywhere (see the index notes above). Returns (state, squared
    normalised distance, level 0..3); (-1, inf, 4) for an empty graph."""
    best = -1
    bd = np.inf
    kidx = _lower(ukeys, key, 0, ukeys.shape[0])
    if kidx < ukeys.shape[0] and ukeys[kidx] == key:
        # level 0: the compatible group, one r-sorted slot per (key, F_other)
        q = (f_other + f0 - 1) // f0
        if f_other + f0 - 1 >= 0 and q < nblock:
            best, bd = _slot_scan(rowsw, ctabw, kidx * nblock + q, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best,
                                  bd, f_other - f0 + 1, f_other + f0 - 1)
        if best >= 0:
            return best, bd, 0
        # level 1: every frame of the key
        best, bd = _slot_scan(rowsk, ctabk, kidx, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd,
                              -(np.int64(1) << 40), np.int64(1) << 40)
        if best >= 0:
            return best, bd, 1
    # level 2: same Next-set
    bt = np.int64(1) << 62
    j = _lower(nkeys, nextset, 0, nkeys.shape[0])
    if j < nkeys.shape[0] and nkeys[j] == nextset:
        best, bd, bt = _scan_bins(xi[0], xf[0], xf[1], xf[2], xi[2], False, bst2, j * _NB2, r, ts, to, inv_sr2,
                                  inv_st2, best, bd, bt)
    if best >= 0:
        return best, bd, 2
    # level 3: anywhere
    best, bd, bt = _scan_bins(xi[1], xf[3], xf[4], xf[5], xi[2], True, bst3, 0, r, ts, to, inv_sr2, inv_st2, best,
                              bd, bt)
    if best >= 0:
        return best, bd, 3
    return -1, np.inf, 4


@njit(cache=True)
def _choose(s, best_ea, q_me, offsets, edge_action, legal_row):
    """Best edge of s if its action is legal, else the best-scoring legal edge; (-1, -1) if none.
    best_ea (S, 2) = (best edge, its action) per state: one cache line for the usual answer."""
    if s < 0:
        return -1, -1
    e = best_ea[s, 0]
    if e >= 0 and legal_row[best_ea[s, 1]]:
        return e, best_ea[s, 1]
    be = -1
    bq = -np.inf
    for k in range(offsets[s], offsets[s + 1]):
        if legal_row[edge_action[k]] and q_me[k] > bq:
            bq = q_me[k]
            be = k
    if be >= 0:
        return be, edge_action[be]
    return -1, -1


# The kernels take the controller's static arrays as three flat arrays (numba's dispatch costs
# about 0.1 us per array argument, a sizeable part of a table decision): ``pi`` int64 = a header
# of part offsets, then the parts named in _INT_PARTS; ``pf`` float64 = (inv_sr2, inv_st2,
# tol_r, tol_theta, cell_w), then rowsw, rowsk, xf, strt flattened; ``pc`` = ctabw, ctabk
# flattened. _views rebuilds the index arrays from them (reshapes of slices: no copy).
_INT_PARTS = ("ukeys", "nkeys", "bst2", "nextset_of", "key_args", "menu_off", "menu_ids", "offsets",
              "edge_action", "kinds", "scalars", "bst3", "xi", "legal", "dims")
# scalars = (f0, number of frame blocks, ncell); legal = (A, A) flattened; dims = (rows of rowsw,
# rows of rowsk, S, slots of ctabw, slots of ctabk, ncell + 1, A, then the pf offsets of rowsw,
# rowsk, xf, strt)
_P_SCALARS, _P_BST3, _P_XI, _P_LEGAL, _P_DIMS = 10, 11, 12, 13, 14


def _pack_ints(parts: dict) -> np.ndarray:
    arrs = [np.asarray(parts[k], dtype=np.int64).ravel() for k in _INT_PARTS]
    head = len(arrs) + 1
    off = head + np.concatenate([[0], np.cumsum([len(x) for x in arrs])])
    return np.ascontiguousarray(np.concatenate([off.astype(np.int64), *arrs]), dtype=np.int64)


def _pack_index(ix: tuple, ix_parts: dict, scalars: list, other_ints: dict, legal: np.ndarray,
                pf_head: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pi, pf, pc) of the notes above from _build_index's output and the controller's tables."""
    rowsw, ctabw, rowsk, ctabk, xf, xi, strt = ix
    fparts = [np.asarray(pf_head, dtype=np.float64), rowsw.ravel(), rowsk.ravel(), xf.ravel(), strt.ravel()]
    foff = np.cumsum([0] + [len(x) for x in fparts])[1:-1]
    dims = [len(rowsw), len(rowsk), strt.shape[0], ctabw.shape[0], ctabk.shape[0], ctabw.shape[1],
            legal.shape[0], *foff]
    pi = _pack_ints(dict(ix_parts, **other_ints, scalars=scalars, xi=xi, legal=legal.astype(np.int64), dims=dims))
    pf = np.ascontiguousarray(np.concatenate(fparts), dtype=np.float64)
    ct = np.int32 if ctabw.dtype == np.int32 and ctabk.dtype == np.int32 else np.int64
    pc = np.ascontiguousarray(np.concatenate([ctabw.ravel(), ctabk.ravel()]), dtype=ct)
    return pi, pf, pc


@njit(cache=True, inline="always")
def _part(pi, i):
    return pi[pi[i]:pi[i + 1]]


@njit(cache=True, inline="always")
def _views(pi, pf, pc):
    """(rowsw, ctabw, rowsk, ctabk, xf, xi, strt) as views of the packed arrays."""
    d = _part(pi, _P_DIMS)
    nw, nk, S, sw, sk, nc = d[0], d[1], d[2], d[3], d[4], d[5]
    rowsw = pf[d[7]:d[7] + 4 * nw].reshape((nw, 4))
    rowsk = pf[d[8]:d[8] + 4 * nk].reshape((nk, 4))
    xf = pf[d[9]:d[9] + 6 * S].reshape((6, S))
    strt = pf[d[10]:d[10] + 3 * S].reshape((S, 3))
    ctabw = pc[:sw * nc].reshape((sw, nc))
    ctabk = pc[sw * nc:sw * nc + sk * nc].reshape((sk, nc))
    xi = _part(pi, _P_XI).reshape((3, S))
    return rowsw, ctabw, rowsk, ctabk, xf, xi, strt


@njit(cache=True, inline="always")
def _legal_row(pi, m):
    """Legal flags (A,) of the actions after action m."""
    A = _part(pi, _P_DIMS)[6]
    return _part(pi, _P_LEGAL)[m * A:(m + 1) * A]


@njit(cache=True)
def _locate_p(pi, pf, pc, r, ts, to, m_self, m_other, f_other, mask):
    """(state, squared normalised distance, level, off_graph) of a live state."""
    rowsw, ctabw, rowsk, ctabk, xf, xi, strt = _views(pi, pf, pc)
    sc = _part(pi, _P_SCALARS)
    nextset_of = _part(pi, 3)
    key_args = _part(pi, 4)
    ns = nextset_of[m_self]
    key = (ns * key_args[0] + m_other) * key_args[1] + mask
    s, d2, level = _nearest(rowsw, ctabw, rowsk, ctabk, _part(pi, 0), sc[1], sc[2], pf[4], xf, xi, _part(pi, 1),
                            _part(pi, 2), _part(pi, _P_BST3), key, ns, f_other, sc[0], r, ts, to, pf[0], pf[1])
    off = level > 0
    if s >= 0 and level == 0:
        off = (abs(strt[s, 0] - r) > pf[2] or abs(_wrap(strt[s, 1] - ts)) > pf[3]
               or abs(_wrap(strt[s, 2] - to)) > pf[3])
    return s, d2, level, off


@njit(cache=True)
def _decide(pi, pf, pc, best_ea, q_me, r, ts, to, m_self, m_other, f_other, mask):
    """Table decision: (action, state, normalised distance, off_graph, edge)."""
    s, d2, level, off = _locate_p(pi, pf, pc, r, ts, to, m_self, m_other, f_other, mask)
    e, a = _choose(s, best_ea, q_me, _part(pi, 7), _part(pi, 8), _legal_row(pi, m_self))
    if a < 0:
        a = _part(pi, 6)[_part(pi, 5)[m_self]]
    return a, s, np.sqrt(d2), off, e


#: columns of _menu_terms' rows
MT_ACTION, MT_POS, MT_GIVEN, MT_RECEIVED, MT_DEF, MT_VALUE = 0, 1, 2, 3, 4, 5
MT_FT = 6          # then the event's raw features sim.FT_* (16 columns)
N_MT = MT_FT + 16


@njit(cache=True)
def _menu_terms(T, pi, pf, pc, V_me_next, V_opp_next, pref, rw, r, ts, to, m_self, m_other, f_other, mask, out):
    """The exact one-step terms of every legal action from a live state: one simulated event per
    action (sim._expand_one), its Eq. 4 reward split into the positional cost, the damage-given
    term (w_dmg_given * kind preference * damage), the damage-received term (w_dmg_received *
    damage), the defence term, and gamma times the policy's depth-(D-1) value of the graph state
    nearest to where it lands; then the event's raw features. Row j of ``out`` (MT_* columns) for
    the j-th action of Next(m_self); returns the number of rows. rw as _lookahead's."""
    rowsw, ctabw, rowsk, ctabk, xf, xi, _ = _views(pi, pf, pc)
    sc = _part(pi, _P_SCALARS)
    nextset_of = _part(pi, 3)
    key_args = _part(pi, 4)
    menu_off = _part(pi, 5)
    menu_ids = _part(pi, 6)
    kinds = _part(pi, 9)
    d_p, w_theta, w_d, w_g, w_r, w_def = rw[0], rw[1], rw[2], rw[3], rw[4], rw[5]
    per_second = rw[6] != 0.0
    use_mean = rw[7] != 0.0
    gamma = rw[8]
    fps = rw[9]
    lo = menu_off[m_self]
    hi = menu_off[m_self + 1]
    si = np.empty(4, dtype=np.int64)
    sf = np.empty(3)
    si[0] = m_self
    si[1] = m_other
    si[2] = f_other
    si[3] = mask
    sf[0] = r
    sf[1] = ts
    sf[2] = to
    ci = np.empty(4, dtype=np.int64)
    cf = np.empty(3)
    ft = np.empty(16)
    S = np.empty((2, 3))
    act = np.empty(2, dtype=np.int64)
    frm = np.empty(2, dtype=np.int64)
    msk = np.empty(2, dtype=np.int64)
    stats = np.empty(13)
    npref = pref.shape[0]
    for j in range(lo, hi):
        a = menu_ids[j]
        swap = _expand_one(T, si, sf, a, ci, cf, ft, S, act, frm, msk, stats)
        rr = ft[2] if use_mean else ft[1]          # sim.FT_R_MEAN / sim.FT_R
        dd = rr - d_p
        pos = w_theta * ft[3] * ft[3] + w_d * dd * dd
        if per_second:
            pos *= ft[0] / fps
        k = kinds[a]
        pk = pref[k] if 0 <= k < npref else 1.0
        ns = nextset_of[ci[0]]
        key = (ns * key_args[0] + ci[1]) * key_args[1] + ci[3]
        s, _, _ = _nearest(rowsw, ctabw, rowsk, ctabk, _part(pi, 0), sc[1], sc[2], pf[4], xf, xi, _part(pi, 1),
                           _part(pi, 2), _part(pi, _P_BST3), key, ns, ci[2], sc[0], cf[0], cf[1], cf[2], pf[0], pf[1])
        v = 0.0
        if s >= 0:
            v = np.float64(V_opp_next[s]) if swap else np.float64(V_me_next[s])
        o = out[j - lo]
        o[MT_ACTION] = a
        o[MT_POS] = pos
        o[MT_GIVEN] = w_g * ft[5] * pk
        o[MT_RECEIVED] = w_r * ft[6]
        o[MT_DEF] = w_def * ft[7]
        o[MT_VALUE] = gamma * v
        o[MT_FT:MT_FT + 16] = ft
    return hi - lo


@njit(cache=True)
def _lookahead(T, pi, pf, pc, V_me_next, V_opp_next, pref, rw, r, ts, to, m_self, m_other, f_other, mask):
    """Off-graph decision: simulate every legal action once from the live state (sim._expand_one)
    and score it by its Eq. 4 reward for the decider (the W_me of planner.rewards) plus gamma
    times the policy's depth-(D-1) value of the graph state nearest to where it lands
    (_menu_terms). rw = (d_p, w_theta, w_d, w_dmg_given, w_dmg_received, w_def, per_second,
    distance is "mean", gamma, fps). Returns (best action, its score); (-1, 0) without legal actions."""
    menu_off = _part(pi, 5)
    out = np.empty((menu_off[m_self + 1] - menu_off[m_self], N_MT))
    n = _menu_terms(T, pi, pf, pc, V_me_next, V_opp_next, pref, rw, r, ts, to, m_self, m_other, f_other, mask, out)
    if n == 0:
        return -1, 0.0
    best_a = -1
    best_q = -np.inf
    for j in range(n):
        o = out[j]
        q = -o[MT_POS] + o[MT_GIVEN] - o[MT_RECEIVED] + o[MT_DEF] + o[MT_VALUE]
        if q > best_q:
            best_q = q
            best_a = int(o[MT_ACTION])
    return best_a, best_q


def _act_batch_py(T, pi, pf, pc, best_ea, q_me, V_me_next, V_opp_next, pref, rw, lookahead, r, ts, to, m_self,
                  m_other, f_other, mask, out, dist):
    for i in prange(len(r)):
        a, s, d, off, e = _decide(pi, pf, pc, best_ea, q_me, r[i], ts[i], to[i], m_self[i], m_other[i], f_other[i],
                                  mask[i])
        if lookahead and off:
            la, _ = _lookahead(T, pi, pf, pc, V_me_next, V_opp_next, pref, rw, r[i], ts[i], to[i], m_self[i],
                               m_other[i], f_other[i], mask[i])
            if la >= 0:
                a = la
                e = -1
        out[i, 0] = a
        out[i, 1] = s
        out[i, 2] = e
        out[i, 3] = 1 if off else 0
        dist[i] = d


#: act_batch runs batches smaller than this on the calling thread (a parallel region costs a
#: thread wake-up, milliseconds on a busy machine).
PARALLEL_MIN = 4096
def _renamed(fn, name: str):
    """A copy of ``fn`` under another name. numba's on-disk cache is keyed by the function's
    qualified name and line, not by the compile flags: two dispatchers of one Python function
    (parallel and serial) shared one cache entry, and whichever compiled first served both (the
    parallel batch kernel ran on one thread after a serial compile had been cached)."""
    g = types.FunctionType(fn.__code__, fn.__globals__, name, fn.__defaults__, fn.__closure__)
    g.__qualname__ = name
    return g


_act_batch = njit(cache=True, parallel=True)(_renamed(_act_batch_py, "_act_batch_parallel_kernel"))
_act_batch_serial = njit(cache=True)(_renamed(_act_batch_py, "_act_batch_serial_kernel"))


def _r_slots(slot: np.ndarray, r: np.ndarray, ts: np.ndarray, to: np.ndarray, sid: np.ndarray, f: np.ndarray,
             nslot: int, ncell: int, cell_w: float) -> tuple[np.ndarray, np.ndarray]:
    """Rows (r, theta_self, theta_other, F_other * 2^32 + state id) sorted by (slot, r) and their
    cell table."""
    o = np.lexsort((sid, r, slot))
    tag = (f[o].astype(np.int64) << 32) + sid[o]
    rows = np.ascontiguousarray(np.stack([r[o], ts[o], to[o], tag.astype(np.float64)], axis=1))
    cell = np.minimum((r[o] / cell_w).astype(np.int64), ncell - 1)
    counts = np.bincount(slot[o] * ncell + cell, minlength=nslot * ncell).reshape(nslot, ncell)
    ctab = np.empty((nslot, ncell + 1), dtype=np.int64)
    ctab[:, ncell] = np.cumsum(counts.sum(axis=1))
    ctab[:, 0] = ctab[:, ncell] - counts.sum(axis=1)
    ctab[:, 1:ncell] = ctab[:, :1] + np.cumsum(counts, axis=1)[:, :-1]
    return rows, np.ascontiguousarray(ctab, dtype=np.int32 if len(o) < 2 ** 31 - 1 else np.int64)


def _angle_bins(a: np.ndarray) -> np.ndarray:
    """_angle_bin for arrays (the same arithmetic)."""
    w = 2.0 * np.pi / _NBA
    b = np.floor((a + np.pi - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))) / w).astype(np.int64)
    return np.clip(b, 0, _NBA - 1)


def _build_index(a: dict, n_actions: int, mask_mod: int, f0: int, ncell: int = 8) -> tuple:
    """The nearest-state index (notes above): returns (rowsw, ctabw, rowsk, ctabk, xf, xi, strt),
    the int parts (ukeys, nkeys, bst2, bst3, fm = number of frame blocks, ncell) and the cell
    width (m)."""
    S = len(a["state_r"])
    r = np.ascontiguousarray(a["state_r"], dtype=np.float64)
    ts = np.ascontiguousarray(a["state_theta_self"], dtype=np.float64)
    to = np.ascontiguousarray(a["state_theta_other"], dtype=np.float64)
    f = a["state_f_other"].astype(np.int64)
    ns = a["state_nextset"].astype(np.int64)
    key = ((ns * (n_actions + 1) + a["state_m_other"].astype(np.int64)) * mask_mod
           + a["state_mask_other"].astype(np.int64))
    fm = int(f.max()) + 1 if S else 1
    ukeys, kidx = np.unique(key, return_inverse=True)
    kidx = kidx.astype(np.int64).ravel()
    sid = np.arange(S, dtype=np.int64)
    cell_w = float(r.max()) / ncell + 1e-9 if S else 1.0
    # level 0: frames in blocks of f0 (shifted by f0 - 1); a query at F reads block
    # (F + f0 - 1) // f0, which holds every state compatible with any frame of the block
    # (|F_other difference| < f0); the scan skips the others. Each state is in about 3 blocks.
    fs = f + f0 - 1
    nblock = (fm + 2 * (f0 - 1)) // f0 + 1
    qs, ids = [], []
    for dq in range(-2, 3):
        q = (fs + f0 - 1) // f0 + dq - 1
        ok = (q >= 0) & (q < nblock) & (q * f0 - f0 + 1 <= fs) & (fs <= q * f0 + 2 * f0 - 2)
        qs.append(q[ok])
        ids.append(sid[ok])
    qw = np.concatenate(qs)
    iw = np.concatenate(ids)
    ab = _angle_bins(ts) * _NBA + _angle_bins(to)
    rowsw, ctabw = _r_slots((kidx[iw] * nblock + qw) * _NB2 + ab[iw], r[iw], ts[iw], to[iw], iw, f[iw],
                            len(ukeys) * nblock * _NB2, ncell, cell_w)
    rowsk, ctabk = _r_slots(kidx * _NB2 + ab, r, ts, to, sid, f, len(ukeys) * _NB2, ncell, cell_w)
    nkeys, ninv = np.unique(ns, return_inverse=True)
    g2 = ninv.astype(np.int64).ravel() * _NB2 + ab
    o2 = np.lexsort((r, g2))
    bst2 = np.concatenate([[0], np.cumsum(np.bincount(g2, minlength=len(nkeys) * _NB2))]).astype(np.int64)
    rank = np.empty(S, dtype=np.int64)
    rank[np.argsort(key, kind="stable")] = np.arange(S)
    o3 = np.lexsort((rank, r, ab))
    bst3 = np.concatenate([[0], np.cumsum(np.bincount(ab, minlength=_NB2))]).astype(np.int64)
    xf = np.ascontiguousarray(np.stack([r[o2], ts[o2], to[o2], r[o3], ts[o3], to[o3]]) if S else np.zeros((6, 0)))
    xi = np.ascontiguousarray(np.stack([o2, o3, rank]).astype(np.int64) if S else np.zeros((3, 0), np.int64))
    strt = np.ascontiguousarray(np.stack([r, ts, to], axis=1))
    return ((rowsw, ctabw, rowsk, ctabk, xf, xi, strt),
            dict(ukeys=ukeys.astype(np.int64), nkeys=nkeys.astype(np.int64), bst2=bst2, bst3=bst3, fm=nblock,
                 ncell=ncell), cell_w)


def _edge_q(policy: Policy, offsets: np.ndarray, target: np.ndarray, swap: np.ndarray) -> np.ndarray:
    """Score of every edge for the controlled fighter deciding: W_me + gamma * V_next(target)."""
    if policy.W2 is not None and policy.search_graph is not None:
        # straight from the packed rewards (no unpacking of W_me / W_opp: half the swap time)
        out = np.empty(len(target), dtype=np.float32)
        _edge_q_kernel(policy.W2, policy.search_graph.edge_rank, target, swap, policy.V_me_next, policy.V_opp_next,
                       np.float32(policy.gamma), out)
        return out
    v_next = np.where(swap.astype(bool), policy.V_opp_next[target], policy.V_me_next[target])
    return (policy.W_me + np.float32(policy.gamma) * v_next).astype(np.float32)


@njit(cache=True)
def _edge_q_kernel(W2, edge_rank, target, swap, V_me_next, V_opp_next, g, out):
    """out[e] = W_me[e] + g * (V_opp_next if swap else V_me_next)[target[e]], in float32 as the
    numpy expression computes it; W_me[e] = W2[2 * edge_rank[e]] (planner's packed layout)."""
    for e in range(target.shape[0]):
        t = target[e]
        v = V_opp_next[t] if swap[e] else V_me_next[t]
        out[e] = np.float32(W2[2 * edge_rank[e]]) + np.float32(g * np.float32(v))


class NPCController:
    """Runtime controller of Interaction Graph fighters (thread-safe reads; one writer thread).

    Args:
        graph: the Interaction Graph (or a path to its file).
        library: the graph's action library (needed for menus); default: the one embedded in or
            next to the graph (``graph.load_library()``).
        style: a planner Style, preset name or style file.
        depth: min-max depth (decisions); gamma: discount per decision (default planner.DEFAULT_GAMMA = 0.5: see there why).
        stochastic: roulette selection among the state's edges instead of the best edge.
        temperature: softmax temperature of the roulette (reward units); usage_penalty: divides the
            probability of an edge by (1 + penalty * times used) (per controller).
        seed: seed of the roulette's random generator.
        offgraph: "lookahead" (default) or "nearest": how off-graph decisions are answered.
        first_ply: "table" (default: the policy table on the graph, the paper's runtime),
            "exact": the simulated one-step lookahead for every decision, or "exact2": two exact
            plies with the graph's values at the leaves (module docstring); act() only
            (act_batch answers from the table as before).
        edge_features: replacement arrays for some of the graph's edge features (feat_*), used
            for the policy table only (the exact plies simulate): e.g. damages as physically
            expected instead of kinematically predicted (tracker.hit_model). Same length as the
            graph's edges.
    """

    def __init__(self, graph: InteractionGraph | str | Path, library=None, style: Style | str | Path = "balanced",
                 depth: int = 5, gamma: float | None = None, stochastic: bool = False, temperature: float = 0.5,
                 usage_penalty: float = 0.0, seed: int = 0, offgraph: str = "lookahead",
                 first_ply: str = "table", edge_features: dict | None = None) -> None:
        if offgraph not in ("lookahead", "nearest"):
            raise ValueError("offgraph must be 'lookahead' or 'nearest'")
        if first_ply not in FIRST_PLY:
            raise ValueError(f"first_ply must be one of {', '.join(FIRST_PLY)}, not {first_ply!r}")
        self.offgraph = offgraph
        self.first_ply = first_ply
        if not isinstance(graph, InteractionGraph):
            graph = load_graph(graph)
        self.graph = graph
        if library is None:
            library = graph.load_library()
        graph.check_library(library)
        self.library = library
        a = graph.arrays
        self._arrays = dict(a)
        if "kinds_table" not in self._arrays:
            self._arrays["kinds_table"] = np.array(KINDS)
        for k, v in (edge_features or {}).items():
            if not k.startswith("feat_") or k not in self._arrays or len(v) != len(self._arrays[k]):
                raise ValueError(f"edge_features: {k!r} is not one of the graph's edge features of "
                                 f"{len(a['edge_target'])} edges")
            self._arrays[k] = np.asarray(v)
        opts = graph.header.get("options", {})
        self.f0 = int(opts.get("f0", 3))
        s_r = float(opts.get("s_r_m", 0.5))
        s_t = float(opts.get("s_theta_rad", np.pi / 6))
        self._inv_sr2, self._inv_st2 = 1.0 / s_r ** 2, 1.0 / s_t ** 2
        self.tol_r = float(opts.get("link_tol_r_m", 0.1))
        self.tol_theta = float(opts.get("link_tol_theta_rad", np.radians(20)))
        # Lookup index (see _build_index): states bucketed by (Next-set id, M_other, mask, F_other)
        # and by Next-set id, each bucket sorted by r.
        A = library.n_actions
        self._nextset_of = _nextset_ids(library)
        mask_mod = int(a["state_mask_other"].max()) + 2 if len(a["state_mask_other"]) else 2
        self._key_args = np.array([A + 1, mask_mod], dtype=np.int64)
        ix, ix_parts, cell_w = _build_index(a, A, mask_mod, self.f0)
        self._offsets = a["state_offsets"].astype(np.int64)
        self._edge_action = a["edge_action"].astype(np.int64)
        self._target = a["edge_target"].astype(np.int64)
        self._swap = a["edge_swap"].astype(np.uint8)
        legal = np.zeros((A, A), dtype=np.bool_)
        for m in range(A):
            legal[m, library.next(m)] = True
        self._legal = legal
        self._menu_off = np.asarray(library.next_offsets, dtype=np.int64)
        self._menu_ids = np.asarray(library.next_ids, dtype=np.int64)
        self._search_graph = SearchGraph.from_arrays(a["state_offsets"], a["edge_target"], a["edge_swap"])
        from .sim import SimTables
        self.tables = SimTables.from_library(library, graph.sim_params())
        self._T = self.tables.kernel_tuple()
        self._kinds = np.asarray(self.tables.kinds, dtype=np.int64)
        self._kinds32 = self._kinds.astype(np.int32)
        self._max_menu = int(max(1, np.diff(self._menu_off).max())) if A else 1
        self._count = np.zeros(2, dtype=np.int64)  # exact2: events simulated, nodes expanded
        self._pi, self._pf, self._pc = _pack_index(
            ix, {k: ix_parts[k] for k in ("ukeys", "nkeys", "bst2", "bst3")},
            [self.f0, ix_parts["fm"], ix_parts["ncell"]],
            dict(nextset_of=self._nextset_of, key_args=self._key_args, menu_off=self._menu_off,
                 menu_ids=self._menu_ids, offsets=self._offsets, edge_action=self._edge_action, kinds=self._kinds),
            legal, [self._inv_sr2, self._inv_st2, self.tol_r, self.tol_theta, cell_w])
        self.stochastic = stochastic
        self.temperature = float(temperature)
        self.usage_penalty = float(usage_penalty)
        # edge -> times chosen, kept only when the usage penalty needs it (a dense per-edge array
        # was 50 MB of lazily zeroed pages whose first touches cost up to 0.3 ms a decision)
        self._usage: dict[int, int] = {}
        self._rng = np.random.default_rng(seed)
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="npc-policy")
        self._lock = threading.Lock()
        self._version = 0
        self.last_swap_ms: float | None = None
        style_obj = style if isinstance(style, Style) else load_style(style)
        self._table = self._compute(style_obj, int(depth), gamma)

    @classmethod
    def load(cls, graph_path: str | Path, library_path: str | Path | None = None, **kwargs) -> "NPCController":
        """Controller from a graph file (and its library file, if not embedded or beside it)."""
        lib = None
        if library_path is not None:
            from motion_graph.library import load_library
            lib = load_library(library_path)
        return cls(graph_path, lib, **kwargs)

    # ----- policy ---------------------------------------------------------------------------
    def _compute(self, style: Style, depth: int, gamma: float | None) -> _Table:
        if depth < 1:
            raise ValueError("depth must be >= 1")
        from planner import DEFAULT_GAMMA
        g = float(gamma) if gamma is not None else DEFAULT_GAMMA
        pol = compute_policy(self._arrays, style, depth, g, search_graph=self._search_graph)
        q = _edge_q(pol, self._offsets, self._target, self._swap)
        with self._lock:
            self._version += 1
            v = self._version
        from planner import kind_preferences
        rw = np.array([style.d_p, style.w_theta, style.w_d, style.w_dmg_given, style.w_dmg_received, style.w_def,
                       float(style.per_second), float(style.distance == "mean"), float(pol.gamma),
                       float(self.tables.fps)], dtype=np.float64)
        la = (np.ascontiguousarray(pol.V_me_next), np.ascontiguousarray(pol.V_opp_next),
              kind_preferences(style, [str(k) for k in self._arrays["kinds_table"]]), rw)
        be = pol.best_me.astype(np.int64)
        best_ea = np.ascontiguousarray(np.stack([be, np.where(be >= 0, self._edge_action[np.maximum(be, 0)], -1)],
                                                axis=1))
        from .agents.common import style_params
        return _Table(pol, best_ea, q, style.name, depth, v, style, la, style_params(style))

    @property
    def style(self) -> str:
        return self._table.style

    @property
    def depth(self) -> int:
        return self._table.depth

    @property
    def policy(self) -> Policy:
        return self._table.policy

    @property
    def style_def(self) -> Style:
        """The live table's Style (weights, kind preferences)."""
        return self._table.style_obj

    @property
    def action_kinds(self) -> np.ndarray:
        """Kind index of each library action (into ``kind_names``; -1 for none)."""
        return self._kinds

    @property
    def kind_names(self) -> list[str]:
        """The kind names the graph's kind indices refer to."""
        return [str(k) for k in self._arrays["kinds_table"]]

    def _swap_in(self, style: Style, depth: int, gamma: float | None, t_request: float) -> _Table:
        table = self._compute(style, depth, gamma)
        self._table = table  # one reference assignment: atomic for readers
        self.last_swap_ms = (time.perf_counter() - t_request) * 1e3
        return table

    def set_style(self, style: Style | str | Path, wait: bool = False) -> Future:
        """Recompute the policy for a new style in the background; the old one answers meanwhile.
        Returns a Future (result: the new table); ``wait=True`` blocks until it is live."""
        st = style if isinstance(style, Style) else load_style(style)
        fut = self._executor.submit(self._swap_in, st, self.depth, None, time.perf_counter())
        if wait:
            fut.result()
        return fut

    def set_depth(self, depth: int, wait: bool = False) -> Future:
        """Change the search depth (strength); recomputed in the background like set_style."""
        fut = self._executor.submit(self._swap_in, self._table.style_obj, int(depth), None, time.perf_counter())
        if wait:
            fut.result()
        return fut

    # ----- decisions ------------------------------------------------------------------------
    def _lookahead(self, table: _Table, obs: Observation) -> tuple[int, float]:
        """One exact simulated event per legal action + the graph value where it lands."""
        a, q = _lookahead(self._T, self._pi, self._pf, self._pc, *table.la, float(obs.r), float(obs.theta_self),
                          float(obs.theta_other), int(obs.m_self), int(obs.m_other), int(obs.f_other),
                          int(obs.mask_other))
        return int(a), float(q)

    def menu_terms(self, obs: Observation) -> np.ndarray:
        """The exact one-step terms of every legal action from ``obs`` under the live style: one
        row per action of Next(m_self), columns MT_* (action, positional cost, damage-given,
        damage-received and defence terms, gamma * graph value where it lands, then the event's
        raw sim.FT_* features). Score = -pos + given - received + def + value (what the
        lookahead maximises); callers may replace terms, e.g. with physically measured hit odds."""
        table = self._table
        m = int(obs.m_self)
        out = np.zeros((int(self._menu_off[m + 1] - self._menu_off[m]), N_MT))
        _menu_terms(self._T, self._pi, self._pf, self._pc, *table.la, float(obs.r), float(obs.theta_self),
                    float(obs.theta_other), m, int(obs.m_other), int(obs.f_other), int(obs.mask_other), out)
        return out

    def _exact2(self, table: _Table, obs: Observation) -> tuple[int, float]:
        """Two exact plies + the graph's values at the leaves (``first_ply="exact2"``)."""
        from .agents.gametree import _search_graph_leaves
        if self._menu_off[obs.m_self + 1] <= self._menu_off[obs.m_self]:
            return -1, 0.0
        si = np.array([obs.m_self, obs.m_other, obs.f_other, obs.mask_other], dtype=np.int64)
        sf = np.array([obs.r, obs.theta_self, obs.theta_other], dtype=np.float64)
        V_me, V_opp, pref, rw = table.la
        j, q = _search_graph_leaves(self._T, self._menu_off, self._menu_ids, self._kinds32, table.style_params, pref,
                                    float(self.tables.fps), si, sf, self._max_menu, self._count, float(rw[8]),
                                    self._pi, self._pf, self._pc, V_me, V_opp)
        if j < 0:
            return -1, 0.0
        return int(self._menu_ids[self._menu_off[obs.m_self] + j]), float(q)

    def act(self, obs: Observation) -> Decision:
        """The action for one live state (see the module docstring)."""
        return self._choose(obs, commit=True)

    def peek(self, obs: Observation) -> int:
        """The action act() would choose for ``obs``, without side effects: the best edge where a
        stochastic controller would spin its roulette, and no edge usage counted (a guess at a
        future decision, e.g. tracker.bout's foresight for a search tracker's look-ahead)."""
        return int(self._choose(obs, commit=False).action)

    def _choose(self, obs: Observation, commit: bool) -> Decision:
        table = self._table  # one read: a consistent snapshot
        a, s, d, off, e = _decide(self._pi, self._pf, self._pc, table.best_ea, table.q_me, float(obs.r),
                                  float(obs.theta_self), float(obs.theta_other), int(obs.m_self), int(obs.m_other),
                                  int(obs.f_other), int(obs.mask_other))
        if self.first_ply == "exact2":
            xa, _ = self._exact2(table, obs)
            if xa >= 0:
                a, e = xa, -1
        elif self.first_ply == "exact" or (off and self.offgraph == "lookahead"):
            la, _ = self._lookahead(table, obs)
            if la >= 0:
                a, e = la, -1
        elif self.stochastic and s >= 0 and commit:
            re = self._roulette(table, s, int(obs.m_self))
            if re >= 0:
                e, a = re, int(self._edge_action[re])
        if e >= 0 and self.usage_penalty > 0.0 and commit:
            self._usage[e] = self._usage.get(e, 0) + 1
        return Decision(a, s, d, off, e)

    def locate(self, obs: Observation) -> tuple[int, float, bool]:
        """The graph state a live state maps to, as act() finds it: (state, normalised distance,
        off_graph). No decision, no lookahead; state -1 only for an empty graph."""
        s, d2, _, off = _locate_p(self._pi, self._pf, self._pc, float(obs.r), float(obs.theta_self),
                                  float(obs.theta_other), int(obs.m_self), int(obs.m_other), int(obs.f_other),
                                  int(obs.mask_other))
        return int(s), float(np.sqrt(d2)), bool(off)

    def _roulette(self, table: _Table, s: int, m_self: int) -> int:
        from planner import roulette_probabilities
        lo, hi = int(self._offsets[s]), int(self._offsets[s + 1])
        legal = self._legal[m_self, self._edge_action[lo:hi]]
        if not legal.any():
            return -1
        q = table.q_me[lo:hi].astype(np.float64)[legal]
        idx = np.arange(lo, hi)[legal]
        used = np.array([self._usage.get(int(i), 0) for i in idx], dtype=np.float64)
        p = roulette_probabilities(q, self.temperature, "softmax", used, self.usage_penalty)
        return int(idx[self._rng.choice(len(idx), p=p)])

    def act_batch(self, r, theta_self, theta_other, m_self, m_other, f_other, mask_other=None,
                  lookahead: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Decisions for many NPCs at once (arrays of equal length; deterministic best edges, in
        parallel). Returns (actions, states, off_graph) arrays. ``lookahead=True`` (with
        ``offgraph="lookahead"``) answers off-graph rows with the simulated lookahead, exactly as
        act() does; the default answers them from the nearest state's table entry."""
        n = len(r)
        mask = np.zeros(n, dtype=np.int64) if mask_other is None else np.asarray(mask_other, dtype=np.int64)
        out = np.empty((n, 4), dtype=np.int64)
        dist = np.empty(n)
        table = self._table
        kernel = _act_batch if n >= PARALLEL_MIN else _act_batch_serial
        kernel(self._T, self._pi, self._pf, self._pc, table.best_ea, table.q_me, *table.la,
               bool(lookahead and self.offgraph == "lookahead"), np.asarray(r, dtype=np.float64),
               np.asarray(theta_self, dtype=np.float64), np.asarray(theta_other, dtype=np.float64),
               np.asarray(m_self, dtype=np.int64), np.asarray(m_other, dtype=np.int64),
               np.asarray(f_other, dtype=np.int64), mask, out, dist)
        return out[:, 0], out[:, 1], out[:, 3].astype(bool)

    def close(self) -> None:
        self._executor.shutdown(wait=True)


def _nextset_ids(library) -> np.ndarray:
    """Next-set id per action, numbered as igraph_fight.sim.SimTables does."""
    seen: dict[tuple, int] = {}
    out = np.empty(library.n_actions, dtype=np.int64)
    for a in range(library.n_actions):
        out[a] = seen.setdefault(tuple(sorted(int(b) for b in library.next(a))), len(seen))
    return out


def observe(state, player: int) -> Observation:
    """Observation of ``player`` in a game.FightState (at its decision instant)."""
    from . import sim
    from .state import to_sample
    si, sf = to_sample(state.game.tables, state.world, player)
    return Observation(float(sf[sim.SF_R]), float(sf[sim.SF_TH_SELF]), float(sf[sim.SF_TH_OTHER]),
                       int(si[sim.SI_MSELF]), int(si[sim.SI_MOTHER]), int(si[sim.SI_FOTHER]), int(si[sim.SI_MASK]))
