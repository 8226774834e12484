"""The Interaction Graph: arrays, the versioned graph file, summaries and export.

File (``.igz``): an uncompressed .npz holding the arrays below and ``header`` (JSON bytes):
format, version, created (UTC timestamp), package version, library fingerprint and summary,
build options, seed, build report, ``content_hash`` (sha256 over the state, edge and edge-feature
arrays; no timestamps) and ``checksum`` (sha256 over every array). Written atomically; ``load``
validates everything and raises GraphFormatError (a LibraryFormatError) with a clear message.

Arrays follow docs/contracts.md. States (S,), from the decider's perspective:
``state_r`` (m), ``state_theta_self``, ``state_theta_other`` (rad), ``state_m_self`` (a
representative finished action; its menu Next(M_self) is the state's menu), ``state_nextset``,
``state_m_other``, ``state_f_other``, ``state_mask_other`` (the other's open resolved-strike bits),
``state_size`` (samples merged), ``state_snap_r`` / ``state_snap_theta`` (largest snapping of a
member, m / rad). Edges (E,) in CSR by ``state_offsets`` (S+1,): ``edge_target``, ``edge_swap``,
``edge_action``, the ``feat_*`` features, and ``edge_snap_r`` / ``edge_snap_theta`` (how far the
simulated landing lies from the target state, m / rad).
"""
from __future__ import annotations

import datetime as _dt
import hashlib
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from motion_graph.rotations import wrap_angle

from motion_graph.atomic import atomic_write
from motion_graph.errors import LibraryFormatError

FORMAT = "igraph-fight/interaction-graph"
VERSION = 1

STATE_ARRAYS = {
    "state_r": np.float64, "state_theta_self": np.float64, "state_theta_other": np.float64,
    "state_m_self": np.int32, "state_nextset": np.int32, "state_m_other": np.int32, "state_f_other": np.int32,
    "state_mask_other": np.int64, "state_size": np.int32, "state_snap_r": np.float64,
    "state_snap_theta": np.float64,
}
EDGE_ARRAYS = {
    "edge_target": np.int32, "edge_swap": np.uint8, "edge_action": np.int32,
    "feat_duration": np.float64, "feat_r": np.float64, "feat_r_mean": np.float64,
    "feat_theta_self": np.float64, "feat_theta_other": np.float64, "feat_dmg_given": np.float64,
    "feat_dmg_received": np.float64, "feat_kind": np.int32, "feat_other_kind": np.int32,
    "feat_def_self": np.float64, "feat_def_other": np.float64,
    "edge_snap_r": np.float64, "edge_snap_theta": np.float64,
}
ALL_ARRAYS = {"state_offsets": np.int64, **STATE_ARRAYS, **EDGE_ARRAYS}


class GraphFormatError(LibraryFormatError):
    """A graph file is missing, truncated, corrupted, of another version or for another library."""


def _hash_arrays(arrays: dict[str, np.ndarray], names) -> str:
    h = hashlib.sha256()
    for k in sorted(names):
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def library_fingerprint(lib) -> str:
    """sha256 over an ActionLibrary's arrays, labels, parts and frame rate."""
    h = hashlib.sha256()
    names = getattr(lib, "_ARRAYS", ())
    for k in sorted(names):
        a = np.ascontiguousarray(np.asarray(getattr(lib, k)))
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(memoryview(a).cast("B"))
    h.update(json.dumps({"labels": list(lib.labels), "parts": dict(sorted(lib.parts.items())),
                         "fps": float(lib.fps)}).encode())
    return h.hexdigest()


def package_version() -> str:
    try:
        from importlib.metadata import version
        return version("igraph-fight")
    except Exception:  # not installed
        return "unknown"


