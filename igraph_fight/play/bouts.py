"""Saved bouts of `igraph-fight play`: writing them (the same log.jsonl and summary.json as
`igraph-fight fight`, igraph_fight.match.write_bout_artifacts, with a meta line), listing them,
and replaying one: the log's initial state and decisions re-simulated in the kinematic game,
which reproduces the bout exactly (the play session never snaps a fighter).

A bout is a folder ``<save dir>/<name>/``; it is written under a temporary name and renamed
into place, so a folder with that name is always complete. Every log read here is treated as
hostile: bounded (match.read_bout_log), its fields checked, errors raised as ReplayError.
"""
from __future__ import annotations

import json
import math
import os
import re
import shutil
import time
from pathlib import Path

import numpy as np

from igraph_fight.game import FightGame, FightState, GameConfig
from igraph_fight.match import BoutLogError, read_bout_log, write_bout_artifacts
from igraph_fight.play.session import BoutPlayer

NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,79}$")
#: bouts listed at most (newest first)
MAX_LISTED = 200
#: longest bout a replay accepts (s)
MAX_REPLAY_SECONDS = 3600.0


class ReplayError(ValueError):
    """A saved bout that cannot be replayed (names the reason)."""


def save_bout(session, save_dir: str | os.PathLike) -> tuple[str, Path]:
    """Write the session's bout so far into a new folder of ``save_dir``; returns (name, folder)."""
    res = session.result()
    save_dir = Path(save_dir)
    save_dir.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S", time.gmtime())
    base = f"{stamp}-{re.sub(r'[^A-Za-z0-9_]+', '_', session.npc_style)[:24]}-d{session.npc_depth}"
    name = base
    k = 1
    while (save_dir / name).exists():
        k += 1
        name = f"{base}-{k}"
    tmp = save_dir / f".tmp-{name}-{os.getpid()}"
    if tmp.exists():
        shutil.rmtree(tmp)
    try:
        write_bout_artifacts(session.bout_game, res, tmp, title="play", plots=False, html=False, bvh=False)
        summary = json.loads((tmp / "summary.json").read_text())
        summary["artifacts"] = {k: v.replace(str(tmp), str(save_dir / name)) for k, v in summary["artifacts"].items()}
        summary["meta"] = res.meta
        (tmp / "summary.json").write_text(json.dumps(summary, indent=1))
        os.replace(tmp, save_dir / name)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    session.saved_as = name
    return name, save_dir / name


def list_bouts(save_dir: str | os.PathLike) -> list[dict]:
    """Saved bouts of ``save_dir``, newest first: name, NPC style and depth, hits, seconds, complete."""
    d = Path(save_dir)
    if not d.is_dir():
        return []
    out = []
    for p in sorted((q for q in d.iterdir() if NAME_RE.match(q.name) and (q / "log.jsonl").is_file()),
                    key=lambda q: q.stat().st_mtime, reverse=True)[:MAX_LISTED]:
        item = {"name": p.name}
        try:
            with open(p / "summary.json", "rb") as fh:
                s = json.loads(fh.read(1_000_000))
            m = s.get("meta") or {}
            item.update(style=m.get("npc_style"), depth=m.get("npc_depth"), seconds=s.get("seconds"),
                        hits=[s.get("hits_a"), s.get("hits_b")], complete=m.get("complete"))
        except (OSError, ValueError, AttributeError):
            pass
        out.append(item)
    return out


def bout_folder(save_dir: str | os.PathLike, name: str) -> Path:
    """The folder of a saved bout by name (no path may leave ``save_dir``)."""
    if not isinstance(name, str) or not NAME_RE.match(name):
        raise ReplayError(f"not a bout name: {str(name)[:80]!r}")
    p = Path(save_dir) / name
    if not (p / "log.jsonl").is_file():
        raise ReplayError(f"no saved bout {name!r}")
    return p


def _numbers(v, n: int, kind, what: str) -> list:
    if not isinstance(v, list) or len(v) != n:
        raise ReplayError(f"meta.start.{what}: not a list of {n}")
    out = []
    for x in v:
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x):
            raise ReplayError(f"meta.start.{what}: not finite numbers")
        if kind is int and x != int(x):
            raise ReplayError(f"meta.start.{what}: not integers")
        out.append(kind(x))
    return out


def replay_player(folder: str | os.PathLike, game: FightGame, library_fingerprint: str) -> tuple[BoutPlayer, dict]:
    """A BoutPlayer that re-plays a saved bout, and what the log says happened ({hits, meta}).
    Raises ReplayError for a log that does not belong to this library or does not replay."""
    try:
        log = read_bout_log(Path(folder) / "log.jsonl")
    except BoutLogError as e:
        raise ReplayError(str(e)) from None
    metas = log.get("meta") or []
    if not metas:
        raise ReplayError("the log has no meta line (only bouts saved by igraph-fight play replay)")
    meta = metas[0]
    if meta.get("library") != library_fingerprint:
        raise ReplayError("the bout was played on another action library")
    start = meta.get("start")
    if not isinstance(start, dict):
        raise ReplayError("meta.start missing")
    x = _numbers(start.get("x"), 2, float, "x")
    z = _numbers(start.get("z"), 2, float, "z")
    h = _numbers(start.get("heading"), 2, float, "heading")
    a = _numbers(start.get("action"), 2, int, "action")
    f = _numbers(start.get("frame"), 2, int, "frame")
    lib = game.library
    if not all(0 <= v < lib.n_actions for v in a):
        raise ReplayError("meta.start.action: not action ids of this library")
    played = meta.get("played_s")
    if isinstance(played, bool) or not isinstance(played, (int, float)) or not 0 <= played <= MAX_REPLAY_SECONDS:
        raise ReplayError("meta.played_s: not a bout length")
    g = FightGame(lib, GameConfig(max_seconds=float(played) + 1.0, sim=game.config.sim), tables=game.tables)
    state: FightState = g.initial_state((x[0], x[1]), (z[0], z[1]), (h[0], h[1]), (a[0], a[1]))
    if [int(v) for v in state.world.frame] != f:
        raise ReplayError("meta.start.frame: the fighters do not start at a decision instant")
    decisions = []
    for d in log.get("action", []):
        p, act = d.get("player"), d.get("action")
        if p not in (0, 1) or isinstance(act, bool) or not isinstance(act, int) or not 0 <= act < lib.n_actions:
            raise ReplayError(f"an action line at t={d.get('t')} is not a decision of this library")
        extra = {k: d[k] for k in ("command", "category", "source") if isinstance(d.get(k), str) and len(d[k]) <= 40}
        if isinstance(d.get("level"), int) and not isinstance(d.get("level"), bool):
            extra["level"] = d["level"]
        decisions.append((p, act, extra))
    queue = list(reversed(decisions))

    def decide(st: FightState, player: int) -> tuple[int, dict]:
        if not queue:
            raise ReplayError(f"the log has no decision for {'AB'[player]} at t={st.time_s:.2f} s")
        p, act, extra = queue.pop()
        if p != player:
            raise ReplayError(f"the log's decision at t={st.time_s:.2f} s is {'AB'[p]}'s, the game asks {'AB'[player]}")
        if act not in st.legal_actions(player):
            raise ReplayError(f"action {act} at t={st.time_s:.2f} s is not in {'AB'[player]}'s menu")
        return act, {**extra, "replay": True}

    hits = np.zeros(2)
    for e in log.get("hit", []):
        if e.get("attacker") in (0, 1):
            hits[e["attacker"]] += 1
    return BoutPlayer(state, float(played), decide), {"hits": hits.tolist(), "meta": meta, "decisions": len(decisions)}
