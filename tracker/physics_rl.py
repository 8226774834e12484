"""Physics RL baseline: a scaled-down version of the competitive-sports paper's bout-level learning
(Won, Gopinath, Hodgins 2021), trained by self-play on CPU.

    python -m tracker.physics_rl train --graph G.igz --tracker CKPT --minutes 75 --out rl.pt
    python -m tracker.physics_rl eval --graph G.igz --rl rl.pt --styles infighter,outboxer --bouts 10

What is learned, and what is kept from the paper:
- Action space: the Interaction Graph's action menus. At each decision (its current action ends,
  tracker.bout's decision rule) the policy picks the next action from Next(M_self) (a masked
  categorical over the library's actions); the same tracking policy as the IG fighters executes
  it. The paper learns a task encoder over a motor decoder's experts at 30 Hz; on 2 CPU cores a
  per-step policy over the 66 PD targets is far out of budget (DESIGN.md section 9), and the
  menu is the tracker's "decoder" here (it only knows how to track library actions).
- Observation: the coupled state (r, sin/cos of both angles, one-hot M_self and M_other, F_other
  and frames left in M_other, the open-strike flag) plus physical features of both bodies
  (pelvis height, tilt, velocity in the decider's facing frame, fallen flags, closest fist-to-target
  distances both ways; tracker.bout.PhysicsBout.features).
- Reward: the paper's eq. 1 per control step, summed over the decision's interval: r_match
  (clipped fist force on head/chest/belly given minus received, N, clip 200 N) + 0.2 r_close
  (exp(-3 d^2), d closest fist-to-target distance) + 0.05 r_facing (exp(-5 |v.f - 1|)) - 0.001
  r_energy (kappa_dist * sum of squared joint angular accelerations) - 30 per fall. The sum is
  multiplied by ``reward_scale`` for the optimiser (the weights' ratios are the paper's).
  Falls do not end the episode (tracker.bout resets the fighter); the paper terminates.
- Learning: PPO (clipped ratio, GAE) on the semi-MDP of decisions, discount 0.99 per control step
  (the paper's gamma) raised to the decision's length; self-play: both fighters run the current
  policy (sampling), and with probability ``snapshot_prob`` the opponent is a past snapshot.
  Workers (processes) play bouts of ``episode_s`` seconds from the kinematic game's random starts.
- Budget: a fixed wall-clock budget (``--minutes``), recorded in the checkpoint with the samples
  (decisions) and simulated seconds.

Evaluation (``evaluate_vs_rl``): planner+tracker fighters (NPCController, given style and depth)
against the RL policy over N physics bouts (seeds 0..N-1, the IG fighter as A): score (IG hits -
RL hits), falls and hits each way.
"""
from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import os
import re
import sys
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import torch
from torch import nn

#: The checkpoint shipped with the repository (trained against the CMU boxing library, 68 actions).
DEFAULT_RL_CKPT = Path(__file__).resolve().parent / "checkpoints" / "physics_rl_cmu13.pt"

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


def parse_overrides(items: list[str] | None) -> dict:
    """``["lr=1e-4", "hidden=256,256"]`` -> typed RLConfig overrides (ValueError naming a bad one)."""
    from .overrides import parse_config_overrides
    return parse_config_overrides(items, RLConfig)


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
    """The policy's input for a tracker.bout.DecisionContext (see the module doc)."""
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


class RLAgent:
    """tracker.bout agent running an ActorCritic. ``sample``: draw from the policy (else its mode);
    ``record``: keep transitions for training (obs, mask, action, logp, value, reward, steps)."""

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

    def reset(self, bout, k, rng) -> None:
        self.rng = np.random.default_rng(rng.integers(1 << 31))
        self.traj = []

    def decide(self, ctx) -> int:
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

    def finish(self, k: int, reward: dict, steps: int) -> None:
        if self.record and self.traj:
            self.traj[-1]["reward"] = decision_reward(reward, self.cfg)
            self.traj[-1]["steps"] = steps


def load_rl_checkpoint(path: str | os.PathLike) -> dict:
    return torch.load(str(path), map_location="cpu", weights_only=False)


def load_rl_agent(path: str | os.PathLike | None, library, sample: bool = True) -> RLAgent:
    """The RL baseline as a tracker.bout agent (default: the shipped checkpoint)."""
    p = Path(path) if path else DEFAULT_RL_CKPT
    if not p.is_file():
        raise FileNotFoundError(f"no physics RL checkpoint at {p} (train: python -m tracker.physics_rl train ...)")
    ck = load_rl_checkpoint(p)
    cfg = RLConfig.from_dict(ck["config"])
    n_actions = int(ck["n_actions"])
    if n_actions != library.n_actions:
        raise ValueError(f"RL checkpoint {p} was trained on {n_actions} actions, the library has {library.n_actions}")
    net = ActorCritic(int(ck["obs_dim"]), n_actions, tuple(cfg.hidden))
    net.load_state_dict(ck["model"])
    net.eval()
    return RLAgent(net, n_actions, np.asarray(library.n_frames, dtype=np.int64), cfg, name="rl-baseline",
                   sample=sample)


