"""Physics bouts: two humanoids in one MuJoCo ring, each driven by an action-choosing agent (an
Interaction Graph NPCController, the physics RL baseline, a script) and executed by the tracking
controller (the learned policy, or PD).

    setup = BoutSetup.create(library)                       # fighter model, 2-fighter scene, env
    agents = [IGAgent(npc_a, snap=False), IGAgent(npc_b, snap=False)]   # igraph_fight.agents.ig
    bout = PhysicsBout(setup, agents, load_policy(ckpt))
    res = bout.run(seed=1)                                  # PhysicsBoutResult
    write_physics_artifacts(bout, res, "out/fight")         # log.jsonl, summary.json, plots, MP4

Set-up, rules and per-fighter bookkeeping: tracker.bouts.setup; agents (the protocol of
igraph_fight.agents.base.Agent: ``step(ctx, player)`` with ctx a DecisionContext, optional
``peek(ctx, player)`` and ``finish(player, reward, steps)``): tracker.bouts.agents; the result
record: tracker.bouts.results; entry points (a bout to its artifacts, series): tracker.bouts.run;
media: tracker.bouts.media.

Rules (what ``run`` does; every number is a BoutConfig field):

* Start: the kinematic game's random start (igraph_fight.game.FightGame.new_initial_state with the
  bout seed: distance 1-3 m, random headings, both at the last frame of a guard action), posed in
  physics. Control at 30 Hz (the library rate), physics at 240 Hz.
* Online references: each fighter's Reference is a buffer over the bout's control steps. When a
  fighter's action ends (``lead`` control steps before its last frame: the tracking policy's
  longest reference horizon, 4 steps for the shipped policy) its agent chooses the next action from the
  coupled state *predicted at the action's end*: each fighter's physical pelvis ground position and
  fighting direction now, moved on by its reference's displacement over the remaining steps. The
  fighting direction is the reference's (placement heading + the library path heading at the
  frame) corrected by the yaw difference between the physical and the reference pelvis. The next
  action's reference is placed at that predicted pose (ActionLibrary.sequence_motion, blended over
  ``blend_frames`` from the previous action's end pose), so the reference is re-anchored on the
  body at every action: root drift never accumulates across actions. Past the current action's
  end the buffer holds that action's last frame still, or, for a search tracker that asks for it
  (``foresee_steps``), the actions the agent would choose next (``_foresee``: guesses for the
  search's rollouts only).
* Coupled state for the agent (igraph_fight.controller.Observation): r, theta_self, theta_other
  from the predicted poses, M_self the finishing action, M_other / F_other the opponent's action
  and frame at that instant, mask_other the opponent's strikes already resolved (planned or hit)
  whose window is still open. When both fighters finish together, the one that did not choose
  last chooses first and the other sees its new action at frame 0 (as in FightState).
* Planned hits: at every decision instant the kinematic simulator (igraph_fight.state.advance,
  frame by frame) runs from that coupled state to the next decision instant; the strikes it judges
  hits are logged as planned (attacker, action instance, strike).
* Realised hits: after every physics substep (TrackingEnv.substep_hook) the contacts of a fist
  geom with the opponent's head, chest or belly geom are read with their normal force. A hit is
  such a contact with force >= ``hit_force_n`` (1 N) inside a strike window of the attacker's
  current action (the window [w0, w1) widened by ``window_slack`` frames: the physical fist lags
  the reference), by the strike's own fist; one hit per strike window (debounced). Fist contacts
  outside a strike window are logged as touches, not hits. Forces are clipped at
  ``force_clip_n`` (200 N) for the damage sum (the competitive-sports paper's r_match).
  A planned hit is realised when the same strike of the same action instance lands physically;
  each planned hit also records ``closest_m``, how near the strike's fist came to the opponent's
  head, chest or belly at the control steps of its open window while both stood (a search tracker
  may aim the open windows: ``planned_windows``), and, at its predicted instant, the physical and
  the predicted pelvis distance and each pelvis's lag behind its reference (``_miss_anatomy``).
* Falls (tracker.body.fall.detect_fall, the one definition: a non-foot geom on the floor, or the pelvis
  35 cm below the reference pelvis): the fall is counted, the fighter lies for ``fall_pause_s``
  (its PD holds its last reference pose; no hits by or on it count), then it is reset to a
  standing guard pose (the first frame of a guard action, chosen with the bout's generator, with
  the reference's velocities) at its reference pelvis ground position when the fall was
  detected (``reset_place="reference"``: where its motion had taken it, the topple
  undone; ``"fall"``: the physical pelvis then, which a topple has already carried 0.5-1.5 m, and
  since the library has no forward step such displacements ratchet the fighters apart), at least
  ``reset_min_distance_m`` from the opponent, and plays that guard action before choosing again.
  It faces the opponent (``reset_facing="opponent"``, the default); ``"fall"`` keeps its fighting
  direction at the fall: a topple often leaves that direction far off, the planner then spends its
  decisions on turns, and the fighters stay apart (docs/tracker.md).
  The library has no get-up motion, so a reset is the rule.
* Score = realised hits of A - realised hits of B (the kinematic bouts' score).
* Per control step and fighter the competitive-sports paper's reward terms are accumulated
  (match: clipped fist force given - received; close: exp(-3 d^2), d the closest distance of the
  fighter's fists to the opponent's head/chest/belly; facing: exp(-5 |v.f - 1|); energy: kappa
  * sum of squared joint angular accelerations, kappa = 1 - exp(-50 max(0, l - 1)^2), the sum
  clipped at ENERGY_CLIP per step; fall); the physics RL baseline (tracker.bouts.rl_agent) learns
  from them, the bout reports their sums. The clip is this module's approximation: a boxer's
  joints stay below it (300 rad/s^2 on all 66 joints is 5.9e6), while a step on which
  MuJoCo reports an unstable simulation and resets the state gives orders of magnitude more
  (enough to move a whole PPO batch's mean reward per decision from about -0.01 to -8e6).
* Real-time factor: simulated seconds / wall seconds of the whole bout loop (decisions,
  references, tracking policy, physics, hit judging), rendering excluded.
"""
from __future__ import annotations

