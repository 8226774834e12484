"""A learned balance head: six numbers a control step that steer the balance layer.

Why: the shipped tracker (policy E over the virtual-force layer, tracker/track/vforce.py) falls after
about 2.2 s. A search that perturbs the layer's targets (the centre of mass's offset from the
feet and its velocity, the pelvis orientation: ``VirtualForceBalance.bias``, six numbers in the
facing frame) for 0.1 s at a time and scores each of 16 candidates over a 1.5 s lookahead keeps
the body up 11 s on average (research/probes/tracker_lowd_probe.py; the same search over the 66 joint
residuals 15.6 s, but its labels are too noisy to learn: research/notes/TRAINING.md). In six dimensions a
weighted average of 16 candidates is a usable label. This module learns that feedback:

1. ``collect``: policy-guided search in the six-number space around the current head (candidate 0:
   the head's own output; the others add Gaussian offsets of ``HeadConfig.sigma``, held for a
   0.1 s segment, then the head steers for the lookahead), on RSI episodes of random walks with
   the shipped joint policy underneath; each segment's observations are labelled with the head's
   output plus the MPPI average of the offsets (weights exp(return / temperature)), weighted by
   the spread of the candidates' returns; the episode goes on from the best candidate's state (or,
   with ``follow_head``, from the head's own, DAgger-style). One process per core.
2. ``fit``: a small MLP (the joint policy's observation, normalised by its statistics) regressed
   on all labels so far (weighted mean squared error, in units of sigma).
3. ``train_head``: rounds of 1-2, each collected around the previous round's head; validation
   walks after each round; the head is saved into a copy of the joint policy's checkpoint
   (``layer_head``), which ``load_head_policy`` runs (tracker.track.policy_net.LearnedController
   with the head plugged in).

    python -m research.layer_head train --out CKPT --rounds 3 --minutes 10 [--workers 2] [--resume CKPT]
    python -m research.layer_head eval --ckpt CKPT [--walks 100 --actions 20 --seed 0] [--json]
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from igraph_fight.stats import mean_ci

from tracker.track.policy_net import DEFAULT_CKPT, NumpyMLP, RunningNorm, mlp


@dataclass
class HeadConfig:
    """Every knob of the head's training (stored in the checkpoint's ``layer_head``)."""

    seed: int = 0
    base_ckpt: str = str(DEFAULT_CKPT)    # the joint policy (with its layer gains) the head steers
    library: str = ""                      # a saved action library; "" = the CMU boxing library
    candidates: int = 16
    segment: int = 3                       # control steps an offset is held (0.1 s)
    lookahead: int = 45                    # control steps that score it (1.5 s)
    sigma: tuple[float, ...] = (0.03, 0.03, 0.10, 0.10, 0.05, 0.05)   # m, m, m/s, m/s, rad, rad
    max_sigmas: float = 3.0                # the head's output is clipped to +- this many sigma
    search_gamma: float = 0.97
    mppi_temp: float = 0.5                 # temperature in units of the returns' std
    label_floor: float = 0.02
    follow_head: float = 0.5               # chance a segment goes on from the head's own state
    walk_actions: int = 10
    walks_per_worker: int = 16
    init_noise: float = 0.1                # RSI joint-velocity noise (rad/s)
    max_episode_s: float = 20.0
    hidden: tuple[int, ...] = (128, 128)
    fit_steps: int = 3000
    fit_minibatch: int = 256
    lr: float = 1e-3
    eval_walks: int = 24                   # validation walks after each round (0: none)
    eval_actions: int = 20
    eval_seed: int = 100

    @classmethod
    def from_dict(cls, d: dict) -> "HeadConfig":
        names = set(cls.__dataclass_fields__)
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names})


class Head(nn.Module):
    """MLP: normalised observation -> six steering numbers in units of sigma."""

    def __init__(self, obs_dim: int, hidden: tuple[int, ...]) -> None:
        super().__init__()
        self.mu = mlp([obs_dim, *hidden, 6])
        nn.init.zeros_(self.mu[-1].weight)
        nn.init.zeros_(self.mu[-1].bias)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.mu(x)


@dataclass
class HeadRunner:
    """The head at run time (numpy): ``bias(obs)`` for raw policy observations (n, D) -> (n, 6)."""

    net: NumpyMLP | None
    norm: RunningNorm
    sigma: np.ndarray
    max_sigmas: float

    @classmethod
    def from_state(cls, state: dict | None, norm: RunningNorm, cfg: HeadConfig) -> "HeadRunner":
        net = None
        if state is not None:
            head = Head(norm.mean.shape[0], tuple(cfg.hidden))
            head.load_state_dict(state)
            net = NumpyMLP(head.mu)
        return cls(net, norm, np.asarray(cfg.sigma, float), float(cfg.max_sigmas))

    def units(self, obs: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(obs)
        if self.net is None:
            return np.zeros((x.shape[0], 6))
        return np.clip(self.net(self.norm(x)), -self.max_sigmas, self.max_sigmas)

    def bias(self, obs: np.ndarray) -> np.ndarray:
        return self.units(obs) * self.sigma


# ----------------------------------------------------------------------------------------------
# 1. labels by search
def collect(cfg: HeadConfig, head_state: dict | None, seconds: float, wid: int, round_: int) -> dict:
    """One worker's labels for ``seconds`` of wall time (module doc, step 1)."""
    from tracker.track.policy_net import load_checkpoint
    from tracker.learn.train_tracker import TrainConfig, Worker
    torch.set_num_threads(1)
    ck = load_checkpoint(cfg.base_ckpt)
    tcfg = TrainConfig.from_dict({**ck["config"], "init_noise": cfg.init_noise, "envs_per_worker": 1,
                                  "walks_per_worker": cfg.walks_per_worker, "walk_actions": cfg.walk_actions,
                                  "push_prob": 0.0, "max_episode_s": cfg.max_episode_s})
    w = Worker(tcfg, cfg.library or None, wid, 1000 * cfg.seed + 100 * round_ + wid)
    rng = w.rng
    env = w.envs[0]
    from tracker.track.policy_net import Actor
    actor = Actor(w.obs.shape[1], w.act_dim, tcfg.hidden, tcfg.init_log_std)
    actor.load_state_dict(ck["policy"])
    net = NumpyMLP(actor.mu)
    norm = RunningNorm(w.obs.shape[1])
    norm.load(ck)
    head = HeadRunner.from_state(head_state, norm, cfg)
    sig = head.sigma
    lim = cfg.max_sigmas * sig
    get_state, set_state = env.get_state, env.set_state

    def step(o, b):
        env.balance.bias[0] = b
        return env.step(w.to_residual(env, net(norm(o[None]))[0]))

    obs_out, lab_out, w_out, episodes, gains = [], [], [], [], []
    o0, ep_len = w.obs[0], 0
    t_end = time.time() + seconds
    sim_steps = 0
    while time.time() < t_end:
        s0 = get_state()
        rets, deltas, seg_obs, seg_head, afters = [], [], None, None, []
        for k in range(cfg.candidates):
            if k:
                set_state(s0)
            delta = np.zeros(6) if k == 0 else rng.normal(0.0, 1.0, 6) * sig
            o, ret, disc, obs_k, head_k, after = o0, 0.0, 1.0, [], [], None
            for j in range(cfg.segment + cfg.lookahead):
                hb = head.bias(o)[0]
                b = np.clip(hb + delta, -lim, lim) if j < cfg.segment else hb
                if j < cfg.segment:
                    obs_k.append(o)
                    head_k.append(hb)
                o, _, done, info = step(o, b)
                o = w.policy_obs(env, o)
                sim_steps += 1
                term = info.fall[0] is not None or w.lost(env, info)
                if not term:
                    ret += disc * w.reward(env)
                disc *= cfg.search_gamma
                if j == cfg.segment - 1 or ((term or done) and j < cfg.segment):
                    after = (get_state(), o, term, done)
                if term or done:
                    break
            rets.append(ret)
            deltas.append(delta)
            afters.append(after)
            if k == 0:
                seg_obs, seg_head = obs_k, head_k
        R = np.array(rets)
        wk = np.exp((R - R.max()) / (cfg.mppi_temp * (R.std() + 1e-9)))
        delta_star = (wk[:, None] * np.array(deltas)).sum(0) / wk.sum()
        gains.append(float(R.max() - R[0]))
        weight = cfg.label_floor + float(R.max() - R.min())
        for o, hb in zip(seg_obs, seg_head):
            obs_out.append(o)
            lab_out.append(np.clip(hb + delta_star, -lim, lim) / sig)
            w_out.append(weight)
        pick = 0 if rng.random() < cfg.follow_head else int(np.argmax(R))
        state, o_next, term, done = afters[pick]
        ep_len += cfg.segment
        if term or done or ep_len >= w.max_steps:
            episodes.append((ep_len / 30.0, "fall" if term else "cut"))
            ep_len = 0
            o0 = w._reset(0)
        else:
            set_state(state)
            o0 = o_next
    env.balance.bias[0] = 0.0
    return dict(obs=np.array(obs_out, np.float32), label=np.array(lab_out, np.float32), w=np.array(w_out, np.float32),
                episodes=episodes, sim_steps=sim_steps, gain=float(np.mean(gains)) if gains else 0.0)


