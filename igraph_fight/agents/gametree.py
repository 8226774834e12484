"""Game-tree baseline (after Shum et al. 2007): depth-limited min-max on the exact simulator.

At each of its decisions the fighter expands the game tree from the live coupled state with the
exact, unclustered kinematic simulator (igraph_fight.sim, the kernel the Interaction Graph was
sampled with) and scores every simulated event with the same Eq. 4 reward as the IG fighter
(planner.rewards._fight_edge on the same edge features). Depth counts decisions (plies) of
either fighter, as the planner's min-max does:

    V_me(s, d)  = max_e W_me[e]  + gamma * V_next(t, d - 1)
    V_opp(s, d) = min_e W_opp[e] + gamma * V_next(t, d - 1),   V(., 0) = 0,

with V_next = V_opp when the other fighter decides at t, else V_me (when both fighters stand at
a decision instant, the one that did not just choose goes next, as in the game).

Speed: the whole search is one numba call (no Python per node; an explicit stack, since numba
cannot cache recursive functions). A node simulates all of its children's events (their rewards
need them), orders them by reward (best first for the side to move) and descends with
alpha-beta pruning (about 2.3x fewer simulated events at depth 3). The pruned search returns the same root value as
plain min-max; at the root every child is searched with a window just below the best value so
far, which resolves exact ties the way plain min-max does (first best in menu order): the
decision is the unpruned one (tests check both). No memoising: transpositions are rare in a
continuous state space.
"""
from __future__ import annotations

import time

import numpy as np
from numba import njit

from planner.rewards import _fight_edge

from .. import sim
from ..controller import _locate_p
from ..sim import N_FEAT, N_SF, N_SI
from ..state import to_sample
from .common import as_style, style_params

_INF = 1e300
_TIE = 1e-9


@njit(cache=True, inline="always")
def _buffers(levels, max_menu):
    """_expand's buffers for ``levels`` levels of children (CI, CF, FT, SW, W, DUR, KIND, OKIND,
    ORD) and the simulator's scratch (S, act, frm, mask, stats)."""
    return (np.empty((levels, max_menu, N_SI), dtype=np.int64), np.empty((levels, max_menu, N_SF)),
            np.empty((levels, max_menu, N_FEAT)), np.empty((levels, max_menu), dtype=np.int64),
            np.empty((levels, max_menu)), np.empty((levels, max_menu)), np.empty((levels, max_menu), dtype=np.int32),
            np.empty((levels, max_menu), dtype=np.int32), np.empty((levels, max_menu), dtype=np.int64),
            np.empty((2, 3)), np.empty(2, dtype=np.int64), np.empty(2, dtype=np.int64), np.empty(2, dtype=np.int64),
            np.empty(sim.N_STAT))


