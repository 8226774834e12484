"""The graph `igraph-fight play` uses without --graph: a small Interaction Graph of the default
mocap, built once and kept in the user cache (``~/.cache/igraph-fight/play/graph.igz``).

Each start segments the default mocap (under a second), and reuses the cached graph when the
fingerprint of the resulting action library and the build settings match the ones the cached
graph was built with; otherwise it builds the graph again (the demo's settings: 30-70 s on a
2-core VM depending on its load, with progress bars; resumable after an interruption).
"""
from __future__ import annotations

import json
import shutil
import sys
import time
from dataclasses import replace
from pathlib import Path

#: what the first start costs, as the command says it (2-core VM)
FIRST_START = "30-70 s on 2 cores, depending on their load"


def cache_dir() -> Path:
    from motion_graph.paths import user_cache_dir
    return user_cache_dir() / "play"


def ensure_demo_graph(mocap: str | None = None, progress: bool = True, out=sys.stderr, options=None) -> Path:
    """The cached demo graph's path, built first when missing or stale (module docstring).
    ``options``: the build options (default: the demo's, igraph_fight.demo)."""
    from motion_graph.atomic import atomic_write_text
    from motion_graph.paths import boxing_files
    from motion_graph.retarget import build_retargeted_library

    from igraph_fight.build.pipeline import BuildOptions, build_graph
    from igraph_fight.demo import DEMO_MAX_SAMPLES, DEMO_SEED_BOUTS
    from igraph_fight.graph import header_summary, library_fingerprint

    files = boxing_files(mocap)
    lib = build_retargeted_library(files)
    fp = library_fingerprint(lib)
    if options is None:
        options = replace(BuildOptions(), max_samples=DEMO_MAX_SAMPLES, seed_bouts=DEMO_SEED_BOUTS)
    want = json.loads(json.dumps({"library": fp, "options": options.to_json(), "seed": 0}))
    d = cache_dir()
    path = d / "graph.igz"
    manifest = d / "manifest.json"
    if path.is_file() and manifest.is_file():
        try:
            have = json.loads(manifest.read_text())
            same = (have.get("options") == want["options"] and have.get("seed") == want["seed"]
                    and header_summary(path).get("library", {}).get("fingerprint") == fp)
        except (OSError, ValueError, KeyError):
            same = False
        if same:
            return path
    d.mkdir(parents=True, exist_ok=True)
    ckpt = d / "graph.igz.ckpt"
    try:  # a checkpoint of other inputs cannot be resumed: start afresh
        b = json.loads((ckpt / "build.json").read_text())
        if b.get("library") != fp or b.get("options") != want["options"] or b.get("seed") != want["seed"]:
            shutil.rmtree(ckpt, ignore_errors=True)
    except (OSError, ValueError):
        pass
    print(f"igraph-fight play: building the demo graph of {', '.join(f.name for f in files)} into {path} "
          f"(first start: {FIRST_START}; later starts reuse it)", file=out, flush=True)
    t0 = time.perf_counter()
    graph, rep = build_graph(lib, options, 0, workers=0, checkpoint_dir=ckpt, progress=progress, out=path)
    atomic_write_text(manifest, json.dumps({**want, "n_states": rep.get("n_states"), "n_edges": rep.get("n_edges"),
                                            "build_s": round(time.perf_counter() - t0, 1)}, indent=1))
    print(f"igraph-fight play: demo graph ready ({rep.get('n_states')} states, {rep.get('n_edges')} edges, "
          f"{time.perf_counter() - t0:.0f} s)", file=out, flush=True)
    return path
