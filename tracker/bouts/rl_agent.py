"""The physics RL baseline at run time: its network, observation, reward and bout agent
(PhysicsRLAgent), and checkpoint loading. A scaled-down version of the competitive-sports paper's
bout-level learning (Won, Gopinath, Hodgins 2021), trained by self-play on CPU
(tracker.learn.train_physics_rl; evaluation against planner fighters: tracker.bouts.rl_eval).

    igraph-fight tracker rl train --graph G.igz --tracker CKPT --minutes 75 --out rl.pt
    igraph-fight tracker rl eval --graph G.igz --rl rl.pt --styles infighter,outboxer --bouts 10
    igraph-fight fight --physics --graph G.igz --a infighter --b rl ...      # rl:CKPT for another checkpoint

What is learned, and what is kept from the paper:
- Action space: the Interaction Graph's action menus. At each decision (its current action ends,
  the physics bout's decision rule) the policy picks the next action from Next(M_self) (a masked
  categorical over the library's actions); the same tracking policy as the IG fighters executes
  it. The paper learns a task encoder over a motor decoder's experts at 30 Hz; on 2 CPU cores a
  per-step policy over the 66 PD targets is far out of budget (docs/protocols.md, "Physics bouts"),
  and the menu is the tracker's "decoder" here (it only knows how to track library actions).
- Observation: the coupled state (r, sin/cos of both angles, one-hot M_self and M_other, F_other
  and frames left in M_other, the open-strike flag) plus physical features of both bodies
  (pelvis height, tilt, velocity in the decider's facing frame, fallen flags, closest fist-to-target
  distances both ways; tracker.bouts.physics_bout.PhysicsBout.features).
- Reward: the paper's eq. 1 per control step, summed over the decision's interval: r_match
  (clipped fist force on head/chest/belly given minus received, N, clip 200 N) + 0.2 r_close
  (exp(-3 d^2), d closest fist-to-target distance) + 0.05 r_facing (exp(-5 |v.f - 1|)) - 0.001
  r_energy (kappa_dist * sum of squared joint angular accelerations) - 30 per fall. The sum is
  multiplied by ``reward_scale`` for the optimiser (the weights' ratios are the paper's).
  Falls do not end the episode (the bout resets the fighter); the paper terminates.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch
from torch import nn

#: The checkpoint shipped with the repository (trained against the CMU boxing library, 68 actions).
DEFAULT_RL_CKPT = Path(__file__).resolve().parent.parent / "checkpoints" / "physics_rl_cmu13.pt"
#: the checkpoint's format and version (igraph_fight.checkpoint; tracker/checkpoints/README.md)
RL_CKPT_FORMAT = "igraph-fight/physics-rl"
RL_CKPT_VERSION = 1

N_PHYS = 14   # PhysicsBout.features


@dataclass
class RLConfig:
    """All knobs of a physics RL run (stored in the checkpoint)."""

    seed: int = 0
    episode_s: float = 20.0          # bout length while training
    n_workers: int = 2
    decisions_per_worker: int = 600  # per iteration and worker (both fighters' decisions)
    hidden: tuple[int, ...] = (128, 128)
    gamma_step: float = 0.99         # per control step (the paper)
    lam: float = 0.95
    lr: float = 3e-4
    epochs: int = 4
    minibatch: int = 256
    clip: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    reward_scale: float = 1e-3
    w_close: float = 0.2
    w_facing: float = 0.05
    w_energy: float = 0.001
    w_penalty: float = 30.0
    snapshot_prob: float = 0.2
    snapshot_every: int = 5          # iterations between snapshots kept in the opponent pool
    ckpt_every_min: float = 5.0

    @classmethod
    def from_dict(cls, d: dict) -> "RLConfig":
        names = {f.name for f in fields(cls)}
        return cls(**{k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names})


class ActorCritic(nn.Module):
    """Shared MLP trunk, a logit per library action (masked to the menu) and a value."""

    def __init__(self, obs_dim: int, n_actions: int, hidden: tuple[int, ...]) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        d = obs_dim
        for h in hidden:
            layers += [nn.Linear(d, h), nn.Tanh()]
            d = h
        self.trunk = nn.Sequential(*layers)
        self.pi = nn.Linear(d, n_actions)
        self.v = nn.Linear(d, 1)
        nn.init.orthogonal_(self.pi.weight, 0.01)
        nn.init.zeros_(self.pi.bias)

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        h = self.trunk(x)
        logits = self.pi(h).masked_fill(~mask, -1e9)
        return logits, self.v(h).squeeze(-1)


def observation(ctx, n_actions: int, nf: np.ndarray) -> np.ndarray:
    """The policy's input for a tracker.bouts.physics_bout.DecisionContext (see the module doc)."""
    o = ctx.obs
    x = np.zeros(5 + 2 * n_actions + 3 + N_PHYS, dtype=np.float32)
    x[0] = o.r / 3.0
    x[1], x[2] = math.sin(o.theta_self), math.cos(o.theta_self)
    x[3], x[4] = math.sin(o.theta_other), math.cos(o.theta_other)
    x[5 + o.m_self] = 1.0
    x[5 + n_actions + o.m_other] = 1.0
    b = 5 + 2 * n_actions
    n = int(nf[o.m_other])
    x[b] = o.f_other / max(n - 1, 1)
    x[b + 1] = (n - 1 - o.f_other) / 30.0
    x[b + 2] = float(o.mask_other != 0)
    f = np.asarray(ctx.features, dtype=np.float32)
    x[b + 3:b + 3 + N_PHYS] = f[:N_PHYS]
    return x


