"""The learned tracking policy (PyTorch) and its Controller ("learned").

    ctrl = load_default_policy()                  # the shipped checkpoint (tracker/checkpoints/)
    obs = env.reset(ref); ctrl.reset(env)
    obs, r, done, info = env.step(ctrl.act(env, obs))

- Per fighter: the policy maps one fighter's observation (``TrackingEnv.observe(k)``:
  proprioception in the facing frame + reference targets a few steps ahead) to residual PD
  targets (radians, rotation-vector components) added to the reference targets of the step. A
  two-fighter scene is a batch of two; nothing couples the fighters inside the policy.
- The controller sets the PD gains / torque limits / velocity-target mode the policy was trained
  with (stored in the checkpoint) at reset, and the virtual-force balance layer under the policy
  (tracker/track/vforce.py) when the checkpoint's config has ``vf_gains``. No force is ever applied to
  the root.
- Inference is a numpy forward pass of the MLP (no torch call per step): a few microseconds.

Checkpoint (igraph_fight.checkpoint, format POLICY_FORMAT version POLICY_VERSION: read
weights-only): ``policy`` (state dict), ``obs_mean``/``obs_var`` (normaliser, float64 tensors),
``config`` (tracker.learn.train_tracker.TrainConfig as a dict), ``library`` (fingerprint of the action library
trained on), ``budget`` (samples, CPU seconds, wall seconds), ``history`` (learning curve); a
resumable training checkpoint also has ``value`` and ``optimizer``.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from tracker.body.frames import facing_rotation, ground_yaw, quat_matrix

#: The checkpoint shipped with the repository (trained on the CMU boxing library, 13_17 + 13_18).
DEFAULT_CKPT = Path(__file__).resolve().parent.parent / "checkpoints" / "boxing_cmu13.pt"
#: the policy checkpoint's format and version (igraph_fight.checkpoint; tracker/checkpoints/README.md)
POLICY_FORMAT = "igraph-fight/tracker-policy"
POLICY_VERSION = 2


def mlp(sizes: list[int], act=nn.ELU) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(act())
    return nn.Sequential(*layers)


class Actor(nn.Module):
    """Gaussian policy: mean = MLP(normalised obs) (residual PD targets), state-independent log std."""

    def __init__(self, obs_dim: int, act_dim: int, hidden: tuple[int, ...], init_log_std: float) -> None:
        super().__init__()
        self.mu = mlp([obs_dim, *hidden, act_dim])
        last = self.mu[-1]
        nn.init.uniform_(last.weight, -1e-3, 1e-3)   # start at zero residual: the PD baseline
        nn.init.zeros_(last.bias)
        self.log_std = nn.Parameter(torch.full((act_dim,), float(init_log_std)))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.mu(x), self.log_std.expand(x.shape[0], -1)


class Critic(nn.Module):
    def __init__(self, obs_dim: int, hidden: tuple[int, ...]) -> None:
        super().__init__()
        self.v = mlp([obs_dim, *hidden, 1])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.v(x).squeeze(-1)


class RunningNorm:
    """Running mean / variance of observations (parallel Welford), clipped standardisation."""

    def __init__(self, dim: int, clip: float = 10.0) -> None:
        self.mean = np.zeros(dim)
        self.var = np.ones(dim)
        self.count = 1e-4
        self.clip = clip

    def update(self, x: np.ndarray) -> None:
        x = x.reshape(-1, self.mean.shape[0])
        bm, bv, n = x.mean(0), x.var(0), x.shape[0]
        delta = bm - self.mean
        tot = self.count + n
        self.mean = self.mean + delta * n / tot
        self.var = (self.var * self.count + bv * n + delta ** 2 * self.count * n / tot) / tot
        self.count = tot

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return np.clip((x - self.mean) / np.sqrt(self.var + 1e-8), -self.clip, self.clip)

    def state(self) -> dict:
        return {"obs_mean": self.mean.copy(), "obs_var": self.var.copy(), "obs_count": float(self.count)}

    def load(self, st: dict) -> None:
        self.mean = np.asarray(st["obs_mean"], float).copy()
        self.var = np.asarray(st["obs_var"], float).copy()
        self.count = float(st.get("obs_count", 1.0))


class NumpyMLP:
    """The actor's mean network as numpy matrices (fast single-sample inference, no autograd)."""

    def __init__(self, seq: nn.Sequential) -> None:
        self.layers = [(m.weight.detach().cpu().double().numpy().T.copy(), m.bias.detach().cpu().double().numpy().copy())
                       for m in seq if isinstance(m, nn.Linear)]

    def __call__(self, x: np.ndarray) -> np.ndarray:
        for i, (w, b) in enumerate(self.layers):
            x = x @ w + b
            if i < len(self.layers) - 1:
                x = np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))   # ELU
        return x


