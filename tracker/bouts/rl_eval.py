"""Planner + tracker fighters against the physics RL baseline over N physics bouts.

    igraph-fight tracker rl eval --graph G.igz --rl rl.pt --styles infighter,outboxer --bouts 10

``evaluate_vs_rl``: planner+tracker fighters (NPCController, given style and depth) against the RL
policy over N physics bouts (seeds 0..N-1, the IG fighter as A): score (IG hits - RL hits), falls
and hits each way.
"""
from __future__ import annotations

import multiprocessing as mp
import re

import numpy as np

from tracker.bouts.rl_agent import DEFAULT_RL_CKPT, load_rl_agent


_ROW_KEYS = ("seed", "score", "hits_a", "hits_b", "falls_a", "falls_b", "planned_hits_a", "planned_hits_b",
             "planned_realised", "planned_hits", "mean_distance_m", "realtime_factor", "damage_n_a", "damage_n_b",
             "decisions_a", "decisions_b", "kind_share_a", "kind_share_b")


def _eval_rows(job: tuple, log=None, trk=None) -> list[dict]:
    """One style's bouts for the given seeds (a worker of evaluate_vs_rl; bouts depend on their
    seed only, so any split of the seeds gives the same rows). ``trk``: the tracking controller
    when the caller has it loaded already."""
    (graph, library, rl_ckpt, tracker, root_assist, style, depth, first_ply, hit_model, future, seconds, seeds) = job
    if log is None:
        import torch
        torch.set_num_threads(1)
        log = lambda s: print(s, flush=True)  # noqa: E731
    from igraph_fight.graph import load_graph

    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.loaders import bout_library, load_tracker, make_agent
    from tracker.bouts.run import search_stats
    from tracker.bouts.setup import BoutConfig, BoutSetup
    g = load_graph(graph)
    lib = bout_library(None, library) if library else g.load_library()
    trk = trk if trk is not None else load_tracker(tracker)
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), root_assist=root_assist, tracker=trk)
    rl = load_rl_agent(rl_ckpt, lib)
    spec = style if not hit_model else f"{style}+phys" + ("" if hit_model == "default" else f":{hit_model}")
    ig = make_agent(spec, g, lib, depth, first_ply=first_ply, future=future)
    npc = ig.controller
    rows = []
    for seed in seeds:
        bout = PhysicsBout(setup, [ig, rl], trk, BoutConfig(seconds=seconds, record_qpos=False,
                                                            physics_hz=setup.scene.options.physics_hz))
        s = bout.run(seed=seed).summary()
        rows.append({k: s[k] for k in _ROW_KEYS})
        if (stats := search_stats(trk)) is not None:
            rows[-1]["search_stats"] = stats
        log(f"{style} vs rl, seed {seed}: score {s['score']:+.0f} (hits {s['hits_a']:.0f}-{s['hits_b']:.0f}), "
            f"falls {s['falls_a']}-{s['falls_b']}, planned {s['planned_hits']:.0f} realised {s['planned_realised']:.0f}, "
            f"distance {s['mean_distance_m']:.2f} m, rtf {s['realtime_factor']:.1f}x")
    npc.close()
    return rows


def evaluate_vs_rl(graph: str, rl_ckpt: str | None, styles: list[str], n_bouts: int = 10, seconds: float = 60.0,
                   depth: int = 5, tracker=None, library: str | None = None, seed0: int = 0,
                   root_assist: bool = False, log=print, first_ply: str = "table",
                   hit_model: str | None = None, future: str = "calibrated", workers: int = 1) -> dict:
    """IG fighters (each style, depth ``depth``, NPCController's ``first_ply``, as A) vs the RL baseline (B) over ``n_bouts``
    physics bouts each (seeds seed0..seed0+n-1). ``hit_model`` ("default" or a path): the IG
    fighters score their first ply with physically measured hit odds (tracker.bouts.hit_model.phys_fighter,
    later plies by ``future``) instead of ``first_ply``. ``workers`` > 1 plays the bouts in that many
    processes (the same rows: a bout depends on its seed only). Returns per style: scores (IG hits -
    RL hits), mean / std / wins, falls and hits each way, planned-vs-realised of the IG fighter."""
    from tracker.bouts.loaders import load_tracker
    if hit_model:
        from tracker.bouts.hit_model import load_hit_model
        load_hit_model(None if hit_model == "default" else hit_model)      # a bad path fails here, not in a worker
    trk = load_tracker(tracker)
    out = {"tracker": getattr(trk, "describe", lambda: trk.name)(), "rl": str(rl_ckpt or DEFAULT_RL_CKPT),
           "seconds": seconds, "n_bouts": n_bouts, "depth": depth, "first_ply": first_ply, "root_assist": root_assist,
           "hit_model": hit_model, "future": future if hit_model else None, "styles": {}}
    seeds = list(range(seed0, seed0 + n_bouts))
    for style in styles:
        jobs = [(graph, library, rl_ckpt, tracker, root_assist, style, depth, first_ply, hit_model, future, seconds,
                 seeds[i::workers]) for i in range(max(1, workers)) if seeds[i::workers]]
        if len(jobs) <= 1:
            rows = _eval_rows(jobs[0], log, trk) if jobs else []
        else:
            # spawn, not fork: the parent has torch's thread pool running (the tracker), which a
            # forked child can deadlock on
            with mp.get_context("spawn").Pool(len(jobs)) as pool:
                rows = sorted((r for part in pool.map(_eval_rows, jobs) for r in part), key=lambda r: r["seed"])
        sc = np.array([r["score"] for r in rows])
        tot = lambda k: float(sum(r[k] for r in rows))  # noqa: E731
        out["styles"][style] = {
            "bouts": rows, "mean_score": float(sc.mean()), "std_score": float(sc.std()),
            "wins": int((sc > 0).sum()), "draws": int((sc == 0).sum()), "losses": int((sc < 0).sum()),
            "hits_ig": tot("hits_a"), "hits_rl": tot("hits_b"),
            "falls_ig_per_min": tot("falls_a") / (n_bouts * seconds / 60), "falls_rl_per_min": tot("falls_b") / (n_bouts * seconds / 60),
            "planned_hits": tot("planned_hits"), "planned_realised": tot("planned_realised"),
            "damage_n_ig": tot("damage_n_a"), "damage_n_rl": tot("damage_n_b"),
            "kind_share_ig": _pooled_shares(rows, "a"), "kind_share_rl": _pooled_shares(rows, "b"),
        }
    return out


def _pooled_shares(rows: list[dict], side: str) -> dict:
    """Share of each action kind among one side's decisions over all bouts (decision-weighted)."""
    counts: dict[str, float] = {}
    for r in rows:
        for k, v in r[f"kind_share_{side}"].items():
            counts[k] = counts.get(k, 0.0) + v * r[f"decisions_{side}"]
    n = sum(counts.values())
    return {k: round(v / n, 4) for k, v in sorted(counts.items(), key=lambda kv: -kv[1])} if n else {}


def split_styles(text: str) -> list[str]:
    """``--styles`` to fighter specs: split at commas, except a comma before a digit, which belongs to
    a style's options (``close=R,THETA``, ``:avoid=A,B``)."""
    return [s for s in re.split(r",(?![\d.])", text) if s]
