"""Are the search's labels a function of the state, or of chaos? (issue 7)

    python -m research.probes.tracker_label_probe [--ckpt CKPT] [--states 40] [--candidates 16] [--noise 0.02] [--seed 0]

The route behind the shipped tracker (tracker/learn/search_labels.py) labels a state with the offset whose
rollout scored best among ``candidates`` tried from exactly that state. In a deterministic but
chaotic contact simulation the best of N may win by luck: a tiny change of the start state
reshuffles which offset does best. This probe measures that, at states the shipped policy
visits (random walk, RSI start, 0-60 plain-policy steps):

1. gain at the state itself: best candidate's return minus the plain policy's (what the search
   sees and credits),
2. the same two offsets (best, and the MPPI-weighted label the student regresses on) replayed from
   ``perturb`` copies of the state with joint-velocity noise of ``noise`` rad/s (1/5 of RSI's): mean
   gain over those copies (what a label is worth to a student that never sees the exact state),
3. agreement of two independent searches at the same state: cosine of their MPPI labels.

A label is only learnable if 2 stays well above zero and 3 is well above chance (about 0).
``--lookahead`` / ``--eval-lookahead`` set the search's horizon and the replays' (does an offset
picked on a 0.4 s horizon help over 1.5 s? does one picked on 1.5 s help more?).
Also reported: each of those with ``--robust K`` (each candidate scored by its mean return over K
perturbed copies; K times the cost), the candidate fix.
"""
from __future__ import annotations

import argparse
import sys
import time

import mujoco
import numpy as np

from tracker.body.humanoid import leg_mask
from tracker.track.policy_net import Actor, NumpyMLP, RunningNorm, load_checkpoint
from tracker.learn.train_tracker import TrainConfig, Worker

SHIPPED = "tracker/checkpoints/boxing_cmu13.pt"


