"""The Interaction Graph fighter: an NPCController playing the agent protocol (agents.base), in the
kinematic game and in physics bouts alike."""
from __future__ import annotations

import time

import numpy as np

from igraph_fight.controller import NPCController
from igraph_fight.agents.base import observation


class IGAgent:
    """Chooses with an NPCController (min-max on the Interaction Graph at the controller's depth).

    snap: when the live state lies within the graph's tolerance of its nearest state it is moved
    onto that state before acting, so bouts stay on the graph instead of drifting off it as
    landing errors compound. "self"/True (default): only this fighter's distance and angle, the
    only thing an NPC may move in a game; "full": the whole coupled state (the fighter's distance
    and angle, the other's angle and clip frame), as in the paper's runtime where both avatars
    move on the graph (a closed IG-vs-IG world only: see the note); False: no snapping.
    Only answers read from the state's policy table are snapped (``Decision.edge >= 0``): an
    answer of the simulated lookahead (off the graph, or every decision with the controller's
    ``first_ply="exact"``) was chosen for the live, unsnapped state.

    Note (measured on the default 244k-state CMU boxing graph, 4 bouts of 60 s, seed 0):
    "full" also edits the *opponent*: it turns it by up to the linking tolerance and moves its
    clip time by up to F0 - 1 frames. Against an external opponent the shifts are mostly
    backwards (the opponent replays frames; 96% of the shifts at depth 5 against the human proxy,
    mean -8.4 frames) and the opponent's hits drop (human proxy: 6.5 -> 0.5 per 60 s bout at
    depth 5). Use "self" or False where the opponent must not be touched.
    Snapping needs a view that can be edited (the kinematic FightState); physics bouts use
    ``snap=False``. Counts decisions, off-graph decisions, snapping displacement and decision time
    for reports (zeroed by reset).
    """

    def __init__(self, controller: NPCController, name: str | None = None, snap: bool | str = "self") -> None:
        self.controller = controller
        self.name = name or f"IG({controller.depth})"
        self.snap = snap
        self.decisions = 0
        self.off_graph = 0
        self.decision_s = 0.0
        self.snap_m: list[float] = []
        self.snap_rad: list[float] = []
        self.snap_frames: list[int] = []

    def reset(self, arena, player: int, rng: np.random.Generator) -> None:
        self.decisions = 0
        self.off_graph = 0
        self.decision_s = 0.0
        self.snap_m, self.snap_rad, self.snap_frames = [], [], []

    def set_style(self, style) -> None:
        """Switch style at run time (the policy table recomputed; blocks until it is live)."""
        self.controller.set_style(style, wait=True)

    def peek(self, view, player: int) -> int:
        """What step() would answer, without side effects (NPCController.peek)."""
        return self.controller.peek(observation(view, player))

    def step(self, state, player: int) -> int:
        t = time.perf_counter()
        d = self.controller.act(observation(state, player))
        self.decision_s += time.perf_counter() - t
        self.decisions += 1
        self.off_graph += int(d.off_graph)
        if self.snap and not d.off_graph and d.state >= 0 and d.edge >= 0:
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