@dataclass
class InteractionGraph:
    """States, edges (CSR) and edge features of an Interaction Graph; see the module docstring."""

    arrays: dict[str, np.ndarray]
    header: dict = field(default_factory=dict)

    # ----- views ---------------------------------------------------------------------------
    def __getattr__(self, name: str):
        arrays = self.__dict__.get("arrays")
        if arrays is not None and name in arrays:
            return arrays[name]
        raise AttributeError(name)

    def __getitem__(self, name: str):
        """Dict-like access to the arrays (and ``kinds_table``), as planner/ takes them."""
        if name == "kinds_table":
            from motion_graph.classify import KINDS
            return list(self.header.get("kinds_table") or KINDS)
        return self.arrays[name]

    def __contains__(self, name: str) -> bool:
        return name in self.arrays or name == "kinds_table"

    def keys(self):
        return [*self.arrays.keys(), "kinds_table"]

    def as_dict(self) -> dict:
        """The arrays plus ``kinds_table`` (the KINDS names feat_kind indexes), for planner/."""
        return {**self.arrays, "kinds_table": self["kinds_table"]}

    @property
    def n_states(self) -> int:
        return len(self.arrays["state_r"])

    @property
    def n_edges(self) -> int:
        return len(self.arrays["edge_target"])

    @property
    def content_hash(self) -> str:
        """sha256 over the state, edge and edge-feature arrays (no timestamps, no options)."""
        return _hash_arrays(self.arrays, ALL_ARRAYS)

    @property
    def library_fingerprint(self) -> str:
        return self.header.get("library", {}).get("fingerprint", "")

    def out_degree(self) -> np.ndarray:
        return np.diff(self.arrays["state_offsets"])

    def edges_of(self, s: int) -> np.ndarray:
        """Edge ids leaving state s."""
        off = self.arrays["state_offsets"]
        return np.arange(off[s], off[s + 1])

    def state_features(self) -> dict[str, np.ndarray]:
        """Per state: r (m), theta_self, theta_other (rad), m_self, nextset, m_other, f_other, mask_other."""
        a = self.arrays
        return {"r": a["state_r"], "theta_self": a["state_theta_self"], "theta_other": a["state_theta_other"],
                "m_self": a["state_m_self"], "nextset": a["state_nextset"], "m_other": a["state_m_other"],
                "f_other": a["state_f_other"], "mask_other": a["state_mask_other"]}

    def edge_features(self) -> dict[str, np.ndarray]:
        """Edge features (decider's perspective), keyed without the ``feat_`` prefix."""
        return {k[5:]: v for k, v in self.arrays.items() if k.startswith("feat_")}

    def sim_params(self):
        """The kinematic simulator's options the graph was built with (a SimParams; the defaults
        for files that do not record them)."""
        from igraph_fight.sim import SimParams
        opts = self.header.get("options", {}).get("sim")
        return SimParams(**opts) if opts else SimParams()

    def load_library(self):
        """The action library the graph was built from (embedded in the graph file)."""
        if "library_npz" not in self.arrays:
            raise GraphFormatError(self.header.get("path", "<graph>"),
                                   "no embedded action library; pass the library file (--library)")
        from motion_graph.library import library_from_bytes
        lib = library_from_bytes(self.arrays["library_npz"].tobytes(), f"{self.header.get('path', '<graph>')}#library")
        self.check_library(lib)
        return lib

    def check_library(self, lib) -> None:
        """Raise GraphFormatError when ``lib`` is not the library this graph was built from."""
        fp = library_fingerprint(lib)
        if fp != self.library_fingerprint:
            raise GraphFormatError(self.header.get("path", "graph"),
                                   f"built from another action library (fingerprint {self.library_fingerprint[:12]}, "
                                   f"given {fp[:12]})")

    def groups(self) -> np.ndarray:
        """Compatible-group id per state (0..G-1, by sorted key)."""
        f0 = int(self.header.get("options", {}).get("f0", 3))
        a = self.arrays
        key = np.stack([a["state_nextset"], a["state_m_other"], a["state_f_other"] // f0, a["state_mask_other"]], 1)
        _, inv = np.unique(key, axis=0, return_inverse=True)
        return inv.reshape(-1)

    def _compatible(self, nextset: int, m_other: int, f_other: int, mask_other: int) -> np.ndarray | None:
        """States of the compatible group of a live state (same Next-set id, M_other and mask,
        |F_other difference| < F0); None when the group holds none."""
        a = self.arrays
        f0 = int(self.header.get("options", {}).get("f0", 3))
        groups = self.__dict__.get("_group_index")
        if groups is None:
            key = (a["state_nextset"].astype(np.int64) * 1_000_003 + a["state_m_other"]) * 2_000_003 + a["state_mask_other"]
            order = np.argsort(key, kind="stable")
            ks = key[order]
            starts = np.concatenate([[0], np.nonzero(ks[1:] != ks[:-1])[0] + 1, [len(ks)]])
            groups = {int(ks[starts[i]]): order[starts[i]:starts[i + 1]] for i in range(len(starts) - 1)}
            self.__dict__["_group_index"] = groups
        cand = groups.get(int((nextset * 1_000_003 + m_other) * 2_000_003 + mask_other))
        if cand is None:
            return None
        cand = cand[np.abs(a["state_f_other"][cand] - f_other) < f0]
        return cand if len(cand) else None

    def _link_tolerance(self) -> tuple[float, float]:
        opts = self.header.get("options", {})
        return float(opts.get("link_tol_r_m", 0.1)), float(opts.get("link_tol_theta_rad", np.radians(20)))

    def nearest_state(self, nextset: int, m_other: int, f_other: int, mask_other: int, r: float,
                      theta_self: float, theta_other: float) -> tuple[int, float, bool]:
        """The state nearest (paper's normalised distance) to a live state among the compatible
        ones: same Next-set id of M_self (SimTables.nextset), M_other and mask, |F_other
        difference| < F0. Returns (state, distance, that state within the linking tolerance);
        (-1, inf, False) when no compatible state exists."""
        a = self.arrays
        opts = self.header.get("options", {})
        cand = self._compatible(nextset, m_other, f_other, mask_other)
        if cand is None:
            return -1, float("inf"), False
        s_r = float(opts.get("s_r_m", 0.5))
        s_t = float(opts.get("s_theta_rad", np.pi / 6))
        dr = a["state_r"][cand] - r
        d1 = wrap_angle(a["state_theta_self"][cand] - theta_self)
        d2 = wrap_angle(a["state_theta_other"][cand] - theta_other)
        d = (dr / s_r) ** 2 + (d1 / s_t) ** 2 + (d2 / s_t) ** 2
        i = int(np.lexsort((cand, d))[0])
        tr, tt = self._link_tolerance()
        within = abs(dr[i]) <= tr and abs(d1[i]) <= tt and abs(d2[i]) <= tt
        return int(cand[i]), float(np.sqrt(d[i])), bool(within)

    def covers(self, nextset: int, m_other: int, f_other: int, mask_other: int, r: float, theta_self: float,
               theta_other: float) -> bool:
        """Whether some compatible state lies within the linking tolerance of a live state (the
        coverage of the paper's section 7.1). The nearest state by the normalised distance can
        miss the tolerance while another state meets it (a larger angle, a smaller distance):
        nearest_state's flag is the stricter test."""
        a = self.arrays
        cand = self._compatible(nextset, m_other, f_other, mask_other)
        if cand is None:
            return False
        tr, tt = self._link_tolerance()
        ok = ((np.abs(a["state_r"][cand] - r) <= tr) & (np.abs(wrap_angle(a["state_theta_self"][cand] - theta_self)) <= tt)
              & (np.abs(wrap_angle(a["state_theta_other"][cand] - theta_other)) <= tt))
        return bool(ok.any())

    def locate(self, tables, world, who: int) -> tuple[int, float, bool]:
        """nearest_state for avatar ``who`` of a live world (igraph_fight.state.WorldState) at its
        decision instant; ``tables`` are the simulator tables of the graph's library."""
        from igraph_fight.state import to_sample
        si, sf = to_sample(tables, world, who)
        return self.nearest_state(int(tables.nextset[si[0]]), int(si[1]), int(si[2]), int(si[3]), float(sf[0]),
                                  float(sf[1]), float(sf[2]))

    # ----- summaries ------------------------------------------------------------------------
    def info(self) -> dict:
        """States, edges, groups, degree histogram, snapping, dead ends, content hash."""
        deg = self.out_degree()
        S, E = self.n_states, self.n_edges
        edges_hist = np.bincount(deg) if S else np.zeros(1, dtype=np.int64)
        rep = self.header.get("report", {})
        from motion_graph.classify import KINDS
        kinds = np.bincount(self.arrays["feat_kind"], minlength=len(KINDS)) if E else np.zeros(len(KINDS), int)
        return {
            "path": self.header.get("path"),
            "format": self.header.get("format", FORMAT), "version": self.header.get("version", VERSION),
            "package_version": self.header.get("package_version"), "created": self.header.get("created"),
            "seed": self.header.get("seed"), "library_fingerprint": self.library_fingerprint,
            "n_states": S, "n_edges": E, "n_groups": int(len(np.unique(self.groups()))) if S else 0,
            "mean_out_degree": float(E / S) if S else 0.0,
            "degree_histogram": {str(i): int(c) for i, c in enumerate(edges_hist) if c},
            "dead_end_fraction": float(np.mean(deg == 0)) if S else 1.0,
            "swap_fraction": float(np.mean(self.arrays["edge_swap"])) if E else 0.0,
            "edges_by_kind": {KINDS[i]: int(c) for i, c in enumerate(kinds) if c},
            "edges_with_damage_given": int(np.sum(self.arrays["feat_dmg_given"] > 0)),
            "edges_with_damage_received": int(np.sum(self.arrays["feat_dmg_received"] > 0)),
            "snap_mean_cm": rep.get("snap_mean_cm"), "snap_max_cm": rep.get("snap_max_cm"),
            "snap_mean_deg": rep.get("snap_mean_deg"), "snap_max_deg": rep.get("snap_max_deg"),
            "edge_snap_mean_cm": float(100 * self.arrays["edge_snap_r"].mean()) if E else 0.0,
            "edge_snap_max_cm": float(100 * self.arrays["edge_snap_r"].max()) if E else 0.0,
            "edge_snap_mean_deg": float(np.degrees(self.arrays["edge_snap_theta"].mean())) if E else 0.0,
            "edge_snap_max_deg": float(np.degrees(self.arrays["edge_snap_theta"].max())) if E else 0.0,
            "content_hash": self.content_hash,
            "options": self.header.get("options"),
        }

    def to_networkx(self):
        """A networkx.MultiDiGraph: nodes with the state features, one edge per graph edge
        (key = edge id) with action, swap and the features."""
        import networkx as nx
        a = self.arrays
        g = nx.MultiDiGraph()
        node_cols = {k[6:]: a[k].tolist() for k in ("state_r", "state_theta_self", "state_theta_other", "state_m_self",
                                                    "state_nextset", "state_m_other", "state_f_other",
                                                    "state_mask_other", "state_size")}
        g.add_nodes_from((s, {k: v[s] for k, v in node_cols.items()}) for s in range(self.n_states))
        off = a["state_offsets"]
        src = np.repeat(np.arange(self.n_states), np.diff(off)).tolist()
        feats = [k for k in EDGE_ARRAYS if k != "edge_target"]
        names = [k[5:] if k.startswith("feat_") else k for k in feats]
        cols = [a[k].tolist() for k in feats]
        tgt = a["edge_target"].tolist()
        g.add_edges_from((src[e], tgt[e], e, dict(zip(names, (c[e] for c in cols)))) for e in range(self.n_edges))
        return g

    # ----- persistence ----------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write the graph file atomically (uncompressed .npz with a JSON header)."""
        arrays = {k: np.ascontiguousarray(self.arrays[k], dtype=ALL_ARRAYS[k]) for k in ALL_ARRAYS}
        if "library_npz" in self.arrays:
            arrays["library_npz"] = np.ascontiguousarray(self.arrays["library_npz"], dtype=np.uint8)
        header = {k: v for k, v in self.header.items() if k != "path"}
        header.update(format=FORMAT, version=VERSION, content_hash=_hash_arrays(arrays, ALL_ARRAYS),
                      checksum=_hash_arrays(arrays, arrays.keys()),
                      shapes={k: list(v.shape) for k, v in arrays.items()})
        header.setdefault("created", _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
        header.setdefault("package_version", package_version())

        def write(fh) -> None:
            np.savez(fh, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays)

        atomic_write(path, write)
        self.header = {**header, "path": str(path)}

    @classmethod
    def load(cls, path: str | os.PathLike) -> "InteractionGraph":
        """Read and validate a graph file (GraphFormatError on any problem)."""
        path = str(path)
        if not os.path.exists(path):
            raise GraphFormatError(path, "no such file")
        try:
            with np.load(path, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except Exception as e:  # BadZipFile, EOFError, ValueError, OSError, CRC errors
            raise GraphFormatError(path, f"not a readable interaction-graph file (truncated or corrupted?): "
                                         f"{type(e).__name__}: {e}") from None
        if "header" not in data:
            raise GraphFormatError(path, "no header: not an igraph-fight interaction graph")
        try:
            header = json.loads(bytes(data.pop("header")).decode())
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise GraphFormatError(path, "header is corrupted") from None
        if not isinstance(header, dict) or header.get("format") != FORMAT:
            raise GraphFormatError(path, f"not an interaction graph (format {header.get('format')!r})"
                                   if isinstance(header, dict) else "header is corrupted")
        if header.get("version") != VERSION:
            raise GraphFormatError(path, f"graph version {header.get('version')} is not supported "
                                         f"(expected {VERSION}); rebuild it with `igraph-fight build`")
        missing = [k for k in ALL_ARRAYS if k not in data]
        if missing:
            raise GraphFormatError(path, f"missing arrays: {', '.join(missing)}")
        for k, dt in ALL_ARRAYS.items():
            if data[k].dtype != np.dtype(dt) or data[k].ndim != 1:
                raise GraphFormatError(path, f"array {k} has dtype {data[k].dtype} and {data[k].ndim} dims "
                                             f"(expected 1-d {np.dtype(dt)})")
        if _hash_arrays(data, data.keys()) != header.get("checksum"):
            raise GraphFormatError(path, "checksum mismatch: the file is corrupted")
        S = len(data["state_r"])
        E = len(data["edge_target"])
        bad = [k for k in STATE_ARRAYS if len(data[k]) != S] + [k for k in EDGE_ARRAYS if len(data[k]) != E]
        off = data["state_offsets"]
        if bad or len(off) != S + 1 or (S + 1 and (off[0] != 0 or off[-1] != E or np.any(np.diff(off) < 0))):
            raise GraphFormatError(path, "inconsistent array lengths or CSR offsets")
        if E and (data["edge_target"].min() < 0 or data["edge_target"].max() >= S):
            raise GraphFormatError(path, "edge targets out of range")
        header["path"] = path
        return cls(data, header)


def load_graph(path: str | os.PathLike) -> InteractionGraph:
    """InteractionGraph.load."""
    return InteractionGraph.load(path)


def export_graphml(graph: InteractionGraph, path: str | os.PathLike) -> None:
    """Write the graph as GraphML (networkx), atomically."""
    import networkx as nx
    g = graph.to_networkx()
    g.graph.update({"content_hash": graph.content_hash, "library_fingerprint": graph.library_fingerprint})
    buf = io.BytesIO()
    nx.write_graphml(g, buf)
    atomic_write(path, lambda fh: fh.write(buf.getvalue()))



def header_summary(path: str | os.PathLike) -> dict:
    """The header of a graph file without validating the arrays (for quick listing)."""
    with np.load(Path(path), allow_pickle=False) as z:
        return json.loads(bytes(z["header"]).decode())
