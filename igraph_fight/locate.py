"""The nearest-state index: maps a live coupled state to the Interaction Graph state nearest to it
(numba kernels on plain arrays), shared by NPCController, the exact search (igraph_fight.search)
and the cooperative controller (igraph_fight.coop).

    parts, pi, pf, pc = ...                       # pack_index(build_index(...), ...): flat arrays
    s, d2, level, off = locate_packed(pi, pf, pc, r, theta_self, theta_other, m_self, m_other, f_other, mask)

A live state (the decider about to choose: the action it just finished, the opponent's action,
frame and open strike bits, distance and angles) is looked up in its compatible group (same
Next(M_self), M_other and mask, |F_other difference| < F0) with the paper's normalised distance
(s_r = 0.5 m, s_theta = pi/6 by default); without a compatible state it falls back to the
nearest state with the same key at any frame, then with the same menu, then anywhere, and flags
the answer as off the graph. ``locate_packed`` returns (state, squared normalised distance,
level 0..3, off_graph); level 0 answers are on the graph when they lie within the linking
tolerance.

Contract of the kernels: every index they take (actions, frames, masks) must already be in range;
callers check their inputs before they enter (NPCController does).
"""
from __future__ import annotations

import numpy as np
from numba import njit

import motion_graph.rotations
from igraph_fight.kernel_cache import drop_stale_caches
from motion_graph.rotations import wrap_angle_nb

drop_stale_caches(__file__, [motion_graph.rotations])

#: The lookup grid: the index holds every state's r (m) and angles (rad) rounded to multiples of
#: 1 / GRID_PER_UNIT (0.12 mm, 0.007 deg) and rounds each query the same way before comparing, so
#: every value compared is an integer times a power of two: exact in float64 and in 16-bit codes
#: (an NPC export stores them so and answers bit for bit what the controller answers). The step is
#: far below the graph's linking tolerances (0.1 m and 20 degrees by default); a lookup answers what
#: it would on the raw values except for a query within a grid step of a tie.
GRID_PER_UNIT = 8192.0


def grid_code(x, grid_per_unit: float = GRID_PER_UNIT) -> np.ndarray:
    """``x`` (m or rad) as its lookup-grid code: the nearest multiple of 1 / ``grid_per_unit``
    (half to even) times ``grid_per_unit``, an integer-valued float64."""
    return np.rint(np.asarray(x, dtype=np.float64) * grid_per_unit)


def on_grid(x) -> np.ndarray:
    """``x`` (m or rad) rounded to the lookup grid (half to even), float64."""
    return grid_code(x) / GRID_PER_UNIT


@njit(cache=True, inline="always")
def on_grid_nb(x):
    """Scalar ``on_grid`` for the kernels."""
    return np.rint(x * GRID_PER_UNIT) / GRID_PER_UNIT

# ----- nearest-state index -------------------------------------------------------------------
# The index (built by build_index), with key = (Next-set id * (A+1) + M_other) * mask_mod + mask
# and kidx the rank of the key among the sorted ``ukeys``:
#   level 0 (the compatible group): a state with frame F_other is copied into the slots
#     (kidx, F) of every frame F with |F - F_other| < f0 (slot kidx * fw + F + f0 - 1), so a query
#     reads one slot (states of frames that are not compatible are skipped by the scan); a slot
#     is split into _NB2 angle bins (theta_self x theta_other); ``rowsw`` (rows, 4) float64 =
#     (r, theta_self, theta_other, F_other * 2^32 + state id) sorted by (slot, bin, r) (two rows
#     per cache line); ``ctabw[slot * _NB2 + bin, c]`` is the bin's first row with r >= c * cell_w
#     (c = 0..ncell-1) and ``ctabw[., ncell]`` its end: one table read and a short walk find the
#     query's place instead of a binary search (this machine's memory is slow: a cache miss
#     costs ~0.4 us, a binary search ~10 of them). The query's own bin is read first, then only
#     the bins whose angle distance alone can still beat the best so far;
#   level 1 (same key, any frame): ``rowsk`` / ``ctabk`` likewise with one slot per key;
#   level 2 (same Next-set): SoA rows sorted by (Next-set id, angle bin, r), bucket starts ``bst2``
#     (per Next-set id of ``nkeys``, _NB2 bins of (theta_self, theta_other));
#   level 3 (anywhere): SoA rows sorted by (angle bin, r), bucket starts ``bst3``; the query's own
#     bin is read first, then only the bins whose angle distance alone can still beat the best.
# ``xf`` (6, S) float64 = (r, theta_self, theta_other) in the level-2 order, then the level-3
# order; ``xi`` (3, S) int64 = their state ids and each state's position in key order;
# ``strt`` (S, 3) = (r, theta_self, theta_other) by state id (the tolerance test).
# Nearest = smallest squared normalised distance dr^2/s_r^2 + (dts^2 + dto^2)/s_theta^2 (angle
# differences wrapped). Rows are visited outwards from the query's r in order of |dr| and the
# walk stops when dr^2/s_r^2 alone exceeds the best so far: the result is the exact minimum.
# Ties go to the smaller state id (levels 0-2) or the earlier in key order (level 3), i.e. what
# a linear scan of the states in key order finds.




