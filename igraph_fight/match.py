"""Bouts between two agents in the kinematic simulator: run, log, summarise, and write the
artifacts a person looks at (JSONL log, summary, plots, HTML animation, BVH per fighter)."""
from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from motion_graph.atomic import atomic_write_text
from motion_graph.motion import Motion
from motion_graph.rotations import matrix_to_quat, quat_to_matrix, yaw_matrix

from igraph_fight.game import FightGame, FightState
from igraph_fight.state import EventResult


@dataclass
class BoutResult:
    """What happened in one bout. Times in seconds, distances in metres.

    decisions: one dict per decision (t, player, action, label, kind).
    hit_events: one dict per hit (t, frame, attacker, victim, kind).
    trace (when recorded): per-frame t (T,), pose (T, 2, 3) pelvis x, z and heading, action and
    frame (T, 2), distance (T,).
    meta (optional): written as the log's first line, ``{"type": "meta", "t": 0.0, ...}`` (e.g.
    who played, the initial state a replay starts from: igraph_fight.play).
    """

    names: tuple[str, str]
    seconds: float
    hits: np.ndarray
    damage: np.ndarray
    defended: np.ndarray
    decisions: list[dict]
    hit_events: list[dict]
    mean_distance_m: float
    wall_s: float
    trace: dict | None = None
    notes: list[dict] = field(default_factory=list)
    meta: dict | None = None

    @property
    def score(self) -> float:
        """Hits landed by A minus hits landed by B (the paper's Table 1 score for A)."""
        return float(self.hits[0] - self.hits[1])

    def kind_counts(self, player: int) -> dict[str, int]:
        out: dict[str, int] = {}
        for d in self.decisions:
            if d["player"] == player:
                out[d["kind"]] = out.get(d["kind"], 0) + 1
        return out

    def kind_share(self, player: int) -> dict[str, float]:
        c = self.kind_counts(player)
        n = max(sum(c.values()), 1)
        return {k: v / n for k, v in sorted(c.items())}

    def summary(self) -> dict:
        return {
            "a": self.names[0], "b": self.names[1], "seconds": self.seconds,
            "hits_a": float(self.hits[0]), "hits_b": float(self.hits[1]), "score": self.score,
            "defended_a": float(self.defended[0]), "defended_b": float(self.defended[1]),
            "mean_distance_m": self.mean_distance_m,
            "decisions_a": sum(1 for d in self.decisions if d["player"] == 0),
            "decisions_b": sum(1 for d in self.decisions if d["player"] == 1),
            "kind_share_a": self.kind_share(0), "kind_share_b": self.kind_share(1),
            "wall_s": self.wall_s,
        }


def run_bout(game: FightGame, agents, seconds: float, rng: np.random.Generator, trace: bool = False,
             schedule: list[tuple[float, Callable[[], None], str]] | None = None,
             initial: FightState | None = None) -> BoutResult:
    """Play one bout of ``seconds`` between agents[0] (A) and agents[1] (B).

    Args:
        rng: draws the initial state (unless ``initial``) and is handed to the agents.
        trace: record per-frame poses (for animation, BVH export and distance plots).
        schedule: [(t, callback, note)]: callbacks run at the first decision at or after t seconds
            (e.g. a style swap); the note is logged.
    """
    lib = game.library
    state = initial.clone() if initial is not None else game.new_initial_state(rng)
    state.game = game
    for p, ag in enumerate(agents):
        ag.reset(game, p, rng)
    cfg_seconds = seconds
    decisions: list[dict] = []
    hit_events: list[dict] = []
    notes: list[dict] = []
    tr: dict[str, list] = {"t": [], "pose": [], "action": [], "frame": [], "distance": []}
    dist_sum = [0.0, 0]

    def record_frame(st: FightState, ev: EventResult | None) -> None:
        w = st.world
        r = float(np.hypot(w.x[1] - w.x[0], w.z[1] - w.z[0]))
        dist_sum[0] += r
        dist_sum[1] += 1
        if trace:
            tr["t"].append(st.time_s)
            tr["pose"].append(np.stack([w.x, w.z, w.heading], axis=1))
            tr["action"].append(w.action.copy())
            tr["frame"].append(w.frame.copy())
            tr["distance"].append(r)
        if ev is not None:
            for i in (0, 1):
                for _ in range(int(round(ev.hits[i]))):
                    a = int(w.action[i])
                    hit_events.append({"t": round(st.time_s, 4), "frame": st.frames, "attacker": i, "victim": 1 - i,
                                       "action": a, "kind": lib.labels[a]})

    state.tracer = record_frame
    record_frame(state, None)
    pending = sorted(schedule or [], key=lambda x: x[0])
    t0 = time.perf_counter()
    max_s = min(cfg_seconds, game.config.max_seconds)
    while state.time_s < max_s:
        while pending and pending[0][0] <= state.time_s:
            _, cb, note = pending.pop(0)
            cb()
            notes.append({"t": round(state.time_s, 4), "note": note})
        p = state.current_player()
        if p < 0:
            break
        a = int(agents[p].step(state, p))
        decisions.append({"t": round(state.time_s, 4), "player": p, "action": a, "label": lib.labels[a],
                          "kind": lib.labels[a], "distance_m": round(state.relative(p)[0], 4)})
        state.apply_action(a)
    wall = time.perf_counter() - t0
    trace_arrays = None
    if trace:
        trace_arrays = {"t": np.array(tr["t"]), "pose": np.array(tr["pose"]), "action": np.array(tr["action"]),
                        "frame": np.array(tr["frame"]), "distance": np.array(tr["distance"])}
    return BoutResult((agents[0].name, agents[1].name), state.time_s, state.hits.copy(), state.damage.copy(),
                      state.defended.copy(), decisions, hit_events, dist_sum[0] / max(dist_sum[1], 1), wall,
                      trace_arrays, notes)


