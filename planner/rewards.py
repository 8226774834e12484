"""Edge rewards from edge features: the fighting reward (Eq. 4 family) and a cooperative one (Eq. 3).

Features follow docs/contracts.md: (E,) arrays from the *decider's* perspective at each edge.

Fighting (Eq. 4), for the controlled fighter ("me"):

    W_me[e]  = -w_theta*th_self^2 - w_d*(r - d_p)^2 + w_dmg_given*D+*pref[kind] - w_dmg_received*D-
               + w_def*def_self
    W_opp[e] = the same with the features seen from the other side (the opponent decides at e's
               source, so me = "other"): th_self<->th_other, D+<->D-, kind<->other_kind,
               def_self<->def_other.

with r = feat_r (or feat_r_mean, ``Style.distance``), th in rad, r and d_p in metres; with
``Style.per_second`` the two position terms are multiplied by feat_duration (s).

Cooperative (Eq. 3 analogue), both fighters maximise the same reward: keep a target distance,
face each other, and move the pair's midpoint at a set speed in one of 8 directions of the pair
frame (see :func:`cooperative_rewards`).
"""
from __future__ import annotations

from typing import Mapping, Sequence

import numba as nb
import numpy as np

from planner.styles import ATTACK_KINDS, DISTANCE_FEATURES, Style

FIGHT_FEATURES: tuple[str, ...] = (
    "feat_duration", "feat_theta_self", "feat_theta_other", "feat_dmg_given", "feat_dmg_received",
    "feat_kind", "feat_other_kind", "feat_def_self", "feat_def_other",
)
COOP_FEATURES: tuple[str, ...] = (
    "feat_duration", "feat_r", "feat_theta_self", "feat_theta_other", "feat_dmg_given",
    "feat_dmg_received", "feat_mid_dx", "feat_mid_dz",
)


def _feature(features: Mapping[str, np.ndarray], key: str, n: int | None = None) -> np.ndarray:
    if key not in features:
        raise KeyError(f"edge feature {key!r} missing (docs/contracts.md lists the edge features)")
    a = np.asarray(features[key])
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        raise ValueError(f"edge feature {key!r} must have shape ({n if n is not None else 'E'},), got {a.shape}")
    return a


def kind_preferences(style: Style, kinds_table: Sequence[str]) -> np.ndarray:
    """(K,) float64 multiplier on damage dealt per kind index of ``kinds_table`` (1.0 for
    non-attack kinds and attack kinds the style does not list)."""
    return np.array([style.pref(k) if k in ATTACK_KINDS else 1.0 for k in kinds_table], dtype=np.float64)


@nb.njit(inline="always")
def fight_edge(e, r, th_s, th_o, dur, dg, dr, kind, okind, def_s, def_o, pref,
                d_p, w_theta, w_d, w_g, w_r, w_def, per_second):
    """(W_me, W_opp) of edge e (module docstring)."""
    dd = r[e] - d_p
    pd = w_d * dd * dd
    pos_me = w_theta * th_s[e] * th_s[e] + pd
    pos_opp = w_theta * th_o[e] * th_o[e] + pd
    if per_second:
        pos_me *= dur[e]
        pos_opp *= dur[e]
    npref = pref.shape[0]
    k = kind[e]
    pk = pref[k] if 0 <= k < npref else 1.0
    k = okind[e]
    po = pref[k] if 0 <= k < npref else 1.0
    me = -pos_me + w_g * dg[e] * pk - w_r * dr[e] + w_def * def_s[e]
    opp = -pos_opp + w_g * dr[e] * po - w_r * dg[e] + w_def * def_o[e]
    return me, opp


@nb.njit(cache=True)
def _fight_kernel(r, th_s, th_o, dur, dg, dr, kind, okind, def_s, def_o, pref,
                  d_p, w_theta, w_d, w_g, w_r, w_def, per_second, out_me, out_opp):
    for e in range(r.shape[0]):
        me, opp = fight_edge(e, r, th_s, th_o, dur, dg, dr, kind, okind, def_s, def_o, pref,
                              d_p, w_theta, w_d, w_g, w_r, w_def, per_second)
        out_me[e] = me
        out_opp[e] = opp


@nb.njit(parallel=True, cache=True)
def fight_rewards_packed(edge_rank, r, th_s, th_o, dur, dg, dr, kind, okind, def_s, def_o, pref,
                         d_p, w_theta, w_d, w_g, w_r, w_def, per_second, W2):
    """W2[2i], W2[2i+1] = (W_me, W_opp) of edge e with i = edge_rank[e] (the search kernels'
    packed layout; features read in their own order, results scattered); returns the number of
    non-finite rewards."""
    bad = 0
    for e in nb.prange(edge_rank.shape[0]):
        me, opp = fight_edge(e, r, th_s, th_o, dur, dg, dr, kind, okind, def_s, def_o, pref,
                              d_p, w_theta, w_d, w_g, w_r, w_def, per_second)
        i = edge_rank[e]
        W2[2 * i] = me
        W2[2 * i + 1] = opp
        if not (np.isfinite(me) and np.isfinite(opp)):
            bad += 1
    return bad


