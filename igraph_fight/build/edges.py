"""Edges of the Interaction Graph (paper section 6.2): simulate, link within tolerance, prune.

For every state and every action of its decider's menu the coupled simulator runs from the
state's centroid to the next decision instant; the landing (a canonical sample seen by the next
decider) is linked to the nearest state (paper's normalised distance) among the compatible ones
(equal Next(M_self), M_other and mask, |F_other difference| < F0) within the linking tolerance.
No state within tolerance, or a landing out of the arena: no edge.

A state without edges is a dead end. Pruning removes dead ends and relinks the edges that
pointed at them to their next-nearest state within tolerance (each landing keeps its
``max_candidates`` nearest), until no dead end is left: the result is the largest set of states
closed under "has an edge into the set", which is unique, so it does not depend on the order of
removal. The pruning never re-simulates; the features of the surviving edges come from a second,
identical simulation pass (to keep memory small).
"""
from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from motion_graph.rotations import wrap_angle
from numba import njit

from igraph_fight import sim
from igraph_fight.build import spatial
from igraph_fight.build.columns import ColumnStore
from igraph_fight.build.explore import point_rows
from igraph_fight.sim import SF_R, SI_MSELF, SimTables


def menu_rows(tables: SimTables, m_self: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row, action) for every menu action of every row's M_self, rows in order, menus in order."""
    no, ni = tables.next_offsets, tables.next_ids
    counts = no[m_self + 1] - no[m_self]
    row = np.repeat(np.arange(len(m_self), dtype=np.int64), counts)
    local = np.arange(len(row)) - np.repeat(np.cumsum(counts) - counts, counts)
    return row, ni[np.repeat(no[m_self], counts) + local]


@njit(cache=True, nogil=True)
def _candidates(ix, G, cf, valid, tol_r, tol_t, cand, cnt, lo, hi):
    """Up to K nearest states within tolerance of each landing (row l: cand[l, :cnt[l]])."""
    d = np.empty(cand.shape[1])
    for l in range(lo, hi):
        cnt[l] = 0
        if valid[l]:
            cnt[l] = spatial.index_search(ix, G[l], cf[l, 0], cf[l, 1], cf[l, 2], tol_r, tol_t, True, cand[l], d)


@njit(cache=True)
def _prune(n_states, loff, off, cand, enabled):
    """Greatest set of states in which every state keeps an edge into the set. loff (S+1,):
    each state's landings; off (L+1,), cand: each landing's candidate states."""
    L = len(off) - 1
    alive_c = np.empty(L, dtype=np.int64)
    src = np.empty(L, dtype=np.int64)
    for s in range(n_states):
        for l in range(loff[s], loff[s + 1]):
            src[l] = s
    deg = np.zeros(n_states, dtype=np.int64)
    for l in range(L):
        alive_c[l] = off[l + 1] - off[l]
        if alive_c[l] > 0:
            deg[src[l]] += 1
    alive = np.ones(n_states, dtype=np.bool_)
    if not enabled:
        return alive, 0
    rcount = np.zeros(n_states + 1, dtype=np.int64)
    for i in range(len(cand)):
        rcount[cand[i] + 1] += 1
    roff = np.cumsum(rcount)
    rl = np.empty(len(cand), dtype=np.int64)
    fill = roff[:-1].copy()
    for l in range(L):
        for i in range(off[l], off[l + 1]):
            t = cand[i]
            rl[fill[t]] = l
            fill[t] += 1
    queue = np.empty(n_states, dtype=np.int64)
    qh = 0
    qt = 0
    for s in range(n_states):
        if deg[s] == 0:
            alive[s] = False
            queue[qt] = s
            qt += 1
    first_wave = qt
    while qh < qt:
        t = queue[qh]
        qh += 1
        for i in range(roff[t], roff[t + 1]):
            l = rl[i]
            alive_c[l] -= 1
            if alive_c[l] == 0:
                s = src[l]
                deg[s] -= 1
                if deg[s] == 0 and alive[s]:
                    alive[s] = False
                    queue[qt] = s
                    qt += 1
    return alive, qt - first_wave


@njit(cache=True)
def _first_alive(off, cand, alive, rows):
    """For each landing row: its nearest surviving candidate (candidates are nearest first)."""
    out = np.full(len(rows), -1, dtype=np.int64)
    for k in range(len(rows)):
        l = rows[k]
        for i in range(off[l], off[l + 1]):
            if alive[cand[i]]:
                out[k] = cand[i]
                break
    return out


