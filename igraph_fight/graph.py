"""The Interaction Graph: arrays, the versioned graph file, summaries and export.

File (``.igz``): the arrays below and a JSON header: format, version, created (UTC timestamp),
package version, library fingerprint and summary, build options, seed, build report,
``content_hash`` and ``checksum``. Written atomically (motion_graph.atomic).

``content_hash`` (every version, the same for one graph in any version): sha256 over the arrays
of ALL_ARRAYS in sorted name order, each as its name, its canonical dtype (ALL_ARRAYS: e.g.
``float64``), its shape and its little-endian bytes in that dtype; no timestamps, no header,
not the embedded library. A file's storage (narrowed integers, tables, derived arrays,
compression) does not enter it: the arrays are hashed as they are in memory after loading.

Versions:

- 4 (written now): version 3's container, with the continuous edge arrays replayed instead of
  stored. ``feat_r``, ``feat_r_mean``, ``feat_theta_self``, ``feat_theta_other``,
  ``edge_snap_r`` and ``edge_snap_theta`` are ``derived`` members of the ``replay/<array>``
  formulas (REPLAYED): igraph_fight.graph_replay repeats each edge's event from its state with
  the embedded library and the header's simulator options, the kinematics only (hits never move
  a body), in the builder's floating-point operations. The writer compares every value bit for
  bit (and stores those that differ) and records the CRC-32 of each array; the reader replays
  on first access (about 1 s per 5 M edges and core) and refuses an array whose CRC-32 differs
  (a machine whose floating point differs from the writer's: convert the file to version 3
  where it was written). A file without an embedded library stores them as version 3 does.
- 3 ("compact"): the container of igraph_fight.graph_compact: an index (the header
  with a ``members`` entry per array) and 64-byte aligned blobs. The continuous float arrays
  (COMPACT_MAPPED) are stored as they are and memory-mapped; integer arrays narrowed to the
  smallest integer dtype holding their values and deflated; float arrays with few distinct values
  (durations, damages, defences, state snapping) as a table of those values and uint8 / uint16
  codes, deflated; ``state_offsets`` as its differences; ``edge_snap_r`` and ``edge_snap_theta``
  as the formulas of DERIVED (how the builder computes them from the landing) plus the values
  where the formula differs in any bit. Every encoding is exact: the arrays decode to the same
  bits. ``checksum`` is sha256 over the index's JSON without ``checksum`` (keys sorted,
  compact), which holds every blob's CRC-32; ``load`` checks both.
- 2 (read still; ``save(version=2)`` writes it): an uncompressed .npz of the arrays and
  ``header``; ``checksum`` is sha256 over the header's JSON without ``checksum`` and every array.
- 1 (read still): the .npz of version 2 whose checksum covers the arrays only.

``igraph-fight graph convert OLD NEW`` rewrites a file of any version as version 4 (``--version
3`` or ``2``: as those). A checksum
anyone can recompute detects corruption, not tampering: what makes a file safe to use is that
``load`` also checks every value (``validate``).

``load`` reads without trusting the file and raises GraphFormatError (a LibraryFormatError) whose
one-line message names the file and the field. Before anything is inflated: for versions 1 and
2, the zip and .npy headers (motion_graph.library.read_npz): every member's declared size equal
to what its .npy shape and dtype need, all together no more than the file's size plus 1 MiB, a
header of at most HEADER_MAX_BYTES; for version 3, the index (at most HEADER_MAX_BYTES of strict
JSON) and every member spec: blobs inside the file, dtypes and shapes as ALL_ARRAYS says, what
decoding allocates at most graph_compact.MAX_INFLATION times the file's size; for version 4, a
replayed member needs the embedded library, and the replay checks every index it follows
(graph_replay.check_inputs) before it runs. Then the checksum
(and version 3's CRC-32s). Then ``validate``: the header's fields and build options
type- and range-checked (unknown option keys refused), every index array within the arrays it
indexes, every float finite and in range, and, with the embedded library (validated as
motion_graph.library.load_library does), every action, frame, mask, Next-set, menu and kind
consistent with it. A graph that loads is safe for the numba kernels. Version 3's validation
reads the stored form (the narrowed integers, the tables' values, the derived arrays'
exceptions: the same values); the arrays other than the memory-mapped ones are decoded on first
access (graph_compact.GraphArrays); a problem found then (a replayed array's CRC-32) is a
GraphFormatError naming the file too.

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
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np

from motion_graph.rotations import wrap_angle

from motion_graph.atomic import atomic_write, kill_point
from motion_graph.errors import LibraryFormatError

from igraph_fight import graph_compact as gc
from igraph_fight.graph_compact import GraphArrays, Member

if TYPE_CHECKING:
    from motion_graph.library import ActionLibrary

FORMAT = "igraph-fight/interaction-graph"
VERSION = 4
#: versions ``load`` reads (see the module docstring for their checksum rules)
READABLE_VERSIONS = (1, 2, 3, 4)
#: versions ``save`` writes
WRITABLE_VERSIONS = (2, 3, 4)
#: versions in the compact container (igraph_fight.graph_compact)
COMPACT_VERSIONS = (3, 4)
#: the largest JSON header of a graph file, bytes
HEADER_MAX_BYTES = 4 << 20
#: states and edges a graph may hold (planner packs 2 * target + swap into an int32)
MAX_STATES = 1 << 30
MAX_EDGES = (1 << 31) - 1

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


def _snap_r(a) -> np.ndarray:
    """edge_snap_r as the builder computes it (igraph_fight.build.edges.link): |landing r - target r|."""
    return np.abs(a["feat_r"] - a["state_r"][a["edge_target"]])


def _snap_theta(a) -> np.ndarray:
    """edge_snap_theta as the builder computes it from the landing's angles, seen by whoever decides
    there (the features' self and other swapped after a swap edge); exact where the landing's
    angles are the features' (the decider does not change), the file keeps the other values."""
    t = a["edge_target"]
    sw = a["edge_swap"].astype(bool)
    c1 = np.where(sw, a["feat_theta_other"], a["feat_theta_self"])
    c2 = np.where(sw, a["feat_theta_self"], a["feat_theta_other"])
    return np.maximum(np.abs(wrap_angle(c1 - a["state_theta_self"][t])),
                      np.abs(wrap_angle(c2 - a["state_theta_other"][t])))


#: version 3: arrays stored as formulas of the others (plus the values where they differ)
DERIVED = {"edge_snap_r": _snap_r, "edge_snap_theta": _snap_theta}
#: version 4: arrays stored as the kinematic replay of their edges (igraph_fight.graph_replay)
REPLAYED = ("feat_r", "feat_r_mean", "feat_theta_self", "feat_theta_other", "edge_snap_r", "edge_snap_theta")


def replay_formula(name: str) -> str:
    """The formula name of replayed array ``name``."""
    return f"replay/{name}"


def _replay_values(a: GraphArrays) -> dict[str, np.ndarray]:
    """The replay of a compact file's edges (graph_replay.replay_edges, run once per file and
    shared by the replayed arrays) plus the snapping it implies; a FormatProblem when the file
    cannot be replayed."""
    with a._lock:
        cache = a.context.get("replay")
        if cache is None:
            cache = replayed_arrays(a, a.context.get("header", {}), a.context.get("library"),
                                    workers=_decode_workers())
            if isinstance(cache, str):
                raise gc.FormatProblem(cache)
            a.context["replay"] = cache
        return cache


def _decode_workers() -> int:
    """Threads a replay uses when a file is decoded: numba's thread count (NUMBA_NUM_THREADS)."""
    import numba
    return max(1, int(numba.config.NUMBA_NUM_THREADS))


class ReplayRefused(ValueError):
    """A shard of replayed_shards that cannot be replayed (an index out of range)."""


def replayed_arrays(arrays, header: dict, library=None, workers: int | None = 1) -> dict[str, np.ndarray] | str:
    """The REPLAYED arrays as the replay of ``arrays``' edges gives them, with the embedded
    library (or ``library``) and ``header``'s simulator options, or a string saying why they
    cannot be replayed."""
    shards = replayed_shards(arrays, header, library, workers, shard_edges=max(len(arrays["edge_target"]), 1))
    if isinstance(shards, str):
        return shards
    try:
        for _, _, r in shards:
            return r
    except ReplayRefused as e:
        return f"cannot replay the edges ({e})"
    return "cannot replay the edges (no shard)"


def replayed_shards(arrays, header: dict, library=None, workers: int | None = 1, shard_edges: int = gc.SHARD_EDGES):
    """replayed_arrays shard by shard (graph_replay.iter_replay): an iterator of (e0, e1, the
    REPLAYED arrays at edges [e0, e1)) over runs of whole states, or a string saying why the
    edges cannot be replayed (checked before the first shard)."""
    from igraph_fight.graph_replay import check_inputs, iter_replay
    from igraph_fight.sim import SimParams, SimTables

    try:
        if library is None:
            if "library_npz" not in arrays:
                return "replayed arrays need the embedded library (library_npz), which the file lacks"
            from motion_graph.library import library_from_bytes
            library = library_from_bytes(np.asarray(arrays["library_npz"]).tobytes(), "<graph>#library")
        opts = header.get("options") if isinstance(header, dict) else None
        opts = (opts.get("sim") if isinstance(opts, dict) else None) or {}
        check_options({"sim": opts}, "<graph>")
        tables = SimTables.from_library(library, SimParams(**opts))
        problem = check_inputs(tables, arrays)
    except (LibraryFormatError, ValueError, TypeError, IndexError, KeyError) as e:
        return f"cannot replay the edges ({getattr(e, 'problem', None) or e})"
    if problem is not None:
        return f"cannot replay the edges ({problem})"
    s_r, s_ts, s_to = (np.asarray(arrays[k]) for k in ("state_r", "state_theta_self", "state_theta_other"))
    S = len(s_r)

    def shards():
        for e0, e1, r in iter_replay(tables, arrays, workers, shard_edges=shard_edges, checked=True):
            t = np.asarray(arrays["edge_target"][e0:e1])
            if len(t) and (t.min() < 0 or t.max() >= S):
                raise ReplayRefused("edge_target: a state outside the graph")
            with np.errstate(all="ignore"):
                r["edge_snap_r"] = np.abs(r["landing_r"] - s_r[t])
                r["edge_snap_theta"] = np.maximum(np.abs(wrap_angle(r["landing_theta_self"] - s_ts[t])),
                                                  np.abs(wrap_angle(r["landing_theta_other"] - s_to[t])))
            yield e0, e1, {k: r[k] for k in REPLAYED}
    return shards()


def _replayed(name: str) -> Callable:
    def formula(a: GraphArrays) -> np.ndarray:
        return _replay_values(a)[name]
    formula.__doc__ = f"{name} as the kinematic replay of its edges."
    return formula


#: every formula a derived member may name: formula -> (the array it yields, its function)
FORMULAS: dict[str, tuple[str, Callable]] = {
    **{k: (k, f) for k, f in DERIVED.items()},
    **{replay_formula(k): (k, _replayed(k)) for k in REPLAYED},
}
#: version 3: float arrays stored as they are and memory-mapped (continuous values: compression
#: gains little and would cost a copy)
COMPACT_MAPPED = ("state_r", "state_theta_self", "state_theta_other", "feat_r", "feat_r_mean", "feat_theta_self",
                  "feat_theta_other", "library_npz")
#: version 3: arrays stored as they are and read into memory (indices the numba kernels follow)
COMPACT_COPIED = ("edge_target",)
#: float arrays in [0, 1e6) (distances, durations, counts), angles (rad, within [-pi, pi]) and
#: damages (within +-1e12); every float array must be finite
NON_NEGATIVE = ("state_r", "state_snap_r", "state_snap_theta", "feat_duration", "feat_r", "feat_r_mean",
                "feat_def_self", "feat_def_other", "edge_snap_r", "edge_snap_theta")
ANGLES = ("state_theta_self", "state_theta_other", "feat_theta_self", "feat_theta_other")
DAMAGES = ("feat_dmg_given", "feat_dmg_received")

_LENGTH = ("float", 1e-9, 1e6)  # a positive length, angle or duration
#: Build options a header may record (igraph_fight.build.pipeline.BuildOptions writes them; a
#: test keeps the two in step): name -> ("int" | "float", min, max), ("bool",), ("choice", values)
#: or ("sim",) for SIM_OPTIONS. Keys missing from a header take their defaults; others are refused.
HEADER_OPTIONS: dict[str, tuple] = {
    "max_samples": ("int", 1, 1 << 40), "min_new_per_round": ("int", 0, 1 << 40), "max_rounds": ("int", 0, 1 << 40),
    "n_initial": ("int", 1, 1 << 40), "initial_r_min_m": ("float", 0.0, 1e6), "initial_r_max_m": ("float", 0.0, 1e6),
    "initial_facing_share": ("float", 0.0, 1.0), "initial_facing_deg": ("float", 1e-9, 180.0),
    "seed_bouts": ("int", 0, 1 << 40), "seed_bout_seconds": _LENGTH, "seed_pairing": ("choice", ("human", "random")),
    "expand_fraction": ("float", 1e-9, 1.0), "f0": ("int", 1, 1 << 31), "tol_r_m": _LENGTH, "tol_theta_rad": _LENGTH,
    "link_tol_r_m": _LENGTH, "link_tol_theta_rad": _LENGTH, "dedup_r_m": _LENGTH, "dedup_theta_rad": _LENGTH,
    "max_distance_m": _LENGTH, "chunk_parents": ("int", 1, 1 << 40), "selection": ("choice", ("round", "parent")),
    "interaction_weight": ("float", 0.0, 1e9), "prune_dead_ends": ("bool",), "max_candidates": ("int", 1, 1 << 20),
    "s_r_m": _LENGTH, "s_theta_rad": _LENGTH, "sim": ("sim",),
}
#: Simulator options (igraph_fight.sim.SimParams) a header may record, as HEADER_OPTIONS;
#: ("map", min, max): names -> numbers.
SIM_OPTIONS: dict[str, tuple] = {
    "contact_radius_m": ("float", 0.0, 100.0), "target_radius_m": ("map", 0.0, 100.0),
    "reach_margin_m": ("float", 0.0, 100.0), "min_distance_m": ("float", 0.0, 100.0),
    "default_damage": ("float", -1e9, 1e9), "damage": ("map", -1e9, 1e9), "max_event_frames": ("int", 1, 10_000_000),
    "guard_radius_m": ("float", 0.0, 100.0), "guard_lead_s": ("float", 0.0, 100.0),
}
#: report fields printed as numbers (`graph info`): a number or null
REPORT_NUMBERS = ("snap_mean_cm", "snap_max_cm", "snap_mean_deg", "snap_max_deg")


class GraphFormatError(LibraryFormatError):
    """A graph file is missing, truncated, corrupted, of another version, out of range or for another library."""


def _hash_arrays(arrays: dict[str, np.ndarray], names, h=None) -> str:
    h = hashlib.sha256() if h is None else h
    for k in sorted(names):
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(memoryview(a).cast("B"))
    return h.hexdigest()


def canonical_header(header: dict) -> bytes:
    """The header's JSON without ``checksum``: keys sorted, compact, ASCII (what version 2 hashes)."""
    return json.dumps({k: v for k, v in header.items() if k != "checksum"}, sort_keys=True, separators=(",", ":"),
                      ensure_ascii=True, allow_nan=False).encode()


def graph_checksum(header: dict, arrays: dict[str, np.ndarray], version: int = VERSION) -> str:
    """The ``checksum`` a graph file of ``version`` records for this header and these arrays:
    sha256 over canonical_header(header) (versions 2 to 4) and, up to version 2, every array
    (name, dtype, shape, bytes); the compact versions' header holds the CRC-32 of every stored
    blob instead."""
    h = hashlib.sha256()
    if version >= 2:
        h.update(canonical_header(header))
    if version >= 3:  # the header's members hold every blob's CRC-32
        return h.hexdigest()
    return _hash_arrays(arrays, arrays.keys(), h)


def _quote(value) -> str:
    from motion_graph.library import quote
    return quote(value)


def _number(v) -> bool:
    """A finite JSON number (not a boolean)."""
    if isinstance(v, bool):
        return False
    return (isinstance(v, float) and math.isfinite(v)) or (isinstance(v, int) and abs(v) < 1 << 1000)


def _check_value(name: str, where: str, v, rule: tuple) -> None:
    """Raise GraphFormatError unless option value ``v`` follows ``rule`` (see HEADER_OPTIONS)."""
    kind = rule[0]
    if kind == "int":
        ok, want = isinstance(v, int) and not isinstance(v, bool) and rule[1] <= v <= rule[2], \
            f"an integer in [{rule[1]}, {rule[2]}]"
    elif kind == "float":
        ok, want = _number(v) and rule[1] <= v <= rule[2], f"a number in [{rule[1]:g}, {rule[2]:g}]"
    elif kind == "bool":
        ok, want = isinstance(v, bool), "true or false"
    elif kind == "choice":
        ok, want = isinstance(v, str) and v in rule[1], "one of " + ", ".join(rule[1])
    else:  # map
        ok = (isinstance(v, dict) and len(v) <= 64
              and all(isinstance(k, str) and len(k) <= 64 and _number(x) and rule[1] <= x <= rule[2]
                      for k, x in v.items()))
        want = f"a map of names to numbers in [{rule[1]:g}, {rule[2]:g}]"
    if not ok:
        raise GraphFormatError(name, f"{where}: {_quote(v)} is not {want}")


def check_options(options: object, name: str = "<graph>") -> None:
    """Raise GraphFormatError unless a header's ``options`` are known build options of the right
    type and range (HEADER_OPTIONS, SIM_OPTIONS) and make a valid SimParams."""
    if not isinstance(options, dict):
        raise GraphFormatError(name, "options: not an object")
    for key, v in options.items():
        rule = HEADER_OPTIONS.get(key)
        if rule is None:
            raise GraphFormatError(name, f"options: unknown key {_quote(key)}")
        if rule[0] != "sim":
            _check_value(name, f"options.{key}", v, rule)
            continue
        if not isinstance(v, dict):
            raise GraphFormatError(name, "options.sim: not an object")
        for k, x in v.items():
            if k not in SIM_OPTIONS:
                raise GraphFormatError(name, f"options.sim: unknown key {_quote(k)}")
            _check_value(name, f"options.sim.{k}", x, SIM_OPTIONS[k])
        from igraph_fight.sim import SimParams
        try:
            SimParams(**v)
        except (TypeError, ValueError) as e:
            raise GraphFormatError(name, f"options.sim: {_quote(str(e))[1:-1]}") from None
    if options.get("initial_r_min_m", 0.0) > options.get("initial_r_max_m", 1e6):
        raise GraphFormatError(name, "options.initial_r_min_m: larger than initial_r_max_m")


def _check_header(header: dict, arrays: dict, name: str) -> None:
    """Types and ranges of a graph header's fields (each optional: in-memory graphs have few)."""
    def bad(what: str, problem: str):
        raise GraphFormatError(name, f"{what}: {problem}")

    if "format" in header and header["format"] != FORMAT:
        bad("format", f"{_quote(header['format'])} is not {FORMAT!r}")
    v = header.get("version", VERSION)
    if isinstance(v, bool) or v not in READABLE_VERSIONS:
        bad("version", f"graph version {_quote(v)} is not supported")
    for key in ("created", "package_version", "content_hash", "checksum"):
        if key in header and not (isinstance(header[key], str) and len(header[key]) <= 200):
            bad(key, f"{_quote(header[key])} is not a string")
    if "seed" in header and not (isinstance(header["seed"], int) and not isinstance(header["seed"], bool)
                                 and abs(header["seed"]) < 1 << 63):
        bad("seed", f"{_quote(header['seed'])} is not an integer")
    if "kinds_table" in header:
        from motion_graph.classify import KINDS
        if header["kinds_table"] != list(KINDS):
            bad("kinds_table", f"{_quote(header['kinds_table'])} is not this version's label table; rebuild the graph")
    lib = header.get("library", {})
    if not isinstance(lib, dict):
        bad("library", "not an object")
    if "fingerprint" in lib and not (isinstance(lib["fingerprint"], str) and len(lib["fingerprint"]) <= 200):
        bad("library.fingerprint", f"{_quote(lib['fingerprint'])} is not a string")
    if "n_actions" in lib:
        _check_value(name, "library.n_actions", lib["n_actions"], ("int", 1, MAX_EDGES))
    if "fps" in lib:
        _check_value(name, "library.fps", lib["fps"], ("float", 1e-9, 10_000.0))
    if "sources" in lib and not (isinstance(lib["sources"], list) and all(isinstance(s, str) for s in lib["sources"])):
        bad("library.sources", "not a list of strings")
    if "options" in header:
        check_options(header["options"], name)
    rep = header.get("report", {})
    if not isinstance(rep, dict):
        bad("report", "not an object")
    for key in REPORT_NUMBERS:
        if rep.get(key) is not None and not _number(rep[key]):
            bad(f"report.{key}", f"{_quote(rep[key])} is not a number")
    shapes = header.get("shapes", {})
    if not isinstance(shapes, dict):
        bad("shapes", "not an object")
    for key, shape in shapes.items():
        if key not in arrays or shape != list(np.shape(_peek(arrays, key))):
            bad("shapes", f"{_quote(key)}: {_quote(shape)} is not the shape of an array of the file")


def _peek(a, k: str):
    """Array ``k`` of a graph's arrays without decoding it: the array, or the graph_compact.Member
    of a compact file not decoded yet."""
    return a.peek(k) if isinstance(a, GraphArrays) else a[k]


def _values(x) -> np.ndarray:
    """What range checks read of an array or a Member (Member.values: the same values)."""
    return x.values() if isinstance(x, Member) else x


def _at(x, i: int) -> str:
    """Where value i of _values(x) lies, for messages."""
    j = x.value_index(i) if isinstance(x, Member) else i
    return f"at [{j}]" if j >= 0 else "in its table of values"


def _within(name: str, what: str, x, lo, hi) -> None:
    """Raise GraphFormatError unless every value of x (an array or a Member) lies in [lo, hi)
    (bounds: numbers or arrays like x)."""
    v = _values(x)
    if len(v) == 0:
        return
    if np.ndim(lo) == 0 and np.ndim(hi) == 0:
        if v.min() >= lo and v.max() < hi:
            return
    out = (v < lo) | (v >= hi)
    if out.any():
        i = int(np.argmax(out))
        lo_i, hi_i = np.broadcast_to(lo, v.shape)[i], np.broadcast_to(hi, v.shape)[i]
        raise GraphFormatError(name, f"{what}: {v[i]} {_at(x, i)} is outside [{lo_i}, {hi_i})")


def _check_arrays(a, header: dict, name: str) -> None:
    """Dtypes, lengths and ranges of a graph's arrays (a dict, or the GraphArrays of a compact
    file, read in their stored form), with the number of actions of the header's library when it
    records one."""
    from motion_graph.classify import KINDS

    def bad(what: str, problem: str):
        raise GraphFormatError(name, f"{what}: {problem}")

    missing = [k for k in ALL_ARRAYS if k not in a]
    if missing:
        bad("arrays", f"missing {', '.join(missing)}")
    x_of = {k: _peek(a, k) for k in [*ALL_ARRAYS, *(("library_npz",) if "library_npz" in a else ())]}
    for k, x in x_of.items():
        dt = ALL_ARRAYS.get(k, np.uint8)
        if not isinstance(x, (np.ndarray, Member)) or x.dtype != np.dtype(dt) or len(x.shape) != 1:
            bad(k, f"dtype {getattr(x, 'dtype', type(x).__name__)} with {len(np.shape(x))} dims "
                   f"(expected 1-d {np.dtype(dt)})")
    S, E = len(x_of["state_r"]), len(x_of["edge_target"])
    if S > MAX_STATES or E > MAX_EDGES:
        bad("state_r", f"{S} states and {E} edges (at most {MAX_STATES} and {MAX_EDGES})")
    for k in STATE_ARRAYS:
        if len(x_of[k]) != S:
            bad(k, f"{len(x_of[k])} values for {S} states")
    for k in EDGE_ARRAYS:
        if len(x_of[k]) != E:
            bad(k, f"{len(x_of[k])} values for {E} edges")
    off = _values(x_of["state_offsets"])
    if len(off) != S + 1 or off[0] != 0 or off[-1] != E or np.any(off[1:] < off[:-1]):
        bad("state_offsets", f"not {S + 1} non-decreasing offsets from 0 to {E}")
    for k, x in x_of.items():
        v = _values(x)
        if k in ALL_ARRAYS and v.dtype.kind == "f":
            for lo, hi in gc.chunks(len(v)):  # piece by piece: no temporary as long as the array
                fin = np.isfinite(v[lo:hi])
                if not fin.all():
                    i = lo + int(np.argmin(fin))
                    bad(k, f"{v[i]} {_at(x, i)} is not finite")
    for k in NON_NEGATIVE:
        _within(name, k, x_of[k], 0.0, 1e6)
    for k in ANGLES:
        _within(name, k, x_of[k], -np.pi - 1e-9, np.pi + 1e-9)
    for k in DAMAGES:
        _within(name, k, x_of[k], -1e12, 1e12)
    _within(name, "edge_target", x_of["edge_target"], 0, S)
    _within(name, "edge_swap", x_of["edge_swap"], 0, 2)
    n_actions = header.get("library", {}).get("n_actions")
    A = int(n_actions) if n_actions is not None else 1 << 31
    for k in ("edge_action", "state_m_self", "state_m_other", "state_nextset"):
        _within(name, k, x_of[k], 0, A)
    _within(name, "state_f_other", x_of["state_f_other"], 0, 1 << 31)
    _within(name, "state_mask_other", x_of["state_mask_other"], 0, 1 << 62)
    _within(name, "state_size", x_of["state_size"], 1, 1 << 31)
    for k in ("feat_kind", "feat_other_kind"):
        _within(name, k, x_of[k], 0, len(KINDS))


def _check_with_library(a, header: dict, lib, name: str) -> None:
    """The graph's actions, frames, masks, Next-sets, menus and kinds against its action library
    (on the stored form of a compact file's arrays, as _check_arrays)."""
    from igraph_fight.locate import nextset_ids
    from motion_graph.library import validate_library

    try:
        validate_library(lib, "library")
    except LibraryFormatError as e:
        raise GraphFormatError(name, f"library: {e.problem}") from None
    A = int(lib.n_actions)
    hdr = header.get("library", {}).get("n_actions")
    if hdr is not None and hdr != A:
        raise GraphFormatError(name, f"library.n_actions: {_quote(hdr)} in the header, the library has {A}")
    x_of = {k: _peek(a, k) for k in ("edge_action", "state_m_self", "state_m_other", "state_f_other",
                                     "state_nextset", "state_mask_other", "state_offsets", "feat_kind",
                                     "feat_other_kind")}
    v = {k: _values(x) for k, x in x_of.items()}
    for k in ("edge_action", "state_m_self", "state_m_other"):
        _within(name, k, x_of[k], 0, A)
    m_self, m_other = v["state_m_self"], v["state_m_other"]  # in range: they index as they are
    _within(name, "state_f_other", x_of["state_f_other"], 0, np.diff(np.asarray(lib.frame_offsets, np.int64))[m_other])
    ns = nextset_ids(lib)[m_self]
    wrong = np.nonzero(v["state_nextset"] != ns)[0]
    if len(wrong):
        i = int(wrong[0])
        raise GraphFormatError(name, f"state_nextset: {v['state_nextset'][i]} at [{i}] is not the Next-set "
                                     f"{ns[i]} of its action {m_self[i]}")
    n_strikes = np.minimum(np.diff(np.asarray(lib.strike_offsets, np.int64))[m_other], 62)
    _within(name, "state_mask_other", x_of["state_mask_other"], 0, np.left_shift(np.int64(1), n_strikes))
    off = np.asarray(v["state_offsets"], dtype=np.int64)
    deg_all = np.diff(off)
    action_all = v["edge_action"]
    if A <= 4096:  # a table of legal (action, next action) pairs
        legal = np.zeros((A, A), dtype=np.bool_)
        legal[np.repeat(np.arange(A), np.diff(np.asarray(lib.next_offsets, np.int64))), np.asarray(lib.next_ids)] = True
    else:  # sorted (action, next action) keys
        menu = np.unique(np.repeat(np.arange(A, dtype=np.int64), np.diff(np.asarray(lib.next_offsets, np.int64))) * A
                         + np.asarray(lib.next_ids, np.int64))
    kinds = np.asarray(lib.kinds)
    kinds = kinds.astype(gc.narrow_dtype(kinds))
    from igraph_fight.graph_replay import state_runs
    for s0, s1 in state_runs(off, gc.CHUNK):  # runs of whole states: memory bounded by a run's edges
        e0, e1 = int(off[s0]), int(off[s1])
        deg = deg_all[s0:s1]
        action = np.asarray(action_all[e0:e1])
        src = np.repeat(m_self[s0:s1], deg)  # the source state's action per edge, in m_self's (stored) dtype
        if A <= 4096:
            ok = legal[src, action]
        else:
            key = src.astype(np.int64) * A + action
            ok = menu[np.minimum(np.searchsorted(menu, key), len(menu) - 1)] == key if len(menu) else key < 0
        if not ok.all():
            e = int(np.argmin(ok))
            raise GraphFormatError(name, f"edge_action: {action[e]} at [{e0 + e}] is not in the menu of its state's "
                                         f"action {src[e]}")
        for k, want in (("feat_kind", kinds[action]), ("feat_other_kind", np.repeat(kinds[m_other[s0:s1]], deg))):
            got = np.asarray(v[k][e0:e1])
            if not np.array_equal(got, want):
                e = int(np.argmax(got != want))
                raise GraphFormatError(name, f"{k}: {got[e]} at [{e0 + e}] is not the kind {want[e]} of its action")


def _check_members(header: dict, members: dict, name: str) -> None:
    """Format, version and the declared dtypes and shapes of a graph file's members (nothing inflated yet)."""
    fmt = header.get("format")
    if fmt != FORMAT:
        raise GraphFormatError(name, f"not an igraph-fight graph file (format {_quote(fmt)})")
    v = header.get("version")
    if v in COMPACT_VERSIONS:
        raise GraphFormatError(name, f"version: an .npz graph file of version {v} (version {v} is the compact "
                                     f"container)")
    if isinstance(v, bool) or v not in READABLE_VERSIONS:
        raise GraphFormatError(name, f"version: graph version {_quote(v)} is not supported (this package reads "
                                     f"{' and '.join(map(str, READABLE_VERSIONS))}); rebuild it with `igraph-fight build`")
    missing = [k for k in ALL_ARRAYS if k not in members]
    if missing:
        raise GraphFormatError(name, f"arrays: missing {', '.join(missing)}")
    extra = sorted(set(members) - set(ALL_ARRAYS) - {"header", "library_npz"})
    if extra:
        raise GraphFormatError(name, f"arrays: unexpected {_quote(extra[0])}")
    for k, dt in [*ALL_ARRAYS.items(), *((("library_npz", np.uint8),) if "library_npz" in members else ())]:
        m = members[k]
        if m.dtype != np.dtype(dt) or len(m.shape) != 1:
            raise GraphFormatError(name, f"{k}: dtype {m.dtype} with {len(m.shape)} dims (expected 1-d {np.dtype(dt)})")
    S, E = members["state_r"].shape[0], members["edge_target"].shape[0]
    for k in ALL_ARRAYS:
        n = S + 1 if k == "state_offsets" else S if k in STATE_ARRAYS else E
        if members[k].shape[0] != n:
            raise GraphFormatError(name, f"{k}: {members[k].shape[0]} values (expected {n})")


def _check_compact_index(header: dict, size: int, data_start: int, name: str) -> None:
    """Format, version and every member spec of a compact file's index (nothing read yet):
    the arrays of ALL_ARRAYS (and library_npz), their canonical dtypes, shapes of S + 1, S or E
    values, blobs inside the file, and what decoding allocates within the file's budget."""
    fmt = header.get("format")
    if fmt != FORMAT:
        raise GraphFormatError(name, f"not an igraph-fight graph file (format {_quote(fmt)})")
    v = header.get("version")
    if isinstance(v, bool) or v not in COMPACT_VERSIONS:
        raise GraphFormatError(name, f"version: graph version {_quote(v)} is not supported in a compact file "
                                     f"(versions {' and '.join(map(str, COMPACT_VERSIONS))}); a newer package "
                                     f"wrote it, or convert it there with `igraph-fight graph convert --version 3`")
    members = header.get("members")
    if not isinstance(members, dict):
        raise GraphFormatError(name, "members: not an object")
    missing = [k for k in ALL_ARRAYS if k not in members]
    if missing:
        raise GraphFormatError(name, f"arrays: missing {', '.join(missing)}")
    extra = sorted(set(members) - set(ALL_ARRAYS) - {"library_npz"})
    if extra:
        raise GraphFormatError(name, f"arrays: unexpected {_quote(extra[0])}")
    need = 0
    for k, m in members.items():
        try:
            need += gc.check_spec(k, m, np.dtype(ALL_ARRAYS.get(k, np.uint8)), size, data_start,
                                  {f: t for f, (t, _) in FORMULAS.items()})
        except gc.FormatProblem as e:
            raise GraphFormatError(name, str(e)) from None
        if m.get("encoding") == "derived" and m.get("formula") != k and "library_npz" not in members:
            raise GraphFormatError(name, f"{k}: replayed, and the file holds no library to replay it with")
        if m["encoding"] == "offsets" and k != "state_offsets":
            raise GraphFormatError(name, f"{k}: only state_offsets may be stored as offsets")
    budget = gc.MAX_INFLATION * size + gc.INFLATION_SLACK
    if need > budget:
        raise GraphFormatError(name, f"members declare {need} bytes once decoded, more than the {budget} allowed "
                                     f"for a file of {size}")
    S, E = members["state_r"]["shape"][0], members["edge_target"]["shape"][0]
    for k in ALL_ARRAYS:
        n = S + 1 if k == "state_offsets" else S if k in STATE_ARRAYS else E
        if members[k]["shape"][0] != n:
            raise GraphFormatError(name, f"{k}: {members[k]['shape'][0]} values (expected {n})")


def _read_compact(path: str) -> tuple[dict, GraphArrays]:
    """The header and arrays of a compact (version 3) file: index vetted, checksum and CRC-32s
    checked, the memory-mapped arrays mapped and what validation reads of the others read."""
    from motion_graph.library import parse_json_header

    size = os.path.getsize(path)
    try:
        with open(path, "rb") as fh:
            raw, data_start = gc.read_index(fh, size, HEADER_MAX_BYTES)
    except gc.FormatProblem as e:
        raise GraphFormatError(path, str(e)) from None
    except OSError as e:
        raise GraphFormatError(path, f"cannot be read ({e.strerror or type(e).__name__})") from None
    header = parse_json_header(raw, path, GraphFormatError)
    _check_compact_index(header, size, data_start, path)
    try:
        ok = graph_checksum(header, {}, 3) == header.get("checksum")
    except ValueError:
        ok = False
    if not ok:
        raise GraphFormatError(path, "checksum: mismatch, the file is corrupted")
    mm = gc.open_map(path, size)
    loaded, members = {}, {}
    try:
        for k, x in gc.load_members(mm, header["members"]).items():
            (members if isinstance(x, Member) else loaded)[k] = x
    except gc.FormatProblem as e:
        raise GraphFormatError(path, str(e)) from None
    arrays = GraphArrays(loaded, members, {f: fn for f, (_, fn) in FORMULAS.items()}, order=list(header["members"]),
                         error=lambda problem: GraphFormatError(path, problem))
    arrays.context["header"] = header
    return header, arrays


def read_graph_file(path: str | os.PathLike) -> tuple[dict, dict[str, np.ndarray]]:
    """The header and arrays of a graph file of any readable version, read boundedly and
    checksum-verified (no value checks: InteractionGraph.load adds them). Version 3's arrays are
    a graph_compact.GraphArrays (decoded on first access)."""
    from motion_graph.library import read_npz

    name = str(path)
    if _is_compact(name):
        return _read_compact(name)
    header, data = read_npz(name, name, "igraph-fight graph file", max_header_bytes=HEADER_MAX_BYTES,
                            max_inflation=1.0, check=lambda h, m: _check_members(h, m, name), error=GraphFormatError)
    try:
        ok = graph_checksum(header, data, header["version"]) == header.get("checksum")
    except ValueError:  # a header that cannot be hashed canonically
        ok = False
    if not ok:
        raise GraphFormatError(name, "checksum: mismatch, the file is corrupted")
    return header, data


def _is_compact(path: str) -> bool:
    try:
        with open(path, "rb") as fh:
            return gc.is_compact(fh.read(len(gc.MAGIC)))
    except OSError as e:
        raise GraphFormatError(path, f"cannot be read ({e.strerror or type(e).__name__})") from None


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


def _finite_or_none(v):
    """A JSON value with every non-finite float replaced by None."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _finite_or_none(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite_or_none(x) for x in v]
    return v


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
        if not opts:
            return SimParams()
        check_options({"sim": opts}, self._name())
        return SimParams(**opts)

    def _name(self) -> str:
        return str(self.header.get("path", "<graph>"))

    def load_library(self) -> "ActionLibrary":
        """The action library the graph was built from (embedded in the graph file; validated
        and parsed once, then the same object)."""
        lib = self.__dict__.get("_library")
        if lib is None:
            if "library_npz" not in self.arrays:
                raise GraphFormatError(self._name(), "no embedded action library; pass the library file (--library)")
            from motion_graph.library import library_from_bytes
            try:
                lib = library_from_bytes(self.arrays["library_npz"].tobytes(), f"{self._name()}#library")
            except GraphFormatError:
                raise
            except LibraryFormatError as e:
                raise GraphFormatError(self._name(), f"library_npz: {e.problem}") from None
            self.__dict__["_library"] = lib
        self.check_library(lib)
        return lib

    def check_library(self, lib: "ActionLibrary") -> None:
        """Raise GraphFormatError when ``lib`` is not the library this graph was built from, or
        when the graph's arrays do not fit it (``validate(lib)``, run once per library)."""
        fp = library_fingerprint(lib)
        if fp != self.library_fingerprint:
            raise GraphFormatError(self._name(),
                                   f"built from another action library (fingerprint {self.library_fingerprint[:12]}, "
                                   f"given {fp[:12]})")
        if self.__dict__.get("_validated_for") != fp:
            self.validate(lib)

    def validate(self, library: "ActionLibrary | None" = None) -> None:
        """Raise GraphFormatError (naming the field) unless the header's fields and options are of
        the right type and range and every array is in range: CSR offsets, targets, actions, kinds,
        finite non-negative distances, angles in [-pi, pi]; with ``library`` (an ActionLibrary),
        also its number of actions, each state's F_other within its M_other's frames, masks within
        its strikes, Next-set ids, each edge's action in its state's menu and the kinds. What the
        numba kernels rely on; ``load`` runs it with the embedded library."""
        name = self._name()
        _check_header(self.header, self.arrays, name)
        _check_arrays(self.arrays, self.header, name)
        if library is not None:
            _check_with_library(self.arrays, self.header, library, name)
            self.__dict__["_validated_for"] = library_fingerprint(library)

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
        version = self.header.get("version", VERSION)
        path = self.header.get("path")
        return {
            "path": path,
            "format": self.header.get("format", FORMAT), "version": version,
            "storage": ("compact (version 4: edge features replayed from the states; memory-mapped floats, "
                        "narrowed and deflated integers and tables)" if version >= 4 else
                        "compact (version 3: memory-mapped floats, narrowed and deflated integers and tables)"
                        if version >= 3 else f"npz (version {version}, the old format: `igraph-fight graph convert` "
                                             f"rewrites it as version 4)"),
            "file_bytes": os.path.getsize(path) if path and os.path.exists(path) else None,
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
    def save(self, path: str | os.PathLike, version: int = VERSION) -> None:
        """Write the graph file atomically, after ``validate()`` (a graph that saves loads):
        version 4 (the default: compact, edge features replayed), 3 (compact, every array stored)
        or 2 (the .npz that older packages read)."""
        if version not in WRITABLE_VERSIONS:
            raise ValueError(f"graph files are written as version {' or '.join(map(str, WRITABLE_VERSIONS))}, "
                             f"not {version!r}")
        self.validate()
        arrays = {k: np.ascontiguousarray(self.arrays[k], dtype=ALL_ARRAYS[k]) for k in ALL_ARRAYS}
        if "library_npz" in self.arrays:
            arrays["library_npz"] = np.ascontiguousarray(self.arrays["library_npz"], dtype=np.uint8)
        header = {k: v for k, v in self.header.items() if k not in ("path", "checksum", "members")}
        header.update(format=FORMAT, version=version, content_hash=_hash_arrays(arrays, ALL_ARRAYS),
                      shapes={k: list(v.shape) for k, v in arrays.items()})
        header.setdefault("created", _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"))
        header.setdefault("package_version", package_version())
        if "report" in header:
            header["report"] = _finite_or_none(header["report"])
        header = json.loads(json.dumps(header, allow_nan=False))  # as load will parse it
        if version >= 3:
            lib = self.load_library() if "library_npz" in arrays else None
            written = write_compact(path, header, arrays, version=version, library=lib)
            self.header = {**written, "path": str(path)}
            return
        header["checksum"] = graph_checksum(header, arrays, version)
        raw = json.dumps(header).encode()
        if len(raw) > HEADER_MAX_BYTES:
            raise ValueError(f"graph header of {len(raw)} bytes (at most {HEADER_MAX_BYTES})")

        def write(fh) -> None:
            np.savez(fh, header=np.frombuffer(raw, dtype=np.uint8), **arrays)
            fh.flush()
            kill_point("write")

        atomic_write(path, write)
        self.header = {**header, "path": str(path)}

    @classmethod
    def load(cls, path: str | os.PathLike) -> "InteractionGraph":
        """Read and validate a graph file (GraphFormatError naming the file and the field on any
        problem; see the module docstring)."""
        path = str(path)
        if not os.path.exists(path):
            raise GraphFormatError(path, "no such file")
        header, data = read_graph_file(path)
        header["path"] = path
        g = cls(data, header)
        _check_header(header, data, path)  # before the library is parsed with the header's fingerprint
        if "library_npz" in data:
            lib = g.load_library()  # validates the library, then the graph against it
            if isinstance(data, GraphArrays):
                data.context["library"] = lib  # what a replay of the edges uses
        else:
            g.validate()
        return g


def compact_members(w: "gc.Writer", arrays: dict[str, np.ndarray], replay=None) -> dict[str, dict]:
    """The member specs of a version 3 file for ``arrays`` (their blobs added to ``w``), or of a
    version 4 file with ``replay`` (replayed_shards of ``arrays``: the replayed arrays' values,
    shard by shard): see the module docstring for which array is stored how. Every array is read
    piece by piece (graph_compact.CHUNK values, or one replay shard, at a time)."""
    members = {}
    if replay is not None:
        enc = {k: gc.DerivedEncoder(arrays[k], replay_formula(k), crc=True) for k in REPLAYED}
        for e0, e1, r in replay:
            for k, e in enc.items():
                e.update(e0, e1, r[k])
        for k, e in enc.items():
            spec = e.finish(w)
            if spec is not None:
                members[k] = spec
    for k in [*ALL_ARRAYS, *(("library_npz",) if "library_npz" in arrays else ())]:
        if k in members:
            continue
        a = arrays[k]
        spec = None
        if k == "state_offsets":
            spec = gc.encode_offsets(w, np.asarray(a))
        elif k in DERIVED:
            spec = _encode_formula(w, arrays, k)
        if spec is None:
            if k in COMPACT_MAPPED or k in COMPACT_COPIED:
                spec = gc.encode_raw(w, a, copy=k in COMPACT_COPIED)
            elif a.dtype.kind in "iu":
                spec = gc.encode_ints(w, a)
            else:
                spec = gc.encode_floats(w, a, deflate=True)
        members[k] = spec
    return {k: members[k] for k in [*ALL_ARRAYS, *(("library_npz",) if "library_npz" in arrays else ())]}


def _encode_formula(w: "gc.Writer", arrays: dict[str, np.ndarray], k: str) -> dict | None:
    """Edge array ``k`` as its DERIVED formula, evaluated piece by piece over the edges (None where
    the arrays do not fit together, as in crafted files, or too many values differ)."""
    a = arrays[k]
    e = gc.DerivedEncoder(a, k)
    part = {n: arrays[n] for n in ALL_ARRAYS if n not in EDGE_ARRAYS}  # the state arrays, whole
    for lo, hi in gc.chunks(len(a), w.chunk):
        part.update({n: arrays[n][lo:hi] for n in EDGE_ARRAYS})
        try:
            with np.errstate(all="ignore"):
                derived = DERIVED[k](part)
        except (IndexError, ValueError, TypeError):
            return None
        if np.shape(derived) != (hi - lo,):
            return None
        e.update(lo, hi, derived)
    return e.finish(w)


def write_compact(path: str | os.PathLike, header: dict, arrays: dict[str, np.ndarray], version: int = VERSION,
                  library=None, chunk: int = gc.CHUNK, shard_edges: int = gc.SHARD_EDGES) -> dict:
    """Write ``arrays`` and ``header`` (as ``save`` prepares it) as a compact file of ``version``
    (3 or 4), atomically, without validating them; returns the index written (the header with
    ``members`` and ``checksum``). Version 4 replays the edges with ``library`` (default: the
    embedded one) where it can (replayed_shards). The arrays may be memory-mapped files: they are
    read piece by piece, the blobs spooled to a temporary file beside ``path`` and copied behind
    the index, so that memory does not grow with the edges (docs/scaling.md): ``chunk`` values
    per piece, ``shard_edges`` edges per replay shard (the file does not depend on either).
    ``save`` is the way to write a graph; this is what it calls."""
    if version not in COMPACT_VERSIONS:
        raise ValueError(f"compact graph files are versions {COMPACT_VERSIONS}, not {version!r}")
    replay = None
    if version >= 4 and ("library_npz" in arrays or library is not None):
        replay = replayed_shards(arrays, header, library, shard_edges=shard_edges)
        replay = None if isinstance(replay, str) else replay
    try:
        return _write_compact(path, header, arrays, version, replay, chunk)
    except ReplayRefused:  # a shard the replay refused: the arrays stored as they are
        return _write_compact(path, header, arrays, version, None, chunk)


def _write_compact(path, header: dict, arrays: dict[str, np.ndarray], version: int, replay, chunk: int) -> dict:
    out: dict = {}
    with gc.Writer(spool_dir=os.path.dirname(os.path.abspath(path)), chunk=chunk) as w:
        header = {**{k: v for k, v in header.items() if k not in ("checksum", "members", "path")}, "version": version,
                  "members": compact_members(w, arrays, replay)}

        def write(fh) -> None:
            out.update(w.finish(fh, header, lambda h: graph_checksum(h, {}, version)))
            fh.flush()
            kill_point("write")

        text_size = len(json.dumps(header).encode())
        if text_size > HEADER_MAX_BYTES:
            raise ValueError(f"graph header of {text_size} bytes (at most {HEADER_MAX_BYTES})")
        atomic_write(path, write)
    return out


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
    """The header of a graph file without reading the arrays (for quick listing; GraphFormatError
    when it is no graph file). Version 3: the index, ``members`` included."""
    from motion_graph.library import parse_json_header, read_npz

    name = str(Path(path))
    if _is_compact(name):
        size = os.path.getsize(name)
        try:
            with open(name, "rb") as fh:
                raw, data_start = gc.read_index(fh, size, HEADER_MAX_BYTES)
        except gc.FormatProblem as e:
            raise GraphFormatError(name, str(e)) from None
        header = parse_json_header(raw, name, GraphFormatError)
        _check_compact_index(header, size, data_start, name)
        return header
    header, _ = read_npz(name, name, "igraph-fight graph file", max_header_bytes=HEADER_MAX_BYTES, max_inflation=1.0,
                         check=lambda h, m: _check_members(h, m, name), error=GraphFormatError, only=())
    return header


def convert_graph_file(src: str | os.PathLike, dst: str | os.PathLike, version: int = VERSION) -> InteractionGraph:
    """Load a graph file of any readable version (validated) and write it as ``version``
    (atomically); the content hash stays. Returns the graph as saved."""
    g = InteractionGraph.load(src)
    g.save(dst, version=version)
    return g
