"""Helpers shared by the baseline agents: styles, the Eq. 4 reward of a game event, geometry.

The reward is the planner's Eq. 4 (planner.rewards) evaluated on the same edge features the
Interaction Graph stores (docs/contracts.md), so the game-tree, static and RL baselines optimise
exactly what the IG fighter optimises. ``EventReward`` is a plain-Python transcription for one
event at a time (the RL loop calls it ~10^6 times); tests check it against planner.edge_rewards.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from motion_graph.classify import ATTACK_KINDS, KINDS
from planner import Style, load_style
from motion_graph.rotations import wrap_angle
from planner.rewards import DISTANCE_FEATURES, kind_preferences

DEFENCE_KINDS = ("duck", "dodge")
MOVE_KINDS = ("step_forward", "step_back", "step_left", "step_right", "turn_left", "turn_right")


def as_style(style: Style | str | Path) -> Style:
    return style if isinstance(style, Style) else load_style(style)


def attack_mask(tables) -> np.ndarray:
    """(A,) bool: actions whose kind is an attack."""
    ids = [KINDS.index(k) for k in ATTACK_KINDS if k in KINDS]
    return np.isin(tables.kinds, ids)


def defence_mask(tables) -> np.ndarray:
    ids = [KINDS.index(k) for k in DEFENCE_KINDS if k in KINDS]
    return np.isin(tables.kinds, ids)


class EventReward:
    """Eq. 4 reward of one game event for a watched fighter (the planner's formula, per event).

    An event is a decision by ``decider`` (launching ``action`` while the other plays
    ``m_other``) followed by the simulation up to the next decision instant. Its edge features
    are those of the graph's edges: distance and angles at the next decision, damage dealt and
    taken, defences, the two action kinds. ``reward(...)`` returns W_me when the watched fighter
    decided and W_opp when the other did (planner.rewards docstring).
    """

    def __init__(self, style: Style, tables) -> None:
        self.style = style
        self.pref = kind_preferences(style, list(KINDS))
        self.kinds = np.asarray(tables.kinds)
        self.fps = float(tables.fps)
        self.mean = DISTANCE_FEATURES[style.distance] == "feat_r_mean"

    def reward(self, watched: int, decider: int, action: int, m_other: int, ev, world) -> float:
        """``ev`` the game's EventResult after the decision (None: a zero-length event, another
        decision follows at once); ``world`` the world state after it."""
        s = self.style
        o = 1 - decider
        dx = float(world.x[o] - world.x[decider])
        dz = float(world.z[o] - world.z[decider])
        r_end = math.hypot(dx, dz)
        b = math.atan2(dx, dz)
        th_d = wrap_angle(b - float(world.heading[decider]))
        th_o = wrap_angle(b + math.pi - float(world.heading[o]))
        if ev is None:
            dur, r_mean, dmg, dfd = 0.0, r_end, (0.0, 0.0), (0.0, 0.0)
        else:
            dur, r_mean, dmg, dfd = ev.frames / self.fps, (ev.r_mean if ev.frames else r_end), ev.damage, ev.defended
        r = r_mean if self.mean else r_end
        pd = s.w_d * (r - s.d_p) ** 2
        given, received = float(dmg[o]), float(dmg[decider])  # damage[i] is damage *received* by i
        if watched == decider:
            pos = s.w_theta * th_d * th_d + pd
            if s.per_second:
                pos *= dur
            return (-pos + s.w_dmg_given * given * self._pref(action) - s.w_dmg_received * received
                    + s.w_def * float(dfd[decider]))
        pos = s.w_theta * th_o * th_o + pd
        if s.per_second:
            pos *= dur
        return (-pos + s.w_dmg_given * received * self._pref(m_other) - s.w_dmg_received * given
                + s.w_def * float(dfd[o]))

    def _pref(self, action: int) -> float:
        k = int(self.kinds[action])
        return float(self.pref[k]) if 0 <= k < len(self.pref) else 1.0


def predicted_relative(lib, actions: np.ndarray, r: float, theta_self: float) -> tuple[np.ndarray, np.ndarray]:
    """Distance and own angle to a *standing* opponent after each action (from the library's
    root displacement of the action; the opponent assumed still). Used by the scripted proxy."""
    a = np.asarray(actions, dtype=np.int64)
    ox, oz = r * math.sin(theta_self), r * math.cos(theta_self)
    vx = ox - np.asarray(lib.dx)[a]
    vz = oz - np.asarray(lib.dz)[a]
    r2 = np.hypot(vx, vz)
    th2 = wrap_angle(np.arctan2(vx, vz) - np.asarray(lib.dheading)[a])
    return r2, th2