# ----------------------------------------------------------------------------------------------
# workers


def _library_from(graph: str | None, library: str | None):
    if library:
        from motion_graph.library import load_library
        return load_library(library)
    from igraph_fight.graph import load_graph
    return load_graph(graph).load_library()


class _Worker:
    def __init__(self, cfg: RLConfig, graph: str | None, library: str | None, tracker: str, wid: int) -> None:
        from .bout_agents import load_tracker
        from .bout_setup import BoutConfig, BoutSetup
        torch.set_num_threads(1)
        self.cfg = cfg
        self.lib = _library_from(graph, library)
        self.setup = BoutSetup.create(self.lib)
        self.tracker = load_tracker(tracker)
        self.nf = np.asarray(self.lib.n_frames, dtype=np.int64)
        self.A = self.lib.n_actions
        self.obs_dim = 5 + 2 * self.A + 3 + N_PHYS
        self.nets = [ActorCritic(self.obs_dim, self.A, cfg.hidden) for _ in range(2)]
        self.bcfg = BoutConfig(seconds=cfg.episode_s, record_qpos=False)
        self.rng = np.random.default_rng([cfg.seed, wid])
        self.wid = wid

    def collect(self, state: dict, opp_state: dict | None, n_decisions: int) -> dict:
        from .bout import PhysicsBout
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
                agents[k] = RLAgent(self.nets[0] if learn else self.nets[1], self.A, self.nf, self.cfg,
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
    """Advantages and returns over concatenated trajectories (``last`` ends each; terminal there)."""
    r, v, n, last = data["reward"], data["value"], data["steps"], data["last"]
    T = len(r)
    adv = np.zeros(T)
    g = 0.0
    for t in range(T - 1, -1, -1):
        disc = cfg.gamma_step ** max(int(n[t]), 1)
        nv = 0.0 if last[t] else v[t + 1]
        if last[t]:
            g = 0.0
        delta = r[t] + disc * nv - v[t]
        g = delta + disc * cfg.lam * g
        adv[t] = g
    return adv, adv + v


def ppo_update(net: ActorCritic, opt: torch.optim.Optimizer, data: dict, cfg: RLConfig,
               rng: np.random.Generator) -> dict:
    adv, ret = gae(data, cfg)
    obs = torch.from_numpy(data["obs"].astype(np.float32))
    mask = torch.from_numpy(data["mask"])
    act = torch.from_numpy(data["action"].astype(np.int64))
    logp_old = torch.from_numpy(data["logp"].astype(np.float32))
    adv_t = torch.from_numpy(((adv - adv.mean()) / (adv.std() + 1e-8)).astype(np.float32))
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
            pl = -torch.min(ratio * a, torch.clamp(ratio, 1 - cfg.clip, 1 + cfg.clip) * a).mean()
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
    if resume:
        ck = load_rl_checkpoint(resume)
        net.load_state_dict(ck["model"])
        if "optimizer" in ck:
            opt.load_state_dict(ck["optimizer"])
        history = list(ck.get("history", []))
        budget = dict(ck.get("budget", budget))
    pool: list[dict] = list(ck.get("pool", [])) if resume else []
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
        tmp = str(out) + ".tmp"
        torch.save(ck, tmp)
        os.replace(tmp, out)

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
    lib = _library_from(graph, library)
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


# ----------------------------------------------------------------------------------------------
# evaluation: planner + tracker vs the RL baseline


_ROW_KEYS = ("seed", "score", "hits_a", "hits_b", "falls_a", "falls_b", "planned_hits_a", "planned_hits_b",
             "planned_realised", "planned_hits", "mean_distance_m", "realtime_factor", "damage_n_a", "damage_n_b",
             "decisions_a", "decisions_b", "kind_share_a", "kind_share_b")


def _eval_rows(job: tuple, log=None, trk=None) -> list[dict]:
    """One style's bouts for the given seeds (a worker of evaluate_vs_rl; bouts depend on their
    seed only, so any split of the seeds gives the same rows). ``trk``: the tracking controller
    when the caller has it loaded already."""
    (graph, library, rl_ckpt, tracker, root_assist, style, depth, first_ply, hit_model, future, seconds, seeds) = job
    if log is None:
        import torch
        torch.set_num_threads(1)
        log = lambda s: print(s, flush=True)  # noqa: E731
    from igraph_fight.graph import load_graph

    from .bout import PhysicsBout
    from .bout_agents import load_tracker, make_agent
    from .bout_run import search_stats
    from .bout_setup import BoutConfig, BoutSetup
    g = load_graph(graph)
    lib = _library_from(None, library) if library else g.load_library()
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), root_assist=root_assist)
    trk = trk if trk is not None else load_tracker(tracker)
    rl = load_rl_agent(rl_ckpt, lib)
    spec = style if not hit_model else f"{style}+phys" + ("" if hit_model == "default" else f":{hit_model}")
    ig = make_agent(spec, g, lib, depth, first_ply=first_ply, future=future)
    npc = ig.controller
    rows = []
    for seed in seeds:
        bout = PhysicsBout(setup, [ig, rl], trk, BoutConfig(seconds=seconds, record_qpos=False))
        s = bout.run(seed=seed).summary()
        rows.append({k: s[k] for k in _ROW_KEYS})
        if (stats := search_stats(trk)) is not None:
            rows[-1]["search_stats"] = stats
        log(f"{style} vs rl, seed {seed}: score {s['score']:+.0f} (hits {s['hits_a']:.0f}-{s['hits_b']:.0f}), "
            f"falls {s['falls_a']}-{s['falls_b']}, planned {s['planned_hits']:.0f} realised {s['planned_realised']:.0f}, "
            f"distance {s['mean_distance_m']:.2f} m, rtf {s['realtime_factor']:.1f}x")
    npc.close()
    return rows


