"""Clustering of archived samples into Interaction Graph states (paper section 6.1).

The paper's distance between two samples is infinite unless Next(M_self), M_other (and here also
the other's open resolved-strike bits) are equal and the other's frames differ by less than F0;
otherwise sqrt((dr / s_r)^2 + (dtheta_self / s_theta)^2 + (dtheta_other / s_theta)^2) with
s_r = 0.5 m, s_theta = pi / 6 and wrapped angles. Compatible groups are the F0-wide buckets of
F_other inside equal (Next(M_self), M_other, mask), so no cluster ever spans two groups.

Inside each group, k-means runs as bisecting 2-means in the normalised space (angles embedded as
(cos, sin) / s_theta, so wrap_angle_nb-around is seamless): a cluster is split until every member lies
within the snapping tolerance of its centroid (|dr| <= tol_r and both |dtheta| <= tol_theta).
So the number of clusters is chosen by the tolerance, which bounds the foot sliding that snapping
a sample to its state causes: the decider pivots in place by dtheta_self, the other slides along
the joining line by dr and pivots by dtheta_other (and its clip time shifts by < F0 frames).

A numba kernel is used rather than scikit-learn: groups are many and small (tens of thousands of
groups of a few samples), where a per-group KMeans call costs about a millisecond of overhead
(measured in benchmarks/bench_build.py --compare-sklearn).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from motion_graph.rotations import wrap_angle
from numba import njit

from igraph_fight.sim import N_SF, N_SI, SF_R, SF_TH_OTHER, SF_TH_SELF, SI_FOTHER, SI_MSELF
from motion_graph.rotations import wrap_angle_nb


@dataclass(frozen=True)
class ClusterOptions:
    """Snapping tolerance (m, rad) and the paper's normalising constants."""

    tol_r_m: float = 0.05
    tol_theta_rad: float = math.radians(10.0)
    s_r_m: float = 0.5
    s_theta_rad: float = math.pi / 6
    max_iter: int = 20

    def to_json(self) -> dict:
        return asdict(self)


@dataclass
class Clusters:
    """States from samples. labels (N,) state of each sample; state ints si (S, N_SI) (M_self: the
    most frequent member action, ties smaller id; F_other: rounded mean) and floats sf (S, N_SF)
    (mean r, circular mean angles); size (S,) members; snapping per sample: snap_r (m),
    snap_theta (rad, the larger of the two angle changes), snap_frames."""

    labels: np.ndarray
    si: np.ndarray
    sf: np.ndarray
    size: np.ndarray
    snap_r: np.ndarray
    snap_theta: np.ndarray
    snap_frames: np.ndarray

    def report(self) -> dict:
        """Snapping statistics in cm and degrees."""
        if len(self.snap_r) == 0:
            return {"snap_mean_cm": 0.0, "snap_max_cm": 0.0, "snap_mean_deg": 0.0, "snap_max_deg": 0.0,
                    "snap_mean_frames": 0.0, "snap_max_frames": 0}
        return {"snap_mean_cm": float(100 * self.snap_r.mean()), "snap_max_cm": float(100 * self.snap_r.max()),
                "snap_mean_deg": float(np.degrees(self.snap_theta.mean())),
                "snap_max_deg": float(np.degrees(self.snap_theta.max())),
                "snap_mean_frames": float(self.snap_frames.mean()), "snap_max_frames": int(self.snap_frames.max())}


@njit(cache=True)
def _centroid(X, sf, fo, perm, lo, hi, out):
    """Mean of members perm[lo:hi]: out = (r, theta_self, theta_other, mean F)."""
    n = hi - lo
    r = 0.0
    c1 = 0.0
    s1 = 0.0
    c2 = 0.0
    s2 = 0.0
    f = 0.0
    for q in range(lo, hi):
        i = perm[q]
        r += sf[i, SF_R]
        c1 += X[i, 1]
        s1 += X[i, 2]
        c2 += X[i, 3]
        s2 += X[i, 4]
        f += fo[i]
    out[0] = r / n
    out[1] = np.arctan2(s1, c1)
    out[2] = np.arctan2(s2, c2)
    out[3] = f / n


@njit(cache=True)
def _violates(sf, perm, lo, hi, cen, tol_r, tol_t):
    for q in range(lo, hi):
        i = perm[q]
        if (abs(sf[i, SF_R] - cen[0]) > tol_r or abs(wrap_angle_nb(sf[i, SF_TH_SELF] - cen[1])) > tol_t
                or abs(wrap_angle_nb(sf[i, SF_TH_OTHER] - cen[2])) > tol_t):
            return True
    return False


@njit(cache=True)
def _d2(X, i, m):
    d = 0.0
    for k in range(5):
        t = X[i, k] - m[k]
        d += t * t
    return d


