"""Exact search on the kinematic simulator: depth-limited min-max with alpha-beta pruning from a
live coupled state, scoring every simulated event with the planner's Eq. 4 reward
(planner.rewards.fight_edge), with a value function at the leaves (none, or the Interaction
Graph's values). Both the game-tree baseline (igraph_fight.agents.gametree) and NPCController's
``first_ply="exact2"`` run it; the static baseline uses its node expansion.

Depth counts decisions (plies) of either fighter, as the planner's min-max does:

    V_me(s, d)  = max_e W_me[e]  + gamma * V_next(t, d - 1)
    V_opp(s, d) = min_e W_opp[e] + gamma * V_next(t, d - 1),   V(., 0) = leaf value,

with V_next = V_opp when the other fighter decides at t, else V_me (when both fighters stand at
a decision instant, the one that did not just choose goes next, as in the game).

Speed: the whole search is one numba call (no Python per node; an explicit stack, since numba
cannot cache recursive functions). A node simulates all of its children's events (their rewards
need them), orders them by reward (best first for the side to move) and descends with
alpha-beta pruning (about 2.3x fewer simulated events at depth 3). The pruned search returns the
same root value as plain min-max; at the root every child is searched with a window just below
the best value so far, which resolves exact ties the way plain min-max does (first best in menu
order): the decision is the unpruned one (tests check both). No memoising: transpositions are
rare in a continuous state space.
"""
from __future__ import annotations

import numpy as np
from numba import njit

import motion_graph.rotations
import planner.rewards
from igraph_fight import locate, sim
from igraph_fight.kernel_cache import drop_stale_caches
from igraph_fight.locate import locate_packed
from igraph_fight.sim import N_FEAT, N_SF, N_SI
from planner.rewards import fight_edge

drop_stale_caches(__file__, [locate, sim, planner.rewards, motion_graph.rotations])

INF = 1e300
#: values closer than this are a tie at the root (first best in menu order wins)
TIE = 1e-9
#: the value function of the plain game tree: no leaf values (V(., 0) = 0)
NO_VALUES = np.zeros(0, dtype=np.float32)
#: placeholders for the nearest-state index when there are no leaf values
NO_INDEX_PI = np.zeros(1, dtype=np.int64)
NO_INDEX_PF = np.zeros(1, dtype=np.float64)
NO_INDEX_PC = np.zeros(1, dtype=np.int32)


@njit(cache=True, inline="always")
def child_buffers(levels, max_menu):
    """expand_children's buffers for ``levels`` levels of children (CI, CF, FT, SW, W, DUR, KIND, OKIND,
    ORD) and the simulator's scratch (S, act, frm, mask, stats)."""
    return (np.empty((levels, max_menu, N_SI), dtype=np.int64), np.empty((levels, max_menu, N_SF)),
            np.empty((levels, max_menu, N_FEAT)), np.empty((levels, max_menu), dtype=np.int64),
            np.empty((levels, max_menu)), np.empty((levels, max_menu)), np.empty((levels, max_menu), dtype=np.int32),
            np.empty((levels, max_menu), dtype=np.int32), np.empty((levels, max_menu), dtype=np.int64),
            np.empty((2, 3)), np.empty(2, dtype=np.int64), np.empty(2, dtype=np.int64), np.empty(2, dtype=np.int64),
            np.empty(sim.N_STAT))


@njit(cache=True)
def expand_children(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, me, level, order,
            CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count):
    """Simulate every child event of a canonical sample (decider's perspective) into row
    ``level`` of the buffers and score it: W = the controlled fighter's Eq. 4 reward (W_me when
    it decides, ``me``, else W_opp). With ``order`` also sort the children best first for the
    side to move (stable). Returns the number of children."""
    m = si[sim.SI_MSELF]
    lo = nxt_off[m]
    k = nxt_off[m + 1] - lo
    for j in range(k):
        SW[level, j] = sim.expand_one(T, si, sf, nxt_ids[lo + j], CI[level, j], CF[level, j], FT[level, j],
                                       S, act, frm, mask, stats)
        DUR[level, j] = FT[level, j, sim.FT_FRAMES] / fps
        KIND[level, j] = kinds[nxt_ids[lo + j]]
        OKIND[level, j] = kinds[si[sim.SI_MOTHER]]
    count[0] += k
    count[1] += 1
    rcol = sim.FT_R_MEAN if P[7] > 0.5 else sim.FT_R
    for j in range(k):
        a, b = fight_edge(j, FT[level, :, rcol], FT[level, :, sim.FT_TH_SELF], FT[level, :, sim.FT_TH_OTHER],
                           DUR[level], FT[level, :, sim.FT_DMG_GIVEN], FT[level, :, sim.FT_DMG_RECEIVED],
                           KIND[level], OKIND[level], FT[level, :, sim.FT_DEF_SELF], FT[level, :, sim.FT_DEF_OTHER],
                           pref, P[0], P[1], P[2], P[3], P[4], P[5], P[6] > 0.5)
        W[level, j] = a if me else b
    if order:
        for j in range(k):
            ORD[level, j] = j
        for i in range(1, k):
            x = ORD[level, i]
            p = i - 1
            while p >= 0 and ((me and W[level, ORD[level, p]] < W[level, x]) or
                              (not me and W[level, ORD[level, p]] > W[level, x])):
                ORD[level, p + 1] = ORD[level, p]
                p -= 1
            ORD[level, p + 1] = x
    return k


@njit(cache=True, inline="always")
def best_leaf(W, level, k, me):
    """(value, index) of the best child for the side to move (first best in menu order)."""
    bj = 0
    for j in range(1, k):
        if (me and W[level, j] > W[level, bj]) or (not me and W[level, j] < W[level, bj]):
            bj = j
    return W[level, bj], bj


