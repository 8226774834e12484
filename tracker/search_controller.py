"""A search controller: the learned policy steered at run time by a sampling search (offline quality).

Every ``segment`` control steps (0.1 s), from the env's current state, ``candidates`` offsets are
tried (the first: none), each held for the segment and followed by the plain policy for
``lookahead`` steps (1.5 s), and scored by the discounted tracking reward (tracker.train's
tracking_reward; nothing after a fall or a 1 m drift from the reference); the best is played.
This is the teacher of the search route (tracker/imitation.py) run as the controller itself: it
keeps the body up far longer than any policy distilled from it (tracker/TRAINING.md, fourteenth
session), at the price of simulating candidates x (segment + lookahead) / segment = 256 control
steps per step played at the defaults: about 0.15x real time on one core. A labelled, non-default
controller for offline work (cutscenes, reference data), not what a game runs per frame:

    igraph-fight tracker eval --controller search [--ckpt POLICY.pt] --walks 20
    igraph-fight tracker render --controller search ...

``space="layer"`` searches the balance layer's six steering numbers (tracker/vforce.py ``bias``)
instead of the 66 joint offsets. Deterministic: the candidates' generator is reseeded at reset.
No force acts on the root; the search only chooses PD targets (or the layer's targets).
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from .controller import register_controller


@dataclass(frozen=True)
class SearchSettings:
    """Knobs of the search (module doc). Sigmas: radians (joints) or the layer's units
    (m, m, m/s, m/s, rad, rad)."""

    candidates: int = 16
    segment: int = 3
    lookahead: int = 45
    space: str = "joints"                 # "joints" or "layer"
    sigma: float = 0.05                   # joint offsets, arms and head
    sigma_legs: float = 0.12              # joint offsets, legs and trunk
    sigma_layer: tuple[float, ...] = (0.03, 0.03, 0.10, 0.10, 0.05, 0.05)
    gamma: float = 0.97
    drift_m: float = 1.0
    reward_weights: tuple[float, ...] = (0.5, 0.05, 0.15, 0.15, 0.15)
    seed: int = 0


class SearchController:
    """Controller (tracker.controller) wrapping a LearnedController; one-fighter envs."""

    name = "search"

    def __init__(self, policy, settings: SearchSettings = SearchSettings()) -> None:
        if settings.space not in ("joints", "layer"):
            raise ValueError(f"search space {settings.space!r}: 'joints' or 'layer'")
        self.policy = policy
        self.s = settings

    def reset(self, env) -> None:
        from .imitation import leg_mask
        from .train import RewardRef
        if env.n_fighters != 1:
            raise ValueError("the search controller drives one fighter")
        self.policy.reset(env)
        if self.s.space == "layer" and env.balance is None:
            raise ValueError("space='layer' needs a policy over the balance layer (config vf_gains)")
        self.rng = np.random.default_rng(self.s.seed)
        self.rr = RewardRef.build(env, env.scene, env.refs[0])
        self.sig = (np.asarray(self.s.sigma_layer, float) if self.s.space == "layer"
                    else np.where(leg_mask(env.scene), self.s.sigma_legs, self.s.sigma))
        self.k = 0
        self.delta = np.zeros(len(self.sig))
        self._snap = mujoco.MjData(env.model)

    def describe(self) -> str:
        s = self.s
        return (f"search over {s.space} ({s.candidates} candidates per {s.segment / 30:.1f} s, {s.lookahead / 30:.1f} s "
                f"lookahead) steering {self.policy.describe()}")

    # ---------------------------------------------------------------- the played action
    def _apply(self, env, obs: np.ndarray, delta: np.ndarray) -> np.ndarray:
        if self.s.space == "layer":
            env.balance.bias[0] = delta
            return self.policy.act(env, obs)
        base = 0.0 if env.config.residual_actions else env.reference_targets()
        res = self.policy.act(env, obs) - base
        return np.clip(res + delta, -self.policy.action_clip, self.policy.action_clip) + base

    def act(self, env, obs: np.ndarray) -> np.ndarray:
        if self.k % self.s.segment == 0:
            self.delta = self._search(env, obs)
        self.k += 1
        return self._apply(env, obs, self.delta)

    # ---------------------------------------------------------------- the search
    def _save(self, env):
        # the whole MjData, not only the integration state: the policy's observation reads derived
        # quantities (contacts, body velocities) that mj_setState + mj_kinematics would leave stale
        mujoco.mj_copyData(self._snap, env.model, env.data)
        return env.t, env.sim_time, env.done

    def _restore(self, env, st) -> None:
        mujoco.mj_copyData(env.data, env.model, self._snap)
        env.t, env.sim_time, env.done = st

    def _score(self, env, obs: np.ndarray, delta: np.ndarray) -> float:
        from .train import tracking_reward
        s = self.s
        zero = np.zeros_like(delta)
        ret, disc, o = 0.0, 1.0, obs
        ref = env.refs[0]
        for j in range(s.segment + s.lookahead):
            o, _, done, info = env.step(self._apply(env, o, delta if j < s.segment else zero))
            dxy = env.data.qpos[:2] - ref.qpos[env.t, :2]
            if info.fall[0] is not None or float(dxy @ dxy) > s.drift_m ** 2:
                break
            ret += disc * tracking_reward(env, self.rr, s.reward_weights)
            disc *= s.gamma
            if done:
                break
        return ret

    def _search(self, env, obs: np.ndarray) -> np.ndarray:
        st = self._save(env)
        best, best_ret = np.zeros(len(self.sig)), -np.inf
        for k in range(self.s.candidates):
            if k:
                self._restore(env, st)
            delta = np.zeros(len(self.sig)) if k == 0 else self.rng.normal(0.0, 1.0, len(self.sig)) * self.sig
            ret = self._score(env, obs, delta)
            if ret > best_ret:
                best, best_ret = delta, ret
        self._restore(env, st)
        return best


def load_search(ckpt: str | None = None, settings: SearchSettings = SearchSettings()) -> SearchController:
    """A search controller around a policy checkpoint (default: the shipped one)."""
    from .policy import load_policy
    return SearchController(load_policy(ckpt), settings)


register_controller("search", lambda ckpt: load_search(ckpt))