# ----- artifacts ---------------------------------------------------------------------------

def fighter_motion(game: FightGame, trace: dict, who: int) -> Motion:
    """One fighter's motion over a traced bout, in world coordinates (library fps)."""
    lib = game.library
    offs = lib.frame_offsets
    g = offs[trace["action"][:, who]] + trace["frame"][:, who]
    pose = trace["pose"][:, who]
    # start transform that puts the library frame's pelvis/heading at the traced pose
    sh = pose[:, 2] - lib.path[g, 2]
    c, s = np.cos(sh), np.sin(sh)
    px, pz = lib.path[g, 0], lib.path[g, 1]
    sx = pose[:, 0] - (c * px + s * pz)
    sz = pose[:, 1] - (-s * px + c * pz)
    R = yaw_matrix(sh)
    rot = lib.rotations[g].copy()
    rot[:, 0] = matrix_to_quat(R @ quat_to_matrix(rot[:, 0]))
    root = np.einsum("tab,tb->ta", R, lib.root_positions[g]) + np.stack([sx, np.zeros_like(sx), sz], axis=1)
    lt = None if lib.local_translations is None else lib.local_translations[g].copy()
    return Motion(lib.skeleton, rot, root, lib.fps, lt, f"bout fighter {'AB'[who]}")


def write_bout_artifacts(game: FightGame, result: BoutResult, out: str | os.PathLike, title: str = "bout",
                         plots: bool = True, html: bool = True, bvh: bool = True) -> dict[str, str]:
    """Write log.jsonl, summary.json, distance.png, bout.html and A.bvh/B.bvh; returns their paths."""
    from motion_graph.io_bvh import save_bvh

    from igraph_fight.viewer import write_bout_html

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    lib = game.library
    paths: dict[str, str] = {}
    lines = []
    if result.meta is not None:
        lines.append(json.dumps({"type": "meta", "t": 0.0, **result.meta}))
    for d in result.decisions:
        lines.append(json.dumps({"type": "action", **d}))
    for h in result.hit_events:
        lines.append(json.dumps({"type": "hit", **h}))
    for n in result.notes:
        lines.append(json.dumps({"type": "note", **n}))
    if result.trace is not None:
        tr = result.trace
        step = max(1, int(round(lib.fps / 10)))
        for k in range(0, len(tr["t"]), step):
            lines.append(json.dumps({"type": "distance", "t": round(float(tr["t"][k]), 4),
                                     "distance_m": round(float(tr["distance"][k]), 4)}))
    lines.sort(key=lambda l: json.loads(l)["t"])  # stable: the meta line stays first
    atomic_write_text(out / "log.jsonl", "\n".join(lines) + "\n")
    paths["log"] = str(out / "log.jsonl")
    if result.trace is not None and plots:
        _plot_bout(result, out / "distance.png", title)
        paths["plot"] = str(out / "distance.png")
    if result.trace is not None and html:
        tr = result.trace
        pos = [fighter_motion(game, tr, w).positions() for w in (0, 1)]
        frame_of_t = lambda t: int(np.searchsorted(tr["t"], t - 1e-9))  # noqa: E731
        hits = [{"frame": frame_of_t(h["t"]), "victim": h["victim"]} for h in result.hit_events]
        events = ([{"frame": frame_of_t(h["t"]), "text": f"{'AB'[h['attacker']]} {h['kind']} hits {'AB'[h['victim']]}"}
                   for h in result.hit_events] +
                  [{"frame": frame_of_t(n["t"]), "text": n["note"]} for n in result.notes])
        events.sort(key=lambda e: e["frame"])
        write_bout_html(out / "bout.html", pos[0], pos[1], lib.skeleton.parents, lib.fps, lib.parts["pelvis"],
                        lib.parts["head"], hits, events, title=title, name_a=result.names[0], name_b=result.names[1])
        paths["animation"] = str(out / "bout.html")
    if result.trace is not None and bvh:
        for w, n in ((0, "A"), (1, "B")):
            save_bvh(fighter_motion(game, result.trace, w), out / f"{n}.bvh")
            paths[f"bvh_{n.lower()}"] = str(out / f"{n}.bvh")
    summary = result.summary()
    summary["artifacts"] = dict(paths)
    summary["artifacts"]["summary"] = str(out / "summary.json")
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1))
    return summary["artifacts"]


