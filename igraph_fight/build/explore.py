"""Tree-expansion sampler (paper section 5.3): an archive of coupled states, independent of rewards.

From a spread of initial states (both avatars in idle actions, distances in [initial_r_min_m,
initial_r_max_m] and all relative angles, drawn with the seed) the motion tree is expanded round
by round. Expanding a node simulates every action of its decider's menu to the next decision
instant; each child is scored by

* C: how many of the child's own menu actions lead to a state already in the archive (within the
  linking tolerance of a compatible sample: the paper's distance is finite), and
* J: interactions of the parent -> child event, both avatars: strikes whose effector came within
  ``reach_margin_m`` of a target ("attacks in the reaching distance") plus defences that worked.

Selection (``selection="round"``, default): at the end of a round the new children with the top
``expand_fraction`` (of the round's children) of C + interaction_weight * J are expanded next,
best first (ties: creation order). ``selection="parent"`` takes the top fraction of each node's
children instead. Measured on the CMU boxing library (150k samples): the global ranking gives a
larger linked core than the per-parent one (13.9k vs 13.4k states, mean out-degree 5.5 vs 4.2).

Every explored node is archived unless it duplicates an archived sample (within the duplicate
tolerance, compatible) or leaves the arena (r > max_distance_m). Exploration stops at
``max_samples``, when a round adds fewer than ``min_new_per_round`` new samples, when nothing is
left to expand, or after ``max_rounds``.

A round is processed in chunks of ``chunk_parents`` frontier nodes; C is measured against the
archive as it stood at the start of the chunk. Chunks are the unit of checkpointing: after each
one, the archive and the sampler's position are written atomically, and a rerun resumes exactly
there (same result as an uninterrupted run). Nothing depends on the thread count.
"""
from __future__ import annotations

import io
import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from numba import njit

from motion_graph.atomic import atomic_write_bytes
from motion_graph.errors import LibraryFormatError

from igraph_fight import sim
from igraph_fight.build import spatial
from igraph_fight.sim import N_SF, N_SI, SF_R, SI_FOTHER, SI_MASK, SI_MOTHER, SI_MSELF, SimTables

CHECKPOINT_FORMAT = "igraph-fight/sample-archive"
CHECKPOINT_VERSION = 1


@dataclass(frozen=True)
class ExploreOptions:
    """Options of the tree-expansion sampler (metres, radians, library frames)."""

    max_samples: int = 60_000
    min_new_per_round: int = 0
    max_rounds: int = 1_000
    n_initial: int = 256
    initial_r_min_m: float = 0.5
    initial_r_max_m: float = 3.0
    initial_facing_share: float = 0.0
    initial_facing_rad: float = math.radians(30.0)
    expand_fraction: float = 0.3
    f0: int = 3
    link_r_m: float = 0.05
    link_theta_rad: float = math.radians(10.0)
    dedup_r_m: float = 0.025
    dedup_theta_rad: float = math.radians(5.0)
    max_distance_m: float = 4.0
    chunk_parents: int = 2048
    selection: str = "round"
    interaction_weight: float = 1.0

    def to_json(self) -> dict:
        return asdict(self)


@dataclass
class Archive:
    """Explored samples (N rows): canonical ints si (N, N_SI), floats sf (N, N_SF) (see sim.SI_*,
    sim.SF_*); provenance
    parent (N,) (-1 for initial states), action (N,) the parent's action, depth (N,); the
    C and J scores the sample got when it was created (-1 for initial states)."""

    si: np.ndarray
    sf: np.ndarray
    parent: np.ndarray
    action: np.ndarray
    depth: np.ndarray
    score_c: np.ndarray
    score_j: np.ndarray
    rounds: int = 0
    stop_reason: str = ""

    def __len__(self) -> int:
        return len(self.si)


