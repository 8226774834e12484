"""The Ray backend of a build: one StageWorker per Ray actor, spread over the cluster's nodes.

    igraph-fight build --backend ray [--address auto|HOST:PORT] [--workers N]

Without ``--address`` a Ray instance is started on this machine (and stopped afterwards); with
``auto`` or ``HOST:PORT`` the build joins a running cluster (``ray start --head`` on one machine,
``ray start --address HEAD:6379`` on the others; igraph-fight must be installed on every node).
``workers``: actors, one CPU each (None or 0: every CPU of the cluster). If Ray is already
initialised in this process (a test's ``ray.init``, a notebook), the build uses that.

Shards are contiguous runs of rows (sampler children, edge landings) or of whole compatible
groups (clustering), one per actor and op, answered in row order (see stages.py); Ray only moves
arrays, so the graph is the same as a local build's, whatever the worker and node count.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from igraph_fight.build.stages import OpClock, StageWorker, cluster_in_shards, connect_ray, row_shards
from igraph_fight.sim import SimTables


#: blocks in flight per actor while linking (one computing, one queued)
IN_FLIGHT = 2


class RayStageWorker(StageWorker):
    """A StageWorker in a Ray actor (its numba kernels single-threaded: one CPU per actor)."""

    def __init__(self, tables: SimTables) -> None:
        super().__init__(tables, threads=1, writable_copy=True)

    def node_id(self) -> str:
        import ray
        return ray.get_runtime_context().get_node_id()


class RayBackend:
    """Build stages on Ray actors (see the module docstring)."""

    name = "ray"

    def __init__(self, tables: SimTables, workers: int | None = None, address: str | None = None) -> None:
        ray, self.started, n = connect_ray(workers, address)
        self.ray = ray
        Actor = ray.remote(num_cpus=1)(RayStageWorker)
        tables_ref = ray.put(tables)
        self.actors = [Actor.options(scheduling_strategy="SPREAD").remote(tables_ref) for _ in range(n)]
        self.nodes = ray.get([a.node_id.remote() for a in self.actors])
        self.pending_inserts: list = []
        self.clock = OpClock()
        self.used: set[int] = set()
        self.n_shards = len(self.actors)

    def _call(self, k: int, call: Callable):
        """call(actor) on actor k mod n (recorded: the report counts the nodes that did work)."""
        k %= len(self.actors)
        self.used.add(k)
        return call(self.actors[k])

    # ---- seed bouts ----------------------------------------------------------------------------
    def seed_bouts(self, library, seconds, pairing, seeds) -> list:
        with self.clock("seed_bouts"):
            lib_ref = self.ray.put(library)
            refs = [self._call(k, lambda a, lo=lo, hi=hi: a.seed_bouts.remote(lib_ref, seconds, pairing,
                                                                              seeds[lo:hi], lo))
                    for k, (lo, hi) in enumerate(row_shards(len(seeds), 4 * len(self.actors)))]
            return self.ray.get(refs)

    # ---- sampler ------------------------------------------------------------------------------
    def sampler_start(self, ix, capacity, link_r_m, link_theta_rad, f0, si, sf) -> None:
        ray = self.ray
        si_ref, sf_ref = ray.put(np.ascontiguousarray(si)), ray.put(np.ascontiguousarray(sf))
        got = ray.get([a.sampler_new_index.remote(capacity, link_r_m, link_theta_rad, f0, si_ref, sf_ref)
                       for a in self.actors])
        if any(g != len(si) for g in got):
            raise RuntimeError("a Ray worker's archive replica did not take every sample")

    def sampler_archived(self, si, sf) -> None:
        if len(si) == 0:
            return
        ray = self.ray
        si_ref, sf_ref = ray.put(np.ascontiguousarray(si)), ray.put(np.ascontiguousarray(sf))
        self.pending_inserts += [(len(si), a.sampler_insert.remote(si_ref, sf_ref)) for a in self.actors]

    def sampler_expand(self, si, sf, parent, action, max_distance_m, link_r_m, link_theta_rad) -> tuple:
        with self.clock("sampler_expand"):
            return self._sampler_expand(si, sf, parent, action, max_distance_m, link_r_m, link_theta_rad)

    def _sampler_expand(self, si, sf, parent, action, max_distance_m, link_r_m, link_theta_rad) -> tuple:
        ray = self.ray
        self._check_inserts()
        refs = []
        for k, (lo, hi) in enumerate(row_shards(len(parent), len(self.actors))):
            p = parent[lo:hi]
            self.used.add(k)
            refs.append(self.actors[k].sampler_expand.remote(
                np.ascontiguousarray(si[p]), np.ascontiguousarray(sf[p]), np.arange(hi - lo, dtype=np.int64),
                np.ascontiguousarray(action[lo:hi]), max_distance_m, link_r_m, link_theta_rad))
        parts = ray.get(refs)
        if not parts:
            return sim_empty()
        return tuple(np.concatenate([p[j] for p in parts]) for j in range(4))

    def sampler_stop(self) -> None:
        self._check_inserts()
        self.ray.get([a.sampler_release.remote() for a in self.actors])

    def _check_inserts(self) -> None:
        if self.pending_inserts:
            want = [n for n, _ in self.pending_inserts]
            got = self.ray.get([r for _, r in self.pending_inserts])
            self.pending_inserts = []
            if want != got:
                raise RuntimeError("a Ray worker's archive replica ran out of room")

    # ---- clustering ---------------------------------------------------------------------------
    def cluster_shards(self, X, sf, fo, perm, gstart, tol_r_m, tol_theta_rad, max_iter) -> tuple:
        def submit_all(args: list) -> list:
            refs = [self._call(k, lambda a, x=x: a.cluster.remote(*x)) for k, x in enumerate(args)]
            return self.ray.get(refs)
        with self.clock("cluster"):
            return cluster_in_shards(None, len(self.actors), X, sf, fo, perm, gstart, tol_r_m, tol_theta_rad,
                                     max_iter, submit_all=submit_all)

    # ---- edge linking -------------------------------------------------------------------------
    def link_start(self, ix, st_si, st_sf, tol_r, tol_theta, f0, s_r, s_theta) -> None:
        ray = self.ray
        a_ref, b_ref = ray.put(np.ascontiguousarray(st_si)), ray.put(np.ascontiguousarray(st_sf))
        ray.get([a.link_new_index.remote(a_ref, b_ref, tol_r, tol_theta, f0, s_r, s_theta) for a in self.actors])

    def link_candidates(self, blocks, max_distance_m, tol_r, tol_theta, max_candidates, sink) -> None:
        with self.clock("link_candidates"):
            self._windowed(len(blocks), lambda k: (lambda a, b=blocks[k]: a.link_candidates.remote(
                b[0], b[1], max_distance_m, tol_r, tol_theta, max_candidates)), sink)

    def link_features(self, blocks, sink) -> None:
        with self.clock("link_features"):
            self._windowed(len(blocks), lambda k: (lambda a, b=blocks[k]: a.link_features.remote(b[0], b[1], b[2])),
                           sink)

    def _windowed(self, n: int, call_of: Callable[[int], Callable], sink: Callable[[int, object], None]) -> None:
        """Blocks 0..n-1 to the actors in turn, at most IN_FLIGHT per actor at once (a block is
        made, sent, and its answer handed to ``sink(k, answer)`` in block order, then dropped):
        the driver and the object store hold a window of blocks, not all of them."""
        from collections import deque
        window = IN_FLIGHT * len(self.actors)
        pending: deque = deque()
        for k in range(n):
            pending.append((k, self._call(k, call_of(k))))
            while len(pending) >= window or (k == n - 1 and pending):
                j, ref = pending.popleft()
                sink(j, self.ray.get(ref))
                del ref

    def link_stop(self) -> None:
        self.ray.get([a.link_release.remote() for a in self.actors])

    # ---- bookkeeping --------------------------------------------------------------------------
    def report(self) -> dict:
        rss = self.ray.get([a.peak_rss_mb.remote() for a in self.actors])
        return {"backend": "ray", "workers": len(self.actors), "nodes": len(set(self.nodes)),
                "nodes_with_tasks": len({self.nodes[k] for k in self.used}),
                "worker_peak_rss_mb": [round(float(x), 1) for x in rss], "parallel_s": self.clock.seconds()}

    def close(self) -> None:
        for a in self.actors:
            self.ray.kill(a)
        self.actors = []
        if self.started:
            self.ray.shutdown()


def sim_empty() -> tuple:
    """(ci, cf, feat, C) of no children."""
    from igraph_fight.sim import N_FEAT, N_SF, N_SI
    return (np.zeros((0, N_SI), np.int64), np.zeros((0, N_SF)), np.zeros((0, N_FEAT)), np.zeros(0, np.int64))
