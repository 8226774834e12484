"""Training the assisted tracker: PPO on the batched environment, one policy for the whole library.

    igraph-fight tracker train-assisted --minutes 60 --out assisted.pt [--resume assisted.pt] [--set k=v ...]

Read top to bottom:
1. ``AssistedTrainConfig``: every knob, one dataclass (stored in the checkpoint).
2. ``Rollouts``: ``n_envs`` worlds of one fighter (tracker.track.batch_env) following references of
   random walks through the action graph (a pool refreshed as it goes, grounded:
   tracker.track.grounding); episodes start at a random frame (reference-state initialisation, with
   joint-velocity noise), end at a fall or when the joint error passes ``et_mpjpe_m`` (terminated),
   and are cut at ``max_episode_steps`` or the walk's end (the value is bootstrapped there).
   With ``placement`` "body" each action's clip is placed under the simulated pelvis at its start
   (BatchEnv.place_on_body), as a game and the bouts place it, so the policy tracks what the
   protocol's re-rooted error measures instead of steering back to the walk as drawn.
   Optional pushes stand in for the opponent's contacts, which the walks lack: with probability
   ``push_prob`` per control step a slot not already pushed gets a horizontal force of
   ``push_force_mg`` body weights (uniform in the range, any direction) on one upper-body body
   (above the pelvis at rest: chest, neck, head, arms) for ``push_steps`` control steps.
3. The policy: a Gaussian over PD-target residuals (rad) and the assist wrench (cap units, facing
   frame); the wrench's mean starts at the fixed PD's (an observation: a learned gain per component
   on it, plus the network's output), so the first episodes already stand; reward = the env's
   tracking terms times exp(-``assist_penalty`` * (|F|/mg + |tau|/(mg m))): positive, so staying up
   always pays, and larger the less the assist does, which teaches the policy to shrink the assist
   where the body's own contacts can carry it. ``root_xy_weight`` prices the pelvis's horizontal
   distance to its reference in the root term (1/m^2; the body lagging its reference is what makes
   a bout's planned punch fall short); ``end_effector_weight`` and ``end_effector_scale`` (1/m^2)
   set the hands-and-feet term (a smaller scale still rewards hands 10-20 cm off, where the
   default's exponent has gone flat); ``com_weight`` and ``com_scale`` ((s/m)^2) set the
   centre-of-mass velocity term (a larger scale prices the pelvis drifting within an action);
   ``sites_weight`` and ``sites_scale`` (1/m^2) add a term on the world positions of the tracked
   joints, what the joint error (MPJPE) measures (off by default).
4. ``update``: PPO with the shared helper (igraph_fight.learn.ppo: GAE, clipped surrogate).
5. The cap curriculum: from ``cap_start`` the assist cap is multiplied by ``cap_decay`` each time
   the completion of the last ``curriculum_window`` episodes is at least ``curriculum_completion``,
   down to ``cap_min``.
6. ``train``: the loop, a progress bar, a resumable checkpoint every ``ckpt_every_min`` minutes and
   at the end (atomic), a learning-curve PNG beside it, a budget in CPU-hours that accumulates over
   resumed runs.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, fields

import numpy as np

from igraph_fight.learn.ppo import clipped_policy_loss, gae, normalise
from tracker.track.assisted_policy import FORMAT, N_ASSIST, VERSION
from tracker.track.pd import STANCE_GAINS


@dataclass
class AssistedTrainConfig:
    """All knobs of a training run (module docstring)."""

    seed: int = 0
    n_envs: int = 32
    horizon: int = 64
    walk_actions: int = 10
    pool_walks: int = 96
    refresh_walks: int = 2
    max_episode_steps: int = 300
    init_noise: float = 0.05
    et_mpjpe_m: float = 0.5
    physics_hz: float = 120.0
    class_scale: tuple = STANCE_GAINS
    arm_velocity_targets: bool = False   # arms damp towards the reference joint velocity (PDTracker)
    hidden: tuple = (512, 256)
    critic_hidden: tuple = (512, 256)
    init_log_std: float = -3.0
    init_log_std_assist: float = -2.3
    min_log_std: float = -4.0
    residual_clip: float = 0.5
    lr: float = 1e-4
    lr_min: float = 3e-6
    gamma: float = 0.95
    lam: float = 0.95
    clip: float = 0.2
    epochs: int = 4
    minibatch: int = 512
    vf_coef: float = 0.5
    max_grad_norm: float = 1.0
    target_kl: float = 0.03
    assist_penalty: float = 2.0
    root_xy_weight: float = 2.0
    end_effector_weight: float = 0.15
    end_effector_scale: float = 40.0
    com_weight: float = 0.1
    com_scale: float = 1.0
    sites_weight: float = 0.0            # the world joint-position term (RewardWeights.sites)
    sites_scale: float = 20.0
    placement: str = "world"             # "body": each action's clip placed under the body at its start
    cap_start: float = 0.5
    cap_min: float = 0.05
    cap_decay: float = 0.9
    curriculum_window: int = 200
    curriculum_completion: float = 0.95
    ckpt_every_min: float = 10.0
    push_prob: float = 0.0
    push_force_mg: tuple = (0.1, 0.4)
    push_steps: tuple = (2, 4)

    @classmethod
    def from_dict(cls, d: dict) -> "AssistedTrainConfig":
        known = {f.name for f in fields(cls)}
        kw = {}
        for k, v in d.items():
            if k in known:
                kw[k] = tuple(tuple(x) if isinstance(x, list) else x for x in v) if isinstance(v, list) else v
        return cls(**kw)


def reward_weights(cfg: AssistedTrainConfig):
    """The batched env's reward weights of a run (its assist penalty, root-position weight,
    end-effector and centre-of-mass velocity terms)."""
    from tracker.track.batch_env import RewardWeights
    return RewardWeights(assist_penalty=cfg.assist_penalty, root_xy=cfg.root_xy_weight,
                         end_effector=cfg.end_effector_weight, ee_scale=cfg.end_effector_scale,
                         com=cfg.com_weight, com_scale=cfg.com_scale, sites=cfg.sites_weight,
                         sites_scale=cfg.sites_scale)


def assisted_nets(obs_dim: int, act_dim: int, cfg: AssistedTrainConfig):
    """The actor (Gaussian over residuals and wrench, the fixed PD's wrench as its prior) and the critic."""
    import torch
    from torch import nn

    def mlp(sizes):
        layers = []
        for i in range(len(sizes) - 1):
            layers.append(nn.Linear(sizes[i], sizes[i + 1]))
            if i < len(sizes) - 2:
                layers.append(nn.ELU())
        return nn.Sequential(*layers)

    class Actor(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.mu = mlp([obs_dim, *cfg.hidden, act_dim])
            nn.init.uniform_(self.mu[-1].weight, -1e-3, 1e-3)
            nn.init.zeros_(self.mu[-1].bias)
            std = torch.full((act_dim,), float(cfg.init_log_std))
            std[act_dim - N_ASSIST:] = float(cfg.init_log_std_assist)
            self.log_std = nn.Parameter(std)
            # the assist's prior: a gain per wrench component on the fixed PD's wrench (the last six
            # raw observations), learned with the rest; 1 at the start
            self.assist_gain = nn.Parameter(torch.ones(N_ASSIST))

        def forward(self, x, fixed):
            mu = self.mu(x)
            prior = torch.cat([torch.zeros(x.shape[0], act_dim - N_ASSIST), fixed * self.assist_gain], dim=1)
            return mu + prior, self.log_std.expand(x.shape[0], -1)

    critic = mlp([obs_dim, *cfg.critic_hidden, 1])
    return Actor(), critic


class RunningNorm:
    """Running mean / variance of observations (parallel Welford)."""

    def __init__(self, dim: int) -> None:
        self.mean = np.zeros(dim)
        self.var = np.ones(dim)
        self.count = 1e-4

    def update(self, x: np.ndarray) -> None:
        bm, bv, n = x.mean(0), x.var(0), x.shape[0]
        delta = bm - self.mean
        tot = self.count + n
        self.mean = self.mean + delta * n / tot
        self.var = (self.var * self.count + bv * n + delta ** 2 * self.count * n / tot) / tot
        self.count = tot

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return np.clip((x - self.mean) / np.sqrt(self.var + 1e-8), -10.0, 10.0)


class Rollouts:
    """The batched env, its reference pool and per-slot episode bookkeeping."""

    def __init__(self, cfg: AssistedTrainConfig, library, seed: int) -> None:
        from tracker.track.assist import AssistConfig
        from tracker.track.batch_env import BatchConfig, BatchEnv
        from tracker.track.evaluation import make_setup
        from tracker.track.pd import PDTracker, batched_model_options
        from tracker.track.walks import LibraryWalks
        from tracker.track.walk_protocol import PLACEMENTS
        if cfg.placement not in PLACEMENTS:
            raise ValueError(f"placement must be one of {PLACEMENTS}, got {cfg.placement!r}")
        self.cfg = cfg
        self.rng = np.random.default_rng(seed)
        self.src = LibraryWalks(library)
        self.setup = make_setup(self.src, batched_model_options(cfg.physics_hz))
        self.cap = cfg.cap_start
        self.bcfg = BatchConfig(init_noise=cfg.init_noise, assist=AssistConfig("learned", cap=self.cap),
                                reward=reward_weights(cfg))
        self.env = BatchEnv(self.setup.scene, cfg.n_envs, self.bcfg)
        PDTracker(class_scale=cfg.class_scale, arm_velocity_targets=cfg.arm_velocity_targets).reset(self.env)
        self.pool = [self._new_ref() for _ in range(cfg.pool_walks)]
        self.steps = np.zeros(cfg.n_envs, dtype=np.int64)
        self.ep_return = np.zeros(cfg.n_envs)
        self.ep_assist = np.zeros(cfg.n_envs)
        self.finished: list[dict] = []
        self.push_bodies = upper_bodies(self.env)
        self.push_left = np.zeros(cfg.n_envs, dtype=np.int64)
        self.push_body = np.zeros(cfg.n_envs, dtype=np.int64)
        self.pushes = 0
        for b in range(cfg.n_envs):
            self._start(b)
        self.obs = self.env.observe()

    def push(self) -> None:
        """Start, hold or end the pushes before a control step (module docstring, item 2)."""
        c = self.cfg
        if c.push_prob <= 0.0 or len(self.push_bodies) == 0:
            return
        for b in range(c.n_envs):
            d = self.env.datas[b]
            if self.push_left[b] > 0:
                self.push_left[b] -= 1
                if self.push_left[b] == 0:
                    d.xfrc_applied[self.push_body[b], :3] = 0.0
            elif self.rng.random() < c.push_prob:
                body = int(self.push_bodies[self.rng.integers(len(self.push_bodies))])
                mag = float(self.rng.uniform(*c.push_force_mg)) * float(self.env.mass[b]) * 9.81
                ang = float(self.rng.uniform(-np.pi, np.pi))
                d.xfrc_applied[body, :3] = (mag * np.cos(ang), mag * np.sin(ang), 0.0)
                self.push_body[b] = body
                self.push_left[b] = int(self.rng.integers(c.push_steps[0], c.push_steps[1] + 1))
                self.pushes += 1

    def _new_ref(self):
        from tracker.track.evaluation import walk_reference
        from tracker.track.walk_protocol import action_starts
        walk = self.src.random_walk(self.cfg.walk_actions, self.rng)
        ref = walk_reference(self.setup, walk, lift="ground")[1]
        ref.meta["action_starts"] = set(int(x) for x in action_starts(self.src.library, walk)[1:])
        return ref

    def place(self) -> None:
        """With ``placement`` "body": the slots at an action's start get that clip placed under the
        body (BatchEnv.place_on_body, as the walk protocol's ``placement="body"`` and the bouts do)."""
        if self.cfg.placement != "body":
            return
        env = self.env
        due = [b for b in range(self.cfg.n_envs)
               if self.steps[b] > 0 and int(env.t[b]) in env.refs[b].meta.get("action_starts", ())]
        if due:
            env.place_on_body(due)
            self.obs = env.observe()

    def refresh(self) -> None:
        for _ in range(self.cfg.refresh_walks):
            self.pool[int(self.rng.integers(len(self.pool)))] = self._new_ref()

    def set_cap(self, cap: float) -> None:
        from dataclasses import replace
        self.cap = float(cap)
        self.env.config = replace(self.env.config, assist=replace(self.env.config.assist, cap=self.cap))

    def _start(self, b: int) -> None:
        if self.push_left[b] > 0:
            self.env.datas[b].xfrc_applied[self.push_body[b], :3] = 0.0
            self.push_left[b] = 0
        ref = self.pool[int(self.rng.integers(len(self.pool)))]
        s = int(self.rng.integers(0, max(1, ref.n_frames - 31)))
        self.env.reset([b], [ref], [s], self.rng)
        self.steps[b] = 0
        self.ep_return[b] = 0.0
        self.ep_assist[b] = 0.0


def upper_bodies(env) -> np.ndarray:
    """Body ids of the single fighter's upper body: more than 0.15 m above its pelvis in the model's
    rest pose (the bodies an opponent's punches and arms meet)."""
    import mujoco
    if env.F != 1:
        raise ValueError("pushes need a one-fighter scene")
    d = mujoco.MjData(env.model)
    mujoco.mj_kinematics(env.model, d)
    pel = env.layouts[0].pelvis
    ids = [b for b in range(1, env.model.nbody) if d.xpos[b, 2] > d.xpos[pel, 2] + 0.15]
    return np.asarray(ids, dtype=np.int64)


def train(out: str, minutes: float, cfg: AssistedTrainConfig = AssistedTrainConfig(), library: str | None = None,
          resume: str | None = None, progress: bool = True, log=print, max_iterations: int | None = None,
          overrides: dict | None = None) -> dict:
    """Train for ``minutes`` of wall clock (or ``max_iterations``); write ``out`` (and ``out``.png).
    ``resume``: continue a checkpoint (weights, optimiser, normaliser, curriculum, budget) under its
    stored config, except the fields in ``overrides`` (the command line's ``--set``); a
    ``cap_start`` among them restarts the cap curriculum at that cap."""
    import torch

    from igraph_fight.checkpoint import save_checkpoint
    from tracker.track.walks import default_library
    torch.set_num_threads(1)
    prior = None
    if resume:
        from igraph_fight.checkpoint import load_checkpoint
        prior = load_checkpoint(resume, FORMAT, (VERSION,), "assisted-tracker checkpoint")
        cfg = AssistedTrainConfig.from_dict({**asdict(cfg), **prior["config"], **(overrides or {})})
    torch.manual_seed(cfg.seed + (prior["budget"]["runs"] if prior else 0))
    if library:
        from motion_graph.library import load_library
        lib = load_library(library)
    else:
        lib = default_library(None)
    roll = Rollouts(cfg, lib, cfg.seed * 1000 + (prior["budget"]["runs"] if prior else 0))
    env = roll.env
    obs_dim, act_dim = roll.obs.shape[1], env.n_act + N_ASSIST
    actor, critic = assisted_nets(obs_dim, act_dim, cfg)
    opt = torch.optim.Adam(list(actor.parameters()) + list(critic.parameters()), lr=cfg.lr)
    norm = RunningNorm(obs_dim)
    budget = {"samples": 0, "cpu_s": 0.0, "wall_s": 0.0, "runs": 0, "iterations": 0}
    curve: list[dict] = []
    completions: list[float] = []
    if prior is not None:
        actor.load_state_dict(prior["actor"])
        critic.load_state_dict(prior["critic"])
        opt.load_state_dict(prior["optimizer"])
        norm.mean = np.asarray(prior["obs_mean"], float)
        norm.var = np.asarray(prior["obs_var"], float)
        norm.count = float(prior["obs_count"])
        budget = dict(prior["budget"])
        curve = list(prior["curve"])
        completions = list(prior.get("completions", []))
        roll.set_cap(cfg.cap_start if "cap_start" in (overrides or {}) else float(prior["cap"]))
    budget["runs"] += 1
    cpu0, wall0 = time.process_time(), time.perf_counter()
    cpu_base, wall_base = budget["cpu_s"], budget["wall_s"]
    N, T = cfg.n_envs, cfg.horizon
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=int(minutes * 60), desc="train-assisted", unit="s")
    last_ckpt = time.perf_counter()
    it = 0

    def save() -> None:
        budget["cpu_s"] = cpu_base + time.process_time() - cpu0
        budget["wall_s"] = wall_base + time.perf_counter() - wall0
        ck = {"actor": actor.state_dict(), "critic": critic.state_dict(),
              "optimizer": opt.state_dict(), "obs_mean": norm.mean, "obs_var": norm.var,
              "obs_count": float(norm.count), "config": plain_config(asdict(cfg)), "cap": float(roll.cap),
              "budget": dict(budget), "curve": curve, "completions": completions[-cfg.curriculum_window:],
              "bout_curve": list(prior.get("bout_curve", [])) if prior else [],
              "torch_version": torch.__version__}
        save_checkpoint(out, ck, FORMAT, VERSION)
        plot_curve(curve, str(out) + ".png")

    while True:
        elapsed = time.perf_counter() - wall0
        if elapsed >= minutes * 60 or (max_iterations is not None and it >= max_iterations):
            break
        # ---- collect ------------------------------------------------------------------------
        b = collect_walks(roll, actor, critic, norm, cfg, completions)
        R = b["r"]
        # ---- PPO update ---------------------------------------------------------------------
        n = T * N
        kl = ppo_update(actor, critic, opt, b["z"], b["fx"], b["a"], b["lp"], b["adv"], b["ret"], cfg,
                        cfg.seed * 100_003 + budget["iterations"])
        norm.update(b["raw"])     # after the update: the batch used the old statistics
        # ---- curriculum, bookkeeping ----------------------------------------------------------
        budget["samples"] += n
        budget["iterations"] += 1
        it += 1
        roll.refresh()
        recent = completions[-cfg.curriculum_window:]
        if len(recent) >= cfg.curriculum_window and np.mean(recent) >= cfg.curriculum_completion \
                and roll.cap > cfg.cap_min + 1e-9:
            roll.set_cap(max(cfg.cap_min, roll.cap * cfg.cap_decay))
            completions.clear()
        fin = roll.finished
        roll.finished = []
        row = {"samples": int(budget["samples"]), "cpu_h": (cpu_base + time.process_time() - cpu0) / 3600,
               "reward_per_step": float(R.mean()), "episodes": len(fin),
               "completion": float(np.mean(recent)) if recent else 0.0,
               "episode_steps": float(np.mean([f["steps"] for f in fin])) if fin else float("nan"),
               "assist_mg": float(np.mean([f["assist_mg"] for f in fin])) if fin else float("nan"),
               "cap": float(roll.cap), "pushes": int(roll.pushes), "kl": kl, "lr": float(opt.param_groups[0]["lr"]),
               "std": float(actor.log_std.detach().exp().mean()),
               "steps_per_s": float(n / max(time.perf_counter() - wall0 - elapsed, 1e-9))}
        curve.append(row)
        if bar is not None:
            bar.n = int(min(time.perf_counter() - wall0, minutes * 60))
            bar.set_postfix(cap=f"{roll.cap:.3f}", done=f"{row['completion']:.2f}", assist=f"{row['assist_mg']:.3f}",
                            sps=f"{row['steps_per_s']:.0f}")
            bar.refresh()
        elif log is not None and it % 10 == 0:
            log(row)
        if time.perf_counter() - last_ckpt > cfg.ckpt_every_min * 60:
            save()
            last_ckpt = time.perf_counter()
    if bar is not None:
        bar.close()
    save()
    return {"out": str(out), "budget": budget, "cap": roll.cap, "last": curve[-1] if curve else {}}



def collect_walks(roll: Rollouts, actor, critic, norm: RunningNorm, cfg: AssistedTrainConfig,
                  completions: list[float]) -> dict:
    """``cfg.horizon`` control steps of the ``n_envs`` walks (module docstring, item 2), sampling the
    policy; an ended episode restarts its slot and appends 1.0 (cut) or 0.0 (terminated) to
    ``completions``. Returns the batch flattened over (step, slot): normalised and raw observations
    ``z``, ``raw``, fixed-PD wrenches ``fx``, actions ``a``, log-probabilities ``lp``, rewards ``r``,
    advantages ``adv`` and returns ``ret`` (GAE)."""
    import torch
    env = roll.env
    N, T = cfg.n_envs, cfg.horizon
    obs_dim, act_dim = roll.obs.shape[1], env.n_act + N_ASSIST
    O = np.zeros((T, N, obs_dim), np.float32)
    FX = np.zeros((T, N, N_ASSIST), np.float32)
    RAW = np.zeros((T, N, obs_dim))
    A = np.zeros((T, N, act_dim), np.float32)
    LP = np.zeros((T, N), np.float32)
    R = np.zeros((T, N), np.float32)
    V = np.zeros((T, N), np.float32)
    NV = np.zeros((T, N), np.float32)
    C = np.zeros((T, N), np.float32)
    for t in range(T):
        roll.place()
        RAW[t] = roll.obs
        x = norm(roll.obs).astype(np.float32)
        with torch.no_grad():
            xt = torch.from_numpy(x)
            fx = roll.obs[:, -N_ASSIST:].astype(np.float32)
            FX[t] = fx
            mu, log_std = actor(xt, torch.from_numpy(fx))
            std = log_std.exp()
            a = mu + std * torch.randn_like(mu)
            lp = (-0.5 * ((a - mu) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
            v = critic(xt).squeeze(-1)
        an = a.numpy().astype(np.float64)
        targets = env.reference_targets() + np.clip(an[:, :env.n_act], -cfg.residual_clip, cfg.residual_clip)
        assist = np.clip(an[:, env.n_act:], -1.0, 1.0)
        roll.push()
        obs2, rew, done, info = env.step(targets, assist)
        roll.steps += 1
        roll.ep_return += rew
        roll.ep_assist += env.assist_force_mg
        fell = info["fall"] != 0
        lost = info["mpjpe_m"] > cfg.et_mpjpe_m
        term = fell | lost
        cut = (done & ~term) | (roll.steps >= cfg.max_episode_steps)
        O[t], A[t], LP[t], R[t], V[t] = x, a.numpy(), lp.numpy(), rew, v.numpy()
        # next value: 0 after a termination, V(final obs) after a cut, else V(s_t+1) (filled below)
        ended = term | cut
        if cut.any():
            with torch.no_grad():
                vc = critic(torch.from_numpy(norm(obs2).astype(np.float32))).squeeze(-1).numpy()
            NV[t] = np.where(cut & ~term, vc, 0.0)
        C[t] = (~ended).astype(np.float32)
        for b in np.nonzero(ended)[0]:
            n = int(roll.steps[b])
            completions.append(0.0 if term[b] else 1.0)
            roll.finished.append({"steps": n, "return": float(roll.ep_return[b]), "fell": bool(term[b]),
                                  "assist_mg": float(roll.ep_assist[b] / max(n, 1))})
            roll._start(b)
        roll.obs = env.observe() if ended.any() else obs2
    with torch.no_grad():
        v_last = critic(torch.from_numpy(norm(roll.obs).astype(np.float32))).squeeze(-1).numpy()
    nxt = np.concatenate([V[1:], v_last[None]], axis=0)
    NV = np.where(C > 0, nxt, NV)
    adv, ret = gae(R, V, NV, C, cfg.gamma, cfg.lam)
    n = T * N
    return {"z": O.reshape(n, obs_dim), "raw": RAW.reshape(n, obs_dim), "fx": FX.reshape(n, N_ASSIST),
            "a": A.reshape(n, act_dim), "lp": LP.reshape(n), "r": R.reshape(n), "adv": adv.reshape(n),
            "ret": ret.reshape(n)}


def ppo_update(actor, critic, opt, O: np.ndarray, FX: np.ndarray, A: np.ndarray, LP: np.ndarray, adv: np.ndarray,
               ret: np.ndarray, cfg: AssistedTrainConfig, seed: int) -> float:
    """PPO epochs over one batch (normalised observations O, raw fixed-PD wrenches FX, actions A,
    their log-probabilities LP, advantages and returns; all (n, ...)) with early stop at twice
    ``target_kl``, then the adaptive step: the update's KL sets the next learning rate within
    [lr_min, lr]. Returns the KL."""
    import torch
    n = O.shape[0]
    X = torch.from_numpy(np.ascontiguousarray(O, dtype=np.float32))
    XF = torch.from_numpy(np.ascontiguousarray(FX, dtype=np.float32))
    Aa = torch.from_numpy(np.ascontiguousarray(A, dtype=np.float32))
    LPo = torch.from_numpy(np.ascontiguousarray(LP, dtype=np.float32))
    ADV = torch.from_numpy(np.ascontiguousarray(adv, dtype=np.float32))
    RET = torch.from_numpy(np.ascontiguousarray(ret, dtype=np.float32))
    g = torch.Generator().manual_seed(seed)
    kl = 0.0
    for ep in range(cfg.epochs):
        perm = torch.randperm(n, generator=g)
        for s in range(0, n, cfg.minibatch):
            idx = perm[s:s + cfg.minibatch]
            mu, log_std = actor(X[idx], XF[idx])
            std = log_std.exp()
            lp = (-0.5 * ((Aa[idx] - mu) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
            ratio = torch.exp(lp - LPo[idx])
            pi_loss = clipped_policy_loss(ratio, normalise(ADV[idx]), cfg.clip)
            v_loss = 0.5 * ((critic(X[idx]).squeeze(-1) - RET[idx]) ** 2).mean()
            opt.zero_grad()
            (pi_loss + cfg.vf_coef * v_loss).backward()
            torch.nn.utils.clip_grad_norm_(list(actor.parameters()) + list(critic.parameters()), cfg.max_grad_norm)
            opt.step()
            with torch.no_grad():
                actor.log_std.clamp_(min=cfg.min_log_std)
        with torch.no_grad():
            mu, log_std = actor(X, XF)
            lp = (-0.5 * ((Aa - mu) / log_std.exp()) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
            logr = lp - LPo
            kl = float((logr.exp() - 1.0 - logr).mean())
        if kl > 2.0 * cfg.target_kl:
            break
    lr = opt.param_groups[0]["lr"]
    lr = max(cfg.lr_min, lr / 1.5) if kl > 2.0 * cfg.target_kl else min(cfg.lr, lr * 1.5) \
        if kl < 0.5 * cfg.target_kl else lr
    for gr in opt.param_groups:
        gr["lr"] = lr
    return kl

def plain_config(d):
    """Config values as plain lists / numbers (what torch.load(weights_only=True) reads back)."""
    if isinstance(d, dict):
        return {k: plain_config(v) for k, v in d.items()}
    if isinstance(d, (list, tuple)):
        return [plain_config(x) for x in d]
    return d


def plot_curve(curve: list[dict], path: str) -> None:
    """Learning curve: reward per step, completion, mean assist and the cap against samples."""
    if not curve:
        return
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from motion_graph.atomic import atomic_write
    x = np.array([r["samples"] for r in curve]) / 1e6
    fig, ax = plt.subplots(1, 4, figsize=(16, 3.4))
    for a, key, title in zip(ax, ("reward_per_step", "completion", "assist_mg", "cap"),
                             ("reward per step", "episodes completed (window)", "mean |F| / mg", "assist cap (mg)")):
        a.plot(x, [r[key] for r in curve], lw=1)
        a.set_title(title)
        a.set_xlabel("samples (M)")
        a.grid(alpha=0.3)
    fig.suptitle("assisted tracker training (assisted physics: the cap is the bound of the residual wrench)")
    fig.tight_layout()
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=90))
    plt.close(fig)
