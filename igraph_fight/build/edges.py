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


def prune_dead_ends(n_states: int, loff: np.ndarray, off: np.ndarray, cand: np.ndarray,
                    enabled: bool) -> tuple[np.ndarray, int]:
    """(alive (S,) bool, states removed by the cascade after the first wave): the greatest set of
    states in which every state keeps an edge into the set. loff (S+1,): each state's landings;
    off (L+1,), cand: each landing's candidate states. The kernel's index buffers are int32
    where the counts allow (4 bytes per landing twice and per candidate once)."""
    L, C = len(off) - 1, len(cand)
    if C and (int(np.min(cand)) < 0 or int(np.max(cand)) >= n_states):
        raise ValueError("prune_dead_ends: a candidate outside the states")
    small = np.int32 if max(L, C, n_states) < np.iinfo(np.int32).max else np.int64
    alive_c = np.empty(L, dtype=small)
    src = np.empty(L, dtype=small)
    rl = np.empty(C if enabled else 0, dtype=small)
    return _prune(n_states, loff, off, cand, enabled, alive_c, src, rl)


@njit(cache=True)
def _prune(n_states, loff, off, cand, enabled, alive_c, src, rl):
    """prune_dead_ends' kernel (alive_c, src: (L,) buffers, rl: (C,) buffer)."""
    L = len(off) - 1
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


