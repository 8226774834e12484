"""A learned tracker against PD-only on the same walks, paired: time to fall per walk and the
difference's confidence interval (the protocol of `tracker eval`: random 20-action library walks).

    python benchmarks/bench_tracker_paired.py --ckpt CKPT [--walks 100] [--seed 0] [--json]
    python benchmarks/bench_tracker_paired.py --ckpt CKPT --baseline OTHER.pt ...   # two policies, paired
    python benchmarks/bench_tracker_paired.py --ckpt CKPT --baseline balance ...    # against PD + virtual-force balance
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path



def paired(ckpt: str | None, n_walks: int = 100, n_actions: int = 20, seed: int = 0, library: str | None = None,
           baseline: str | None = None) -> dict:
    """tracker.track.evaluation.paired_comparison of the checkpoint's policy against PD-only (or against the
    policy of checkpoint ``baseline``)."""
    from tracker.track.evaluation import make_setup, paired_comparison
    from tracker.track.pd import PDController
    from tracker.track.policy_net import load_policy
    from tracker.track.walks import walk_source
    base = (PDController.balanced() if baseline == "balance" else load_policy(baseline) if baseline
            else PDController())
    return paired_comparison(make_setup(walk_source(library)), load_policy(ckpt), base, n_walks, n_actions, seed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--ckpt", help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--baseline", help="a second policy checkpoint to compare with instead of PD-only, or 'balance' "
                    "(PD + the virtual-force balance layer, tracker/track/vforce.py)")
    ap.add_argument("--library", help="action library file (default: built from the CMU boxing takes)")
    ap.add_argument("--walks", type=int, default=100)
    ap.add_argument("--actions", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    r = paired(a.ckpt, a.walks, a.actions, a.seed, a.library, a.baseline)
    base = f"baseline {Path(a.baseline).name}" if a.baseline else "PD"
    if a.json:
        print(json.dumps(r, indent=1))
    else:
        print(f"{r['walks']} walks x {r['actions']} actions, seed {r['seed']}: mean time to fall {base} {r['baseline_ttf_s']:.3f} s, "
              f"policy {r['policy_ttf_s']:.3f} s ({r['ratio']:.2f}x); paired difference {r['diff_s']:+.3f} s "
              f"(95% {r['diff_ci95_s'][0]:+.3f} .. {r['diff_ci95_s'][1]:+.3f}); policy longer on {r['policy_better_walks']} "
              f"walks, shorter on {r['policy_worse_walks']}; MPJPE {base} {r['baseline_mpjpe_cm']:.1f} cm, policy "
              f"{r['policy_mpjpe_cm']:.1f} cm ({r['wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
