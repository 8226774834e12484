"""A bout between the player (fighter A) and the NPC (fighter B) in the kinematic FightGame,
stepped in real time; and the replay of a saved bout.

``BoutPlayer`` plays a FightState frame by frame: when the frames of the current event run out
(a fighter stands at the end of its action) it asks ``decide(state, player)`` for the action,
then simulates the event up to the next decision instant (igraph_fight.game, frame by frame, so
every frame's pose and hits are known) and hands those frames out one at a time. A decision is
thus taken at the wall-clock instant its frame is shown: a command queued meanwhile reaches it.

``GameSession`` is the live game: A's decisions resolve the player's command (queued by a key
press, else the held key, else the idle command: igraph_fight.play.commands) over the menu
rated by the Interaction Graph for A's side; B is NPCController.act on B's observation (no
snapping: neither fighter is ever moved off its motion, and the log replays exactly). The
bout ends at ``seconds``; hits after the last shown frame do not count.
"""
from __future__ import annotations

import os
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from motion_graph.classify import KINDS

from igraph_fight.controller import observe
from igraph_fight.game import FightGame, FightState, GameConfig
from igraph_fight.play.commands import COMMANDS, rate_menu, resolve
from igraph_fight.play.drawing import body_drawing, world_positions

#: frames sent at most per tick when the server falls behind (older poses are skipped; their
#: hits and decisions are still reported)
MAX_CATCHUP_FRAMES = 4
#: the clock advances by at most this per tick (a stalled server slows the bout, it does not jump)
MAX_TICK_S = 0.25


@dataclass
class Frame:
    """One simulated frame: its index, the world after it, hits landed in it (attacker indices),
    damage received and strikes defended per fighter."""

    i: int
    world: object
    hits: list[int] = field(default_factory=list)
    damage: tuple[float, float] = (0.0, 0.0)
    defended: tuple[float, float] = (0.0, 0.0)


class BoutPlayer:
    """Plays a FightState frame by frame, asking ``decide(state, player) -> (action, info)`` at
    each decision instant (module docstring). ``seconds``: the bout's length."""

    def __init__(self, state: FightState, seconds: float, decide: Callable[[FightState, int], tuple[int, dict]]) -> None:
        self.state = state
        self.game = state.game
        self.lib = self.game.library
        self.fps = float(self.game.fps)
        self.end_frame = int(round(seconds * self.fps))
        self.decide = decide
        self.buffer: deque[Frame] = deque([Frame(state.frames, state.world)])
        self.played = -1                       # index of the last frame handed out
        self.hits = np.zeros(2)
        self.damage = np.zeros(2)
        self.defended = np.zeros(2)
        self.decisions: list[dict] = []
        self.hit_events: list[dict] = []
        self.trace: dict[str, list] = {"t": [], "pose": [], "action": [], "frame": [], "distance": []}
        self.done = False
        state.tracer = self._trace

    def _trace(self, st: FightState, ev) -> None:
        hits = [i for i in (0, 1) for _ in range(int(round(ev.hits[i])))]
        self.buffer.append(Frame(st.frames, st.world, hits, tuple(ev.damage), tuple(ev.defended)))

    def _fill(self) -> None:
        """Decide at the current instant until an event produces frames."""
        st = self.state
        for _ in range(8):
            p = st.current_player()
            if p < 0:
                self.done = True
                return
            a, info = self.decide(st, p)
            a = int(a)
            r = st.relative(p)[0]
            self.decisions.append({"t": round(st.time_s, 4), "player": p, "action": a, "label": self.lib.labels[a],
                                   "kind": self.lib.labels[a], "distance_m": round(float(r), 4), **info})
            st.apply_action(a)
            if self.buffer:
                return
        raise RuntimeError("the simulator made no progress after 8 decisions")

    def step(self) -> Frame | None:
        """The next frame (None when the bout is over)."""
        if self.done:
            return None
        if not self.buffer:
            self._fill()
            if self.done or not self.buffer:
                self.done = True
                return None
        fr = self.buffer.popleft()
        if fr.i > self.end_frame:
            self.done = True
            return None
        self.played = fr.i
        w = fr.world
        for att in fr.hits:
            a = int(w.action[att])
            self.hit_events.append({"t": round(fr.i / self.fps, 4), "frame": fr.i, "attacker": att, "victim": 1 - att,
                                    "action": a, "kind": self.lib.labels[a]})
            self.hits[att] += 1
        self.damage += fr.damage
        self.defended += fr.defended
        r = float(np.hypot(w.x[1] - w.x[0], w.z[1] - w.z[0]))
        self.trace["t"].append(fr.i / self.fps)
        self.trace["pose"].append(np.stack([w.x, w.z, w.heading], axis=1))
        self.trace["action"].append(w.action.copy())
        self.trace["frame"].append(w.frame.copy())
        self.trace["distance"].append(r)
        if fr.i >= self.end_frame:
            self.done = True
        return fr

    @property
    def time_s(self) -> float:
        return max(self.played, 0) / self.fps

    def trace_arrays(self) -> dict:
        tr = self.trace
        return {"t": np.array(tr["t"]), "pose": np.array(tr["pose"]).reshape(-1, 2, 3),
                "action": np.array(tr["action"]).reshape(-1, 2), "frame": np.array(tr["frame"]).reshape(-1, 2),
                "distance": np.array(tr["distance"])}