@njit(cache=True)
def _expand(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, me, level, order,
            CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count):
    """Simulate every child event of a canonical sample (decider's perspective) into row
    ``level`` of the buffers and score it: W = the controlled fighter's Eq. 4 reward (W_me when
    it decides, ``me``, else W_opp). With ``order`` also sort the children best first for the
    side to move (stable). Returns the number of children."""
    m = si[sim.SI_MSELF]
    lo = nxt_off[m]
    k = nxt_off[m + 1] - lo
    for j in range(k):
        SW[level, j] = sim._expand_one(T, si, sf, nxt_ids[lo + j], CI[level, j], CF[level, j], FT[level, j],
                                       S, act, frm, mask, stats)
        DUR[level, j] = FT[level, j, sim.FT_FRAMES] / fps
        KIND[level, j] = kinds[nxt_ids[lo + j]]
        OKIND[level, j] = kinds[si[sim.SI_MOTHER]]
    count[0] += k
    count[1] += 1
    rcol = sim.FT_R_MEAN if P[7] > 0.5 else sim.FT_R
    for j in range(k):
        a, b = _fight_edge(j, FT[level, :, rcol], FT[level, :, sim.FT_TH_SELF], FT[level, :, sim.FT_TH_OTHER],
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
def _best_leaf(W, level, k, me):
    """(value, index) of the best child for the side to move (first best in menu order)."""
    bj = 0
    for j in range(1, k):
        if (me and W[level, j] > W[level, bj]) or (not me and W[level, j] < W[level, bj]):
            bj = j
    return W[level, bj], bj


@njit(cache=True)
def _search(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, depth, gamma, prune, max_menu, count, root_me=True):
    """Depth-limited min-max (alpha-beta) from a canonical sample where the controlled fighter
    (``root_me``) or its opponent decides; an explicit stack (numba cannot cache recursive
    functions). Returns (root value, menu index of the best child; -1 for a dead end)."""
    L = max(depth, 1) + 1
    CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats = _buffers(L, max_menu)
    # per-level frame of the stack
    K = np.zeros(L, dtype=np.int64)
    POS = np.zeros(L, dtype=np.int64)
    ME = np.zeros(L, dtype=np.bool_)
    A = np.zeros(L)
    B = np.zeros(L)
    BV = np.zeros(L)
    BJ = np.zeros(L, dtype=np.int64)
    k = _expand(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, root_me, 0, depth > 1,
                CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count)
    if k == 0:
        return 0.0, -1
    if depth <= 1:
        return _best_leaf(W, 0, k, root_me)
    K[0] = k
    POS[0] = 0
    ME[0] = root_me
    A[0] = -_INF
    B[0] = _INF
    BV[0] = -_INF if root_me else _INF
    BJ[0] = -1
    lev = 0
    while True:
        if POS[lev] < K[lev]:
            j = ORD[lev, POS[lev]]
            w = W[lev, j]
            cme = ME[lev] if SW[lev, j] == 0 else not ME[lev]
            a_c = -_INF
            b_c = _INF
            if prune:
                if lev == 0:  # the root: a window just beyond the best so far resolves exact ties
                    if BJ[0] >= 0:
                        if root_me:
                            a_c = (BV[0] - _TIE - w) / gamma
                        else:
                            b_c = (BV[0] + _TIE - w) / gamma
                else:
                    a_c = (A[lev] - w) / gamma
                    b_c = (B[lev] - w) / gamma
            cd = depth - lev - 1  # plies left below the child
            nk = _expand(T, nxt_off, nxt_ids, kinds, P, pref, fps, CI[lev, j], CF[lev, j], cme, lev + 1, cd > 1,
                         CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count)
            if nk == 0:
                v = 0.0
            elif cd <= 1:
                v, _ = _best_leaf(W, lev + 1, nk, cme)
            else:  # descend
                lev += 1
                K[lev] = nk
                POS[lev] = 0
                ME[lev] = cme
                A[lev] = a_c
                B[lev] = b_c
                BV[lev] = -_INF if cme else _INF
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
            better = v > BV[0] + _TIE if root_me else v < BV[0] - _TIE
            if BJ[0] < 0 or better or (abs(v - BV[0]) <= _TIE and j < BJ[0]):
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


@njit(cache=True)
def _search_graph_leaves(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, max_menu, count, gamma, pi, pf, pc,
                         V_me, V_opp):
    """Two exact plies with Interaction Graph values at the leaves (NPCController's
    ``first_ply="exact2"``): every action of the controlled fighter and every answer of whoever
    decides next are simulated exactly from the live canonical sample and scored with Eq. 4 (W_me
    or W_opp); below them the value of the graph state nearest to each landing sample (V_me when
    the controlled fighter decides there, else V_opp; the policy's depth-(D-1) values, an
    approximation of depth D-2) is discounted by ``gamma``:

        Q(a) = W(a) + gamma * opt_b [W(b) + gamma * V(nearest(landing(a, b)))],

    opt = max where the controlled fighter decides after a, min where the opponent does.
    An action whose opponent already has an answer that keeps it no better than the best action so
    far is left (alpha-beta at the root: the choice and its Q are those of the full search).
    Returns (menu index of the best action, its Q; -1 for an empty menu)."""
    CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats = _buffers(2, max_menu)
    k = _expand(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, True, 0, False,
                CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count)
    best_j = -1
    best_q = -_INF
    for j in range(k):
        cme = SW[0, j] == 0
        nk = _expand(T, nxt_off, nxt_ids, kinds, P, pref, fps, CI[0, j], CF[0, j], cme, 1, False,
                     CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats, count)
        v = 0.0
        if nk > 0:
            v = -_INF if cme else _INF
            for i in range(nk):
                lme = cme if SW[1, i] == 0 else not cme
                s, _, _, _ = _locate_p(pi, pf, pc, CF[1, i, sim.SF_R], CF[1, i, sim.SF_TH_SELF],
                                       CF[1, i, sim.SF_TH_OTHER], CI[1, i, sim.SI_MSELF], CI[1, i, sim.SI_MOTHER],
                                       CI[1, i, sim.SI_FOTHER], CI[1, i, sim.SI_MASK])
                leaf = 0.0
                if s >= 0:
                    leaf = np.float64(V_me[s]) if lme else np.float64(V_opp[s])
                x = W[1, i] + gamma * leaf
                if (cme and x > v) or (not cme and x < v):
                    v = x
                if not cme and best_j >= 0 and W[0, j] + gamma * v <= best_q + _TIE:
                    break  # the opponent's answer already makes j no better than the best so far
        q = W[0, j] + gamma * v
        if q > best_q + _TIE:
            best_q = q
            best_j = j
    return best_j, best_q


class GameTreeSearch:
    """Min-max over the exact simulator for one set of simulator tables and one style."""

    def __init__(self, tables, style="infighter", depth: int = 2, gamma: float = 1.0, prune: bool = True) -> None:
        from motion_graph.classify import KINDS
        from planner.rewards import kind_preferences

        if depth < 1:
            raise ValueError("depth must be >= 1")
        self.tables = tables
        self.style = as_style(style)
        self.depth = int(depth)
        self.gamma = float(gamma)
        self.prune = bool(prune)
        self._T = tables.kernel_tuple()
        self._off = np.asarray(tables.next_offsets, dtype=np.int64)
        self._ids = np.asarray(tables.next_ids, dtype=np.int64)
        self._kinds = np.asarray(tables.kinds, dtype=np.int32)
        self._P = style_params(self.style)
        self._pref = kind_preferences(self.style, list(KINDS))
        self._max_menu = int(max(1, np.diff(self._off).max()))
        self.count = np.zeros(2, dtype=np.int64)  # events simulated, nodes expanded

    def search(self, si: np.ndarray, sf: np.ndarray) -> tuple[int, float]:
        """(action, root value) for a canonical sample (igraph_fight.state.to_sample)."""
        si = np.ascontiguousarray(si, dtype=np.int64)
        sf = np.ascontiguousarray(sf, dtype=np.float64)
        v, j = _search(self._T, self._off, self._ids, self._kinds, self._P, self._pref, float(self.tables.fps),
                       si, sf, self.depth, self.gamma, self.prune, self._max_menu, self.count)
        m = int(si[sim.SI_MSELF])
        if j < 0:
            return int(self._ids[self._off[m]]) if self._off[m + 1] > self._off[m] else -1, 0.0
        return int(self._ids[self._off[m] + j]), float(v)

    def root_q(self, si: np.ndarray, sf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(menu actions, exact min-max value of launching each one) at this depth: its Eq. 4
        reward plus the depth-1 search below it (for diagnostics: regret of another policy)."""
        from motion_graph.classify import KINDS
        from planner import edge_rewards

        from ..edge_features import edge_features
        si = np.ascontiguousarray(si, dtype=np.int64)
        sf = np.ascontiguousarray(sf, dtype=np.float64)
        acts = self.tables.menu(int(si[sim.SI_MSELF])).astype(np.int64)
        ci, cf, ft, sw = sim.expand_samples(self._T, si[None], sf[None], np.zeros(len(acts), dtype=np.int64), acts)
        w_me, _ = edge_rewards(edge_features(self.tables, np.full(len(acts), si[sim.SI_MOTHER]), acts, ft), self.style,
                               list(KINDS))
        q = w_me.astype(np.float64).copy()
        if self.depth > 1:
            for k in range(len(acts)):
                v, _ = _search(self._T, self._off, self._ids, self._kinds, self._P, self._pref, float(self.tables.fps),
                               ci[k], cf[k], self.depth - 1, self.gamma, self.prune, self._max_menu, self.count,
                               bool(sw[k] == 0))
                q[k] += self.gamma * v
        return acts, q


class GameTreeAgent:
    """The game-tree fighter on the game API (agents.base.Agent). Records its decision time."""

    def __init__(self, depth: int = 2, style="infighter", gamma: float = 1.0, prune: bool = True,
                 name: str | None = None) -> None:
        self.depth = int(depth)
        self.style = as_style(style)
        self.gamma = gamma
        self.prune = prune
        self.name = name or f"gametree{depth}"
        self._search: GameTreeSearch | None = None
        self.decisions = 0
        self.decision_s = 0.0

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        if self._search is None or self._search.tables is not game.tables:
            self._search = GameTreeSearch(game.tables, self.style, self.depth, self.gamma, self.prune)

    def step(self, state, player: int) -> int:
        if self._search is None or self._search.tables is not state.game.tables:
            self.reset(state.game, player, np.random.default_rng(0))
        t = time.perf_counter()
        si, sf = to_sample(state.game.tables, state.world, player)
        a, _ = self._search.search(si, sf)
        self.decision_s += time.perf_counter() - t
        self.decisions += 1
        return a

    @property
    def events(self) -> int:
        return int(self._search.count[0]) if self._search is not None else 0