#: bounds of ``read_bout_log``: file size, lines
MAX_LOG_BYTES = 16 * 1024 * 1024
MAX_LOG_LINES = 500_000


class BoutLogError(ValueError):
    """A bout log that cannot be read (names the file and the line)."""


def read_bout_log(path: str | os.PathLike, max_bytes: int = MAX_LOG_BYTES) -> dict[str, list[dict]]:
    """The lines of a log.jsonl written by ``write_bout_artifacts``, grouped by type ("meta",
    "action", "hit", "note", "distance", and any other), each a list in file order. Bounded (at
    most ``max_bytes`` and MAX_LOG_LINES lines); raises BoutLogError for a missing, oversized or
    malformed file (a line that is not a JSON object with a string ``type`` and a finite ``t``)."""
    import math

    p = Path(path)
    try:
        size = p.stat().st_size
    except OSError as e:
        raise BoutLogError(f"{p}: {e.strerror or e}") from None
    if size > max_bytes:
        raise BoutLogError(f"{p}: {size} bytes (at most {max_bytes})")
    out: dict[str, list[dict]] = {}
    with open(p, "rb") as fh:
        data = fh.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise BoutLogError(f"{p}: more than {max_bytes} bytes")
    lines = data.split(b"\n")
    if len(lines) > MAX_LOG_LINES + 1:
        raise BoutLogError(f"{p}: more than {MAX_LOG_LINES} lines")
    for i, raw in enumerate(lines):
        if not raw.strip():
            continue
        try:
            d = json.loads(raw.decode("utf-8"), parse_constant=lambda c: float("nan"))
        except (ValueError, RecursionError) as e:
            raise BoutLogError(f"{p}:{i + 1}: not JSON ({str(e)[:80]})") from None
        t = d.get("t") if isinstance(d, dict) else None
        if (not isinstance(d, dict) or not isinstance(d.get("type"), str) or isinstance(t, bool)
                or not isinstance(t, (int, float)) or not math.isfinite(t)):
            raise BoutLogError(f"{p}:{i + 1}: not a log line (an object with a type and a time t)")
        out.setdefault(d["type"], []).append(d)
    return out


def _plot_bout(result: BoutResult, path: Path, title: str) -> None:
    from igraph_fight.bout_plot import cumulative_steps, distance_and_hits_figure, save_figure
    tr = result.trace
    fig, ax0, ax1 = distance_and_hits_figure(tr["t"], tr["distance"], "distance (m)",
                                             f"{title}: {result.names[0]} (A) vs {result.names[1]} (B)")
    for n in result.notes:
        for ax in (ax0, ax1):
            ax.axvline(n["t"], color="k", ls="--", lw=1)
        ax0.text(n["t"], ax0.get_ylim()[1], " " + n["note"], va="top", fontsize=8)
    for who, col in ((0, "#e4572e"), (1, "#3fa7d6")):
        ts = [h["t"] for h in result.hit_events if h["attacker"] == who]
        cumulative_steps(ax1, ts, result.seconds, color=col, label=f"hits by {'AB'[who]} ({result.names[who]})")
    ax1.set_xlabel("time (s)")
    ax1.legend(loc="upper left")
    save_figure(fig, path)