def evaluate_vs_rl(graph: str, rl_ckpt: str | None, styles: list[str], n_bouts: int = 10, seconds: float = 60.0,
                   depth: int = 5, tracker: str | None = None, library: str | None = None, seed0: int = 0,
                   root_assist: bool = False, log=print, first_ply: str = "table",
                   hit_model: str | None = None, future: str = "calibrated", workers: int = 1) -> dict:
    """IG fighters (each style, depth ``depth``, NPCController's ``first_ply``, as A) vs the RL baseline (B) over ``n_bouts``
    physics bouts each (seeds seed0..seed0+n-1). ``hit_model`` ("default" or a path): the IG
    fighters score their first ply with physically measured hit odds (tracker.hit_model.phys_fighter,
    later plies by ``future``) instead of ``first_ply``. ``workers`` > 1 plays the bouts in that many
    processes (the same rows: a bout depends on its seed only). Returns per style: scores (IG hits -
    RL hits), mean / std / wins, falls and hits each way, planned-vs-realised of the IG fighter."""
    from .bout_agents import load_tracker
    if hit_model:
        from .hit_model import load_hit_model
        load_hit_model(None if hit_model == "default" else hit_model)      # a bad path fails here, not in a worker
    trk = load_tracker(tracker)
    out = {"tracker": getattr(trk, "describe", lambda: trk.name)(), "rl": str(rl_ckpt or DEFAULT_RL_CKPT),
           "seconds": seconds, "n_bouts": n_bouts, "depth": depth, "first_ply": first_ply, "root_assist": root_assist,
           "hit_model": hit_model, "future": future if hit_model else None, "styles": {}}
    seeds = list(range(seed0, seed0 + n_bouts))
    for style in styles:
        jobs = [(graph, library, rl_ckpt, tracker, root_assist, style, depth, first_ply, hit_model, future, seconds,
                 seeds[i::workers]) for i in range(max(1, workers)) if seeds[i::workers]]
        if len(jobs) <= 1:
            rows = _eval_rows(jobs[0], log, trk) if jobs else []
        else:
            # spawn, not fork: the parent has torch's thread pool running (the tracker), which a
            # forked child can deadlock on
            with mp.get_context("spawn").Pool(len(jobs)) as pool:
                rows = sorted((r for part in pool.map(_eval_rows, jobs) for r in part), key=lambda r: r["seed"])
        sc = np.array([r["score"] for r in rows])
        tot = lambda k: float(sum(r[k] for r in rows))  # noqa: E731
        out["styles"][style] = {
            "bouts": rows, "mean_score": float(sc.mean()), "std_score": float(sc.std()),
            "wins": int((sc > 0).sum()), "draws": int((sc == 0).sum()), "losses": int((sc < 0).sum()),
            "hits_ig": tot("hits_a"), "hits_rl": tot("hits_b"),
            "falls_ig_per_min": tot("falls_a") / (n_bouts * seconds / 60), "falls_rl_per_min": tot("falls_b") / (n_bouts * seconds / 60),
            "planned_hits": tot("planned_hits"), "planned_realised": tot("planned_realised"),
            "damage_n_ig": tot("damage_n_a"), "damage_n_rl": tot("damage_n_b"),
            "kind_share_ig": _pooled_shares(rows, "a"), "kind_share_rl": _pooled_shares(rows, "b"),
        }
    return out


