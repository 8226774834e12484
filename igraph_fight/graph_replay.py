"""Kinematic replay of a graph's edges: the continuous edge features recomputed from the states.

An edge is the event in which its state's decider starts ``edge_action`` from the state's
centroid and both avatars play on to the next decision instant (igraph_fight.sim.expand_one).
Where both bodies go depends only on the library's root paths, the state's distance, angles,
M_other and F_other, and the push that keeps them ``min_distance_m`` apart; hits never change a
motion. ``replay_edges`` repeats exactly those floating-point operations, in the simulator's
order, without the hit tests, and returns:

- ``feat_r``, ``feat_r_mean``, ``feat_theta_self``, ``feat_theta_other``: the edge features as
  the builder stores them (slot 0's perspective, igraph_fight.build.edge_features);
- ``landing_r``, ``landing_theta_self``, ``landing_theta_other``: the landing sample seen by
  whoever decides next (what ``edge_snap_r`` / ``edge_snap_theta`` measure against the target);
- ``swap``: 1 where the other avatar decides next (must equal ``edge_swap``).

The graph file stores these features as this replay (graph file version 4); the writer checks
every value bit for bit and stores those that differ, shard by shard (``iter_replay``: a run of
whole states at a time, so that writing never holds the whole edge set's replay). The inputs must be in range for the
library (``check_inputs``; ``InteractionGraph.load`` validates them too).
"""
from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from numba import njit

from igraph_fight import sim
from igraph_fight.graph_compact import SHARD_EDGES
from igraph_fight.sim import relative_pose, sample_world

#: what replay_edges returns, in column order of its kernel's output
REPLAY_COLUMNS = ("feat_r", "feat_r_mean", "feat_theta_self", "feat_theta_other", "landing_r",
                  "landing_theta_self", "landing_theta_other")


@njit(cache=True, inline="always")
def _move(T, S, act, frm, c, s):
    """sim.advance_to_decision's motion, the same operations in the same order: both avatars to
    the next decision (pushed apart below the minimum distance), ``c``, ``s`` their headings'
    cosines and sines (headings do not change within an event); returns (frames advanced, sum of
    the pelvis distances)."""
    n_frames = T[0]
    offs = T[1]
    path = T[2]
    dmin = T[13]
    max_frames = T[14]
    last0 = n_frames[act[0]] - 1
    last1 = n_frames[act[1]] - 1
    g0 = offs[act[0]]
    g1 = offs[act[1]]
    f0 = frm[0]
    f1 = frm[1]
    c0, s0, c1, s1 = c[0], s[0], c[1], s[1]
    x0, z0, x1, z1 = S[0, 0], S[0, 1], S[1, 0], S[1, 1]
    steps = 0
    sumr = 0.0
    while f0 < last0 and f1 < last1 and steps < max_frames:
        steps += 1
        f0 += 1
        f1 += 1
        lx = path[g0 + f0, 0]
        lz = path[g0 + f0, 1]
        px0 = c0 * lx + s0 * lz + x0
        pz0 = -s0 * lx + c0 * lz + z0
        lx = path[g1 + f1, 0]
        lz = path[g1 + f1, 1]
        px1 = c1 * lx + s1 * lz + x1
        pz1 = -s1 * lx + c1 * lz + z1
        dx = px1 - px0
        dz = pz1 - pz0
        d = np.sqrt(dx * dx + dz * dz)
        if d < dmin:
            if d > 1e-9:
                ux = dx / d
                uz = dz / d
            else:
                ux = np.sin(S[0, 2] + path[g0 + f0, 2])
                uz = np.cos(S[0, 2] + path[g0 + f0, 2])
            h = 0.5 * (dmin - d)
            x0 -= ux * h
            z0 -= uz * h
            x1 += ux * h
            z1 += uz * h
            d = dmin
        sumr += d
    frm[0] = f0
    frm[1] = f1
    S[0, 0], S[0, 1], S[1, 0], S[1, 1] = x0, z0, x1, z1
    return steps, sumr