@njit(cache=True)
def _scan_rows(rows, lo, hi, p, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi, lbt):
    """Nearest among rows[lo:hi] (sorted by r; p = about the first row with r >= the query's r)
    whose F_other lies in [flo, fhi]; rows = (r, theta_self, theta_other, F_other * 2^32 + id);
    ``lbt`` a lower bound of the rows' angle term (their angle bin's distance)."""
    while p > lo and rows[p - 1, 0] >= r:
        p -= 1
    while p < hi and rows[p, 0] < r:
        p += 1
    dn = p - 1
    up = p
    while dn >= lo or up < hi:
        if up >= hi or (dn >= lo and r - rows[dn, 0] <= rows[up, 0] - r):
            k = dn
            dn -= 1
        else:
            k = up
            up += 1
        dr = rows[k, 0] - r
        d0 = dr * dr * inv_sr2
        if d0 + lbt > bd:
            break  # every row left is at least this far
        tag = np.int64(rows[k, 3])
        f = tag >> 32
        if f < flo or f > fhi:
            continue
        d1 = wrap_angle_nb(rows[k, 1] - ts)
        d2 = wrap_angle_nb(rows[k, 2] - to)
        d = d0 + (d1 * d1 + d2 * d2) * inv_st2
        s = tag & 0xFFFFFFFF
        if d < bd or (d == bd and s < best):
            bd = d
            best = s
    return best, bd


@njit(cache=True)
def _scan_soa(st, sr, sts, sto, rank, use_rank, lo, hi, r, ts, to, inv_sr2, inv_st2, best, bd, bt, lbt):
    """Nearest among SoA rows [lo, hi) sorted by r (levels 2 and 3); ties to the smaller tie value
    (the state id, or ``rank[state]`` with ``use_rank``). ``lbt``: a lower bound of the angle
    term of every row (their angle bin's distance). Returns (state, distance, tie value)."""
    a = lo
    b = hi
    while a < b:
        m = (a + b) >> 1
        if sr[m] < r:
            a = m + 1
        else:
            b = m
    dn = a - 1
    up = a
    while dn >= lo or up < hi:
        if up >= hi or (dn >= lo and r - sr[dn] <= sr[up] - r):
            k = dn
            dn -= 1
        else:
            k = up
            up += 1
        dr = sr[k] - r
        d0 = dr * dr * inv_sr2
        if d0 + lbt > bd:
            break
        d1 = wrap_angle_nb(sts[k] - ts)
        d2 = wrap_angle_nb(sto[k] - to)
        d = d0 + (d1 * d1 + d2 * d2) * inv_st2
        s = st[k]
        t = rank[s] if use_rank else s
        if d < bd or (d == bd and t < bt):
            bd = d
            best = s
            bt = t
    return best, bd, bt


#: Angle bins of the level-2/3 rows: (theta_self, theta_other) in _NBA x _NBA bins of 2 pi / _NBA.
_NBA = 8
_NB2 = _NBA * _NBA


@njit(cache=True, inline="always")
def _angle_bin(a):
    w = 2.0 * np.pi / _NBA
    b = int(np.floor((a + np.pi - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))) / w))
    return min(max(b, 0), _NBA - 1)


@njit(cache=True, inline="always")
def _bin_gap(a, b):
    """Lower bound of |wrapped difference| between angle a and any angle of bin b (rad)."""
    w = 2.0 * np.pi / _NBA
    lo = b * w - np.pi
    d = wrap_angle_nb(a - lo)
    if 0.0 <= d < w:
        return 0.0
    g = min(abs(d), abs(wrap_angle_nb(a - lo - w)))
    return max(g - 1e-9, 0.0)


