"""A fight as a two-player game over the coupled kinematic simulator (after OpenSpiel's shape).

    game = FightGame(library)
    state = game.new_initial_state(rng)
    while not state.is_terminal():
        p = state.current_player()
        state.apply_action(agent[p].step(state, p))
    state.returns()

Decisions happen when a fighter stands at the last frame of its action: it picks the next action
from Next(M) (``legal_actions``). Between decisions both fighters play their actions and the
simulator judges hits both ways (igraph_fight.sim). A bout ends after ``max_seconds``.
Returns are hits landed minus hits received (the score of the paper's Table 1).
The same API serves the Interaction Graph fighter, the game-tree and scripted baselines and RL.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from motion_graph.library import ActionLibrary

from igraph_fight.sim import SimParams, SimTables
from igraph_fight.state import EventResult, PaperState, WorldState, advance, perspective, relative, start_action


@dataclass(frozen=True)
class GameConfig:
    """Bout rules: length (s), initial distance range (m), and the simulator's contact rules."""

    max_seconds: float = 60.0
    init_distance_m: tuple[float, float] = (1.0, 3.0)
    sim: SimParams = SimParams()


@dataclass
class Event:
    """A step of the bout log: a decision or what happened until the next decision."""

    t: float
    kind: str            # "decide" or "advance"
    player: int = -1
    action: int = -1
    result: EventResult | None = None


class FightGame:
    """The game definition: library, simulator tables and rules."""

    def __init__(self, library: ActionLibrary, config: GameConfig = GameConfig(),
                 tables: SimTables | None = None) -> None:
        self.library = library
        self.config = config
        self.tables = tables if tables is not None else SimTables.from_library(library, config.sim)
        self.trace_tables = replace(self.tables, params=replace(self.tables.params, max_event_frames=1))
        guard = [a for a in range(library.n_actions) if library.labels[a] == "guard"]
        self.start_actions = np.array(guard or list(range(library.n_actions)), dtype=np.int64)

    @property
    def fps(self) -> float:
        return self.tables.fps

    def num_players(self) -> int:
        return 2

    def new_initial_state(self, rng: np.random.Generator) -> "FightState":
        """Random start (docs/protocols.md, Match): distance in init_distance_m, random headings, both fighters at
        the last frame of a random guard action (both about to decide)."""
        lo, hi = self.config.init_distance_m
        r = float(rng.uniform(lo, hi))
        bearing = float(rng.uniform(-np.pi, np.pi))
        h = rng.uniform(-np.pi, np.pi, size=2)
        acts = rng.choice(self.start_actions, size=2)
        return self.initial_state((0.0, r * np.sin(bearing)), (0.0, r * np.cos(bearing)), (float(h[0]), float(h[1])),
                                  (int(acts[0]), int(acts[1])))

    def initial_state(self, x: tuple[float, float], z: tuple[float, float], heading: tuple[float, float],
                      actions: tuple[int, int]) -> "FightState":
        """Both fighters at the last frame of the given actions at pelvis (x, z) m, heading rad."""
        nf = self.tables.n_frames
        world = WorldState.new(x, z, heading, actions, (int(nf[actions[0]] - 1), int(nf[actions[1]] - 1)))
        return FightState(self, world)


