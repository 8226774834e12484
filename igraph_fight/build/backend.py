"""Where a build's parallel stages run: this process (``local``) or a Ray cluster (``ray``).

A build has four data-parallel stages, each written once in ``stages.StageWorker`` against plain
arrays (the numba kernels of sim, spatial, explore, cluster and edges):

* seed bouts: runs of the sampler's reward-free seed bouts (seeding.py), each with its own seed;
* sampler expansion: simulate the children of a chunk of frontier nodes and score them (C: how
  many of a child's own menu actions land within tolerance of an archived sample). Each worker
  holds a replica of the archive's hash index; the driver deduplicates (in order, as the local
  build does) and sends every worker the samples it archived, so all replicas hold the same
  points with the same ids and answer exactly as the driver's index would;
* clustering: bisecting k-means inside shards of whole compatible groups;
* edge linking: simulate every (state, menu action) landing and find its candidate states
  (each worker holds the index of the states), then the features of the surviving edges.

The backend only splits rows into shards and puts the answers back in row order; every kernel is
deterministic and row-independent, so the graph and its content hash do not depend on the
backend or the worker count. The stages' own functions (explore.explore, cluster.cluster_samples,
edges.link, seeding.bout_seed_states) run in this process when given no backend.
``LocalBackend`` runs one StageWorker in this process on ``workers`` threads and shares the
driver's index (nothing is copied); its seed bouts run in ``workers`` forked processes. ``RayBackend`` (ray_backend.py, needs the optional ``ray``
extra) runs one StageWorker per Ray actor, spread over the cluster's nodes. ``BACKENDS`` is the
registry the CLI reads.

Memory per Ray worker: the simulator tables (the action library, a few MB) plus, while the
sampler runs, a replica of the archive index (4 int64 keys, 3 float64 features, a chain link and
two to four hash slots: 96-128 bytes per sample), and while edges are linked, the state index
(the same per state) plus one shard's landings and features; the driver holds the archive and
the edge set it returns, whose columns it fills block by block in place (columns.py; memory-mapped
files in a checkpoint folder: docs/scaling.md).
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Callable, Protocol

import numpy as np

from igraph_fight import sim
from igraph_fight.build.stages import (RAY_INSTALL_HINT, BackendUnavailable, OpClock, StageWorker,
                                       cluster_in_shards, require_ray, row_shards)
from igraph_fight.sim import SimTables

__all__ = ["BACKENDS", "Backend", "BackendUnavailable", "LocalBackend", "RAY_INSTALL_HINT", "make_backend",
           "require_ray"]


class Backend(Protocol):
    """What the build stages ask of a backend (see the module docstring)."""

    name: str
    n_shards: int  # how many pieces a stage's rows are worth cutting into

    def seed_bouts(self, library, seconds: float, pairing: str, seeds: np.ndarray) -> list[tuple]: ...

    def sampler_start(self, ix: tuple, capacity: int, link_r_m: float, link_theta_rad: float, f0: int,
                      si: np.ndarray, sf: np.ndarray) -> None: ...

    def sampler_expand(self, si: np.ndarray, sf: np.ndarray, parent: np.ndarray, action: np.ndarray,
                       max_distance_m: float, link_r_m: float, link_theta_rad: float) -> tuple: ...

    def sampler_archived(self, si: np.ndarray, sf: np.ndarray) -> None: ...

    def sampler_stop(self) -> None: ...

    def cluster_shards(self, X: np.ndarray, sf: np.ndarray, fo: np.ndarray, perm: np.ndarray, gstart: np.ndarray,
                       tol_r_m: float, tol_theta_rad: float, max_iter: int) -> tuple: ...

    def link_start(self, ix: tuple, st_si: np.ndarray, st_sf: np.ndarray, tol_r: float, tol_theta: float, f0: int,
                   s_r: float, s_theta: float) -> None: ...

    def link_candidates(self, blocks: Sequence[tuple[np.ndarray, np.ndarray]], max_distance_m: float, tol_r: float,
                        tol_theta: float, max_candidates: int, sink: Callable[[int, tuple], None]) -> None:
        """Each block's (counts, candidates, out of arena) handed to ``sink(k, answer)`` in block
        order, as they come (``blocks[k]`` is made when it is sent)."""

    def link_features(self, blocks: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]],
                      sink: Callable[[int, dict], None]) -> None:
        """Each block's feature columns handed to ``sink(k, columns)`` in block order, as they come."""

    def link_stop(self) -> None: ...

    def report(self) -> dict: ...

    def close(self) -> None: ...