def decision_reward(r: dict, cfg: RLConfig) -> float:
    """The paper's eq. 1 summed over a decision interval, times reward_scale."""
    return cfg.reward_scale * (r["match"] + cfg.w_close * r["close"] + cfg.w_facing * r["facing"]
                               - cfg.w_energy * r["energy"] - cfg.w_penalty * r["fall"])


class PhysicsRLAgent:
    """A physics bout agent (igraph_fight.agents.base.Agent protocol) running an ActorCritic.
    ``sample``: draw from the policy (else its mode); ``record``: keep transitions for training
    (obs, mask, action, logp, value, reward, steps)."""

    def __init__(self, net: ActorCritic, n_actions: int, nf: np.ndarray, cfg: RLConfig, name: str = "rl",
                 sample: bool = True, record: bool = False) -> None:
        self.net = net
        self.n_actions = n_actions
        self.nf = nf
        self.cfg = cfg
        self.name = name
        self.sample = sample
        self.record = record
        self.rng = np.random.default_rng(0)
        self.traj: list[dict] = []

    def reset(self, bout, player: int, rng: np.random.Generator) -> None:
        self.rng = np.random.default_rng(rng.integers(1 << 31))
        self.traj = []

    def step(self, ctx, player: int) -> int:
        """The next action for the bout's DecisionContext ``ctx`` (``player`` == ctx.k)."""
        x = observation(ctx, self.n_actions, self.nf)
        mask = np.zeros(self.n_actions, dtype=bool)
        mask[np.asarray(ctx.menu, dtype=np.int64)] = True
        with torch.no_grad():
            logits, v = self.net(torch.from_numpy(x)[None], torch.from_numpy(mask)[None])
        lg = logits[0].double().numpy()
        p = np.exp(lg - lg.max())
        p /= p.sum()
        a = int(self.rng.choice(self.n_actions, p=p)) if self.sample else int(np.argmax(lg))
        if self.record:
            if self.traj:
                self.traj[-1]["reward"] = decision_reward(ctx.reward, self.cfg)
                self.traj[-1]["steps"] = ctx.steps
            self.traj.append({"obs": x, "mask": mask, "action": a, "logp": float(np.log(p[a] + 1e-12)),
                              "value": float(v[0]), "reward": 0.0, "steps": 0})
        return a

    def finish(self, player: int, reward: dict, steps: int) -> None:
        """The bout's end: the reward terms since the last decision close its transition."""
        if self.record and self.traj:
            self.traj[-1]["reward"] = decision_reward(reward, self.cfg)
            self.traj[-1]["steps"] = steps


def load_rl_checkpoint(path: str | os.PathLike) -> dict:
    """A physics RL checkpoint, read weights-only with its format checked (igraph_fight.checkpoint);
    a CheckpointError naming the file otherwise."""
    from igraph_fight.checkpoint import load_checkpoint
    return load_checkpoint(path, RL_CKPT_FORMAT, (RL_CKPT_VERSION,), what="physics RL")


def load_rl_agent(path: str | os.PathLike | None, library, sample: bool = True) -> PhysicsRLAgent:
    """The RL baseline as a physics bout agent (default: the shipped checkpoint)."""
    p = Path(path) if path else DEFAULT_RL_CKPT
    if not p.is_file():
        raise FileNotFoundError(f"no physics RL checkpoint at {p} (train: igraph-fight tracker rl train ...)")
    ck = load_rl_checkpoint(p)
    cfg = RLConfig.from_dict(ck["config"])
    n_actions = int(ck["n_actions"])
    if n_actions != library.n_actions:
        raise ValueError(f"RL checkpoint {p} was trained on {n_actions} actions, the library has {library.n_actions}")
    net = ActorCritic(int(ck["obs_dim"]), n_actions, tuple(cfg.hidden))
    net.load_state_dict(ck["model"])
    net.eval()
    return PhysicsRLAgent(net, n_actions, np.asarray(library.n_frames, dtype=np.int64), cfg, name="rl-baseline",
                   sample=sample)
