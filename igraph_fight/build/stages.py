"""The build's parallel stages on one shard of rows (``StageWorker``), and the sharding helpers.

Each stage is written once against plain arrays (the numba kernels of sim, spatial, explore,
cluster and edges) and runs wherever a backend (backend.py) puts a StageWorker: in the driver's
process, or in a Ray actor (ray_backend.py). Every kernel is deterministic and independent from row
to row, so answers put back in row order are those of one pass over all rows.
"""
from __future__ import annotations

import resource
from typing import Callable

import numpy as np

from igraph_fight.build import spatial
from igraph_fight.sim import SimTables

RAY_INSTALL_HINT = "the Ray backend needs Ray: pip install 'igraph-fight[ray]'"


class BackendUnavailable(ValueError):
    """A backend whose optional dependency is missing (the message says how to install it)."""


class StageWorker:
    """The build's parallel stages on one shard of rows (one per process, or the driver's own).

    ``tables``: the simulator tables; ``threads``: numba kernel threads inside this worker.
    Arrays that come from a Ray object store are read-only; ``writable_copy`` copies them once so
    the kernels see the same array types as in a local build.
    """

    def __init__(self, tables: SimTables, threads: int | None = 1, writable_copy: bool = False) -> None:
        if writable_copy:
            import copy
            tables = copy.deepcopy(tables)
        self.tables = tables
        self.T = tables.kernel_tuple()
        self.nextset = tables.nextset
        self.next_offsets = tables.next_offsets
        self.next_ids = tables.next_ids
        self.threads = threads
        self.sampler_ix: tuple | None = None
        self.link_ix: tuple | None = None
        self.st_si: np.ndarray | None = None
        self.st_sf: np.ndarray | None = None

    # ---- seed bouts ----------------------------------------------------------------------------
    def seed_bouts(self, library, seconds: float, pairing: str, seeds: np.ndarray, first: int) -> tuple:
        """Decision samples (si, sf) of the seed bouts first, first + 1, ... (seeding.py)."""
        from igraph_fight.build.seeding import seed_bout_range
        return seed_bout_range(library, self.tables, seconds, pairing, writable(seeds), first)

    # ---- sampler ------------------------------------------------------------------------------
    def sampler_use_index(self, ix: tuple) -> None:
        """Score against ``ix`` itself (the driver's index, in this process)."""
        self.sampler_ix = ix

    def sampler_new_index(self, capacity: int, link_r_m: float, link_theta_rad: float, f0: int,
                          si: np.ndarray, sf: np.ndarray) -> int:
        """A replica of the archive index holding samples (si, sf) with ids 0.. in order."""
        self.sampler_ix = spatial.new_index(int(capacity), float(link_r_m), float(link_theta_rad), int(f0))
        return self.sampler_insert(si, sf)

    def sampler_insert(self, si: np.ndarray, sf: np.ndarray) -> int:
        """Append archived samples (in id order) to the replica; returns how many fitted."""
        from igraph_fight.build.explore import point_rows
        if len(si) == 0:
            return 0
        return int(spatial.index_insert_many(self.sampler_ix, point_rows(self.nextset, writable(si)),
                                             writable(np.ascontiguousarray(sf, dtype=np.float64))))

    def sampler_expand(self, si: np.ndarray, sf: np.ndarray, parent: np.ndarray, action: np.ndarray,
                       max_distance_m: float, link_r_m: float, link_theta_rad: float) -> tuple:
        """Children of (si[parent[k]], sf[parent[k]]) under action[k]: (ci, cf, feat, C)."""
        from igraph_fight.build.explore import expand_and_score
        return expand_and_score(self.T, self.sampler_ix, self.nextset, self.next_offsets, self.next_ids, writable(si),
                                writable(sf), writable(parent), writable(action), max_distance_m, link_r_m,
                                link_theta_rad, self.threads)

    def sampler_release(self) -> None:
        self.sampler_ix = None

    # ---- clustering ---------------------------------------------------------------------------
    def cluster(self, X: np.ndarray, sf: np.ndarray, fo: np.ndarray, gstart: np.ndarray, tol_r_m: float,
                tol_theta_rad: float, max_iter: int) -> tuple:
        """Bisecting 2-means inside the groups [gstart[g], gstart[g+1]) of rows 0..n-1 (rows sorted
        by group): (perm, local, clpos, cen, nclust) as cluster._cluster_groups leaves them."""
        from igraph_fight.build.cluster import cluster_groups
        return cluster_groups(writable(X), writable(sf), writable(fo), writable(gstart), tol_r_m, tol_theta_rad,
                              max_iter)

    # ---- edge linking -------------------------------------------------------------------------
    def link_use_index(self, ix: tuple, st_si: np.ndarray, st_sf: np.ndarray) -> None:
        self.link_ix, self.st_si, self.st_sf = ix, st_si, st_sf

    def link_new_index(self, st_si: np.ndarray, st_sf: np.ndarray, tol_r: float, tol_theta: float, f0: int,
                       s_r: float, s_theta: float) -> None:
        from igraph_fight.build.edges import state_index
        self.st_si = np.array(st_si)
        self.st_sf = np.array(st_sf)
        self.link_ix = state_index(self.nextset, self.st_si, self.st_sf, tol_r, tol_theta, f0, s_r, s_theta)

    def link_candidates(self, src: np.ndarray, action: np.ndarray, max_distance_m: float, tol_r: float,
                        tol_theta: float, max_candidates: int) -> tuple:
        """Landings of (state src[k], action[k]): (candidate count per landing, the candidates of
        all landings in order as int32, landings out of the arena)."""
        from igraph_fight.build.edges import landing_candidates
        src, action = writable(src), writable(action)
        return landing_candidates(self.T, self.nextset, self.link_ix, self.st_si, self.st_sf, src, action,
                                  max_distance_m, tol_r, tol_theta, max_candidates, self.threads)

    def link_features(self, src: np.ndarray, action: np.ndarray, tgt: np.ndarray) -> dict:
        """Feature columns of the edges (src[k], action[k]) -> tgt[k] (edges.FEATURE_COLUMNS,
        snap_r, snap_theta, swap)."""
        from igraph_fight.build.edges import edge_features
        return edge_features(self.T, self.st_si, self.st_sf, writable(src), writable(action), writable(tgt),
                             self.threads)

    def link_release(self) -> None:
        self.link_ix = self.st_si = self.st_sf = None

    # ---- bookkeeping --------------------------------------------------------------------------
    def peak_rss_mb(self) -> float:
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def writable(a: np.ndarray) -> np.ndarray:
    """``a``, or a copy of it when it is read-only (arrays from a Ray object store are): the numba
    kernels then see the array types of a local build and need no second compilation."""
    a = np.asarray(a)
    return a if a.flags.writeable else np.array(a)