@njit(cache=True)
def _split(X, perm, lo, hi, side, max_iter):
    """2-means on members perm[lo:hi] (normalised 5-d embedding); reorders perm so the first
    part is one cluster; returns the split point."""
    n = hi - lo
    mean = np.zeros(5)
    for q in range(lo, hi):
        for k in range(5):
            mean[k] += X[perm[q], k] / n
    # seeds: farthest from the mean, then farthest from it (ties: first in order)
    a = perm[lo]
    best = -1.0
    for q in range(lo, hi):
        d = _d2(X, perm[q], mean)
        if d > best:
            best = d
            a = perm[q]
    ma = X[a].copy()
    b = perm[lo]
    best = -1.0
    for q in range(lo, hi):
        d = _d2(X, perm[q], ma)
        if d > best:
            best = d
            b = perm[q]
    mb = X[b].copy()
    for q in range(lo, hi):
        side[q - lo] = -1
    for it in range(max_iter):
        changed = False
        na = 0
        for q in range(lo, hi):
            i = perm[q]
            s = 0 if _d2(X, i, ma) <= _d2(X, i, mb) else 1
            if s != side[q - lo]:
                changed = True
                side[q - lo] = s
            if s == 0:
                na += 1
        if na == 0 or na == n:
            break
        if not changed:
            break
        ma[:] = 0.0
        mb[:] = 0.0
        for q in range(lo, hi):
            i = perm[q]
            if side[q - lo] == 0:
                for k in range(5):
                    ma[k] += X[i, k] / na
            else:
                for k in range(5):
                    mb[k] += X[i, k] / (n - na)
    na = 0
    for q in range(lo, hi):
        if side[q - lo] == 0:
            na += 1
    if na == 0 or na == n:  # degenerate: peel off the farthest point
        for q in range(lo, hi):
            side[q - lo] = 0 if perm[q] == a else 1
        na = 1
    # stable partition
    tmp = np.empty(n, dtype=np.int64)
    p = 0
    for q in range(lo, hi):
        if side[q - lo] == 0:
            tmp[p] = perm[q]
            p += 1
    for q in range(lo, hi):
        if side[q - lo] != 0:
            tmp[p] = perm[q]
            p += 1
    for q in range(n):
        perm[lo + q] = tmp[q]
    return lo + na


@njit(cache=True)
def _cluster_groups(X, sf, fo, perm, gstart, tol_r, tol_t, max_iter, local, clpos, cen_all, nclust):
    """Bisecting 2-means inside each group [gstart[g], gstart[g+1]) of perm. For each sorted
    position q: local[q] its cluster's id in the group, clpos[q] the cluster's first position;
    cen_all[clpos] the cluster centroid (r, theta_self, theta_other, mean F); nclust[g]."""
    G = len(gstart) - 1
    for g in range(G):
        lo0 = gstart[g]
        hi0 = gstart[g + 1]
        n = hi0 - lo0
        side = np.empty(n, dtype=np.int8)
        stack_lo = np.empty(n + 1, dtype=np.int64)
        stack_hi = np.empty(n + 1, dtype=np.int64)
        stack_lo[0] = lo0
        stack_hi[0] = hi0
        sp = 1
        cen = np.empty(4)
        k = 0
        while sp > 0:
            sp -= 1
            lo = stack_lo[sp]
            hi = stack_hi[sp]
            _centroid(X, sf, fo, perm, lo, hi, cen)
            if hi - lo > 1 and _violates(sf, perm, lo, hi, cen, tol_r, tol_t):
                mid = _split(X, perm, lo, hi, side[lo - lo0:hi - lo0], max_iter)
                # push the second half first so the first half is finalised first
                stack_lo[sp] = mid
                stack_hi[sp] = hi
                sp += 1
                stack_lo[sp] = lo
                stack_hi[sp] = mid
                sp += 1
            else:
                for q in range(lo, hi):
                    local[q] = k
                    clpos[q] = lo
                for j in range(4):
                    cen_all[lo, j] = cen[j]
                k += 1
        nclust[g] = k


def cluster_groups(X: np.ndarray, sf: np.ndarray, fo: np.ndarray, gstart: np.ndarray, tol_r_m: float,
                   tol_theta_rad: float, max_iter: int) -> tuple:
    """Bisecting 2-means inside the groups [gstart[g], gstart[g+1]) of rows 0..n-1 (sorted by
    group): X (n, 5) the normalised embedding, sf (n, N_SF), fo (n,) F_other. Returns (perm:
    the rows reordered by cluster inside each group, local: each sorted position's cluster id in
    its group, clpos: its cluster's first position, cen (n, 4): centroids at clpos, nclust per
    group). One shard of cluster_samples (a whole run of groups: no cluster spans two groups)."""
    n = len(X)
    G = len(gstart) - 1
    if len(gstart) == 0 or gstart[0] != 0 or gstart[-1] != n or np.any(np.diff(gstart) < 0):
        raise ValueError(f"gstart must run from 0 to {n} without decreasing")
    perm = np.arange(n, dtype=np.int64)
    local = np.empty(n, dtype=np.int64)
    clpos = np.empty(n, dtype=np.int64)
    cen = np.zeros((n, 4))
    nclust = np.zeros(max(G, 0), dtype=np.int64)
    _cluster_groups(np.ascontiguousarray(X, dtype=np.float64), np.ascontiguousarray(sf, dtype=np.float64),
                    np.ascontiguousarray(fo, dtype=np.float64), perm, np.ascontiguousarray(gstart, dtype=np.int64),
                    float(tol_r_m), float(tol_theta_rad), int(max_iter), local, clpos, cen, nclust)
    return perm, local, clpos, cen, nclust


