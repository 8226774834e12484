"""The search controller (research/search_controller.py) inside a physics bout: each fighter's
tracking policy steered at run time by a sampling search (offline quality, not a game's per-frame
controller).

    trk = load_search_tracker("search")     # or "search:8,24", "search:8,24:POLICY.pt" (load_bout_search)
    PhysicsBout(setup, agents, trk).run(seed=1)
    python -m research.bout_search fight|series|rl-eval ... --tracker search[:...]
                                            # the options of `igraph-fight tracker bouts fight|series`, `rl eval`

Every ``segment`` control steps, for each standing fighter: its physical state (joint positions and
velocities) is copied into a one-fighter scene of the same body (built once from the bout scene's
FighterSpec), whose reference is a view of the fighter's online reference buffer; there the
search tries ``candidates`` offsets on the policy's PD targets (the first: none), each held for the
segment and followed by the plain policy for ``lookahead`` steps, scored by the discounted tracking
reward; the best offset is played in the bout until the next search.

Approximations, named: (1) the rollouts leave the opponent out (a one-fighter scene: punches,
clinches and pushes are not foreseen; they are rare next to falls, which is what the search
prevents); (2) the look-ahead past a fighter's planned action reads the reference's placeholder
(the action's last frame held still, tracker.bouts.physics_bout) since the next action is not chosen yet, or,
with ``foresee``, the actions its agent would choose from the coupled state
predicted at each action's end (PhysicsBout._foresee: a guess, one frame late, rewritten by the
real decision; measured in bouts: right one time in three, and more falls, research/notes/BOUTS.md); (3)
MuJoCo's warm start and the contacts of the first substep are recomputed in the copy (mj_forward),
so a rollout of the unchanged policy differs from the bout's own continuation in the last digits
of the solver. No force acts on any root; the search only chooses PD targets.

Two options (research/notes/BOUTS.md): ``duel`` rolls the candidates out in a copy of
the whole bout (both bodies simulated, the opponent on its plain policy: it does not search in
there), so a rollout sees the opponent's arms in the way of a punch, clinches and pushes, at about
twice the cost; ``aim`` adds a reward for the fighter's planned hits (PhysicsBout.planned_windows):
inside each strike window, how near the strike's fist comes to the opponent's head, chest or belly
(the opponent's geoms as simulated in duel rollouts, else where they are now moved on by its
reference). Planned hits missed mostly because the fist met the opponent's guard, which the
kinematic simulator does not model (its targets are spheres, a guard action no defence).
``touch`` adds a reward for each rollout step that ends with the strike's
fist on a target: the aim term alone scores a fist stopped by a forearm 2 cm short of the head
at 98% of a hit. ``lead`` rewards the striker's pelvis on its reference from 0.5 s
before each planned window to its end (measured: three times the falls, no larger landed share).
``upfirst`` (SearchSettings.up_first) ranks the candidates by how long their
rollouts stay up before their returns: with the heading, aim and touch terms a candidate that falls
late in the look-ahead otherwise wins over one that stays up whenever it pays more early on (in 20 s
of two bouts under ``search:early:yawtol=0.35:aim=3:touch=10:spread=3:duel``, 7-14 of a fighter's
83-119 full searches chose a rollout that fell while another stayed up). Each bout's summary.json,
and each bout row of a series or of the RL evaluation, has the searches' counts (``search_stats``,
tracker.bouts.run.search_stats).

Defaults (BOUT_SEARCH): 16 candidates, 1.5 s look-ahead, every candidate tried, and a heading
reward (SearchSettings.heading_weight). Cost: candidates x (segment + lookahead) / segment = 256
one-fighter control steps per control step and fighter: 0.074x real time for the two fighters on
one core of the development VM; early acceptance (":early", the plain policy played when its own
rollout stays up) 0.27x without the heading reward (research/notes/BOUTS.md);
``search:early:yawtol=0.35:aim=3:touch=10:spread=3:duel`` 0.06-0.08x.
"""
from __future__ import annotations

from dataclasses import replace

import mujoco
import numpy as np

from tracker.bouts.judging import fist_gap, target_geometry
from tracker.body.humanoid import EFFECTOR_LABELS, TARGET_LABELS
from research.search_controller import SearchController, SearchSettings