@njit(cache=True)
def _scan_bins(st, sr, sts, sto, rank, use_rank, bst, base, r, ts, to, inv_sr2, inv_st2, best, bd, bt):
    """Nearest among the rows of the _NB2 angle bins bst[base:base + _NB2 + 1] (each sorted by
    r): the query's own bin first, then every bin whose angle distance alone does not exceed
    the best so far."""
    qs = _angle_bin(ts)
    qo = _angle_bin(to)
    own = qs * _NBA + qo
    best, bd, bt = _scan_soa(st, sr, sts, sto, rank, use_rank, bst[base + own], bst[base + own + 1], r, ts, to,
                             inv_sr2, inv_st2, best, bd, bt, 0.0)
    for bs in range(_NBA):
        gs = _bin_gap(ts, bs)
        gs2 = gs * gs * inv_st2
        if gs2 > bd:
            continue
        for bo in range(_NBA):
            b = bs * _NBA + bo
            if b == own or bst[base + b] == bst[base + b + 1]:
                continue
            go = _bin_gap(to, bo)
            lbt = gs2 + go * go * inv_st2
            if lbt > bd:
                continue
            best, bd, bt = _scan_soa(st, sr, sts, sto, rank, use_rank, bst[base + b], bst[base + b + 1], r, ts, to,
                                     inv_sr2, inv_st2, best, bd, bt, lbt)
    return best, bd, bt


@njit(cache=True, inline="always")
def _lower(a, x, lo, hi):
    """First index in [lo, hi) of sorted ``a`` with a[i] >= x."""
    while lo < hi:
        m = (lo + hi) >> 1
        if a[m] < x:
            lo = m + 1
        else:
            hi = m
    return lo


@njit(cache=True, inline="always")
def _cell_scan(rows, ctab, slot, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi, lbt):
    lo = ctab[slot, 0]
    hi = ctab[slot, ncell]
    if lo == hi:
        return best, bd
    c = int(r / cell_w) if r > 0.0 else 0
    if c >= ncell:
        p = hi
    else:
        p = ctab[slot, c]
        e = ctab[slot, c + 1]
        while p < e and rows[p, 0] < r:
            p += 1
    return _scan_rows(rows, lo, hi, p, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi, lbt)


@njit(cache=True)
def _slot_scan(rows, ctab, slot, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi):
    """Nearest in a slot's _NB2 angle bins (ctab rows slot * _NB2 + bin): the query's own bin
    first, then only the bins whose angle distance alone can still beat the best."""
    qs = _angle_bin(ts)
    qo = _angle_bin(to)
    base = slot * _NB2
    own = qs * _NBA + qo
    best, bd = _cell_scan(rows, ctab, base + own, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi,
                          0.0)
    for bs in range(_NBA):
        gs = _bin_gap(ts, bs)
        gs2 = gs * gs * inv_st2
        if gs2 > bd:
            continue
        for bo in range(_NBA):
            b = bs * _NBA + bo
            if b == own:
                continue
            go = _bin_gap(to, bo)
            lbt = gs2 + go * go * inv_st2
            if lbt > bd or ctab[base + b, 0] == ctab[base + b, ncell]:
                continue
            best, bd = _cell_scan(rows, ctab, base + b, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd, flo, fhi,
                                  lbt)
    return best, bd


@njit(cache=True)
def nearest(rowsw, ctabw, rowsk, ctabk, ukeys, nblock, ncell, cell_w, xf, xi, nkeys, bst2, bst3, key, nextset,
             f_other, f0, r, ts, to, inv_sr2, inv_st2):
    """Nearest state: compatible group first (same key, |F_other difference| < f0), then same
    key any frame, same menu, anywhere (see the index notes above). Returns (state, squared
    normalised distance, level 0..3) on the lookup grid; (-1, inf, 4) for an empty graph."""
    return _nearest_on_grid(rowsw, ctabw, rowsk, ctabk, ukeys, nblock, ncell, cell_w, xf, xi, nkeys, bst2, bst3,
                            key, nextset, f_other, f0, on_grid_nb(r), on_grid_nb(ts), on_grid_nb(to), inv_sr2, inv_st2)


