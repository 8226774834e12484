"""Game-tree baseline (after Shum et al. 2007): depth-limited min-max on the exact simulator.

At each of its decisions the fighter expands the game tree from the live coupled state with the
exact, unclustered kinematic simulator (igraph_fight.sim, the kernel the Interaction Graph was
sampled with) and scores every simulated event with the same Eq. 4 reward as the IG fighter
(planner.rewards.fight_edge on the same edge features), with no value at the leaves. The search
itself is igraph_fight.search (alpha-beta, one numba call).
"""
from __future__ import annotations

import time

import numpy as np

from igraph_fight import sim
from igraph_fight.agents.common import as_style
from igraph_fight.search import NO_INDEX_PC, NO_INDEX_PF, NO_INDEX_PI, NO_VALUES, search
from igraph_fight.state import to_sample
from planner.rewards import style_params


class GameTreeSearch:
    """Min-max over the exact simulator for one set of simulator tables and one style."""

    def __init__(self, tables, style="infighter", depth: int = 2, gamma: float = 1.0, prune: bool = True) -> None:
        from motion_graph.classify import KINDS
        from planner.rewards import kind_preferences

        if depth < 1:
            raise ValueError("depth must be >= 1")
        self.tables = tables
        self.style = as_style(style)
        self.depth = int(depth)
        self.gamma = float(gamma)
        self.prune = bool(prune)
        self._T = tables.kernel_tuple()
        self._off = np.asarray(tables.next_offsets, dtype=np.int64)
        self._ids = np.asarray(tables.next_ids, dtype=np.int64)
        self._kinds = np.asarray(tables.kinds, dtype=np.int32)
        self._P = style_params(self.style)
        self._pref = kind_preferences(self.style, list(KINDS))
        self._max_menu = int(max(1, np.diff(self._off).max()))
        self.count = np.zeros(2, dtype=np.int64)  # events simulated, nodes expanded
        self._no_leaf = (NO_INDEX_PI, NO_INDEX_PF, NO_INDEX_PC, NO_VALUES, NO_VALUES)

    def search(self, si: np.ndarray, sf: np.ndarray) -> tuple[int, float]:
        """(action, root value) for a canonical sample (igraph_fight.state.to_sample)."""
        si = np.ascontiguousarray(si, dtype=np.int64)
        sf = np.ascontiguousarray(sf, dtype=np.float64)
        v, j = search(self._T, self._off, self._ids, self._kinds, self._P, self._pref, float(self.tables.fps),
                      si, sf, self.depth, self.gamma, self.prune, self._max_menu, self.count, True, *self._no_leaf)
        m = int(si[sim.SI_MSELF])
        if j < 0:
            return int(self._ids[self._off[m]]) if self._off[m + 1] > self._off[m] else -1, 0.0
        return int(self._ids[self._off[m] + j]), float(v)

    def root_q(self, si: np.ndarray, sf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(menu actions, exact min-max value of launching each one) at this depth: its Eq. 4
        reward plus the depth-1 search below it (for diagnostics: regret of another policy)."""
        from motion_graph.classify import KINDS
        from planner import edge_rewards

        from igraph_fight.build.edge_features import edge_features
        si = np.ascontiguousarray(si, dtype=np.int64)
        sf = np.ascontiguousarray(sf, dtype=np.float64)
        acts = self.tables.menu(int(si[sim.SI_MSELF])).astype(np.int64)
        ci, cf, ft, sw = sim.expand_samples(self._T, si[None], sf[None], np.zeros(len(acts), dtype=np.int64), acts)
        w_me, _ = edge_rewards(edge_features(self.tables, np.full(len(acts), si[sim.SI_MOTHER]), acts, ft), self.style,
                               list(KINDS))
        q = w_me.astype(np.float64).copy()
        if self.depth > 1:
            for k in range(len(acts)):
                v, _ = search(self._T, self._off, self._ids, self._kinds, self._P, self._pref, float(self.tables.fps),
                              ci[k], cf[k], self.depth - 1, self.gamma, self.prune, self._max_menu, self.count,
                              bool(sw[k] == 0), *self._no_leaf)
                q[k] += self.gamma * v
        return acts, q


class GameTreeAgent:
    """The game-tree fighter on the game API (agents.base.Agent). Records its decision time."""

    def __init__(self, depth: int = 2, style="infighter", gamma: float = 1.0, prune: bool = True,
                 name: str | None = None) -> None:
        self.depth = int(depth)
        self.style = as_style(style)
        self.gamma = gamma
        self.prune = prune
        self.name = name or f"gametree{depth}"
        self._search: GameTreeSearch | None = None
        self.decisions = 0
        self.decision_s = 0.0

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        if self._search is None or self._search.tables is not game.tables:
            self._search = GameTreeSearch(game.tables, self.style, self.depth, self.gamma, self.prune)

    def step(self, state, player: int) -> int:
        if self._search is None or self._search.tables is not state.game.tables:
            self.reset(state.game, player, np.random.default_rng(0))
        t = time.perf_counter()
        si, sf = to_sample(state.game.tables, state.world, player)
        a, _ = self._search.search(si, sf)
        self.decision_s += time.perf_counter() - t
        self.decisions += 1
        return a

    @property
    def events(self) -> int:
        return int(self._search.count[0]) if self._search is not None else 0