@dataclass
class Edges:
    """Linked edges, ordered by source state then menu order (state numbering before pruning):
    src, action, target, swap (E,) and per-edge columns ``cols`` (feature name -> (E,) array:
    the sim.FT_* columns named in FEATURE_COLUMNS, plus snap_r (m) and snap_theta (rad));
    alive (S,) states kept; stats."""

    src: np.ndarray
    action: np.ndarray
    target: np.ndarray
    swap: np.ndarray
    cols: dict
    alive: np.ndarray
    stats: dict


FEATURE_COLUMNS = {"frames": sim.FT_FRAMES, "r": sim.FT_R, "r_mean": sim.FT_R_MEAN, "theta_self": sim.FT_TH_SELF,
                   "theta_other": sim.FT_TH_OTHER, "dmg_given": sim.FT_DMG_GIVEN,
                   "dmg_received": sim.FT_DMG_RECEIVED, "def_self": sim.FT_DEF_SELF, "def_other": sim.FT_DEF_OTHER}


def state_index(nextset: np.ndarray, st_si: np.ndarray, st_sf: np.ndarray, tol_r: float, tol_theta: float, f0: int,
                s_r: float = 0.5, s_theta: float = np.pi / 6) -> tuple:
    """The hash index of the states (spatial.new_index), ids = state numbers."""
    ix = spatial.new_index(len(st_si), tol_r, tol_theta, f0, s_r, s_theta)
    spatial.index_insert_many(ix, point_rows(nextset, st_si), np.ascontiguousarray(st_sf, dtype=np.float64))
    return ix


def landing_candidates(T: tuple, nextset: np.ndarray, ix: tuple, st_si: np.ndarray, st_sf: np.ndarray,
                       src: np.ndarray, action: np.ndarray, max_distance_m: float, tol_r: float, tol_theta: float,
                       max_candidates: int, workers: int | None = 1) -> tuple[np.ndarray, np.ndarray, int]:
    """Simulate the landings of (state src[k], action[k]) and find each one's up to
    ``max_candidates`` nearest states within tolerance. Returns (count per landing, the
    candidates of all landings in order (int32), landings out of the arena)."""
    K = int(max_candidates)
    ci, cf, _, _ = sim.expand_samples(T, st_si, st_sf, src, action, workers)
    valid = cf[:, SF_R] <= max_distance_m
    G = point_rows(nextset, ci)
    cand = np.empty((len(G), K), dtype=np.int64)
    cnt = np.empty(len(G), dtype=np.int64)
    sim.parallel_for(_candidates, len(G), workers, ix, G, cf, valid, float(tol_r), float(tol_theta), cand, cnt)
    return cnt, cand[np.arange(K)[None, :] < cnt[:, None]].astype(np.int32), int((~valid).sum())


def edge_features(T: tuple, st_si: np.ndarray, st_sf: np.ndarray, src: np.ndarray, action: np.ndarray,
                  tgt: np.ndarray, workers: int | None = 1) -> dict:
    """Re-simulate the edges (src[k], action[k]) -> tgt[k]: their FEATURE_COLUMNS, the snap of
    the landing onto its target (snap_r m, snap_theta rad) and swap."""
    _, cf, feat, swap = sim.expand_samples(T, st_si, st_sf, src, action, workers)
    out = {k: feat[:, c].copy() for k, c in FEATURE_COLUMNS.items()}
    out["snap_r"] = np.abs(cf[:, 0] - st_sf[tgt, 0])
    out["snap_theta"] = np.maximum(np.abs(wrap_angle(cf[:, 1] - st_sf[tgt, 1])),
                                   np.abs(wrap_angle(cf[:, 2] - st_sf[tgt, 2])))
    out["swap"] = swap
    return out