def _collect_star(args):
    return collect(*args)


# ----------------------------------------------------------------------------------------------
# 2. regression
def fit(cfg: HeadConfig, norm: RunningNorm, obs: np.ndarray, label: np.ndarray, weight: np.ndarray,
        init: dict | None = None) -> tuple[dict, float]:
    """Weighted least squares of the head on (obs, label in sigma units); returns (state, final loss)."""
    torch.manual_seed(cfg.seed)
    head = Head(obs.shape[1], tuple(cfg.hidden))
    if init is not None:
        head.load_state_dict(init)
    x = torch.as_tensor(norm(obs), dtype=torch.float32)
    y = torch.as_tensor(label, dtype=torch.float32)
    wt = torch.as_tensor(weight / weight.mean(), dtype=torch.float32)
    opt = torch.optim.Adam(head.parameters(), lr=cfg.lr)
    g = torch.Generator().manual_seed(cfg.seed)
    loss = torch.tensor(0.0)
    for _ in range(cfg.fit_steps):
        idx = torch.randint(0, len(x), (min(cfg.fit_minibatch, len(x)),), generator=g)
        loss = (wt[idx, None] * (head(x[idx]) - y[idx]) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    return {k: v.detach().clone() for k, v in head.state_dict().items()}, float(loss.detach())


# ----------------------------------------------------------------------------------------------
# 3. rounds
def save_head(out: str, cfg: HeadConfig, state: dict, history: list) -> None:
    """A copy of the base checkpoint with ``layer_head`` added (atomic)."""
    from tracker.track.policy_net import load_checkpoint, save_policy_checkpoint
    ck = load_checkpoint(cfg.base_ckpt)
    ck["layer_head"] = dict(state=state, config=asdict(cfg), history=history)
    save_policy_checkpoint(out, ck)


def load_head_policy(path):
    """The policy of a checkpoint written by save_head, its balance head steering the layer
    (a LearnedController with ``head``); a ValueError when the policy has no balance layer."""
    from tracker.track.policy_net import LearnedController, load_checkpoint
    ck = load_checkpoint(path)
    lh = ck.get("layer_head")
    if lh is None:
        raise ValueError(f"{path}: no layer_head in this checkpoint")
    norm = RunningNorm(len(ck["obs_mean"]))
    norm.load(ck)
    head = HeadRunner.from_state(lh["state"], norm, HeadConfig.from_dict(lh["config"]))
    return LearnedController(ck, str(path), head=head)


def validate(ckpt: str, cfg: HeadConfig) -> dict:
    """Validation walks (cfg.eval_*): mean seconds tracked with the head and without it (same walks)."""
    from tracker.track.evaluation import draw_walks, make_setup, run_walk
    from tracker.track.policy_net import load_policy
    from tracker.track.walks import walk_source
    src = walk_source(cfg.library or None)
    setup = make_setup(src)
    walks = draw_walks(src, cfg.eval_walks, cfg.eval_actions, cfg.eval_seed)
    out = {}
    for name, path in (("head", ckpt), ("base", cfg.base_ckpt)):
        ctrl = load_head_policy(path) if name == "head" else load_policy(path)
        out[name] = [run_walk(setup, ctrl, wk).time_s for wk in walks]
    return dict(head_s=float(np.mean(out["head"])), base_s=float(np.mean(out["base"])),
                paired=[round(a - b, 3) for a, b in zip(out["head"], out["base"])])


def train_head(cfg: HeadConfig, out: str, rounds: int, minutes: float, workers: int,
               resume: str | None = None, log=print) -> list:
    """Rounds of collect (``minutes`` of wall time on ``workers`` processes) + fit + validate."""
    from tracker.track.policy_net import load_checkpoint
    ck = load_checkpoint(cfg.base_ckpt)
    norm = RunningNorm(len(ck["obs_mean"]))
    norm.load(ck)
    data_path = Path(str(out) + ".labels.npz")
    state, history = None, []
    data = {k: [] for k in ("obs", "label", "w")}
    if resume:
        rk = load_checkpoint(resume).get("layer_head")
        if rk is None:
            raise ValueError(f"{resume}: no layer_head in this checkpoint")
        state, history = rk["state"], list(rk["history"])
        old = Path(str(resume) + ".labels.npz")
        if old.is_file():
            z = np.load(old)
            data = {k: [z[k]] for k in data}
    ctx = mp.get_context("spawn")
    for r in range(len(history), len(history) + rounds):
        t0 = time.time()
        jobs = [(cfg, state, 60.0 * minutes, wid, r) for wid in range(workers)]
        with ctx.Pool(workers) as pool:
            parts = pool.map(_collect_star, jobs)
        for p in parts:
            for k in data:
                data[k].append(p[k])
        eps = [e for p in parts for e in p["episodes"]]
        cat = {k: np.concatenate(v) for k, v in data.items()}
        tmp = data_path.with_name(data_path.name + ".tmp.npz")
        np.savez(tmp, **cat)
        tmp.replace(data_path)
        state, loss = fit(cfg, norm, cat["obs"], cat["label"], cat["w"], init=state)
        save_head(out, cfg, state, history)
        val = validate(out, cfg) if cfg.eval_walks > 0 else dict(head_s=float("nan"), base_s=float("nan"), paired=[0.0, 0.0])
        row = dict(round=r, labels=int(len(cat["obs"])), new=int(sum(len(p["obs"]) for p in parts)),
                   search_episode_s=float(np.mean([e[0] for e in eps])) if eps else float("nan"),
                   search_falls=int(sum(e[1] == "fall" for e in eps)), gain=float(np.mean([p["gain"] for p in parts])),
                   loss=loss, wall_s=round(time.time() - t0, 1), **val)
        history.append({k: v for k, v in row.items() if k != "paired"})
        save_head(out, cfg, state, history)
        d = np.array(val["paired"])
        log(f"round {r}: {row['new']} new labels ({row['labels']} in all), search episodes {row['search_episode_s']:.2f} s "
            f"({row['search_falls']} falls), loss {loss:.3f}; validation {val['head_s']:.3f} s against {val['base_s']:.3f} s "
            f"(paired {d.mean():+.3f} +- {mean_ci(d, normal=True)['half']:.3f}), {row['wall_s']:.0f} s")
    return history


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m research.layer_head", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="rounds of search labels and fits of the head")
    t.add_argument("--out", required=True)
    t.add_argument("--rounds", type=int, default=3)
    t.add_argument("--minutes", type=float, default=10.0, help="collection wall minutes per round")
    t.add_argument("--workers", type=int, default=2)
    t.add_argument("--resume", default=None)
    t.add_argument("--set", nargs="*", default=[], help="HeadConfig overrides key=value")
    e = sub.add_parser("eval", help="the walk evaluation (tracker.track.evaluation) of a checkpoint with a head")
    e.add_argument("--ckpt", required=True)
    e.add_argument("--library", default=None)
    e.add_argument("--walks", type=int, default=100)
    e.add_argument("--actions", type=int, default=20)
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--workers", type=int, default=1)
    e.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    if a.cmd == "eval":
        import json

        from tracker.track.evaluation import evaluate_walks, format_report, make_setup
        from tracker.track.walks import walk_source
        m = evaluate_walks(make_setup(walk_source(a.library)), load_head_policy(a.ckpt), a.walks, a.actions, a.seed,
                           workers=a.workers)
        print(json.dumps(m, indent=2) if a.json else format_report(m))
        return 0
    from tracker.learn.overrides import parse_config_overrides
    kw = parse_config_overrides(a.set, HeadConfig)
    base = HeadConfig()
    if a.resume:
        from tracker.track.policy_net import load_checkpoint
        rk = load_checkpoint(a.resume).get("layer_head")
        if rk:
            base = HeadConfig.from_dict(rk["config"])
    cfg = HeadConfig.from_dict({**asdict(base), **kw})
    train_head(cfg, a.out, a.rounds, a.minutes, a.workers, a.resume)
    return 0


if __name__ == "__main__":
    sys.exit(main())
