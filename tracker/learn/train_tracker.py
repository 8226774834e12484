"""Training of the learned tracking policy: PPO on random walks through the action graph.

    igraph-fight tracker train --library LIB --minutes M --out CKPT [--resume CKPT] [--device auto]

Read top to bottom:
1. ``TrainConfig``: every knob, one dataclass (stored in the checkpoint).
2. ``Worker``: one process per core. It owns ``envs_per_worker`` TrackingEnvs (one fighter each)
   and a pool of references built from random walks of ``walk_actions`` actions (refreshed as it
   goes). Episodes start at a random frame of a random walk (reference-state initialisation, with
   joint-velocity noise), end at a fall (tracker.body.fall) or when the joint error passes
   ``et_drift_m`` (early termination), and are cut at ``max_episode_s`` or the walk's end (the
   value is bootstrapped there). Optional pushes: a horizontal force on the torso for a few steps.
   The reward is the environment's DeepMimic-style imitation reward (pose, velocity, end
   effectors, root) blended with a centre-of-mass term.
3. ``collect``: workers step their environments with the current policy (residual PD targets on
   the reference, Gaussian exploration) for ``horizon`` steps and send the transitions back.
4. ``ppo_update``: GAE advantages, clipped-ratio policy loss, value regression, a few epochs of
   minibatches (on the GPU when ``--device`` finds one; the CPU path is the product). Fine-tuning
   a distilled policy (``--resume`` a search run with ``--set algo=ppo``): ``critic_warmup``
   updates fit the critic alone first, and ``--set lr_actor=3e-6`` starts the actor's step small.
5. ``train``: the loop; logs a learning curve (reward per step, fall rate / mean time between
   falls under RSI, episode length), writes a resumable checkpoint every ``ckpt_every_min``
   minutes and at the end, and a PNG of the curve next to it.

The budget (samples, CPU seconds of all processes, wall seconds) accumulates across resumed runs.
"""
from __future__ import annotations

import math
import multiprocessing as mp
import os
import sys
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import torch

from igraph_fight.learn.ppo import clipped_policy_loss, gae, normalise

from tracker.learn.overrides import parse_config_overrides
from tracker.learn.search_labels import LabelBuffer, distill, labels_path, search_labels
from tracker.track.policy_net import (Actor, Critic, RunningNorm, load_checkpoint, policy_observation,
                                      save_policy_checkpoint)
from tracker.track.tracking_reward import RewardRef, tracking_reward


# ----------------------------------------------------------------------------------------------
# 1. configuration
@dataclass
class TrainConfig:
    """All knobs of a training run (see the module doc)."""

    seed: int = 0
    algo: str = "ppo"                 # "ppo"; "search": policy-guided search + distillation; "teacher":
                                      # distillation of the worker's teacher_labels (a Worker subclass has one)
    # data: random walks through the action graph
    walk_actions: int = 10            # actions per training walk
    walks_per_worker: int = 24        # reference pool per worker
    refresh_walks: int = 1            # pool entries replaced per iteration and worker
    mirror: bool = False              # (reserved) mirrored walks
    # episodes
    max_episode_s: float = 10.0
    et_drift_m: float = 1.0           # early termination: pelvis this far (horizontally) from the reference
    et_mpjpe_m: float = 0.0           # ... or global joint error above this (0: off; 0.4 measured harmful)
    init_noise: float = 0.1           # RSI joint-velocity noise (rad/s)
    push_prob: float = 0.0            # per control step, chance to start a push
    push_force_n: float = 120.0       # horizontal force on the torso during a push
    push_steps: int = 3               # push duration in control steps
    # reward (tracking_reward): weights of pose, joint velocity, end effectors relative to the root
    # (facing frame), root (height, tilt, heading, drift), centre-of-mass velocity
    reward_weights: tuple[float, ...] = (0.5, 0.05, 0.15, 0.15, 0.15)
    reward: str = "tracking"          # "residual": exp(-20 mean(residual^2)), a sanity objective with a
                                      # known optimum (no correction) that the unit test climbs quickly
    # PD the residuals act through, and the physics
    kp_scale: float = 1.0
    kd_ratio: float = 0.2
    torque_scale: float = 1.0
    velocity_targets: bool = False
    vf_gains: tuple[float, ...] = ()  # virtual-force balance layer under the policy (tracker.track.vforce.BalanceGains:
                                      # com_kp, com_kd, root_kp, root_kd, torque_clip); () = off
    arm_velocity_targets: bool = False  # the arm actuators damp towards the reference velocity (tracker.track.env)
    physics_hz: float = 240.0
    # policy
    action_space: str = "joints"      # "joints": residual per actuator (others: a Worker subclass's ACTION_SPACES)
    balance_obs: bool = True          # add tracker.track.policy_net.balance_features to the observation
    obs_future: tuple[int, ...] = (1, 2, 4)     # control steps ahead at which the reference is observed;
                                                # --resume with more horizons widens the policy (tracker.learn.widen)
    hidden: tuple[int, ...] = (128, 128)        # actor (small: the gradient noise of a wide net swamps the signal)
    critic_hidden: tuple[int, ...] = (256, 256)
    init_log_std: float = -3.0        # exp(-3) = 0.05 rad exploration (0.135 measured worse at the start)
    min_log_std: float = -3.5
    action_clip: float = 1.0
    # PPO
    n_workers: int = 2
    envs_per_worker: int = 16
    horizon: int = 64                 # steps per env per iteration
    gamma: float = 0.95
    lam: float = 0.95
    lr_actor: float = 1e-3            # initial; then adapted to target_kl
    lr_critic: float = 1e-3
    epochs: int = 5
    minibatch: int = 512
    clip: float = 0.2
    target_kl: float = 0.01           # adaptive actor learning rate: per-update KL kept near this
    lr_min: float = 1e-6
    lr_max: float = 1e-3
    max_grad_norm: float = 1.0        # critic
    max_grad_norm_actor: float = 1e3  # SGD actor: the step size comes from the adaptive lr, not clipping
    critic_warmup: int = 0            # PPO updates of each run that fit the critic only (the actor is
                                      # kept): for fine-tuning a distilled policy whose critic never trained
    # imitation of a teacher (algo "teacher": Worker.teacher_labels(teacher_gains, horizon))
    teacher_gains: tuple[float, ...] = ()
    teacher_noise: float = 0.05       # DART noise on the executed teacher action (rad)
    # policy-guided search + distillation (tracker.learn.search_labels)
    candidates: int = 8               # offsets tried per segment (the first: none)
    segment: int = 3                  # control steps an offset is held (0.1 s)
    lookahead: int = 18               # policy steps after the segment that score it (0.6 s)
    search_sigma: float = 0.05        # offset std (rad), arms and head
    search_sigma_legs: float = 0.12   # offset std (rad), legs and trunk
    search_gamma: float = 0.97
    label_floor: float = 0.02         # label weight = floor + spread of the candidates' returns
    mppi_temp: float = 0.5            # temperature of the offset weights, in units of the returns' std
    follow_policy: float = 0.0        # chance per segment to go on from the plain policy's state (DAgger)
    search_segments: int = 40         # segments per worker per iteration
    replay_labels: int = 150_000
    distill_steps: int = 150          # minibatches per iteration
    distill_minibatch: int = 512
    distill_lr: float = 3e-4
    # bookkeeping
    ckpt_every_min: float = 5.0
    eval_every_min: float = 10.0      # validation walks (deterministic policy, no noise), 0 = never
    eval_walks: int = 20
    eval_actions: int = 20
    eval_seed: int = 100              # disjoint from the reported evaluation's seed 0

    @classmethod
    def from_dict(cls, d: dict) -> "TrainConfig":
        names = {f.name for f in fields(cls)}
        kw = {k: (tuple(v) if isinstance(v, list) else v) for k, v in d.items() if k in names}
        return cls(**kw)