def link(tables: SimTables, st_si: np.ndarray, st_sf: np.ndarray, f0: int, tol_r: float, tol_theta: float,
         max_distance_m: float, prune: bool = True, s_r: float = 0.5, s_theta: float = np.pi / 6,
         max_candidates: int = 8, block: int = 20_000, progress: bool = False, workers: int = 1,
         backend=None, spill_dir: str | os.PathLike | None = None) -> Edges:
    """Simulate every (state, menu action), link within (tol_r m, tol_theta rad), prune dead ends.

    Each landing keeps its ``max_candidates`` nearest states within tolerance (nearest first): it
    links to the first that survives pruning. Two passes keep memory small: the first keeps only
    the candidates, the second re-simulates the landings that keep an edge (deterministic, hence
    identical) for their features, in blocks of states, each block written into columns allocated
    once at the final edge count (igraph_fight.build.columns; files mapped into memory under
    ``spill_dir`` when given, else arrays). The simulations run on ``backend``
    (igraph_fight.build.backend; None: this process on ``workers`` threads); pruning runs here.
    """
    S = len(st_si)
    K = int(max_candidates)
    T = tables.kernel_tuple()
    shards = backend.n_shards if backend is not None else 1
    block = max(1, min(int(block), -(-S // max(1, shards)))) if S else int(block)
    ix = None
    if backend is None or backend.name == "local":  # the state index lives in this process
        ix = state_index(tables.nextset, st_si, st_sf, tol_r, tol_theta, f0, s_r, s_theta)
    if backend is not None:
        backend.link_start(ix, st_si, st_sf, tol_r, tol_theta, f0, s_r, s_theta)
    no = tables.next_offsets
    m = st_si[:, SI_MSELF]
    loff = np.concatenate([[0], np.cumsum(no[m + 1] - no[m])]).astype(np.int64)
    L = int(loff[-1])
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=2 * S, desc="edges", unit="state", leave=False, dynamic_ncols=True)
    spans = [(b, min(S, b + block)) for b in range(0, S, block)]

    def tick(k: int) -> None:
        if bar is not None:
            bar.update(spans[k][1] - spans[k][0])

    blocks = []
    for b, e in spans:
        src, action = menu_rows(tables, m[b:e])
        blocks.append((src + b, action))
    if backend is None:
        answers = []
        for k, (src, action) in enumerate(blocks):
            answers.append(landing_candidates(T, tables.nextset, ix, st_si, st_sf, src, action, max_distance_m, tol_r,
                                              tol_theta, K, workers))
            tick(k)
    else:
        answers = backend.link_candidates(blocks, max_distance_m, tol_r, tol_theta, K, on_block=tick)
    del blocks
    counts = np.concatenate([a[0] for a in answers]).astype(np.int64) if answers else np.zeros(0, np.int64)
    n_out = int(sum(a[2] for a in answers))
    cand = np.concatenate([a[1] for a in answers]).astype(np.int64) if answers else np.zeros(0, dtype=np.int64)
    del answers
    off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    linked_before = int(np.sum(counts > 0))
    # linked edges per state (reduceat mishandles empty segments: use a cumulative sum)
    linked_cum = np.concatenate([[0], np.cumsum(counts > 0)])
    dead_before = float(np.mean(linked_cum[loff[1:]] - linked_cum[loff[:-1]] == 0)) if S and L else 1.0
    alive, cascaded = _prune(S, loff, off, cand, prune)
    # second pass, in blocks of states: landings of surviving states with a surviving candidate
    picked = []
    for b, e in spans:
        rows = np.arange(loff[b], loff[e])
        src = np.repeat(np.arange(b, e, dtype=np.int64), np.diff(loff[b:e + 1]))
        keep = alive[src]
        rows, src = rows[keep], src[keep]
        tgt = _first_alive(off, cand, alive, rows)
        keep = tgt >= 0
        rows, src, tgt = rows[keep], src[keep], tgt[keep]
        picked.append((src, tables.next_ids[no[m[src]] + rows - loff[src]], tgt))
    del cand, off, counts
    starts = np.concatenate([[0], np.cumsum([len(p[0]) for p in picked])]).astype(np.int64)
    E = int(starts[-1])
    store = ColumnStore(spill_dir)
    ids = [store.new(name, E, np.int64) for name in ("src", "action", "target")]
    blocks = []
    for k, p in enumerate(picked):
        lo, hi = starts[k], starts[k + 1]
        for col, x in zip(ids, p):
            col[lo:hi] = x
        blocks.append(tuple(np.asarray(col[lo:hi]) for col in ids))
    del picked
    swap = store.new("swap", E, np.int8)
    feat = {name: store.new(name, E, np.float64) for name in (*FEATURE_COLUMNS, "snap_r", "snap_theta")}

    def sink(k: int, cols: dict) -> None:
        lo, hi = starts[k], starts[k + 1]
        swap[lo:hi] = cols["swap"]
        for name, col in feat.items():
            col[lo:hi] = cols[name]
        tick(k)

    if backend is None:
        for k, (src, action, tgt) in enumerate(blocks):
            sink(k, edge_features(T, st_si, st_sf, src, action, tgt, workers))
    else:
        backend.link_features(blocks, sink)
        backend.link_stop()
    del blocks, ids, swap, feat
    if bar is not None:
        bar.close()
    cat = store.finish()
    stats = {"landings": L, "landings_linked_before_pruning": linked_before,
             "dead_end_fraction_before_pruning": dead_before, "pruned_by_cascade": int(cascaded),
             "out_of_arena_fraction": float(n_out / L) if L else 0.0}
    cols = {k: cat[k] for k in (*FEATURE_COLUMNS, "snap_r", "snap_theta")}
    return Edges(cat["src"], cat["action"], cat["target"], cat["swap"], cols, alive, stats)
