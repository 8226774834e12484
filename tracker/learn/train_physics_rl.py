"""Training of the physics RL baseline (tracker.bouts.rl_agent): PPO on the semi-MDP of decisions.

    igraph-fight tracker rl train --graph G.igz --tracker CKPT --minutes 75 --out rl.pt

- Learning: PPO (clipped ratio, GAE: igraph_fight.learn.ppo) on the semi-MDP of decisions, discount
  0.99 per control step (the paper's gamma) raised to the decision's length; self-play: both
  fighters run the current policy (sampling), and with probability ``snapshot_prob`` the opponent
  is a past snapshot. Workers (processes) play bouts of ``episode_s`` seconds from the kinematic
  game's random starts.
- Budget: a fixed wall-clock budget (``--minutes``), recorded in the checkpoint with the samples
  (decisions) and simulated seconds.
"""
from __future__ import annotations

import multiprocessing as mp
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from torch import nn

from igraph_fight.checkpoint import save_checkpoint
from igraph_fight.learn import ppo

from tracker.bouts.loaders import bout_library
from tracker.bouts.rl_agent import (N_PHYS, RL_CKPT_FORMAT, RL_CKPT_VERSION, ActorCritic, PhysicsRLAgent, RLConfig,
                                    load_rl_checkpoint)


def parse_overrides(items: list[str] | None) -> dict:
    """``["lr=1e-4", "hidden=256,256"]`` -> typed RLConfig overrides (ValueError naming a bad one)."""
    from tracker.learn.overrides import parse_config_overrides
    return parse_config_overrides(items, RLConfig)


# ----------------------------------------------------------------------------------------------
# workers


class _Worker:
    def __init__(self, cfg: RLConfig, graph: str | None, library: str | None, tracker: str, wid: int) -> None:
        from tracker.bouts.loaders import load_tracker
        from tracker.bouts.setup import BoutConfig, BoutSetup
        torch.set_num_threads(1)
        self.cfg = cfg
        self.lib = bout_library(graph, library)
        self.tracker = load_tracker(tracker)
        self.setup = BoutSetup.create(self.lib, tracker=self.tracker)
        self.nf = np.asarray(self.lib.n_frames, dtype=np.int64)
        self.A = self.lib.n_actions
        self.obs_dim = 5 + 2 * self.A + 3 + N_PHYS
        self.nets = [ActorCritic(self.obs_dim, self.A, cfg.hidden) for _ in range(2)]
        self.bcfg = BoutConfig(seconds=cfg.episode_s, record_qpos=False,
                               physics_hz=self.setup.scene.options.physics_hz)
        self.rng = np.random.default_rng([cfg.seed, wid])
        self.wid = wid

    def collect(self, state: dict, opp_state: dict | None, n_decisions: int) -> dict:
        from tracker.bouts.physics_bout import PhysicsBout
        self.nets[0].load_state_dict(state)
        use_snap = opp_state is not None and self.rng.random() < self.cfg.snapshot_prob
        self.nets[1].load_state_dict(opp_state if use_snap else state)
        out = {k: [] for k in ("obs", "mask", "action", "logp", "value", "reward", "steps", "last")}
        stats = {"bouts": 0, "hits": 0.0, "falls": 0.0, "sim_s": 0.0, "match": 0.0, "ep_reward": 0.0}
        t0 = time.process_time()
        n = 0
        while n < n_decisions:
            learner_side = int(self.rng.integers(2))
            agents = [None, None]
            for k in (0, 1):
                learn = (k == learner_side) or not use_snap
                agents[k] = PhysicsRLAgent(self.nets[0] if learn else self.nets[1], self.A, self.nf, self.cfg,
                                    sample=True, record=learn)
            bout = PhysicsBout(self.setup, agents, self.tracker, self.bcfg)
            res = bout.run(seed=int(self.rng.integers(1 << 31)))
            stats["bouts"] += 1
            stats["hits"] += float(res.hits.sum())
            stats["falls"] += float(res.falls.sum())
            stats["sim_s"] += res.sim_s
            for k in (0, 1):
                ag = agents[k]
                if not ag.record or not ag.traj:
                    continue
                stats["match"] += float(res.reward[k]["match"])
                for i, tr in enumerate(ag.traj):
                    for key in ("obs", "mask", "action", "logp", "value", "reward", "steps"):
                        out[key].append(tr[key])
                    out["last"].append(i == len(ag.traj) - 1)
                    stats["ep_reward"] += tr["reward"]
                n += len(ag.traj)
        stats["cpu_s"] = time.process_time() - t0
        arr = {k: np.array(v) for k, v in out.items()}
        return {"data": arr, "stats": stats}