def reference_balance(env, k: int, ref) -> np.ndarray:
    """(T, 12) per-frame reference centre of mass (relative to the feet's midpoint), its velocity
    and the feet (ankle bodies, relative to the centre of mass), in the reference's facing frame:
    the reference block of balance_features, cached on ``ref.meta`` (computed once per reference)."""
    key = f"_balance_f{k}"
    if key in ref.meta:
        return ref.meta[key]
    import mujoco

    m = env.model
    f = env.scene.fighters[k]
    c = env._cache[k]
    feet = _feet_bodies(f)
    d = mujoco.MjData(m)
    T = ref.n_frames
    com, fp, yaw = np.zeros((T, 3)), np.zeros((T, 2, 3)), np.zeros(T)
    for t in range(T):
        d.qpos[f.qpos_slice] = ref.qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        com[t] = d.subtree_com[f.pelvis_body]
        fp[t] = d.xpos[feet]
        yaw[t] = ground_yaw(quat_matrix(ref.qpos[t, 3:7]), c.lateral)
    vel = np.gradient(com, 1.0 / ref.fps, axis=0) if T > 1 else np.zeros_like(com)
    out = np.zeros((T, 12))
    for t in range(T):
        Ry = facing_rotation(yaw[t])
        mid = fp[t].mean(0)
        out[t, 0:3] = Ry @ (com[t] - mid)
        out[t, 3:6] = Ry @ vel[t]
        out[t, 6:12] = ((fp[t] - com[t]) @ Ry.T).ravel()
    ref.meta[key] = out
    return out


def _feet_bodies(f) -> np.ndarray:
    sp = f.spec
    return np.array([int(f.body_ids[list(f.body_joints).index(sp.parts[p])]) for p in ("l_ankle", "r_ankle")])


def balance_features(env, k: int = 0) -> np.ndarray:
    """(N_BALANCE,) balance features of fighter k, added to TrackingEnv.observe(k) for the policy:
    centre of mass relative to the feet's midpoint, its velocity, each foot relative to the centre
    of mass (simulation, facing frame), whether each foot touches the floor, the same quantities of
    the reference one step ahead (its facing frame), and the simulation-minus-reference COM offset
    and velocity. Everything of the fighter's own body: per fighter, no other fighter involved."""
    import mujoco

    d = env.data
    c = env._cache[k]
    f = env.scene.fighters[k]
    if not hasattr(c, "_feet"):
        c._feet = _feet_bodies(f)
        geoms_l = np.asarray(f.geom_label["l_foot"], int)
        geoms_r = np.asarray(f.geom_label["r_foot"], int)
        lab = np.zeros(env.model.ngeom, int)
        lab[geoms_l], lab[geoms_r] = 1, 2
        c._foot_lab = lab
    mujoco.mj_comPos(env.model, d)          # subtree COM of the current poses (mj_kinematics ran after the step)
    mujoco.mj_subtreeVel(env.model, d)      # from the last substep's velocities
    R = d.xmat[c.pelvis].reshape(3, 3)
    Ry = facing_rotation(ground_yaw(R, c.lateral))
    com = d.subtree_com[c.pelvis]
    fp = d.xpos[c._feet]
    sim = np.concatenate([Ry @ (com - fp.mean(0)), Ry @ d.subtree_linvel[c.pelvis], ((fp - com) @ Ry.T).ravel()])
    touch = np.zeros(2)
    n = d.ncon
    if n:
        g = d.contact.geom[:n]
        fl = env.scene.floor_geom
        other = np.where(g[:, 0] == fl, g[:, 1], np.where(g[:, 1] == fl, g[:, 0], -1))
        lab = c._foot_lab[other[other >= 0]]
        touch[0], touch[1] = float((lab == 1).any()), float((lab == 2).any())
    ref = env.refs[k]
    rb = reference_balance(env, k, ref)[min(env.t + 1, env.t_end)]
    return np.concatenate([sim, touch, rb, sim[:6] - rb[:6]])


