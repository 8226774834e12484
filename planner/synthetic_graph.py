"""Synthetic Interaction-Graph-like graphs (contract arrays) for tests and benchmarks.

Structure, after a real IG: states fall in compatible groups (same Next(M_self), M_other and
F_other bin) and carry a continuous part x in [0, 1) (distance/angles). A group is a pair
(context m, frame bin f). An edge launches action j of the menu; the target's group is
(h(m, action), f + 1 + action % 3 mod F) and its continuous part is close to the source's
(x + small noise): neighbouring states of a group, and neighbouring frame bins of a context,
send their edges to neighbouring states of the same target groups. ``locality=False`` gives
uniform random targets.
"""
from __future__ import annotations

import numpy as np

STATE_ORDERS: tuple[str, ...] = ("natural", "group", "shuffled")


def synthetic_graph(n_states: int, mean_degree: float, seed: int, *, n_groups: int | None = None,
                    frame_bins: int = 8, locality: bool = True, noise: float = 0.02, swap_prob: float = 0.5,
                    dead_end_fraction: float = 0.0, state_order: str = "group",
                    n_kinds: int = 14, features: bool = True) -> dict[str, np.ndarray]:
    """A random graph with the contract's arrays (docs/contracts.md).

    Args:
        n_states: S.
        mean_degree: mean out-degree (degrees uniform in [mean/2, 3*mean/2]).
        seed: seed of the numpy Generator.
        n_groups: number of compatible groups (default S // 40).
        frame_bins: F, frame bins per context (groups = contexts x F).
        locality: targets near the source's continuous part in a group chosen by (group, action);
            False: uniform random targets.
        noise: spread of the target's continuous part (fraction of the group).
        swap_prob: probability that an edge hands the decision to the other fighter.
        dead_end_fraction: share of states without edges.
        state_order: "natural" (by context, frame bin, x: a builder that sorts its states),
            "group" (groups contiguous in random order, states random inside: per-group
            k-means written group by group), "shuffled" (random state ids).
        n_kinds: size of the kinds table the kind features index.
        features: also make random edge features (feat_*).

    Returns:
        dict with state_offsets, edge_target, edge_swap, edge_action (+ feat_* when ``features``).
    """
    if state_order not in STATE_ORDERS:
        raise ValueError(f"state_order must be one of {STATE_ORDERS}, got {state_order!r}")
    rng = np.random.default_rng(seed)
    S = int(n_states)
    F = max(1, int(frame_bins))
    G = max(F, int(n_groups if n_groups is not None else S // 40) // F * F)
    M = G // F
    # Natural numbering: group g = m*F + f holds states [gstart[g], gstart[g+1]), sorted by x.
    cuts = np.sort(rng.choice(np.arange(1, S), size=G - 1, replace=False)) if G > 1 else np.array([], dtype=np.int64)
    gstart = np.concatenate([[0], cuts, [S]]).astype(np.int64)
    gsize = np.diff(gstart)
    group = np.repeat(np.arange(G), gsize)
    x = (np.arange(S) - gstart[group] + rng.random(S)) / gsize[group]
    lo, hi = max(1, int(round(mean_degree * 0.5))), max(1, int(round(mean_degree * 1.5)))
    deg = rng.integers(lo, hi + 1, size=S)
    deg[rng.random(S) < dead_end_fraction] = 0
    offsets = np.zeros(S + 1, dtype=np.int64)
    np.cumsum(deg, out=offsets[1:])
    E = int(offsets[-1])
    src = np.repeat(np.arange(S), deg)
    j = np.arange(E) - offsets[src]                      # index in the menu = action slot
    m, f = group[src] // F, group[src] % F
    action = (j * 7 + m * 3) % 137
    if locality:
        hm = (m.astype(np.int64) * 7919 + action * 104729 + 17) % M
        hf = (f + 1 + action % 3) % F
        hgroup = hm * F + hf
        xt = np.clip(x[src] + rng.normal(0.0, noise, E), 0.0, 1.0 - 1e-9)
        target = gstart[hgroup] + np.floor(xt * gsize[hgroup]).astype(np.int64)
    else:
        target = rng.integers(0, S, size=E)
    swap = (rng.random(E) < swap_prob).astype(np.uint8)
    # Relabel states for the requested order.
    if state_order == "natural":
        perm = np.arange(S)                               # new id -> natural id
    elif state_order == "group":
        perm = np.concatenate([gstart[g] + rng.permutation(gsize[g]) for g in rng.permutation(G)])
    else:
        perm = rng.permutation(S)
    rank = np.empty(S, dtype=np.int64)
    rank[perm] = np.arange(S)
    new_deg = deg[perm]
    new_off = np.zeros(S + 1, dtype=np.int64)
    np.cumsum(new_deg, out=new_off[1:])
    eidx = np.arange(E, dtype=np.int64) + np.repeat(offsets[perm] - new_off[:-1], new_deg)
    out: dict[str, np.ndarray] = {
        "state_offsets": new_off,
        "edge_target": rank[target[eidx]].astype(np.int32),
        "edge_swap": swap[eidx],
        "edge_action": action[eidx].astype(np.int32),
    }
    if features:
        out.update(random_features(E, seed + 1, n_kinds))
    return out


def random_features(n_edges: int, seed: int, n_kinds: int = 14) -> dict[str, np.ndarray]:
    """Random edge features with plausible ranges (units as in docs/contracts.md)."""
    rng = np.random.default_rng(seed)
    E = int(n_edges)
    hit = rng.random(E)
    return {
        "feat_duration": rng.uniform(0.3, 1.2, E),
        "feat_r": rng.uniform(0.3, 3.0, E),
        "feat_r_mean": rng.uniform(0.3, 3.0, E),
        "feat_theta_self": rng.uniform(-np.pi, np.pi, E),
        "feat_theta_other": rng.uniform(-np.pi, np.pi, E),
        "feat_dmg_given": np.where(hit < 0.1, rng.uniform(0.5, 1.5, E), 0.0),
        "feat_dmg_received": np.where(hit > 0.9, rng.uniform(0.5, 1.5, E), 0.0),
        "feat_kind": rng.integers(0, n_kinds, E).astype(np.int32),
        "feat_other_kind": rng.integers(0, n_kinds, E).astype(np.int32),
        "feat_def_self": (rng.random(E) < 0.05).astype(np.float64),
        "feat_def_other": (rng.random(E) < 0.05).astype(np.float64),
        "feat_mid_dx": rng.normal(0.0, 0.2, E),
        "feat_mid_dz": rng.normal(0.0, 0.2, E),
    }
