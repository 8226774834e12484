"""The search controller (tracker/search_controller.py) inside a physics bout: each fighter's
tracking policy steered at run time by a sampling search (offline quality, not a game's per-frame
controller).

    trk = load_tracker("search")            # or "search:8,24", "search:8,24:POLICY.pt" (tracker.bout_agents)
                                            # igraph-fight fight --physics ... with IGRAPH_FIGHT_TRACKER=search
                                            # python -m tracker.bout_cli fight|series ... --tracker search
    PhysicsBout(setup, agents, trk).run(seed=1)

Every ``segment`` control steps, for each standing fighter: its physical state (joint positions and
velocities) is copied into a one-fighter scene of the same body (built once from the bout scene's
FighterSpec), whose reference is a view of the fighter's online reference buffer; there the
search tries ``candidates`` offsets on the policy's PD targets (the first: none), each held for the
segment and followed by the plain policy for ``lookahead`` steps, scored by the discounted tracking
reward; the best offset is played in the bout until the next search.

Approximations, named: (1) the rollouts leave the opponent out (a one-fighter scene: punches,
clinches and pushes are not foreseen; they are rare next to falls, which is what the search
prevents); (2) the look-ahead past a fighter's planned action reads the reference's placeholder
(the action's last frame held still, tracker.bout) since the next action is not chosen yet; (3)
MuJoCo's warm start and the contacts of the first substep are recomputed in the copy (mj_forward),
so a rollout of the unchanged policy differs from the bout's own continuation in the last digits
of the solver. No force acts on any root; the search only chooses PD targets.

Defaults (BOUT_SEARCH): 16 candidates, 1.5 s look-ahead, every candidate tried, and a heading
reward (SearchSettings.heading_weight). Cost: candidates x (segment + lookahead) / segment = 256
one-fighter control steps per control step and fighter: 0.074x real time for the two fighters on
one core of the development VM; early acceptance (":early", the plain policy played when its own
rollout stays up) 0.27x without the heading reward (tracker/BOUTS.md, fifteenth session).
"""
from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np

from .search_controller import SearchController, SearchSettings

# The bout default (fifteenth session, tracker/BOUTS.md): the walks' strong search (16 candidates,
# 1.5 s look-ahead, every candidate tried) with a heading reward that keeps a fighter facing where
# its reference faces (without it the fighters drift apart facing away). Early acceptance
# (":early") is cheaper; with the heading reward it was not measured in bouts.
BOUT_SEARCH = SearchSettings(candidates=16, lookahead=45, heading_weight=1.0)


class BoutSearchTracker:
    """A bout tracker (reset(env), act(env, obs) for the two-fighter env) running one
    SearchController per fighter on a one-fighter copy of its body."""

    name = "search"

    def __init__(self, policy, settings: SearchSettings = BOUT_SEARCH) -> None:
        if settings.space != "joints":
            raise ValueError("the bout search steers joint offsets (space='joints')")
        self.policy = policy
        self.s = settings
        self.obs_future = policy.obs_future
        # Set by PhysicsBout before every act: True for a fighter that is down (no search for it).
        self.idle: list[bool] | None = None
        self._solo_key = None

    def describe(self) -> str:
        s = self.s
        return (f"bout search ({s.candidates} candidates per {s.segment / 30:.1f} s, {s.lookahead / 30:.1f} s "
                f"lookahead{s.variants()}, opponent left out of the rollouts) steering {self.policy.describe()}")

    # ---------------------------------------------------------------- set-up
    def _solo_env(self, env):
        from .env import TrackingEnv
        from .model import build_fighter_scene
        specs = env.scene.specs
        if not specs:
            raise ValueError("the bout search needs a scene built by tracker.model.build_fighter_scene (FighterScene.specs)")
        key = (id(env.scene), env.config)
        if self._solo_key != key:
            self._solos = [TrackingEnv(build_fighter_scene(specs[k], 1, env.scene.options), env.config)
                           for k in range(env.n_fighters)]
            self._solo_key = key
        return self._solos

    def reset(self, env) -> None:
        from .reference import Reference
        solos = self._solo_env(env)
        self.k = 0
        self.refs, self.searchers = [], []
        for k, r in enumerate(env.refs):
            # a view of the bout's online buffer (filled as the bout plays), with the balance
            # features under the one-fighter scene's key
            view = Reference(r.fps, r.qpos, r.qvel, r.ctrl, r.ctrl_vel, r.sites, r.penetration, r.source,
                             {"_balance_f0": r.meta[f"_balance_f{k}"]} if f"_balance_f{k}" in r.meta else {})
            self.refs.append(view)
            solos[k].reset([view], min(env.t, view.n_frames - 2))
            sc = SearchController(self.policy, replace(self.s, seed=self.s.seed + k))
            sc.reset(solos[k])
            self.searchers.append(sc)
        self.policy.reset(env)          # after the searchers' resets, which set the policy's PD on their scenes

    # ---------------------------------------------------------------- one fighter's search
    def _load(self, env, k: int):
        """Put fighter k's physical state into its one-fighter env; its observation."""
        solo = self._solos[k]
        fm, sm = env.scene.fighters[k], solo.scene.fighters[0]
        d, sd = env.data, solo.data
        sd.qpos[sm.qpos_slice] = d.qpos[fm.qpos_slice]
        sd.qvel[sm.qvel_slice] = d.qvel[fm.qvel_slice]
        sd.act[:] = 0.0
        sd.time = d.time
        solo.refs = [self.refs[k]]
        solo.t, solo.t_end, solo.done = env.t, env.t_end, False
        mujoco.mj_forward(solo.model, sd)
        return solo._obs_all()

    def _refresh_reward_ref(self, k: int, t: int) -> None:
        """The search's reward reference over the frames its rollouts can read (the buffer changes
        as the bout plays, so it is rebuilt for that window before every search)."""
        from .reference import Reference
        from .train import RewardRef
        sc, r, solo = self.searchers[k], self.refs[k], self._solos[k]
        a = max(t - 1, 0)
        b = min(t + self.s.segment + self.s.lookahead + 2, r.n_frames)
        win = Reference(r.fps, r.qpos[a:b], r.qvel[a:b], r.ctrl[a:b], r.ctrl_vel[a:b], r.sites[a:b], r.penetration)
        w = RewardRef.build(solo, solo.scene, win)
        for name in ("ee_local", "up", "heading", "com_vel"):
            getattr(sc.rr, name)[a:b] = getattr(w, name)

    def act(self, env, obs: np.ndarray) -> np.ndarray:
        if self.k % self.s.segment == 0:
            for k, sc in enumerate(self.searchers):
                if self.idle is not None and self.idle[k]:
                    sc.delta = np.zeros_like(sc.delta)
                    continue
                o = self._load(env, k)
                self._refresh_reward_ref(k, env.t)
                sc._search(self._solos[k], o)            # keeps its choice as sc.delta
        self.k += 1
        base = 0.0 if env.config.residual_actions else env.reference_targets()
        res = self.policy.act(env, obs) - base
        delta = np.concatenate([sc.delta for sc in self.searchers])   # fighters' actions are consecutive
        return np.clip(res + delta, -self.policy.action_clip, self.policy.action_clip) + base
