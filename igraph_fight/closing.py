"""Closing in: a geometric rule that turns a fighter towards its opponent and walks it into range
before the Interaction Graph decides.

Why: far apart or facing away, the Interaction Graph's values differ between actions by less than
their noise, so the min-max answer does not turn a fighter round; raising the facing weight of
Eq. 4 instead costs the kinematic bouts their hits. The rule is what lets the planner fighters of
a physics bout engage (figures: docs/results.md, "closing rule").

The rule (``ClosingRule.choose``), for the action about to be launched, from the coupled state at
the current action's end (distance r in metres, own facing error theta_self in radians, positive
when the opponent is to the left of the fighting direction):

* engaged (|theta_self| <= ``engage_theta_rad`` and r <= ``engage_r_m``): no answer; the
  Interaction Graph decides;
* otherwise: the rule looks ``depth`` actions ahead through the motion graph (Next(M)) and
  rates each first action by its best sequence: the seconds until the first engaged action end,
  or, for a sequence that does not engage, its seconds plus an optimistic estimate of the rest
  (the facing error beyond ``engage_theta_rad`` at ``turn_rad_s``, the distance beyond
  ``engage_r_m`` at ``approach_m_s``). Among the first actions rated within ``tie_s`` of the
  best it launches the one that progresses fastest now (estimated seconds saved per second
  played). Why not simply the best: the estimate is decided by centimetres of distance, and a
  plan that starts with a near-free guard is re-made with that guard first at every decision
  (measured in a physics bout against the RL baseline: 39 guards of 0.33 s in a row, 2 rad
  away, 3-4 m apart); and why a look-ahead at all: a one-action greedy rule gets caught in the
  graph's loops (from a dodge whose only successors are itself and a jab it dodges on, turning
  away, for 20 actions).

Measured (``python -m research.probes.closing_kinematic``; figures in docs/results.md): the rule
cuts the share of decisions facing more than 1 rad away about threefold and, from 3 m facing away,
engages a fighter in about 8 s (the library has no forward step, so closing in rides on straights
and turns). Known limits: it adds falls in physics bouts, and with the rule on both fighters the
two can circle each other.

Where an action ends comes from its library displacement (dx, dz metres in its own start frame,
dheading radians). Named approximation: the opponent is taken to stand still while the sequence
plays.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def end_geometry(r: float, theta_self: float, dx: np.ndarray, dz: np.ndarray,
                 dheading: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance m, theta_self rad) after each action of displacement (dx, dz, dheading), the
    opponent at distance ``r`` and bearing ``theta_self`` from the fighting direction at the start
    and standing still. Arrays of one length; angles wrapped to [-pi, pi)."""
    # the fighter at the origin facing +Z; the bearing b = atan2(x, z) is measured like a heading,
    # so theta_self = b - heading (igraph_fight.state.relative)
    ox, oz = r * np.sin(theta_self), r * np.cos(theta_self)
    vx, vz = ox - np.asarray(dx, dtype=np.float64), oz - np.asarray(dz, dtype=np.float64)
    th = np.arctan2(vx, vz) - np.asarray(dheading, dtype=np.float64)
    return np.hypot(vx, vz), (th + np.pi) % (2 * np.pi) - np.pi


