"""'human' baseline: a scripted, reactive stand-in for a person issuing high-level commands.

This is a PROXY, not a person. The paper's human player steered an avatar with commands (move
forward / backward, turn left / right, punch, kick, dodge, avoid), the system playing the best
action of the chosen category. This agent issues such commands from simple rules with noise and
perceives the bout with a human reaction delay:

* perception: the bout as it was ``delay_s`` (0.25 s, d frames) ago -- distance, angles and
  the opponent's visible action -- plus Gaussian noise on distance and angle. Both fighters'
  root poses d frames ago are recovered from the live state along their current actions'
  paths (exact unless a push-apart happened meanwhile; clamped at the action's first frame when
  it started less than d frames ago). An opponent action started less than d frames ago is not
  visible yet: the proxy still sees the action the opponent was playing at its own previous
  decision if that was a different one, or nothing;
* rules, in order: with probability ``p_random`` a random legal action (a slip of the thumb);
  if the visible opponent action is an attack and the opponent is within ``threat_m``, dodge
  (a duck or dodge of the menu) with probability ``p_dodge``; if the opponent is more than
  ``turn_deg`` off the facing, turn towards it; if it is beyond the reach of the menu's
  attacks, move forward; if closer than ``too_close_m``, move back; else punch (an attack of the
  menu) with probability ``p_punch``, otherwise hold the guard;
* "the best action of the category" (the paper's interface picked it on the graph): for moves
  and turns the menu action whose root displacement (lib.dx, dz, dheading) brings the fighter
  closest to the goal (distance or facing), assuming the opponent stands still, one of the
  ``pick_top`` best at random; for a punch, the menu attack that lands most hits in one
  simulated event against the opponent standing (frozen in guard) where the proxy perceives it,
  ties at random (agents.static.dummy_tables).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from motion_graph.classify import KINDS

from igraph_fight.agents.common import DEFENCE_KINDS, attack_mask, defence_mask, predicted_relative


@dataclass(frozen=True)
class HumanConfig:
    """Reaction delay (s), rule thresholds (m, degrees) and noise of the proxy."""

    delay_s: float = 0.25
    p_random: float = 0.1
    p_dodge: float = 0.5
    threat_m: float = 1.4
    turn_deg: float = 30.0
    reach_margin_m: float = 0.2
    too_close_m: float = 0.5
    p_punch: float = 0.85
    r_noise_m: float = 0.05
    theta_noise_deg: float = 5.0
    pick_top: int = 2


class HumanProxyAgent:
    """Scripted reactive player with a reaction delay (module docstring)."""

    def __init__(self, config: HumanConfig = HumanConfig(), name: str = "human") -> None:
        self.name = name
        self.config = config
        self._rng = np.random.default_rng(0)
        self._seen: int = -1   # opponent action seen at the previous decision
        self._lib = None
        self.decisions = 0
        self.decision_s = 0.0
        self.commands: dict[str, int] = {}

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        self._rng = rng
        self._seen = -1
        self._prepare(game)

    def _prepare(self, game) -> None:
        if self._lib is game.library:
            return
        lib = game.library
        self._lib = lib
        tables = game.tables
        self._attack = attack_mask(tables)
        self._defence = defence_mask(tables)
        so = np.asarray(lib.strike_offsets)
        reach = np.zeros(lib.n_actions)
        w1 = np.zeros(lib.n_actions, dtype=np.int64)
        for a in range(lib.n_actions):
            if so[a + 1] > so[a]:
                reach[a] = float(np.max(lib.strike_reach[so[a]:so[a + 1]]))
                w1[a] = int(np.max(lib.strike_w1[so[a]:so[a + 1]]))
        self._reach = reach
        self._strike_end = w1  # frame after which the action's strikes are over
        from igraph_fight.agents.static import dummy_tables
        self._dt, self._dummy = dummy_tables(tables)
        self._T = self._dt.kernel_tuple()

    # ----- perception -------------------------------------------------------------------------
    def perceive(self, state, player: int) -> tuple[float, float, float, int, int]:
        """(r, theta_self, theta_other, visible opponent action (-1 if none), its frame) as seen
        ``delay_s`` ago, without noise (module docstring)."""
        o = 1 - player
        d = int(round(self.config.delay_s * state.game.fps))
        w = state.world
        T = state.game.tables
        pose = []
        for i in (0, 1):
            a, f = int(w.action[i]), int(w.frame[i])
            pose.append(_root_back(T, a, f, max(f - d, 0), float(w.x[i]), float(w.z[i]), float(w.heading[i])))
        dx, dz = pose[o][0] - pose[player][0], pose[o][1] - pose[player][1]
        b = math.atan2(dx, dz)
        r = math.hypot(dx, dz)
        ts = (b - pose[player][2] + math.pi) % (2 * math.pi) - math.pi
        to = (b + math.pi - pose[o][2] + math.pi) % (2 * math.pi) - math.pi
        a_o, f_o = int(w.action[o]), int(w.frame[o])
        if f_o >= d:
            return r, ts, to, a_o, f_o - d
        if self._seen >= 0 and self._seen != a_o:
            return r, ts, to, self._seen, int(T.n_frames[self._seen]) - 1
        return r, ts, to, -1, -1

    # ----- decision ---------------------------------------------------------------------------
    def step(self, state, player: int) -> int:
        t0 = time.perf_counter()
        self._prepare(state.game)
        c = self.config
        rng = self._rng
        menu = np.asarray(state.legal_actions(player), dtype=np.int64)
        r, ts, _, m_o, f_o = self.perceive(state, player)
        self._seen = int(state.world.action[1 - player])
        r = max(0.0, r + rng.normal(0.0, c.r_noise_m))
        ts = ts + math.radians(rng.normal(0.0, c.theta_noise_deg))
        if rng.random() < c.p_random:
            cmd, a = "random", int(rng.choice(menu))
        else:
            cmd, a = self._rules(menu, r, ts, m_o, f_o)
        self.commands[cmd] = self.commands.get(cmd, 0) + 1
        self.decision_s += time.perf_counter() - t0
        self.decisions += 1
        return a

    def _rules(self, menu: np.ndarray, r: float, ts: float, m_o: int, f_o: int) -> tuple[str, int]:
        c = self.config
        rng = self._rng
        lib = self._lib
        threat = m_o >= 0 and self._attack[m_o] and f_o < self._strike_end[m_o] and r < c.threat_m
        if threat and rng.random() < c.p_dodge:
            dodges = menu[self._defence[menu]]
            if len(dodges):
                return "dodge", int(rng.choice(dodges))
        r2, th2 = predicted_relative(lib, menu, r, ts)
        if abs(ts) > math.radians(c.turn_deg):
            return "turn", self._best(menu, np.abs(th2))
        attacks = menu[self._attack[menu]]
        reach = self._reach[attacks] + c.reach_margin_m
        if r > (reach.max() if len(attacks) else 0.9):  # any action may serve (no forward step in some libraries)
            return "forward", self._best(menu, r2 + 0.5 * np.abs(th2))
        if r < c.too_close_m:
            return "back", self._best(menu, -r2)
        if rng.random() < c.p_punch and len(attacks):
            return "punch", self._best_punch(attacks, r, ts)
        guards = [int(a) for a in menu if KINDS[int(lib.kinds[a])] == "guard"]
        return "guard", int(rng.choice(guards)) if guards else int(rng.choice(menu))

    def _best_punch(self, attacks: np.ndarray, r: float, ts: float) -> int:
        """The attack with the most hits (then most near misses) in one simulated event against a
        guard dummy at the perceived distance and angle, facing the proxy; ties at random."""
        from igraph_fight import sim
        si = np.array([[int(attacks[0]), self._dummy, 0, 0]], dtype=np.int64)
        sf = np.array([[r, ts, 0.0]])
        _, _, ft, _ = sim.expand_samples(self._T, si, sf, np.zeros(len(attacks), dtype=np.int64), attacks)
        score = ft[:, sim.FT_HITS_SELF] * 100.0 + ft[:, sim.FT_NEAR_SELF]
        top = np.nonzero(score == score.max())[0]
        return int(attacks[top[int(self._rng.integers(len(top)))]])

    def _best(self, acts: np.ndarray, cost: np.ndarray) -> int:
        """One of the ``pick_top`` lowest-cost actions, at random."""
        order = np.argsort(cost, kind="stable")[: max(1, self.config.pick_top)]
        return int(acts[order[int(self._rng.integers(len(order)))]])


def _root_back(T, a: int, f: int, f_back: int, x: float, z: float, h: float) -> tuple[float, float, float]:
    """Root pose (x, z, heading) at frame ``f_back`` of action ``a`` for a fighter whose root is
    at (x, z, h) at frame ``f`` (the same start transform; sim.start_from_root / sim.root_pose)."""
    p = T.path
    g = int(T.frame_offsets[a]) + f
    sh = h - p[g, 2]
    c, s = math.cos(sh), math.sin(sh)
    sx = x - (c * p[g, 0] + s * p[g, 1])
    sz = z - (-s * p[g, 0] + c * p[g, 1])
    g2 = int(T.frame_offsets[a]) + f_back
    return c * p[g2, 0] + s * p[g2, 1] + sx, -s * p[g2, 0] + c * p[g2, 1] + sz, sh + p[g2, 2]


__all__ = ["HumanConfig", "HumanProxyAgent", "DEFENCE_KINDS"]