def start_of(state: FightState) -> dict:
    """The initial world of a bout as the log's meta records it (replays start from it)."""
    w = state.world
    return {"x": [float(v) for v in w.x], "z": [float(v) for v in w.z], "heading": [float(v) for v in w.heading],
            "action": [int(v) for v in w.action], "frame": [int(v) for v in w.frame]}


class Streamer:
    """Turns a BoutPlayer into the page's messages in real time: ``tick(now)`` advances the bout
    clock (seconds, monotonic) and returns the frame / hit / decision messages that are due."""

    def __init__(self, player: BoutPlayer, joints: list[int]) -> None:
        self.player = player
        self.joints = joints
        self.clock = 0.0
        self.last_now: float | None = None
        self.paused = False
        self.speed = 1.0
        self.pending_events: list[dict] = []

    def tick(self, now: float) -> list[dict]:
        dt = 0.0 if self.last_now is None else min(max(now - self.last_now, 0.0), MAX_TICK_S)
        self.last_now = now
        if not self.paused:
            self.clock += dt * self.speed
        p = self.player
        due = int(self.clock * p.fps + 1e-6)
        frames: list[Frame] = []
        hits: list[dict] = []
        n_dec = len(p.decisions)
        n_hit = len(p.hit_events)
        while p.played < due and not p.done:
            fr = p.step()
            if fr is None:
                break
            frames.append(fr)
        out: list[dict] = []
        for d in p.decisions[n_dec:]:
            out.append({"type": "decision", **d})
        hits = p.hit_events[n_hit:]
        if frames:
            out.append(self.frame_message(frames[-1], hits))
        return out

    def frame_view(self, fr: Frame) -> tuple[np.ndarray, list[str], float, dict]:
        """What a frame shows: the drawn joints' positions (2, J, 3), both action labels, the
        distance (m) and extra message fields."""
        p = self.player
        w = fr.world
        return (world_positions(p.lib, fr.world, self.joints), [p.lib.labels[int(a)] for a in w.action],
                float(np.hypot(w.x[1] - w.x[0], w.z[1] - w.z[0])), {})

    def frame_message(self, fr: Frame, hits: list[dict]) -> dict:
        p = self.player
        pos, labels, distance, extra = self.frame_view(fr)
        msg = {"type": "frame", "i": fr.i, "t": round(fr.i / p.fps, 4),
               "pose": [np.round(pos[k], 3).ravel().tolist() for k in (0, 1)],
               "hits": [int(x) for x in p.hits], "score": int(p.hits[0] - p.hits[1]),
               "distance": round(distance, 3), "labels": labels,
               "time_left": round(max(p.end_frame - fr.i, 0) / p.fps, 2), **extra}
        if hits:
            msg["hit_events"] = [{"attacker": h["attacker"], "victim": h["victim"], "kind": h["kind"]} for h in hits]
        return msg