@dataclass(frozen=True)
class ClosingRule:
    """When the Interaction Graph is left to decide and how a fighter closes in otherwise (module
    docstring). engage_r_m: metres; engage_theta_rad: radians; depth: actions searched ahead;
    turn_rad_s, approach_m_s: the estimate's turning (rad/s) and approach (m/s) speeds; tie_s:
    first actions whose best sequences engage within this many seconds of the best count as tied;
    avoid: library ids the rule does not launch (unless the menu holds nothing else; the graph still
    may, and the look-ahead still passes through them): actions after which the physics fighters fell
    often while closing in (``python -m research.fall_odds``)."""

    engage_r_m: float = 1.6
    engage_theta_rad: float = 1.0
    depth: int = 3
    turn_rad_s: float = 0.4
    approach_m_s: float = 0.1
    tie_s: float = 1.0
    avoid: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        if not self.engage_r_m > 0 or not 0 < self.engage_theta_rad <= np.pi:
            raise ValueError(f"ClosingRule needs engage_r_m > 0 and 0 < engage_theta_rad <= pi, got "
                             f"{self.engage_r_m}, {self.engage_theta_rad}")
        if self.depth < 1 or not self.turn_rad_s > 0 or not self.approach_m_s > 0:
            raise ValueError("ClosingRule needs depth >= 1 and positive turn_rad_s, approach_m_s")

    def engaged(self, r, theta_self):
        """True where the fighter is engaged (scalars or arrays)."""
        return (np.abs(theta_self) <= self.engage_theta_rad) & (r <= self.engage_r_m)

    def _rest(self, r, theta):
        """Optimistic seconds to engage from (r, theta): the facing error beyond engage_theta_rad at
        turn_rad_s plus the distance beyond engage_r_m at approach_m_s."""
        return (np.maximum(np.abs(theta) - self.engage_theta_rad, 0.0) / self.turn_rad_s
                + np.maximum(r - self.engage_r_m, 0.0) / self.approach_m_s)

    def plan(self, menu: np.ndarray, r: float, theta_self: float, library) -> list[int]:
        """The sequence of actions (library ids, the first from ``menu``, each next one in Next of
        the one before; at most ``depth``, ending at the first engaged end) the rule would play, the
        opponent standing still; [] when the fighter is engaged or the menu is empty. ``library``:
        an ActionLibrary (dx, dz, dheading, duration, next_offsets, next_ids)."""
        menu = np.asarray(menu, dtype=np.int64)
        if len(menu) == 0 or self.engaged(r, theta_self):
            return []
        if self.avoid:                                     # not launched by the rule, unless nothing else is legal
            keep = menu[~np.isin(menu, np.asarray(self.avoid, dtype=np.int64))]
            menu = keep if len(keep) else menu
        dur = np.asarray(library.duration, dtype=np.float64)
        rr, th = end_geometry(r, theta_self, library.dx[menu], library.dz[menu], library.dheading[menu])
        # progress of each first action: estimated seconds to engage it saves per second it lasts
        progress = (self._rest(r, theta_self) - self._rest(rr, th)) / dur[menu]
        act, t, fi = menu, dur[menu], np.arange(len(menu))
        levels = [(act, np.full(len(menu), -1))]            # per level: actions, index of the parent node
        best_cost = np.full(len(menu), np.inf)              # per first action: its best sequence's seconds
        best_node = np.zeros((len(menu), 2), dtype=np.int64)  # ... and where that sequence ends (level, node)
        for level in range(self.depth):
            done = self.engaged(rr, th)
            last = level == self.depth - 1
            leaf = last | (library.next_offsets[act + 1] == library.next_offsets[act])   # or a dead end
            cost = np.where(done, t, np.where(leaf, t + self._rest(rr, th), np.inf))
            order = np.argsort(cost, kind="stable")          # the first node per first action is its best
            f, first_at = np.unique(fi[order], return_index=True)
            c, node = cost[order][first_at], order[first_at]
            better = c < best_cost[f]
            best_cost[f[better]] = c[better]
            best_node[f[better]] = np.column_stack([np.full(better.sum(), level), node[better]])
            go = np.flatnonzero(~done & ~leaf)
            if last or len(go) == 0:
                break
            a = act[go]
            lo, n = library.next_offsets[a], library.next_offsets[a + 1] - library.next_offsets[a]
            parent = np.repeat(go, n)
            child = library.next_ids[np.repeat(lo - np.cumsum(np.r_[0, n[:-1]]), n) + np.arange(n.sum())]
            act = child.astype(np.int64)
            rr, th = end_geometry(rr[parent], th[parent], library.dx[act], library.dz[act], library.dheading[act])
            t, fi = t[parent] + dur[act], fi[parent]
            levels.append((act, parent))
        # among the first actions whose best sequence is within tie_s of the best, the one that
        # progresses fastest now (a plan may otherwise start with a near-free guard every time it
        # is made, and a re-planning fighter then never gets to the rest of it)
        tied = np.flatnonzero(best_cost <= best_cost.min() + self.tie_s)
        j = int(tied[np.argmax(progress[tied])])
        out, (level, i) = [], best_node[j]
        while level >= 0:
            out.append(int(levels[level][0][i]))
            i = int(levels[level][1][i])
            level -= 1
        return out[::-1]

    def choose(self, menu: np.ndarray, r: float, theta_self: float, library) -> int | None:
        """The first action of ``plan`` (None when the fighter is engaged or the menu is empty)."""
        p = self.plan(menu, r, theta_self, library)
        return p[0] if p else None

    def rollout(self, library, m: int, r: float, theta_self: float,
                max_s: float = 60.0) -> tuple[float, float, float, list[int]]:
        """Play the rule's answers one after another from the end of action ``m`` at (r m,
        theta_self rad), the opponent standing still, until the fighter is engaged or ``max_s``
        seconds have been played: (seconds played, r, theta_self, actions played)."""
        t, played = 0.0, []
        while t < max_s:
            a = self.choose(library.next(m), r, theta_self, library)
            if a is None:
                break
            r1, th1 = end_geometry(r, theta_self, library.dx[[a]], library.dz[[a]], library.dheading[[a]])
            r, theta_self, m = float(r1[0]), float(th1[0]), a
            t += float(library.duration[a])
            played.append(a)
        return t, r, theta_self, played
