"""The Interaction Graph fighter: an NPCController playing the game API."""
from __future__ import annotations

import time

import numpy as np

from ..controller import NPCController, observe


class IGAgent:
    """Chooses with an NPCController (min-max on the Interaction Graph at the controller's depth).

    snap: when the live state lies within the graph's tolerance of its nearest state, the fighter
    is moved onto that state before acting (the paper's runtime snapping; bounded foot sliding),
    so bouts stay on the graph instead of drifting off it as snapping errors compound.
    Counts decisions, off-graph decisions, snapping displacement and decision time for reports.
    """

    def __init__(self, controller: NPCController, name: str | None = None, snap: bool = True) -> None:
        self.controller = controller
        self.name = name or f"IG({controller.depth})"
        self.snap = snap
        self.decisions = 0
        self.off_graph = 0
        self.decision_s = 0.0
        self.snap_m: list[float] = []
        self.snap_rad: list[float] = []

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        pass

    def step(self, state, player: int) -> int:
        t = time.perf_counter()
        d = self.controller.act(observe(state, player))
        self.decision_s += time.perf_counter() - t
        self.decisions += 1
        self.off_graph += int(d.off_graph)
        if self.snap and not d.off_graph and d.state >= 0:
            g = self.controller.graph.arrays
            dm, dr = state.snap(player, float(g["state_r"][d.state]), float(g["state_theta_self"][d.state]))
            self.snap_m.append(dm)
            self.snap_rad.append(dr)
        return d.action
