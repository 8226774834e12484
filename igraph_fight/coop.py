"""Cooperative control on the Interaction Graph (paper sections 6.3 and 7.2).

The paper's carrying task (two avatars keep a distance and move the pair in one of eight
directions, Eq. 3, dynamic programming) transposed to the data we have: two sparring partners
who keep a set distance, face each other, avoid hitting each other and move their midpoint in
one of 8 directions of the pair frame (planner.rewards.cooperative_rewards).

The graph has no midpoint features yet (docs/contracts.md: ``feat_mid_dx``, ``feat_mid_dz``), so
:func:`midpoint_features` computes them: every edge is simulated once more from its source
state's canonical sample with its action (the decider at the origin facing +Z, the other at
(r, theta_self, theta_other) in its action and frame; sim.sample_world / sim.advance_to_decision, exactly
as the graph's builder and NPCController's lookahead simulate), and the displacement of the
midpoint between the two pelvis ground points is expressed in the pair frame at the edge start
(+Z from the decider towards the other, +X to its left). The same simulation gives the edge's
distance and duration, which must equal the graph's ``feat_r`` / ``feat_duration``
(``check`` in the result).

:func:`cooperative_policy` runs planner.value_iteration_pair for one direction; both fighters
maximise the common reward (W_a when fighter A decides, W_b when B does: the same direction seen
from the other end of the pair). :class:`CoopAgent` plays such a policy in the game API (nearest
graph state of the live state, best legal edge there); :func:`run_pair` plays a bout of two
agents and measures the objective frame by frame (:func:`progress`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

import motion_graph.rotations
from igraph_fight import locate, sim
from igraph_fight.kernel_cache import drop_stale_caches
from igraph_fight.locate import locate_packed
from igraph_fight.sim import advance_to_decision, expand_one, root_pose, sample_world

drop_stale_caches(__file__, [locate, sim, motion_graph.rotations])


@njit(cache=True, inline="always")
def _midpoint_move(T, S, act, frm, r0, b):
    """Move of the pair's midpoint since the event started, in the decider's pair frame at the
    start (+Z towards the other, +X to its left; the other started at distance r0 and bearing b
    from the decider at the origin, heading 0), and the distance between the roots now.
    Returns (dx, dz, r) in metres."""
    xa, za, _ = root_pose(T, S, act, frm, 0)
    xb, zb, _ = root_pose(T, S, act, frm, 1)
    dmx = 0.5 * (xa + xb) - 0.5 * r0 * np.sin(b)
    dmz = 0.5 * (za + zb) - 0.5 * r0 * np.cos(b)
    return (dmx * np.cos(b) - dmz * np.sin(b), dmx * np.sin(b) + dmz * np.cos(b),
            np.sqrt((xb - xa) ** 2 + (zb - za) ** 2))


@njit(cache=True, nogil=True)
def _mid_range(T, offsets, st_i, st_f, edge_action, out, lo, hi):
    """out[e] = (mid_dx, mid_dz, frames, r_end) for the edges of states lo..hi-1."""
    S = np.empty((2, 3))
    act = np.empty(2, dtype=np.int64)
    frm = np.empty(2, dtype=np.int64)
    mask = np.empty(2, dtype=np.int64)
    stats = np.empty(sim.N_STAT)
    for s in range(lo, hi):
        for e in range(offsets[s], offsets[s + 1]):
            sample_world(T, st_i[s], st_f[s], edge_action[e], S, act, frm, mask)
            for k in range(sim.N_STAT):
                stats[k] = 0.0
            advance_to_decision(T, S, act, frm, mask, stats)
            mx, mz, r_end = _midpoint_move(T, S, act, frm, st_f[s, 0], st_f[s, 1])
            out[e, 0] = mx
            out[e, 1] = mz
            out[e, 2] = stats[sim.ST_FRAMES]
            out[e, 3] = r_end


def midpoint_features(graph, tables, workers: int | None = 1) -> dict:
    """feat_mid_dx / feat_mid_dz (m, pair frame at the edge start) of every edge, by simulation.

    Returns {"feat_mid_dx", "feat_mid_dz", "check"}; check = largest differences between the
    re-simulated and stored distance (m) and duration (s) of the edges (0 when the graph and the
    simulator tables agree)."""
    a = graph.arrays
    S = len(a["state_r"])
    st_i = np.ascontiguousarray(np.stack([a["state_m_self"], a["state_m_other"], a["state_f_other"],
                                          a["state_mask_other"]], axis=1), dtype=np.int64)
    st_f = np.ascontiguousarray(np.stack([a["state_r"], a["state_theta_self"], a["state_theta_other"]], axis=1),
                                dtype=np.float64)
    offsets = np.ascontiguousarray(a["state_offsets"], dtype=np.int64)
    out = np.empty((int(offsets[-1]), 4))
    sim.parallel_for(_mid_range, S, sim.resolve_workers(workers), tables.kernel_tuple(), offsets, st_i, st_f,
                     np.ascontiguousarray(a["edge_action"], dtype=np.int64), out, min_chunk=256)
    dur = out[:, 2] / tables.fps
    check = {"max_abs_r_diff_m": float(np.max(np.abs(out[:, 3] - a["feat_r"]))) if len(out) else 0.0,
             "max_abs_duration_diff_s": float(np.max(np.abs(dur - a["feat_duration"]))) if len(out) else 0.0}
    return {"feat_mid_dx": out[:, 0].copy(), "feat_mid_dz": out[:, 1].copy(), "check": check}


@njit(cache=True)
def _coop_lookahead(T, pi, pf, pc, V_self, V_other, gamma, rw, menu, si, sf):
    """Off-graph cooperative decision: simulate every legal action once from the live state and
    score it by the cooperative reward of that event (planner.cooperative_rewards' formula) plus
    gamma times the value of the graph state nearest to where it lands (igraph_fight.locate, on
    its lookup grid; V_other when the other
    fighter decides there). rw = (target_distance, w_theta, w_d, w_v, w_dmg, v_ref_x, v_ref_z) in
    the decider's pair frame, fps). Returns (best action, its score); (-1, -inf) without actions."""
    S = np.empty((2, 3))
    act = np.empty(2, dtype=np.int64)
    frm = np.empty(2, dtype=np.int64)
    mask = np.empty(2, dtype=np.int64)
    stats = np.empty(sim.N_STAT)
    feat = np.empty(sim.N_FEAT)
    ci = np.empty(sim.N_SI, dtype=np.int64)
    cf = np.empty(sim.N_SF)
    best_a = -1
    best_q = -np.inf
    for j in range(menu.shape[0]):
        a = menu[j]
        d = expand_one(T, si, sf, a, ci, cf, feat, S, act, frm, mask, stats)
        mx, mz, _ = _midpoint_move(T, S, act, frm, sf[0], sf[1])
        r, ts, to = feat[sim.FT_R], feat[sim.FT_TH_SELF], feat[sim.FT_TH_OTHER]
        dur = max(feat[sim.FT_FRAMES] / rw[7], 1e-3)
        vx = mx / dur
        vz = mz / dur
        w = (-rw[1] * (ts * ts + to * to) - rw[2] * (r - rw[0]) ** 2
             - rw[4] * (feat[sim.FT_DMG_GIVEN] + feat[sim.FT_DMG_RECEIVED])
             - rw[3] * ((vx - rw[5]) ** 2 + (vz - rw[6]) ** 2))
        s, _, _, _ = locate_packed(pi, pf, pc, cf[0], cf[1], cf[2], ci[0], ci[1], ci[2], ci[3])
        v = 0.0
        if s >= 0:
            v = V_other[s] if d == 1 else V_self[s]
        q = w + gamma * v
        if q > best_q:
            best_q = q
            best_a = a
    return best_a, best_q


@dataclass
class CoopPolicy:
    """A cooperative policy for one travel direction (index into planner.direction_vector, in A's
    pair frame). Q_a / Q_b: (E,) edge scores when A / B decides at the edge's source."""

    direction: int
    target_distance: float
    speed: float
    W_a: np.ndarray
    W_b: np.ndarray
    V_a: np.ndarray
    V_b: np.ndarray
    best_a: np.ndarray
    best_b: np.ndarray
    Q_a: np.ndarray
    Q_b: np.ndarray
    sweeps: int
    error: float
    compute_ms: float
    gamma: float = 0.9
    weights: tuple = (0.5, 4.0, 2.0, 5.0)   # w_theta, w_d, w_v, w_dmg of planner.cooperative_rewards


def cooperative_policy(graph, features: dict, direction: int | None, target_distance: float = 1.2,
                       speed: float = 0.3, gamma: float = 0.9, tol: float = 1e-3, n_threads: int | None = None,
                       **reward_kw) -> CoopPolicy:
    """Value iteration (planner.value_iteration_pair) of the cooperative reward for one direction
    (None: keep the distance and face each other, no travel). ``features``: the graph's arrays
    plus feat_mid_dx / feat_mid_dz; reward_kw go to planner.cooperative_rewards. ``n_threads``:
    numba threads for the sweeps (None: numba's setting; on a busy shared machine one thread is
    often much faster, every sweep being a parallel region that waits for all its threads)."""
    import time

    import numba

    from planner import cooperative_rewards, value_iteration_pair

    t0 = time.perf_counter()
    a = graph.arrays
    W_a, W_b = cooperative_rewards(features, target_distance, direction, speed, **reward_kw)
    old = numba.get_num_threads()
    if n_threads:
        numba.set_num_threads(min(int(n_threads), numba.config.NUMBA_NUM_THREADS))
    try:
        V_a, V_b, best_a, best_b, sweeps, err = value_iteration_pair(a["state_offsets"], a["edge_target"],
                                                                     a["edge_swap"], W_a, W_b, gamma, tol)
    finally:
        numba.set_num_threads(old)
    t = a["edge_target"].astype(np.int64)
    sw = a["edge_swap"].astype(bool)
    Q_a = W_a + gamma * np.where(sw, V_b[t], V_a[t])
    Q_b = W_b + gamma * np.where(sw, V_a[t], V_b[t])
    w = {"w_theta": 0.5, "w_d": 4.0, "w_v": 2.0, "w_dmg": 5.0}
    w.update({k: float(v) for k, v in reward_kw.items() if k in w})
    return CoopPolicy(direction, target_distance, speed, W_a, W_b, V_a, V_b, best_a, best_b, Q_a, Q_b, sweeps, err,
                      (time.perf_counter() - t0) * 1e3, float(gamma), (w["w_theta"], w["w_d"], w["w_v"], w["w_dmg"]))


class CoopAgent:
    """Plays a CoopPolicy in the game API as fighter ``role`` (0 = A, 1 = B). On the graph (the
    live state within tolerance of its nearest state, ``NPCController.locate``): the best-scoring
    legal edge of that state. Off the graph (``lookahead=True``): every legal action simulated
    once from the live state, scored by its cooperative reward plus the value where it lands
    (like NPCController's off-graph lookahead); else the nearest state's best legal edge.

    snap: move onto the state when within tolerance (as IGAgent(snap=True)); off by default so
    that the measured travel is the motion's own."""

    def __init__(self, controller, policy: CoopPolicy, role: int, name: str | None = None, snap: bool = False,
                 lookahead: bool = True) -> None:
        self.controller = controller
        self.policy = policy
        self.role = role
        self.name = name or f"coop{'AB'[role]}(dir {policy.direction})"
        self.snap = snap
        self.lookahead = lookahead
        self.decisions = 0
        self.off_graph = 0
        self._rw = None

    def set_policy(self, policy: CoopPolicy) -> None:
        """Switch direction (policies for the 8 directions can be precomputed and swapped)."""
        self.policy = policy
        self._rw = None

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        pass

    def _weights(self) -> np.ndarray:
        if self._rw is None:
            from planner import direction_vector
            p = self.policy
            k = p.direction if self.role == 0 else p.direction + 4
            vx, vz = direction_vector(k) if p.direction is not None else (0.0, 0.0)
            w_theta, w_d, w_v, w_dmg = p.weights
            self._rw = np.array([p.target_distance, w_theta, w_d, w_v if p.direction is not None else 0.0, w_dmg,
                                 p.speed * vx, p.speed * vz, self.controller.tables.fps], dtype=np.float64)
        return self._rw

    def step(self, state, player: int) -> int:
        from igraph_fight.controller import observe
        from igraph_fight.state import to_sample

        c = self.controller
        obs = observe(state, player)
        s, _, off = c.locate(obs)
        self.decisions += 1
        self.off_graph += int(off)
        legal = state.legal_actions(player)
        p = self.policy
        if off and self.lookahead:
            si, sf = to_sample(state.game.tables, state.world, player)
            V_self, V_other = (p.V_a, p.V_b) if self.role == 0 else (p.V_b, p.V_a)
            a, _ = _coop_lookahead(c.kernel_tables, *c.packed_index, V_self, V_other, p.gamma, self._weights(),
                                np.ascontiguousarray(legal, dtype=np.int64), si.astype(np.int64), sf.astype(np.float64))
            if a >= 0:
                return int(a)
        q = p.Q_a if self.role == 0 else p.Q_b
        best, bq = -1, -np.inf
        if s >= 0:
            for e in range(int(c._offsets[s]), int(c._offsets[s + 1])):
                if c._edge_action[e] in legal and q[e] > bq:
                    best, bq = int(c._edge_action[e]), float(q[e])
        if best < 0:
            return int(legal[0])
        if self.snap and not off:
            g = c.graph.arrays
            state.snap(player, float(g["state_r"][s]), float(g["state_theta_self"][s]))
        return best


def progress(trace: dict, direction: int, target_distance: float, n_directions: int = 8) -> dict:
    """The cooperative objective measured on a traced bout (per-frame poses of A and B):

    travel_m: midpoint displacement along the commanded direction, summed frame by frame in the
        pair frame of that frame (+Z from A to B, +X to A's left), i.e. what the reward asks for;
    world_m: displacement of the midpoint from start to end along the commanded direction of the
        *initial* pair frame;
    distance_err_m: mean |distance - target|; facing_err_rad: mean of |theta_A| and |theta_B|.
    """
    from planner import direction_vector

    p = trace["pose"]                  # (T, 2, 3) x, z, heading
    mid = 0.5 * (p[:, 0, :2] + p[:, 1, :2])
    d = p[:, 1, :2] - p[:, 0, :2]
    r = np.hypot(d[:, 0], d[:, 1])
    u = d / np.maximum(r, 1e-9)[:, None]                 # +Z of the pair frame (x, z)
    left = np.stack([u[:, 1], -u[:, 0]], axis=1)         # +X
    vx, vz = direction_vector(direction, n_directions)
    w = vx * left + vz * u                               # commanded direction, world, per frame
    step = np.diff(mid, axis=0)
    travel = float(np.sum(np.einsum("ij,ij->i", step, w[:-1])))
    world = float((mid[-1] - mid[0]) @ w[0])
    b = np.arctan2(d[:, 0], d[:, 1])
    th_a = (b - p[:, 0, 2] + np.pi) % (2 * np.pi) - np.pi
    th_b = (b + np.pi - p[:, 1, 2] + np.pi) % (2 * np.pi) - np.pi
    return {"travel_m": travel, "world_m": world, "distance_err_m": float(np.mean(np.abs(r - target_distance))),
            "facing_err_rad": float(np.mean(0.5 * (np.abs(th_a) + np.abs(th_b)))),
            "seconds": float(trace["t"][-1] - trace["t"][0]) if len(trace["t"]) > 1 else 0.0}


def realized_reward(res, policy: CoopPolicy, damage_per_hit: float = 1.0) -> dict:
    """The cooperative reward the pair actually earned in a traced bout: every decision's event
    (until the next decision) scored with planner.cooperative_rewards' formula from the
    decider's side (A: direction k, B: k + 4), from the trace. Returns the mean per decision and
    the total."""
    from planner import direction_vector

    tr = res.trace
    t = tr["t"]
    p = tr["pose"]
    dec = sorted(res.decisions, key=lambda d: d["t"])
    w_theta, w_d, w_v, w_dmg = policy.weights
    hit_t = np.array(sorted(h["t"] for h in res.hit_events))
    total, n = 0.0, 0
    for i in range(len(dec) - 1):
        t0, t1 = dec[i]["t"], dec[i + 1]["t"]
        k0 = int(np.searchsorted(t, t0 - 1e-9))
        k1 = int(np.searchsorted(t, t1 - 1e-9))
        if k1 >= len(t):
            break
        me = dec[i]["player"]
        o = 1 - me
        dx, dz = p[k1, o, 0] - p[k1, me, 0], p[k1, o, 1] - p[k1, me, 1]
        r = float(np.hypot(dx, dz))
        b = np.arctan2(dx, dz)
        ts = (b - p[k1, me, 2] + np.pi) % (2 * np.pi) - np.pi
        to = (b + np.pi - p[k1, o, 2] + np.pi) % (2 * np.pi) - np.pi
        w = -w_theta * (ts * ts + to * to) - w_d * (r - policy.target_distance) ** 2
        w -= w_dmg * damage_per_hit * float(np.sum((hit_t >= t0) & (hit_t < t1)))
        if policy.direction is not None:
            b0 = np.arctan2(p[k0, o, 0] - p[k0, me, 0], p[k0, o, 1] - p[k0, me, 1])
            m0 = 0.5 * (p[k0, 0, :2] + p[k0, 1, :2])
            m1 = 0.5 * (p[k1, 0, :2] + p[k1, 1, :2])
            dm = m1 - m0
            dur = max(t1 - t0, 1e-3)
            vx = (dm[0] * np.cos(b0) - dm[1] * np.sin(b0)) / dur
            vz = (dm[0] * np.sin(b0) + dm[1] * np.cos(b0)) / dur
            ux, uz = direction_vector(policy.direction + (4 if me == 1 else 0))
            w -= w_v * ((vx - policy.speed * ux) ** 2 + (vz - policy.speed * uz) ** 2)
        total += w
        n += 1
    return {"reward_per_decision": total / max(n, 1), "reward_total": total, "decisions": n}


def start_state(game, target_distance: float, rng: np.random.Generator):
    """A facing B at about the target distance (small random offsets), both in a guard action."""
    r = target_distance + rng.normal(0, 0.05)
    h = rng.normal(0, 0.1, size=2)
    acts = rng.choice(game.start_actions, size=2)
    return game.initial_state((0.0, 0.0), (0.0, r), (float(h[0]), float(np.pi + h[1])), (int(acts[0]), int(acts[1])))


def play(game, agents, seconds: float, seed: int, target_distance: float):
    """One traced bout of two agents from :func:`start_state` (seeded); returns the BoutResult."""
    from igraph_fight.match import run_bout

    rng = np.random.default_rng(seed)
    init = start_state(game, target_distance, rng)
    return run_bout(game, agents, seconds, rng, trace=True, initial=init)


def measure(res, policy: CoopPolicy) -> dict:
    """A traced bout measured against ``policy``'s objective: :func:`progress`, the realized
    reward (:func:`realized_reward`) and hits."""
    out = progress(res.trace, policy.direction if policy.direction is not None else 0, policy.target_distance)
    out.update(realized_reward(res, policy))
    out["hits"] = float(res.hits.sum())
    return out


def run_pair(game, agents, seconds: float, seed: int, policy: CoopPolicy) -> tuple[dict, object]:
    """:func:`play` then :func:`measure`: returns (measures, BoutResult)."""
    res = play(game, agents, seconds, seed, policy.target_distance)
    return measure(res, policy), res
