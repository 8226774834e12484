"""Physics bouts with the fighters passing through each other: how many falls the opponent's
contacts cause (docs/results.md, Assisted physics).

    python -m research.probes.bout_no_contacts --graph G.igz --bouts 12 [--seed0 1] [--contacts]

Fighter geoms keep colliding with the floor only (conaffinity bit 1); ``--contacts`` plays the same
bouts unchanged for the paired figure.
"""
from __future__ import annotations

import argparse

from tracker.bouts.run import run_series
from tracker.bouts.setup import BoutSetup


def _floor_only(setup: BoutSetup) -> BoutSetup:
    m = setup.scene.model
    for i in range(m.ngeom):
        if m.geom(i).name != "floor":
            m.geom_conaffinity[i] &= 1
    return setup


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--graph", required=True)
    ap.add_argument("--bouts", type=int, default=12)
    ap.add_argument("--seed0", type=int, default=1)
    ap.add_argument("--contacts", action="store_true", help="keep the fighters' contacts (the control)")
    a = ap.parse_args()
    create = BoutSetup.create.__func__
    if not a.contacts:
        BoutSetup.create = classmethod(lambda cls, *p, **k: _floor_only(create(cls, *p, **k)))
    out = run_series(a.graph, n_bouts=a.bouts, seconds=60.0, seed0=a.seed0, log=lambda *x: None)
    print(f"{'with' if a.contacts else 'without'} fighter contacts, {a.bouts} bouts: falls per minute "
          f"{out['falls_per_min_a']:.2f} / {out['falls_per_min_b']:.2f}, hits {out['hits_a']:.0f} / {out['hits_b']:.0f}")


if __name__ == "__main__":
    main()
