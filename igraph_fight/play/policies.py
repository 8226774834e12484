"""Policy tables by (style, depth), shared by every connection and game session of a server.

One NPCController holds the graph, its lookup index and the simulator tables; each (style,
depth) is a shallow copy of it with its own policy table (the copy shares the graph, the index
and the controller's single policy worker thread, so tables are computed one at a time and the
server's other requests keep being answered meanwhile). At most ``max_entries`` tables are kept,
the least recently used evicted (a connection still holding one keeps it alive), and at most
``max_pending`` are computed at once (more: a ``busy`` error).
"""
from __future__ import annotations

import asyncio
import copy
import time
from collections import OrderedDict
from functools import lru_cache
from pathlib import Path

import numpy as np

from igraph_fight.play.protocol import (
    DEPTH_RANGE, MAX_PENDING_TABLES, MAX_POLICIES, MAX_STYLE_FILE_BYTES, ProtocolError)


@lru_cache(maxsize=1)
def presets() -> frozenset[str]:
    """The preset style names (read once: the package's presets do not change while it runs)."""
    from planner import list_presets
    return frozenset(list_presets())


def style_key(style: str) -> str:
    """A canonical key for a style: the preset name, or the resolved path of a style file with its
    size and modification time (an edited file is a new style). Raises ProtocolError("bad_style")
    for a name that is neither a preset nor a readable .toml / .json file of at most
    MAX_STYLE_FILE_BYTES."""
    if style in presets():
        return style
    p = Path(style).expanduser()
    if p.suffix.lower() not in (".toml", ".json"):
        raise ProtocolError("bad_style", f"{style[:80]!r} is no preset ({', '.join(sorted(presets()))}) and no "
                                         ".toml / .json style file")
    try:
        st = p.resolve().stat()
    except (OSError, RuntimeError):
        raise ProtocolError("bad_style", f"no style file {style[:80]!r}") from None
    if not p.is_file():
        raise ProtocolError("bad_style", f"{style[:80]!r} is not a file")
    if st.st_size > MAX_STYLE_FILE_BYTES:
        raise ProtocolError("bad_style", f"style file of more than {MAX_STYLE_FILE_BYTES} bytes")
    return f"{p.resolve()}|{st.st_size}|{st.st_mtime_ns}"


class PolicyPool:
    """NPC controllers by (style, depth), computed on demand (module docstring)."""

    def __init__(self, base, base_style: str, max_entries: int = MAX_POLICIES,
                 max_pending: int = MAX_PENDING_TABLES) -> None:
        self.base = base
        self.max_entries = int(max_entries)
        self.max_pending = int(max_pending)
        self._entries: OrderedDict[tuple[str, int], tuple[object, str, float]] = OrderedDict()
        self._pending: dict[tuple[str, int], asyncio.Future] = {}
        self._entries[(style_key(base_style), int(base.depth))] = (base, base.style, 0.0)

    def cached(self, style: str, depth: int):
        """The controller of (style, depth) if it is ready, else None (no computation)."""
        try:
            key = (style_key(style), int(depth))
        except ProtocolError:
            return None
        e = self._entries.get(key)
        if e is not None:
            self._entries.move_to_end(key)
            return e[0]
        return None

    async def get(self, style: str, depth: int) -> tuple[object, float]:
        """(controller, milliseconds its table took: 0 when cached) of (style, depth). Raises
        ProtocolError("bad_style") for an unknown or invalid style or depth out of DEPTH_RANGE."""
        depth = int(depth)
        if not DEPTH_RANGE[0] <= depth <= DEPTH_RANGE[1]:
            raise ProtocolError("bad_request", f"depth {depth} outside {DEPTH_RANGE[0]}..{DEPTH_RANGE[1]}")
        key = (style_key(style), depth)
        e = self._entries.get(key)
        if e is not None:
            self._entries.move_to_end(key)
            return e[0], 0.0
        fut = self._pending.get(key)
        if fut is None:
            if len(self._pending) >= self.max_pending:
                raise ProtocolError("busy", f"{len(self._pending)} policy tables are being computed: try again")
            fut = asyncio.ensure_future(self._compute(key, style, depth))
            self._pending[key] = fut
            fut.add_done_callback(lambda f, k=key: (self._pending.pop(k, None), f.cancelled() or f.exception()))
        return await asyncio.shield(fut)

    async def _compute(self, key, style: str, depth: int):
        from planner import load_style

        t0 = time.perf_counter()
        try:
            st = await asyncio.to_thread(load_style, style)
        except ValueError as e:  # planner.StyleError
            raise ProtocolError("bad_style", str(e)) from None
        c = copy.copy(self.base)  # shares graph, index, tables and the policy worker; gets its own table
        if depth != c.depth:
            await asyncio.wrap_future(c.set_depth(depth))
        await asyncio.wrap_future(c.set_style(st))
        ms = (time.perf_counter() - t0) * 1e3
        self._entries[key] = (c, st.name, ms)
        while len(self._entries) > self.max_entries:
            self._entries.popitem(last=False)
        return c, ms

    def __len__(self) -> int:
        return len(self._entries)


def changed_share(old, new) -> float:
    """Share of graph states whose best action differs between two controllers' policies."""
    act = np.asarray(new.graph.arrays["edge_action"])
    a = np.asarray(old.policy.best_me)
    b = np.asarray(new.policy.best_me)
    if len(a) == 0:
        return 0.0
    aa = np.where(a >= 0, act[np.maximum(a, 0)], -1)
    bb = np.where(b >= 0, act[np.maximum(b, 0)], -1)
    return float(np.mean(aa != bb))
