"""Policy-guided sampling search + supervised distillation (the "search" phase of tracker.learn.train_tracker).

An approximate policy iteration that uses the simulator's determinism instead of PPO's noisy
gradient estimate:

1. Roll the current (deterministic) policy on an RSI episode of a random walk. Every ``segment``
   control steps, from the current state, try ``candidates`` offsets on the policy's residual
   (candidate 0: none; the others Gaussian, constant over the segment), each followed by the plain
   policy for ``lookahead`` steps, and score each by its discounted imitation reward (0 after a
   fall or early termination). Same start state for all: the comparison has no state noise.
2. Label the segment's observations with the best candidate's residuals (weight: how much it beat
   the plain policy, plus a floor), continue the episode from the best candidate's state (so the
   search follows, and labels, the states an improved policy reaches: SAMCON with the policy as
   the sampling mean), and end it at a fall. With TrainConfig.follow_policy = p, a segment goes on
   from the plain policy's state instead with probability p (DAgger on the policy's own states,
   where its falls begin; the labels are the same).
3. The learner regresses the policy on the aggregated labels (a replay of the latest
   ``replay_labels``), then the next round searches around the improved policy (DAgger-style:
   the states come from the policy being trained).

Costs ``candidates x (segment + lookahead) / segment`` simulated steps per labelled step. PPO can
fine-tune the result afterwards (TrainConfig.algo = "ppo" on resume).
"""
from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np
import torch

from tracker.body.humanoid import leg_mask
from tracker.track.policy_net import NumpyMLP, RunningNorm


def search_labels(worker, actor_state: dict, norm_state: dict, n_segments: int) -> dict:
    """Run policy-guided search on worker.envs[0] for ``n_segments`` segments; see the module doc."""
    from tracker.track.policy_net import Actor
    cfg = worker.cfg
    env = worker.envs[0]
    D, A = worker.obs.shape[1], worker.act_dim
    actor = Actor(D, A, cfg.hidden, cfg.init_log_std)
    actor.load_state_dict(actor_state)
    net = NumpyMLP(actor.mu)
    norm = RunningNorm(D)
    norm.load(norm_state)
    sig = (np.full(A, cfg.search_sigma_legs) if A != env.n_act
           else np.where(leg_mask(worker.scene), cfg.search_sigma_legs, cfg.search_sigma))
    clip = cfg.action_clip
    get_state, set_state = env.get_state, env.set_state

    def policy(o):
        return net(norm(o[None]))[0]

    rng = worker.rng
    obs_out, act_out, w_out = [], [], []
    episodes = []
    sim_steps = 0
    gains = []
    t0 = time.process_time()
    if getattr(worker, "search_obs", None) is None:
        worker.search_obs = worker._reset(0)
        worker.search_len = 0
    o0 = worker.search_obs
    for _ in range(n_segments):
        s0 = get_state()
        best = None
        rets, deltas = [], []
        for k in range(cfg.candidates):
            if k:
                set_state(s0)
            delta = np.zeros(A) if k == 0 else rng.normal(0.0, 1.0, A) * sig
            o = o0
            ret, disc = 0.0, 1.0
            seg_obs, seg_pi = [], []
            after = None
            for j in range(cfg.segment + cfg.lookahead):
                a = policy(o)
                if j < cfg.segment:
                    seg_obs.append(o)
                    seg_pi.append(a)
                    a = a + delta
                o, r_env, done, info = env.step(worker.to_residual(env, a))
                o = worker.policy_obs(env, o)
                sim_steps += 1
                term = info.fall[0] is not None or worker.lost(env, info)
                if not term:
                    ret += disc * worker.reward(env, r_env)
                disc *= cfg.search_gamma
                if j == cfg.segment - 1 or (term or done) and j < cfg.segment:
                    after = (get_state(), o, term, done)
                if term or done:
                    break
            rets.append(ret)
            deltas.append(delta)
            if k == 0:
                after_plain = after
            if best is None or ret > best[0]:
                best = (ret, seg_obs, seg_pi, after)
        ret_b, seg_obs, seg_pi, after = best
        if cfg.follow_policy > 0.0 and rng.random() < cfg.follow_policy:
            after = after_plain     # DAgger: go on from the plain policy's state (the labels are the same)
        # MPPI-style target: the offsets weighted by exp(return / temperature), temperature
        # proportional to the spread of the returns (all from the same state: no state noise)
        R = np.array(rets)
        spread = float(R.max() - R.min())
        wk = np.exp((R - R.max()) / (cfg.mppi_temp * (R.std() + 1e-9)))
        delta_star = (wk[:, None] * np.array(deltas)).sum(0) / wk.sum()
        gains.append(ret_b - rets[0])
        w = cfg.label_floor + spread
        obs_out.extend(seg_obs)
        act_out.extend([np.clip(a + delta_star, -clip, clip) for a in seg_pi])
        w_out.extend([w] * len(seg_obs))
        state, o_next, term, done = after
        worker.search_len += len(seg_obs)
        if term or done or worker.search_len >= worker.max_steps:
            episodes.append((worker.search_len, 0.0, "fall" if term else "cut"))
            worker.search_len = 0
            o0 = worker._reset(0)
        else:
            set_state(state)
            o0 = o_next
    worker.search_obs = o0
    return {"obs": np.array(obs_out, np.float32), "act": np.array(act_out, np.float32),
            "w": np.array(w_out, np.float32), "episodes": episodes, "sim_steps": sim_steps,
            "gain": float(np.mean(gains)) if gains else 0.0, "cpu_s": time.process_time() - t0}