# The bout default (research/notes/BOUTS.md): the walks' strong search (16 candidates,
# 1.5 s look-ahead, every candidate tried) with a heading reward that keeps a fighter facing where
# its reference faces (without it the fighters drift apart facing away). Early acceptance
# (":early") is cheaper; with the heading reward, a yaw tolerance and the touch reward it was
# measured (research/notes/BOUTS.md: no worse, 1.5-2.3x cheaper).
BOUT_SEARCH = SearchSettings(candidates=16, lookahead=45, heading_weight=1.0)
# The pelvis lead term (``lead``): from LEAD_IN_STEPS control steps before a planned
# strike's window to its end, lead * exp(-(d / LEAD_SIGMA_M)^2) per rollout step, d the striker's
# pelvis distance from its reference's (ground plane): planned punches in bouts missed mostly out of
# reach, the striker's pelvis 10-22 cm behind its reference (the miss anatomy of tracker.bouts.physics_bout).
LEAD_IN_STEPS = 15
LEAD_SIGMA_M = 0.1


class BoutSearchTracker:
    """A bout tracker (reset(env), act(env, obs) for the two-fighter env) running one
    SearchController per fighter on a one-fighter copy of its body."""

    name = "search"

    def __init__(self, policy, settings: SearchSettings = BOUT_SEARCH, aim: float = 0.0,
                 aim_sigma_m: float = 0.15, duel: bool = False, aim_spread: float = 1.0, touch: float = 0.0,
                 lead: float = 0.0, foresee: bool = False) -> None:
        if settings.space != "joints":
            raise ValueError("the bout search steers joint offsets (space='joints')")
        if aim < 0 or aim_sigma_m <= 0 or aim_spread <= 0 or touch < 0 or lead < 0:
            raise ValueError("aim weight >= 0, aim sigma > 0 (m), aim spread > 0, touch weight >= 0 and lead weight >= 0")
        self.policy = policy
        self.s = settings
        self.aim = aim
        self.touch = touch                      # reward per rollout step with the strike's fist on a target
        self.lead = lead                        # reward for the striker's pelvis on its reference (LEAD_SIGMA_M)
        self.aim_sigma_m = aim_sigma_m
        self.duel = duel
        self.aim_spread = aim_spread            # arm offsets' sigma multiplied by this while aiming
        # PhysicsBout writes guessed next actions this far past each fighter's current action when
        # > 0 (its foresight: the agents' peek), instead of holding the action's last frame still
        self.foresee_steps = settings.segment + settings.lookahead + 2 if foresee else 0
        self.obs_future = policy.obs_future
        # Set by PhysicsBout before every act: True for a fighter that is down (no search for it).
        self.idle: list[bool] | None = None
        # Set by PhysicsBout before every act: per fighter, its planned hits' windows still to come,
        # [(first step, end step, fist side or -1)] (PhysicsBout.planned_windows).
        self.aims: list[list[tuple[int, int, int]]] | None = None
        self._solo_key = None

    def describe(self) -> str:
        s = self.s
        aim = (f", planned strikes aimed (weight {self.aim:g}, {self.aim_sigma_m:g} m"
               + (f", touch {self.touch:g}" if self.touch else "")
               + (f", pelvis lead {self.lead:g}" if self.lead else "")
               + (f", arm offsets x{self.aim_spread:g}" if self.aim_spread != 1 else "") + ")") if self.aiming else ""
        opp = ("the opponent in the rollouts on its plain policy" if self.duel else
               "opponent left out of the rollouts") + (", next actions foreseen" if self.foresee_steps else "")
        return (f"bout search ({s.candidates} candidates per {s.segment / 30:.1f} s, {s.lookahead / 30:.1f} s "
                f"lookahead{s.variants()}{aim}, {opp}) steering {self.policy.describe()}")

    @property
    def aiming(self) -> bool:
        """Whether the rollouts reward the planned strikes (PhysicsBout then hands over their windows)."""
        return self.aim > 0 or self.touch > 0 or self.lead > 0

    # ---------------------------------------------------------------- set-up
    def _solo_env(self, env):
        from tracker.track.env import TrackingEnv
        from tracker.body.humanoid import build_fighter_scene
        specs = env.scene.specs
        if not specs:
            raise ValueError("the bout search needs a scene built by tracker.body.humanoid.build_fighter_scene (FighterScene.specs)")
        key = (id(env.scene), env.config)
        if self._solo_key != key:
            self._solos = [TrackingEnv(build_fighter_scene(specs[k], 1, env.scene.options), env.config)
                           for k in range(env.n_fighters)]
            # the duel copy: the whole bout scene again (same layout, so the same addresses and geom ids)
            self._duel = (TrackingEnv(build_fighter_scene(list(specs), len(specs), env.scene.options), env.config)
                          if self.duel else None)
            self._solo_key = key
        return self._solos

    def reset(self, env) -> None:
        from tracker.track.reference import Reference
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
        # per bout (and duel) fighter: fist geoms (both, left, right) and target geoms; a one-fighter
        # copy has fighter 0's geom ids (the same body, built first), so its fists are _fists[0]
        from tracker.body.humanoid import leg_mask
        self._legs = leg_mask(solos[0].scene)
        self._fists = [[np.concatenate([fm.geom_label[e] for e in EFFECTOR_LABELS])]
                       + [np.asarray(fm.geom_label[e]) for e in EFFECTOR_LABELS] for fm in env.scene.fighters]
        self._fist_r = [env.model.geom_size[g, 0].copy() for g in self._fists[0]]
        self._targets = [target_geometry(env.model, np.concatenate([fm.geom_label[t] for t in TARGET_LABELS]))
                         for fm in env.scene.fighters]
        if self._duel is not None:
            self._duel.refs = env.refs
            self.policy.reset(self._duel)
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

    def _load_duel(self, env):
        """Put the whole bout state into the duel copy; its observation (both fighters)."""
        du = self._duel
        du.data.qpos[:] = env.data.qpos
        du.data.qvel[:] = env.data.qvel
        du.data.act[:] = 0.0
        du.data.time = env.data.time
        du.refs = env.refs
        du.t, du.t_end, du.done = env.t, env.t_end, False
        mujoco.mj_forward(du.model, du.data)
        return du._obs_all()

    def _refresh_reward_ref(self, k: int, t: int) -> None:
        """The search's reward reference over the frames its rollouts can read (the buffer changes
        as the bout plays, so it is rebuilt for that window before every search)."""
        from tracker.track.reference import Reference
        from tracker.track.tracking_reward import RewardRef
        sc, r, solo = self.searchers[k], self.refs[k], self._solos[k]
        a = max(t - 1, 0)
        b = min(t + self.s.segment + self.s.lookahead + 2, r.n_frames)
        win = Reference(r.fps, r.qpos[a:b], r.qvel[a:b], r.ctrl[a:b], r.ctrl_vel[a:b], r.sites[a:b], r.penetration)
        w = RewardRef.build(solo, solo.scene, win)
        for name in ("ee_local", "up", "heading", "com_vel"):
            getattr(sc.rr, name)[a:b] = getattr(w, name)

    def _aim_reward(self, env, k: int):
        """The rollouts' extra reward for fighter k's planned strikes within the search's horizon:
        per step inside a strike window, aim * exp(-(gap / aim_sigma_m)^2), gap the distance of the
        strike's fist to the opponent's head, chest or belly (judging.fist_gap). In duel rollouts the
        opponent's geoms are where its simulated body is (its arms may be in the way: the gap is
        to the targets, which the fist cannot reach through a guard); otherwise the opponent is not
        in the rollouts and its target geoms are taken where they are now, moved on by its reference
        pelvis displacement (a named approximation). With ``touch``, each such step whose gap is
        under 1 mm (the fist on the target at the step's end: what the judge counts, bar its 1 N)
        adds touch: near misses at a guard score almost the full aim reward, a contact more. None
        when nothing is aimed."""
        if not self.aiming or self.aims is None:
            return None
        t0, t1 = env.t, env.t + self.s.segment + self.s.lookahead
        pre = LEAD_IN_STEPS if self.lead else 0
        wins = [(a, b, side) for a, b, side in self.aims[k] if a - pre < t1 and b > t0]
        if not wins:
            return None
        o = 1 - k
        g, tr, thl = self._targets[o]
        w, inv_s2, wt = self.aim, 1.0 / self.aim_sigma_m ** 2, self.touch
        if self._duel is not None:                  # the opponent's geoms as simulated
            d = self._duel.data
            fists = self._fists[k]
            pel, ref_k = self._duel._cache[k].qpos.start, self._duel.refs[k]

            def targets(tau: int):
                return d.geom_xpos[g], d.geom_xmat[g][:, [2, 5, 8]]
        else:                                       # held, moved on by the opponent's reference
            d = self._solos[k].data
            fists = self._fists[0]
            pel, ref_k = self._solos[k]._cache[0].qpos.start, self.refs[k]
            c0 = env.data.geom_xpos[g].copy()
            ax = env.data.geom_xmat[g][:, [2, 5, 8]].copy()
            ref_o = self.refs[o]
            base = ref_o.qpos[env.t, :2].copy()
            shift = np.zeros(3)

            def targets(tau: int):
                shift[:2] = ref_o.qpos[min(tau, ref_o.n_frames - 1), :2] - base
                return c0 + shift, ax

        wl, inv_l2 = self.lead, 1.0 / LEAD_SIGMA_M ** 2

        def extra(rollout_env) -> float:
            tau = rollout_env.t
            r = 0.0
            for a, b, side in wins:
                if wl and a - pre <= tau < b:
                    dp = d.qpos[pel:pel + 2] - ref_k.qpos[min(tau, ref_k.n_frames - 1), :2]
                    r += wl * float(np.exp(-float(dp @ dp) * inv_l2))
                if a <= tau < b and (w or wt):
                    xyz, axis = targets(tau)
                    gap = fist_gap(d.geom_xpos[fists[side + 1]], self._fist_r[side + 1], xyz, axis, tr, thl)
                    r += w * float(np.exp(-gap * gap * inv_s2)) + (wt if gap < 1e-3 else 0.0)
            return r
        return extra

    def act(self, env, obs: np.ndarray) -> np.ndarray:
        if self.k % self.s.segment == 0:
            for k, sc in enumerate(self.searchers):
                if self.idle is not None and self.idle[k]:
                    sc.delta = np.zeros_like(sc.delta)
                    sc._tail = None           # a rollout kept for incremental checks is stale after this
                    continue
                self._refresh_reward_ref(k, env.t)
                sc.extra = self._aim_reward(env, k)
                sig = sc.sig
                if sc.extra is not None and self.aim_spread != 1.0:
                    sc.sig = np.where(self._legs, sig, sig * self.aim_spread)
                if self._duel is not None:
                    sc.fighter = k
                    sc._search(self._duel, self._load_duel(env))
                else:
                    sc._search(self._solos[k], self._load(env, k))   # keeps its choice as sc.delta
                sc.sig = sig
        self.k += 1
        base = 0.0 if env.config.residual_actions else env.reference_targets()
        res = self.policy.act(env, obs) - base
        delta = np.concatenate([sc.delta for sc in self.searchers])   # fighters' actions are consecutive
        return np.clip(res + delta, -self.policy.action_clip, self.policy.action_clip) + base