N_BALANCE = 32


def policy_observation(env, obs: np.ndarray | None = None) -> np.ndarray:
    """(n_fighters, obs_dim) policy input: TrackingEnv.observe(k) + balance_features(env, k) per fighter."""
    obs = np.atleast_2d(np.stack([env.observe(k) for k in range(env.n_fighters)]) if obs is None else obs)
    return np.concatenate([obs, np.stack([balance_features(env, k) for k in range(env.n_fighters)])], axis=1)


@dataclass
class PDSettings:
    """The PD the policy's residuals act through (tracker.track.pd.PDController's knobs)."""

    kp_scale: float = 1.0
    kd_ratio: float = 0.2
    torque_scale: float = 1.0
    velocity_targets: bool = False
    vf_gains: tuple = ()              # virtual-force balance layer (tracker.track.vforce); () = off
    arm_velocity_targets: bool = False


class LearnedController:
    """Controller (tracker.track.controllers) running a trained policy; deterministic (the Gaussian mean).

    ``head``: an object whose ``bias(obs)`` ((n_fighters, 6) from the raw policy observations)
    steers the balance layer (VirtualForceBalance.bias) every control step; ``action_map(env, k,
    action, targets)``: the (n_act,) PD-target offsets of fighter k for a policy whose outputs are
    not one residual per actuator (a checkpoint whose config has another ``action_space`` than
    "joints"). The shipped policy needs neither; experiments plug theirs in (research/).

    Attributes:
        action_clip: residuals are clipped to +- this (radians), as in training.
    """

    name = "learned"

    def __init__(self, ckpt: dict, path: str = "", head=None, action_map=None) -> None:
        cfg = ckpt["config"]
        self.ckpt_path = path
        self.config = cfg
        self.library = ckpt.get("library", {})
        self.budget = ckpt.get("budget", {})
        hidden = tuple(cfg["hidden"])
        sd = ckpt["policy"]
        obs_dim = sd["mu.0.weight"].shape[1]
        act_dim = sd["log_std"].shape[0]
        actor = Actor(obs_dim, act_dim, hidden, 0.0)
        actor.load_state_dict(sd)
        self.net = NumpyMLP(actor.mu)
        self.norm = RunningNorm(obs_dim)
        self.norm.load(ckpt)
        self.obs_dim, self.act_dim = obs_dim, act_dim
        self.action_clip = float(cfg.get("action_clip", 1.0))
        self.balance = bool(cfg.get("balance_obs", False))
        self.action_space = cfg.get("action_space", "joints")
        self.obs_future = tuple(cfg.get("obs_future", (1, 2, 4)))   # reference horizons it was trained with
        name = path or "checkpoint"
        if ckpt.get("layer_head") is not None and head is None:
            raise ValueError(f"{name}: a checkpoint with a balance head (layer_head): run it with its head "
                             "(research.layer_head.load_head_policy)")
        if head is not None and not cfg.get("vf_gains"):
            raise ValueError(f"{name}: a balance head needs the balance layer (config vf_gains)")
        if self.action_space != "joints" and action_map is None:
            raise ValueError(f"{name}: a policy in the {self.action_space!r} action space needs its action_map")
        self.head = head
        self.action_map = action_map
        self.pd = PDSettings(**{k: cfg[k] for k in ("kp_scale", "kd_ratio", "torque_scale", "velocity_targets",
                                                    "arm_velocity_targets") if k in cfg},
                             vf_gains=tuple(cfg.get("vf_gains", ())))

    # ---------------------------------------------------------------- Controller interface
    def reset(self, env) -> None:
        from tracker.track.pd import PDController
        pd = PDController(self.pd.kp_scale, self.pd.kd_ratio, self.pd.torque_scale, self.pd.velocity_targets,
                          balance=tuple(self.pd.vf_gains) or None, arm_velocity_targets=bool(self.pd.arm_velocity_targets))
        pd.reset(env)
        for c in env._cache:
            if self.action_space == "joints" and c.n_act != self.act_dim:
                raise ValueError(f"policy has {self.act_dim} actions, the fighter {c.n_act}: trained on another skeleton")

    def residual(self, obs: np.ndarray) -> np.ndarray:
        """(n_fighters, act_dim) residual PD targets for observations (n_fighters, obs_dim) or (obs_dim,)."""
        x = np.atleast_2d(obs)
        if x.shape[1] != self.obs_dim:
            raise ValueError(f"observation has {x.shape[1]} numbers, the policy expects {self.obs_dim}")
        return np.clip(self.net(self.norm(x)), -self.action_clip, self.action_clip)

    def act(self, env, obs: np.ndarray) -> np.ndarray:
        """``obs``: the env's observation (one fighter: (D,), several: (n, D)); balance features are added here.
        When the env observes other reference horizons than the policy was trained with, the
        observation is rebuilt with the policy's."""
        if tuple(env.config.obs_future) != self.obs_future:
            obs = np.stack([env.observe(k, self.obs_future) for k in range(env.n_fighters)])
        if self.balance:
            obs = policy_observation(env, obs)
        a = self.residual(obs)
        if self.head is not None:
            env.balance.bias[:] = self.head.bias(obs)
        if self.action_map is not None:
            tg = env.reference_targets()
            out, off = [], 0
            for k, c in enumerate(env._cache):
                out.append(self.action_map(env, k, a[k], tg[off:off + c.n_act]))
                off += c.n_act
            a = np.concatenate(out)
        a = a.reshape(-1)
        if env.config.residual_actions:
            return a
        return env.reference_targets() + a

    def describe(self) -> str:
        b = self.budget
        vf = " over the virtual-force balance layer" if self.pd.vf_gains else ""
        vf += " steered by a balance head" if self.head is not None else ""
        vf += ", arm velocity targets" if self.pd.arm_velocity_targets else ""
        return (f"learned policy {self.ckpt_path or '(in memory)'}{vf}: trained {b.get('samples', 0) / 1e6:.1f}M samples, "
                f"{b.get('cpu_hours', 0.0):.2f} CPU-hours on {self.library.get('describe', '?')}")