# ---------------------------------------------------------------------------------------------
# kernels
# ---------------------------------------------------------------------------------------------
def group_rows(nextset: np.ndarray, si: np.ndarray, f0: int) -> np.ndarray:
    """Compatible-group key columns (N, 4) of canonical samples: Next-set id of M_self, M_other,
    F_other // f0, mask (the clustering's groups)."""
    si = np.atleast_2d(si)
    return np.stack([nextset[si[:, SI_MSELF]], si[:, SI_MOTHER], si[:, SI_FOTHER] // f0, si[:, SI_MASK]],
                    1).astype(np.int64)


@njit(cache=True, inline="always")
def _point(nextset, si, k):
    k[0] = nextset[si[SI_MSELF]]
    k[1] = si[SI_MOTHER]
    k[2] = si[SI_FOTHER]
    k[3] = si[SI_MASK]


def point_rows(nextset: np.ndarray, si: np.ndarray) -> np.ndarray:
    """Index key columns (N, 4) of canonical samples: Next-set id of M_self, M_other, F_other, mask."""
    si = np.atleast_2d(si)
    return np.stack([nextset[si[:, SI_MSELF]], si[:, SI_MOTHER], si[:, SI_FOTHER], si[:, SI_MASK]], 1).astype(np.int64)


@njit(cache=True, nogil=True)
def _score_range(T, ix, nextset, next_offsets, next_ids, ci, cf, valid, tol_r, tol_t, C, lo, hi):
    S = np.empty((2, 3))
    act = np.empty(2, dtype=np.int64)
    frm = np.empty(2, dtype=np.int64)
    mask = np.empty(2, dtype=np.int64)
    stats = np.empty(sim.N_STAT)
    gi = np.empty(N_SI, dtype=np.int64)
    gf = np.empty(N_SF)
    feat = np.empty(sim.N_FEAT)
    g = np.empty(4, dtype=np.int64)
    no_i = np.empty(0, dtype=np.int64)
    no_d = np.empty(0)
    for k in range(lo, hi):
        C[k] = 0
        if not valid[k]:
            continue
        m = ci[k, SI_MSELF]
        c = 0
        for e in range(next_offsets[m], next_offsets[m + 1]):
            sim.expand_one(T, ci[k], cf[k], next_ids[e], gi, gf, feat, S, act, frm, mask, stats)
            _point(nextset, gi, g)
            if spatial.index_search(ix, g, gf[0], gf[1], gf[2], tol_r, tol_t, False, no_i, no_d) >= 0:
                c += 1
        C[k] = c


def score_children(T: tuple, ix: tuple, nextset: np.ndarray, next_offsets: np.ndarray, next_ids: np.ndarray,
                   ci: np.ndarray, cf: np.ndarray, valid: np.ndarray, tol_r: float, tol_t: float,
                   workers: int = 1) -> np.ndarray:
    """C of each valid child: menu actions whose next decision state lies within tolerance of an
    indexed sample (children's children are simulated and looked up, never stored)."""
    C = np.zeros(len(ci), dtype=np.int64)
    sim.parallel_for(_score_range, len(ci), workers, T, ix, nextset, next_offsets, next_ids, ci, cf, valid,
                     float(tol_r), float(tol_t), C, min_chunk=256)
    return C


def expand_and_score(T: tuple, ix: tuple, nextset: np.ndarray, next_offsets: np.ndarray, next_ids: np.ndarray,
                     si: np.ndarray, sf: np.ndarray, parent: np.ndarray, action: np.ndarray, max_distance_m: float,
                     link_r_m: float, link_theta_rad: float, workers: int | None = 1) -> tuple:
    """Children of (si[parent[k]], sf[parent[k]]) under action[k] and their scores C: (ci, cf,
    feat, C); children beyond ``max_distance_m`` score 0."""
    ci, cf, feat, _ = sim.expand_samples(T, si, sf, parent, action, workers)
    valid = cf[:, SF_R] <= max_distance_m
    C = score_children(T, ix, nextset, next_offsets, next_ids, ci, cf, valid, link_r_m, link_theta_rad, workers)
    return ci, cf, feat, C


@njit(cache=True)
def dedup_insert(ix, dix, nextset, ci, cf, valid, tol_r, tol_t):
    """Insert the valid children that are not within (tol_r, tol_t) of an indexed sample, in
    order, into both indexes; returns the new ids (-1: duplicate, invalid or no room). ``dix``
    holds the same points as ``ix`` on a grid as fine as the duplicate tolerance (a query then
    scans a few points, not a linking-tolerance cell's many); the answer does not depend on it."""
    K = len(ci)
    out = np.full(K, -1, dtype=np.int64)
    g = np.empty(4, dtype=np.int64)
    no_i = np.empty(0, dtype=np.int64)
    no_d = np.empty(0)
    for k in range(K):
        if not valid[k]:
            continue
        _point(nextset, ci[k], g)
        if spatial.index_search(dix, g, cf[k, 0], cf[k, 1], cf[k, 2], tol_r, tol_t, False, no_i, no_d) >= 0:
            continue
        out[k] = spatial.index_insert(ix, g, cf[k, 0], cf[k, 1], cf[k, 2])
        if out[k] < 0:
            break
        spatial.index_insert(dix, g, cf[k, 0], cf[k, 1], cf[k, 2])
    return out


# ---------------------------------------------------------------------------------------------
# Python driver
# ---------------------------------------------------------------------------------------------
def initial_samples(tables: SimTables, options: ExploreOptions, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A spread of initial canonical samples: both avatars in idle (guard) actions, distances in
    [initial_r_min_m, initial_r_max_m], all relative angles (drawn with ``seed``); a share
    ``initial_facing_share`` of them with both angles within +-``initial_facing_rad`` (facing each
    other, where every hit happens: with all angles uniform only ~3% of close states face)."""
    from motion_graph.classify import KINDS

    rng = np.random.default_rng(seed)
    idle = np.nonzero(tables.kinds == KINDS.index("guard"))[0]
    if len(idle) == 0:  # no guard in this library: any non-attack action
        idle = np.array([a for a in range(tables.n_actions)
                         if tables.strike_offsets[a + 1] == tables.strike_offsets[a]] or range(tables.n_actions))
    n = options.n_initial
    si = np.zeros((n, N_SI), dtype=np.int64)
    sf = np.zeros((n, N_SF), dtype=np.float64)
    si[:, SI_MSELF] = rng.choice(idle, n)
    si[:, SI_MOTHER] = rng.choice(idle, n)
    si[:, SI_FOTHER] = np.floor(rng.random(n) * (tables.n_frames[si[:, SI_MOTHER]] - 1)).astype(np.int64)
    sf[:, SF_R] = rng.uniform(options.initial_r_min_m, options.initial_r_max_m, n)
    sf[:, 1:] = rng.uniform(-np.pi, np.pi, (n, 2))
    n_face = int(round(options.initial_facing_share * n))
    if n_face > 0:
        sf[:n_face, 1:] = rng.uniform(-options.initial_facing_rad, options.initial_facing_rad, (n_face, 2))
    return si, sf


class _Run:
    """Mutable sampler state (what a checkpoint holds)."""

    def __init__(self, cap: int) -> None:
        self.si = np.zeros((cap, N_SI), dtype=np.int64)
        self.sf = np.zeros((cap, N_SF), dtype=np.float64)
        self.parent = np.full(cap, -1, dtype=np.int64)
        self.action = np.full(cap, -1, dtype=np.int64)
        self.depth = np.zeros(cap, dtype=np.int64)
        self.score_c = np.full(cap, -1, dtype=np.int64)
        self.score_j = np.full(cap, -1.0, dtype=np.float64)
        self.n = 0
        self.round = 0
        self.frontier = np.zeros(0, dtype=np.int64)
        self.pos = 0
        self.next_frontier: list[np.ndarray] = []
        self.round_new = 0
        self.round_start = 0
        self.round_children = 0
        self.chunks = 0
        self.done = False
        self.reason = ""

    def arrays(self) -> dict:
        n = self.n
        return dict(si=self.si[:n], sf=self.sf[:n], parent=self.parent[:n], action=self.action[:n],
                    depth=self.depth[:n], score_c=self.score_c[:n], score_j=self.score_j[:n],
                    frontier=self.frontier,
                    next_frontier=np.concatenate(self.next_frontier) if self.next_frontier else np.zeros(0, np.int64))

    def meta(self) -> dict:
        return dict(n=self.n, round=self.round, pos=self.pos, round_new=self.round_new, chunks=self.chunks,
                    round_start=self.round_start, round_children=self.round_children,
                    done=self.done, reason=self.reason)


def _save_checkpoint(path: Path, run: _Run, fingerprint: str) -> None:
    header = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "fingerprint": fingerprint, **run.meta()}
    buf = io.BytesIO()
    np.savez(buf, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **run.arrays())
    atomic_write_bytes(path, buf.getvalue())


def read_checkpoint_header(path: str | os.PathLike) -> dict:
    """The JSON header of a checkpoint file (LibraryFormatError when unreadable)."""
    try:
        with np.load(path, allow_pickle=False) as z:
            header = json.loads(bytes(z["header"]).decode())
    except Exception as e:
        raise LibraryFormatError(str(path), f"unreadable sampler checkpoint: {e}") from None
    if header.get("format") != CHECKPOINT_FORMAT or header.get("version") != CHECKPOINT_VERSION:
        raise LibraryFormatError(str(path), "not a sampler checkpoint of this version")
    return header


def _load_checkpoint(path: Path, run: _Run) -> dict:
    header = read_checkpoint_header(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            d = {k: z[k] for k in z.files if k != "header"}
    except Exception as e:
        raise LibraryFormatError(str(path), f"unreadable sampler checkpoint: {e}") from None
    n = int(header["n"])
    for k in ("si", "sf", "parent", "action", "depth", "score_c", "score_j"):
        getattr(run, k)[:n] = d[k]
    run.n = n
    run.round = int(header["round"])
    run.pos = int(header["pos"])
    run.round_new = int(header["round_new"])
    run.round_start = int(header["round_start"])
    run.round_children = int(header["round_children"])
    run.chunks = int(header["chunks"])
    run.done = bool(header["done"])
    run.reason = str(header["reason"])
    run.frontier = d["frontier"].astype(np.int64)
    run.next_frontier = [d["next_frontier"].astype(np.int64)] if len(d["next_frontier"]) else []
    return header


def explore(tables: SimTables, options: ExploreOptions, seed: int, checkpoint: str | os.PathLike | None = None,
            fingerprint: str = "", progress: bool = False,
            on_chunk: Callable[[int, int], None] | None = None, workers: int = 1,
            extra_initial: tuple[np.ndarray, np.ndarray] | None = None, backend=None) -> Archive:
    """Run the sampler and return the archive.

    Args:
        tables: simulator tables of the library.
        options: sampler options.
        seed: seeds the initial states (the only random draw).
        checkpoint: file to write after every chunk and resume from when it exists with the
            same ``fingerprint`` (a checkpoint with another fingerprint raises ValueError).
        fingerprint: identifies the inputs (library, options, seed) in the checkpoint.
        progress: show a progress bar (stderr).
        on_chunk: called as on_chunk(chunks_done, n_samples) after each checkpoint (tests use it
            to interrupt a run).
        workers: threads (None or 0: all cores); the result does not depend on it.
        extra_initial: more initial samples (si, sf), appended to the spread (e.g.
            igraph_fight.seeding.bout_seed_states); duplicates are dropped as usual.
        backend: where children are simulated and scored (igraph_fight.build.backend; None:
            this process on ``workers`` threads); deduplication and selection run here.
    """
    o = options
    if o.selection not in ("round", "parent"):
        raise ValueError(f"selection must be 'round' or 'parent', not {o.selection!r}")
    T = tables.kernel_tuple()
    cap = int(o.max_samples)
    run = _Run(cap)
    ckpt = Path(checkpoint) if checkpoint else None
    if ckpt is not None and ckpt.exists():
        header = read_checkpoint_header(ckpt)
        if header.get("fingerprint") != fingerprint:
            raise ValueError(f"{ckpt}: checkpoint of a build with other inputs or options")
        _load_checkpoint(ckpt, run)
    if o.dedup_r_m > o.link_r_m or o.dedup_theta_rad > o.link_theta_rad:
        raise ValueError("the duplicate tolerance must not exceed the linking tolerance")
    ix = spatial.new_index(cap, o.link_r_m, o.link_theta_rad, o.f0)
    dtr, dtt = o.dedup_r_m, o.dedup_theta_rad
    dix = spatial.new_index(cap, dtr, dtt, o.f0)
    nextset = tables.nextset
    if run.n:
        keys = point_rows(nextset, run.si[:run.n])
        spatial.index_insert_many(ix, keys, run.sf[:run.n])
        spatial.index_insert_many(dix, keys, run.sf[:run.n])
    else:
        si0, sf0 = initial_samples(tables, o, seed)
        if extra_initial is not None and len(extra_initial[0]):
            si0 = np.concatenate([si0, np.asarray(extra_initial[0], dtype=np.int64)])
            sf0 = np.concatenate([sf0, np.asarray(extra_initial[1], dtype=np.float64)])
        valid = sf0[:, SF_R] <= o.max_distance_m
        ids = dedup_insert(ix, dix, nextset, si0, sf0, valid, dtr, dtt)
        keep = ids >= 0
        k = int(keep.sum())
        run.si[:k] = si0[keep]
        run.sf[:k] = sf0[keep]
        run.n = k
        run.frontier = np.arange(k, dtype=np.int64)
        run.round_start = k
        if ckpt is not None:
            _save_checkpoint(ckpt, run, fingerprint)
    if backend is not None:
        backend.sampler_start(ix, cap, o.link_r_m, o.link_theta_rad, o.f0, run.si[:run.n], run.sf[:run.n])

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=cap, initial=run.n, desc="explore", unit="sample", dynamic_ncols=True, leave=False)
    try:
        while not run.done:
            if run.n >= cap:
                run.done, run.reason = True, "max_samples"
                break
            if run.pos >= len(run.frontier):
                # end of a round
                if run.round > 0 and run.round_new < o.min_new_per_round:
                    run.done, run.reason = True, "min_new_per_round"
                    break
                if o.selection == "round":
                    run.frontier = _select_round(run, o)
                else:
                    run.frontier = (np.concatenate(run.next_frontier) if run.next_frontier
                                    else np.zeros(0, dtype=np.int64))
                run.next_frontier = []
                run.round_start = run.n
                run.round_children = 0
                run.pos = 0
                run.round += 1
                run.round_new = 0
                if len(run.frontier) == 0:
                    run.done, run.reason = True, "frontier_empty"
                    break
                if run.round > o.max_rounds:
                    run.done, run.reason = True, "max_rounds"
                    break
            chunk = run.frontier[run.pos:run.pos + o.chunk_parents]
            added, n_children = _expand_chunk(T, tables, ix, dix, run, chunk, o, dtr, dtt, backend, workers)
            run.round_children += n_children
            run.pos += len(chunk)
            run.round_new += added
            run.chunks += 1
            if run.n >= cap:
                run.done, run.reason = True, "max_samples"
            if ckpt is not None:
                _save_checkpoint(ckpt, run, fingerprint)
            if bar is not None:
                bar.n = run.n
                bar.set_postfix(round=run.round, refresh=False)
                bar.refresh()
            if on_chunk is not None:
                on_chunk(run.chunks, run.n)
        if ckpt is not None:
            _save_checkpoint(ckpt, run, fingerprint)
    finally:
        if bar is not None:
            bar.close()
        if backend is not None:
            backend.sampler_stop()
    n = run.n
    return Archive(run.si[:n].copy(), run.sf[:n].copy(), run.parent[:n].copy(), run.action[:n].copy(),
                   run.depth[:n].copy(), run.score_c[:n].copy(), run.score_j[:n].copy(), run.round, run.reason)


def _expand_chunk(T: tuple, tables: SimTables, ix, dix, run: _Run, chunk: np.ndarray, o: ExploreOptions,
                  dtr: float, dtt: float, backend, workers: int | None = 1) -> tuple[int, int]:
    """Expand the frontier nodes of one chunk; returns (new samples archived, children simulated)."""
    no, ni = tables.next_offsets, tables.next_ids
    m = run.si[chunk, SI_MSELF]
    counts = no[m + 1] - no[m]
    parent = np.repeat(chunk, counts)
    starts = np.repeat(no[m], counts)
    local = np.arange(len(parent)) - np.repeat(np.cumsum(counts) - counts, counts)
    action = ni[starts + local]
    if backend is None:
        ci, cf, feat, C = expand_and_score(T, ix, tables.nextset, no, ni, run.si, run.sf, parent, action,
                                           o.max_distance_m, o.link_r_m, o.link_theta_rad, workers)
    else:
        ci, cf, feat, C = backend.sampler_expand(run.si, run.sf, parent, action, o.max_distance_m, o.link_r_m,
                                                 o.link_theta_rad)
    valid = cf[:, SF_R] <= o.max_distance_m
    J = (feat[:, sim.FT_NEAR_SELF] + feat[:, sim.FT_NEAR_OTHER] + feat[:, sim.FT_DEF_SELF]
         + feat[:, sim.FT_DEF_OTHER])
    ids = dedup_insert(ix, dix, tables.nextset, ci, cf, valid, dtr, dtt)
    new = ids >= 0
    k = int(new.sum())
    if backend is not None:
        backend.sampler_archived(ci[new], cf[new])  # ids ascend with k: the replicas insert them in id order
    if k:
        dst = ids[new]
        run.si[dst] = ci[new]
        run.sf[dst] = cf[new]
        run.parent[dst] = parent[new]
        run.action[dst] = action[new]
        run.depth[dst] = run.depth[parent[new]] + 1
        run.score_c[dst] = C[new]
        run.score_j[dst] = J[new]
        run.n = int(dst.max()) + 1
    if o.selection == "round":
        return k, len(parent)
    # per-parent selection: the top expand_fraction of its children by C + J (ties: menu order)
    score = np.where(valid, C + o.interaction_weight * J, -np.inf)
    seg = np.repeat(np.arange(len(chunk)), counts)
    order = np.lexsort((local, -score, seg))
    rank = np.empty(len(order), dtype=np.int64)
    rank[order] = np.arange(len(order)) - np.repeat(np.cumsum(counts) - counts, counts)
    top = np.ceil(o.expand_fraction * counts).astype(np.int64)
    chosen = (rank < np.repeat(top, counts)) & new
    sel = np.nonzero(chosen)[0]
    # order: parent order, then rank
    sel = sel[np.lexsort((rank[sel], seg[sel]))]
    if len(sel):
        run.next_frontier.append(ids[sel])
    return k, len(parent)


def _select_round(run: _Run, o: ExploreOptions) -> np.ndarray:
    """Global selection: the top expand_fraction of the round's children by C + J among the new
    samples of the round (ties: creation order), best first."""
    ids = np.arange(run.round_start, run.n, dtype=np.int64)
    n_sel = min(len(ids), int(math.ceil(o.expand_fraction * run.round_children)))
    score = run.score_c[ids] + o.interaction_weight * run.score_j[ids]
    order = np.lexsort((ids, -score))
    return ids[order[:n_sel]]
