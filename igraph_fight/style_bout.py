"""Style bouts: two Interaction Graph fighters with given styles, from a graph file to artifacts."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from igraph_fight.agents import IGAgent
from igraph_fight.controller import NPCController
from igraph_fight.game import FightGame, GameConfig
from igraph_fight.graph import load_graph
from igraph_fight.match import run_bout, write_bout_artifacts


def run_style_bout(graph_path: str | Path, style_a: str, style_b: str, depth_a: int = 5, depth_b: int = 5,
                   seconds: float = 60.0, seed: int = 1, out: str | Path = "out/fight", library=None,
                   swap_a: tuple[float, str] | None = None, progress: bool = False,
                   first_ply_a: str = "table", first_ply_b: str = "table") -> dict:
    """Play one traced bout and write its artifacts; returns the summary (with ``artifacts``).

    swap_a: (t seconds, style) to switch fighter A's style mid-bout (recomputed in the background),
    0 <= t < seconds. first_ply_a / _b: each fighter's decision rule (NPCController's first_ply:
    table, exact, exact2). ValueError for a bout length that is not a finite number > 0, a negative
    seed or a swap outside the bout; planner.StyleError for a style that does not load (both
    before anything is computed).
    """
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not (math.isfinite(seconds)
                                                                                   and seconds > 0):
        raise ValueError(f"seconds must be a finite number > 0, got {seconds!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0, got {seed!r}")
    if swap_a is not None:
        from planner import load_style
        if not (isinstance(swap_a[0], (int, float)) and 0 <= swap_a[0] < seconds):
            raise ValueError(f"swap_a: the swap time must lie in [0, {seconds:g}) s (the bout), got {swap_a[0]!r}")
        load_style(swap_a[1])
    graph = load_graph(graph_path)
    if library is not None and not hasattr(library, "n_actions"):
        from motion_graph.library import load_library
        library = load_library(library)
    lib = library if library is not None else graph.load_library()
    ca = NPCController(graph, lib, style=style_a, depth=depth_a, first_ply=first_ply_a)
    cb = NPCController(graph, lib, style=style_b, depth=depth_b, first_ply=first_ply_b)
    game = FightGame(lib, GameConfig(max_seconds=seconds, sim=graph.sim_params()),
                     tables=ca.tables)
    tag = {"table": "", "exact": "+exact", "exact2": "+exact2"}
    a = IGAgent(ca, f"{ca.style}({depth_a}){tag[first_ply_a]}")
    b = IGAgent(cb, f"{cb.style}({depth_b}){tag[first_ply_b]}")
    schedule = []
    if swap_a is not None:
        t, st = swap_a

        def do_swap() -> None:
            ca.set_style(st, wait=True)
            a.name = f"{a.name}->{st}"

        schedule.append((float(t), do_swap, f"A switches to {st}"))
    res = run_bout(game, [a, b], seconds, np.random.default_rng(seed), trace=True, schedule=schedule)
    arts = write_bout_artifacts(game, res, out, title=f"{style_a} vs {style_b}")
    summary = res.summary()
    summary.update(artifacts=arts, off_graph_a=a.off_graph / max(a.decisions, 1),
                   off_graph_b=b.off_graph / max(b.decisions, 1),
                   snap_mean_cm=100 * float(np.mean(a.snap_m + b.snap_m)) if (a.snap_m or b.snap_m) else 0.0,
                   style_swap_ms=ca.last_swap_ms)
    import json
    from motion_graph.atomic import atomic_write_text
    atomic_write_text(Path(out) / "summary.json", json.dumps(summary, indent=1))
    return summary
