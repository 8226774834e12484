"""Short runs of the search route (policy-guided search + distillation), from PD and from a bad policy.

The configuration of tests/test_tracker_policy.py (one worker, two 3-action walks, 64-64 policy,
8 candidates per 0.1 s, 0.3 s lookahead): the deterministic policy's tracking reward on the walks
it trained on (tracker.learn.train_tracker.rollout_reward) after 0, 4, 8 and 12 iterations, starting from the
untrained policy (zero residual, i.e. PD) and from one that adds 0.3 rad to every PD target.
Results: research/notes/TRAINING.md.

    python -m research.probes.tracker_search_short [--iterations 4 8 12]
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path


from tracker.track.policy_net import offset_checkpoint
from tracker.learn.train_tracker import TrainConfig, rollout_reward, train

CFG = TrainConfig(seed=1, algo="search", n_workers=1, envs_per_worker=1, walks_per_worker=2, walk_actions=3,
                  refresh_walks=0, hidden=(64, 64), critic_hidden=(32, 32), init_noise=0.0, eval_every_min=0,
                  candidates=8, segment=3, lookahead=9, search_segments=12, distill_steps=60)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--iterations", type=int, nargs="+", default=[4, 8, 12])
    a = ap.parse_args(argv)
    quiet = dict(progress=False, log=lambda *x: None)
    t0 = time.time()
    with tempfile.TemporaryDirectory() as tmp:
        start = Path(tmp) / "start.pt"
        train(CFG, None, 30.0, str(start), max_iterations=0, **quiet)
        for offset in (0.0, 0.3):
            first = Path(tmp) / f"offset{offset}.pt"
            offset_checkpoint(start, first, offset)
            row = [f"0: {rollout_reward(str(first), None, CFG, starts=3, horizon=30):.4f}"]
            for n in a.iterations:
                out = Path(tmp) / f"offset{offset}_{n}.pt"
                shutil.copy(first, out)
                train(CFG, None, 30.0, str(out), resume=str(out), max_iterations=n, **quiet)
                row.append(f"{n}: {rollout_reward(str(out), None, CFG, starts=3, horizon=30):.4f}")
            print(f"start offset {offset} rad: tracking reward after iterations " + ", ".join(row), flush=True)
    print(f"{time.time() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
