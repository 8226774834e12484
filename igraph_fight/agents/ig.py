"""The Interaction Graph fighter: an NPCController playing the game API."""
from __future__ import annotations

import time

import numpy as np

from ..controller import NPCController, observe


class IGAgent:
    """Chooses with an NPCController (min-max on the Interaction Graph at the controller's depth).

    snap: when the live state lies within the graph's tolerance of its nearest state it is moved
    onto that state before acting, so bouts stay on the graph instead of drifting off it as
    landing errors compound. "full" (default): the whole coupled state (the fighter's distance and
    angle, the other's angle and clip frame), as in the paper's runtime where both avatars move
    on the graph; "self"/True: only this fighter's distance and angle; False: no snapping.
    Counts decisions, off-graph decisions, snapping displacement and decision time for reports.
    """

    def __init__(self, controller: NPCController, name: str | None = None, snap: bool | str = "full") -> None:
        self.controller = controller
        self.name = name or f"IG({controller.depth})"
        self.snap = snap
        self.decisions = 0
        self.off_graph = 0
        self.decision_s = 0.0
        self.snap_m: list[float] = []
        self.snap_rad: list[float] = []
        self.snap_frames: list[int] = []

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
            s = d.state
            if self.snap == "full" and int(g["state_f_other"][s]) >= 0:
                dm, dr, do, df = state.snap_full(player, float(g["state_r"][s]), float(g["state_theta_self"][s]),
                                                 float(g["state_theta_other"][s]), int(g["state_f_other"][s]))
                self.snap_frames.append(df)
            else:
                dm, dr = state.snap(player, float(g["state_r"][s]), float(g["state_theta_self"][s]))
            self.snap_m.append(dm)
            self.snap_rad.append(dr)
        return d.action
