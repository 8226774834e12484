"""A search controller: the learned policy steered at run time by a sampling search (offline quality).

Every ``segment`` control steps (0.1 s), from the env's current state, ``candidates`` offsets are
tried (the first: none), each held for the segment and followed by the plain policy for
``lookahead`` steps (1.5 s), and scored by the discounted tracking reward
(tracker.track.tracking_reward; nothing after a fall or a 1 m drift from the reference); the best
is played. This is the teacher of the search route (tracker/learn/search_labels.py) run as the
controller itself: it keeps the body up far longer than any policy distilled from it
(research/notes/TRAINING.md), at the price of simulating candidates x (segment + lookahead) /
segment = 256 control steps per step played at the defaults: about 0.15x real time on one core.
A controller for offline work (cutscenes, reference data), not what a game runs per frame:

    python -m research.search_controller eval --controller search|search-fast [--ckpt POLICY.pt] --walks 20
    python -m research.search_controller render --controller search --out walk.png ...

(the options of `igraph-fight tracker eval|render`, with these controllers' names added).
``space="layer"`` searches the balance layer's six steering numbers (tracker/track/vforce.py ``bias``)
instead of the 66 joint offsets. Deterministic: the candidates' generator is reseeded at reset.
No force acts on the root; the search only chooses PD targets (or the layer's targets).
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

UP = 1 << 30        # SearchController._score's steps stayed up for a rollout that never fell or drifted


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
    # Cheaper variants (off by default: the figures of research/notes/TRAINING.md are without them):
    early_accept: bool = False    # play no offset, trying nothing else, when the plain policy's rollout
    #                               stays up and within drift_m over the whole look-ahead
    reuse: bool = False           # the previous segment's offset is always the second candidate
    first_kept: bool = False      # stop at the first candidate whose rollout stays up (and on the
    #                               reference, within yaw_tol) over the look-ahead, instead of trying all
    incremental: bool = False     # with early_accept: an accepted plain rollout is kept and, at the next
    #                               search, extended by one segment instead of simulated again (exact
    #                               where the env is the one played: the plain policy is deterministic);
    #                               with first_kept too, the chosen offset's rollout likewise
    # Heading (physics bouts, where a fighter's facing steers the planner):
    heading_weight: float = 0.0   # extra reward heading_weight * exp(-10 (1 - cos(yaw error))) per step
    yaw_tol: float = float("inf")  # early_accept also needs the pelvis yaw within this (rad) of the reference's
    # Ranking: by default the best discounted return wins, so a rollout that
    # falls late in the look-ahead (its return only truncated) can beat one that stays up when an extra
    # term (heading, aim) pays more early on; up_first ranks by steps stayed up (a rollout that stays up
    # over the whole look-ahead first), then by return
    up_first: bool = False

    def variants(self) -> str:
        """The non-default knobs in words (for describe()), e.g. ", early acceptance, heading weight 1"."""
        words = [w for on, w in ((self.early_accept, "early acceptance"), (self.incremental, "incremental"),
                                 (self.first_kept, "first candidate that stays up"), (self.reuse, "previous offset reused"))
                 if on]
        if self.heading_weight:
            words.append(f"heading weight {self.heading_weight:g}")
        if self.yaw_tol < np.inf:
            words.append(f"yaw tolerance {self.yaw_tol:g} rad")
        if self.up_first:
            words.append("staying up ranked first")
        return "".join(", " + w for w in words)


class SearchController:
    """Controller (tracker.track.controllers) wrapping a LearnedController; one-fighter envs."""

    name = "search"

    def __init__(self, policy, settings: SearchSettings = SearchSettings()) -> None:
        if settings.space not in ("joints", "layer"):
            raise ValueError(f"search space {settings.space!r}: 'joints' or 'layer'")
        self.policy = policy
        self.s = settings
        # The fighter searched for in the envs it is given: 0 in its own one-fighter env; the bout
        # search (research.bout_search) may hand it a two-fighter copy of the bout with another index.
        self.fighter = 0

    def reset(self, env) -> None:
        from tracker.body.humanoid import leg_mask
        from tracker.track.tracking_reward import RewardRef
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
        self._snaps = {}                        # model -> (state snapshot, tail snapshot)
        self._tail = None                       # (t, sim_time, done, obs) at the end of the kept rollout (incremental)
        # extra(env) -> float: a reward added to every rollout step's (None: none); the bout search
        # sets it for the strikes it aims (research.bout_search)
        self.extra = None
        # counts over the searches since reset: full ones (not ended by early acceptance or an
        # incremental extension), those where no candidate stayed up, and those whose chosen
        # candidate fell in its rollout while another stayed up (only possible without up_first)
        self.stats = {"searches": 0, "full": 0, "none_up": 0, "fallen_chosen": 0}

    def describe(self) -> str:
        s = self.s
        return (f"search over {s.space} ({s.candidates} candidates per {s.segment / 30:.1f} s, {s.lookahead / 30:.1f} s "
                f"lookahead{s.variants()}) steering {self.policy.describe()}")

    # ---------------------------------------------------------------- the played action
    def _apply(self, env, obs: np.ndarray, delta: np.ndarray) -> np.ndarray:
        if self.s.space == "layer":
            env.balance.bias[self.fighter] = delta
            return self.policy.act(env, obs)
        base = 0.0 if env.config.residual_actions else env.reference_targets()
        res = self.policy.act(env, obs) - base
        if env.n_fighters > 1:                  # the offset on this fighter's actions only
            off = sum(c.n_act for c in env._cache[:self.fighter])
            full = np.zeros_like(res)
            full[off:off + len(delta)] = delta
            delta = full
        return np.clip(res + delta, -self.policy.action_clip, self.policy.action_clip) + base

    def act(self, env, obs: np.ndarray) -> np.ndarray:
        if self.k % self.s.segment == 0:
            self._search(env, obs)
        self.k += 1
        return self._apply(env, obs, self.delta)

    # ---------------------------------------------------------------- the search
    def _snap_of(self, env, which: int) -> mujoco.MjData:
        """Scratch MjData for env's model: 0 the saved state, 1 the kept rollout's end."""
        if id(env.model) not in self._snaps:
            self._snaps[id(env.model)] = (env.model, mujoco.MjData(env.model), mujoco.MjData(env.model))
        return self._snaps[id(env.model)][1 + which]

    def _save(self, env):
        # the whole MjData, not only the integration state: the policy's observation reads derived
        # quantities (contacts, body velocities) that mj_setState + mj_kinematics would leave stale
        mujoco.mj_copyData(self._snap_of(env, 0), env.model, env.data)
        return env.t, env.sim_time, env.done

    def _restore(self, env, st) -> None:
        mujoco.mj_copyData(env.data, env.model, self._snap_of(env, 0))
        env.t, env.sim_time, env.done = st

    def _lost(self, env, info) -> bool:
        """A fall, or the pelvis more than drift_m from the reference's."""
        k = self.fighter
        a = env._cache[k].qpos.start
        dxy = env.data.qpos[a:a + 2] - env.refs[k].qpos[env.t, :2]
        return info.fall[k] is not None or float(dxy @ dxy) > self.s.drift_m ** 2

    def _cos_yaw_err(self, env) -> float:
        from tracker.body.frames import ground_yaw
        c = env._cache[self.fighter]
        return float(np.cos(ground_yaw(env.data.xmat[c.pelvis].reshape(3, 3), c.lateral) - self.rr.heading[env.t]))

    def _yaw_ok(self, cos_err: float) -> bool:
        """The pelvis yaw within yaw_tol of the reference's (always, without a tolerance)."""
        return self.s.yaw_tol == np.inf or cos_err >= np.cos(self.s.yaw_tol)

    def _score(self, env, obs: np.ndarray, delta: np.ndarray, keep_tail: bool = False) -> tuple[float, bool, int]:
        """Discounted tracking return of one candidate, whether its rollout stayed up and on the
        reference to the end of the look-ahead (or of the reference), and the control steps it stayed
        up and within drift_m (a large number when it never fell or drifted). ``keep_tail``: remember
        the rollout's end state when it stayed (SearchSettings.incremental)."""
        from tracker.track.tracking_reward import tracking_reward
        s = self.s
        zero = np.zeros_like(delta)
        ret, disc, o, kept = 0.0, 1.0, obs, True
        for j in range(s.segment + s.lookahead):
            o, _, done, info = env.step(self._apply(env, o, delta if j < s.segment else zero))
            if self._lost(env, info):
                return ret, False, j
            r = tracking_reward(env, self.rr, s.reward_weights, self.fighter)
            if s.heading_weight or s.yaw_tol < np.inf:
                cos_err = self._cos_yaw_err(env)
                r += s.heading_weight * float(np.exp(-10.0 * (1.0 - cos_err)))
                kept = kept and self._yaw_ok(cos_err)
            if self.extra is not None:
                r += self.extra(env)
            ret += disc * r
            disc *= s.gamma
            if done:
                break
        if kept and keep_tail:
            mujoco.mj_copyData(self._snap_of(env, 1), env.model, env.data)
            self._tail = (env.t, env.sim_time, env.done, o.copy())
        return ret, kept, UP

    def _extend(self, env) -> bool:
        """Extend the kept plain rollout by one segment (the env is left at its end); False, and the
        rollout forgotten, when the extension falls, drifts or turns off the yaw tolerance."""
        t, sim_time, done, o = self._tail
        mujoco.mj_copyData(env.data, env.model, self._snap_of(env, 1))
        env.t, env.sim_time, env.done = t, sim_time, done
        zero = np.zeros(len(self.sig))
        for _ in range(self.s.segment):
            if env.done:
                break
            o, _, _, info = env.step(self._apply(env, o, zero))
            if self._lost(env, info) or (self.s.yaw_tol < np.inf and not self._yaw_ok(self._cos_yaw_err(env))):
                self._tail = None
                return False
        mujoco.mj_copyData(self._snap_of(env, 1), env.model, env.data)
        self._tail = (env.t, env.sim_time, env.done, o.copy())
        return True

    def _search(self, env, obs: np.ndarray) -> np.ndarray:
        """The best offset from the env's current state (left as it was); also kept as ``delta``."""
        st = self._save(env)
        # an extra reward (an aimed strike) is what a rollout's staying up says nothing about: no
        # early or first-kept stop while one is set
        early = self.s.early_accept and self.extra is None
        incremental = early and self.s.incremental
        self.stats["searches"] += 1
        if incremental and self._tail is not None:
            ok = self._extend(env)
            self._restore(env, st)
            if ok:                    # the kept rollout plays no offset after its first segment
                self.delta = np.zeros(len(self.sig))
                return self.delta
        self._tail = None
        best, best_key, best_up, any_up = np.zeros(len(self.sig)), (-np.inf, -np.inf), 0, False
        accepted = False                      # ended by early acceptance (not a full search)
        prev = self.delta
        for k in range(self.s.candidates):
            if k:
                self._restore(env, st)
            if k == 0:
                delta = np.zeros(len(self.sig))
            elif k == 1 and self.s.reuse and np.any(prev):
                delta = prev
            else:
                delta = self.rng.normal(0.0, 1.0, len(self.sig)) * self.sig
            # the rollout kept for extension is the chosen one's: the plain policy's when early
            # acceptance takes it, with first_kept also the first offset that stays up (its rollout is
            # the offset for one segment and the plain policy after it: what is played next if the
            # following searches accept the plain policy)
            ret, kept, up = self._score(env, obs, delta, keep_tail=incremental and (k == 0 or self.s.first_kept))
            key = (up, ret) if self.s.up_first else (0, ret)
            any_up = any_up or up == UP
            if key > best_key:
                best, best_key, best_up = delta, key, up
            if kept and ((k == 0 and early) or (k > 0 and self.s.first_kept and self.extra is None)):
                if k > 0:
                    best, best_up = delta, up      # the first that stays up, not the best return so far
                accepted = k == 0
                break
        if not accepted:
            self.stats["full"] += 1
            self.stats["none_up"] += not any_up
            self.stats["fallen_chosen"] += any_up and best_up != UP
        self._restore(env, st)
        self.delta = best
        return best


