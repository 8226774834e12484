"""``igraph-fight export``: NPCController's table decision for an engine, in one small file.

    info = export_npc(graph, ["infighter", "outboxer", "balanced"], [1, 3, 5], "npc.bin")

The file (docs/npc_export.md) holds the nearest-state index (every state's distance and angles
as integer codes of the controller's lookup grid, frame and key, in key order) and, per (style,
depth), the action of each state's best edge; a reader that follows docs/npc_export.md
(examples/npc_export_reader.py: numpy only) answers what
``NPCController(graph, style=S, depth=D, offgraph="nearest", first_ply="table")`` answers: the
same action and the same graph state for every observation. Off the graph's Next-sets (a live
Next(M_self) that no state has: the search's last level, anywhere) the best edge may be illegal
for the live menu; for those Next-sets the file holds each state's fallback answer too.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from motion_graph.atomic import atomic_write

from igraph_fight import graph_compact as gc
from igraph_fight.locate import grid_code

FORMAT = "igraph-fight/npc-export"
VERSION = 2
MAGIC = b"IGFNPCX1"
#: the action value meaning "none" in the best-action and fallback tables: answer the first
#: action of the live Next(M_self)
NO_ACTION = -1


def _seal(index: dict) -> str:
    """sha256 over the index's JSON without ``checksum`` (keys sorted, compact, ASCII)."""
    body = {k: v for k, v in index.items() if k != "checksum"}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":"), ensure_ascii=True,
                                     allow_nan=False).encode()).hexdigest()


def grid_codes(x: np.ndarray, order: np.ndarray, grid_per_unit: float) -> np.ndarray:
    """``x[order]`` (m or rad) as integer codes of the lookup grid (igraph_fight.locate.on_grid:
    value = code / grid_per_unit, exactly), in the smallest integer dtype that holds them."""
    c = grid_code(np.asarray(x, dtype=np.float64)[order], grid_per_unit)
    if len(c) and not np.abs(c).max() < 2.0 ** 53:
        raise ValueError("a state's distance or angle is too large for the lookup grid")
    c = c.astype(np.int64)
    return c.astype(gc.narrow_dtype(c))


def fallback_actions(best_edge: np.ndarray, scores: np.ndarray, offsets: np.ndarray, edge_action: np.ndarray,
                     legal: np.ndarray) -> np.ndarray:
    """Per state, what the table decision answers for a live menu ``legal`` (A,) bool: the best
    edge's action if legal, else the action of the first highest-scoring edge with a legal action,
    else NO_ACTION (igraph_fight.controller's table choice)."""
    S = len(offsets) - 1
    out = np.full(S, NO_ACTION, dtype=np.int64)
    ok = best_edge >= 0
    ok[ok] = legal[edge_action[best_edge[ok]]]
    out[ok] = edge_action[best_edge[ok]]
    el = legal[edge_action]
    q = np.where(el, scores.astype(np.float64), -np.inf)
    src = np.repeat(np.arange(S), np.diff(offsets))
    has = np.diff(offsets) > 0
    seg = np.full(S, -np.inf)
    if has.any():  # segments of the states with edges (the empty ones between them add nothing)
        seg[has] = np.maximum.reduceat(q, offsets[:-1][has])
    top = el & (q > -np.inf) & (q == seg[src])
    first_src, first_e = np.unique(src[top], return_index=True)
    need = ~ok
    pick = need[first_src]
    out[first_src[pick]] = edge_action[np.flatnonzero(top)[first_e[pick]]]
    return out