# ----------------------------------------------------------------------------------------------
# 2. the worker: environments, references, episodes
class Worker:
    """Runs ``envs_per_worker`` environments in this process (see the module doc).

    The policy acts in ``TrainConfig.action_space`` "joints" (one residual per actuator). A subclass
    may add action spaces (``ACTION_SPACES``, ``action_dim``, ``to_residual``) and a teacher whose
    labels ``algo="teacher"`` distils (``teacher_labels``); ``train(worker_cls=...)`` runs it."""

    ACTION_SPACES: tuple[str, ...] = ("joints",)

    def __init__(self, cfg: TrainConfig, library: str | None, wid: int, seed: int) -> None:
        from tracker.track.env import EnvConfig, TrackingEnv
        from tracker.track.evaluation import make_setup
        from tracker.body.humanoid import ModelOptions
        from tracker.track.pd import PDController
        from tracker.track.walks import walk_source

        if cfg.action_space not in self.ACTION_SPACES:
            raise ValueError(f"action_space {cfg.action_space!r}: {type(self).__name__} trains in "
                             f"{', '.join(self.ACTION_SPACES)}")
        torch.set_num_threads(1)
        # the exploration noise (torch.randn_like in collect) comes from torch's global generator:
        # seed it here, or a forked worker would inherit whatever state its parent process had
        torch.manual_seed(int(np.random.SeedSequence([seed, wid]).generate_state(1)[0]))
        self.cfg = cfg
        self.rng = np.random.default_rng([seed, wid])
        self.src = walk_source(library)
        env_cfg = EnvConfig(residual_actions=True, init_noise=cfg.init_noise, obs_future=tuple(cfg.obs_future))
        self.setup = make_setup(self.src, ModelOptions(physics_hz=cfg.physics_hz), env_cfg)
        self.scene = self.setup.scene
        self.envs = [TrackingEnv(self.scene, env_cfg) for _ in range(cfg.envs_per_worker)]
        self.pd = PDController(cfg.kp_scale, cfg.kd_ratio, cfg.torque_scale, cfg.velocity_targets,
                               balance=tuple(cfg.vf_gains) or None, arm_velocity_targets=cfg.arm_velocity_targets)
        self.pd_plain = PDController(cfg.kp_scale, cfg.kd_ratio, cfg.torque_scale, cfg.velocity_targets)
        f = self.scene.fighters[0]
        self.pelvis = f.pelvis_body
        torso = [f.body_ids[i] for i, j in enumerate(f.body_joints) if j == f.spec.parts.get("chest", -1)]
        self.push_body = int(torso[0]) if torso else self.pelvis
        self.pool = [self._new_ref() for _ in range(cfg.walks_per_worker)]
        self.max_steps = int(round(cfg.max_episode_s * env_cfg.control_hz))
        self.actor: Actor | None = None
        self.act_dim = self.action_dim()
        self.obs = np.stack([self._reset(i) for i in range(len(self.envs))])
        self.ep_ret = np.zeros(len(self.envs))
        self.ep_len = np.zeros(len(self.envs), int)
        self.push_left = np.zeros(len(self.envs), int)
        self.pd_eval: dict[int, float] = {}      # validation walk -> PD-only time tracked (s)

    def _new_ref(self):
        from tracker.track.evaluation import walk_reference
        _, ref = walk_reference(self.setup, self.src.random_walk(self.cfg.walk_actions, self.rng))
        return ref, RewardRef.build(self.envs[0] if hasattr(self, "envs") else None, self.scene, ref)

    def _reset(self, i: int) -> np.ndarray:
        env = self.envs[i]
        ref, com = self.pool[int(self.rng.integers(len(self.pool)))]
        start = int(self.rng.integers(0, max(1, ref.n_frames - 10)))
        obs = env.reset(ref, start, self.rng)
        self.pd.reset(env)
        env._reward_ref = com
        return self.policy_obs(env, obs)

    def action_dim(self) -> int:
        """Numbers per policy action: one residual per actuator."""
        return self.envs[0].n_act

    def to_residual(self, env, a: np.ndarray) -> np.ndarray:
        """The env action (residual PD targets) for a policy action (clipped)."""
        return np.clip(a, -self.cfg.action_clip, self.cfg.action_clip).astype(np.float64)

    def teacher_labels(self, *args) -> dict:
        """Labels from a teacher controller (``algo="teacher"``): this worker has none."""
        raise ValueError(f"algo='teacher' needs a worker with a teacher; {type(self).__name__} has none")

    def policy_obs(self, env, obs: np.ndarray) -> np.ndarray:
        """The policy's input: the env observation (+ balance features, TrainConfig.balance_obs)."""
        return policy_observation(env, obs)[0] if self.cfg.balance_obs else obs

    def reward(self, env, r_env: float | None = None) -> float:
        """The training reward (tracking_reward); ``r_env`` (the env's own reward) is not used."""
        if self.cfg.reward == "residual":
            c = env._cache[0]
            k = min(env.t - 1 + env.config.target_lead, env.t_end)
            res = env.data.ctrl[c.act] - env.refs[0].ctrl[k]
            return math.exp(-20.0 * float(np.mean(res * res)))
        return tracking_reward(env, env._reward_ref, self.cfg.reward_weights)

    def lost(self, env, info) -> bool:
        """Early termination other than a fall: drifted too far, or (optional) too large a joint error."""
        c = self.cfg
        dxy = env.data.qpos[:2] - env.refs[0].qpos[env.t, :2]
        return bool((c.et_drift_m > 0 and float(dxy @ dxy) > c.et_drift_m ** 2)
                    or (c.et_mpjpe_m > 0 and info.mpjpe_m[0] > c.et_mpjpe_m))

    def collect(self, actor_state: dict, norm_state: dict, horizon: int) -> dict:
        """Step every env ``horizon`` times with the policy; return the transitions (raw obs)."""
        if self.actor is None:
            self.actor = Actor(self.obs.shape[1], self.act_dim, self.cfg.hidden, self.cfg.init_log_std)
        self.actor.load_state_dict(actor_state)
        norm = RunningNorm(self.obs.shape[1])
        norm.load(norm_state)
        E = len(self.envs)
        D, A = self.obs.shape[1], self.act_dim
        out = {k: np.zeros((E, horizon) + s, dtype=np.float32) for k, s in
               (("obs", (D,)), ("act", (A,)), ("logp", ()), ("rew", ()), ("term", ()), ("trunc", ()))}
        trunc_obs = np.zeros((E, horizon, D), dtype=np.float32)   # the obs a truncated episode ended in
        episodes = []
        t0 = time.process_time()
        sim_steps = 0
        for t in range(horizon):
            with torch.no_grad():
                x = torch.as_tensor(norm(self.obs), dtype=torch.float32)
                mu, log_std = self.actor(x)
                std = log_std.exp()
                a = mu + std * torch.randn_like(mu)
                logp = (-0.5 * ((a - mu) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
            a = a.numpy()
            out["obs"][:, t] = self.obs
            out["act"][:, t] = a
            out["logp"][:, t] = logp.numpy()
            for i, env in enumerate(self.envs):
                self._push(i, env)
                o, r_env, done, info = env.step(self.to_residual(env, a[i]))
                o = self.policy_obs(env, o)
                r = self.reward(env, r_env)
                sim_steps += 1
                self.ep_ret[i] += r
                self.ep_len[i] += 1
                fell = info.fall[0] is not None
                lost = self.lost(env, info)
                term = fell or lost
                trunc = (not term) and (info.end or self.ep_len[i] >= self.max_steps)
                out["rew"][i, t] = r
                out["term"][i, t] = float(term)
                out["trunc"][i, t] = float(trunc)
                if term or trunc:
                    trunc_obs[i, t] = o
                    episodes.append((int(self.ep_len[i]), float(self.ep_ret[i]),
                                     "fall" if fell else ("lost" if lost else "cut")))
                    self.ep_ret[i] = 0.0
                    self.ep_len[i] = 0
                    self.push_left[i] = 0
                    o = self._reset(i)
                self.obs[i] = o
        # replace a few references of the pool (new random walks)
        for _ in range(self.cfg.refresh_walks):
            self.pool[int(self.rng.integers(len(self.pool)))] = self._new_ref()
        out["trunc_obs"] = trunc_obs
        out["last_obs"] = self.obs.astype(np.float32).copy()
        out["episodes"] = episodes
        out["cpu_s"] = time.process_time() - t0
        out["sim_steps"] = sim_steps
        return out

    def evaluate(self, actor_state: dict, norm_state: dict, walk_ids: list[int]) -> list[tuple]:
        """Run validation walks (tracker.track.evaluation.run_walk) with the deterministic policy:
        [(walk index, time tracked s, fell, mpjpe m, PD-only time tracked s)]; the PD-only run of a
        walk is done once per worker and kept."""
        from tracker.track.evaluation import draw_walks, run_walk
        from tracker.track.policy_net import LearnedController
        ctrl = LearnedController({"policy": actor_state, **norm_state, "config": asdict(self.cfg)})
        walks = draw_walks(self.src, self.cfg.eval_walks, self.cfg.eval_actions, self.cfg.eval_seed)
        out = []
        for i in walk_ids:
            if i not in self.pd_eval:
                self.pd_eval[i] = run_walk(self.setup, self.pd_plain, walks[i]).time_s
            r = run_walk(self.setup, ctrl, walks[i])
            out.append((i, r.time_s, r.fell, r.mpjpe_m, self.pd_eval[i]))
        return out

    def _push(self, i: int, env) -> None:
        c = self.cfg
        if c.push_prob <= 0:
            return
        d = env.data
        if self.push_left[i] > 0:
            self.push_left[i] -= 1
            if self.push_left[i] == 0:
                d.xfrc_applied[self.push_body, :3] = 0.0
        elif self.rng.random() < c.push_prob:
            ang = self.rng.uniform(0, 2 * np.pi)
            mag = c.push_force_n * self.rng.uniform(0.5, 1.0)
            d.xfrc_applied[self.push_body, :3] = (mag * np.cos(ang), mag * np.sin(ang), 0.0)
            self.push_left[i] = c.push_steps


def rollout_reward(ckpt: str, library: str | None, cfg: TrainConfig, run: int = 1, starts: int = 4,
                   horizon: int = 45) -> float:
    """The training objective of a checkpoint, measured without noise: the deterministic policy on
    the reference pool of run ``run`` (the walks that run trained on), ``starts`` evenly spaced
    start frames per walk, ``horizon`` steps; reward per step, 0 after a termination."""
    from tracker.track.policy_net import load_policy
    ctrl = load_policy(ckpt)
    w = Worker(TrainConfig.from_dict({**asdict(cfg), "init_noise": 0.0, "push_prob": 0.0}), library, 0,
               cfg.seed * 1000 + run)
    env = w.envs[0]
    total, n = 0.0, 0
    for ref, com in w.pool:
        for s in np.linspace(0, ref.n_frames - 2, starts + 1)[:-1].astype(int):
            obs = env.reset(ref, int(s))
            ctrl.reset(env)
            env._reward_ref = com
            for _ in range(horizon):
                obs, r_env, done, info = env.step(ctrl.act(env, obs))
                if info.fall[0] is not None or w.lost(env, info):
                    break
                total += w.reward(env, r_env)
                if done:
                    break
            n += horizon
    return total / n


def _worker_loop(conn, cfg_dict: dict, library: str | None, wid: int, seed: int, worker_cls: type = Worker) -> None:
    import signal
    # Ctrl-C reaches the whole process group: only the trainer handles it (it finishes the
    # iteration, writes the checkpoint and closes the workers), a worker killed here would lose it
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        w = worker_cls(TrainConfig.from_dict(cfg_dict), library, wid, seed)
        conn.send(("ready", w.obs.shape[1], w.act_dim, time.process_time()))
        while True:
            msg = conn.recv()
            if msg[0] == "collect":
                conn.send(("data", w.collect(*msg[1:]), time.process_time()))
            elif msg[0] == "teacher":
                conn.send(("teacher", w.teacher_labels(*msg[1:]), time.process_time()))
            elif msg[0] == "search":
                conn.send(("search", search_labels(w, *msg[1:]), time.process_time()))
            elif msg[0] == "eval":
                conn.send(("eval", w.evaluate(*msg[1:]), time.process_time()))
            elif msg[0] == "close":
                break
    except Exception as e:  # report, do not hang the trainer
        import traceback
        conn.send(("error", f"{e}\n{traceback.format_exc()}"))


# ----------------------------------------------------------------------------------------------
# 3-4. collection and the PPO update
class Learner:
    def __init__(self, cfg: TrainConfig, obs_dim: int, act_dim: int, device: str) -> None:
        torch.manual_seed(cfg.seed)
        self.cfg = cfg
        self.device = torch.device(device)
        self.actor = Actor(obs_dim, act_dim, cfg.hidden, cfg.init_log_std).to(self.device)
        self.critic = Critic(obs_dim, cfg.critic_hidden).to(self.device)
        # Actor: SGD with momentum (a step proportional to the gradient: consistent directions add
        # up, noisy ones cancel; Adam's per-parameter normalised steps moved the whole 512-wide net at
        # random, KL 3.6 after two steps at lr 1e-4, see docs/tracker.md). Critic: Adam.
        self.actor_opt = torch.optim.SGD(self.actor.parameters(), lr=cfg.lr_actor, momentum=0.9)
        self.opt = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr_critic)
        self.norm = RunningNorm(obs_dim)
        self.n_updates = 0
        self.lr_actor = cfg.lr_actor
        self.distill_opt = torch.optim.Adam(self.actor.mu.parameters(), lr=cfg.distill_lr)

    def cpu_actor_state(self) -> dict:
        return {k: v.detach().cpu() for k, v in self.actor.state_dict().items()}

    def values(self, obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            x = torch.as_tensor(self.norm(obs.reshape(-1, obs.shape[-1])), dtype=torch.float32, device=self.device)
            return self.critic(x).cpu().numpy().reshape(obs.shape[:-1])

    def update(self, batch: dict) -> dict:
        """GAE + clipped PPO on one iteration's transitions (E envs x T steps)."""
        c = self.cfg
        obs, act, logp_old = batch["obs"], batch["act"], batch["logp"]
        rew, term, trunc = batch["rew"], batch["term"], batch["trunc"]
        E, T = rew.shape
        v = self.values(obs)
        v_last = self.values(batch["last_obs"])
        v_trunc = self.values(batch["trunc_obs"]) * trunc          # bootstrap cut episodes
        # next value: 0 after a termination, V(final obs) after a cut, else V(s_t+1)
        v_next = np.concatenate([v[:, 1:], v_last[:, None]], axis=1)
        nv = np.where(trunc > 0, v_trunc, v_next) * (1.0 - term)
        ended = np.maximum(term, trunc)
        adv_t, ret_t = gae(rew.T, v.T, nv.T, (1.0 - ended).T, c.gamma, c.lam)     # time-major
        adv, ret = adv_t.T, ret_t.T
        n = E * T
        flat = lambda a: torch.as_tensor(a.reshape(n, *a.shape[2:]), dtype=torch.float32, device=self.device)  # noqa: E731
        X = flat(self.norm(obs).astype(np.float32))
        Aa, LP, ADV, RET = flat(act), flat(logp_old), flat(adv), flat(ret)
        ADV = normalise(ADV)
        stats = {"pi_loss": 0.0, "v_loss": 0.0, "kl": 0.0, "epochs": 0}
        self.n_updates += 1
        warmup = self.n_updates <= c.critic_warmup
        self.actor_opt.param_groups[0]["lr"] = self.lr_actor
        g = torch.Generator().manual_seed(int(c.seed * 100003 + self.n_updates))
        for ep in range(c.epochs):
            perm = torch.randperm(n, generator=g).to(self.device)
            for s in range(0, n, c.minibatch):
                idx = perm[s:s + c.minibatch]
                mu, log_std = self.actor(X[idx])
                std = log_std.exp()
                lp = (-0.5 * ((Aa[idx] - mu) / std) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
                ratio = torch.exp(lp - LP[idx])
                pi_loss = clipped_policy_loss(ratio, ADV[idx], c.clip)
                v_loss = 0.5 * ((self.critic(X[idx]) - RET[idx]) ** 2).mean()
                self.opt.zero_grad()
                self.actor_opt.zero_grad()
                (pi_loss + v_loss).backward()
                torch.nn.utils.clip_grad_norm_(self.actor.parameters(), c.max_grad_norm_actor)
                torch.nn.utils.clip_grad_norm_(self.critic.parameters(), c.max_grad_norm)
                self.opt.step()
                if not warmup:
                    self.actor_opt.step()
                with torch.no_grad():
                    self.actor.log_std.clamp_(min=c.min_log_std)
                stats["pi_loss"] = float(pi_loss.detach())
                stats["v_loss"] = float(v_loss.detach())
            with torch.no_grad():                     # KL(old || new) on the whole batch (k3 estimator)
                mu, log_std = self.actor(X)
                lp = (-0.5 * ((Aa - mu) / log_std.exp()) ** 2 - log_std - 0.5 * math.log(2 * math.pi)).sum(-1)
                logr = lp - LP
                stats["kl"] = float((logr.exp() - 1.0 - logr).mean())
            stats["epochs"] = ep + 1
            if stats["kl"] > 2.0 * c.target_kl:
                break
        # adaptive step size: Adam's per-parameter steps do not shrink with a noisy gradient, so the
        # KL of each update sets the actor's learning rate (measured: a fixed 1e-4..1e-3 moved the
        # policy at random, KL 0.1..7 per update)
        if not warmup and stats["kl"] > 2.0 * c.target_kl:
            self.lr_actor = max(c.lr_min, self.lr_actor / 1.5)
        elif not warmup and stats["kl"] < 0.5 * c.target_kl:
            self.lr_actor = min(c.lr_max, self.lr_actor * 1.5)
        stats["lr_actor"] = self.lr_actor
        self.norm.update(obs.reshape(-1, obs.shape[-1]))   # after the update: the batch used the old stats
        stats["std"] = float(self.actor.log_std.detach().exp().mean())
        return stats


# ----------------------------------------------------------------------------------------------
# 5. the loop, checkpoints, learning curve
def ppo_iteration(pipes, learner: Learner, cfg: TrainConfig) -> tuple[dict, list]:
    """Collect ``horizon`` steps per env in every worker, then one PPO update (on a fresh run the
    first batch only initialises the observation normaliser: no update on raw observations)."""
    state = learner.cpu_actor_state()
    for c in pipes:
        c.send(("collect", state, learner.norm.state(), cfg.horizon))
    msgs = [_recv(c) for c in pipes]
    parts = [m[1] for m in msgs]
    batch = {k: np.concatenate([p[k] for p in parts]) for k in ("obs", "act", "logp", "rew", "term", "trunc",
                                                               "trunc_obs", "last_obs")}
    if learner.norm.count < 1.0:
        learner.norm.update(batch["obs"].reshape(-1, batch["obs"].shape[-1]))
        stats = {"kl": 0.0, "std": float(learner.actor.log_std.detach().exp().mean()), "lr_actor": learner.lr_actor,
                 "warmup": 1}
    else:
        stats = learner.update(batch)
    episodes = [e for p in parts for e in p["episodes"]]
    steps = int(sum(p["sim_steps"] for p in parts))
    falls = int(batch["term"].sum())
    sim_s = steps / 30.0
    return {"steps": steps, "reward": float(batch["rew"].mean()), "falls": falls,
            "mtbf_s": sim_s / falls if falls else 2 * sim_s,
            "ep_len_s": float(np.mean([e[0] for e in episodes]) / 30.0) if episodes else float("nan"),
            "lost": sum(e[2] == "lost" for e in episodes), **stats}, msgs


def search_iteration(pipes, learner: Learner, buf: LabelBuffer, cfg: TrainConfig,
                     teacher: bool = False) -> tuple[dict, list]:
    """Labels from every worker (policy-guided search, or the worker's teacher), then
    distillation of the actor on the label buffer (tracker.learn.search_labels)."""
    state = learner.cpu_actor_state()
    for c in pipes:
        if teacher:
            c.send(("teacher", np.asarray(cfg.teacher_gains, float), cfg.horizon))
        else:
            c.send(("search", state, learner.norm.state(), cfg.search_segments))
    msgs = [_recv(c) for c in pipes]
    parts = [m[1] for m in msgs]
    obs = np.concatenate([p["obs"] for p in parts])
    buf.add(obs, np.concatenate([p["act"] for p in parts]), np.concatenate([p["w"] for p in parts]))
    learner.norm.update(obs)
    stats = distill(learner, buf, cfg.distill_steps, cfg.distill_minibatch, cfg.seed * 7919 + len(buf))
    episodes = [e for p in parts for e in p["episodes"]]
    falls = sum(e[2] == "fall" for e in episodes)
    labelled_s = len(obs) / 30.0
    return {"steps": int(sum(p["sim_steps"] for p in parts)), "reward": float("nan"), "falls": falls,
            "mtbf_s": labelled_s / falls if falls else 2 * labelled_s,
            "ep_len_s": float(np.mean([e[0] for e in episodes]) / 30.0) if episodes else float("nan"),
            "gain": float(np.mean([p["gain"] for p in parts])), **stats}, msgs


def validate(pipes, learner: Learner, cfg: TrainConfig) -> tuple[dict, list[float]]:
    """Validation walks split over the workers (keeps the process count at n_workers); returns the
    metrics and the workers' CPU seconds."""
    state, norm = learner.cpu_actor_state(), learner.norm.state()
    for k, c in enumerate(pipes):
        c.send(("eval", state, norm, list(range(k, cfg.eval_walks, len(pipes)))))
    msgs = [_recv(c) for c in pipes]
    res = [r for m in msgs for r in m[1]]
    return {"eval_ttf_s": float(np.mean([r[1] for r in res])), "eval_pd_ttf_s": float(np.mean([r[4] for r in res])),
            "eval_completion": float(np.mean([not r[2] for r in res])),
            "eval_mpjpe_m": float(np.mean([r[3] for r in res]))}, [m[2] for m in msgs]


def training_library_info(source) -> dict:
    """What a policy was trained on (the checkpoint's ``library``): the source's description and, for an
    action library, its action count, frames, fps, a content hash and its source files."""
    import hashlib
    lib = getattr(source, "library", None)
    out = {"describe": source.describe() if hasattr(source, "describe") else type(source).__name__}
    if lib is not None:
        h = hashlib.sha256()
        for a in (lib.rotations, lib.root_positions, lib.frame_offsets, lib.next_offsets, lib.next_ids):
            h.update(np.ascontiguousarray(a).tobytes())
        out.update(n_actions=int(lib.n_actions), n_frames=int(len(lib.rotations)), fps=float(lib.fps),
                   sha256=h.hexdigest()[:16], sources=sorted({os.path.basename(str(s)) for s in lib.sources}))
    return out


def _device(name: str) -> str:
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    return name


def save_checkpoint(path: str | os.PathLike, learner: Learner, cfg: TrainConfig, library: dict, budget: dict,
                    history: list, slim: bool = False) -> None:
    """Write the checkpoint atomically (slim: the policy only, no critic / optimizer)."""
    ck = {"policy": learner.cpu_actor_state(), **learner.norm.state(), "config": asdict(cfg),
          "library": library, "budget": {k: v for k, v in budget.items() if not k.startswith("_")}, "history": list(history)}
    ck["lr_actor"] = learner.lr_actor
    if not slim:
        ck["value"] = {k: v.detach().cpu() for k, v in learner.critic.state_dict().items()}
        ck["optimizer"] = learner.opt.state_dict()
        ck["actor_optimizer"] = learner.actor_opt.state_dict()
    save_policy_checkpoint(path, ck)


def plot_curve(history: list, path: str | os.PathLike, title: str = "") -> None:
    """Learning curve PNG: reward per step and mean time between falls vs samples."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    if not history:
        return
    keys = sorted({k for r in history for k, v in r.items() if isinstance(v, (int, float))})
    h = {k: np.array([r.get(k, np.nan) for r in history], float) for k in keys}
    x = h["samples"] / 1e6
    fig, ax = plt.subplots(1, 2, figsize=(10, 3.6))
    # PPO: the reward per step; search / teacher runs have none: the search's gain over the plain policy
    search = not np.isfinite(h["reward"]).any() and "gain" in h
    left, left_label = (h["gain"], "search gain over the plain policy (return)") if search else (h["reward"], "reward per step")
    ax[0].plot(x, left, lw=0.6, alpha=0.5)
    ax[0].plot(x, _smooth(left), lw=1.5)
    ax[0].set_xlabel("samples (M)")
    ax[0].set_ylabel(left_label)
    ax[0].grid(alpha=0.3)
    ax[1].plot(x, h["mtbf_s"], lw=0.6, alpha=0.5, label="search episodes" if search else "training episodes (RSI)")
    ax[1].plot(x, _smooth(h["mtbf_s"]), lw=1.5)
    if "eval_ttf_s" in h and np.isfinite(h["eval_ttf_s"]).any():
        ok = np.isfinite(h["eval_ttf_s"])
        ax[1].plot(x[ok], h["eval_ttf_s"][ok], "o-", label="validation walks: mean time to fall")
        if "eval_pd_ttf_s" in h and np.isfinite(h["eval_pd_ttf_s"]).any():
            pd_ok = np.isfinite(h["eval_pd_ttf_s"])
            ax[1].plot(x[pd_ok], h["eval_pd_ttf_s"][pd_ok], "k--", lw=1, label="the same walks, PD only")
    ax[1].set_xlabel("samples (M)")
    ax[1].set_ylabel("mean time between falls (s)")
    ax[1].set_yscale("log")
    from matplotlib.ticker import FormatStrFormatter
    ax[1].yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax[1].yaxis.set_minor_formatter(FormatStrFormatter("%g"))
    ax[1].grid(alpha=0.3)
    ax[1].legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    fig.savefig(str(path), dpi=110)
    plt.close(fig)


def _smooth(y: np.ndarray, k: int = 20) -> np.ndarray:
    out = np.empty_like(y)
    for i in range(len(y)):
        s = y[max(0, i - k + 1):i + 1]
        s = s[np.isfinite(s)]
        out[i] = s.mean() if len(s) else np.nan
    return out


def train(cfg: TrainConfig, library: str | None, minutes: float, out: str, resume: str | None = None,
          device: str = "auto", progress: bool = True, log=print, max_iterations: int | None = None,
          overrides: dict | None = None, worker_cls: type = Worker) -> dict:
    """Train (or continue) a policy for ``minutes`` of wall clock; returns the final checkpoint dict's budget
    and history. ``max_iterations`` caps the iterations (tests). On resume the checkpoint's config is
    kept except the process layout and ``overrides`` (e.g. a later, lower learning rate).
    ``worker_cls``: the Worker (sub)class the worker processes run (Worker's doc)."""
    # One thread: on a shared 2-core machine torch's thread pool oversubscribes the cores
    # (measured: 830 ms vs 55 ms per minibatch with 2 threads vs 1 while the workers run).
    torch.set_num_threads(1)
    ck, widen_labels_of = None, None
    if resume:
        ck = load_checkpoint(resume)
        if "critic_hidden" not in ck["config"] and "value" in ck:
            # written before the critic's size was a config field: read it off the stored weights
            ck["config"]["critic_hidden"] = tuple(int(w.shape[0]) for k, w in ck["value"].items()
                                                  if k.endswith(".weight"))[:-1]
        cfg = TrainConfig.from_dict({**ck["config"], "n_workers": cfg.n_workers, "envs_per_worker": cfg.envs_per_worker,
                                     "ckpt_every_min": cfg.ckpt_every_min, **(overrides or {})})
        log(f"resuming {resume}: {ck['budget']['samples']} samples so far; overrides {overrides or {}}")
        old_future = tuple(ck["config"].get("obs_future", (1, 2, 4)))
        if old_future != tuple(cfg.obs_future):
            from tracker.learn.widen import widen_checkpoint, widen_labels
            ck, src, new = widen_checkpoint(ck, tuple(cfg.obs_future))
            mean = np.asarray(ck["obs_mean"], float)
            widen_labels_of = lambda o: widen_labels(o, src, new, mean)  # noqa: E731 (stored labels, below)
            log(f"observation widened: reference horizons {old_future} -> {tuple(cfg.obs_future)} "
                f"(new inputs start with zero weights; optimiser states restart)")
    budget = dict(ck["budget"]) if ck else {"samples": 0, "cpu_s": 0.0, "wall_s": 0.0, "iterations": 0, "runs": 0}
    history = list(ck["history"]) if ck else []
    budget = {k: v for k, v in budget.items() if not k.startswith("_")}
    budget["runs"] = budget.get("runs", 0) + 1
    wall0 = budget.get("wall_s", 0.0)
    run_seed = cfg.seed * 1000 + budget["runs"]              # new walks and noise on each resumed run
    ctx = mp.get_context("spawn" if sys.platform == "darwin" else "fork")
    pipes, procs = [], []
    for wid in range(cfg.n_workers):
        a, b = ctx.Pipe()
        p = ctx.Process(target=_worker_loop, args=(b, asdict(cfg), library, wid, run_seed, worker_cls), daemon=True)
        p.start()
        pipes.append(a)
        procs.append(p)
    try:
        dims = [_recv(c) for c in pipes]
        obs_dim, act_dim = dims[0][1], dims[0][2]
        worker_cpu = [d[3] for d in dims]                 # CPU seconds of each worker so far
        budget["cpu_s"] += float(sum(worker_cpu))
        learner = Learner(cfg, obs_dim, act_dim, _device(device))
        if ck:
            learner.actor.load_state_dict(ck["policy"])
            if "value" in ck:
                learner.critic.load_state_dict(ck["value"])
            for key, opt in (("optimizer", learner.opt), ("actor_optimizer", learner.actor_opt)):
                if key in ck:
                    try:
                        opt.load_state_dict(ck[key])
                    except (ValueError, KeyError) as e:  # an older optimizer layout: start it afresh
                        log(f"{resume}: {key} state not reused ({e}); it restarts")
            learner.opt.param_groups[0]["lr"] = cfg.lr_critic
            learner.lr_actor = float(ck.get("lr_actor", cfg.lr_actor)) if "lr_actor" not in (overrides or {}) \
                else cfg.lr_actor
            learner.norm.load(ck)
        from tracker.track.walks import walk_source
        lib_fp = ck["library"] if ck else training_library_info(walk_source(library))
        t_start = time.time()
        t_ckpt = t_eval = t_start
        main_cpu0 = time.process_time()
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=int(minutes * 60), unit="s", desc="train", dynamic_ncols=True)
        buf = LabelBuffer(cfg.replay_labels)
        if resume and cfg.algo in ("search", "teacher"):
            if buf.load(labels_path(resume), obs_dim, act_dim, transform=widen_labels_of):
                log(f"resumed {len(buf)} labels from {labels_path(resume)}")
            else:   # the first iterations distil on a few hundred new labels only
                log(f"warning: no labels at {labels_path(resume)}; the buffer starts empty")
        it = 0
        stop = _StopFlag()
        while (time.time() - t_start < minutes * 60 and (max_iterations is None or it < max_iterations)
               and not stop.set):
            t_c = time.time()
            if cfg.algo == "search":
                row, msgs = search_iteration(pipes, learner, buf, cfg)
            elif cfg.algo == "teacher":
                row, msgs = search_iteration(pipes, learner, buf, cfg, teacher=True)
            else:
                row, msgs = ppo_iteration(pipes, learner, cfg)
            budget["cpu_s"] += float(sum(m[2] - w for m, w in zip(msgs, worker_cpu)))
            worker_cpu = [m[2] for m in msgs]
            budget["samples"] += row["steps"]
            budget["iterations"] += 1
            it += 1
            row = {"iteration": budget["iterations"], "samples": budget["samples"], "algo": cfg.algo,
                   "wall_s": wall0 + time.time() - t_start, "iter_s": time.time() - t_c, **row}
            history.append(row)
            if bar is not None:
                bar.n = min(int(time.time() - t_start), bar.total)
                bar.set_postfix(samples=f"{budget['samples'] / 1e6:.2f}M", rew=f"{row['reward']:.3f}",
                                mtbf=f"{row['mtbf_s']:.1f}s")
                bar.refresh()
            if it % 10 == 0:
                log(f"it {budget['iterations']} ({cfg.algo}) samples {budget['samples']} reward {row['reward']:.3f} "
                    f"mtbf {_smooth(np.array([h['mtbf_s'] for h in history[-10:]]), 10)[-1]:.2f}s "
                    f"ep {row['ep_len_s']:.2f}s wall {row['wall_s']:.0f}s ({row['iter_s']:.1f}s/it) "
                    + " ".join(f"{k} {row[k]:.4g}" for k in ("kl", "std", "gain", "distill_loss", "labels") if k in row))
            if cfg.eval_every_min > 0 and (time.time() - t_eval > cfg.eval_every_min * 60 or it == 1):
                val, cpus = validate(pipes, learner, cfg)
                budget["cpu_s"] += float(sum(c - w for c, w in zip(cpus, worker_cpu)))
                worker_cpu = cpus
                row.update(val)
                t_eval = time.time()
                log(f"validation: {cfg.eval_walks} walks x {cfg.eval_actions} actions: mean time to fall "
                    f"{row['eval_ttf_s']:.2f}s (PD only {row['eval_pd_ttf_s']:.2f}s), "
                    f"completed {100 * row['eval_completion']:.0f}%, "
                    f"mpjpe {100 * row['eval_mpjpe_m']:.1f}cm")
            if time.time() - t_ckpt > cfg.ckpt_every_min * 60:
                _account(budget, t_start, main_cpu0)
                save_checkpoint(out, learner, cfg, lib_fp, budget, history)
                buf.save(labels_path(out))
                plot_curve(history, Path(out).with_suffix(".png"), _title(budget))
                t_ckpt = time.time()
        _account(budget, t_start, main_cpu0)
        save_checkpoint(out, learner, cfg, lib_fp, budget, history)
        buf.save(labels_path(out))
        plot_curve(history, Path(out).with_suffix(".png"), _title(budget))
        if bar is not None:
            bar.close()
    finally:
        for c in pipes:
            try:
                c.send(("close",))
            except (BrokenPipeError, OSError):
                pass
        for p in procs:
            p.join(timeout=5)
            if p.is_alive():
                p.terminate()
    return {"budget": budget, "history": history}


class _StopFlag:
    """SIGTERM / SIGINT end the run after the current iteration, with a checkpoint (resumable)."""

    def __init__(self) -> None:
        import signal
        self.set = False
        try:
            for sig in (signal.SIGTERM, signal.SIGINT):
                signal.signal(sig, self._handler)
        except ValueError:          # not the main thread
            pass

    def _handler(self, *_):
        self.set = True


def _account(budget: dict, t_start: float, main_cpu0: float) -> None:
    """Fold the wall / main-process CPU time since the last accounting into the budget (idempotent
    per call: the marks are kept on the dict)."""
    now, cpu = time.time(), time.process_time()
    last_t = budget.pop("_mark_t", t_start)
    last_c = budget.pop("_mark_c", main_cpu0)
    budget["wall_s"] = budget.get("wall_s", 0.0) + now - last_t
    budget["cpu_s"] = budget.get("cpu_s", 0.0) + cpu - last_c
    budget["cpu_hours"] = budget["cpu_s"] / 3600.0
    budget["_mark_t"], budget["_mark_c"] = now, cpu


def _title(b: dict) -> str:
    return (f"{b['samples'] / 1e6:.2f}M samples, {b.get('cpu_hours', 0):.2f} CPU-hours, "
            f"{b.get('wall_s', 0) / 3600:.2f} h wall, {b.get('runs', 1)} run(s)")


def _recv(conn):
    msg = conn.recv()
    if msg[0] == "error":
        raise RuntimeError(f"training worker failed: {msg[1]}")
    return msg


# ----------------------------------------------------------------------------------------------
def parse_overrides(items: list[str] | None) -> dict:
    """``["gamma=0.97", "hidden=256,256"]`` -> typed TrainConfig overrides (ValueError naming a bad one)."""
    return parse_config_overrides(items, TrainConfig)


def main_args(args, worker_cls: type = Worker) -> int:
    """`igraph-fight tracker train` (tracker.cli.add_train_arguments' options)."""
    try:
        over = parse_overrides(getattr(args, "set", None))
    except ValueError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if args.push_prob is not None:
        over["push_prob"] = args.push_prob
    cfg = TrainConfig(**{**asdict(TrainConfig()), "seed": args.seed, "n_workers": args.workers,
                         "envs_per_worker": args.envs, **over})
    res = train(cfg, args.library, args.minutes, args.out, args.resume, args.device, progress=not args.no_progress,
                overrides=over, worker_cls=worker_cls)
    b = res["budget"]
    print(f"wrote {args.out}: {_title(b)}")
    if args.slim:
        ck = load_checkpoint(args.out)
        ck.pop("optimizer", None)
        slim = Path(args.out).with_name(Path(args.out).stem + "-slim.pt")
        save_policy_checkpoint(slim, ck)
        print(f"wrote {slim} (policy, critic, normaliser; no optimizer state: a resume restarts Adam)")
    return 0