@njit(cache=True)
def _leaf_value(W, CI, CF, SW, level, k, me, gamma, pi, pf, pc, V_me, V_opp):
    """(value, index) of the best of the ``k`` children in row ``level`` for the side to move (first
    best in menu order): their reward W alone when there is no value function (``V_me`` empty), else
    W + gamma * the graph value where each child lands."""
    if V_me.shape[0] == 0:
        return best_leaf(W, level, k, me)
    bv = 0.0
    bj = -1
    for i in range(k):
        lme = me if SW[level, i] == 0 else not me
        s, _, _, _ = locate_packed(pi, pf, pc, CF[level, i, sim.SF_R], CF[level, i, sim.SF_TH_SELF],
                                   CF[level, i, sim.SF_TH_OTHER], CI[level, i, sim.SI_MSELF],
                                   CI[level, i, sim.SI_MOTHER], CI[level, i, sim.SI_FOTHER], CI[level, i, sim.SI_MASK])
        v = 0.0
        if s >= 0:
            v = np.float64(V_me[s]) if lme else np.float64(V_opp[s])
        x = W[level, i] + gamma * v
        if bj < 0 or (me and x > bv) or (not me and x < bv):
            bv = x
            bj = i
    return bv, bj


@njit(cache=True)
def search(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, depth, gamma, prune, max_menu, count, root_me,
           pi, pf, pc, V_me, V_opp):
    """Depth-limited min-max (alpha-beta) from a canonical sample where the controlled fighter
    (``root_me``) or its opponent decides; an explicit stack (numba cannot cache recursive
    functions). The value function at the leaves (depth exhausted): 0 when ``V_me`` is empty (the
    plain game tree, V(., 0) = 0), else the value of the Interaction Graph state nearest to the
    leaf's landing sample (igraph_fight.locate, on its lookup grid; ``V_me`` where the controlled fighter decides
    there, else ``V_opp``), so that

        Q(a) = W(a) + gamma * opt_b [W(b) + gamma * V(nearest(landing(a, b)))]

    at depth 2 (NPCController's ``first_ply="exact2"``). Returns (root value, menu index of the
    best child; -1 for a dead end)."""
    L = max(depth, 1) + 1
    CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats = child_buffers(L, max_menu)
    # per-level frame of the stack
    K = np.zeros(L, dtype=np.int64)
    POS = np.zeros(L, dtype=np.int64)
    ME = np.zeros(L, dtype=np.bool_)
    A = np.zeros(L)
    B = np.zeros(L)
    BV = np.zeros(L)
    BJ = np.zeros(L, dtype=np.int64)
    k = expand_children(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, root_me, 0, depth > 1,
                CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count)
    if k == 0:
        return 0.0, -1
    if depth <= 1:
        return _leaf_value(W, CI, CF, SW, 0, k, root_me, gamma, pi, pf, pc, V_me, V_opp)
    K[0] = k
    POS[0] = 0
    ME[0] = root_me
    A[0] = -INF
    B[0] = INF
    BV[0] = -INF if root_me else INF
    BJ[0] = -1
    lev = 0
    while True:
        if POS[lev] < K[lev]:
            j = ORD[lev, POS[lev]]
            w = W[lev, j]
            cme = ME[lev] if SW[lev, j] == 0 else not ME[lev]
            a_c = -INF
            b_c = INF
            if prune:
                if lev == 0:  # the root: a window just beyond the best so far resolves exact ties
                    if BJ[0] >= 0:
                        if root_me:
                            a_c = (BV[0] - TIE - w) / gamma
                        else:
                            b_c = (BV[0] + TIE - w) / gamma
                else:
                    a_c = (A[lev] - w) / gamma
                    b_c = (B[lev] - w) / gamma
            cd = depth - lev - 1  # plies left below the child
            nk = expand_children(T, nxt_off, nxt_ids, kinds, P, pref, fps, CI[lev, j], CF[lev, j], cme, lev + 1, cd > 1,
                         CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count)
            if nk == 0:
                v = 0.0
            elif cd <= 1:
                v, _ = _leaf_value(W, CI, CF, SW, lev + 1, nk, cme, gamma, pi, pf, pc, V_me, V_opp)
            else:  # descend
                lev += 1
                K[lev] = nk
                POS[lev] = 0
                ME[lev] = cme
                A[lev] = a_c
                B[lev] = b_c
                BV[lev] = -INF if cme else INF
                BJ[lev] = -1
                continue
        else:  # this node is done: return its value to the parent
            if lev == 0:
                return BV[0], BJ[0]
            v = BV[lev]
            lev -= 1
            j = ORD[lev, POS[lev]]
            w = W[lev, j]
        # integrate the child's value v into node lev
        v = w + gamma * v
        POS[lev] += 1
        if lev == 0:
            better = v > BV[0] + TIE if root_me else v < BV[0] - TIE
            if BJ[0] < 0 or better or (abs(v - BV[0]) <= TIE and j < BJ[0]):
                BV[0] = v
                BJ[0] = j
            continue
        if ME[lev]:
            if v > BV[lev]:
                BV[lev] = v
                BJ[lev] = j
            if prune and BV[lev] > A[lev]:
                A[lev] = BV[lev]
        else:
            if v < BV[lev]:
                BV[lev] = v
                BJ[lev] = j
            if prune and BV[lev] < B[lev]:
                B[lev] = BV[lev]
        if prune and A[lev] >= B[lev]:
            POS[lev] = K[lev]