@njit(cache=True)
def _nearest_on_grid(rowsw, ctabw, rowsk, ctabk, ukeys, nblock, ncell, cell_w, xf, xi, nkeys, bst2, bst3, key,
                     nextset, f_other, f0, r, ts, to, inv_sr2, inv_st2):
    """``nearest`` for a query already on the lookup grid."""
    best = -1
    bd = np.inf
    kidx = _lower(ukeys, key, 0, ukeys.shape[0])
    if kidx < ukeys.shape[0] and ukeys[kidx] == key:
        # level 0: the compatible group, one r-sorted slot per (key, F_other)
        q = (f_other + f0 - 1) // f0
        if f_other + f0 - 1 >= 0 and q < nblock:
            best, bd = _slot_scan(rowsw, ctabw, kidx * nblock + q, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best,
                                  bd, f_other - f0 + 1, f_other + f0 - 1)
        if best >= 0:
            return best, bd, 0
        # level 1: every frame of the key
        best, bd = _slot_scan(rowsk, ctabk, kidx, ncell, cell_w, r, ts, to, inv_sr2, inv_st2, best, bd,
                              -(np.int64(1) << 40), np.int64(1) << 40)
        if best >= 0:
            return best, bd, 1
    # level 2: same Next-set
    bt = np.int64(1) << 62
    j = _lower(nkeys, nextset, 0, nkeys.shape[0])
    if j < nkeys.shape[0] and nkeys[j] == nextset:
        best, bd, bt = _scan_bins(xi[0], xf[0], xf[1], xf[2], xi[2], False, bst2, j * _NB2, r, ts, to, inv_sr2,
                                  inv_st2, best, bd, bt)
    if best >= 0:
        return best, bd, 2
    # level 3: anywhere
    best, bd, bt = _scan_bins(xi[1], xf[3], xf[4], xf[5], xi[2], True, bst3, 0, r, ts, to, inv_sr2, inv_st2, best,
                              bd, bt)
    if best >= 0:
        return best, bd, 3
    return -1, np.inf, 4



# The kernels take the controller's static arrays as three flat arrays (numba's dispatch costs
# about 0.1 us per array argument, a sizeable part of a table decision): ``pi`` int64 = a header
# of part offsets, then the parts named in INT_PARTS; ``pf`` float64 = (inv_sr2, inv_st2,
# tol_r, tol_theta, cell_w), then rowsw, rowsk, xf, strt flattened; ``pc`` = ctabw, ctabk
# flattened. index_views rebuilds the index arrays from them (reshapes of slices: no copy).
INT_PARTS = ("ukeys", "nkeys", "bst2", "nextset_of", "key_args", "menu_off", "menu_ids", "offsets",
              "edge_action", "kinds", "scalars", "bst3", "xi", "legal", "dims")
# scalars = (f0, number of frame blocks, ncell); legal = (A, A) flattened; dims = (rows of rowsw,
# rows of rowsk, S, slots of ctabw, slots of ctabk, ncell + 1, A, then the pf offsets of rowsw,
# rowsk, xf, strt)
P_SCALARS, P_BST3, P_XI, P_LEGAL, P_DIMS = 10, 11, 12, 13, 14


def pack_ints(parts: dict) -> np.ndarray:
    arrs = [np.asarray(parts[k], dtype=np.int64).ravel() for k in INT_PARTS]
    head = len(arrs) + 1
    off = head + np.concatenate([[0], np.cumsum([len(x) for x in arrs])])
    return np.ascontiguousarray(np.concatenate([off.astype(np.int64), *arrs]), dtype=np.int64)


