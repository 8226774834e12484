"""'rl' baseline: a PyTorch policy over the same action menus, with continuous state features.

Observation of a fighter at its decision (``RLFeatures``; no graph, no clustering):
distance r / 4 m, sin and cos of theta_self and theta_other, one-hot of the action it just
finished (its menu is Next of it), one-hot of the opponent's action, the opponent's progress in
it (frame fraction and seconds left), whether one of the opponent's strikes already resolved,
and the seconds since the fighter last landed / last took a hit (capped at 3 s).
The action is a library action id; illegal actions (not in the menu) are masked out of the
logits (invalid-action masking). Trained with masked PPO by igraph_fight.rl_train.
"""
from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

CHECKPOINT_DIR = Path(__file__).resolve().parent.parent / "checkpoints"
HIT_CAP_S = 3.0
#: the checkpoint's format and version (igraph_fight.checkpoint; igraph_fight/checkpoints/README.md)
RL_FORMAT = "igraph-fight/rl-ppo"
RL_VERSION = 2


def default_checkpoint(style: str = "infighter") -> Path:
    return CHECKPOINT_DIR / f"rl_{style}.pt"


class RLFeatures:
    """Feature vector of a fighter at its decision (module docstring). One instance per fighter
    and bout (it remembers when hits happened)."""

    def __init__(self, tables) -> None:
        self.tables = tables
        self.A = int(tables.n_actions)
        self.dim = 10 + 2 * self.A
        self.nf = np.asarray(tables.n_frames, dtype=np.float64)
        self.fps = float(tables.fps)
        self.reset()

    def reset(self) -> None:
        self._hits = None
        self._t_given = -1e9
        self._t_taken = -1e9

    def __call__(self, state, player: int) -> np.ndarray:
        w = state.world
        o = 1 - player
        t = state.time_s
        if self._hits is None:
            self._hits = state.hits.copy()
        if state.hits[player] > self._hits[player]:
            self._t_given = t
        if state.hits[o] > self._hits[o]:
            self._t_taken = t
        self._hits = state.hits.copy()
        dx = float(w.x[o] - w.x[player])
        dz = float(w.z[o] - w.z[player])
        r = math.hypot(dx, dz)
        b = math.atan2(dx, dz)
        ts = b - float(w.heading[player])
        to = b + math.pi - float(w.heading[o])
        mo, fo = int(w.action[o]), int(w.frame[o])
        x = np.zeros(self.dim, dtype=np.float32)
        x[0] = min(r, 6.0) / 4.0
        x[1], x[2], x[3], x[4] = math.sin(ts), math.cos(ts), math.sin(to), math.cos(to)
        x[5] = fo / max(self.nf[mo] - 1.0, 1.0)
        x[6] = min((self.nf[mo] - 1.0 - fo) / self.fps, 2.0)
        x[7] = 1.0 if int(w.resolved[o]) != 0 else 0.0
        x[8] = min(t - self._t_given, HIT_CAP_S) / HIT_CAP_S
        x[9] = min(t - self._t_taken, HIT_CAP_S) / HIT_CAP_S
        x[10 + int(w.action[player])] = 1.0
        x[10 + self.A + mo] = 1.0
        return x

    def legal_mask(self, state, player: int) -> np.ndarray:
        m = np.zeros(self.A, dtype=bool)
        m[state.legal_actions(player)] = True
        return m


def make_network(obs_dim: int, n_actions: int, hidden: int = 128):
    """Actor-critic MLP (two tanh hidden layers shared by nothing: separate actor and critic)."""
    import torch
    from torch import nn

    def layer(i, o, std=math.sqrt(2)):
        lin = nn.Linear(i, o)
        nn.init.orthogonal_(lin.weight, std)
        nn.init.constant_(lin.bias, 0.0)
        return lin

    class ActorCritic(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.actor = nn.Sequential(layer(obs_dim, hidden), nn.Tanh(), layer(hidden, hidden), nn.Tanh(),
                                       layer(hidden, n_actions, 0.01))
            self.critic = nn.Sequential(layer(obs_dim, hidden), nn.Tanh(), layer(hidden, hidden), nn.Tanh(),
                                        layer(hidden, 1, 1.0))

        def logits(self, x: torch.Tensor, legal: torch.Tensor) -> torch.Tensor:
            return self.actor(x).masked_fill(~legal, -1e9)

        def value(self, x: torch.Tensor) -> torch.Tensor:
            return self.critic(x).squeeze(-1)

    return ActorCritic()


def load_checkpoint(path: str | Path) -> dict:
    """An RL policy checkpoint (igraph_fight.checkpoint.load_checkpoint: read weights-only, format
    checked); a CheckpointError naming the file otherwise."""
    from igraph_fight.checkpoint import load_checkpoint as load_versioned
    return load_versioned(path, RL_FORMAT, (RL_VERSION,), what="RL policy")


class RLAgent:
    """The trained policy on the game API. ``greedy``: the most probable legal action (default,
    deterministic); else a sample from the masked policy with the agent's rng."""

    def __init__(self, checkpoint: dict | str | Path | None = None, network=None, greedy: bool = True,
                 name: str = "rl") -> None:
        import torch
        torch.set_num_threads(1)
        self.name = name
        self.greedy = greedy
        if network is None:
            ck = load_checkpoint(checkpoint or default_checkpoint()) if not isinstance(checkpoint, dict) else checkpoint
            network = make_network(ck["obs_dim"], ck["n_actions"], ck["config"]["hidden"])
            network.load_state_dict(ck["state_dict"])
            self.checkpoint_info = {k: v for k, v in ck.items() if k != "state_dict"}
        else:
            self.checkpoint_info = {}
        self.net = network
        self.net.eval()
        self._feat: RLFeatures | None = None
        self._rng = np.random.default_rng(0)
        self.decisions = 0
        self.decision_s = 0.0

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        self._rng = rng
        if self._feat is None or self._feat.tables is not game.tables:
            self._feat = RLFeatures(game.tables)
            n = self.checkpoint_info.get("n_actions")
            if n is not None and n != self._feat.A:
                raise ValueError(f"RL checkpoint is for {n} actions, the library has {self._feat.A}")
        self._feat.reset()

    def step(self, state, player: int) -> int:
        import torch
        t0 = time.perf_counter()
        if self._feat is None:
            self.reset(state.game, player, self._rng)
        x = self._feat(state, player)
        legal = self._feat.legal_mask(state, player)
        with torch.no_grad():
            lg = self.net.logits(torch.from_numpy(x)[None], torch.from_numpy(legal)[None])[0].numpy().astype(np.float64)
        if self.greedy:
            a = int(np.argmax(lg))
        else:
            p = np.exp(lg - lg.max())
            p[~legal] = 0.0
            p /= p.sum()
            a = int(self._rng.choice(len(p), p=p))
        self.decision_s += time.perf_counter() - t0
        self.decisions += 1
        return a