# ----------------------------------------------------------------------------------------------
# loading by name, command line


# spec tokens -> SearchSettings flags
_FLAGS = {"reuse": "reuse", "incr": "incremental", "first": "first_kept", "upfirst": "up_first"}


def load_bout_search(spec: str) -> "BoutSearchTracker":
    """``search[:C,L][:early|full][:reuse][:incr][:first][:upfirst][:heading=W][:yawtol=RAD][:aim=W][:touch=W][:lead=W][:spread=F][:duel][:foresee][:CKPT]``
    -> a BoutSearchTracker: the policy CKPT (default the shipped one) steered by a run-time search
    (default BOUT_SEARCH; C candidates, L look-ahead control steps, early acceptance on or off, and
    the other knobs of research.search_controller.SearchSettings; aim=W: the planned strikes aimed
    with weight W (touch=W: and each rollout step with the strike's fist on a target rewarded with
    W; lead=W: the striker's pelvis kept on its reference from 0.5 s before each planned strike's
    window to its end; spread=F: the arm offsets' sigma times F while aiming); duel: the rollouts in
    a copy of the whole bout, the opponent on its plain policy; foresee: the look-ahead past a
    fighter's current action reads the actions its agent would choose next (PhysicsBout._foresee)
    instead of the action's last frame held still; offline quality, slower than real time)."""
    from tracker.track.policy_net import load_policy
    settings, ckpt, duel, foresee = BOUT_SEARCH, None, False, False
    aimed = {"aim": 0.0, "touch": 0.0, "lead": 0.0, "spread": 1.0}
    for tok in spec.split(":")[1:]:
        c, comma, la = tok.partition(",")
        if comma and c.isdigit() and la.isdigit():
            if int(c) < 1 or int(la) < 0:
                raise ValueError(f"tracker {spec!r}: candidates >= 1 and look-ahead >= 0 control steps")
            settings = replace(settings, candidates=int(c), lookahead=int(la))
        elif tok in ("early", "full"):
            settings = replace(settings, early_accept=tok == "early")
        elif tok in _FLAGS:
            settings = replace(settings, **{_FLAGS[tok]: True})
        elif tok == "duel":
            duel = True
        elif tok == "foresee":
            foresee = True
        elif tok.startswith(("aim=", "touch=", "lead=", "spread=")):
            name, _, val = tok.partition("=")
            try:
                aimed[name] = float(val)
            except ValueError:
                raise ValueError(f"tracker {spec!r}: {name}= needs a number") from None
        elif tok.startswith(("heading=", "yawtol=")):
            name, _, val = tok.partition("=")
            try:
                settings = replace(settings, **{"heading_weight" if name == "heading" else "yaw_tol": float(val)})
            except ValueError:
                raise ValueError(f"tracker {spec!r}: {name}= needs a number") from None
        elif tok:
            ckpt = tok
    return BoutSearchTracker(load_policy(ckpt), settings, aim=aimed["aim"], duel=duel, aim_spread=aimed["spread"],
                             touch=aimed["touch"], lead=aimed["lead"], foresee=foresee)