def pack_index(ix: tuple, ix_parts: dict, scalars: list, other_ints: dict, legal: np.ndarray,
                pf_head: list) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(pi, pf, pc) of the notes above from build_index's output and the controller's tables."""
    rowsw, ctabw, rowsk, ctabk, xf, xi, strt = ix
    fparts = [np.asarray(pf_head, dtype=np.float64), rowsw.ravel(), rowsk.ravel(), xf.ravel(), strt.ravel()]
    foff = np.cumsum([0] + [len(x) for x in fparts])[1:-1]
    dims = [len(rowsw), len(rowsk), strt.shape[0], ctabw.shape[0], ctabk.shape[0], ctabw.shape[1],
            legal.shape[0], *foff]
    pi = pack_ints(dict(ix_parts, **other_ints, scalars=scalars, xi=xi, legal=legal.astype(np.int64), dims=dims))
    pf = np.ascontiguousarray(np.concatenate(fparts), dtype=np.float64)
    ct = np.int32 if ctabw.dtype == np.int32 and ctabk.dtype == np.int32 else np.int64
    pc = np.ascontiguousarray(np.concatenate([ctabw.ravel(), ctabk.ravel()]), dtype=ct)
    return pi, pf, pc


@njit(cache=True, inline="always")
def part(pi, i):
    return pi[pi[i]:pi[i + 1]]


@njit(cache=True, inline="always")
def index_views(pi, pf, pc):
    """(rowsw, ctabw, rowsk, ctabk, xf, xi, strt) as views of the packed arrays."""
    d = part(pi, P_DIMS)
    nw, nk, S, sw, sk, nc = d[0], d[1], d[2], d[3], d[4], d[5]
    rowsw = pf[d[7]:d[7] + 4 * nw].reshape((nw, 4))
    rowsk = pf[d[8]:d[8] + 4 * nk].reshape((nk, 4))
    xf = pf[d[9]:d[9] + 6 * S].reshape((6, S))
    strt = pf[d[10]:d[10] + 3 * S].reshape((S, 3))
    ctabw = pc[:sw * nc].reshape((sw, nc))
    ctabk = pc[sw * nc:sw * nc + sk * nc].reshape((sk, nc))
    xi = part(pi, P_XI).reshape((3, S))
    return rowsw, ctabw, rowsk, ctabk, xf, xi, strt


@njit(cache=True, inline="always")
def legal_row(pi, m):
    """Legal flags (A,) of the actions after action m."""
    A = part(pi, P_DIMS)[6]
    return part(pi, P_LEGAL)[m * A:(m + 1) * A]


@njit(cache=True)
def locate_packed(pi, pf, pc, r, ts, to, m_self, m_other, f_other, mask):
    """(state, squared normalised distance, level, off_graph) of a live state (on the lookup grid)."""
    r = on_grid_nb(r)
    ts = on_grid_nb(ts)
    to = on_grid_nb(to)
    rowsw, ctabw, rowsk, ctabk, xf, xi, strt = index_views(pi, pf, pc)
    sc = part(pi, P_SCALARS)
    nextset_of = part(pi, 3)
    key_args = part(pi, 4)
    ns = nextset_of[m_self]
    key = (ns * key_args[0] + m_other) * key_args[1] + mask
    s, d2, level = _nearest_on_grid(rowsw, ctabw, rowsk, ctabk, part(pi, 0), sc[1], sc[2], pf[4], xf, xi,
                                     part(pi, 1), part(pi, 2), part(pi, P_BST3), key, ns, f_other, sc[0], r, ts, to,
                                     pf[0], pf[1])
    off = level > 0
    if s >= 0 and level == 0:
        off = (abs(strt[s, 0] - r) > pf[2] or abs(wrap_angle_nb(strt[s, 1] - ts)) > pf[3]
               or abs(wrap_angle_nb(strt[s, 2] - to)) > pf[3])
    return s, d2, level, off


def _r_slots(slot: np.ndarray, r: np.ndarray, ts: np.ndarray, to: np.ndarray, sid: np.ndarray, f: np.ndarray,
             nslot: int, ncell: int, cell_w: float) -> tuple[np.ndarray, np.ndarray]:
    """Rows (r, theta_self, theta_other, F_other * 2^32 + state id) sorted by (slot, r) and their
    cell table."""
    o = np.lexsort((sid, r, slot))
    tag = (f[o].astype(np.int64) << 32) + sid[o]
    rows = np.ascontiguousarray(np.stack([r[o], ts[o], to[o], tag.astype(np.float64)], axis=1))
    cell = np.minimum((r[o] / cell_w).astype(np.int64), ncell - 1)
    counts = np.bincount(slot[o] * ncell + cell, minlength=nslot * ncell).reshape(nslot, ncell)
    ctab = np.empty((nslot, ncell + 1), dtype=np.int64)
    ctab[:, ncell] = np.cumsum(counts.sum(axis=1))
    ctab[:, 0] = ctab[:, ncell] - counts.sum(axis=1)
    ctab[:, 1:ncell] = ctab[:, :1] + np.cumsum(counts, axis=1)[:, :-1]
    return rows, np.ascontiguousarray(ctab, dtype=np.int32 if len(o) < 2 ** 31 - 1 else np.int64)


def _angle_bins(a: np.ndarray) -> np.ndarray:
    """_angle_bin for arrays (the same arithmetic)."""
    w = 2.0 * np.pi / _NBA
    b = np.floor((a + np.pi - 2.0 * np.pi * np.floor((a + np.pi) / (2.0 * np.pi))) / w).astype(np.int64)
    return np.clip(b, 0, _NBA - 1)


def build_index(a: dict, n_actions: int, mask_mod: int, f0: int, ncell: int = 8) -> tuple:
    """The nearest-state index (notes above; values on the lookup grid): returns (rowsw, ctabw,
    rowsk, ctabk, xf, xi, strt),
    the int parts (ukeys, nkeys, bst2, bst3, fm = number of frame blocks, ncell) and the cell
    width (m)."""
    S = len(a["state_r"])
    r = np.ascontiguousarray(on_grid(a["state_r"]))
    ts = np.ascontiguousarray(on_grid(a["state_theta_self"]))
    to = np.ascontiguousarray(on_grid(a["state_theta_other"]))
    f = a["state_f_other"].astype(np.int64)
    ns = a["state_nextset"].astype(np.int64)
    key = ((ns * (n_actions + 1) + a["state_m_other"].astype(np.int64)) * mask_mod
           + a["state_mask_other"].astype(np.int64))
    fm = int(f.max()) + 1 if S else 1
    ukeys, kidx = np.unique(key, return_inverse=True)
    kidx = kidx.astype(np.int64).ravel()
    sid = np.arange(S, dtype=np.int64)
    cell_w = float(r.max()) / ncell + 1e-9 if S else 1.0
    # level 0: frames in blocks of f0 (shifted by f0 - 1); a query at F reads block
    # (F + f0 - 1) // f0, which holds every state compatible with any frame of the block
    # (|F_other difference| < f0); the scan skips the others. Each state is in about 3 blocks.
    fs = f + f0 - 1
    nblock = (fm + 2 * (f0 - 1)) // f0 + 1
    qs, ids = [], []
    for dq in range(-2, 3):
        q = (fs + f0 - 1) // f0 + dq - 1
        ok = (q >= 0) & (q < nblock) & (q * f0 - f0 + 1 <= fs) & (fs <= q * f0 + 2 * f0 - 2)
        qs.append(q[ok])
        ids.append(sid[ok])
    qw = np.concatenate(qs)
    iw = np.concatenate(ids)
    ab = _angle_bins(ts) * _NBA + _angle_bins(to)
    rowsw, ctabw = _r_slots((kidx[iw] * nblock + qw) * _NB2 + ab[iw], r[iw], ts[iw], to[iw], iw, f[iw],
                            len(ukeys) * nblock * _NB2, ncell, cell_w)
    rowsk, ctabk = _r_slots(kidx * _NB2 + ab, r, ts, to, sid, f, len(ukeys) * _NB2, ncell, cell_w)
    nkeys, ninv = np.unique(ns, return_inverse=True)
    g2 = ninv.astype(np.int64).ravel() * _NB2 + ab
    o2 = np.lexsort((r, g2))
    bst2 = np.concatenate([[0], np.cumsum(np.bincount(g2, minlength=len(nkeys) * _NB2))]).astype(np.int64)
    rank = np.empty(S, dtype=np.int64)
    rank[np.argsort(key, kind="stable")] = np.arange(S)
    o3 = np.lexsort((rank, r, ab))
    bst3 = np.concatenate([[0], np.cumsum(np.bincount(ab, minlength=_NB2))]).astype(np.int64)
    xf = np.ascontiguousarray(np.stack([r[o2], ts[o2], to[o2], r[o3], ts[o3], to[o3]]) if S else np.zeros((6, 0)))
    xi = np.ascontiguousarray(np.stack([o2, o3, rank]).astype(np.int64) if S else np.zeros((3, 0), np.int64))
    strt = np.ascontiguousarray(np.stack([r, ts, to], axis=1))
    return ((rowsw, ctabw, rowsk, ctabk, xf, xi, strt),
            dict(ukeys=ukeys.astype(np.int64), nkeys=nkeys.astype(np.int64), bst2=bst2, bst3=bst3, fm=nblock,
                 ncell=ncell), cell_w)


def nextset_ids(library) -> np.ndarray:
    """Next-set id per action, numbered as igraph_fight.sim.SimTables does."""
    seen: dict[tuple, int] = {}
    out = np.empty(library.n_actions, dtype=np.int64)
    for a in range(library.n_actions):
        out[a] = seen.setdefault(tuple(sorted(int(b) for b in library.next(a))), len(seen))
    return out