def export_npc(graph, styles: list[str], depths: list[int], out: str | os.PathLike, library=None) -> dict:
    """Write the export of ``graph`` (an InteractionGraph or a graph file) for every (style,
    depth) to ``out`` (atomically); returns a summary (sizes, tables, sections)."""
    from igraph_fight.controller import NPCController

    if not styles or not depths:
        raise ValueError("export needs at least one style and one depth")
    ctrl = NPCController(graph, library, style=styles[0], depth=depths[0], offgraph="nearest")
    try:
        g, lib = ctrl.graph, ctrl.library
        a = g.arrays
        A, S = int(lib.n_actions), g.n_states
        lp = ctrl.locate_params
        nextset_of = np.asarray(ctrl.nextset_of, dtype=np.int64)
        ns = nextset_of[a["state_m_self"]] if S else np.zeros(0, np.int64)
        key = ((ns * lp["key_a1"] + a["state_m_other"].astype(np.int64)) * lp["mask_mod"]
               + a["state_mask_other"].astype(np.int64))
        order = np.argsort(key, kind="stable")
        ukeys, ustart = np.unique(key[order], return_index=True)
        ustart = np.append(ustart, S).astype(np.int64)
        present = set(np.unique(ns).tolist())
        absent = sorted(set(nextset_of.tolist()) - present)
        offsets = np.asarray(a["state_offsets"], dtype=np.int64)
        edge_action = np.asarray(a["edge_action"], dtype=np.int64)
        menu_off = np.asarray(lib.next_offsets, dtype=np.int64)
        menu_ids = np.asarray(lib.next_ids, dtype=np.int64)
        w = gc.Writer(spool_dir=os.path.dirname(os.path.abspath(out)))
        sections = {
            "nextset_of": w.blob(nextset_of.astype(gc.narrow_dtype(nextset_of)), True),
            "menu_offsets": w.blob(menu_off.astype(gc.narrow_dtype(menu_off)), True),
            "menu_ids": w.blob(menu_ids.astype(gc.narrow_dtype(menu_ids)), True),
            "key_values": w.blob(ukeys.astype(np.int64), True),
            "key_starts": w.blob(ustart.astype(gc.narrow_dtype(ustart)), True),
            "r": w.blob(grid_codes(a["state_r"], order, lp["grid_per_unit"]), True),
            "theta_self": w.blob(grid_codes(a["state_theta_self"], order, lp["grid_per_unit"]), True),
            "theta_other": w.blob(grid_codes(a["state_theta_other"], order, lp["grid_per_unit"]), True),
            "f_other": w.blob(np.asarray(a["state_f_other"])[order].astype(gc.narrow_dtype(a["state_f_other"])), True),
            "state": w.blob(order.astype(gc.narrow_dtype(order)), True),
        }
        act_dt = np.int8 if A <= 127 else np.int16 if A <= 32767 else np.int32
        tables = []
        for st in styles:
            ctrl.set_style(st, wait=True)
            for d in depths:
                ctrl.set_depth(int(d), wait=True)
                best_edge = np.asarray(ctrl.policy.best_me, dtype=np.int64)
                best = np.where(best_edge >= 0, edge_action[np.maximum(best_edge, 0)], NO_ACTION)
                name = f"best/{st}/{int(d)}"
                sections[name] = w.blob(best.astype(act_dt), True)
                entry = {"style": str(st), "depth": int(d), "gamma": float(ctrl.policy.gamma), "best": name,
                         "fallback": {}}
                for n in absent:
                    m = int(np.flatnonzero(nextset_of == n)[0])
                    legal = np.zeros(A, dtype=bool)
                    legal[menu_ids[menu_off[m]:menu_off[m + 1]]] = True
                    fb = fallback_actions(best_edge, ctrl.edge_scores, offsets, edge_action, legal)
                    fname = f"fallback/{st}/{int(d)}/{n}"
                    sections[fname] = w.blob(fb.astype(act_dt), True)
                    entry["fallback"][str(n)] = fname
                tables.append(entry)
        index = {
            "format": FORMAT, "version": VERSION,
            "graph_content_hash": g.header.get("content_hash") or g.content_hash,
            "library_fingerprint": g.library_fingerprint,
            "n_actions": A, "n_states": S, "n_keys": int(len(ukeys)),
            "grid_per_unit": float(lp["grid_per_unit"]),
            "f0": int(lp["f0"]), "inv_sr2": float(lp["inv_sr2"]), "inv_st2": float(lp["inv_st2"]),
            "tol_r": float(lp["tol_r"]), "tol_theta": float(lp["tol_theta"]),
            "key_a1": int(lp["key_a1"]), "mask_mod": int(lp["mask_mod"]),
            "nextsets_present": sorted(int(x) for x in present), "nextsets_absent": [int(x) for x in absent],
            "no_action": NO_ACTION, "tables": tables, "members": {k: {"data": b} for k, b in sections.items()},
        }
        written: dict = {}

        def write(fh) -> None:
            written.update(w.finish(fh, index, _seal, MAGIC))

        atomic_write(out, write, mode="wb")
        w.close()
    finally:
        ctrl.close()
    size = Path(out).stat().st_size
    parts = {k: v["data"]["nbytes"] for k, v in written["members"].items()}
    return {"out": str(out), "bytes": size, "n_states": S, "n_actions": A, "tables": len(tables),
            "styles": list(styles), "depths": [int(d) for d in depths], "nextsets_absent": absent,
            "index_bytes": size - sum(parts.values()),
            "section_bytes": {"index (r, angles, frames, keys, states)": sum(
                v for k, v in parts.items() if not k.startswith(("best/", "fallback/"))),
                "best-action tables": sum(v for k, v in parts.items() if k.startswith("best/")),
                "fallback tables": sum(v for k, v in parts.items() if k.startswith("fallback/"))}}
