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

The policy table is an immutable object; ``set_style``/``set_depth`` build a new one in a worker
thread while the old one keeps answering, then replace the reference in one assignment, so a
reader sees either the old or the new table, never a mix.
"""
from __future__ import annotations

import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit, prange

from motion_graph.classify import KINDS
from planner import Policy, SearchGraph, Style, compute_policy, load_style

from .graph import InteractionGraph, load_graph


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
    best_me: np.ndarray      # (S,) edge
    q_me: np.ndarray         # (E,) float32 edge score for the controlled fighter deciding
    style: str
    depth: int
    version: int
    style_obj: Style


@njit(cache=True)
def _wrap(a):
    return a - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))


@njit(cache=True)
def _nearest(keys, order, by_next_keys, by_next_order, st_r, st_ts, st_to, st_f, key, nextset, f_other, f0,
             r, ts, to, inv_sr2, inv_st2):
    """Nearest state: compatible group first, then same key any frame, same menu, anywhere.
    Returns (state, squared normalised distance, level 0..3)."""
    for level in range(4):
        if level <= 1:
            lo = np.searchsorted(keys, key, side="left")
            hi = np.searchsorted(keys, key, side="right")
            idx = order
        elif level == 2:
            lo = np.searchsorted(by_next_keys, nextset, side="left")
            hi = np.searchsorted(by_next_keys, nextset, side="right")
            idx = by_next_order
        else:
            lo = 0
            hi = len(order)
            idx = order
        best = -1
        bd = np.inf
        for k in range(lo, hi):
            s = idx[k]
            if level == 0 and abs(st_f[s] - f_other) >= f0:
                continue
            dr = st_r[s] - r
            d1 = _wrap(st_ts[s] - ts)
            d2 = _wrap(st_to[s] - to)
            d = dr * dr * inv_sr2 + (d1 * d1 + d2 * d2) * inv_st2
            if d < bd:
                bd = d
                best = s
        if best >= 0:
            return best, bd, level
    return -1, np.inf, 4


@njit(cache=True)
def _choose(s, best_me, q_me, offsets, edge_action, legal_row):
    """Best edge of s if its action is legal, else the best-scoring legal edge; (-1, -1) if none."""
    if s < 0:
        return -1, -1
    e = best_me[s]
    if e >= 0 and legal_row[edge_action[e]]:
        return e, edge_action[e]
    be = -1
    bq = -np.inf
    for k in range(offsets[s], offsets[s + 1]):
        if legal_row[edge_action[k]] and q_me[k] > bq:
            bq = q_me[k]
            be = k
    if be >= 0:
        return be, edge_action[be]
    return -1, -1


@njit(cache=True)
def _act_one(keys, order, by_next_keys, by_next_order, st_r, st_ts, st_to, st_f, nextset_of, key_of_args,
             f0, inv_sr2, inv_st2, tol_r, tol_t, best_me, q_me, offsets, edge_action, legal, menu_off, menu_ids,
             r, ts, to, m_self, m_other, f_other, mask, out):
    ns = nextset_of[m_self]
    key = (ns * key_of_args[0] + m_other) * key_of_args[1] + mask
    s, d2, level = _nearest(keys, order, by_next_keys, by_next_order, st_r, st_ts, st_to, st_f, key, ns, f_other,
                            f0, r, ts, to, inv_sr2, inv_st2)
    e, a = _choose(s, best_me, q_me, offsets, edge_action, legal[m_self])
    if a < 0:
        a = menu_ids[menu_off[m_self]]
    off = level > 0
    if s >= 0 and level == 0:
        off = (abs(st_r[s] - r) > tol_r or abs(_wrap(st_ts[s] - ts)) > tol_t or abs(_wrap(st_to[s] - to)) > tol_t)
    out[0] = a
    out[1] = s
    out[2] = e
    out[3] = 1 if off else 0
    return np.sqrt(d2)


@njit(cache=True, parallel=True)
def _act_batch(keys, order, by_next_keys, by_next_order, st_r, st_ts, st_to, st_f, nextset_of, key_of_args,
               f0, inv_sr2, inv_st2, tol_r, tol_t, best_me, q_me, offsets, edge_action, legal, menu_off, menu_ids,
               r, ts, to, m_self, m_other, f_other, mask, out, dist):
    for i in prange(len(r)):
        dist[i] = _act_one(keys, order, by_next_keys, by_next_order, st_r, st_ts, st_to, st_f, nextset_of,
                           key_of_args, f0, inv_sr2, inv_st2, tol_r, tol_t, best_me, q_me, offsets, edge_action,
                           legal, menu_off, menu_ids, r[i], ts[i], to[i], m_self[i], m_other[i], f_other[i],
                           mask[i], out[i])


def _edge_q(policy: Policy, offsets: np.ndarray, target: np.ndarray, swap: np.ndarray) -> np.ndarray:
    """Score of every edge for the controlled fighter deciding: W_me + gamma * V_next(target)."""
    v_next = np.where(swap.astype(bool), policy.V_opp_next[target], policy.V_me_next[target])
    return (policy.W_me + np.float32(policy.gamma) * v_next).astype(np.float32)


class NPCController:
    """Runtime controller of Interaction Graph fighters (thread-safe reads; one writer thread).

    Args:
        graph: the Interaction Graph (or a path to its file).
        library: the graph's action library (needed for menus); default: the one embedded in or
            next to the graph (``graph.load_library()``).
        style: a planner Style, preset name or style file.
        depth: min-max depth (decisions); gamma: discount (default 1 up to depth 5, else 0.95).
        stochastic: roulette selection among the state's edges instead of the best edge.
        temperature: softmax temperature of the roulette (reward units); usage_penalty: divides the
            probability of an edge by (1 + penalty * times used) (per controller).
        seed: seed of the roulette's random generator.
    """

    def __init__(self, graph: InteractionGraph | str | Path, library=None, style: Style | str | Path = "balanced",
                 depth: int = 5, gamma: float | None = None, stochastic: bool = False, temperature: float = 0.5,
                 usage_penalty: float = 0.0, seed: int = 0, offgraph: str = "lookahead") -> None:
        if offgraph not in ("lookahead", "nearest"):
            raise ValueError("offgraph must be 'lookahead' or 'nearest'")
        self.offgraph = offgraph
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
        opts = graph.header.get("options", {})
        self.f0 = int(opts.get("f0", 3))
        s_r = float(opts.get("s_r_m", 0.5))
        s_t = float(opts.get("s_theta_rad", np.pi / 6))
        self._inv_sr2, self._inv_st2 = 1.0 / s_r ** 2, 1.0 / s_t ** 2
        self.tol_r = float(opts.get("link_tol_r_m", 0.1))
        self.tol_theta = float(opts.get("link_tol_theta_rad", np.radians(20)))
        # Lookup index: states sorted by (Next-set id, M_other, mask) and by Next-set id alone.
        A = library.n_actions
        self._nextset_of = _nextset_ids(library)
        mask_mod = int(a["state_mask_other"].max()) + 2 if len(a["state_mask_other"]) else 2
        self._key_args = np.array([A + 1, mask_mod], dtype=np.int64)
        key = (a["state_nextset"].astype(np.int64) * (A + 1) + a["state_m_other"]) * mask_mod + a["state_mask_other"]
        self._order = np.argsort(key, kind="stable").astype(np.int64)
        self._keys = key[self._order]
        nk = a["state_nextset"].astype(np.int64)
        self._by_next_order = np.argsort(nk, kind="stable").astype(np.int64)
        self._by_next_keys = nk[self._by_next_order]
        self._st = tuple(np.ascontiguousarray(a[k], dtype=np.float64) for k in
                         ("state_r", "state_theta_self", "state_theta_other")) + (a["state_f_other"].astype(np.int64),)
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
        from .sim import SimParams, SimTables
        sim_opts = graph.header.get("options", {}).get("sim")
        self.tables = SimTables.from_library(library, SimParams(**sim_opts) if sim_opts else SimParams())
        self._T = self.tables.kernel_tuple()
        self.stochastic = stochastic
        self.temperature = float(temperature)
        self.usage_penalty = float(usage_penalty)
        self._usage = np.zeros(len(self._edge_action), dtype=np.float64)
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
        g = float(gamma) if gamma is not None else (1.0 if depth <= 5 else 0.95)
        pol = compute_policy(self._arrays, style, depth, g, search_graph=self._search_graph)
        q = _edge_q(pol, self._offsets, self._target, self._swap)
        with self._lock:
            self._version += 1
            v = self._version
        return _Table(pol, pol.best_me.astype(np.int64), q, style.name, depth, v, style)

    @property
    def style(self) -> str:
        return self._table.style

    @property
    def depth(self) -> int:
        return self._table.depth

    @property
    def policy(self) -> Policy:
        return self._table.policy

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
    def _args(self, table: _Table) -> tuple:
        return (self._keys, self._order, self._by_next_keys, self._by_next_order, *self._st, self._nextset_of,
                self._key_args, self.f0, self._inv_sr2, self._inv_st2, self.tol_r, self.tol_theta, table.best_me,
                table.q_me, self._offsets, self._edge_action, self._legal, self._menu_off, self._menu_ids)

    def act(self, obs: Observation) -> Decision:
        """The action for one live state (see the module docstring)."""
        table = self._table  # one read: a consistent snapshot
        out = np.empty(4, dtype=np.int64)
        d = _act_one(*self._args(table), float(obs.r), float(obs.theta_self), float(obs.theta_other),
                     int(obs.m_self), int(obs.m_other), int(obs.f_other), int(obs.mask_other), out)
        if out[3] and self.offgraph == "lookahead":
            a, v = self._lookahead(table, obs)
            if a >= 0:
                out[0], out[2] = a, -1
        elif self.stochastic and out[1] >= 0:
            e = self._roulette(table, int(out[1]), int(obs.m_self))
            if e >= 0:
                out[2], out[0] = e, self._edge_action[e]
        if out[2] >= 0:
            self._usage[out[2]] += 1
        return Decision(int(out[0]), int(out[1]), float(d), bool(out[3]), int(out[2]))

    def _lookahead(self, table: _Table, obs: Observation) -> tuple[int, float]:
        """One exact simulated event per legal action + the graph value where it lands."""
        from planner import edge_rewards

        from . import sim
        from .edge_features import edge_features

        acts = self.library.next(int(obs.m_self)).astype(np.int64)
        if len(acts) == 0:
            return -1, 0.0
        si = np.array([[obs.m_self, obs.m_other, obs.f_other, obs.mask_other]], dtype=np.int64)
        sf = np.array([[obs.r, obs.theta_self, obs.theta_other]], dtype=np.float64)
        ci, cf, ft, swap = sim.expand_samples(self._T, si, sf, np.zeros(len(acts), dtype=np.int64), acts)
        feats = edge_features(self.tables, np.full(len(acts), obs.m_other), acts, ft)
        w_me, _ = edge_rewards(feats, table.style_obj, list(KINDS))
        pol = table.policy
        q = np.empty(len(acts))
        out = np.empty(4, dtype=np.int64)
        args = self._args(table)
        for k in range(len(acts)):
            ns = self._nextset_of[ci[k, 0]]
            key = (ns * self._key_args[0] + ci[k, 1]) * self._key_args[1] + ci[k, 3]
            s, _, _ = _nearest(*args[:8], key, ns, ci[k, 2], self.f0, cf[k, 0], cf[k, 1], cf[k, 2],
                               self._inv_sr2, self._inv_st2)
            v = 0.0 if s < 0 else float(pol.V_opp_next[s] if swap[k] else pol.V_me_next[s])
            q[k] = w_me[k] + pol.gamma * v
        best = int(np.argmax(q))
        return int(acts[best]), float(q[best])

    def _roulette(self, table: _Table, s: int, m_self: int) -> int:
        from planner import roulette_probabilities
        lo, hi = int(self._offsets[s]), int(self._offsets[s + 1])
        legal = self._legal[m_self, self._edge_action[lo:hi]]
        if not legal.any():
            return -1
        q = table.q_me[lo:hi].astype(np.float64)[legal]
        idx = np.arange(lo, hi)[legal]
        p = roulette_probabilities(q, self.temperature, "softmax", self._usage[idx], self.usage_penalty)
        return int(idx[self._rng.choice(len(idx), p=p)])

    def act_batch(self, r, theta_self, theta_other, m_self, m_other, f_other, mask_other=None
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Decisions for many NPCs at once (arrays of equal length; deterministic best edges).
        Returns (actions, states, off_graph) arrays."""
        n = len(r)
        mask = np.zeros(n, dtype=np.int64) if mask_other is None else np.asarray(mask_other, dtype=np.int64)
        out = np.empty((n, 4), dtype=np.int64)
        dist = np.empty(n)
        _act_batch(*self._args(self._table), np.asarray(r, dtype=np.float64), np.asarray(theta_self, dtype=np.float64),
                   np.asarray(theta_other, dtype=np.float64), np.asarray(m_self, dtype=np.int64),
                   np.asarray(m_other, dtype=np.int64), np.asarray(f_other, dtype=np.int64), mask, out, dist)
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