@dataclass
class PlayConfig:
    """A live bout's settings: length (s), the NPC's initial style and depth, the player's style
    (rates A's menu), the idle command and the initial state's seed (None: random)."""

    seconds: float = 60.0
    style: str = "balanced"
    depth: int = 3
    player_style: str = "balanced"
    idle: str = "guard"
    seed: int | None = None


class GameSession:
    """The live game of one page (module docstring). ``npc``: B's controller; ``rater``: the
    controller that rates A's menu (the player's style)."""

    def __init__(self, game: FightGame, npc, rater, config: PlayConfig, graph_hash: str = "",
                 npc_style: str | None = None) -> None:
        self.game = game
        self.lib = game.library
        self.npc = npc
        self.npc_style = npc_style or config.style
        self.npc_depth = int(npc.depth)
        self.rater = rater
        self.config = config
        self.graph_hash = graph_hash
        self.drawing = body_drawing(self.lib)
        self.kinds = np.asarray(self.lib.kinds, dtype=np.int64)
        self.queued: str | None = None
        self.queued_at = 0.0
        self.held: list[str] = []
        self.notes: list[dict] = []
        self.styles_used: list[str] = []
        self.depths_used: list[int] = []
        self.seed = 0
        self.new_bout(config.seconds, config.seed)

    # ----- the bout ------------------------------------------------------------------------------
    def new_bout(self, seconds: float | None = None, seed: int | None = None) -> None:
        if seconds is not None:
            self.config.seconds = float(seconds)
        self.seed = int(seed) if seed is not None else int.from_bytes(os.urandom(4), "little")
        self.start_bout()
        self.queued, self.held = None, []
        self.notes = []
        self.styles_used = [self.npc_style]
        self.depths_used = [self.npc_depth]
        self.created = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        self.saved_as: str | None = None

    def start_bout(self) -> None:
        """The bout of ``self.seed``: its player (``self.player``), streamer and start record."""
        game = FightGame(self.lib, GameConfig(max_seconds=self.config.seconds, sim=self.game.config.sim),
                         tables=self.game.tables)
        self.bout_game = game
        state = game.new_initial_state(np.random.default_rng(self.seed))
        self.start = start_of(state)
        self.player = BoutPlayer(state, self.config.seconds, self._decide)
        self.streamer = Streamer(self.player, self.drawing["joints"])

    def _decide(self, state: FightState, p: int) -> tuple[int, dict]:
        if p == 1:
            try:
                d = self.npc.act(observe(state, 1))
                return int(d.action), {"off_graph": bool(d.off_graph)}
            except ValueError as e:  # the controller refused the state: play the first legal action
                return int(state.legal_actions(1)[0]), {"error": str(e)[:200]}
        return self.player_action(observe(state, 0), state.legal_actions(0))

    def player_action(self, obs, legal) -> tuple[int, dict]:
        """Fighter A's action at a decision: the queued command (else the held key, else the idle
        command) resolved over A's menu rated by the player's style (``obs``: A's Observation;
        ``legal``: A's legal actions, used unrated when the rater refuses the state)."""
        now = time.monotonic()
        if self.queued is not None:
            cmd, source, latency = self.queued, "key", (now - self.queued_at) * 1e3
            self.queued = None
        elif self.held:
            cmd, source, latency = self.held[-1], "held", None
        else:
            cmd, source, latency = (None if self.config.idle == "best" else "guard"), "idle", None
        try:
            acts, scores = rate_menu(self.rater, obs)
        except ValueError:  # the controller refused the state: the category rule on an unrated menu
            acts = np.asarray(legal, dtype=np.int64)
            scores = np.zeros(len(acts))
        if cmd is None:
            j = int(np.argmax(scores))
            a, kind, level = int(acts[j]), KINDS[int(self.kinds[acts[j]])], -1
        else:
            res = resolve(cmd, acts, scores, self.kinds)
            a, kind, level = res.action, res.kind, res.level
        info = {"command": cmd or "best", "category": kind, "level": level, "source": source}
        if latency is not None:
            info["latency_ms"] = round(latency, 1)
        return a, info

    # ----- input ---------------------------------------------------------------------------------
    def command(self, name: str, held: bool = False) -> None:
        """The player pressed a key: ``name`` is queued for A's next decision (the latest press
        wins); ``held``: it repeats at A's later decisions until released."""
        if name not in COMMANDS:
            raise ValueError(f"unknown command {name!r}")
        self.queued = name
        self.queued_at = time.monotonic()
        if held:
            if name in self.held:
                self.held.remove(name)
            self.held.append(name)

    def release(self, name: str) -> None:
        if name in self.held:
            self.held.remove(name)

    def set_npc(self, controller, style: str) -> None:
        """B plays ``controller`` (style label ``style``) from its next decision on."""
        self.npc = controller
        self.npc_style = style
        self.npc_depth = int(controller.depth)
        t = round(self.player.time_s, 4)
        self.notes.append({"t": t, "note": f"B style {style}, depth {self.npc_depth}"})
        if style not in self.styles_used:
            self.styles_used.append(style)
        if self.npc_depth not in self.depths_used:
            self.depths_used.append(self.npc_depth)

    def tick(self, now: float) -> list[dict]:
        return self.streamer.tick(now)

    @property
    def over(self) -> bool:
        return self.player.done

    def status(self, mode: str | None = None) -> dict:
        p = self.player
        return {"type": "status", "mode": mode or ("over" if p.done else "paused" if self.streamer.paused else "live"),
                "style": self.npc_style, "depth": self.npc_depth, "player_style": self.config.player_style,
                "idle": self.config.idle, "seconds": self.config.seconds, "queued": self.queued,
                "held": list(self.held), "saved_as": self.saved_as}

    # ----- saving --------------------------------------------------------------------------------
    def result(self):
        """The bout so far as a match.BoutResult (frames shown so far; meta for replay and evaluation)."""
        from igraph_fight.graph import package_version
        from igraph_fight.match import BoutResult

        p = self.player
        tr = p.trace_arrays()
        meta = {"format": "igraph-fight-bout/1", "source": "igraph-fight play", "human": 0, "npc": 1,
                "npc_style": self.npc_style, "npc_depth": self.npc_depth, "npc_styles": list(self.styles_used),
                "npc_depths": list(self.depths_used), "player_style": self.config.player_style,
                "idle": self.config.idle, "graph": self.graph_hash, "library": self._library_fp(),
                "seconds": self.config.seconds, "played_s": round(p.time_s, 4), "complete": bool(p.done),
                "start": self.start, "seed": self.seed, "fps": p.fps, "package_version": package_version(),
                "created": self.created}
        dist = tr["distance"]
        return BoutResult(("human", f"IG({self.npc_depth}) {self.npc_style}"), p.time_s, p.hits.copy(),
                          p.damage.copy(), p.defended.copy(), [d for d in p.decisions if d["t"] <= p.time_s],
                          list(p.hit_events), float(dist.mean()) if len(dist) else 0.0, 0.0, tr, list(self.notes), meta)

    def _library_fp(self) -> str:
        from igraph_fight.graph import library_fingerprint
        if not hasattr(self, "_lib_fp"):
            self._lib_fp = library_fingerprint(self.lib)
        return self._lib_fp
