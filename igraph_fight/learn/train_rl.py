"""Masked PPO for the 'rl' baseline, CleanRL-style: one config, one file, top to bottom.

The learner plays bouts in the kinematic simulator through the game API (FightGame/FightState),
choosing library actions from its menu (invalid-action masking) with the features of
igraph_fight.agents.rl.RLFeatures. Its reward is Eq. 4 of a style (default infighter), summed
over every event between two of its decisions -- its own edge (W_me) and the opponent's edges
(W_opp) -- exactly the sum the IG fighter's min-max maximises (agents.common.EventReward).
Opponents, drawn per episode: a frozen snapshot of the learner (self-play, refreshed every
``self_play_refresh`` updates), random, static, the human proxy and the depth-2 game tree.

    igraph-fight train-rl --graph G.igz --style infighter --out igraph_fight/checkpoints/rl_infighter.pt
    igraph-fight train-rl --graph G.igz --style outboxer --init-from igraph_fight/checkpoints/rl_infighter.pt ...

The checkpoint (igraph_fight.checkpoint, format igraph-fight/rl-ppo, ~0.4 MB) holds the weights,
the config, the budget actually spent (CPU minutes of the process, wall minutes, learner
decisions, updates), the learning curve and the library fingerprint. Deterministic for a seed (single torch thread).
"""
from __future__ import annotations

import copy
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from igraph_fight.learn.ppo import clipped_policy_loss, gae, normalise


@dataclass
class RLConfig:
    style: str = "infighter"            # Eq. 4 reward preset or style file
    seed: int = 1
    total_decisions: int = 1_000_000    # learner decisions (the budget); also stops at max_cpu_minutes
    max_cpu_minutes: float = 15.0
    num_envs: int = 16                  # bouts played side by side
    num_steps: int = 128                # learner decisions per env per update
    episode_seconds: float = 30.0
    gamma: float = 0.97                 # per learner decision (~0.5 s)
    gae_lambda: float = 0.95
    lr: float = 3e-4
    anneal_lr: bool = True
    update_epochs: int = 4
    num_minibatches: int = 4
    clip_coef: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    reward_scale: float = 0.1
    hidden: int = 128
    opponents: dict = field(default_factory=lambda: {"self": 0.3, "random": 0.15, "static": 0.2, "human": 0.2,
                                                     "gametree2": 0.15})
    opponent_style: str = "infighter"   # reward of the static and game-tree opponents (fixed baselines)
    self_play_refresh: int = 10         # updates between self-play snapshots
    init_from: str | None = None        # warm start (e.g. retraining for a new style)


class FightEnv:
    """One learner slot in a bout against an opponent drawn per episode; auto-resets."""

    def __init__(self, game, cfg: RLConfig, rng: np.random.Generator, opponents: dict, reward) -> None:
        from igraph_fight.agents.rl import RLFeatures
        self.game, self.cfg, self.rng, self.opponents, self.reward = game, cfg, rng, opponents, reward
        self.feat = RLFeatures(game.tables)
        self.names = list(cfg.opponents)
        p = np.array([cfg.opponents[n] for n in self.names], dtype=np.float64)
        self.p = p / p.sum()
        self.finished: list[dict] = []
        self.reset()

    def reset(self) -> None:
        self.state = self.game.new_initial_state(self.rng)
        self.slot = int(self.rng.integers(2))
        self.opp_name = self.names[int(self.rng.choice(len(self.names), p=self.p))]
        self.opp = self.opponents[self.opp_name]
        self.opp.reset(self.game, 1 - self.slot, self.rng)
        self.feat.reset()
        self.ep_return = 0.0
        self.acc = 0.0
        self._run_opponent()
        self.acc = 0.0  # events before the learner's first decision belong to no action of it

    def _apply(self, p: int, a: int) -> None:
        st = self.state
        m_other = int(st.world.action[1 - p])
        ev = st.apply_action(a)
        self.acc += self.reward.reward(self.slot, p, a, m_other, ev, st.world)

    def _run_opponent(self) -> None:
        st = self.state
        while not st.is_terminal() and st.current_player() != self.slot:
            o = st.current_player()
            self._apply(o, int(self.opp.step(st, o)))

    def observe(self) -> tuple[np.ndarray, np.ndarray]:
        return self.feat(self.state, self.slot), self.feat.legal_mask(self.state, self.slot)

    def step(self, a: int) -> tuple[float, bool]:
        self._apply(self.slot, a)
        self._run_opponent()
        r, self.acc = self.acc, 0.0
        self.ep_return += r
        done = self.state.is_terminal()
        if done:
            h = self.state.hits
            self.finished.append({"opponent": self.opp_name, "return": self.ep_return,
                                  "score": float(h[self.slot] - h[1 - self.slot])})
            self.reset()
        return r, done