def _worker_main(conn, cfg_d: dict, graph, library, tracker, wid: int) -> None:
    cfg = RLConfig.from_dict(cfg_d)
    w = _Worker(cfg, graph, library, tracker, wid)
    conn.send(("ready", w.obs_dim, w.A))
    while True:
        msg = conn.recv()
        if msg[0] == "stop":
            break
        _, state, opp, n = msg
        conn.send(("data", w.collect(state, opp, n)))


# ----------------------------------------------------------------------------------------------
# PPO


def gae(data: dict, cfg: RLConfig) -> tuple[np.ndarray, np.ndarray]:
    """Advantages and returns over concatenated trajectories (``last`` ends each; terminal there):
    igraph_fight.learn.ppo.gae with each decision discounted by gamma_step ** its control steps."""
    r, v, n, last = data["reward"], data["value"], data["steps"], data["last"]
    last = np.asarray(last, dtype=bool)
    disc = np.array([cfg.gamma_step ** max(int(k), 1) for k in n], dtype=np.float64)
    v_next = np.where(last, 0.0, np.concatenate([v[1:], [0.0]])) if len(r) else np.zeros(0)
    return ppo.gae(r, v, v_next, np.where(last, 0.0, 1.0), disc, cfg.lam)


def ppo_update(net: ActorCritic, opt: torch.optim.Optimizer, data: dict, cfg: RLConfig,
               rng: np.random.Generator) -> dict:
    adv, ret = gae(data, cfg)
    obs = torch.from_numpy(data["obs"].astype(np.float32))
    mask = torch.from_numpy(data["mask"])
    act = torch.from_numpy(data["action"].astype(np.int64))
    logp_old = torch.from_numpy(data["logp"].astype(np.float32))
    adv_t = torch.from_numpy(ppo.normalise(adv).astype(np.float32))
    ret_t = torch.from_numpy(ret.astype(np.float32))
    N = len(act)
    info = {"kl": 0.0, "entropy": 0.0, "v_loss": 0.0}
    nb = 0
    for _ in range(cfg.epochs):
        perm = rng.permutation(N)
        for s in range(0, N, cfg.minibatch):
            idx = torch.from_numpy(perm[s:s + cfg.minibatch])
            logits, v = net(obs[idx], mask[idx])
            dist = torch.distributions.Categorical(logits=logits)
            lp = dist.log_prob(act[idx])
            ratio = torch.exp(lp - logp_old[idx])
            a = adv_t[idx]
            pl = ppo.clipped_policy_loss(ratio, a, cfg.clip)
            ent = dist.entropy().mean()
            vl = ((v - ret_t[idx]) ** 2).mean()
            loss = pl + cfg.vf_coef * vl - cfg.ent_coef * ent
            opt.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(net.parameters(), cfg.max_grad_norm)
            opt.step()
            with torch.no_grad():
                info["kl"] += float((logp_old[idx] - lp).mean())
                info["entropy"] += float(ent)
                info["v_loss"] += float(vl)
            nb += 1
    return {k: v / max(nb, 1) for k, v in info.items()}