def _pooled_shares(rows: list[dict], side: str) -> dict:
    """Share of each action kind among one side's decisions over all bouts (decision-weighted)."""
    counts: dict[str, float] = {}
    for r in rows:
        for k, v in r[f"kind_share_{side}"].items():
            counts[k] = counts.get(k, 0.0) + v * r[f"decisions_{side}"]
    n = sum(counts.values())
    return {k: round(v / n, 4) for k, v in sorted(counts.items(), key=lambda kv: -kv[1])} if n else {}


def split_styles(text: str) -> list[str]:
    """``--styles`` to fighter specs: split at commas, except a comma before a digit, which belongs to
    a style's options (``close=R,THETA``, ``:avoid=A,B``)."""
    return [s for s in re.split(r",(?![\d.])", text) if s]


def main(argv: list[str] | None = None) -> int:
    from igraph_fight.controller import FIRST_PLY
    p = argparse.ArgumentParser(prog="python -m tracker.physics_rl", description="physics RL baseline")
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="self-play PPO for a fixed wall-clock budget")
    t.add_argument("--graph", default=None, help="graph file whose embedded library gives the actions")
    t.add_argument("--library", default=None)
    t.add_argument("--tracker", required=True, help="tracking policy checkpoint (or 'pd')")
    t.add_argument("--minutes", type=float, default=75.0)
    t.add_argument("--out", required=True)
    t.add_argument("--resume", default=None)
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override an RLConfig field")
    t.add_argument("--no-progress", action="store_true", help="no progress bar (the per-iteration lines stay)")
    e = sub.add_parser("eval", help="planner+tracker fighters vs the RL baseline")
    e.add_argument("--graph", required=True)
    e.add_argument("--library", default=None)
    e.add_argument("--rl", default=None)
    e.add_argument("--tracker", default=None)
    e.add_argument("--styles", default="infighter,outboxer",
                   help="comma-separated IG styles; STYLE+close[=R,THETA][:avoid=A,B,...]: closes in by a geometric "
                   "rule until engaged (igraph_fight.closing)")
    e.add_argument("--bouts", type=int, default=10)
    e.add_argument("--seconds", type=float, default=60.0)
    e.add_argument("--depth", type=int, default=5)
    e.add_argument("--seed0", type=int, default=0, help="first bout's seed (bouts use seed0, seed0+1, ...)")
    e.add_argument("--first-ply", default="table", choices=FIRST_PLY,
                   help="the IG fighters' first plies (igraph_fight.controller.NPCController)")
    e.add_argument("--hit-model", nargs="?", const="default", default=None, metavar="MODEL",
                   help="IG fighters score their first ply with physically measured hit odds (tracker.hit_model; "
                        "no value: the shipped tracker/checkpoints/hit_model_cmu13.pt)")
    from .hit_model import FUTURES
    e.add_argument("--future", default="calibrated", choices=FUTURES,
                   help="with --hit-model: the later plies' values (tracker.hit_model.phys_fighter)")
    e.add_argument("--workers", type=int, default=1, help="processes playing the bouts (same results)")
    e.add_argument("--root-assist", action="store_true")
    e.add_argument("--out", default=None, help="write the result as JSON")
    a = p.parse_args(argv)
    if a.cmd == "train":
        try:
            kw = parse_overrides(a.set)
        except ValueError as exc:
            p.error(str(exc))
        if not (a.graph or a.library):
            p.error("train needs --graph or --library (where the actions come from)")
        cfg = RLConfig(**{**asdict(RLConfig()), **kw})
        res = train(a.graph, a.tracker, a.out, a.minutes, cfg, library=a.library, resume=a.resume,
                    log=lambda s: print(s, flush=True), progress=not a.no_progress)
        print(json.dumps(res["budget"]))
        return 0
    res = evaluate_vs_rl(a.graph, a.rl, split_styles(a.styles), a.bouts, a.seconds, a.depth, a.tracker, a.library,
                         seed0=a.seed0, root_assist=a.root_assist, log=lambda s: print(s, flush=True), first_ply=a.first_ply,
                         hit_model=a.hit_model, future=a.future, workers=a.workers)
    summary = {k: v for k, v in res.items() if k != "styles"}
    summary["styles"] = {s: {k: v for k, v in d.items() if k != "bouts"} for s, d in res["styles"].items()}
    print(json.dumps(summary, indent=1))
    if a.out:
        from motion_graph.atomic import atomic_write_text
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(a.out, json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
