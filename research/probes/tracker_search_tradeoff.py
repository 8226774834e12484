"""Strength against cost of the run-time search controller (research/search_controller.py).

The protocol's first N walks (seed 0, 20 actions) under a search with the given candidates and
lookahead; prints one JSON line: completion, mean time to fall, MPJPE and the real-time factor
(one process). research/notes/TRAINING.md:

    python -m research.probes.tracker_search_tradeoff --candidates 8 --lookahead 24 --walks 10 [--early-accept [--incremental]] [--first-kept] [--reuse]
    python -m research.probes.tracker_search_tradeoff --first 40 --walks 30 --workers 2 --json-out F.json
        (the protocol's walks 40-69 under the default search, per-walk rows kept)
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


from tracker.track.evaluation import draw_walks, make_setup, run_walks, summarise
from research.search_controller import SearchSettings, load_search
from tracker.track.walks import walk_source


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--candidates", type=int, default=16)
    ap.add_argument("--lookahead", type=int, default=45, help="control steps (30 per second)")
    ap.add_argument("--space", default="joints", choices=("joints", "layer"))
    ap.add_argument("--early-accept", action="store_true", help="SearchSettings.early_accept")
    ap.add_argument("--reuse", action="store_true", help="SearchSettings.reuse")
    ap.add_argument("--incremental", action="store_true", help="SearchSettings.incremental (with --early-accept)")
    ap.add_argument("--first-kept", action="store_true", help="SearchSettings.first_kept")
    ap.add_argument("--walks", type=int, default=10)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--first", type=int, default=0, help="skip the seed's first walks")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--json-out", default="", help="also write the metrics and per-walk rows here")
    a = ap.parse_args(argv)
    setup = make_setup(walk_source(None))
    ctrl = load_search(None, SearchSettings(candidates=a.candidates, lookahead=a.lookahead, space=a.space,
                                                  early_accept=a.early_accept, reuse=a.reuse,
                                                  incremental=a.incremental, first_kept=a.first_kept))
    walks = draw_walks(setup.source, a.first + a.walks, 20, a.seed)[a.first:]
    rows = run_walks(setup, ctrl, walks, workers=a.workers)
    m = summarise(rows, ctrl, setup, 20, a.seed)
    if a.json_out:
        Path(a.json_out).write_text(json.dumps(dict(m, first=a.first, rows=[
            dict(walk=r.walk, time_s=r.time_s, duration_s=r.duration_s, fell=bool(r.fell), mpjpe_m=r.mpjpe_m)
            for r in rows]), indent=1))
    keys = ("n_walks", "completion_rate", "mean_time_to_fall_s", "mean_walk_duration_s", "mpjpe_cm", "realtime_factor")
    print(json.dumps(dict(candidates=a.candidates, lookahead=a.lookahead, space=a.space, early_accept=a.early_accept,
                          reuse=a.reuse, incremental=a.incremental, first_kept=a.first_kept, **{k: m[k] for k in keys})))
    return 0


if __name__ == "__main__":
    sys.exit(main())
