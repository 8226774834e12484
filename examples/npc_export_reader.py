"""Reference reader of an ``igraph-fight export`` file (docs/npc_export.md): numpy and the
standard library only, nothing of igraph_fight, no numba. What an engine ports.

    npc = NPCExport.load("npc.bin")
    action, state, off_graph = npc.decide("outboxer", 5, r=1.4, theta_self=0.1, theta_other=-0.2,
                                          m_self=12, m_other=40, f_other=7, mask_other=0)

``decide`` answers what ``NPCController(graph, style=S, depth=D, offgraph="nearest",
first_ply="table").act(obs)`` answers (its ``action`` and ``state``) for every observation
within the controller's input contract (ids in range, finite numbers: check them first, as the
controller does). Run as a script it prints a file's summary and one decision:

    python examples/npc_export_reader.py npc.bin
"""
from __future__ import annotations

import hashlib
import json
import struct
import sys
import zlib

import numpy as np

FORMAT = "igraph-fight/npc-export"
VERSION = 2
MAGIC = b"IGFNPCX1"


def wrap(a):
    """Angle wrap to [-pi, pi) in the form the controller's kernels use: a - 2 pi floor((a + pi) / 2 pi)."""
    return a - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))


class NPCExport:
    """The sections of an export file as numpy arrays, and the table decision over them."""

    def __init__(self, index: dict, sections: dict[str, np.ndarray]) -> None:
        self.index = index
        g = float(index["grid_per_unit"])
        for name in ("r", "theta_self", "theta_other"):  # integer codes of the lookup grid
            sections[name] = sections[name].astype(np.float64) / g
        self.s = sections
        self.tables = {(t["style"], t["depth"]): t for t in index["tables"]}
        self.n_states = index["n_states"]

    @classmethod
    def load(cls, path: str) -> "NPCExport":
        """Read and check an export file: magic, index, checksum, every section's CRC-32 and size."""
        with open(path, "rb") as fh:
            data = fh.read()
        if data[:8] != MAGIC:
            raise ValueError(f"{path}: not an igraph-fight NPC export")
        (n,) = struct.unpack("<Q", data[8:16])
        if 16 + n > len(data):
            raise ValueError(f"{path}: truncated")
        index = json.loads(data[16:16 + n].decode("utf-8"))
        if index.get("format") != FORMAT or index.get("version") != VERSION:
            raise ValueError(f"{path}: format {index.get('format')!r} version {index.get('version')!r} "
                             f"(this reader reads {FORMAT} version {VERSION})")
        body = {k: v for k, v in index.items() if k != "checksum"}
        digest = hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                                           allow_nan=False).encode()).hexdigest()
        if digest != index.get("checksum"):
            raise ValueError(f"{path}: checksum mismatch")
        sections = {}
        for name, m in index["members"].items():
            b = m["data"]
            raw = data[b["offset"]:b["offset"] + b["nbytes"]]
            if len(raw) != b["nbytes"] or zlib.crc32(raw) != b["crc32"]:
                raise ValueError(f"{path}: section {name} truncated or corrupted")
            if b["compression"] == "deflate":
                raw = zlib.decompress(raw)
            dt = np.dtype(b["dtype"])
            if len(raw) != b["count"] * dt.itemsize:
                raise ValueError(f"{path}: section {name} holds {len(raw)} bytes, not {b['count']} {b['dtype']}")
            sections[name] = np.frombuffer(raw, dtype=dt).astype(np.float64 if dt.kind == "f" else np.int64)
        return cls(index, sections)

    # ----- the nearest-state search ---------------------------------------------------------
    def _nearest(self, lo: int, hi: int, r: float, ts: float, to: float, frame_window: tuple[int, int] | None,
                 tie_by_position: bool) -> tuple[int, float]:
        """(key-order position, squared normalised distance) of the nearest state among positions
        [lo, hi) (and F_other within ``frame_window``, inclusive); ties: the smaller state id, or
        the smaller position with ``tie_by_position``; (-1, inf) if none."""
        s = self.s
        pos = np.arange(lo, hi)
        if frame_window is not None:
            f = s["f_other"][lo:hi]
            pos = pos[(f >= frame_window[0]) & (f <= frame_window[1])]
        if len(pos) == 0:
            return -1, float("inf")
        ix = self.index
        dr = s["r"][pos] - r
        d1 = wrap(s["theta_self"][pos] - ts)
        d2 = wrap(s["theta_other"][pos] - to)
        d = dr * dr * ix["inv_sr2"] + (d1 * d1 + d2 * d2) * ix["inv_st2"]
        best = d.min()
        tied = pos[d == best]
        if tie_by_position:
            return int(tied[0]), float(best)
        return int(tied[np.argmin(s["state"][tied])]), float(best)

    def locate(self, r: float, theta_self: float, theta_other: float, m_self: int, m_other: int, f_other: int,
               mask_other: int = 0) -> tuple[int, int, bool, float]:
        """(state, level, off_graph, squared normalised distance): level 0 the compatible group
        (same key, |F_other difference| < f0), 1 the same key at any frame, 2 the same Next-set,
        3 anywhere; off_graph unless level 0 within the linking tolerance. (-1, 4, True, inf)
        for an empty graph. Distances and angles are compared on the file's grid (code /
        grid_per_unit): the state values are stored so, the query is rounded half to even."""
        ix, s = self.index, self.s
        g = float(ix["grid_per_unit"])  # the query on the lookup grid, as the controller rounds it
        r, theta_self, theta_other = (float(np.rint(x * g) / g) for x in (r, theta_self, theta_other))
        ns = int(s["nextset_of"][m_self])
        key = (ns * ix["key_a1"] + m_other) * ix["mask_mod"] + mask_other
        keys = s["key_values"]
        k = int(np.searchsorted(keys, key))
        if k < len(keys) and keys[k] == key:
            lo, hi = int(s["key_starts"][k]), int(s["key_starts"][k + 1])
            f0 = ix["f0"]
            p, d = self._nearest(lo, hi, r, theta_self, theta_other, (f_other - f0 + 1, f_other + f0 - 1), False)
            if p >= 0:
                off = (abs(s["r"][p] - r) > ix["tol_r"] or abs(wrap(s["theta_self"][p] - theta_self)) > ix["tol_theta"]
                       or abs(wrap(s["theta_other"][p] - theta_other)) > ix["tol_theta"])
                return int(s["state"][p]), 0, bool(off), d
            p, d = self._nearest(lo, hi, r, theta_self, theta_other, None, False)
            return int(s["state"][p]), 1, True, d
        if ns in ix["nextsets_present"]:  # level 2: the Next-set's keys are contiguous in key order
            span = ix["key_a1"] * ix["mask_mod"]
            klo = int(np.searchsorted(keys, ns * span))
            khi = int(np.searchsorted(keys, (ns + 1) * span))
            p, d = self._nearest(int(s["key_starts"][klo]), int(s["key_starts"][khi]), r, theta_self, theta_other,
                                 None, False)
            return int(s["state"][p]), 2, True, d
        p, d = self._nearest(0, self.n_states, r, theta_self, theta_other, None, True)
        if p < 0:
            return -1, 4, True, float("inf")
        return int(s["state"][p]), 3, True, d

    # ----- the table decision ---------------------------------------------------------------
    def first_action(self, m_self: int) -> int:
        """The first action of Next(m_self): the answer when no edge is legal."""
        return int(self.s["menu_ids"][self.s["menu_offsets"][m_self]])

    def decide(self, style: str, depth: int, r: float, theta_self: float, theta_other: float, m_self: int,
               m_other: int, f_other: int, mask_other: int = 0) -> tuple[int, int, bool]:
        """(action, state, off_graph) of the table decision of (style, depth): the nearest state's
        best action (levels 0-2: the state has the live Next-set, so it is legal); at level 3 the
        file's fallback for the live Next-set (the best edge if legal, else the best-scoring
        legal edge); the first action of Next(m_self) when neither exists."""
        t = self.tables[(style, int(depth))]
        s, level, off, _ = self.locate(r, theta_self, theta_other, m_self, m_other, f_other, mask_other)
        if s < 0:
            return self.first_action(m_self), s, off
        if level < 3:
            a = int(self.s[t["best"]][s])
        else:
            ns = str(int(self.s["nextset_of"][m_self]))
            a = int(self.s[t["fallback"][ns]][s])
        if a == self.index["no_action"]:
            a = self.first_action(m_self)
        return a, s, off


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print("usage: python examples/npc_export_reader.py NPC.bin", file=sys.stderr)
        return 2
    npc = NPCExport.load(argv[0])
    ix = npc.index
    print(f"{argv[0]}: {ix['n_states']} states, {ix['n_actions']} actions, graph {ix['graph_content_hash'][:12]}...")
    print("tables: " + ", ".join(f"{t['style']}({t['depth']})" for t in ix["tables"]))
    style, depth = ix["tables"][0]["style"], ix["tables"][0]["depth"]
    a, s, off = npc.decide(style, depth, 1.4, 0.1, -0.2, 0, 0, 0)
    print(f"{style}({depth}) at r=1.4 m, theta 0.1/-0.2 rad, M_self 0, M_other 0, F_other 0: action {a}, "
          f"state {s}{' (off the graph)' if off else ''}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
