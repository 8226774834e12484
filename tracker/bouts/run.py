"""Entry points of physics bouts: one bout from a graph file to its artifacts
(`igraph-fight fight --physics ...`) and a series of bouts with aggregate figures
(`igraph-fight tracker bouts series ...`)."""
from __future__ import annotations

import json
import os
from dataclasses import replace
from pathlib import Path

import numpy as np

from tracker.bouts.loaders import load_tracker, make_agent
from tracker.bouts.media import machine_load, write_physics_artifacts
from tracker.bouts.physics_bout import PhysicsBout
from tracker.bouts.setup import BoutConfig, BoutSetup


# ----------------------------------------------------------------------------------------------
# entry points: `igraph-fight fight --physics ...` and `igraph-fight tracker bouts fight ...`


def run_physics_fight(graph, style_a: str = "infighter", style_b: str = "outboxer", depth_a: int = 5,
                      depth_b: int = 5, seconds: float = 60.0, seed: int = 1, out: str | os.PathLike = "out/fight",
                      library=None, swap_a: tuple[float, str] | None = None, tracker=None,
                      video: bool = True, video_fps: float = 15.0, width: int = 640, height: int = 360,
                      root_assist: bool = False, progress: bool = False, config: BoutConfig | None = None,
                      max_wall_s: float | None = None) -> dict:
    """One physics bout from a graph file to artifacts (the physics twin of igraph_fight.bouts.run_style_bout).
    ``tracker``: a spec for tracker.bouts.loaders.load_tracker ("pd", a checkpoint, None) or a
    tracker object. Returns the summary dict (see PhysicsBoutResult.summary, plus ``artifacts``). ``max_wall_s``: stop
    the bout after this many wall-clock seconds (PhysicsBout.run); the summary's ``seconds`` says how
    much was simulated."""
    from igraph_fight.graph import load_graph
    g = load_graph(graph) if not hasattr(graph, "arrays") else graph
    if library is not None and not hasattr(library, "n_actions"):
        from motion_graph.library import load_library
        library = load_library(library)
    lib = library if library is not None else g.load_library()
    trk = load_tracker(tracker)
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), root_assist=root_assist, tracker=trk)
    agents = [make_agent(style_a, g, lib, depth_a), make_agent(style_b, g, lib, depth_b)]
    cfg = config or BoutConfig(seconds=seconds)
    cfg = replace(cfg, seconds=seconds, physics_hz=setup.scene.options.physics_hz)
    bout = PhysicsBout(setup, agents, trk, cfg)
    if swap_a is not None:
        t_sw, st = swap_a
        a0 = agents[0]
        if not hasattr(a0, "set_style"):
            raise ValueError("--swap-a needs an Interaction Graph fighter as A")

        def do_swap() -> None:
            a0.set_style(st)
            a0.name = f"{a0.name}->{st}"

        bout.schedule.append((float(t_sw), do_swap, f"A switches to {st}"))
    res = bout.run(seed=seed, progress=progress, max_wall_s=max_wall_s)
    title = f"{style_a} vs {style_b}" + (" [root assist: not physics]" if root_assist else f" [{res.physics}]")
    summary = write_physics_artifacts(bout, res, out, title=title, video=video, video_fps=video_fps, width=width,
                                      height=height)
    summary["root_assist"] = bool(root_assist)
    summary["reset_place"] = cfg.reset_place
    summary["reset_facing"] = cfg.reset_facing
    summary["machine_load"] = machine_load()
    if (stats := search_stats(trk)) is not None:
        summary["search_stats"] = stats
    from motion_graph.atomic import atomic_write_text
    atomic_write_text(Path(out) / "summary.json", json.dumps(summary, indent=1))
    return summary


def search_stats(tracker) -> list[dict] | None:
    """A search tracker's counts over the bout it last played, per fighter (the ``stats`` dict of
    each of its ``searchers``, e.g. research.search_controller.SearchController's searches, full,
    none_up, fallen_chosen); None for a tracker without searchers."""
    if not hasattr(tracker, "searchers"):
        return None
    return [dict(sc.stats) for sc in tracker.searchers]


def _median(xs: list) -> float | None:
    return float(np.median(xs)) if xs else None


