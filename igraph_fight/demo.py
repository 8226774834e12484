"""The end-to-end kinematic demo: mocap -> actions -> (graph -> bout) with artifacts on disk."""
from __future__ import annotations

import json
import time
from pathlib import Path


def run_demo(mocap: str | None = None, out: str | Path = "out/demo", seed: int = 0, progress: bool = True) -> dict:
    """Run the demo chain and write its artifacts under `out`; returns a summary dict."""
    from motion_graph.library import LibraryParams, library_from_clips, segment_files
    from motion_graph.plot import plot_timelines

    from .cli_mocap import default_boxing_files

    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = default_boxing_files(mocap)
    params = LibraryParams()
    clips = segment_files(files, params, progress=progress)
    lib = library_from_clips(clips, params)
    lib.save(out / "library.npz")
    plot_timelines([{
        "name": Path(c.path).name, "fps": c.motion.fps, "contacts": c.segmentation.contacts,
        "quietness": c.segmentation.quietness, "reach": c.features.reach, "cuts": c.segmentation.cuts,
        "labels": [lib.labels[i] for i in range(lib.n_actions) if lib.sources[i] == c.path],
        "strikes": c.strikes} for c in clips], out / "segmentation.png")
    summary = {"n_actions": lib.n_actions, "label_counts": lib.label_counts(), **lib.graph_report(),
               "artifacts": {"library": str(out / "library.npz"), "segmentation_plot": str(out / "segmentation.png")},
               "seconds": round(time.perf_counter() - t0, 2)}
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    summary["artifacts"]["summary"] = str(out / "summary.json")
    return summary
