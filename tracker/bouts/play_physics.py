"""`igraph-fight play --physics`: the browser game with both fighters simulated in MuJoCo.

The page and its protocol are the kinematic game's (igraph_fight.play); only the bout differs. A
PhysicsBout (tracker.bouts.physics_bout) between the player's fighter A and the NPC B, tracked by
the default physics tracker (the learned assisted tracker: assisted physics, its bounded wrench
reported in the status), is stepped one control step (1/30 s) per frame the page is due; the
poses sent are the simulated bodies' joint sites, not the reference. A decides through
``GameSession.player_action`` (the queued command over A's rated menu), B through its
NPCController; both decide at the predicted end of their current action, as in every physics bout.

Physics bouts are not saved: a saved bout replays in the kinematic game, which would not
reproduce it.

Registered in the ``igraph_fight.physics`` entry-point group as ``play``: ``physics_play(server)``
returns the factory the server builds its sessions with.
"""
from __future__ import annotations

import numpy as np

from igraph_fight.play.session import GameSession, PlayConfig, Streamer

from tracker.body.humanoid import C_MOCAP_TO_MJ


class HumanAgent:
    """Fighter A of a physics game: its action is the session's answer to the player's keys."""

    name = "human"

    def __init__(self, session: "PhysicsGameSession") -> None:
        self.session = session
        self.choices: list[dict] = []       # per decision: the action and how the command resolved

    def reset(self, bout, player: int, rng: np.random.Generator) -> None:
        self.choices = []

    def step(self, ctx, player: int) -> int:
        a, info = self.session.player_action(ctx.obs, ctx.menu)
        self.choices.append({"t": round(float(ctx.t_s), 4), "action": int(a), **info})
        return int(a)


class NPCAgent:
    """Fighter B: the session's current NPCController on B's predicted Observation."""

    def __init__(self, session: "PhysicsGameSession") -> None:
        self.session = session
        self.name = "npc"

    def reset(self, bout, player: int, rng: np.random.Generator) -> None:
        pass

    def step(self, ctx, player: int) -> int:
        try:
            return int(self.session.npc.act(ctx.obs).action)
        except ValueError:          # the controller refused the state: the first legal action
            return int(ctx.menu[0])


class PhysicsFrame:
    """One simulated control step: its index and both fighters' drawn joints (2, J, 3), page axes."""

    def __init__(self, i: int, pose: np.ndarray) -> None:
        self.i = i
        self.pose = pose


class PhysicsPlayer:
    """Plays a PhysicsBout one control step at a time, with the interface of
    igraph_fight.play.session.BoutPlayer that the Streamer and the server read."""

    def __init__(self, setup, tracker, agents: list, seconds: float, seed: int, joints: list[int]) -> None:
        from tracker.bouts.physics_bout import PhysicsBout
        from tracker.bouts.setup import BoutConfig
        self.lib = setup.library
        self.fps = 30.0
        self.end_frame = int(round(seconds * self.fps))
        cfg = BoutConfig(seconds=float(seconds), record_qpos=False, physics_hz=setup.scene.options.physics_hz)
        self.bout = PhysicsBout(setup, agents, tracker, cfg)
        self.human = agents[0]
        self.n_a = 0                        # A's decisions reported so far
        self.bout.start(seed=seed)
        self.sites = [_site_rows(setup.scene.fighters[k], self.lib, joints) for k in (0, 1)]
        self.played = 0
        self.hits = np.zeros(2)
        self.damage = np.zeros(2)
        self.defended = np.zeros(2)
        self.decisions: list[dict] = []
        self.hit_events: list[dict] = []
        self.done = False

    def pose(self) -> np.ndarray:
        """(2, J, 3) world positions (m, Y up as the page draws them) of the drawn joints."""
        xpos = self.bout.env.data.site_xpos
        return np.stack([xpos[rows] @ C_MOCAP_TO_MJ for rows in self.sites])

    def step(self) -> PhysicsFrame | None:
        if self.done:
            return None
        b = self.bout
        n_dec, n_hit = len(b.decisions), len(b.hit_events)
        b.step()
        self.played = int(b.env.t)
        for d in b.decisions[n_dec:]:
            row = {k: d[k] for k in ("t", "player", "action", "label", "kind", "distance_m") if k in d}
            if row.get("player") == 0 and self.n_a < len(self.human.choices):
                row.update({k: v for k, v in self.human.choices[self.n_a].items() if k not in ("t", "action")})
                self.n_a += 1
            self.decisions.append(row)
        for h in b.hit_events[n_hit:]:
            att = int(h["attacker"])
            self.hits[att] += 1
            self.hit_events.append({"t": round(self.played / self.fps, 4), "frame": self.played, "attacker": att,
                                    "victim": 1 - att, "kind": str(h.get("kind", "hit"))})
        if self.played >= self.end_frame:
            self.done = True
        return PhysicsFrame(self.played, self.pose())

    @property
    def time_s(self) -> float:
        return self.played / self.fps

    def labels(self) -> list[str]:
        b = self.bout
        return [self.lib.labels[int(b.F[k].action_frame(b.env.t, b.nf)[0])] for k in (0, 1)]

    def distance_m(self) -> float:
        return float(np.linalg.norm(self.bout.pelvis_xy(1) - self.bout.pelvis_xy(0)))


