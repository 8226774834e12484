"""The action-level motion graph: Next(a) from end/start pose compatibility."""
from __future__ import annotations

import numpy as np

from motion_graph.rotations import yaw_matrix


def boundary_poses(lib) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Start and end poses of every action, each in its own ground frame (pelvis over the origin,
    fighting direction along +Z): positions (A, J, 3) and velocities (A, J, 3) in m and m/s."""
    A = lib.n_actions
    J = lib.skeleton.n_joints
    P = lib.positions
    s_pos = np.empty((A, J, 3))
    e_pos = np.empty((A, J, 3))
    s_vel = np.empty((A, J, 3))
    e_vel = np.empty((A, J, 3))
    for a in range(A):
        f0, f1 = int(lib.frame_offsets[a]), int(lib.frame_offsets[a + 1]) - 1
        s_pos[a] = P[f0]
        s_vel[a] = (P[f0 + 1] - P[f0]) * lib.fps
        x, z, h = lib.path[f1]
        Ri = yaw_matrix(-h)
        e_pos[a] = (P[f1] - np.array([x, 0.0, z])) @ Ri.T
        e_vel[a] = ((P[f1] - P[f1 - 1]) * lib.fps) @ Ri.T
    return s_pos, s_vel, e_pos, e_vel


def transition_costs(lib, velocity_s: float = 0.05) -> np.ndarray:
    """(A, A) cost of a -> b: mean joint distance (m) of a's end vs b's start pose,
    plus velocity_s times the mean joint velocity difference (m/s)."""
    s_pos, s_vel, e_pos, e_vel = boundary_poses(lib)
    dp = np.linalg.norm(e_pos[:, None] - s_pos[None], axis=-1).mean(axis=-1)
    dv = np.linalg.norm(e_vel[:, None] - s_vel[None], axis=-1).mean(axis=-1)
    return dp + velocity_s * dv


def pose_hubs(lib, threshold_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Cluster all start and end poses (each in its own ground frame) by complete linkage so that
    any two poses of a cluster are within ``threshold_m`` mean joint distance. Returns the cluster
    of each action's start and of its end pose, (A,) each."""
    from scipy.cluster.hierarchy import fcluster, linkage

    s_pos, _, e_pos, _ = boundary_poses(lib)
    A, J = s_pos.shape[:2]
    X = np.concatenate([e_pos, s_pos])  # (2A, J, 3)
    n = len(X)
    # condensed pairwise mean joint distances
    iu = np.triu_indices(n, 1)
    D = np.linalg.norm(X[iu[0]] - X[iu[1]], axis=-1).mean(axis=-1)
    lab = fcluster(linkage(D, "complete"), threshold_m, "distance")
    return lab[A:], lab[:A]


def compute_next_hubs(lib, threshold_m: float = 0.2) -> None:
    """Next(a) = every action whose start pose is in the pose cluster ("hub") of a's end pose.

    Clusters are complete-linkage groups of boundary poses whose members are all within
    ``threshold_m`` (mean joint distance, m) of each other, so every transition pops by at most
    the threshold, and actions that end in the same hub share their menu: the Interaction Graph's
    compatible groups (keyed by Next(M)) are then few (13 hubs on CMU 13_17 + 13_18 at 0.2 m).
    The successor in the same take is always included (same pose, hence same hub).
    """
    start_hub, end_hub = pose_hubs(lib, threshold_m)
    s_pos, _, e_pos, _ = boundary_poses(lib)
    ids, costs, offs = [], [], [0]
    for a in range(lib.n_actions):
        nb = np.nonzero(start_hub == end_hub[a])[0]
        ids.extend(nb.tolist())
        costs.extend(np.linalg.norm(e_pos[a][None] - s_pos[nb], axis=-1).mean(axis=-1).tolist())
        offs.append(len(ids))
    lib.next_offsets = np.array(offs, dtype=np.int64)
    lib.next_ids = np.array(ids, dtype=np.int32)
    lib.next_cost = np.array(costs, dtype=np.float64)


def compute_next(lib, threshold_m: float = 0.15, velocity_s: float = 0.05, min_degree: int = 3) -> None:
    """Fill lib.next_offsets / next_ids / next_cost.

    a -> b when the transition cost is under ``threshold_m``; the successor in the same take is
    always kept; every action gets at least ``min_degree`` successors and predecessors (its
    cheapest ones), so no action is a dead end (the last action of a take has no natural successor).
    """
    cost = transition_costs(lib, velocity_s)
    A = lib.n_actions
    ok = cost <= threshold_m
    for a in range(A):
        for b in range(A):
            if lib.sources[b] == lib.sources[a] and lib.src_start[b] == lib.src_end[a]:
                ok[a, b] = True
    k = min(min_degree, A)
    for a in range(A):
        if ok[a].sum() < k:
            ok[a, np.argsort(cost[a], kind="stable")[:k]] = True
        if ok[:, a].sum() < k:
            ok[np.argsort(cost[:, a], kind="stable")[:k], a] = True
    ids, costs, offs = [], [], [0]
    for a in range(A):
        nb = np.nonzero(ok[a])[0]
        ids.extend(nb.tolist())
        costs.extend(cost[a, nb].tolist())
        offs.append(len(ids))
    lib.next_offsets = np.array(offs, dtype=np.int64)
    lib.next_ids = np.array(ids, dtype=np.int32)
    lib.next_cost = np.array(costs, dtype=np.float64)