@njit(cache=True, inline="always")
def _pose(T, S, act, frm, c, s, i):
    """sim.root_pose with the heading's cosine and sine given."""
    offs = T[1]
    path = T[2]
    g = offs[act[i]] + frm[i]
    lx = path[g, 0]
    lz = path[g, 1]
    return c[i] * lx + s[i] * lz + S[i, 0], -s[i] * lx + c[i] * lz + S[i, 1], S[i, 2] + path[g, 2]


@njit(cache=True, nogil=True)
def _replay_range(T, si, sf, off, action, out, swap, lo, hi):
    """Replay the edges of states [lo, hi): sim.sample_world's start once per state (the other's
    start transform does not depend on the decider's action), then each edge's event."""
    S = np.empty((2, 3))
    S0 = np.empty((2, 3))
    act = np.empty(2, dtype=np.int64)
    frm = np.empty(2, dtype=np.int64)
    mask = np.empty(2, dtype=np.int64)
    c = np.empty(2)
    s = np.empty(2)
    n_frames = T[0]
    for p in range(lo, hi):
        if off[p + 1] == off[p]:
            continue
        sample_world(T, si[p], sf[p], action[off[p]], S0, act, frm, mask)
        for i in range(2):
            c[i] = np.cos(S0[i, 2])
            s[i] = np.sin(S0[i, 2])
        for k in range(off[p], off[p + 1]):
            for i in range(2):
                for j in range(3):
                    S[i, j] = S0[i, j]
            act[0] = action[k]
            act[1] = si[p, sim.SI_MOTHER]
            frm[0] = 0
            frm[1] = si[p, sim.SI_FOTHER]
            steps, sumr = _move(T, S, act, frm, c, s)
            d = 1 if frm[1] >= n_frames[act[1]] - 1 else 0  # sim._next_decider (0 when neither)
            x0, z0, h0 = _pose(T, S, act, frm, c, s, 0)
            x1, z1, h1 = _pose(T, S, act, frm, c, s, 1)
            r, ts, to = relative_pose(x0, z0, h0, x1, z1, h1)
            n = np.float64(steps)
            out[k, 0] = r
            out[k, 1] = sumr / n if n > 0 else r
            out[k, 2] = ts
            out[k, 3] = to
            if d == 0:
                out[k, 4] = r
                out[k, 5] = ts
                out[k, 6] = to
            else:
                rc, tc, oc = relative_pose(x1, z1, h1, x0, z0, h0)
                out[k, 4] = rc
                out[k, 5] = tc
                out[k, 6] = oc
            swap[k] = d


def check_inputs(tables: sim.SimTables, arrays) -> str | None:
    """What makes the replay unsafe for these arrays (an index out of the library's range, CSR
    offsets that do not cover the edges), or None."""
    A = tables.n_actions
    off = np.asarray(arrays["state_offsets"])
    act = np.asarray(arrays["edge_action"])
    mo = np.asarray(arrays["state_m_other"])
    fo = np.asarray(arrays["state_f_other"])
    E, S = len(act), len(mo)
    if len(off) != S + 1 or (S and (off[0] != 0 or off[-1] != E or np.any(np.diff(off) < 0))):
        return "state_offsets: not the CSR offsets of the edges"
    if E and (act.min() < 0 or act.max() >= A):
        return "edge_action: an action outside the library"
    if S and (mo.min() < 0 or mo.max() >= A):
        return "state_m_other: an action outside the library"
    if S and (fo.min() < 0 or np.any(fo >= tables.n_frames[np.clip(mo, 0, A - 1)])):
        return "state_f_other: a frame outside its action"
    return None


