"""Cross-entropy search over the virtual-force balance gains (tracker/vforce.py) under PD tracking.

Each candidate (com_kp, com_kd, root_kp, root_kd, torque_clip; searched in log space) is scored by
the mean time to fall over the same random 20-action walks of the tuning seed (100), no force on
the root; both cores evaluate candidates. This is how BalanceGains' defaults were picked (ninth
session: 8 generations of 12 on 24 walks, about 7 minutes; tracker/TRAINING.md).

    python benchmarks/tracker_vforce_cem.py [--walks 24] [--generations 8] [--population 12] [--seed 0]
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tracker.evaluate import draw_walks, make_setup, run_walk  # noqa: E402
from tracker.pd import PDController  # noqa: E402
from tracker.walks import walk_source  # noqa: E402

START = (4000.0, 800.0, 1000.0, 100.0, 150.0)    # hand-set first guess (PD + it: 2.61 s on the 24 walks)
_SETUP = None
_WALKS: list = []


def _init(n_walks: int, seed: int) -> None:
    global _SETUP, _WALKS
    _SETUP = make_setup(walk_source(None))
    _WALKS = draw_walks(_SETUP.source, n_walks, 20, seed)


def score(log_gains: np.ndarray) -> float:
    """Mean time to fall (s) of PD + the balance layer with exp(log_gains) on the walks."""
    ctrl = PDController(balance=tuple(float(g) for g in np.exp(log_gains)))
    return float(np.mean([run_walk(_SETUP, ctrl, w).time_s for w in _WALKS]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--walks", type=int, default=24)
    ap.add_argument("--generations", type=int, default=8)
    ap.add_argument("--population", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0, help="sampling seed (the walks are always of seed 100)")
    ap.add_argument("--workers", type=int, default=2)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    mu, sd = np.log(np.array(START)), np.full(len(START), 0.6)
    _init(a.walks, 100)
    pd_plain = float(np.mean([run_walk(_SETUP, PDController(), w).time_s for w in _WALKS]))
    best = (score(mu), mu)
    print(f"{a.walks} walks of seed 100: PD {pd_plain:.2f} s, start {np.round(np.exp(mu))} {best[0]:.2f} s", flush=True)
    with mp.get_context("fork").Pool(a.workers, initializer=_init, initargs=(a.walks, 100)) as pool:
        for gen in range(a.generations):
            t0 = time.time()
            X = mu + sd * rng.standard_normal((a.population, len(mu)))
            S = np.array(pool.map(score, list(X)))
            elite = X[np.argsort(-S)[:max(3, a.population // 4)]]
            mu, sd = elite.mean(0), np.maximum(elite.std(0), 0.1)
            i = int(np.argmax(S))
            if S[i] > best[0]:
                best = (float(S[i]), X[i])
            print(f"generation {gen}: best {S.max():.2f} s, mean {S.mean():.2f} s, mean gains {np.round(np.exp(mu))}; "
                  f"best so far {best[0]:.2f} s at {np.round(np.exp(best[1]))} ({time.time() - t0:.0f} s)", flush=True)
    print(f"final mean gains {np.round(np.exp(mu))}: {score(mu):.2f} s (PD {pd_plain:.2f} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