def run_series(graph, style_a: str = "infighter", style_b: str = "outboxer", n_bouts: int = 10, seconds: float = 60.0,
               depth_a: int = 5, depth_b: int = 5, seed0: int = 0, tracker=None,
               root_assist: bool = False, log=print, config: BoutConfig | None = None) -> dict:
    """``n_bouts`` physics bouts (seeds seed0..) between two agents (styles or rl[:CKPT]) under the
    rules ``config`` (default BoutConfig; its seconds are replaced by ``seconds``); the
    per-bout summaries and the aggregate: mean / std score, falls per fighter per minute, planned
    and realised hits (ratio over all bouts), mean real-time factor."""
    from igraph_fight.graph import load_graph
    g = load_graph(graph) if not hasattr(graph, "arrays") else graph
    lib = g.load_library()
    trk = load_tracker(tracker)
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), root_assist=root_assist, tracker=trk)
    agents = [make_agent(style_a, g, lib, depth_a), make_agent(style_b, g, lib, depth_b)]
    cfg = replace(config or BoutConfig(), seconds=seconds, record_qpos=False,
                  physics_hz=setup.scene.options.physics_hz)
    rows = []
    for i in range(n_bouts):
        bout = PhysicsBout(setup, agents, trk, cfg)
        s = bout.run(seed=seed0 + i).summary()
        s.pop("agents", None)
        if (stats := search_stats(trk)) is not None:
            s["search_stats"] = stats
        rows.append(s)
        log(f"seed {seed0 + i}: score {s['score']:+.0f} (hits {s['hits_a']:.0f}-{s['hits_b']:.0f}), falls "
            f"{s['falls_a']}-{s['falls_b']}, planned {s['planned_hits']:.0f} realised {s['planned_realised']:.0f}, "
            f"unplanned {s['unplanned_hits']:.0f}, distance {s['mean_distance_m']:.2f} m, rtf {s['realtime_factor']:.1f}x")
    tot = lambda k: float(sum(r[k] for r in rows))  # noqa: E731
    sc = np.array([r["score"] for r in rows])
    minutes = n_bouts * seconds / 60.0
    p = tot("planned_hits")
    return {"a": style_a, "b": style_b, "n_bouts": n_bouts, "seconds": seconds, "root_assist": root_assist,
            "reset_place": cfg.reset_place, "reset_facing": cfg.reset_facing,
            "tracker": rows[0]["tracker"] if rows else None,
            "mean_score": float(sc.mean()), "std_score": float(sc.std()), "wins_a": int((sc > 0).sum()),
            "losses_a": int((sc < 0).sum()), "hits_a": tot("hits_a"), "hits_b": tot("hits_b"),
            "falls_per_min_a": tot("falls_a") / minutes, "falls_per_min_b": tot("falls_b") / minutes,
            "planned_hits": p, "planned_realised": tot("planned_realised"),
            "planned_realised_ratio": tot("planned_realised") / p if p else None,
            "unplanned_hits": tot("unplanned_hits"),
            "planned_closest_m_median": _median([g for r in rows for g in r["planned_closest_m"] if g is not None]),
            "mean_distance_m": tot("mean_distance_m") / max(n_bouts, 1),
            "realtime_factor_mean": tot("realtime_factor") / max(n_bouts, 1),
            "physics_label": rows[0].get("physics_label") if rows else None,
            **({"assist_a": _pooled_assist([r["assist_a"] for r in rows]),
                "assist_b": _pooled_assist([r["assist_b"] for r in rows]), "hits_at_cap": int(tot("hits_at_cap"))}
               if rows and "assist_a" in rows[0] else {}),
            "bouts": rows}


def _pooled_assist(per_bout: list[dict]) -> dict:
    """Per-fighter assist figures over several bouts: means weighted by control steps, the p95s as the
    largest bout p95 (an upper bound: the per-step values are not kept), the cap as reported."""
    steps = np.array([d["steps"] for d in per_bout], float)
    w = steps / steps.sum() if steps.sum() > 0 else np.full(len(steps), 1.0 / max(len(steps), 1))
    mean = lambda k: float(np.dot(w, [d[k] for d in per_bout]))  # noqa: E731
    return {"cap_mg": per_bout[0]["cap_mg"], "steps": int(steps.sum()),
            "force_mean_mg": mean("force_mean_mg"), "force_p95_mg": max(d["force_p95_mg"] for d in per_bout),
            "torque_mean_mgm": mean("torque_mean_mgm"), "torque_p95_mgm": max(d["torque_p95_mgm"] for d in per_bout),
            "at_cap_share": mean("at_cap_share"), "impulse_n_s_per_s": mean("impulse_n_s_per_s"),
            "angular_impulse_nm_s_per_s": mean("angular_impulse_nm_s_per_s")}
