"""The end-to-end kinematic demo: mocap -> actions -> Interaction Graph -> a bout with a style swap.

Writes under ``out``: library.npz, segmentation.png, graph.igz, bout/ (log.jsonl, summary.json,
distance.png, bout.html, A.bvh, B.bvh) and summary.json; returns the summary.
"""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

from motion_graph.atomic import atomic_write_text

#: Sampler archive of the demo's graph: sized for about a minute on 2 cores, not the default's several.
DEMO_MAX_SAMPLES = 250_000
#: Seed bouts of the demo's graph (the default's 1024 take about 90 s alone: the coverage they buy
#: matters for the evaluation, not for one watchable bout).
DEMO_SEED_BOUTS = 256


def run_demo(mocap: str | None = None, out: str | Path = "out/demo", seed: int = 0, progress: bool = True,
             seconds: float = 60.0, swap_at_s: float = 30.0, max_samples: int = DEMO_MAX_SAMPLES) -> dict:
    """Segment the shared boxing takes (on one body), build a small Interaction Graph, and play infighter (A) vs
    outboxer (B) where A switches to outboxer at ``swap_at_s``; write every artifact."""
    from motion_graph.library import LibraryParams
    from motion_graph.plot import plot_timelines
    from motion_graph.retarget import retargeted_library_and_clips

    from igraph_fight.style_bout import run_style_bout
    from igraph_fight.build.pipeline import BuildOptions, build_graph
    from motion_graph.paths import boxing_files

    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    files = boxing_files(mocap)
    params = LibraryParams()
    lib, clips = retargeted_library_and_clips(files, params, progress=progress)
    lib.save(out / "library.npz")
    plot_timelines([{
        "name": Path(c.path).name, "fps": c.motion.fps, "contacts": c.segmentation.contacts,
        "quietness": c.segmentation.quietness, "reach": c.features.reach, "cuts": c.segmentation.cuts,
        "labels": [lib.labels[i] for i in range(lib.n_actions) if lib.sources[i] == c.path],
        "strikes": c.strikes} for c in clips], out / "segmentation.png")
    timings["segment_s"] = time.perf_counter() - t0

    t = time.perf_counter()
    options = replace(BuildOptions(), max_samples=max_samples, seed_bouts=DEMO_SEED_BOUTS)
    # the graph file is written before the checkpoint goes: a kill during the write resumes
    graph, rep = build_graph(lib, options, seed, workers=0, checkpoint_dir=out / "graph.igz.ckpt", progress=progress,
                             out=out / "graph.igz")
    timings["build_s"] = time.perf_counter() - t

    t = time.perf_counter()
    bout = run_style_bout(out / "graph.igz", "infighter", "outboxer", 5, 5, seconds, seed + 1, out / "bout",
                          library=lib, swap_a=(swap_at_s, "outboxer"), progress=progress)
    timings["bout_s"] = time.perf_counter() - t
    summary = {
        "n_actions": lib.n_actions, "label_counts": lib.label_counts(),
        "action_graph": lib.graph_report(),
        "graph": {k: rep[k] for k in ("n_states", "n_edges", "mean_out_degree", "dead_end_fraction", "snap_mean_cm",
                                      "snap_max_cm", "content_hash") if k in rep},
        "bout": {k: v for k, v in bout.items() if k != "artifacts"},
        "artifacts": {"library": str(out / "library.npz"), "segmentation_plot": str(out / "segmentation.png"),
                      "graph": str(out / "graph.igz"), **{f"bout_{k}": v for k, v in bout["artifacts"].items()}},
        "timings_s": {k: round(v, 2) for k, v in timings.items()},
        "seconds": round(time.perf_counter() - t0, 2),
    }
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1))
    summary["artifacts"]["summary"] = str(out / "summary.json")
    return summary