@dataclass
class FightState:
    """One bout in progress. Mutable (apply_action); ``clone`` copies it."""

    game: FightGame
    world: WorldState
    frames: int = 0
    hits: np.ndarray = field(default_factory=lambda: np.zeros(2))
    damage: np.ndarray = field(default_factory=lambda: np.zeros(2))
    defended: np.ndarray = field(default_factory=lambda: np.zeros(2))
    last_player: int = -1
    record: bool = False
    log: list[Event] = field(default_factory=list)
    tracer: object = None  # callable(state, EventResult) called after every frame when set

    # ----- queries ------------------------------------------------------------------------
    @property
    def time_s(self) -> float:
        return self.frames / self.game.fps

    def is_terminal(self) -> bool:
        return self.time_s >= self.game.config.max_seconds

    def deciders(self) -> list[int]:
        nf = self.game.tables.n_frames
        return [i for i in (0, 1) if self.world.frame[i] >= nf[self.world.action[i]] - 1]

    def current_player(self) -> int:
        """The fighter to choose now (-1 when terminal). When both stand at a decision instant,
        the one that did not choose last goes first."""
        if self.is_terminal():
            return -1
        d = self.deciders()
        if not d:
            raise RuntimeError("no fighter at a decision instant (internal error)")
        if len(d) == 2:
            return 1 if self.last_player == 0 else 0
        return d[0]

    def legal_actions(self, player: int | None = None) -> np.ndarray:
        """Next(M): the actions the fighter may launch (library action ids)."""
        p = self.current_player() if player is None else player
        return self.game.tables.menu(int(self.world.action[p]))

    def observation(self, player: int) -> PaperState:
        """The paper's state I of ``player`` (r, theta_self, theta_other, Next(M_self), M_self, M_other, F_other)."""
        return perspective(self.game.tables, self.world, player)

    def relative(self, player: int) -> tuple[float, float, float]:
        """(distance m, theta_self rad, theta_other rad) of ``player``."""
        return relative(self.world, player)

    def returns(self) -> np.ndarray:
        """Score of each player: hits landed minus hits received."""
        return np.array([self.hits[0] - self.hits[1], self.hits[1] - self.hits[0]])

    def snap(self, player: int, r: float, theta_self: float) -> tuple[float, float]:
        """Move ``player`` along the line to the other until the distance is ``r`` and turn it in
        place so that its angle to the line is ``theta_self``: the runtime snapping of the paper
        (a live state joins its Interaction Graph state; the move shows as a little foot sliding).
        The other fighter is not touched. Returns the displacement (m) and rotation (rad)."""
        w = self.world
        o = 1 - player
        dx, dz = float(w.x[o] - w.x[player]), float(w.z[o] - w.z[player])
        b = np.arctan2(dx, dz)  # bearing from player to the other
        x = float(w.x[o]) - r * np.sin(b)
        z = float(w.z[o]) - r * np.cos(b)
        dh = float((b - theta_self - float(w.heading[player]) + np.pi) % (2 * np.pi) - np.pi)
        xs, zs, hs = w.x.copy(), w.z.copy(), w.heading.copy()
        move = float(np.hypot(x - xs[player], z - zs[player]))
        xs[player], zs[player], hs[player] = x, z, float(w.heading[player]) + dh
        self.world = replace(w, x=xs, z=zs, heading=hs)
        return move, abs(dh)

    def snap_full(self, player: int, r: float, theta_self: float, theta_other: float, f_other: int
                  ) -> tuple[float, float, float, int]:
        """Snap the whole coupled state onto an Interaction Graph state (the paper's runtime, where
        both avatars move on the graph): ``player`` moves along the line and turns in place
        (``snap``), the other turns in place to ``theta_other`` and its clip time moves to frame
        ``f_other`` (a jump of fewer than F0 frames, same action). Returns (player move m, player
        turn rad, other turn rad, other frame shift)."""
        move, turn = self.snap(player, r, theta_self)
        w = self.world
        o = 1 - player
        b = np.arctan2(float(w.x[player] - w.x[o]), float(w.z[player] - w.z[o]))  # bearing other -> player
        dh = float((b - theta_other - float(w.heading[o]) + np.pi) % (2 * np.pi) - np.pi)
        hs, fr = w.heading.copy(), w.frame.copy()
        hs[o] = float(w.heading[o]) + dh
        nf = int(self.game.tables.n_frames[w.action[o]])
        shift = int(np.clip(f_other, 0, nf - 2)) - int(fr[o]) if fr[o] < nf - 1 else 0
        fr[o] += shift
        self.world = replace(w, heading=hs, frame=fr)
        return move, turn, abs(dh), shift

    # ----- transitions ---------------------------------------------------------------------
    def apply_action(self, action: int) -> EventResult | None:
        """The current player launches ``action``; when no fighter is left to decide the bout runs on
        to the next decision instant. Returns that event (None if another decision follows now)."""
        p = self.current_player()
        if p < 0:
            raise ValueError("the bout is over")
        menu = self.legal_actions(p)
        if int(action) not in menu:
            raise ValueError(f"action {action} is not in Next({int(self.world.action[p])}) of player {p}")
        self.world = start_action(self.game.tables, self.world, p, int(action))
        self.last_player = p
        if self.record:
            self.log.append(Event(self.time_s, "decide", p, int(action)))
        if self.deciders():
            return None
        return self._advance()

    def _advance(self) -> EventResult:
        if self.tracer is None:
            self.world, ev = advance(self.game.tables, self.world)
            self._account(ev)
        else:  # frame by frame (same rules), reporting every frame
            frames = 0
            hits, dmg, reached, defended = np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2)
            r_sum = push = 0.0
            while True:
                self.world, ev = advance(self.game.trace_tables, self.world)
                self._account(ev)
                self.tracer(self, ev)
                frames += ev.frames
                hits += ev.hits
                dmg += ev.damage
                reached += ev.reached
                defended += ev.defended
                r_sum += ev.r_mean * ev.frames
                push += ev.push_m
                if ev.deciders or ev.frames == 0:
                    break
            ev = EventResult(frames, frames / self.game.fps, ev.deciders, tuple(hits), tuple(dmg), tuple(reached),
                             tuple(defended), r_sum / max(frames, 1), push)
        if self.record:
            self.log.append(Event(self.time_s, "advance", result=ev))
        return ev

    def _account(self, ev: EventResult) -> None:
        self.frames += ev.frames
        self.hits += np.array(ev.hits)
        self.damage += np.array(ev.damage)
        self.defended += np.array(ev.defended)

    def clone(self) -> "FightState":
        return replace(self, hits=self.hits.copy(), damage=self.damage.copy(), defended=self.defended.copy(),
                       log=list(self.log))