def train(game, cfg: RLConfig, out: str | Path | None = None, progress: bool = True, log=None) -> dict:
    """Train (or fine-tune, cfg.init_from) and return the checkpoint dict; save it to ``out``."""
    import torch
    from torch import nn, optim

    from igraph_fight.agents.common import EventReward, as_style
    from igraph_fight.agents.gametree import GameTreeAgent
    from igraph_fight.agents.human import HumanProxyAgent
    from igraph_fight.agents.rl import RL_FORMAT, RL_VERSION, RLAgent, load_checkpoint, make_network
    from igraph_fight.checkpoint import save_checkpoint
    from igraph_fight.agents.static import StaticAgent
    from igraph_fight.agents.base import RandomAgent
    from igraph_fight.graph import library_fingerprint

    torch.set_num_threads(1)
    torch.manual_seed(cfg.seed)
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    style = as_style(cfg.style)
    reward = EventReward(style, game.tables)

    # ---- networks -----------------------------------------------------------------------------
    A = int(game.tables.n_actions)
    from igraph_fight.agents.rl import RLFeatures
    obs_dim = RLFeatures(game.tables).dim
    net = make_network(obs_dim, A, cfg.hidden)
    prior = None
    if cfg.init_from:
        prior = load_checkpoint(cfg.init_from)
        net.load_state_dict(prior["state_dict"])
    opt = optim.Adam(net.parameters(), lr=cfg.lr, eps=1e-5)
    snapshot = copy.deepcopy(net)

    # ---- environments (each with its own opponents and random stream) ---------------------------
    from igraph_fight.game import FightGame
    from dataclasses import replace
    egame = FightGame(game.library, replace(game.config, max_seconds=cfg.episode_seconds), tables=game.tables)
    envs = []
    for i in range(cfg.num_envs):
        opps = {"self": RLAgent(network=snapshot, greedy=False, name="self"), "random": RandomAgent(),
                "static": StaticAgent(cfg.opponent_style), "human": HumanProxyAgent(),
                "gametree2": GameTreeAgent(2, cfg.opponent_style)}
        envs.append(FightEnv(egame, cfg, np.random.default_rng([cfg.seed, i]), opps, reward))

    N, S = cfg.num_envs, cfg.num_steps
    obs = torch.zeros((S, N, obs_dim))
    legal = torch.zeros((S, N, A), dtype=torch.bool)
    actions = torch.zeros((S, N), dtype=torch.long)
    logprobs = torch.zeros((S, N))
    rewards = torch.zeros((S, N))
    dones = torch.zeros((S, N))
    values = torch.zeros((S, N))
    batch = N * S
    mb = batch // cfg.num_minibatches
    n_updates = max(1, cfg.total_decisions // batch)
    curve: list[dict] = []
    decisions = 0
    o_np = [e.observe() for e in envs]
    next_obs = torch.from_numpy(np.stack([o for o, _ in o_np]))
    next_legal = torch.from_numpy(np.stack([m for _, m in o_np]))
    next_done = torch.zeros(N)
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=n_updates * batch, desc=f"rl {style.name}", unit="dec", leave=False)
    stop = "budget"
    update = 0
    for update in range(1, n_updates + 1):
        if (time.process_time() - t_cpu) / 60.0 > cfg.max_cpu_minutes:
            stop = "max_cpu_minutes"
            update -= 1
            break
        if cfg.anneal_lr:
            opt.param_groups[0]["lr"] = cfg.lr * (1.0 - (update - 1.0) / n_updates)
        # ---- rollout -----------------------------------------------------------------------------
        for step in range(S):
            obs[step], legal[step], dones[step] = next_obs, next_legal, next_done
            with torch.no_grad():
                logits = net.logits(next_obs, next_legal)
                dist = torch.distributions.Categorical(logits=logits)
                a = dist.sample()
                values[step] = net.value(next_obs)
            actions[step], logprobs[step] = a, dist.log_prob(a)
            r = np.zeros(N, dtype=np.float32)
            d = np.zeros(N, dtype=np.float32)
            for i, env in enumerate(envs):
                r[i], d[i] = env.step(int(a[i]))
            rewards[step] = torch.from_numpy(r) * cfg.reward_scale
            o_np = [e.observe() for e in envs]
            next_obs = torch.from_numpy(np.stack([o for o, _ in o_np]))
            next_legal = torch.from_numpy(np.stack([m for _, m in o_np]))
            next_done = torch.from_numpy(d)
        decisions += batch
        if bar is not None:
            bar.update(batch)
        # ---- advantages (GAE) --------------------------------------------------------------------
        with torch.no_grad():
            next_value = net.value(next_obs)
            # continues[t]: 1 - done of the step after t (the last step: the next observation's done)
            cont = torch.cat([dones[1:], next_done[None]]).neg_().add_(1.0)
            nv = torch.cat([values[1:], next_value[None]]) * cont
            adv_np, ret_np = gae(rewards.numpy(), values.numpy(), nv.numpy(), cont.numpy(), cfg.gamma, cfg.gae_lambda)
            adv, ret = torch.from_numpy(adv_np), torch.from_numpy(ret_np)
        # ---- PPO update --------------------------------------------------------------------------
        b_obs, b_legal = obs.reshape(batch, obs_dim), legal.reshape(batch, A)
        b_act, b_logp = actions.reshape(batch), logprobs.reshape(batch)
        b_adv, b_ret = adv.reshape(batch), ret.reshape(batch)
        gen = torch.Generator().manual_seed(cfg.seed * 100_003 + update)
        clipfracs = []
        for _ in range(cfg.update_epochs):
            perm = torch.randperm(batch, generator=gen)
            for s in range(0, batch, mb):
                idx = perm[s:s + mb]
                logits = net.logits(b_obs[idx], b_legal[idx])
                dist = torch.distributions.Categorical(logits=logits)
                newlogp = dist.log_prob(b_act[idx])
                # entropy over legal actions only (masked logits carry ~0 probability)
                p = dist.probs
                ent = -(p * torch.where(b_legal[idx], torch.log(p.clamp_min(1e-12)), torch.zeros_like(p))).sum(-1)
                ratio = (newlogp - b_logp[idx]).exp()
                pg = clipped_policy_loss(ratio, normalise(b_adv[idx]), cfg.clip_coef)
                v_loss = 0.5 * ((net.value(b_obs[idx]) - b_ret[idx]) ** 2).mean()
                loss = pg - cfg.ent_coef * ent.mean() + cfg.vf_coef * v_loss
                opt.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(net.parameters(), cfg.max_grad_norm)
                opt.step()
                clipfracs.append(float(((ratio - 1.0).abs() > cfg.clip_coef).float().mean()))
        if update % cfg.self_play_refresh == 0:
            snapshot.load_state_dict(net.state_dict())
        # ---- learning curve ----------------------------------------------------------------------
        fin = [f for e in envs for f in e.finished]
        for e in envs:
            e.finished.clear()
        row = {"update": update, "decisions": decisions, "wall_s": round(time.perf_counter() - t_wall, 2),
               "cpu_s": round(time.process_time() - t_cpu, 2), "episodes": len(fin),
               "mean_reward": float(rewards.mean() / cfg.reward_scale), "value_loss": float(v_loss.detach()),
               "entropy": float(ent.detach().mean()), "clipfrac": float(np.mean(clipfracs))}
        for name in cfg.opponents:
            sub = [f for f in fin if f["opponent"] == name]
            if sub:
                row[f"score_{name}"] = float(np.mean([f["score"] for f in sub]))
                row[f"return_{name}"] = float(np.mean([f["return"] for f in sub]))
        curve.append(row)
        if log is not None:
            log(row)
    if bar is not None:
        bar.close()
    ck = {
        "format": RL_FORMAT, "version": RL_VERSION, "state_dict": net.state_dict(), "config": asdict(cfg),
        "obs_dim": obs_dim, "n_actions": A, "style": style.name, "library_fingerprint": library_fingerprint(game.library),
        "sim": game.tables.params.to_json(),
        "budget": {"cpu_minutes": (time.process_time() - t_cpu) / 60.0, "wall_minutes": (time.perf_counter() - t_wall) / 60.0,
                   "decisions": decisions, "updates": update, "stop": stop, "torch_threads": 1},
        "init_from": None if prior is None else {"path": str(cfg.init_from), "style": prior.get("style"),
                                                  "budget": prior.get("budget")},
        "curve": curve, "torch_version": str(torch.__version__),
    }
    if out is not None:
        save_checkpoint(out, ck, RL_FORMAT, RL_VERSION)
    return ck
