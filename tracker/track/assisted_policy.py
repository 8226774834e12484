"""The learned assisted tracker: one policy over the whole action library that outputs PD-target
residuals for every joint and the balance assist's wrench (tracker.track.assist, mode "learned").

    ctrl = load_assisted()                           # the shipped checkpoint
    env = BatchEnv(scene, n, BatchConfig(assist=AssistConfig("learned", cap=ctrl.cap)))
    targets, wrench = ctrl.act(env, obs)            # (B, n_act) rad, (B, 6) in cap units

Inference is a numpy forward pass of the actor's mean (no torch per step). ``assist_off=True``
plays the same policy with its wrench ignored (the env's assist mode must then be "none"): the
pure-physics figure.

Checkpoint (igraph_fight.checkpoint: read weights-only, no code runs from the file):
``format`` "igraph-fight/assisted-tracker", ``version`` 1, ``actor`` (state dict), ``obs_mean`` /
``obs_var`` (tensors), ``config`` (the training config), ``cap`` (the assist cap it ends at),
``budget`` (samples, CPU seconds), ``curve`` (learning curve rows); a resumable training
checkpoint also has ``critic``, ``optimizer`` and the curriculum state.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from igraph_fight.checkpoint import CheckpointError, load_checkpoint

FORMAT = "igraph-fight/assisted-tracker"
VERSION = 1
#: The checkpoint shipped with the repository (trained on the CMU boxing library).
DEFAULT_ASSISTED_CKPT = Path(__file__).resolve().parent.parent / "checkpoints" / "assisted_cmu13.pt"
N_ASSIST = 6


def mlp_forward(layers: list[tuple[np.ndarray, np.ndarray]], x: np.ndarray) -> np.ndarray:
    """ELU MLP forward pass (weights (in, out), biases (out,)); the last layer is linear."""
    for i, (w, b) in enumerate(layers):
        x = x @ w + b
        if i < len(layers) - 1:
            x = np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))
    return x


def actor_layers(state: dict, prefix: str = "mu.") -> list[tuple[np.ndarray, np.ndarray]]:
    """The (weight.T, bias) pairs of an nn.Sequential of Linear layers stored under ``prefix``."""
    idx = sorted({int(k[len(prefix):].split(".")[0]) for k in state if k.startswith(prefix) and k.endswith(".weight")})
    out = []
    for i in idx:
        w = np.asarray(state[f"{prefix}{i}.weight"], dtype=np.float64)
        b = np.asarray(state[f"{prefix}{i}.bias"], dtype=np.float64)
        out.append((w.T.copy(), b.copy()))
    return out


class AssistedController:
    """The batched-env controller running a trained assisted policy (deterministic: the mean).

    Attributes:
        cap: the assist cap (body weights) the policy was trained at last.
        residual_clip: residuals are clipped to +- this (rad), as in training.
        assist_off: ignore the policy's wrench (pure physics with the same joint policy).
        hold: add this share of the fixed PD's wrench toward the reference root pose (what the
            observation's last six numbers hold, cap units) to the policy's wrench before the cap
            (0: the policy alone).
    """

    name = "learned"
    batched = True
    physics_hz = 120.0

    def __init__(self, ckpt: dict, path: str = "", assist_off: bool = False, hold: float = 0.0) -> None:
        if ckpt.get("format") != FORMAT or int(ckpt.get("version", -1)) != VERSION:
            raise CheckpointError(path or "checkpoint", f"not an assisted-tracker checkpoint of version {VERSION}")
        self.path = path
        self.config = dict(ckpt["config"])
        self.layers = actor_layers(ckpt["actor"])
        self.obs_mean = np.asarray(ckpt["obs_mean"], dtype=np.float64)
        self.obs_std = np.sqrt(np.asarray(ckpt["obs_var"], dtype=np.float64) + 1e-8)
        self.obs_dim = self.layers[0][0].shape[0]
        self.act_dim = self.layers[-1][0].shape[1]
        self.n_act = self.act_dim - N_ASSIST
        self.cap = float(ckpt.get("cap", self.config.get("cap_start", 0.5)))
        self.residual_clip = float(self.config.get("residual_clip", 0.5))
        self.budget = dict(ckpt.get("budget", {}))
        self.gain_scale = tuple(tuple(x) for x in self.config.get("class_scale", ()))
        self.arm_velocity_targets = bool(self.config.get("arm_velocity_targets", False))
        self.assist_off = bool(assist_off)
        if not 0.0 <= hold <= 2.0:
            raise ValueError(f"hold must be in [0, 2] (a share of the fixed assist), not {hold}")
        self.hold = float(hold)
        self.assist_gain = np.asarray(ckpt["actor"].get("assist_gain", np.zeros(N_ASSIST)), dtype=np.float64)
        self.physics_hz = float(self.config.get("physics_hz", 120.0))

    # ------------------------------------------------------------------ controller protocol
    def reset(self, env) -> None:
        from tracker.track.pd import PDTracker
        per_fighter = getattr(env, "batch", env).n_act
        if per_fighter != self.n_act:
            raise CheckpointError(self.path, f"the policy drives {self.n_act} actuators, the body has {per_fighter}")
        PDTracker(class_scale=self.gain_scale, arm_velocity_targets=self.arm_velocity_targets).reset(env)

    def assist_config(self):
        """The assist the policy drives: its own (mode "learned") at its cap, or none when off."""
        from tracker.track.assist import AssistConfig
        return AssistConfig("none", 0.0) if self.assist_off else AssistConfig("learned", self.cap)

    def policy_output(self, obs: np.ndarray) -> np.ndarray:
        """(B, act_dim) deterministic output for observations (B, obs_dim)."""
        x = np.atleast_2d(obs)
        if x.shape[1] != self.obs_dim:
            raise CheckpointError(self.path, f"observation has {x.shape[1]} numbers, the policy expects {self.obs_dim}")
        z = np.clip((x - self.obs_mean) / self.obs_std, -10.0, 10.0)
        out = mlp_forward(self.layers, z)
        out[:, self.n_act:] += x[:, -N_ASSIST:] * self.assist_gain     # the fixed PD's wrench as the prior
        return out

    def act(self, env, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """PD targets (reference + clipped residuals) and the wrench in cap units (None when off)."""
        a = self.policy_output(obs)
        targets = env.reference_targets() + np.clip(a[:, :self.n_act], -self.residual_clip, self.residual_clip)
        if self.assist_off:
            return targets, None
        wrench = a[:, self.n_act:]
        if self.hold:
            wrench = wrench + self.hold * np.atleast_2d(obs)[:, -N_ASSIST:]
        return targets, np.clip(wrench, -1.0, 1.0)

    def describe(self) -> str:
        b = self.budget
        off = ", assist off" if self.assist_off else (f", root hold {self.hold:g}" if self.hold else "")
        off += ", arm velocity targets" if self.arm_velocity_targets else ""
        return (f"assisted tracker {self.path or '(in memory)'}{off}: cap {self.cap:g} mg, trained "
                f"{b.get('samples', 0) / 1e6:.1f}M samples, {b.get('cpu_s', 0.0) / 3600:.2f} CPU-hours")


def load_assisted(path: str | os.PathLike | None = None, assist_off: bool = False,
                  hold: float = 0.0) -> AssistedController:
    """An AssistedController from a checkpoint file (default: the shipped one), read weights-only
    (igraph_fight.checkpoint.load_checkpoint: no code runs from the file)."""
    p = Path(path) if path else DEFAULT_ASSISTED_CKPT
    if not p.is_file():
        raise CheckpointError(str(p), "no assisted-tracker checkpoint here (train one: igraph-fight tracker train-assisted)")
    ck = load_checkpoint(p, FORMAT, (VERSION,), "assisted-tracker checkpoint")
    return AssistedController(ck, str(p), assist_off=assist_off, hold=hold)
