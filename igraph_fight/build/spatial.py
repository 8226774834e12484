"""Hash grid over canonical samples for the paper's distance (numba kernels).

A point is (key k = (Next-set id of M_self, M_other, F_other, mask) as 4 int64 columns, r (m),
theta_self, theta_other (rad)). Two points are *within tolerance* when they are compatible (equal
Next-set, M_other and mask, and |F_other difference| < F0: the paper's distance is finite) and
|dr| <= tol_r and both wrapped angle differences are <= tol_theta.

Cells are keyed by (Next-set, M_other, F_other // F0, mask) and a grid at least twice the index
tolerance wide in r and both angles, so a query visits at most 3 frame buckets x 2 x 2 x 2 cells.
The table is an open-addressing hash (linear probing, key and chain head side by side) from a cell
key to a chain of point ids; searches break ties by the smaller id, so answers never depend on the
thread count. The index is a tuple (see ``new_index``) so kernels take it as one argument.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from motion_graph.rotations import wrap_angle_nb

# params layout: cell_r, cell_t, n_t, tol_r, tol_t, s_r, s_t, f0


def new_index(capacity: int, tol_r: float, tol_theta: float, f0: int, s_r: float = 0.5,
              s_theta: float = np.pi / 6) -> tuple:
    """An empty index for up to ``capacity`` points, searchable within (tol_r m, tol_theta rad)
    or less and |dF| < f0 frames; s_r, s_theta are the paper's normalising constants (used to
    rank by distance)."""
    size = 1
    while size < 2 * max(capacity, 1):
        size *= 2
    n_t = max(1, int(np.floor(np.pi / tol_theta)))
    params = np.array([2.0 * tol_r, 2 * np.pi / n_t, n_t, tol_r, tol_theta, s_r, s_theta, max(1, int(f0))],
                      dtype=np.float64)
    table = np.zeros((size, 2), dtype=np.int64)
    table[:, 1] = -1
    cap = max(capacity, 1)
    return (table, np.full(cap, -1, dtype=np.int64), np.zeros((cap, 4), dtype=np.int64),
            np.zeros((cap, 3), dtype=np.float64), np.zeros(1, dtype=np.int64), params)


@njit(cache=True, inline="always")
def _mix(h, v):
    h = h ^ (v + np.int64(0x1E3779B97F4A7C15) + (h << np.int64(6)) + (h >> np.int64(2)))
    h = (h ^ (h >> np.int64(30))) * np.int64(-4658895280553007687)
    h = (h ^ (h >> np.int64(27))) * np.int64(-7723592293110705685)
    return h ^ (h >> np.int64(31))


@njit(cache=True, inline="always")
def _ghash(k0, k1, bucket, k3):
    return _mix(_mix(_mix(_mix(np.int64(0x12345), k0), k1), bucket), k3)


@njit(cache=True, inline="always")
def _key(hg, cr, c1, c2):
    return _mix(_mix(_mix(hg, cr), c1), c2)


@njit(cache=True, inline="always")
def _find(table, key):
    m = table.shape[0] - 1
    i = key & m
    while table[i, 1] >= 0 and table[i, 0] != key:
        i = (i + 1) & m
    return i


@njit(cache=True)
def index_insert(ix, k, r, t1, t2):
    """Append a point (sequential); returns its id, or -1 when the index is full."""
    table, nxt, K, F, count, params = ix
    i = count[0]
    if i >= len(nxt):
        return -1
    for j in range(4):
        K[i, j] = k[j]
    F[i, 0] = r
    F[i, 1] = t1
    F[i, 2] = t2
    n_t = np.int64(params[2])
    f0 = np.int64(params[7])
    cr = np.int64(np.floor(r / params[0]))
    c1 = np.int64(np.floor((t1 + np.pi) / params[1])) % n_t
    c2 = np.int64(np.floor((t2 + np.pi) / params[1])) % n_t
    key = _key(_ghash(k[0], k[1], k[2] // f0, k[3]), cr, c1, c2)
    s = _find(table, key)
    table[s, 0] = key
    nxt[i] = table[s, 1]
    table[s, 1] = i
    count[0] = i + 1
    return i


@njit(cache=True)
def index_insert_many(ix, Kr, F):
    """Insert rows of Kr (N, 4), F (N, 3) in order; returns how many fitted."""
    n = 0
    for i in range(len(Kr)):
        if index_insert(ix, Kr[i], F[i, 0], F[i, 1], F[i, 2]) < 0:
            break
        n += 1
    return n


@njit(cache=True, inline="always")
def _pair(u, n_cells):
    """The two cells (of unit width) that a box of half-width 1/2 around u touches."""
    c = np.int64(np.floor(u))
    other = c + 1 if u - c >= 0.5 else c - 1
    if n_cells > 0:
        c = c % n_cells
        other = other % n_cells
    return c, other


@njit(cache=True)
def index_search(ix, k, r, t1, t2, tol_r, tol_t, nearest, out_ids, out_d):
    """Points within tolerance of the query (k, r, t1, t2) (tolerances not above the index's).

    nearest=False: returns the first point found (-1: none). nearest=True: writes the up to
    len(out_ids) nearest points by the paper's normalised distance (ties: smaller id) to
    out_ids / out_d, nearest first, and returns how many.
    """
    table, nxt, Kp, F, count, params = ix
    K = len(out_ids)
    s_r = params[5]
    s_t = params[6]
    n_t = np.int64(params[2])
    f0 = np.int64(params[7])
    r0, r1 = _pair(r / params[0], 0)
    a0, a1 = _pair((t1 + np.pi) / params[1], n_t)
    b0, b1 = _pair((t2 + np.pi) / params[1], n_t)
    na = 1 if a1 == a0 else 2
    nb = 1 if b1 == b0 else 2
    fq = k[2]
    n = 0
    for bucket in range((fq - f0 + 1) // f0, (fq + f0 - 1) // f0 + 1):
        hg = _ghash(k[0], k[1], bucket, k[3])
        for i in range(2):
            cr = r0 if i == 0 else r1
            for j in range(na):
                c1 = a0 if j == 0 else a1
                for jj in range(nb):
                    c2 = b0 if jj == 0 else b1
                    s = _find(table, _key(hg, cr, c1, c2))
                    p = table[s, 1]
                    while p >= 0:
                        if (Kp[p, 0] == k[0] and Kp[p, 1] == k[1] and Kp[p, 3] == k[3]
                                and abs(Kp[p, 2] - fq) < f0):
                            a = abs(F[p, 0] - r)
                            b = abs(wrap_angle_nb(F[p, 1] - t1))
                            c = abs(wrap_angle_nb(F[p, 2] - t2))
                            if a <= tol_r and b <= tol_t and c <= tol_t:
                                if not nearest:
                                    return p
                                d = (a / s_r) ** 2 + (b / s_t) ** 2 + (c / s_t) ** 2
                                if n < K or d < out_d[n - 1] or (d == out_d[n - 1] and p < out_ids[n - 1]):
                                    q = n if n < K else K - 1
                                    while q > 0 and (out_d[q - 1] > d or (out_d[q - 1] == d and out_ids[q - 1] > p)):
                                        out_d[q] = out_d[q - 1]
                                        out_ids[q] = out_ids[q - 1]
                                        q -= 1
                                    out_d[q] = d
                                    out_ids[q] = p
                                    if n < K:
                                        n += 1
                        p = nxt[p]
    return n if nearest else -1