def load_search_tracker(spec=None):
    """A bout search tracker for a ``search[:...]`` spec (load_bout_search), else the product's
    tracking controller (tracker.bouts.loaders.load_tracker: "pd", a checkpoint, None)."""
    import os

    from tracker.bouts.loaders import load_tracker
    spec = spec if spec is not None else os.environ.get("IGRAPH_FIGHT_TRACKER") or None
    if isinstance(spec, str) and (spec == "search" or spec.startswith("search:")):
        return load_bout_search(spec)
    return load_tracker(spec)


SEARCH_TRACKER_HELP = ("tracking controller: a policy checkpoint, 'pd', or 'search[:C,L][:early|full][:heading=W]"
                       "[:aim=W][:touch=W][:lead=W][:spread=F][:duel][:foresee][:CKPT]' (the policy steered by a "
                       "run-time search: far fewer falls, 0.03-0.3x real time; load_bout_search); default: the "
                       "shipped policy")


def main(argv: list[str] | None = None) -> int:
    """``python -m research.bout_search fight|series|rl-eval ...``: the product's bout commands with
    the search trackers (``--tracker search[:...]``)."""
    import argparse
    import sys

    from tracker.bouts import cli
    p = argparse.ArgumentParser(prog="python -m research.bout_search", description="physics bouts with the bout search")
    sub = p.add_subparsers(dest="cmd", required=True)
    cli.add_fight_arguments(sub.add_parser("fight", help="one physics bout with artifacts"), SEARCH_TRACKER_HELP)
    cli.add_series_arguments(sub.add_parser("series", help="N physics bouts, aggregated"), SEARCH_TRACKER_HELP)
    cli.add_rl_eval_arguments(sub.add_parser("rl-eval", help="planner+tracker fighters vs the RL baseline"),
                              SEARCH_TRACKER_HELP)
    a = p.parse_args(argv)
    try:
        a.tracker = load_search_tracker(a.tracker)
    except (ValueError, FileNotFoundError) as e:
        print(f"python -m research.bout_search: error: {e}", file=sys.stderr)
        return 2
    return {"fight": cli.cmd_physics_fight, "series": cli.cmd_series, "rl-eval": cli.cmd_rl_eval}[a.cmd](a)


if __name__ == "__main__":
    raise SystemExit(main())