class MenuBlocks:
    """The first linking pass's blocks, made when asked for: block k is (src, action) of every menu
    action of the states in ``spans[k]`` (the whole list is never held)."""

    def __init__(self, tables: SimTables, m_self: np.ndarray, spans: list[tuple[int, int]]) -> None:
        self.tables, self.m, self.spans = tables, m_self, spans

    def __len__(self) -> int:
        return len(self.spans)

    def __getitem__(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        b, e = self.spans[k]
        src, action = menu_rows(self.tables, self.m[b:e])
        return src + b, action

    def __iter__(self):
        return (self[k] for k in range(len(self)))


def candidate_offsets(counts: np.ndarray, out: np.ndarray) -> None:
    """out[0] = 0, out[1:] = cumsum(counts), piece by piece (no temporary as long as counts)."""
    from igraph_fight.graph_compact import chunks
    out[0] = 0
    run = 0
    for lo, hi in chunks(len(counts)):
        c = np.cumsum(np.asarray(counts[lo:hi]), dtype=np.int64)
        c += run
        out[lo + 1:hi + 1] = c
        run = int(c[-1]) if len(c) else run


def link(tables: SimTables, st_si: np.ndarray, st_sf: np.ndarray, f0: int, tol_r: float, tol_theta: float,
         max_distance_m: float, prune: bool = True, s_r: float = 0.5, s_theta: float = np.pi / 6,
         max_candidates: int = 8, block: int = 20_000, progress: bool = False, workers: int = 1,
         backend=None, spill_dir: str | os.PathLike | None = None) -> Edges:
    """Simulate every (state, menu action), link within (tol_r m, tol_theta rad), prune dead ends.

    Each landing keeps its ``max_candidates`` nearest states within tolerance (nearest first): it
    links to the first that survives pruning. Two passes keep memory small: the first keeps only
    the candidates, the second re-simulates the landings that keep an edge (deterministic, hence
    identical) for their features, in blocks of states. Every per-landing and per-edge column (the
    candidates and their counts, the surviving edges, their features) is written block by block
    as the answers arrive (igraph_fight.build.columns: files mapped into memory under
    ``spill_dir`` when given, else arrays); the blocks sent out are made when sent. What this
    process holds besides: the states, the pruning's reverse index (4 bytes per landing twice and
    per candidate once: prune_dead_ends) and one block. The simulations run on ``backend``
    (igraph_fight.build.backend; None: this process on ``workers`` threads); pruning runs here.
    """
    import shutil
    from pathlib import Path

    from igraph_fight.graph_replay import state_runs
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

    cdir = Path(spill_dir) / "candidates" if spill_dir is not None else None
    cstore = ColumnStore(cdir)
    counts_col = cstore.appender("counts", np.int32)
    cand_col = cstore.appender("cand", np.int32)
    n_out = [0]

    def take(k: int, answer: tuple) -> None:
        counts_col.append(answer[0])
        cand_col.append(answer[1])
        n_out[0] += int(answer[2])
        tick(k)

    blocks = MenuBlocks(tables, m, spans)
    if backend is None:
        for k, (src, action) in enumerate(blocks):
            take(k, landing_candidates(T, tables.nextset, ix, st_si, st_sf, src, action, max_distance_m, tol_r,
                                       tol_theta, K, workers))
    else:
        backend.link_candidates(blocks, max_distance_m, tol_r, tol_theta, K, sink=take)
    ostore = ColumnStore(cdir)
    off = ostore.new("off", L + 1, np.int64)
    cc = cstore.finish()
    counts, cand = np.asarray(cc["counts"]), np.asarray(cc["cand"])
    candidate_offsets(counts, off)
    off = np.asarray(ostore.finish()["off"])
    linked_before, dead = 0, 0
    for s0, s1 in state_runs(loff, 1 << 21):  # linked landings per state, a run of states at a time
        l0, l1 = int(loff[s0]), int(loff[s1])
        cum = np.concatenate([[0], np.cumsum(counts[l0:l1] > 0)])
        linked_before += int(cum[-1])
        dead += int(np.sum(cum[loff[s0 + 1:s1 + 1] - l0] - cum[loff[s0:s1] - l0] == 0))
    dead_before = float(dead / S) if S and L else 1.0
    alive, cascaded = prune_dead_ends(S, loff, off, cand, prune)
    # second pass, in blocks of states: landings of surviving states with a surviving candidate
    store = ColumnStore(spill_dir)
    ids = [store.appender(name, np.int64) for name in ("src", "action", "target")]
    starts = [0]
    for b, e in spans:
        rows = np.arange(loff[b], loff[e])
        src = np.repeat(np.arange(b, e, dtype=np.int64), np.diff(loff[b:e + 1]))
        keep = alive[src]
        rows, src = rows[keep], src[keep]
        tgt = _first_alive(off, cand, alive, rows)
        keep = tgt >= 0
        rows, src, tgt = rows[keep], src[keep], tgt[keep]
        for col, x in zip(ids, (src, tables.next_ids[no[m[src]] + rows - loff[src]], tgt)):
            col.append(x)
        starts.append(starts[-1] + len(src))
    del cand, off, counts, cc
    if cdir is not None:
        shutil.rmtree(cdir, ignore_errors=True)
    E = int(starts[-1])
    id_cols = [np.asarray(col.finish()) for col in ids]
    fblocks = [tuple(col[starts[k]:starts[k + 1]] for col in id_cols) for k in range(len(spans))]
    swap = store.new("swap", E, np.int8)
    feat = {name: store.new(name, E, np.float64) for name in (*FEATURE_COLUMNS, "snap_r", "snap_theta")}

    def sink(k: int, cols: dict) -> None:
        lo, hi = starts[k], starts[k + 1]
        swap[lo:hi] = cols["swap"]
        for name, col in feat.items():
            col[lo:hi] = cols[name]
        tick(k)

    if backend is None:
        for k, (src, action, tgt) in enumerate(fblocks):
            sink(k, edge_features(T, st_si, st_sf, src, action, tgt, workers))
    else:
        backend.link_features(fblocks, sink)
        backend.link_stop()
    del fblocks, id_cols, ids
    if bar is not None:
        bar.close()
    cat = store.finish()
    stats = {"landings": L, "landings_linked_before_pruning": linked_before,
             "dead_end_fraction_before_pruning": dead_before, "pruned_by_cascade": int(cascaded),
             "out_of_arena_fraction": float(n_out[0] / L) if L else 0.0}
    cols = {k: cat[k] for k in (*FEATURE_COLUMNS, "snap_r", "snap_theta")}
    return Edges(cat["src"], cat["action"], cat["target"], cat["swap"], cols, alive, stats)