import time
from typing import Callable

import mujoco
import numpy as np

from motion_graph.rotations import quat_mul_wxyz, slerp_wxyz, wrap_angle, yaw_quat_wxyz

from tracker.body.frames import ground_yaw, ground_yaws, z_rotation
from tracker.bouts.agents import DecisionContext
from tracker.bouts.judging import HitJudge
from tracker.bouts.results import PhysicsBoutResult, zero_reward
from tracker.bouts.setup import ActionSegment, BoutConfig, BoutSetup, FighterState

# ----------------------------------------------------------------------------------------------
# the bout

#: per-step ceiling of the energy term's sum of squared joint accelerations ((rad/s^2)^2; module docstring)
ENERGY_CLIP = 1.0e7


class PhysicsBout:
    """One physics bout runner (see the module doc). Reusable: ``run`` resets everything.

    ``tracker``: the tracking controller of the two-fighter env (``reset(env)``, ``act(env, obs)``;
    tracker.bouts.loaders.load_tracker). A tracker may also read what the bout knows ahead: with an
    ``idle`` attribute it is told, before every act, which fighters are down; with ``aiming`` true,
    the planned hits' windows still to come (``aims``, planned_windows); with ``foresee_steps`` > 0
    the references past each current action hold the agents' guessed next actions (``_foresee``).
    An offline search tracker (research/bout_search.py) uses these."""

    def __init__(self, setup: BoutSetup, agents: list, tracker, config: BoutConfig = BoutConfig()) -> None:
        if setup.batched:             # the batched trackers run at their own physics rate
            from dataclasses import replace
            config = replace(config, physics_hz=setup.scene.options.physics_hz)
        if abs(config.physics_hz - setup.scene.options.physics_hz) > 1e-9:
            raise ValueError("BoutConfig.physics_hz differs from the setup's scene")
        self.setup = setup
        self.lib = setup.library
        self.tables = setup.tables
        self.env = setup.env
        self.scene = setup.scene
        self.model = setup.scene.model
        self.agents = list(agents)
        self.tracker = tracker
        self.config = config
        # decisions are made this many control steps before an action ends, so the reference the
        # tracker observes (up to its longest horizon) is always known
        self.lead = int(max(tuple(self.env.config.obs_future) + tuple(getattr(tracker, "obs_future", ()))))
        self.nf = np.asarray(self.tables.n_frames, dtype=np.int64)
        self.fms = setup.scene.fighters
        self.judge = HitJudge(self.model, self.fms, self.lib, config)
        self._trace_tables = None
        # foresight (``_foresee``): how far past a fighter's current action its agent's next actions are guessed
        self._foresee_steps = int(getattr(tracker, "foresee_steps", 0) or 0)
        self.schedule: list[tuple[float, Callable[[], None], str]] = []
        self.hook_gap_m = 0.5

    # ------------------------------------------------------------------ run
    def run(self, seed: int = 0, initial=None, progress: bool = False,
            max_wall_s: float | None = None) -> PhysicsBoutResult:
        """Play one bout (deterministic for a seed on one machine): ``start``, ``step`` until the
        bout's length, ``finish``. ``initial``: a igraph_fight.game.FightState to start from
        instead of the seed's random start. ``max_wall_s``: stop early once the loop has taken this
        many wall-clock seconds (slow trackers); the result then covers the seconds simulated so far
        (its ``seconds``), which per-minute figures divide by. The steps played are the same as a
        full bout's first ones."""
        if max_wall_s is not None and not max_wall_s > 0:
            raise ValueError(f"max_wall_s must be positive seconds, got {max_wall_s}")
        self.start(seed, initial)
        it = range(self.n_steps)
        if progress:
            from tqdm import tqdm
            it = tqdm(it, desc="physics bout", unit="step", mininterval=2.0)
        t_wall = time.perf_counter()
        try:
            for _ in it:
                self.step()
                if max_wall_s is not None and time.perf_counter() - t_wall > max_wall_s:
                    break
        finally:
            self.env.substep_hook = None
        return self.finish(time.perf_counter() - t_wall)

    def start(self, seed: int = 0, initial=None) -> None:
        """Reset everything, draw the initial state, take the first decisions, pose both fighters."""
        from igraph_fight.state import WorldState
        cfg = self.config
        rng = np.random.default_rng(seed)
        env = self.env
        self.seed = seed
        self.n_steps = int(round(cfg.seconds * env.config.control_hz))
        T = self.n_steps + 2 * int(self.nf.max()) + int(cfg.fall_pause_s * 30) + 4 * self.lead + 8
        self.F = [FighterState(k, T, self.fms[k], self.setup) for k in range(2)]
        self.T = T
        self.rng = rng
        self.decisions: list[dict] = []
        self.hit_events: list[dict] = []
        self.planned_events: list[dict] = []
        self.fall_events: list[dict] = []
        self.touch_events: list[dict] = []
        self.notes: list[dict] = []
        self.last_decider = -1
        self._guess: list[tuple[int, int] | None] = [None, None]   # foresight's next action: (step, action)
        self.damage = np.zeros(2)
        self.judge.clear()
        from tracker.track.assist import AssistStats
        self.assist_stats = AssistStats(2)
        self._prev_v = [None, None]
        self._gap = 0.0
        self._pending = sorted(self.schedule, key=lambda x: x[0])
        self.step_reward, self.step_info = None, None
        # initial coupled state: the kinematic game's random start (both at a guard's last frame)
        st = initial if initial is not None else self.setup.game.new_initial_state(rng)
        w0: WorldState = st.world
        for k in range(2):
            f = self.F[k]
            f.segments.append(ActionSegment(-int(self.nf[w0.action[k]]) + 1, int(w0.action[k]), -1))
            f.t_dec_end = 0
            f.start_pose = (float(w0.x[k]), float(w0.z[k]), float(w0.heading[k]))
        for k, ag in enumerate(self.agents):
            ag.reset(self, k, rng)
        # first decisions at t = 0 (no physics yet: the poses are the initial world's)
        self._decide_due(0, initial_world=w0)
        self._obs = env.reset([self.F[0].ref, self.F[1].ref], 0)
        for k in range(2):
            self._foresee(k, 0)
        self.tracker.reset(env)
        if self.setup.root_assist:
            env.set_root_assist(True)
        self._trace = {"t": [], "pose": [], "action": [], "frame": [], "distance": [], "qpos": [], "down": []}
        self._record(self._trace)

    @property
    def observation(self) -> np.ndarray:
        """The tracker's observation of both fighters for the next control step."""
        return self._obs

    def step(self, before_physics: Callable[["PhysicsBout"], None] | None = None) -> None:
        """One control step: scheduled callbacks, tracking controller, physics (contacts judged),
        falls and resets, decisions. ``before_physics(bout)`` runs right before the physics (a test
        may drive a body kinematically there)."""
        env = self.env
        while self._pending and self._pending[0][0] <= env.t / 30.0:
            _, cb, note = self._pending.pop(0)
            cb()
            self.notes.append({"t": round(env.t / 30.0, 4), "note": note})
        if self._foresee_steps:                     # guesses refreshed from the physical state now
            for k in (0, 1):
                self._foresee(k, env.t, record=False)
        if hasattr(self.tracker, "idle"):          # a search tracker skips fallen fighters
            self.tracker.idle = [f.down for f in self.F]
        if getattr(self.tracker, "aiming", False):   # and may aim the planned strikes
            self.tracker.aims = [self.planned_windows(k, env.t) for k in (0, 1)]
        out = self.tracker.act(env, self._obs)
        act, assist = out if isinstance(out, tuple) else (out, None)
        act = np.array(act, dtype=np.float64, copy=True).reshape(-1)
        for f in self.F:
            if f.down:
                na = self.fms[f.k].n_act
                sl = slice(f.k * na, (f.k + 1) * na)
                k_ref = min(env.t + env.config.target_lead, env.t_end)
                act[sl] = (0.0 if getattr(env.config, "residual_actions", False) else f.ref.ctrl[k_ref])
        if self.setup.batched:
            env.batch.assist_enabled[:] = [not f.down for f in self.F]
        self.judge.clear()
        if before_physics is not None:
            before_physics(self)
            self._gap = 0.0
        # contacts are read every substep only when a fist is near a target (a fist moves less
        # than ``hook_gap_m`` in one control step)
        env.substep_hook = self.judge.substep if self._gap < self.hook_gap_m else None
        n_hits = len(self.hit_events)
        obs, rew, _, info = env.step(act, assist) if self.setup.batched else env.step(act)
        self.step_reward, self.step_info = rew, info   # what a trainer in bouts reads
        t = env.t
        self._after_step(t, info)
        if self.setup.batched:
            b = env.batch
            for k in (0, 1):
                if not self.F[k].down:
                    self.assist_stats.add(k, b.assist_force_mg[k], b.assist_torque_mgm[k], b.assist_at_cap[k])
            for h in self.hit_events[n_hits:]:
                h["assist_at_cap"] = bool(b.assist_at_cap[h["attacker"]])
        changed = self._falls_and_resets(t, info)
        changed |= self._decide_due(t)
        self._obs = env._obs_all() if changed else obs
        self._record(self._trace)

    def finish(self, wall_s: float = float("nan")) -> PhysicsBoutResult:
        """The result of the bout so far; learning agents receive their last action's reward."""
        self.env.substep_hook = None
        for k, ag in enumerate(self.agents):
            if hasattr(ag, "finish"):
                ag.finish(k, dict(self.F[k].reward), self.F[k].steps_since)
        self.sim_s = self.env.t / self.env.config.control_hz
        return self._result(self.seed, self._trace, wall_s)

    # ------------------------------------------------------------------ physical state
    def pelvis_xy(self, k: int) -> np.ndarray:
        a = self.fms[k].qpos_adr
        return self.env.data.qpos[a:a + 2].copy()

    def physical_yaw(self, k: int) -> float:
        c = self.env._cache[k]
        return ground_yaw(self.env.data.xmat[c.pelvis].reshape(3, 3), c.lateral)

    def fighting_heading(self, k: int, t: int) -> float:
        """Physical fighting direction now (mocap heading convention, rad)."""
        f = self.F[k]
        return float(wrap_angle(f.fight_heading[t] + wrap_angle(self.physical_yaw(k) - f.ref_yaw[t])))

    def predicted_pose(self, k: int, t_now: int, t_e: int) -> tuple[float, float, float]:
        """(x, z, heading) in the library's ground frame (mocap axes) predicted at step t_e: the
        physical pose now moved by the reference's displacement from t_now to t_e."""
        f = self.F[k]
        te = min(t_e, self.T - 1)
        xy = self.pelvis_xy(k) + (f.ref.qpos[te, :2] - f.ref.qpos[t_now, :2])
        h = wrap_angle(f.fight_heading[te] + wrap_angle(self.physical_yaw(k) - f.ref_yaw[t_now]))
        return float(xy[0]), float(-xy[1]), float(h)

    def world_at(self, t_e: int, t_now: int, initial_world=None):
        """Coupled WorldState predicted at step t_e (igraph_fight.state.WorldState)."""
        from igraph_fight.state import WorldState
        xs, zs, hs, acts, frs, res = [], [], [], [], [], []
        for k in range(2):
            f = self.F[k]
            if initial_world is not None:
                x, z, h = f.start_pose
            else:
                x, z, h = self.predicted_pose(k, t_now, t_e)
            a, fr, inst = f.action_frame(t_e, self.nf)
            xs.append(x), zs.append(z), hs.append(h), acts.append(a), frs.append(fr)
            res.append(f.resolved.get(inst, 0))
        return WorldState(np.array(xs), np.array(zs), np.array(hs), np.array(acts, dtype=np.int64),
                          np.array(frs, dtype=np.int64), np.array(res, dtype=np.int64))

    def features(self, k: int) -> np.ndarray:
        """Physical features of fighter k for a learning agent (own and opponent's body):
        pelvis height, up-vector tilt (2), pelvis velocity in k's facing frame (2) for each fighter,
        closest fist-to-target distances both ways, down flags."""
        d = self.env.data
        out = []
        yaw = self.physical_yaw(k)
        cy, sy = np.cos(yaw), np.sin(yaw)
        for j in (k, 1 - k):
            c = self.env._cache[j]
            R = d.xmat[c.pelvis].reshape(3, 3)
            v = d.qvel[c.qvel.start:c.qvel.start + 2]
            out += [d.xpos[c.pelvis, 2], R[2, 0], R[2, 1], cy * v[0] + sy * v[1], -sy * v[0] + cy * v[1],
                    float(self.F[j].down)]
        out += [self.judge.fist_target_distance(d, k, 1 - k), self.judge.fist_target_distance(d, 1 - k, k)]
        return np.array(out, dtype=np.float64)

    def planned_windows(self, k: int, t: int) -> list[tuple[int, int, int]]:
        """(first step, end step, fist side: 0 left, 1 right, -1 either) of fighter k's planned hits
        that have not landed and whose strike window (widened by ``window_slack``, as judged) has
        not passed at control step t."""
        return [(w0, w1, side) for _, w0, w1, side in self._open_planned(k, t)]

    def _open_planned(self, k: int, t: int) -> list[tuple[dict, int, int, int]]:
        """(planned event, first step, end step, fist side) for planned_windows."""
        f = self.F[k]
        lib = self.lib
        lo, hi = self.config.window_slack
        seg_of = {s.inst: s for s in f.segments[-4:]}
        out = []
        for p in self.planned_events[-40:]:
            seg = seg_of.get(p["inst"]) if p["attacker"] == k else None
            if seg is None or f.realised.get(p["inst"], 0) >> p["strike"] & 1:
                continue
            j = int(lib.strike_offsets[p["action"]]) + p["strike"]
            w1 = seg.t0 + int(lib.strike_w1[j]) + hi
            if w1 > t:
                out.append((p, seg.t0 + int(lib.strike_w0[j]) - lo, w1, int(self.judge.strike_side[j])))
        return out

    # ------------------------------------------------------------------ references
    def _write_segment(self, k: int, t0: int, action: int, prev: int | None, pose: tuple[float, float, float],
                       inst: int) -> None:
        """Place ``action`` with its frame 0 at ``pose`` (x, z, heading; mocap ground frame) and
        write its reference into fighter k's buffer from step t0, the first ``blend_frames`` frames'
        joint rotations blended from ``prev``'s end pose as ActionLibrary.sequence_motion does."""
        lib = self.lib
        X, Z, H = pose
        c = self.setup.action_reference(action)
        n = c["qpos"].shape[0]
        f = self.F[k]
        n_w = min(n, self.T - t0)
        if n_w <= 0:
            return
        Rz, qz = z_rotation(H), yaw_quat_wxyz(H)
        tr = np.array([X, -Z, 0.0])
        qpos = c["qpos"][:n_w].copy()
        qpos[:, :3] = qpos[:, :3] @ Rz.T + tr
        qpos[:, 3:7] = quat_mul_wxyz(qz, qpos[:, 3:7])
        qvel = c["qvel"][:n_w].copy()
        qvel[:, :3] = qvel[:, :3] @ Rz.T
        ctrl = c["ctrl"][:n_w].copy()
        nb = min(self.config.blend_frames, n_w - 1)
        if prev is not None and prev >= 0 and nb > 0:
            pc = self.setup.action_reference(int(prev))
            end = pc["qpos"][-1].copy()
            end[3:7] = quat_mul_wxyz(yaw_quat_wxyz(H - float(lib.dheading[prev])), end[3:7])
            quat_cols = self.setup.quat_cols
            w = 1.0 - (np.arange(nb) + 1) / (nb + 1)
            w[0] = 1.0
            for i in range(nb):
                qpos[i, quat_cols] = slerp_wxyz(qpos[i, quat_cols].reshape(-1, 4), end[quat_cols].reshape(-1, 4),
                                            float(w[i])).ravel()
            ctrl[:nb] = self.setup.ctrl_of(qpos[:nb])
        sl = slice(t0, t0 + n_w)
        sites = c["sites"][:n_w] @ Rz.T + tr
        yaw = c["yaw"][:n_w] + H
        if prev is not None and prev >= 0 and nb > 0:
            sites[:nb] = self.setup.sites_of(qpos[:nb])
            yaw[:nb] = ground_yaws(qpos[:nb, 3:7], self.env._cache[0].lateral)
        f.ref.qpos[sl] = qpos
        f.ref.qvel[sl] = qvel
        f.ref.ctrl[sl] = ctrl
        f.ref.ctrl_vel[sl] = c["ctrl_vel"][:n_w]
        f.ref.sites[sl] = sites
        g0 = int(lib.frame_offsets[action])
        f.fight_heading[sl] = H + lib.path[g0:g0 + n_w, 2]
        f.ref_yaw[sl] = yaw
        f.ref.meta[f"_balance_f{k}"][sl] = c["balance"][:n_w]
        if self.setup.batched:
            self._write_tables(k, sl, c["tables"], n_w, Rz, tr, H, qpos[:nb] if prev is not None and prev >= 0
                               and nb > 0 else None)
        self._hold_after(k, t0 + n_w - 1)

    def _write_tables(self, k: int, sl: slice, tab: dict, n_w: int, Rz: np.ndarray, tr: np.ndarray, H: float,
                      blended: np.ndarray | None) -> None:
        """The batched observation's reference tables of a placed action (facing-frame rows as they
        are, world rows rotated by the placement); blended first frames recomputed from their poses."""
        out = self.F[k].ref.meta[f"batch_tables_{k}"]
        out["R"][sl] = np.einsum("ij,tjk->tik", Rz, tab["R"][:n_w])
        out["yaw"][sl] = tab["yaw"][:n_w] + H
        out["up"][sl] = tab["up"][:n_w] @ Rz.T
        out["ee"][sl] = tab["ee"][:n_w]
        out["com"][sl] = tab["com"][:n_w] @ Rz.T + tr
        out["com_vel"][sl] = tab["com_vel"][:n_w] @ Rz.T
        out["com_feet"][sl] = tab["com_feet"][:n_w]
        out["com_vel_f"][sl] = tab["com_vel_f"][:n_w]
        if blended is not None and len(blended):
            b = self.setup.tables_of(blended)
            n = len(blended)
            rows = slice(sl.start, sl.start + n)
            for key in ("R", "yaw", "up", "ee", "com", "com_feet"):
                out[key][rows] = b[key][:n]

    def _hold_after(self, k: int, t_last: int) -> None:
        """Fill the buffer after step t_last with that frame held still (a placeholder, so the
        tracker's look-ahead never reads an unwritten frame)."""
        f = self.F[k]
        sl = slice(t_last + 1, self.T)
        if sl.start >= self.T:
            return
        f.ref.qpos[sl] = f.ref.qpos[t_last]
        f.ref.qvel[sl] = 0.0
        f.ref.ctrl[sl] = f.ref.ctrl[t_last]
        f.ref.ctrl_vel[sl] = 0.0
        f.ref.sites[sl] = f.ref.sites[t_last]
        f.fight_heading[sl] = f.fight_heading[t_last]
        f.ref_yaw[sl] = f.ref_yaw[t_last]
        bal = f.ref.meta[f"_balance_f{k}"]
        bal[sl] = bal[t_last]
        bal[sl, 3:6] = 0.0
        tab = f.ref.meta.get(f"batch_tables_{k}")
        if tab is not None:
            for key in ("R", "yaw", "up", "ee", "com", "com_feet"):
                tab[key][sl] = tab[key][t_last]
            tab["com_vel"][sl] = 0.0
            tab["com_vel_f"][sl] = 0.0

    def _foresee(self, k: int, t: int, record: bool = True) -> None:
        """Foresight for a search tracker's look-ahead (``tracker.foresee_steps`` > 0): past fighter
        k's current action, write into its reference buffer the actions its agent would choose
        (``agent.peek``, no side effects), each from the coupled state predicted at the end of the
        one before, until ``foresee_steps`` past the current action's end, instead of that action's
        last frame held still. A guess, named approximation: the real decision (``lead`` steps
        before the action's end, from the physical state then) may differ, and rewrites the buffer
        from its own step. Each guessed action starts one frame after the previous one's last frame
        (a real decision overwrites that last frame, which the decisions' own predictions read, so
        the guesses leave it alone); the opponent's action and frame are its real ones (clamped at
        the last frame). The tracking policy never reads these frames (its horizon, ``lead``, ends
        where the next real decision writes), only the search's rollouts do. Called after every
        decision and reset (``record``: the first guess is kept, and the decision it guessed logs
        ``foreseen``, whether it was right) and, from the physical state then, before every control
        step's tracking (so the guesses the search reads are at most one step old)."""
        f = self.F[k]
        agent = self.agents[k]
        if record:
            self._guess[k] = None
        if not self._foresee_steps or f.down or not hasattr(agent, "peek"):
            return
        a_prev = f.segments[-1].action
        t_end = f.t_dec_end
        stop = min(f.t_dec_end + self._foresee_steps, self.T - 2)
        while t_end < stop:
            world = self.world_at(t_end, t)
            # the guessed action at its last frame (the segments hold only real actions)
            world.action[k], world.frame[k], world.resolved[k] = a_prev, int(self.nf[a_prev]) - 1, 0
            obs, _, _ = self._observation(world, k)
            menu = self.tables.menu(a_prev)
            if len(menu) == 0:
                return
            ctx = DecisionContext(k, t_end / 30.0, obs, menu, world, self.features(k), dict(f.reward), f.steps_since)
            a = int(agent.peek(ctx, k))
            if a not in set(int(x) for x in menu):
                return
            if record and self._guess[k] is None:
                self._guess[k] = (t_end, a)
            pose = (float(world.x[k]), float(world.z[k]), float(world.heading[k]))
            self._write_segment(k, t_end + 1, a, a_prev, pose, -1)
            t_end = t_end + int(self.nf[a])
            a_prev = a

    def _observation(self, world, k: int):
        """(igraph_fight.controller.Observation, sample ints, sample floats) of ``world`` seen by fighter k."""
        from igraph_fight.controller import Observation
        from igraph_fight.state import to_sample
        from igraph_fight import sim as ksim
        si, sf = to_sample(self.tables, world, k)
        obs = Observation(float(sf[ksim.SF_R]), float(sf[ksim.SF_TH_SELF]), float(sf[ksim.SF_TH_OTHER]),
                          int(si[ksim.SI_MSELF]), int(si[ksim.SI_MOTHER]), int(si[ksim.SI_FOTHER]),
                          int(si[ksim.SI_MASK]))
        return obs, si, sf

    # ------------------------------------------------------------------ decisions
    def _decide_due(self, t: int, initial_world=None) -> bool:
        """Ask every fighter whose action ends within ``lead`` steps for its next action; then
        predict the planned hits of each new decision instant. Returns True if a reference changed."""
        from igraph_fight import sim as ksim
        due = [k for k in range(2) if not self.F[k].down and t >= self.F[k].t_dec_end - self.lead
               and self.F[k].t_dec_end < self.n_steps + self.lead + 1]
        if not due:
            return False
        first = 1 if self.last_decider == 0 else 0
        due.sort(key=lambda k: (self.F[k].t_dec_end, 0 if k == first else 1))
        instants = []
        for k in due:
            f = self.F[k]
            t_e = f.t_dec_end
            world = self.world_at(t_e, t, initial_world)
            obs, si, sf = self._observation(world, k)
            menu = self.tables.menu(int(world.action[k]))
            ctx = DecisionContext(k, t_e / 30.0, obs, menu, world,
                                  self.features(k) if initial_world is None else np.zeros(14), dict(f.reward),
                                  f.steps_since)
            a = int(self.agents[k].step(ctx, k))
            if a not in set(int(x) for x in menu):
                raise ValueError(f"agent {self.agents[k].name} chose {a}, not in Next({int(world.action[k])})")
            f.reward = zero_reward()
            f.steps_since = 0
            prev = int(world.action[k])
            pose = (float(world.x[k]), float(world.z[k]), float(world.heading[k]))
            f.n_inst += 1
            inst = f.n_inst
            f.segments.append(ActionSegment(t_e, a, inst))
            f.resolved[inst] = 0
            self._write_segment(k, t_e, a, prev, pose, inst)
            f.t_dec_end = t_e + int(self.nf[a]) - 1
            self.last_decider = k
            label = self.lib.labels[a]
            self.decisions.append({"t": round(t_e / 30.0, 4), "player": k, "action": a, "label": label,
                                   "kind": label, "distance_m": round(float(sf[ksim.SF_R]), 4),
                                   "theta_self": round(float(sf[ksim.SF_TH_SELF]), 4),
                                   "theta_other": round(float(sf[ksim.SF_TH_OTHER]), 4),
                                   "m_other": int(si[ksim.SI_MOTHER]), "f_other": int(si[ksim.SI_FOTHER]),
                                   "decided_at": round(t / 30.0, 4)})
            g = self._guess[k]
            if g is not None and g[0] == t_e:      # foresight's guess for this decision (self._foresee)
                self.decisions[-1]["foreseen"] = g[1] == a
            if t_e not in instants:
                instants.append(t_e)
        for t_e in instants:
            self._predict(t_e, t, initial_world)
        if initial_world is None:
            for k in due:
                self._foresee(k, t)
        return True

    def _predict(self, t_e: int, t_now: int, initial_world=None) -> None:
        """Planned hits: the kinematic simulator from the coupled state at t_e to the next decision."""
        from igraph_fight.state import advance
        if any(f.down for f in self.F):
            return
        if self._trace_tables is None:
            from dataclasses import replace
            self._trace_tables = replace(self.tables, params=replace(self.tables.params, max_event_frames=1))
        world = self.world_at(t_e, t_now, initial_world)
        insts = [self.F[k].action_frame(t_e, self.nf)[2] for k in range(2)]
        nf = self.nf
        frames = 0
        while frames < 400:
            if any(world.frame[i] >= nf[world.action[i]] - 1 for i in (0, 1)):
                break
            before = world.resolved.copy()
            world, ev = advance(self._trace_tables, world)
            frames += ev.frames
            if ev.frames == 0:
                break
            for i in (0, 1):
                new = int(world.resolved[i]) & ~int(before[i])
                if not new:
                    continue
                nh = int(round(ev.hits[i]))
                a = int(world.action[i])
                s0 = int(self.lib.strike_offsets[a])
                bits = [j for j in range(int(self.lib.strike_offsets[a + 1]) - s0) if new >> j & 1]
                self.F[i].resolved[insts[i]] = self.F[i].resolved.get(insts[i], 0) | new
                for j in bits[:nh]:
                    self.planned_events.append({
                        "t": round((t_e + frames) / 30.0, 4), "step": t_e + frames, "attacker": i, "victim": 1 - i,
                        "action": a, "kind": self.lib.labels[a], "strike": j, "inst": insts[i],
                        "frame": int(world.frame[i])})

    def _after_step(self, t: int, info) -> None:
        """Judge the contacts of the step's substeps (hits, touches), accumulate rewards."""
        self.judge.judge(t, self.F, self.planned_events, self.hit_events, self.touch_events)
        # rewards (per control step, the competitive-sports paper's terms)
        d = self.env.data
        given = self.judge.step_force.copy() if not (self.F[0].down or self.F[1].down) else np.zeros(2)
        self.damage += given
        p0, p1 = self.pelvis_xy(0), self.pelvis_xy(1)
        l = float(np.linalg.norm(p1 - p0))
        kappa = 1.0 - np.exp(-50.0 * max(0.0, l - 1.0) ** 2)
        gaps = []
        for k in (0, 1):
            f = self.F[k]
            o = 1 - k
            v = (p1 - p0) if k == 0 else (p0 - p1)
            v = v / max(np.linalg.norm(v), 1e-9)
            h = self.fighting_heading(k, t)
            # facing vector in MuJoCo axes: mocap heading h faces (sin h, cos h) in (x, z) -> (x, -y)
            fv = np.array([np.sin(h), -np.cos(h)])
            qv = d.qvel[self.fms[k].qvel_slice][6:].copy()
            energy = 0.0
            if self._prev_v[k] is not None:
                acc = (qv - self._prev_v[k]) * self.env.config.control_hz
                energy = float(kappa * min(float(acc @ acc), ENERGY_CLIP))
            self._prev_v[k] = qv
            gap = self.judge.fist_target_distance(self.env.data, k, o)
            gaps.append(gap)
            inc = {"match": float(given[k] - given[o]), "given_n": float(given[k]), "received_n": float(given[o]),
                   "close": float(np.exp(-3.0 * gap ** 2)),
                   "facing": float(np.exp(-5.0 * abs(float(v @ fv) - 1.0))), "energy": energy}
            for key, val in inc.items():
                f.reward[key] += val
                f.reward_total[key] += val
            f.steps_since += 1
        self._gap = min(gaps)
        self._miss_anatomy(t)
        # how near each planned hit's fist came while its window was open (m; the log's closest_m)
        for k in (0, 1):
            if self.F[k].down or self.F[1 - k].down:
                continue
            for p, w0, w1, side in self._open_planned(k, t):
                if w0 <= t < w1:
                    g = self.judge.fist_target_distance(d, k, 1 - k, side)
                    p["closest_m"] = round(min(p.get("closest_m", np.inf), g), 4)

    def _miss_anatomy(self, t: int) -> None:
        """At a planned hit's predicted instant, where the bodies are against the prediction (m):
        ``distance_m`` the physical pelvis distance, ``ref_distance_m`` the references' (the
        prediction: both references were placed at the predicted poses of the decision that planned
        the hit, and neither fighter decides again before it), and how far each pelvis lags its
        reference along the line between them (``lag_attacker_m``: positive when the attacker is
        farther back than its reference, ``lag_victim_m``: positive when the victim is farther
        away); distance_m is ref_distance_m + both lags, plus what lies sideways."""
        if self.F[0].down or self.F[1].down:
            return
        for p in self.planned_events[-40:]:
            if p["step"] != t or "distance_m" in p:
                continue
            a, v = p["attacker"], p["victim"]
            pa, pv = self.pelvis_xy(a), self.pelvis_xy(v)
            ra, rv = self.F[a].ref.qpos[t, :2], self.F[v].ref.qpos[t, :2]
            u = (rv - ra) / max(float(np.linalg.norm(rv - ra)), 1e-9)     # attacker -> victim, reference
            p["distance_m"] = round(float(np.linalg.norm(pv - pa)), 4)
            p["ref_distance_m"] = round(float(np.linalg.norm(rv - ra)), 4)
            p["lag_attacker_m"] = round(float((ra - pa) @ u), 4)
            p["lag_victim_m"] = round(float((pv - rv) @ u), 4)

    # ------------------------------------------------------------------ falls
    def _falls_and_resets(self, t: int, info) -> bool:
        cfg = self.config
        changed = False
        for k in (0, 1):
            f = self.F[k]
            if not f.down and info.fall[k] is not None:
                f.down = True
                f.reset_at = t + max(1, int(round(cfg.fall_pause_s * 30)))
                f.reward["fall"] += 1.0
                f.reward_total["fall"] += 1.0
                g = int(self.rng.choice(self.setup.game.start_actions))
                f.n_inst += 1
                f.segments = [s for s in f.segments if s.t0 <= t]
                f.segments.append(ActionSegment(t, g, -f.n_inst, hold=True))
                f.pending_guard = g
                xy = f.ref.qpos[t, :2].copy() if cfg.reset_place == "reference" else self.pelvis_xy(k)
                f.fall_pose = (xy, self.fighting_heading(k, t))
                self._hold_after(k, t)
                self._guess[k] = None
                f.t_dec_end = f.reset_at + int(self.nf[g]) - 1
                self.fall_events.append({"t": round(t / 30.0, 4), "player": k, "reason": info.fall[k],
                                         "reset_t": round(f.reset_at / 30.0, 4)})
                changed = True
            elif f.down and t >= f.reset_at:
                self._reset_fighter(k, t)
                changed = True
        return changed

    def _reset_fighter(self, k: int, t: int) -> None:
        f = self.F[k]
        o = 1 - k
        g = f.pending_guard
        xy, h = f.fall_pose
        xy = xy.copy()
        oxy = self.pelvis_xy(o)
        dv = xy - oxy
        dist = float(np.linalg.norm(dv))
        if dist < self.config.reset_min_distance_m:
            u = dv / dist if dist > 1e-6 else np.array([1.0, 0.0])
            xy = oxy + u * self.config.reset_min_distance_m
        if self.config.reset_facing == "opponent":
            # mocap heading h faces (sin h, -cos h) in MuJoCo (x, y); the guard's own path heading at
            # its frame 0 is taken off so that the fighting direction points at the opponent
            v = oxy - xy
            h = float(wrap_angle(np.arctan2(v[0], -v[1]) - self.lib.path[int(self.lib.frame_offsets[g]), 2]))
        f.n_inst += 1
        inst = f.n_inst
        f.segments.append(ActionSegment(t, g, inst))
        f.resolved[inst] = 0
        self._write_segment(k, t, g, None, (float(xy[0]), float(-xy[1]), h), inst)
        fm = self.fms[k]
        d = self.env.data
        d.qpos[fm.qpos_slice] = f.ref.qpos[t]
        d.qvel[fm.qvel_slice] = f.ref.qvel[t]
        mujoco.mj_forward(self.model, d)
        f.down = False
        f.t_dec_end = t + int(self.nf[g]) - 1
        self._foresee(k, t)
        self._prev_v[k] = None
        self.notes.append({"t": round(t / 30.0, 4), "note": f"{'AB'[k]} reset to guard after a fall"})

    # ------------------------------------------------------------------ trace and result
    def _record(self, tr: dict) -> None:
        t = self.env.t
        poses, acts, frs = [], [], []
        for k in range(2):
            xy = self.pelvis_xy(k)
            poses.append([xy[0], -xy[1], self.fighting_heading(k, t)])
            a, fr, _ = self.F[k].action_frame(t, self.nf)
            acts.append(a)
            frs.append(fr)
        tr["t"].append(t / 30.0)
        tr["pose"].append(poses)
        tr["action"].append(acts)
        tr["frame"].append(frs)
        tr["distance"].append(float(np.hypot(poses[1][0] - poses[0][0], poses[1][1] - poses[0][1])))
        tr["down"].append([self.F[0].down, self.F[1].down])
        if self.config.record_qpos:
            tr["qpos"].append(self.env.data.qpos.copy())

    def _result(self, seed: int, tr: dict, wall: float) -> PhysicsBoutResult:
        trace = {k: np.array(v) for k, v in tr.items()}
        hits = np.zeros(2)
        for h in self.hit_events:
            hits[h["attacker"]] += 1
        planned = np.zeros(2)
        pr = np.zeros(2)
        ps = np.zeros(2)
        psr = np.zeros(2)
        down = trace["down"]
        landed = {(h["attacker"], h["inst"], h["strike"]) for h in self.hit_events}
        for p in self.planned_events:
            if p["step"] > self.env.t:
                continue
            a = p["attacker"]
            planned[a] += 1
            ok = (a, p["inst"], p["strike"]) in landed
            p["realised"] = ok
            pr[a] += ok
            s = min(p["step"], len(down) - 1)
            lo = max(0, s - 12)
            if not down[lo:s + 1].any():
                ps[a] += 1
                psr[a] += ok
        self.planned_events = [p for p in self.planned_events if p["step"] <= self.env.t]
        falls = np.array([sum(1 for e in self.fall_events if e["player"] == k) for k in (0, 1)])
        touches = np.array([sum(1 for e in self.touch_events if e["attacker"] == k) for k in (0, 1)])
        c = self.config
        rewards = []
        for f in self.F:
            r = {k: round(v, 4) for k, v in f.reward_total.items()}
            r["total"] = round(r["match"] + c.w_close * r["close"] + c.w_facing * r["facing"]
                               - c.w_energy * r["energy"] - c.w_penalty * r["fall"], 4)
            rewards.append(r)
        info = []
        for ag in self.agents:
            d = {"name": ag.name}
            if hasattr(ag, "off_graph"):
                d.update(decisions=ag.decisions, off_graph=ag.off_graph)
            if hasattr(ag, "closing"):
                d["closing"] = ag.closing       # decisions taken by the closing rule (ClosingAgent)
            info.append(d)
        assist, label = None, "physics (no assist)"
        if self.setup.batched:
            acfg = self.env.config.assist
            mass = float(self.env.batch.mass[0])
            assist = [self.assist_stats.summary(k, mass, acfg.cap if acfg.active else 0.0) for k in (0, 1)]
            label = acfg.label()
        return PhysicsBoutResult(
            (self.agents[0].name, self.agents[1].name), self.sim_s, seed, hits, planned, pr, ps, psr, falls,
            self.damage.copy(), touches, self.decisions, self.hit_events, self.planned_events, self.fall_events,
            self.touch_events, self.notes, trace, rewards, wall, self.sim_s,
            getattr(self.tracker, "describe", lambda: getattr(self.tracker, "name", "?"))(), info, assist, label)
