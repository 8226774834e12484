"""Can a search over six balance numbers keep the body up as a search over 66 joint offsets does?
(issue 7 probe)

The strong search teacher (16 candidates per 0.1 s, 1.5 s lookahead, around the shipped policy over
its balance layer) keeps the body up for 10 s and more, but its 66-dimensional labels are too
noisy for a student to learn (research/notes/TRAINING.md). If the same search over a few
numbers that steer the balance layer (its centre-of-mass offset and velocity targets and the
pelvis orientation target, benchmarks/tracker_feasible_probe.layer_bias) kept the body up as long,
the feedback to learn would be six-dimensional. Per walk: seconds until the search's own
trajectory falls (or ``--seconds``), for the joint-space search, the layer-space search and no
search (the shipped tracker alone).

    python -m research.probes.tracker_lowd_probe --space layer|joints|none --walks 0 1 2 3 [--seconds 20]
    python -m research.probes.tracker_lowd_probe --consistency 30 --seed 1     (the layer search's labels:
        two independent searches from each of 30 states the plain tracker visits; do they agree?)
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


import numpy as np  # noqa: E402
import torch  # noqa: E402

from tracker.track.evaluation import draw_walks, walk_reference
from tracker.learn.train_tracker import TrainConfig, Worker
from tracker.track.policy_net import load_checkpoint
from research.probes.tracker_feasible_probe import CKPT, searched_trajectory  # noqa: E402

#: Search std of the layer targets: offset (m), velocity (m/s), pelvis orientation (rad).
LAYER_SIGMA = (0.03, 0.03, 0.10, 0.10, 0.05, 0.05)


def consistency(seed: int, n_states: int) -> dict:
    """Two independent layer-space searches (MPPI labels in sigma units, best offsets) from each of
    ``n_states`` states of the plain tracker (RSI start plus 0-39 of its own steps)."""
    from research.layer_head import HeadConfig
    from tracker.track.policy_net import Actor, NumpyMLP, RunningNorm, load_checkpoint
    torch.set_num_threads(1)
    cfg = HeadConfig()
    ck = load_checkpoint(cfg.base_ckpt)
    tcfg = TrainConfig.from_dict({**ck["config"], "init_noise": 0.1, "envs_per_worker": 1, "walks_per_worker": 8,
                                  "walk_actions": 10, "push_prob": 0.0})
    w = Worker(tcfg, None, 0, seed)
    env = w.envs[0]
    actor = Actor(w.obs.shape[1], w.act_dim, tcfg.hidden, tcfg.init_log_std)
    actor.load_state_dict(ck["policy"])
    net, norm = NumpyMLP(actor.mu), RunningNorm(w.obs.shape[1])
    norm.load(ck)
    sig = np.array(cfg.sigma)
    get, put = env.get_state, env.set_state

    def rollout(o, delta):
        ret, disc = 0.0, 1.0
        for j in range(cfg.segment + cfg.lookahead):
            env.balance.bias[0] = delta if j < cfg.segment else 0.0
            o, _, done, info = env.step(w.to_residual(env, net(norm(o[None]))[0]))
            o = w.policy_obs(env, o)
            term = info.fall[0] is not None or w.lost(env, info)
            if not term:
                ret += disc * w.reward(env)
            disc *= cfg.search_gamma
            if term or done:
                break
        return ret

    def search(o0, s0, rng):
        R, D = [], []
        for k in range(cfg.candidates):
            put(s0)
            delta = np.zeros(6) if k == 0 else rng.normal(0, 1, 6) * sig
            R.append(rollout(o0, delta))
            D.append(delta / sig)
        R, D = np.array(R), np.array(D)
        wk = np.exp((R - R.max()) / (cfg.mppi_temp * (R.std() + 1e-9)))
        return (wk[:, None] * D).sum(0) / wk.sum(), D[np.argmax(R)], R

    rng = np.random.default_rng(seed)
    L1, L2, B1, B2, G = [], [], [], [], []
    for i in range(n_states):
        o = w._reset(0)
        for _ in range(int(rng.integers(0, 40))):
            env.balance.bias[0] = 0.0
            o, _, done, info = env.step(w.to_residual(env, net(norm(o[None]))[0]))
            o = w.policy_obs(env, o)
            if done or info.fall[0] is not None:
                o = w._reset(0)
        s0 = get()
        l1, b1, r1 = search(o, s0, np.random.default_rng([seed, i, 1]))
        l2, b2, r2 = search(o, s0, np.random.default_rng([seed, i, 2]))
        put(s0)
        L1.append(l1), L2.append(l2), B1.append(b1), B2.append(b2)
        G.append((r1.max() - r1[0], r2.max() - r2[0], r1[0]))
    L1, L2, B1, B2, G = map(np.array, (L1, L2, B1, B2, G))

    def cos(a, b):
        return (a * b).sum(1) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) + 1e-12)

    return dict(mppi_cosine=float(cos(L1, L2).mean()), best_cosine=float(cos(B1, B2).mean()),
                mppi_corr=[round(float(np.corrcoef(L1[:, j], L2[:, j])[0, 1]), 3) for j in range(6)],
                gain=[round(float(x), 3) for x in G[:, :2].mean(0)], plain_return=float(G[:, 2].mean()))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--space", choices=("layer", "joints", "none"), default="layer")
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--walks", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--candidates", type=int, default=16)
    ap.add_argument("--lookahead", type=int, default=45)
    ap.add_argument("--sigma-scale", type=float, default=1.0, help="multiplies LAYER_SIGMA")
    ap.add_argument("--consistency", type=int, default=0, help="instead: label agreement over this many states")
    ap.add_argument("--out", default="")
    a = ap.parse_args(argv)
    if a.consistency:
        res = consistency(a.seed, a.consistency)
        print(json.dumps(res))
        if a.out:
            Path(a.out).write_text(json.dumps(dict(vars(a), **res), indent=1))
        return 0
    ck = load_checkpoint(CKPT)
    cfg = TrainConfig.from_dict({**ck["config"], "init_noise": 0.0, "envs_per_worker": 1, "walks_per_worker": 1,
                                 "push_prob": 0.0})
    walks = draw_walks(Worker(cfg, None, 0, a.seed).src, max(a.walks) + 1, 20, a.seed)
    rows = []
    for i in a.walks:
        w = Worker(cfg, None, 0, a.seed)      # a fresh env per walk (layer_bias patches its layer)
        _, ref = walk_reference(w.setup, walks[i])
        t0 = time.time()
        qpos, _, reason = searched_trajectory(
            w, ck, ref, a.seconds, 1 if a.space == "none" else a.candidates, a.lookahead,
            np.random.default_rng([a.seed, i]), log=lambda *x: None,
            bias_sigma=np.array(LAYER_SIGMA) * a.sigma_scale if a.space == "layer" else None)
        rows.append(dict(walk=i, seconds=round((len(qpos) - 1) / 30.0, 3), end=reason, wall_s=round(time.time() - t0, 1)))
        print(f"walk {i}: {rows[-1]['seconds']:.2f} s ({reason}), {rows[-1]['wall_s']:.0f} s wall", flush=True)
    secs = [r["seconds"] for r in rows]
    print(f"{a.space}: mean {np.mean(secs):.2f} s over {len(secs)} walks, {sum(r['end'] != 'fall' for r in rows)} "
          f"without a fall in {a.seconds:g} s")
    if a.out:
        Path(a.out).write_text(json.dumps(dict(vars(a), rows=rows), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