def load_search(ckpt: str | None = None, settings: SearchSettings = SearchSettings()) -> SearchController:
    """A search controller around a policy checkpoint (default: the shipped one)."""
    from tracker.track.policy_net import load_policy
    return SearchController(load_policy(ckpt), settings)


# The cheaper strong search (research/notes/TRAINING.md): early acceptance, incremental checks, full
# searches ended at the first candidate that stays up.
FAST_SEARCH = SearchSettings(early_accept=True, incremental=True, first_kept=True)

#: name -> factory(ckpt): the search controllers (the product's table: tracker.track.controllers.CONTROLLERS)
SEARCH_CONTROLLERS = {
    "search": lambda ckpt: load_search(ckpt),
    "search-fast": lambda ckpt: load_search(ckpt, FAST_SEARCH),
}


def make_search_controller(name: str, ckpt: str | None = None):
    """A search controller by name ("search", "search-fast"), else the product's (make_controller)."""
    if name in SEARCH_CONTROLLERS:
        return SEARCH_CONTROLLERS[name](ckpt)
    from tracker.track.controllers import make_controller
    return make_controller(name, ckpt)


def main(argv: list[str] | None = None) -> int:
    """``python -m research.search_controller eval|render ...``: `igraph-fight tracker eval|render`
    with the search controllers."""
    import argparse
    import sys

    from tracker.cli import register
    p = argparse.ArgumentParser(prog="python -m research.search_controller",
                                description="walk evaluation / rendering with the search controllers")
    sub = p.add_subparsers(dest="command", required=True)
    register(sub)
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in ("eval", "render"):
        p.error("commands: eval, render (the options of igraph-fight tracker eval|render)")
    a = p.parse_args(["tracker", *argv])
    try:
        a.controller = make_search_controller(a.controller, a.ckpt)
    except (ValueError, FileNotFoundError) as e:
        print(f"python -m research.search_controller: {e}", file=sys.stderr)
        return 2
    return a.func(a)


if __name__ == "__main__":
    raise SystemExit(main())