class LocalBackend:
    """Every stage in this process on ``workers`` threads (None or 0: all cores)."""

    name = "local"
    n_shards = 1

    def __init__(self, tables: SimTables, workers: int | None = 1) -> None:
        self.workers = sim.resolve_workers(workers)
        self.worker = StageWorker(tables, workers)
        self.clock = OpClock()

    def seed_bouts(self, library, seconds, pairing, seeds) -> list:
        """The seed bouts in this process, or with several workers in as many forked processes
        (bouts are Python: threads would not run them side by side)."""
        import multiprocessing as mp

        from igraph_fight.build.seeding import seed_bout_range
        with self.clock("seed_bouts"):
            if self.workers <= 1 or len(seeds) < 2 * self.workers or "fork" not in mp.get_all_start_methods():
                return [self.worker.seed_bouts(library, seconds, pairing, seeds, 0)]
            shards = row_shards(len(seeds), self.workers)
            with mp.get_context("fork").Pool(len(shards)) as pool:
                return pool.starmap(seed_bout_range, [(library, self.worker.tables, seconds, pairing, seeds[lo:hi], lo)
                                                      for lo, hi in shards])

    def sampler_start(self, ix, capacity, link_r_m, link_theta_rad, f0, si, sf) -> None:
        self.worker.sampler_use_index(ix)

    def sampler_expand(self, si, sf, parent, action, max_distance_m, link_r_m, link_theta_rad) -> tuple:
        with self.clock("sampler_expand"):
            return self.worker.sampler_expand(si, sf, parent, action, max_distance_m, link_r_m, link_theta_rad)

    def sampler_archived(self, si, sf) -> None:
        pass  # the worker scores against the driver's own index

    def sampler_stop(self) -> None:
        self.worker.sampler_release()

    def cluster_shards(self, X, sf, fo, perm, gstart, tol_r_m, tol_theta_rad, max_iter) -> tuple:
        with self.clock("cluster"):
            return cluster_in_shards(lambda *a: self.worker.cluster(*a), 1, X, sf, fo, perm, gstart, tol_r_m,
                                     tol_theta_rad, max_iter)

    def link_start(self, ix, st_si, st_sf, tol_r, tol_theta, f0, s_r, s_theta) -> None:
        self.worker.link_use_index(ix, st_si, st_sf)

    def link_candidates(self, blocks, max_distance_m, tol_r, tol_theta, max_candidates, sink) -> None:
        for k, (src, action) in enumerate(blocks):
            with self.clock("link_candidates"):
                answer = self.worker.link_candidates(src, action, max_distance_m, tol_r, tol_theta, max_candidates)
            sink(k, answer)

    def link_features(self, blocks, sink) -> None:
        for k, (src, action, tgt) in enumerate(blocks):
            with self.clock("link_features"):
                cols = self.worker.link_features(src, action, tgt)
            sink(k, cols)

    def link_stop(self) -> None:
        self.worker.link_release()

    def report(self) -> dict:
        return {"backend": "local", "workers": self.workers, "parallel_s": self.clock.seconds()}

    def close(self) -> None:
        pass


def make_backend(name: str, tables: SimTables, workers: int | None = 1, address: str | None = None) -> Backend:
    """The backend called ``name`` (``BACKENDS``); BackendUnavailable when its extra is missing."""
    if name not in BACKENDS:
        raise ValueError(f"unknown backend {name!r} (known: {', '.join(BACKENDS)})")
    return BACKENDS[name](tables, workers, address)


def _local(tables: SimTables, workers: int | None, address: str | None) -> Backend:
    if address is not None:
        raise ValueError("--address is for the ray backend")
    return LocalBackend(tables, workers)


def _ray(tables: SimTables, workers: int | None, address: str | None) -> Backend:
    from igraph_fight.build.ray_backend import RayBackend
    return RayBackend(tables, workers, address)


BACKENDS: dict[str, Callable[..., Backend]] = {"local": _local, "ray": _ray}