def _site_rows(fm, lib, joints: list[int]) -> np.ndarray:
    """The model site of each drawn skeleton joint (a joint without a site takes its nearest
    ancestor's)."""
    site_of = {int(j): int(s) for j, s in zip(fm.site_joints, fm.site_ids)}
    parents = np.asarray(lib.skeleton.parents)
    rows = []
    for j in joints:
        p = int(j)
        while p >= 0 and p not in site_of:
            p = int(parents[p])
        if p < 0:
            raise ValueError(f"skeleton joint {j} has no simulated body above it")
        rows.append(site_of[p])
    return np.asarray(rows, dtype=np.int64)


class PhysicsStreamer(Streamer):
    """The Streamer of a physics game: frames carry the simulated poses and the fighters' falls."""

    def frame_view(self, fr: PhysicsFrame) -> tuple[np.ndarray, list[str], float, dict]:
        p = self.player
        extra = {"down": [bool(f.down) for f in p.bout.F]}
        batch = getattr(p.bout.env, "batch", None)
        if batch is not None:
            extra["assist_mg"] = [round(float(x), 3) for x in batch.assist_force_mg]
        return fr.pose, p.labels(), p.distance_m(), extra


class PhysicsGameSession(GameSession):
    """A GameSession whose bout is simulated (module docstring)."""

    saveable = False

    def __init__(self, physics: "PhysicsPlay", npc, rater, config: PlayConfig, graph_hash: str = "",
                 npc_style: str | None = None) -> None:
        self.physics = physics
        super().__init__(physics.setup.game, npc, rater, config, graph_hash, npc_style)

    def start_bout(self) -> None:
        """The simulated bout of ``self.seed`` (no start record: physics bouts are not replayed)."""
        agents = [HumanAgent(self), NPCAgent(self)]
        self.player = PhysicsPlayer(self.physics.setup, self.physics.tracker, agents, self.config.seconds, self.seed,
                                    self.drawing["joints"])
        self.streamer = PhysicsStreamer(self.player, self.drawing["joints"])
        self.start = {}

    def status(self, mode: str | None = None) -> dict:
        st = super().status(mode)
        st["physics"] = self.physics.label
        stats = self.player.bout.assist_stats
        if self.physics.assisted:
            mass = float(self.player.bout.env.batch.mass[0])
            st["assist"] = [stats.summary(k, mass, self.physics.cap)["force_mean_mg"] for k in (0, 1)]
        return st

    def result(self):
        raise ValueError("physics bouts are not saved (a saved bout replays in the kinematic game)")


class PhysicsPlay:
    """What the server keeps for physics games: the two-fighter scene and the tracker, built once."""

    def __init__(self, library, sim_params, tracker=None) -> None:
        from tracker.bouts.loaders import load_tracker
        from tracker.bouts.setup import BoutSetup
        self.tracker = load_tracker(tracker)
        self.setup = BoutSetup.create(library, sim_params=sim_params, tracker=self.tracker)
        acfg = self.tracker.assist_config() if hasattr(self.tracker, "assist_config") else None
        self.assisted = bool(acfg is not None and acfg.active)
        self.cap = float(acfg.cap) if acfg is not None else 0.0
        self.label = acfg.label() if acfg is not None else "physics (no assist)"

    def session(self, npc, rater, config: PlayConfig, graph_hash: str = "", npc_style: str | None = None
                ) -> PhysicsGameSession:
        return PhysicsGameSession(self, npc, rater, config, graph_hash, npc_style)


def physics_play(library, sim_params, tracker=None) -> PhysicsPlay:
    """The entry point igraph_fight.play.server calls for ``play --physics``."""
    return PhysicsPlay(library, sim_params, tracker)