def fight_kernel_args(features: Mapping[str, np.ndarray], style: Style, kinds_table: Sequence[str]) -> tuple:
    """Arrays and constants of the fighting-reward kernels, checked and converted (E,)."""
    r = _feature(features, DISTANCE_FEATURES[style.distance])
    n = r.shape[0]
    f = {k: _feature(features, k, n) for k in FIGHT_FEATURES}

    def f64(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=np.float64)

    def i32(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(a, dtype=np.int32)

    return (f64(r), f64(f["feat_theta_self"]), f64(f["feat_theta_other"]), f64(f["feat_duration"]),
            f64(f["feat_dmg_given"]), f64(f["feat_dmg_received"]), i32(f["feat_kind"]), i32(f["feat_other_kind"]),
            f64(f["feat_def_self"]), f64(f["feat_def_other"]), kind_preferences(style, kinds_table),
            float(style.d_p), float(style.w_theta), float(style.w_d), float(style.w_dmg_given),
            float(style.w_dmg_received), float(style.w_def), bool(style.per_second))


def edge_rewards(features: Mapping[str, np.ndarray], style: Style, kinds_table: Sequence[str],
                 dtype: type = np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 4 rewards of every edge for the controlled fighter, from both perspectives.

    Args:
        features: edge features (docs/contracts.md), (E,) each.
        style: the controlled fighter's style.
        kinds_table: kind names indexed by feat_kind / feat_other_kind (the graph's KINDS table);
            indices outside it count preference 1.0.
        dtype: float dtype of the result.

    Returns:
        (W_me, W_opp), (E,) each: W_me[e] when the controlled fighter decides at e's source,
        W_opp[e] when the opponent does (the opponent minimises it in min-max).
    """
    args = fight_kernel_args(features, style, kinds_table)
    n = args[0].shape[0]
    out_me = np.empty(n, dtype=dtype)
    out_opp = np.empty(n, dtype=dtype)
    _fight_kernel(*args, out_me, out_opp)
    return out_me, out_opp


#: Number of travel directions of the cooperative task (paper: eight).
N_DIRECTIONS = 8


def direction_vector(direction_index: int, n_directions: int = N_DIRECTIONS) -> tuple[float, float]:
    """Unit (x, z) of travel direction ``direction_index`` in the pair frame: 0 = +Z (towards the
    partner), then counter-clockwise seen from above in steps of 360/n degrees: 2 = +X (left),
    4 = -Z (away), 6 = -X (right) for n = 8."""
    a = 2.0 * np.pi * (direction_index % n_directions) / n_directions
    return float(np.sin(a)), float(np.cos(a))


def cooperative_rewards(features: Mapping[str, np.ndarray], target_distance: float,
                        direction_index: int | None, speed: float = 0.5, *,
                        w_theta: float = 0.5, w_d: float = 4.0, w_v: float = 2.0, w_dmg: float = 5.0,
                        n_directions: int = N_DIRECTIONS,
                        dtype: type = np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3 analogue for two sparring partners moving together at a set distance.

    r = -w_theta*(th_self^2 + th_other^2) - w_d*(feat_r - target_distance)^2
        - w_v*|v - v_ref|^2 - w_dmg*(D+ + D-)

    v = (feat_mid_dx, feat_mid_dz) / feat_duration is the pair midpoint's mean velocity (m/s)
    in the pair frame at the edge start (docs/contracts.md: +Z from the decider towards the other,
    +X to the decider's left of that line), and v_ref = speed * direction_vector(k).

    The pair frame is anchored on the decider, so one direction for the pair is index k when
    fighter A decides and k + n/2 when B decides (the frame turns by 180 degrees). Hence two arrays.

    Args:
        features: edge features; needs the COOP_FEATURES keys.
        target_distance: metres (> 0).
        direction_index: 0..n_directions-1 (A's pair frame), or None for no travel term.
        speed: m/s of the wanted midpoint travel.
        w_theta, w_d, w_v, w_dmg: weights (per rad^2, m^2, (m/s)^2, damage unit).

    Returns:
        (W_a, W_b), (E,) each: the reward when fighter A / B decides at e's source. Feed them to
        :func:`planner.dp.value_iteration_pair` (identical arrays when direction_index is None).
    """
    if not target_distance > 0:
        raise ValueError(f"target_distance must be > 0 metres, got {target_distance!r}")
    n = _feature(features, "feat_r").shape[0]
    f = {k: _feature(features, k, n).astype(np.float64, copy=False) for k in COOP_FEATURES
         if direction_index is not None or k not in ("feat_mid_dx", "feat_mid_dz")}
    base = (-w_theta * (f["feat_theta_self"] ** 2 + f["feat_theta_other"] ** 2)
            - w_d * (f["feat_r"] - target_distance) ** 2
            - w_dmg * (f["feat_dmg_given"] + f["feat_dmg_received"]))
    if direction_index is None:
        w = base.astype(dtype)
        return w, w.copy()
    dt = np.maximum(f["feat_duration"], 1e-3)
    vx, vz = f["feat_mid_dx"] / dt, f["feat_mid_dz"] / dt
    out = []
    for k in (direction_index, direction_index + n_directions // 2):
        ux, uz = direction_vector(k, n_directions)
        out.append((base - w_v * ((vx - speed * ux) ** 2 + (vz - speed * uz) ** 2)).astype(dtype))
    return out[0], out[1]


def style_params(style: Style) -> np.ndarray:
    """The style as the float vector the numba kernels take:
    [d_p, w_theta, w_d, w_dmg_given, w_dmg_received, w_def, per_second, distance is 'mean']."""
    return np.array([style.d_p, style.w_theta, style.w_d, style.w_dmg_given, style.w_dmg_received, style.w_def,
                     float(style.per_second), float(DISTANCE_FEATURES[style.distance] == "feat_r_mean")],
                    dtype=np.float64)
