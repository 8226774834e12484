"""Build an Interaction Graph from an action library: explore -> cluster -> link -> prune.

``build_graph`` is the Python entry point (the ``igraph-fight build`` command only parses its
arguments and calls it). The result depends only on the library, the options and the seed: the
thread count (``workers``) and interruptions (the sampler checkpoints its archive) change nothing.

Crash safety: the sampler's checkpoint is written atomically after every chunk; clustering and
linking are recomputed from the finished archive on a rerun; with ``out`` the graph file is
written atomically (motion_graph.atomic) and only then is the checkpoint removed. A kill at any
point followed by the same call gives the same graph. Test hook: the stages at which
motion_graph.atomic.kill_point may kill the process (IGRAPH_FIGHT_TEST_KILL_AT) are ``sample``
(after each sampler checkpoint), ``cluster``, ``link``, ``write`` (graph file written, not yet
renamed into place) and ``written`` (in place, checkpoint not yet removed).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import resource
import shutil
import time
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Callable

import numpy as np

from motion_graph.atomic import atomic_write_text, fsync_dir, kill_point

from igraph_fight.build import cluster, edges, explore
from igraph_fight.graph import FORMAT, VERSION, InteractionGraph, library_fingerprint, package_version
from igraph_fight.build.seeding import SEED_PAIRINGS
from igraph_fight.sim import SI_FOTHER, SI_MASK, SI_MOTHER, SI_MSELF, SimParams, SimTables


@dataclass(frozen=True)
class BuildOptions:
    """Everything that shapes the graph (metres, radians, library frames). See explore.py,
    cluster.py and edges.py for the algorithms.

    Defaults measured on the CMU boxing library (lead's notes in the README): F0 = 10 frames
    (1/3 s) and a linking tolerance of 15 cm / 30 degrees give 244k states, 4.7M edges, 78% of
    menu actions linked, against 153k / 1.4M / 42% for F0 = 3 and 10 cm / 20 degrees; the
    interaction weight 5 makes J count against C (C reaches the menu size, ~17, J a few), which
    puts more states within punching range. Three quarters of the sampler's initial states face
    each other within 30 degrees (initial_facing_*): with uniform angles only ~3% of the close
    states of the graph faced each other and the game-tree fighter's states were covered 34%
    (61% with facing starts, 4-bout evaluation of 2026-11-26). The sampler also starts from the
    decision states of 1024 reward-free 30 s bouts (seeding.py). 20-bout evaluations, seed 0
    (coverage here as measured then: the nearest state within tolerance): 512 bouts of the human
    proxy vs a random fighter took coverage 46% -> 72% and states without a compatible group 21%
    -> 0.1%, and the IG fighter's score grew with depth against all five baselines (128 bouts:
    63%; 1024: 76%); bouts of two human proxies (seed_pairing "human", the default since): 84%
    with 512 bouts, 87% with 1024, scores against the game-tree fighters unchanged within their
    intervals. With the paper's coverage (some state within tolerance): 89.8% with 512 bouts,
    91.3% with 1024 (held-out seed 100: 89.1%, 93.6%); 1024 bouts cost about 40 s more build.

    tol_*: snapping tolerance of the clustering (bounds a sample's move to its state).
    link_tol_*: tolerance of an edge's landing around its target state (also the sampler's C).
    dedup_*: samples closer than this to an archived one are duplicates.
    """

    max_samples: int = 600_000
    min_new_per_round: int = 0
    max_rounds: int = 1_000
    n_initial: int = 64
    initial_r_min_m: float = 0.4
    initial_r_max_m: float = 2.5
    initial_facing_share: float = 0.75
    initial_facing_deg: float = 30.0
    seed_bouts: int = 1024
    seed_bout_seconds: float = 30.0
    seed_pairing: str = "human"
    expand_fraction: float = 0.3
    f0: int = 10
    tol_r_m: float = 0.05
    tol_theta_rad: float = math.radians(10.0)
    link_tol_r_m: float = 0.15
    link_tol_theta_rad: float = math.radians(30.0)
    dedup_r_m: float = 0.025
    dedup_theta_rad: float = math.radians(5.0)
    max_distance_m: float = 4.0
    chunk_parents: int = 2048
    selection: str = "round"
    interaction_weight: float = 5.0
    prune_dead_ends: bool = True
    max_candidates: int = 8
    s_r_m: float = 0.5
    s_theta_rad: float = math.pi / 6
    sim: SimParams = field(default_factory=SimParams)

    def to_json(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "sim"}
        d["sim"] = self.sim.to_json()
        return d

    @classmethod
    def from_json(cls, d: dict) -> "BuildOptions":
        d = dict(d)
        s = d.pop("sim", None)
        known = {f.name for f in fields(cls)}
        kw = {k: v for k, v in d.items() if k in known}
        if "seed_bouts" in d and "seed_pairing" not in d:
            kw["seed_pairing"] = "random"  # files from before the option: their seed bouts were vs random
        if s is not None:
            kw["sim"] = SimParams(**s)
        return cls(**kw)

    def explore_options(self) -> explore.ExploreOptions:
        return explore.ExploreOptions(
            max_samples=self.max_samples, min_new_per_round=self.min_new_per_round, max_rounds=self.max_rounds,
            n_initial=self.n_initial, initial_r_min_m=self.initial_r_min_m, initial_r_max_m=self.initial_r_max_m,
            initial_facing_share=self.initial_facing_share, initial_facing_rad=math.radians(self.initial_facing_deg),
            expand_fraction=self.expand_fraction, f0=self.f0, link_r_m=self.link_tol_r_m,
            link_theta_rad=self.link_tol_theta_rad, dedup_r_m=self.dedup_r_m, dedup_theta_rad=self.dedup_theta_rad,
            max_distance_m=self.max_distance_m, chunk_parents=self.chunk_parents, selection=self.selection,
            interaction_weight=self.interaction_weight)

    def cluster_options(self) -> cluster.ClusterOptions:
        return cluster.ClusterOptions(tol_r_m=self.tol_r_m, tol_theta_rad=self.tol_theta_rad, s_r_m=self.s_r_m,
                                      s_theta_rad=self.s_theta_rad)

    def validate(self) -> None:
        if self.max_samples < 1 or self.n_initial < 1 or self.f0 < 1 or self.chunk_parents < 1:
            raise ValueError("max_samples, n_initial, f0 and chunk_parents must be positive")
        if self.seed_bouts < 0 or self.seed_bout_seconds <= 0:
            raise ValueError("seed_bouts must be >= 0 and seed_bout_seconds positive")
        if self.seed_pairing not in SEED_PAIRINGS:
            raise ValueError(f"seed_pairing must be one of {', '.join(SEED_PAIRINGS)}, not {self.seed_pairing!r}")
        if not 0 <= self.initial_facing_share <= 1 or not 0 < self.initial_facing_deg <= 180:
            raise ValueError("initial_facing_share must be in [0, 1] and initial_facing_deg in (0, 180]")
        if not 0 < self.expand_fraction <= 1:
            raise ValueError("expand_fraction must be in (0, 1]")
        for name in ("tol_r_m", "tol_theta_rad", "link_tol_r_m", "link_tol_theta_rad", "dedup_r_m", "dedup_theta_rad"):
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be positive")
        if self.dedup_r_m > self.link_tol_r_m or self.dedup_theta_rad > self.link_tol_theta_rad:
            raise ValueError("the duplicate tolerance must not exceed the linking tolerance")


def build_fingerprint(lib_fp: str, options: BuildOptions, seed: int) -> str:
    """What a checkpoint must match to be resumed: library, options, seed, file format."""
    blob = json.dumps({"library": lib_fp, "options": options.to_json(), "seed": int(seed), "format": FORMAT,
                       "version": VERSION, "checkpoint": explore.CHECKPOINT_VERSION}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()


def peak_rss_mb() -> float:
    """Peak resident memory of this process (MiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def build_graph(library, options: BuildOptions = BuildOptions(), seed: int = 0, workers: int | None = 1,
                checkpoint_dir: str | os.PathLike | None = None, progress: bool = False,
                on_chunk: Callable[[int, int], None] | None = None,
                keep_checkpoint: bool = False, out: str | os.PathLike | None = None, backend: str = "local",
                address: str | None = None) -> tuple[InteractionGraph, dict]:
    """Build the Interaction Graph of ``library`` (a motion_graph.ActionLibrary).

    Args:
        options: build options; seed: seeds the sampler's initial states.
        workers: threads of the local backend, Ray actors of the ray backend (None or 0: all
            cores); does not change the result.
        backend: where the sampler, clustering and linking run: ``local`` (this process) or
            ``ray`` (igraph_fight.build.ray_backend; ``address``: a running cluster's, else a
            local Ray is started); the same graph and content hash either way.
        checkpoint_dir: folder for the sampler checkpoint (``archive.npz``); a build with the same
            library, options and seed resumes from it; one with other inputs raises ValueError.
            The edges' columns are memory-mapped files under its ``edges/`` while the graph is
            linked and written (igraph_fight.build.columns). Removed after success (after ``out``
            is in place) unless ``keep_checkpoint``.
        progress: progress bars on stderr.
        on_chunk: called after each sampler checkpoint (chunks done, samples).
        out: write the graph file here (InteractionGraph.save) before the checkpoint is removed.
    Returns (graph, report); the report has n_states, n_edges, build_seconds, peak_rss_mb,
    dead_end_fraction, snap_mean_cm, snap_max_cm and more.
    """
    options.validate()
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    lib_fp = library_fingerprint(library)
    fp = build_fingerprint(lib_fp, options, seed)
    tables = SimTables.from_library(library, options.sim)
    ckpt = None
    if checkpoint_dir is not None:
        Path(checkpoint_dir).mkdir(parents=True, exist_ok=True)
        ckpt = Path(checkpoint_dir) / "archive.npz"
        meta = Path(checkpoint_dir) / "build.json"
        if not meta.exists():
            atomic_write_text(meta, json.dumps({"fingerprint": fp, "options": options.to_json(), "seed": seed,
                                                "library": lib_fp}, indent=1))
    def chunk_done(chunks: int, n: int) -> None:
        kill_point("sample")
        if on_chunk is not None:
            on_chunk(chunks, n)

    from igraph_fight.build.backend import make_backend
    t = time.perf_counter()
    runner = make_backend(backend, tables, workers, address)
    timings["backend_start_s"] = time.perf_counter() - t
    resumed = ckpt is not None and ckpt.exists()
    try:
        t = time.perf_counter()
        extra = None
        if options.seed_bouts > 0 and not resumed:
            from igraph_fight.build.seeding import bout_seed_states
            extra = bout_seed_states(library, tables, options.seed_bouts, options.seed_bout_seconds, seed,
                                     options.seed_pairing, backend=runner)
        timings["seed_bouts_s"] = time.perf_counter() - t

        t = time.perf_counter()
        arc = explore.explore(tables, options.explore_options(), seed, ckpt, fp, progress, chunk_done, workers,
                              extra_initial=extra, backend=runner)
        timings["explore_s"] = time.perf_counter() - t

        kill_point("cluster")
        t = time.perf_counter()
        grows = explore.group_rows(tables.nextset, arc.si, options.f0)
        cl = cluster.cluster_samples(grows, arc.si, arc.sf, options.cluster_options(), backend=runner)
        timings["cluster_s"] = time.perf_counter() - t

        kill_point("link")
        t = time.perf_counter()
        ed = edges.link(tables, cl.si, cl.sf, options.f0, options.link_tol_r_m, options.link_tol_theta_rad,
                        options.max_distance_m, options.prune_dead_ends, options.s_r_m, options.s_theta_rad,
                        options.max_candidates, progress=progress, workers=workers, backend=runner,
                        spill_dir=Path(checkpoint_dir) / "edges" if checkpoint_dir is not None else None)
        timings["edges_s"] = time.perf_counter() - t
        backend_report = runner.report()
    finally:
        runner.close()

    t = time.perf_counter()
    graph, rep = _assemble(tables, cl, ed, options)
    timings["assemble_s"] = time.perf_counter() - t
    rep.update({
        "n_samples": len(arc), "sampler_rounds": arc.rounds, "sampler_stop": arc.stop_reason,
        "resumed_from_checkpoint": bool(resumed),
        "build_seconds": time.perf_counter() - t_start, "peak_rss_mb": peak_rss_mb(),
        "timings": {k: round(v, 3) for k, v in timings.items()},
        "workers": backend_report["workers"], "backend": backend_report, "seed": int(seed),
    })
    from motion_graph.classify import KINDS
    graph.header.update({
        "kinds_table": list(KINDS),
        "library": {"fingerprint": lib_fp, "n_actions": int(library.n_actions), "fps": float(library.fps),
                    "sources": sorted({os.path.basename(s) for s in library.sources})},
        "options": options.to_json(), "seed": int(seed), "package_version": package_version(),
        "report": {k: v for k, v in rep.items() if k not in ("build_seconds", "peak_rss_mb", "timings", "workers",
                                                             "resumed_from_checkpoint", "backend")},
    })
    graph.arrays["library_npz"] = np.frombuffer(library.to_bytes(), dtype=np.uint8)
    rep["content_hash"] = graph.content_hash
    if out is not None:
        graph.save(out)
        kill_point("written")
    if checkpoint_dir is not None and not keep_checkpoint:
        remove_checkpoint(checkpoint_dir)
    return graph, rep


def remove_checkpoint(checkpoint_dir: str | os.PathLike) -> None:
    """Delete a build's checkpoint folder and fsync its parent."""
    shutil.rmtree(checkpoint_dir, ignore_errors=True)
    fsync_dir(Path(checkpoint_dir).parent)


def _assemble(tables: SimTables, cl: cluster.Clusters, ed: edges.Edges,
              options: BuildOptions) -> tuple[InteractionGraph, dict]:
    S0 = len(cl.si)
    alive = ed.alive
    new_id = np.full(S0, -1, dtype=np.int64)
    new_id[alive] = np.arange(int(alive.sum()))
    src = new_id[ed.src]
    tgt = new_id[ed.target]
    S = int(alive.sum())
    counts = np.bincount(src, minlength=S)  # edges are ordered by source state, then menu order
    off = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    c = ed.cols
    st_si = cl.si[alive]
    st_sf = cl.sf[alive]
    snap_r_edge = c["snap_r"]
    snap_t_edge = c["snap_theta"]
    st_snap_r = np.zeros(S0)
    st_snap_t = np.zeros(S0)
    np.maximum.at(st_snap_r, cl.labels, cl.snap_r)
    np.maximum.at(st_snap_t, cl.labels, cl.snap_theta)
    a = {
        "state_offsets": off,
        "state_r": st_sf[:, 0], "state_theta_self": st_sf[:, 1], "state_theta_other": st_sf[:, 2],
        "state_m_self": st_si[:, SI_MSELF], "state_nextset": tables.nextset[st_si[:, SI_MSELF]],
        "state_m_other": st_si[:, SI_MOTHER], "state_f_other": st_si[:, SI_FOTHER],
        "state_mask_other": st_si[:, SI_MASK], "state_size": cl.size[alive],
        "state_snap_r": st_snap_r[alive], "state_snap_theta": st_snap_t[alive],
        "edge_target": tgt, "edge_swap": ed.swap.astype(np.uint8), "edge_action": ed.action,
        "feat_duration": c["frames"] / tables.fps, "feat_r": c["r"],
        "feat_r_mean": c["r_mean"], "feat_theta_self": c["theta_self"],
        "feat_theta_other": c["theta_other"], "feat_dmg_given": c["dmg_given"],
        "feat_dmg_received": c["dmg_received"], "feat_kind": tables.kinds[ed.action],
        "feat_other_kind": tables.kinds[cl.si[ed.src, SI_MOTHER]],
        "feat_def_self": c["def_self"], "feat_def_other": c["def_other"],
        "edge_snap_r": snap_r_edge, "edge_snap_theta": snap_t_edge,
    }
    from igraph_fight.graph import ALL_ARRAYS
    arrays = {k: np.ascontiguousarray(v, dtype=ALL_ARRAYS[k]) for k, v in a.items()}
    g = InteractionGraph(arrays, {})
    member_alive = alive[cl.labels]
    snap = cluster.Clusters(cl.labels[member_alive], cl.si, cl.sf, cl.size, cl.snap_r[member_alive],
                            cl.snap_theta[member_alive], cl.snap_frames[member_alive]).report()
    deg = np.diff(off)
    E = len(tgt)
    n_menu = int(np.sum((tables.next_offsets[st_si[:, SI_MSELF] + 1] - tables.next_offsets[st_si[:, SI_MSELF]])))
    rep = {
        "n_states": S, "n_edges": E, "n_states_before_pruning": S0,
        "n_edges_before_pruning": ed.stats["landings_linked_before_pruning"],
        "pruned_states": int(S0 - S), "pruned_fraction": float((S0 - S) / S0) if S0 else 0.0,
        "dead_end_fraction": float(np.mean(deg == 0)) if S else 1.0,
        "dead_end_fraction_before_pruning": ed.stats["dead_end_fraction_before_pruning"],
        "mean_out_degree": float(E / S) if S else 0.0,
        "menu_actions_linked": float(E / n_menu) if n_menu else 0.0,
        "out_of_arena_fraction": ed.stats["out_of_arena_fraction"],
        **snap,
        "edge_snap_mean_cm": float(100 * snap_r_edge.mean()) if E else 0.0,
        "edge_snap_max_cm": float(100 * snap_r_edge.max()) if E else 0.0,
        "edge_snap_mean_deg": float(np.degrees(snap_t_edge.mean())) if E else 0.0,
        "edge_snap_max_deg": float(np.degrees(snap_t_edge.max())) if E else 0.0,
        "n_groups": int(len(np.unique(np.stack([arrays["state_nextset"], arrays["state_m_other"],
                                                arrays["state_f_other"] // options.f0,
                                                arrays["state_mask_other"]], 1), axis=0))) if S else 0,
        "attack_edges": int(np.sum(np.isin(arrays["feat_kind"], _attack_kind_ids()))),
        "edges_with_damage_given": int(np.sum(arrays["feat_dmg_given"] > 0)),
        "edges_with_damage_received": int(np.sum(arrays["feat_dmg_received"] > 0)),
    }
    return g, rep


def _attack_kind_ids() -> np.ndarray:
    from motion_graph.classify import ATTACK_KINDS, KINDS
    return np.array([KINDS.index(k) for k in ATTACK_KINDS])