class OpClock:
    """Wall seconds a backend spent in each parallel op (the rest of a stage is the driver's)."""

    def __init__(self) -> None:
        self.total: dict[str, float] = {}

    def __call__(self, name: str):
        import contextlib
        import time

        @contextlib.contextmanager
        def timed():
            t = time.perf_counter()
            try:
                yield
            finally:
                self.total[name] = self.total.get(name, 0.0) + time.perf_counter() - t
        return timed()

    def seconds(self) -> dict[str, float]:
        return {k: round(v, 3) for k, v in self.total.items()}


def cluster_in_shards(run: Callable, n_shards: int, X: np.ndarray, sf: np.ndarray, fo: np.ndarray, perm: np.ndarray,
                      gstart: np.ndarray, tol_r_m: float, tol_theta_rad: float, max_iter: int,
                      submit_all: Callable | None = None) -> tuple:
    """Cluster the groups of ``perm`` (sorted rows, groups [gstart[g], gstart[g+1])) in up to
    ``n_shards`` shards of whole groups with about equal rows; returns (perm, local, clpos, cen,
    nclust) exactly as one pass over all groups would. ``run(X, sf, fo, gstart, ...)`` clusters one
    shard (rows renumbered 0..n-1); ``submit_all(list of argument tuples)`` may run all shards at
    once (Ray) and return their answers in order."""
    N = len(perm)
    G = len(gstart) - 1
    cuts = shard_cuts(gstart, n_shards)
    args = []
    for a, b in zip(cuts[:-1], cuts[1:]):
        p0, p1 = int(gstart[a]), int(gstart[b])
        rows = perm[p0:p1]
        args.append((np.ascontiguousarray(X[rows]), np.ascontiguousarray(sf[rows]), np.ascontiguousarray(fo[rows]),
                     (gstart[a:b + 1] - p0).astype(np.int64), tol_r_m, tol_theta_rad, max_iter))
    answers = submit_all(args) if submit_all is not None else [run(*x) for x in args]
    perm_out = perm.copy()
    local = np.empty(N, dtype=np.int64)
    clpos = np.empty(N, dtype=np.int64)
    cen = np.zeros((N, 4))
    nclust = np.zeros(G, dtype=np.int64)
    for (a, b), (p_loc, loc, cp, c, nc) in zip(zip(cuts[:-1], cuts[1:]), answers):
        p0, p1 = int(gstart[a]), int(gstart[b])
        rows = perm[p0:p1]
        perm_out[p0:p1] = rows[np.asarray(p_loc)]
        local[p0:p1] = loc
        clpos[p0:p1] = np.asarray(cp) + p0
        cen[p0:p1] = c
        nclust[a:b] = nc
    return perm_out, local, clpos, cen, nclust