class Prober:
    def __init__(self, ckpt: str, seed: int, candidates: int) -> None:
        ck = load_checkpoint(ckpt)
        cfg = TrainConfig.from_dict(ck["config"])
        cfg.envs_per_worker, cfg.walks_per_worker, cfg.candidates = 1, 8, candidates
        self.cfg = cfg
        self.w = Worker(cfg, None, 0, seed)
        self.env = self.w.envs[0]
        D = self.w.obs.shape[1]
        actor = Actor(D, self.w.act_dim, cfg.hidden, cfg.init_log_std)
        actor.load_state_dict(ck["policy"])
        self.net = NumpyMLP(actor.mu)
        self.norm = RunningNorm(D)
        self.norm.load({"obs_mean": ck["obs_mean"], "obs_var": ck["obs_var"], "obs_count": ck["obs_count"]})
        m = self.env.model
        self.spec = mujoco.mjtState.mjSTATE_INTEGRATION
        self.size = mujoco.mj_stateSize(m, self.spec)
        A = self.w.act_dim
        self.sig = np.where(leg_mask(self.w.scene), cfg.search_sigma_legs, cfg.search_sigma) if A == self.env.n_act \
            else np.full(A, cfg.search_sigma_legs)
        f = self.w.scene.fighters[0]
        self.dof = slice(f.qvel_adr + 6, f.qvel_adr + f.nv)       # joint velocities (not the root's)

    def get(self):
        s = np.empty(self.size)
        mujoco.mj_getState(self.env.model, self.env.data, s, self.spec)
        return s, self.env.t, self.env.done

    def put(self, st, noise: float = 0.0, rng=None):
        env = self.env
        mujoco.mj_setState(env.model, env.data, st[0], self.spec)
        env.t, env.done = st[1], st[2]
        if noise > 0:
            env.data.qvel[self.dof] += rng.normal(0.0, noise, env.data.qvel[self.dof].shape)
        mujoco.mj_kinematics(env.model, env.data)

    def act(self, o):
        return self.net(self.norm(o[None]))[0]

    def score(self, st, o0, delta, noise=0.0, rng=None, lookahead: int | None = None) -> float:
        """Discounted tracking reward of holding ``delta`` for a segment then the plain policy
        (0 after a fall), from ``st`` (plus velocity noise). The observation at the start is
        recomputed when noise is added."""
        cfg, env, w = self.cfg, self.env, self.w
        self.put(st, noise, rng)
        o = o0 if noise == 0 else w.policy_obs(env, env.observe())
        ret, disc = 0.0, 1.0
        for j in range(cfg.segment + (cfg.lookahead if lookahead is None else lookahead)):
            a = self.act(o)
            if j < cfg.segment:
                a = a + delta
            o, r_env, done, info = env.step(w.to_residual(env, a))
            o = w.policy_obs(env, o)
            if info.fall[0] is not None or w.lost(env, info):
                break
            ret += disc * w.reward(env, r_env)
            disc *= cfg.search_gamma
            if done:
                break
        return ret

    def search(self, st, o0, rng, robust: int = 0, noise: float = 0.0):
        """Candidates' offsets and returns (candidate 0: none); robust > 0 scores each by the mean
        over ``robust`` perturbed copies (common random numbers: the same perturbations for all)."""
        cfg = self.cfg
        A = self.w.act_dim
        deltas = [np.zeros(A)] + [rng.normal(0.0, 1.0, A) * self.sig for _ in range(cfg.candidates - 1)]
        seeds = rng.integers(1 << 31, size=max(robust, 1))
        rets = []
        for dl in deltas:
            if robust:
                rets.append(np.mean([self.score(st, o0, dl, noise, np.random.default_rng(s)) for s in seeds]))
            else:
                rets.append(self.score(st, o0, dl))
        R = np.array(rets)
        wk = np.exp((R - R.max()) / (cfg.mppi_temp * (R.std() + 1e-9)))
        mppi = (wk[:, None] * np.array(deltas)).sum(0) / wk.sum()
        return np.array(deltas), R, mppi


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--ckpt", default=SHIPPED)
    p.add_argument("--states", type=int, default=40)
    p.add_argument("--candidates", type=int, default=16)
    p.add_argument("--noise", type=float, default=0.02, help="joint-velocity noise of the perturbed copies (rad/s)")
    p.add_argument("--perturb", type=int, default=8, help="perturbed copies a label is replayed from")
    p.add_argument("--robust", type=int, default=0, help="also a robust search scoring each candidate over K copies")
    p.add_argument("--lookahead", type=int, default=None, help="search lookahead (control steps; default: the checkpoint's)")
    p.add_argument("--eval-lookahead", type=int, default=None,
                   help="lookahead of the replays from perturbed copies (default: the search's)")
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    pr = Prober(a.ckpt, a.seed, a.candidates)
    if a.lookahead is not None:
        pr.cfg.lookahead = a.lookahead
    L = a.eval_lookahead
    print(f"search: {pr.cfg.candidates} candidates, segment {pr.cfg.segment}, lookahead {pr.cfg.lookahead} steps; "
          f"replays: lookahead {pr.cfg.lookahead if L is None else L} steps, noise {a.noise} rad/s", flush=True)
    rng = np.random.default_rng(a.seed)
    rows = []
    t0 = time.time()
    modes = [("plain", 0)] + ([("robust", a.robust)] if a.robust else [])
    while len(rows) < a.states:
        o = pr.w._reset(0)
        for _ in range(int(rng.integers(0, 60))):
            o, _, done, info = pr.env.step(pr.w.to_residual(pr.env, pr.act(o)))
            o = pr.w.policy_obs(pr.env, o)
            if done or info.fall[0] is not None:
                break
        if pr.env.done or info.fall[0] is not None:
            continue
        st = pr.get()
        row = {}
        pert = [np.random.default_rng(s) for s in rng.integers(1 << 31, size=a.perturb)]
        pseeds = [int(g.integers(1 << 31)) for g in pert]
        for name, k in modes:
            deltas, R, mppi = pr.search(st, o, rng, k, a.noise)
            _, _, mppi2 = pr.search(st, o, rng, k, a.noise)
            best = deltas[int(np.argmax(R))]
            g_here = float(R.max() - R[0])
            base = [pr.score(st, o, np.zeros_like(best), a.noise, np.random.default_rng(s), L) for s in pseeds]
            g_best = [pr.score(st, o, best, a.noise, np.random.default_rng(s), L) - b for s, b in zip(pseeds, base)]
            g_mppi = [pr.score(st, o, mppi, a.noise, np.random.default_rng(s), L) - b for s, b in zip(pseeds, base)]
            cos = float(mppi @ mppi2 / (np.linalg.norm(mppi) * np.linalg.norm(mppi2) + 1e-12))
            row[name] = (g_here, float(np.mean(g_best)), float(np.mean(g_mppi)), cos, float(np.mean(base)))
        rows.append(row)
        print(f"state {len(rows)}/{a.states} ({time.time() - t0:.0f} s): " + "; ".join(
            f"{n}: gain here {r[0]:+.3f}, best perturbed {r[1]:+.3f}, mppi perturbed {r[2]:+.3f}, cos {r[3]:+.2f}"
            for n, r in row.items()), flush=True)
    for name, _ in modes:
        x = np.array([r[name] for r in rows])
        se = x.std(0) / np.sqrt(len(x))
        print(f"{name} search over {len(x)} states (plain return {x[:, 4].mean():.3f}): gain at the state "
              f"{x[:, 0].mean():+.4f} +- {se[0]:.4f}; best offset from perturbed copies {x[:, 1].mean():+.4f} +- {se[1]:.4f}; "
              f"MPPI label from perturbed copies {x[:, 2].mean():+.4f} +- {se[2]:.4f}; two searches' labels cos "
              f"{x[:, 3].mean():+.3f} +- {se[3]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