def cluster_samples(group_rows: np.ndarray, si: np.ndarray, sf: np.ndarray, options: ClusterOptions,
                    backend=None) -> Clusters:
    """Cluster samples inside their groups (group_rows (N, 4) from explore.group_rows).

    States are numbered by group (sorted group key), then in the order the bisection finalises
    them; everything is deterministic and independent of the thread count and of the backend
    (igraph_fight.build.backend: shards of whole groups; None: one pass in this process).
    """
    N = len(si)
    if N == 0:
        z = np.zeros(0, dtype=np.int64)
        return Clusters(z, np.zeros((0, N_SI), np.int64), np.zeros((0, N_SF)), z, np.zeros(0), np.zeros(0), z)
    o = options
    sf = np.ascontiguousarray(sf, dtype=np.float64)
    X = np.empty((N, 5))
    X[:, 0] = sf[:, SF_R] / o.s_r_m
    X[:, 1] = np.cos(sf[:, SF_TH_SELF]) / o.s_theta_rad
    X[:, 2] = np.sin(sf[:, SF_TH_SELF]) / o.s_theta_rad
    X[:, 3] = np.cos(sf[:, SF_TH_OTHER]) / o.s_theta_rad
    X[:, 4] = np.sin(sf[:, SF_TH_OTHER]) / o.s_theta_rad
    order = np.lexsort((np.arange(N), group_rows[:, 3], group_rows[:, 2], group_rows[:, 1], group_rows[:, 0]))
    gs = group_rows[order]
    brk = np.nonzero(np.any(gs[1:] != gs[:-1], axis=1))[0] + 1
    gstart = np.concatenate([[0], brk, [N]]).astype(np.int64)
    perm = order.astype(np.int64).copy()
    fo = si[:, SI_FOTHER].astype(np.float64)
    if backend is None:
        p_loc, local, clpos, cen, nclust = cluster_groups(X[perm], sf[perm], fo[perm], gstart, o.tol_r_m,
                                                          o.tol_theta_rad, o.max_iter)
        perm = perm[p_loc]
    else:
        perm, local, clpos, cen, nclust = backend.cluster_shards(X, sf, fo, perm, gstart, o.tol_r_m, o.tol_theta_rad,
                                                                 o.max_iter)
    base = np.concatenate([[0], np.cumsum(nclust)[:-1]]).astype(np.int64)
    gid = np.repeat(np.arange(len(nclust)), np.diff(gstart))
    labels = np.empty(N, dtype=np.int64)
    labels[perm] = base[gid] + local
    S = int(nclust.sum())
    size = np.bincount(labels, minlength=S)
    # centroid of each state: at its cluster's first sorted position
    spos = np.empty(S, dtype=np.int64)
    spos[labels[perm]] = clpos
    c = cen[spos]
    f = np.floor(c[:, 3] + 0.5).astype(np.int64)
    first = np.full(S, N, dtype=np.int64)
    np.minimum.at(first, labels, np.arange(N))
    st_si = si[first].astype(np.int64).copy()
    st_si[:, SI_FOTHER] = f
    # M_self: the most frequent member action (ties: smaller id)
    A = int(si[:, SI_MSELF].max()) + 1
    u, cnt = np.unique(labels * A + si[:, SI_MSELF], return_counts=True)
    lab_u, act_u = u // A, u % A
    o2 = np.lexsort((act_u, -cnt, lab_u))
    lab_sorted = lab_u[o2]
    firsts = np.concatenate([[True], lab_sorted[1:] != lab_sorted[:-1]])
    st_si[lab_sorted[firsts], SI_MSELF] = act_u[o2][firsts]
    st_sf = np.ascontiguousarray(c[:, :3])
    snap_r = np.abs(sf[:, SF_R] - st_sf[labels, 0])
    snap_t = np.maximum(np.abs(wrap_angle(sf[:, SF_TH_SELF] - st_sf[labels, 1])),
                        np.abs(wrap_angle(sf[:, SF_TH_OTHER] - st_sf[labels, 2])))
    snap_f = np.abs(si[:, SI_FOTHER] - f[labels])
    return Clusters(labels, st_si, st_sf, size, snap_r, snap_t, snap_f)