class LabelBuffer:
    """The latest ``capacity`` labels (obs, residual, weight)."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.obs: np.ndarray | None = None
        self.act: np.ndarray | None = None
        self.w: np.ndarray | None = None

    def add(self, obs: np.ndarray, act: np.ndarray, w: np.ndarray) -> None:
        if self.obs is None:
            self.obs, self.act, self.w = obs, act, w
        else:
            self.obs = np.concatenate([self.obs, obs])[-self.capacity:]
            self.act = np.concatenate([self.act, act])[-self.capacity:]
            self.w = np.concatenate([self.w, w])[-self.capacity:]

    def __len__(self) -> int:
        return 0 if self.obs is None else len(self.obs)

    def save(self, path) -> None:
        """Write the labels to ``path`` (.npz) atomically (a resumed run continues with them)."""
        if self.obs is None:
            return
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp.npz")
        np.savez(tmp, obs=self.obs, act=self.act, w=self.w)
        os.replace(tmp, path)

    def load(self, path, obs_dim: int, act_dim: int, transform=None) -> bool:
        """Add the labels saved at ``path`` when their shapes fit this run; True when loaded.
        ``transform``: applied to the stored observations first (tracker.learn.widen.widen_labels)."""
        if not Path(path).is_file():
            return False
        with np.load(path) as z:
            obs, act, w = z["obs"], z["act"], z["w"]
        if transform is not None and obs.ndim == 2:
            obs = transform(obs)
        if obs.ndim != 2 or obs.shape[1] != obs_dim or act.shape[1:] != (act_dim,) or len(obs) != len(w):
            return False
        self.add(obs, act, w)
        return True


def labels_path(ckpt) -> Path:
    """Where the label buffer of a checkpoint is kept: CKPT.labels.npz beside it."""
    ckpt = Path(ckpt)
    return ckpt.with_name(ckpt.name + ".labels.npz")


def distill(learner, buf: LabelBuffer, steps: int, minibatch: int, seed: int) -> dict:
    """``steps`` minibatches of weighted MSE regression of the actor's mean on random labels of the
    buffer (the normaliser is updated first)."""
    actor = learner.actor
    dev = learner.device
    X = torch.as_tensor(learner.norm(buf.obs).astype(np.float32), device=dev)
    Y = torch.as_tensor(buf.act, device=dev)
    W = torch.as_tensor(buf.w / buf.w.mean(), device=dev)
    n = len(X)
    g = torch.Generator().manual_seed(seed)
    opt = learner.distill_opt
    tot = 0.0
    for _ in range(steps):
        idx = torch.randint(0, n, (min(minibatch, n),), generator=g).to(dev)
        mu, _ = actor(X[idx])
        loss = (W[idx] * ((mu - Y[idx]) ** 2).mean(-1)).mean()
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(actor.parameters(), 1.0)
        opt.step()
        tot += float(loss.detach())
    loss_v = tot / max(steps, 1)
    return {"distill_loss": loss_v, "labels": n, "residual_rms": float(math.sqrt(float((Y ** 2).mean())))}