def load_checkpoint(path: str | os.PathLike) -> dict:
    """A policy checkpoint, read weights-only with its format checked (igraph_fight.checkpoint);
    a CheckpointError naming the file otherwise."""
    from igraph_fight.checkpoint import load_checkpoint as load_versioned
    return load_versioned(path, POLICY_FORMAT, (POLICY_VERSION,), what="tracking policy")


def save_policy_checkpoint(path: str | os.PathLike, ck: dict) -> None:
    """Write a policy checkpoint atomically in POLICY_FORMAT (numpy arrays stored as tensors)."""
    from igraph_fight.checkpoint import save_checkpoint
    save_checkpoint(path, ck, POLICY_FORMAT, POLICY_VERSION)


def offset_checkpoint(src: str | os.PathLike, dst: str | os.PathLike, offset_rad: float) -> None:
    """Write to ``dst`` the checkpoint ``src`` with its policy's output bias set to ``offset_rad``
    on every joint: a policy that adds that offset to every PD target. A deliberately wrong start
    for tests and benchmarks of the training loop (it must find a clear improvement)."""
    ck = load_checkpoint(src)
    last_bias = [k for k in ck["policy"] if k.startswith("mu.") and k.endswith(".bias")][-1]
    ck["policy"][last_bias] = torch.full_like(ck["policy"][last_bias], float(offset_rad))
    save_policy_checkpoint(dst, ck)


def load_policy(path: str | os.PathLike | None = None) -> LearnedController:
    """A LearnedController from a checkpoint file (default: the shipped one)."""
    p = Path(path) if path else DEFAULT_CKPT
    if not p.is_file():
        raise FileNotFoundError(f"no policy checkpoint at {p} (train one: igraph-fight tracker train --out CKPT)")
    return LearnedController(load_checkpoint(p), str(p))


def load_default_policy() -> LearnedController:
    """The policy shipped with the repository (tracker/checkpoints/boxing_cmu13.pt)."""
    return load_policy(DEFAULT_CKPT)