def shard_cuts(starts: np.ndarray, n_shards: int) -> list[int]:
    """Group indices 0 = c0 < c1 < ... = G cutting G groups (row starts ``starts``, G+1 entries)
    into at most ``n_shards`` runs of whole groups with about equal rows."""
    G = len(starts) - 1
    if G <= 0:
        return [0, 0]
    n = int(starts[-1])
    targets = [n * k / max(1, n_shards) for k in range(1, max(1, n_shards))]
    cuts = [0]
    for t in targets:
        c = int(np.searchsorted(starts, t))
        if cuts[-1] < c < G:
            cuts.append(c)
    cuts.append(G)
    return cuts


def row_shards(n: int, n_shards: int) -> list[tuple[int, int]]:
    """[lo, hi) ranges splitting n rows into at most n_shards contiguous runs."""
    k = max(1, min(int(n_shards), n))
    b = np.linspace(0, n, k + 1).astype(np.int64)
    return [(int(b[i]), int(b[i + 1])) for i in range(k) if b[i + 1] > b[i]]


def require_ray():
    """The ``ray`` module, or BackendUnavailable saying how to install it."""
    try:
        import ray
    except ImportError:
        raise BackendUnavailable(RAY_INSTALL_HINT) from None
    return ray


def connect_ray(workers: int | None = None, address: str | None = None) -> tuple[object, bool, int]:
    """(the ray module, whether this call started Ray, how many one-CPU actors to run). Joins Ray
    if this process already initialised it, else the cluster at ``address`` (``auto`` or
    HOST:PORT), else starts Ray on this machine with ``workers`` CPUs. Actors: ``workers``, or
    (None or 0) every CPU of the cluster."""
    ray = require_ray()
    started = False
    if not ray.is_initialized():
        kw = {"include_dashboard": False, "logging_level": "ERROR", "log_to_driver": False}
        if address:
            ray.init(address=address, **kw)
        else:
            ray.init(num_cpus=workers or None, **kw)
        started = True
    n = int(workers) if workers else max(1, int(ray.cluster_resources().get("CPU", 1)))
    return ray, started, n