def replay_edges(tables: sim.SimTables, arrays, workers: int | None = 1) -> dict[str, np.ndarray]:
    """REPLAY_COLUMNS and ``swap`` of every edge of ``arrays`` (a graph's arrays, states and
    edges as the file holds them) on ``workers`` threads (None or 0: all cores; the result does
    not depend on it). ValueError when check_inputs finds a problem."""
    S = len(arrays["state_r"])
    for _, _, res in iter_replay(tables, arrays, workers, shard_states=max(S, 1)):
        return res
    raise AssertionError("iter_replay yields at least one shard")


def state_runs(offsets: np.ndarray, edges_per_run: int) -> list[tuple[int, int]]:
    """Consecutive runs [s0, s1) of whole states covering CSR ``offsets`` (S + 1 values), each cut
    at the first state boundary past a multiple of ``edges_per_run`` edges; [(0, 0)] for no state."""
    S = len(offsets) - 1
    if S <= 0:
        return [(0, 0)]
    E = int(offsets[-1])
    cuts = np.searchsorted(offsets, np.arange(0, E, max(1, int(edges_per_run))), side="right") - 1
    bounds = sorted(set(np.clip(cuts, 0, S).tolist()) | {0, S})
    return list(zip(bounds[:-1], bounds[1:]))


def iter_replay(tables: sim.SimTables, arrays, workers: int | None = 1, shard_edges: int = SHARD_EDGES,
                shard_states: int | None = None,
                checked: bool = False) -> Iterator[tuple[int, int, dict[str, np.ndarray]]]:
    """replay_edges shard by shard: (e0, e1, the replay of edges [e0, e1)) for consecutive runs
    of whole states holding about ``shard_edges`` edges each (or ``shard_states`` states each),
    in edge order, covering every edge (one empty shard when there is none). Memory: one shard's
    states and edges at a time. ValueError when check_inputs finds a problem (before any shard;
    ``checked``: the caller has run check_inputs on these tables and arrays already)."""
    problem = None if checked else check_inputs(tables, arrays)
    if problem is not None:
        raise ValueError(problem)
    S = len(arrays["state_r"])
    off = np.asarray(arrays["state_offsets"], dtype=np.int64)
    if shard_states is not None:
        bounds = list(range(0, S, max(1, int(shard_states)))) + [S]
        runs = list(zip(bounds[:-1], bounds[1:])) or [(0, 0)]
    else:
        runs = state_runs(off, shard_edges)
    T = tables.kernel_tuple()
    for s0, s1 in runs:
        n = s1 - s0
        si = np.empty((n, sim.N_SI), dtype=np.int64)
        si[:, sim.SI_MSELF] = arrays["state_m_self"][s0:s1]
        si[:, sim.SI_MOTHER] = arrays["state_m_other"][s0:s1]
        si[:, sim.SI_FOTHER] = arrays["state_f_other"][s0:s1]
        si[:, sim.SI_MASK] = arrays["state_mask_other"][s0:s1]
        sf = np.empty((n, sim.N_SF), dtype=np.float64)
        sf[:, sim.SF_R] = arrays["state_r"][s0:s1]
        sf[:, sim.SF_TH_SELF] = arrays["state_theta_self"][s0:s1]
        sf[:, sim.SF_TH_OTHER] = arrays["state_theta_other"][s0:s1]
        e0, e1 = int(off[s0]), int(off[s1])
        loc = off[s0:s1 + 1] - e0
        action = np.ascontiguousarray(arrays["edge_action"][e0:e1], dtype=np.int64)
        out = np.empty((e1 - e0, len(REPLAY_COLUMNS)), dtype=np.float64)
        swap = np.empty(e1 - e0, dtype=np.uint8)
        sim.parallel_for(_replay_range, n, workers, T, si, sf, loc, action, out, swap, min_chunk=256)
        res = {k: np.ascontiguousarray(out[:, i]) for i, k in enumerate(REPLAY_COLUMNS)}
        res["swap"] = swap
        yield e0, e1, res
