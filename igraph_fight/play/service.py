"""The network NPC service: answers the protocol's requests (decide, set_style, set_depth, info,
health) for one connection, independently of the transport (igraph_fight.play.server carries
them over WebSocket and HTTP).

A connection has a current (style, depth), the server's defaults at first; ``decide`` answers
with the policy of the request's own style / depth when it names them, else the connection's.
Decisions are NPCController.act (one observation: the table, with the simulated lookahead off
the graph) or act_batch with the lookahead (a batch); each reply carries the action id, its
label, the off-graph flag and the server's decision time in microseconds. Any ValueError the
controller raises (e.g. an observation it refuses) becomes a ``bad_observation`` error reply.
"""
from __future__ import annotations

import time

import numpy as np

from igraph_fight.play.policies import PolicyPool, changed_share
from igraph_fight.play.protocol import (
    DEPTH_RANGE, MAX_PENDING_POLICIES, PROTOCOL_VERSION, ProtocolError, limits, observation_from)


class NPCService:
    """What the server knows to answer NPC requests: the graph, the library and the policy pool."""

    def __init__(self, pool: PolicyPool, default_style: str, default_depth: int) -> None:
        self.pool = pool
        base = pool.base
        self.graph = base.graph
        self.library = base.library
        self.default_style = default_style
        self.default_depth = int(default_depth)
        self.n_actions = int(base.library.n_actions)
        self.n_frames = np.diff(np.asarray(base.library.frame_offsets)).astype(np.int64)
        self.labels = [str(x) for x in base.library.labels]
        self.started = time.time()
        from igraph_fight.graph import package_version
        self.version = package_version()

    def info(self, conn: "Connection") -> dict:
        from planner import list_presets

        g, lib = self.graph, self.library
        return {"v": PROTOCOL_VERSION, "type": "info", "version": self.version,
                "graph": {"content_hash": g.content_hash, "n_states": int(g.n_states), "n_edges": int(g.n_edges)},
                "library": {"fingerprint": g.library_fingerprint, "n_actions": self.n_actions,
                            "n_frames": self.n_frames.tolist(), "labels": self.labels, "fps": float(lib.fps)},
                "styles": list_presets(), "depth_range": list(DEPTH_RANGE), "limits": limits(),
                "style": conn.style, "depth": conn.depth}

    def health(self, counters: dict | None = None) -> dict:
        out = {"v": PROTOCOL_VERSION, "type": "health", "status": "ok", "version": self.version,
               "protocol": PROTOCOL_VERSION, "graph": self.graph.content_hash,
               "n_states": int(self.graph.n_states), "uptime_s": round(time.time() - self.started, 1)}
        if counters:
            out.update(counters)
        return out

    async def handle(self, msg: dict, conn: "Connection", counters: dict | None = None) -> dict:
        """The reply to one validated request (raises ProtocolError for a refused one)."""
        kind = msg["type"]
        tag = msg.get("id")
        try:
            if kind == "decide":
                out = await self.decide(msg, conn)
            elif kind == "set_style" or kind == "set_depth":
                out = await self.set_policy(conn, msg.get("style", conn.style), msg.get("depth", conn.depth))
            elif kind == "info":
                out = self.info(conn)
            elif kind == "health":
                out = self.health(counters)
            else:
                raise ProtocolError("invalid", f"unknown type {kind!r}")
        except ProtocolError as e:
            if e.tag is None:
                e.tag = tag
            raise
        if tag is not None:
            out["id"] = tag
        return out

    async def _controller(self, style: str, depth: int, conn: "Connection"):
        c = self.pool.cached(style, depth)
        if c is None:
            if conn.pending >= MAX_PENDING_POLICIES:
                raise ProtocolError("busy", f"{conn.pending} policy changes already under way on this connection")
            conn.pending += 1
            try:
                c, _ = await self.pool.get(style, depth)
            finally:
                conn.pending -= 1
        return c

    async def decide(self, msg: dict, conn: "Connection") -> dict:
        style = msg.get("style", conn.style)
        depth = int(msg.get("depth", conn.depth))
        c = await self._controller(style, depth, conn)
        try:
            if "obs" in msg:
                obs = observation_from(msg["obs"], self.n_actions, self.n_frames)
                t0 = time.perf_counter()
                d = c.act(obs)
                us = (time.perf_counter() - t0) * 1e6
                a = int(d.action)
                return {"v": PROTOCOL_VERSION, "type": "decision", "action": a, "label": self.labels[a],
                        "off_graph": bool(d.off_graph), "decision_us": round(us, 2), "style": c.style, "depth": c.depth}
            rows = [observation_from(o, self.n_actions, self.n_frames) for o in msg["batch"]]
            cols = list(zip(*rows))
            t0 = time.perf_counter()
            acts, _, off = c.act_batch(*(np.asarray(x) for x in cols), lookahead=True)
            us = (time.perf_counter() - t0) * 1e6
        except ValueError as e:  # the controller refuses the observation (e.g. its ObservationError)
            raise ProtocolError("bad_observation", str(e)) from None
        return {"v": PROTOCOL_VERSION, "type": "decisions", "decision_us": round(us, 2), "style": c.style,
                "depth": c.depth,
                "decisions": [{"action": int(a), "label": self.labels[int(a)], "off_graph": bool(o)}
                              for a, o in zip(acts, off)]}

    async def set_policy(self, conn: "Connection", style: str, depth: int) -> dict:
        """Make (style, depth) the connection's policy once its table is ready; the old one answers
        the connection's decisions meanwhile."""
        if conn.pending >= MAX_PENDING_POLICIES:
            raise ProtocolError("busy", f"{conn.pending} policy changes already under way on this connection")
        conn.pending += 1
        try:
            old = self.pool.cached(conn.style, conn.depth)
            c, ms = await self.pool.get(style, int(depth))
        finally:
            conn.pending -= 1
        conn.style, conn.depth = style, int(depth)
        out = {"v": PROTOCOL_VERSION, "type": "policy", "style": c.style, "depth": int(c.depth), "policy_ms": round(ms, 1)}
        if old is not None and old is not c:
            out["changed_share"] = round(changed_share(old, c), 6)
        return out


class Connection:
    """One client's state: its (style, depth) and policy changes under way."""

    def __init__(self, style: str, depth: int) -> None:
        self.style = style
        self.depth = int(depth)
        self.pending = 0