def train(graph: str | None, tracker: str, out: str, minutes: float, cfg: RLConfig = RLConfig(),
          library: str | None = None, resume: str | None = None, log=print, max_iterations: int | None = None,
          progress: bool = False) -> dict:
    """Self-play PPO for ``minutes`` of wall clock (or ``max_iterations`` PPO iterations, whichever
    ends first); writes ``out`` (checkpoint, atomically, every ``ckpt_every_min`` and at the end)
    and ``out``.png. ``resume`` continues a checkpoint: weights, optimiser, opponent pool, budget."""
    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    ck = load_rl_checkpoint(resume) if resume else None     # a refused file fails before the workers start
    ctx = mp.get_context("spawn")
    pipes, procs = [], []
    for w in range(cfg.n_workers):
        a, b = ctx.Pipe()
        p = ctx.Process(target=_worker_main, args=(b, asdict(cfg), graph, library, tracker, w), daemon=True)
        p.start()
        pipes.append(a)
        procs.append(p)
    ready = [c.recv() for c in pipes]
    obs_dim, A = ready[0][1], ready[0][2]
    net = ActorCritic(obs_dim, A, cfg.hidden)
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    history: list[dict] = []
    budget = {"decisions": 0, "sim_s": 0.0, "wall_s": 0.0, "worker_cpu_s": 0.0, "bouts": 0, "iterations": 0}
    if ck is not None:
        net.load_state_dict(ck["model"])
        if "optimizer" in ck:
            opt.load_state_dict(ck["optimizer"])
        history = list(ck.get("history", []))
        budget = dict(ck.get("budget", budget))
    pool: list[dict] = list(ck.get("pool", [])) if ck is not None else []
    lib_info = _lib_info(graph, library)
    t_start = time.time()
    wall0 = budget["wall_s"]
    last_ckpt = time.time()
    it = budget["iterations"]

    def save(final: bool = False) -> None:
        budget["wall_s"] = wall0 + (time.time() - t_start)
        ck = {"model": net.state_dict(), "optimizer": opt.state_dict(), "config": asdict(cfg), "obs_dim": obs_dim,
              "n_actions": A, "history": history, "budget": budget, "library": lib_info,
              "tracker": str(tracker), "final": final, "pool": pool}
        save_checkpoint(out, ck, RL_CKPT_FORMAT, RL_CKPT_VERSION)

    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=int(minutes * 60), unit="s", desc="physics rl", dynamic_ncols=True)
        log = bar.write                  # the per-iteration lines go above the bar
    n_it = 0
    try:
        while time.time() - t_start < minutes * 60.0 and (max_iterations is None or n_it < max_iterations):
            n_it += 1
            state = {k: v.clone() for k, v in net.state_dict().items()}
            opp = pool[int(rng.integers(len(pool)))] if pool else None
            for c in pipes:
                c.send(("collect", state, opp, cfg.decisions_per_worker))
            parts = [c.recv()[1] for c in pipes]
            data = {k: np.concatenate([p["data"][k] for p in parts]) for k in parts[0]["data"]}
            st = {k: sum(p["stats"][k] for p in parts) for k in parts[0]["stats"]}
            info = ppo_update(net, opt, data, cfg, rng)
            it += 1
            n = len(data["action"])
            budget["decisions"] += n
            budget["sim_s"] += st["sim_s"]
            budget["worker_cpu_s"] += st["cpu_s"]
            budget["bouts"] += st["bouts"]
            budget["iterations"] = it
            minutes_sim = max(st["sim_s"] / 60.0, 1e-9)
            h = {"it": it, "decisions": budget["decisions"], "wall_min": round((wall0 + time.time() - t_start) / 60, 2),
                 "reward_per_decision": float(data["reward"].mean()), "hits_per_min": st["hits"] / minutes_sim,
                 "falls_per_min": st["falls"] / minutes_sim, "entropy": info["entropy"], "kl": info["kl"],
                 "v_loss": info["v_loss"]}
            history.append(h)
            log(f"it {it} decisions {budget['decisions']} wall {h['wall_min']:.1f} min: reward/decision "
                f"{h['reward_per_decision']:+.4f} hits/min {h['hits_per_min']:.2f} falls/min {h['falls_per_min']:.1f} "
                f"entropy {h['entropy']:.3f} kl {h['kl']:.4f}")
            if it % cfg.snapshot_every == 0:
                pool.append({k: v.clone() for k, v in net.state_dict().items()})
                pool = pool[-10:]
            if bar is not None:
                bar.n = min(int(time.time() - t_start), bar.total)
                bar.set_postfix(decisions=budget["decisions"], falls_min=f"{h['falls_per_min']:.1f}",
                                hits_min=f"{h['hits_per_min']:.2f}")
                bar.refresh()
            if time.time() - last_ckpt > cfg.ckpt_every_min * 60.0:
                save()
                last_ckpt = time.time()
    finally:
        if bar is not None:
            bar.close()
        for c in pipes:
            try:
                c.send(("stop",))
            except (BrokenPipeError, OSError):
                pass
        for p in procs:
            p.join(timeout=10)
    save(final=True)
    _plot_history(history, Path(str(out) + ".png"))
    return {"budget": budget, "history": history[-1] if history else None}


def _lib_info(graph, library) -> dict:
    lib = bout_library(graph, library)
    return {"n_actions": int(lib.n_actions), "fps": float(lib.fps), "graph": str(graph), "library": str(library)}


def _plot_history(history: list[dict], path: Path) -> None:
    if not history:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    x = [h["wall_min"] for h in history]
    fig, axs = plt.subplots(1, 3, figsize=(13, 3.5))
    axs[0].plot(x, [h["reward_per_decision"] for h in history])
    axs[0].set_title("reward per decision (scaled)")
    axs[1].plot(x, [h["hits_per_min"] for h in history], label="hits/min (both)")
    axs[1].plot(x, [h["falls_per_min"] for h in history], label="falls/min (both)")
    axs[1].legend()
    axs[2].plot(x, [h["entropy"] for h in history])
    axs[2].set_title("policy entropy")
    for a in axs:
        a.set_xlabel("wall minutes")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
