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
the depth-(D-1) values where each action lands. Why: the graph's edges reproduce the simulator
exactly from each state's centroid, but a live state within the linking tolerance of a state
often has another best action than the centroid, and a state has edges for only part of its menu
(tests/test_ig_consistency.py). The table answer also presumes the live state is snapped onto the
state; an IGAgent snaps only after table answers (``Decision.edge >= 0``).

``first_ply="exact2"`` (opt-in) searches the first *two* plies exactly (every legal action, then
every answer of whoever decides next, the opponent minimising) and uses the graph's values only
at the leaves (igraph_fight.search): a game-tree search of depth 2 with the Interaction Graph as
its evaluation function. It is much stronger than the table against exact game-tree searches and
costs about a millisecond of CPU a decision instead of microseconds (figures: docs/results.md).

The policy table is an immutable object; ``set_style``/``set_depth`` build a new one in a worker
thread while the old one keeps answering, then replace the reference in one assignment, so a
reader sees either the old or the new table, never a mix. Each request records the settings it
wants (style, depth) over the latest *requested* ones, and the worker builds the newest settings
requested so far: ``set_style`` then ``set_depth`` in a row end with both, whatever their timing.

Input contract: everything a decision passes to the numba kernels is checked first, at the API
(``act``, ``peek``, ``locate``, ``menu_terms``, ``act_batch``), since the kernels index arrays
with the ids unchecked. An Observation must hold finite numbers with 0 <= r <= MAX_DISTANCE_M
and |theta| <= MAX_ANGLE_RAD, integer ids with 0 <= m_self, m_other < A (the library's actions),
0 <= f_other < frames of m_other, and 0 <= mask_other < 2 ** (strikes of m_other); anything else
(NaN or infinite values included: there is no fallback answer for them) raises an
ObservationError naming the field (and the row, for batches). Depth is an integer in
1..MAX_DEPTH and gamma a finite number in (0, 1].
"""
from __future__ import annotations

import threading
import time
import types
from collections import ChainMap
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit, prange

import motion_graph.rotations
import planner.rewards
from motion_graph.classify import KINDS
from planner import Policy, SearchGraph, Style, compute_policy, load_style
from planner.rewards import style_params

from igraph_fight.graph import InteractionGraph, load_graph
from igraph_fight.locate import (
    GRID_PER_UNIT, P_BST3, P_SCALARS, build_index, index_views, legal_row, locate_packed, nearest, nextset_ids,
    pack_index, part)
from igraph_fight import locate, search as search_module, sim
from igraph_fight.kernel_cache import drop_stale_caches
from igraph_fight.search import search
from igraph_fight.sim import expand_one

drop_stale_caches(__file__, [locate, search_module, sim, planner.rewards, motion_graph.rotations])


#: NPCController's first_ply choices (see the module docstring)
FIRST_PLY = ("table", "exact", "exact2")

#: Deepest min-max search a controller computes (decisions). The policy's time grows linearly with
#: the depth (on the default graph of 5 M edges: 0.3 s at depth 5, 0.55 s at 12) and gamma = 0.5
#: makes ply 12 weigh 0.05% of the first: deeper only blocks the policy worker.
MAX_DEPTH = 12
#: Largest distance r an Observation may hold (m): far beyond any arena, still exact in the
#: kernels' integer cell arithmetic.
MAX_DISTANCE_M = 1.0e6
#: Largest |theta_self|, |theta_other| an Observation may hold (rad; angles are wrapped to
#: [-pi, pi) inside, and beyond this the wrap loses precision).
MAX_ANGLE_RAD = 1.0e6


class ObservationError(ValueError):
    """An observation (or a row of a batch) outside the controller's input contract (module
    docstring). ``field`` names the offending field, ``row`` the batch row (None for one
    observation), ``value`` what it held."""

    def __init__(self, field: str, problem: str, value: object = None, row: int | None = None) -> None:
        self.field = field
        self.problem = problem
        self.value = value
        self.row = row
        where = f"observation {field}" + (f" (row {row})" if row is not None else "")
        got = "" if value is None else f", got {value!r}"
        super().__init__(f"{where}: {problem}{got}")


def _real(x, field: str) -> float:
    """x as a float if it is a real number (not bool), else an ObservationError."""
    if isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool):
        try:
            return float(x)
        except OverflowError:
            pass
    raise ObservationError(field, "must be a real number", x)


def _integer(x, field: str) -> int:
    """x as an int if it is an integer (not bool), else an ObservationError."""
    if isinstance(x, (int, np.integer)) and not isinstance(x, bool):
        return int(x)
    raise ObservationError(field, "must be an integer id", x)


def observation_checker(n_frames, n_strikes):
    """The contract check of one Observation for a library with ``n_frames[a]`` frames and
    ``n_strikes[a]`` strikes per action: a function obs -> (r, theta_self, theta_other, m_self,
    m_other, f_other, mask_other) as Python floats and ints, raising ObservationError. Plain
    Python comparisons on values bound in its closure: a fraction of a microsecond."""
    nf = [int(x) for x in n_frames]
    lim = [1 << int(k) for k in n_strikes]
    A = len(nf)
    R, T = MAX_DISTANCE_M, MAX_ANGLE_RAD

    def check(obs) -> tuple:
        if type(obs) is Observation:
            r, ts, to, ms, mo, fo, mk = obs
        else:
            try:
                r, ts, to, ms, mo, fo = obs.r, obs.theta_self, obs.theta_other, obs.m_self, obs.m_other, obs.f_other
                mk = getattr(obs, "mask_other", 0)
            except AttributeError:
                raise ObservationError("observation", "must be an Observation (r, theta_self, theta_other, m_self, "
                                                      "m_other, f_other, mask_other)", type(obs).__name__) from None
        if type(r) is not float:
            r = _real(r, "r")
        if type(ts) is not float:
            ts = _real(ts, "theta_self")
        if type(to) is not float:
            to = _real(to, "theta_other")
        if type(ms) is not int:
            ms = _integer(ms, "m_self")
        if type(mo) is not int:
            mo = _integer(mo, "m_other")
        if type(fo) is not int:
            fo = _integer(fo, "f_other")
        if type(mk) is not int:
            mk = _integer(mk, "mask_other")
        if not 0.0 <= r <= R:
            raise ObservationError("r", f"must be a finite distance in [0, {R:g}] m", r)
        if not -T <= ts <= T:
            raise ObservationError("theta_self", f"must be a finite angle within +-{T:g} rad", ts)
        if not -T <= to <= T:
            raise ObservationError("theta_other", f"must be a finite angle within +-{T:g} rad", to)
        if not 0 <= ms < A:
            raise ObservationError("m_self", f"must be an action id in [0, {A})", ms)
        if not 0 <= mo < A:
            raise ObservationError("m_other", f"must be an action id in [0, {A})", mo)
        if not 0 <= fo < nf[mo]:
            raise ObservationError("f_other", f"must be a frame of action {mo}, in [0, {nf[mo]})", fo)
        if not 0 <= mk < lim[mo]:
            raise ObservationError("mask_other", f"must hold only the bits of action {mo}'s strikes, in "
                                                 f"[0, {lim[mo]})", mk)
        return r, ts, to, ms, mo, fo, mk

    return check


def check_depth(depth) -> int:
    """``depth`` as an int if it is an integer in 1..MAX_DEPTH, else a ValueError."""
    if not isinstance(depth, (int, np.integer)) or isinstance(depth, bool) or not 1 <= depth <= MAX_DEPTH:
        raise ValueError(f"depth must be an integer in 1..{MAX_DEPTH}, got {depth!r}")
    return int(depth)


def check_gamma(gamma) -> float | None:
    """``gamma`` as a float if it is a finite number in (0, 1] (None: the planner's default), else a
    ValueError."""
    if gamma is None:
        return None
    ok = isinstance(gamma, (int, float, np.integer, np.floating)) and not isinstance(gamma, bool)
    if not ok or not 0.0 < float(gamma) <= 1.0:
        raise ValueError(f"gamma must be a finite number in (0, 1], got {gamma!r}")
    return float(gamma)


class Observation(NamedTuple):
    """The live coupled state from the NPC's side, at the instant it must choose.

    r: pelvis ground distance (m); theta_self / theta_other: angle between the NPC's (the
    opponent's) facing and the line to the other (rad); m_self: the action the NPC just finished;
    m_other, f_other: the opponent's action and frame; mask_other: bits of the opponent's strikes
    already resolved whose window is still open (bit k: m_other's k-th strike; 0 if unknown).
    The controller checks every field (the module docstring's input contract; ObservationError).
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



@njit(cache=True)
def _decide(pi, pf, pc, best_ea, q_me, r, ts, to, m_self, m_other, f_other, mask):
    """Table decision: (action, state, normalised distance, off_graph, edge)."""
    s, d2, level, off = locate_packed(pi, pf, pc, r, ts, to, m_self, m_other, f_other, mask)
    e, a = _choose(s, best_ea, q_me, part(pi, 7), part(pi, 8), legal_row(pi, m_self))
    if a < 0:
        a = part(pi, 6)[part(pi, 5)[m_self]]
    return a, s, np.sqrt(d2), off, e


#: columns of _menu_terms' rows
MT_ACTION, MT_POS, MT_GIVEN, MT_RECEIVED, MT_DEF, MT_VALUE = 0, 1, 2, 3, 4, 5
MT_FT = 6          # then the event's raw features sim.FT_* (16 columns)
N_MT = MT_FT + 16


@njit(cache=True)
def _menu_terms(T, pi, pf, pc, V_me_next, V_opp_next, pref, rw, r, ts, to, m_self, m_other, f_other, mask, out):
    """The exact one-step terms of every legal action from a live state: one simulated event per
    action (sim.expand_one), its Eq. 4 reward split into the positional cost, the damage-given
    term (w_dmg_given * kind preference * damage), the damage-received term (w_dmg_received *
    damage), the defence term, and gamma times the policy's depth-(D-1) value of the graph state
    nearest to where it lands; then the event's raw features. Row j of ``out`` (MT_* columns) for
    the j-th action of Next(m_self); returns the number of rows. rw as _lookahead's."""
    rowsw, ctabw, rowsk, ctabk, xf, xi, _ = index_views(pi, pf, pc)
    sc = part(pi, P_SCALARS)
    nextset_of = part(pi, 3)
    key_args = part(pi, 4)
    menu_off = part(pi, 5)
    menu_ids = part(pi, 6)
    kinds = part(pi, 9)
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
        swap = expand_one(T, si, sf, a, ci, cf, ft, S, act, frm, msk, stats)
        rr = ft[2] if use_mean else ft[1]          # sim.FT_R_MEAN / sim.FT_R
        dd = rr - d_p
        pos = w_theta * ft[3] * ft[3] + w_d * dd * dd
        if per_second:
            pos *= ft[0] / fps
        k = kinds[a]
        pk = pref[k] if 0 <= k < npref else 1.0
        ns = nextset_of[ci[0]]
        key = (ns * key_args[0] + ci[1]) * key_args[1] + ci[3]
        s, _, _ = nearest(rowsw, ctabw, rowsk, ctabk, part(pi, 0), sc[1], sc[2], pf[4], xf, xi, part(pi, 1),
                           part(pi, 2), part(pi, P_BST3), key, ns, ci[2], sc[0], cf[0], cf[1], cf[2], pf[0], pf[1])
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
    """Off-graph decision: simulate every legal action once from the live state (sim.expand_one)
    and score it by its Eq. 4 reward for the decider (the W_me of planner.rewards) plus gamma
    times the policy's depth-(D-1) value of the graph state nearest to where it lands
    (_menu_terms). rw = (d_p, w_theta, w_d, w_dmg_given, w_dmg_received, w_def, per_second,
    distance is "mean", gamma, fps). Returns (best action, its score); (-1, 0) without legal actions."""
    menu_off = part(pi, 5)
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
            expected instead of kinematically predicted (tracker.bouts.hit_model). Same length as the
            graph's edges.
    """

    def __init__(self, graph: InteractionGraph | str | Path, library=None, style: Style | str | Path = "balanced",
                 depth: int = 5, gamma: float | None = None, stochastic: bool = False, temperature: float = 0.5,
                 usage_penalty: float = 0.0, seed: int = 0, offgraph: str = "lookahead",
                 first_ply: str = "table", edge_features: dict | None = None) -> None:
        depth = check_depth(depth)
        gamma = check_gamma(gamma)
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
        # the graph's arrays with this controller's overrides on top (a compact file's arrays are
        # decoded on first use: only those the policy reads)
        self._arrays = ChainMap({}, a)
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
        # Lookup index (see build_index): states bucketed by (Next-set id, M_other, mask, F_other)
        # and by Next-set id, each bucket sorted by r.
        A = library.n_actions
        self._nextset_of = nextset_ids(library)
        # every mask an observation may hold (< 2 ** strikes of M_other) gets a key of its own
        n_bits = int(np.diff(np.asarray(library.strike_offsets, dtype=np.int64)).max()) if A else 0
        mask_mod = max(int(a["state_mask_other"].max()) + 2 if len(a["state_mask_other"]) else 2, 1 << n_bits)
        self._key_args = np.array([A + 1, mask_mod], dtype=np.int64)
        ix, ix_parts, cell_w = build_index(a, A, mask_mod, self.f0)
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
        from igraph_fight.sim import SimTables
        self.tables = SimTables.from_library(library, graph.sim_params())
        self._T = self.tables.kernel_tuple()
        self._kinds = np.asarray(self.tables.kinds, dtype=np.int64)
        self._kinds32 = self._kinds.astype(np.int32)
        self._n_frames = np.asarray(self.tables.n_frames, dtype=np.int64)
        self._mask_limit = np.left_shift(np.int64(1), np.diff(np.asarray(self.tables.strike_offsets, dtype=np.int64)))
        self._check = observation_checker(self._n_frames, np.diff(np.asarray(self.tables.strike_offsets)))
        self._max_menu = int(max(1, np.diff(self._menu_off).max())) if A else 1
        self._count = np.zeros(2, dtype=np.int64)  # exact2: events simulated, nodes expanded
        self._pi, self._pf, self._pc = pack_index(
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
        # the latest requested settings (style, depth, gamma) and their request number; the worker
        # builds the newest (set_style / set_depth)
        self._want = (style_obj, depth, gamma)
        self._want_seq = 0
        self._built_seq = 0
        self._table = self._compute(style_obj, depth, gamma)

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
        depth = check_depth(depth)
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
    def edge_scores(self) -> np.ndarray:
        """The live table's score of every edge for the controlled fighter deciding (E,) float32:
        W_me + gamma * V_next(target), what a table decision compares among legal edges."""
        return self._table.q_me

    @property
    def locate_params(self) -> dict:
        """What the nearest-state search computes with: f0, inv_sr2 = 1 / s_r^2, inv_st2 =
        1 / s_theta^2, the linking tolerances tol_r (m) and tol_theta (rad), and the state key's
        factors key_a1 = A + 1 and mask_mod (key = (Next-set id * key_a1 + M_other) * mask_mod + mask),
        and grid_per_unit: distances and angles are compared rounded to multiples of its inverse
        (igraph_fight.locate.on_grid)."""
        return {"grid_per_unit": GRID_PER_UNIT, "f0": self.f0, "inv_sr2": self._inv_sr2, "inv_st2": self._inv_st2,
                "tol_r": self.tol_r,
                "tol_theta": self.tol_theta, "key_a1": int(self._key_args[0]), "mask_mod": int(self._key_args[1])}

    @property
    def nextset_of(self) -> np.ndarray:
        """Next-set id of every library action (A,) (igraph_fight.locate.nextset_ids)."""
        return self._nextset_of

    @property
    def packed_index(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The nearest-state index as the kernels take it (igraph_fight.locate: pi, pf, pc)."""
        return self._pi, self._pf, self._pc

    @property
    def kernel_tables(self) -> tuple:
        """The kinematic simulator's tables as the kernels take them (SimTables.kernel_tuple())."""
        return self._T

    @property
    def kind_names(self) -> list[str]:
        """The kind names the graph's kind indices refer to."""
        return [str(k) for k in self._arrays["kinds_table"]]

    def _build_latest(self, t_request: float) -> _Table:
        """Worker job of a request: build the newest requested settings, unless an earlier job
        already built them (requests made while a table is computed are served by one build)."""
        with self._lock:
            want, seq = self._want, self._want_seq
        if seq <= self._built_seq:
            return self._table
        table = self._compute(*want)
        self._table = table  # one reference assignment: atomic for readers
        self._built_seq = seq
        self.last_swap_ms = (time.perf_counter() - t_request) * 1e3
        return table

    def _request(self, style: Style | None = None, depth: int | None = None, wait: bool = False) -> Future:
        """Record the wanted settings over the latest requested ones and queue a build."""
        with self._lock:
            st, d, g = self._want
            self._want = (style if style is not None else st, depth if depth is not None else d, g)
            self._want_seq += 1
        fut = self._executor.submit(self._build_latest, time.perf_counter())
        if wait:
            fut.result()
        return fut

    def set_style(self, style: Style | str | Path, wait: bool = False) -> Future:
        """Recompute the policy for a new style in the background (at the depth last requested);
        the old table answers meanwhile. Returns a Future whose result is a live table with this
        style (the newest requested settings: later requests may be in it too); ``wait=True``
        blocks until it is live. A bad style raises planner.StyleError here."""
        st = style if isinstance(style, Style) else load_style(style)
        return self._request(style=st, wait=wait)

    def set_depth(self, depth: int, wait: bool = False) -> Future:
        """Change the search depth (strength, an integer in 1..MAX_DEPTH: a ValueError otherwise),
        with the style last requested; recomputed in the background like set_style."""
        return self._request(depth=check_depth(depth), wait=wait)

    # ----- decisions ------------------------------------------------------------------------
    def _lookahead(self, table: _Table, ob: tuple) -> tuple[int, float]:
        """One exact simulated event per legal action + the graph value where it lands (``ob``:
        a checked observation)."""
        a, q = _lookahead(self._T, self._pi, self._pf, self._pc, *table.la, *ob)
        return int(a), float(q)

    def menu_terms(self, obs: Observation) -> np.ndarray:
        """The exact one-step terms of every legal action from ``obs`` under the live style: one
        row per action of Next(m_self), columns MT_* (action, positional cost, damage-given,
        damage-received and defence terms, gamma * graph value where it lands, then the event's
        raw sim.FT_* features). Score = -pos + given - received + def + value (what the
        lookahead maximises); callers may replace terms, e.g. with physically measured hit odds.
        ObservationError for an observation outside the input contract."""
        ob = self._check(obs)
        table = self._table
        m = ob[3]
        out = np.zeros((int(self._menu_off[m + 1] - self._menu_off[m]), N_MT))
        _menu_terms(self._T, self._pi, self._pf, self._pc, *table.la, *ob, out)
        return out

    def _exact2(self, table: _Table, ob: tuple) -> tuple[int, float]:
        """Two exact plies + the graph's values at the leaves (``first_ply="exact2"``; ``ob``: a
        checked observation)."""
        r, ts, to, ms, mo, fo, mk = ob
        if self._menu_off[ms + 1] <= self._menu_off[ms]:
            return -1, 0.0
        si = np.array([ms, mo, fo, mk], dtype=np.int64)
        sf = np.array([r, ts, to], dtype=np.float64)
        V_me, V_opp, pref, rw = table.la
        q, j = search(self._T, self._menu_off, self._menu_ids, self._kinds32, table.style_params, pref,
                      float(self.tables.fps), si, sf, 2, float(rw[8]), True, self._max_menu, self._count, True,
                      self._pi, self._pf, self._pc, V_me, V_opp)
        if j < 0:
            return -1, 0.0
        return int(self._menu_ids[self._menu_off[ms] + j]), float(q)

    def act(self, obs: Observation) -> Decision:
        """The action for one live state (see the module docstring). ObservationError (naming the
        field) for an observation outside the input contract: ids out of range, NaN or infinite
        numbers, wrong types; no action is answered for those."""
        return self._choose(obs, commit=True)

    def peek(self, obs: Observation) -> int:
        """The action act() would choose for ``obs``, without side effects: the best edge where a
        stochastic controller would spin its roulette, and no edge usage counted (a guess at a
        future decision, e.g. a physics bout's foresight for a tracker's look-ahead)."""
        return int(self._choose(obs, commit=False).action)

    def _choose(self, obs: Observation, commit: bool) -> Decision:
        ob = self._check(obs)
        table = self._table  # one read: a consistent snapshot
        a, s, d, off, e = _decide(self._pi, self._pf, self._pc, table.best_ea, table.q_me, *ob)
        if self.first_ply == "exact2":
            xa, _ = self._exact2(table, ob)
            if xa >= 0:
                a, e = xa, -1
        elif self.first_ply == "exact" or (off and self.offgraph == "lookahead"):
            la, _ = self._lookahead(table, ob)
            if la >= 0:
                a, e = la, -1
        elif self.stochastic and s >= 0 and commit:
            re = self._roulette(table, s, ob[3])
            if re >= 0:
                e, a = re, int(self._edge_action[re])
        if e >= 0 and self.usage_penalty > 0.0 and commit:
            self._usage[e] = self._usage.get(e, 0) + 1
        return Decision(a, s, d, off, e)

    def locate(self, obs: Observation) -> tuple[int, float, bool]:
        """The graph state a live state maps to, as act() finds it: (state, normalised distance,
        off_graph). No decision, no lookahead; state -1 only for an empty graph. ObservationError
        for an observation outside the input contract."""
        s, d2, _, off = locate_packed(self._pi, self._pf, self._pc, *self._check(obs))
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
        act() does; the default answers them from the nearest state's table entry. The arrays are
        checked as act() checks one observation (1-d, equal lengths, real numbers for r and the
        angles, integer dtypes for the ids; ObservationError naming the field and the first bad row)."""
        cols = self._check_batch(r, theta_self, theta_other, m_self, m_other, f_other, mask_other)
        n = len(cols[0])
        out = np.empty((n, 4), dtype=np.int64)
        dist = np.empty(n)
        table = self._table
        kernel = _act_batch if n >= PARALLEL_MIN else _act_batch_serial
        kernel(self._T, self._pi, self._pf, self._pc, table.best_ea, table.q_me, *table.la,
               bool(lookahead and self.offgraph == "lookahead"), *cols, out, dist)
        return out[:, 0], out[:, 1], out[:, 3].astype(bool)

    def _check_batch(self, r, theta_self, theta_other, m_self, m_other, f_other, mask_other) -> list[np.ndarray]:
        """The batch arrays as the kernel takes them (float64 x 3, int64 x 4), checked against the
        input contract (module docstring); ObservationError naming the field and the first bad row."""
        names = ("r", "theta_self", "theta_other", "m_self", "m_other", "f_other", "mask_other")
        raw = [r, theta_self, theta_other, m_self, m_other, f_other, mask_other]
        arrs = []
        for k, (name, x) in enumerate(zip(names, raw)):
            if x is None and name == "mask_other":
                arrs.append(None)
                continue
            try:
                a = np.asarray(x)
            except (TypeError, ValueError) as e:
                raise ObservationError(name, f"must be a 1-d array ({e})") from None
            if a.ndim != 1:
                raise ObservationError(name, f"must be a 1-d array, got shape {a.shape}")
            kind = "biuf" if k < 3 else "iu"
            if a.dtype.kind not in kind or a.dtype.kind == "b":
                want = "real numbers" if k < 3 else "integers (an integer dtype)"
                raise ObservationError(name, f"must hold {want}, got dtype {a.dtype}")
            arrs.append(a)
        n = len(arrs[0])
        for name, a in zip(names, arrs):
            if a is not None and len(a) != n:
                raise ObservationError(name, f"has {len(a)} rows, r has {n} (the arrays must have equal lengths)")
        if arrs[6] is None:
            arrs[6] = np.zeros(n, dtype=np.int64)

        def first_bad(name: str, ok: np.ndarray, problem: str) -> None:
            if not ok.all():
                i = int(np.flatnonzero(~ok)[0])
                raise ObservationError(name, problem, raw_value(name, i), row=i)

        def raw_value(name: str, i: int):
            v = arrs[names.index(name)][i]
            return v.item() if hasattr(v, "item") else v

        A = len(self._n_frames)
        with np.errstate(invalid="ignore"):
            first_bad("r", (arrs[0] >= 0.0) & (arrs[0] <= MAX_DISTANCE_M),
                      f"must be a finite distance in [0, {MAX_DISTANCE_M:g}] m")
            for k in (1, 2):
                first_bad(names[k], np.abs(arrs[k]) <= MAX_ANGLE_RAD,
                          f"must be a finite angle within +-{MAX_ANGLE_RAD:g} rad")
        for k in (3, 4):
            first_bad(names[k], (arrs[k] >= 0) & (arrs[k] < A), f"must be an action id in [0, {A})")
        mo = arrs[4].astype(np.int64)
        first_bad("f_other", (arrs[5] >= 0) & (arrs[5] < self._n_frames[mo]),
                  "must be a frame of m_other, in [0, frames of m_other)")
        first_bad("mask_other", (arrs[6] >= 0) & (arrs[6] < self._mask_limit[mo]),
                  "must hold only the bits of m_other's strikes, in [0, 2 ** strikes of m_other)")
        return [np.ascontiguousarray(a, dtype=np.float64) for a in arrs[:3]] + \
               [np.ascontiguousarray(a, dtype=np.int64) for a in arrs[3:]]

    def close(self) -> None:
        self._executor.shutdown(wait=True)




def observe(state, player: int) -> Observation:
    """Observation of ``player`` in a game.FightState (at its decision instant)."""
    from igraph_fight import sim
    from igraph_fight.state import to_sample
    si, sf = to_sample(state.game.tables, state.world, player)
    return Observation(float(sf[sim.SF_R]), float(sf[sim.SF_TH_SELF]), float(sf[sim.SF_TH_OTHER]),
                       int(si[sim.SI_MSELF]), int(si[sim.SI_MOTHER]), int(si[sim.SI_FOTHER]), int(si[sim.SI_MASK]))