"""'static' baseline (after Lee & Lee 2004): a boxer trained to approach and hit a target that
does not fight back. It has no notion of defence (nor of the opponent's attacks).

Training (dynamic programming, a few seconds): the target is a dummy frozen in the library's
guard pose (an extra, motionless action appended to the simulator tables, longer than any real
action, so every event ends when the boxer finishes its action). States are a grid over
(Next-set of the boxer's last action, distance r, own angle to the dummy theta_self); the dummy
faces the boxer. Every menu action is simulated once from every grid state with the exact
simulator; the reward is Eq. 4 of the style (default infighter) on the event's edge features,
the same formula as the IG fighter's, except that the dummy never hits back, so damage taken and
defence never appear. Value iteration with discount ``gamma`` over bilinear interpolation in
(r, theta) gives V.

Acting: the boxer simulates each legal action once against the dummy placed where the real
opponent stands (with its real facing) and takes the best W + gamma * V(landing). The real
opponent's action is ignored: the agent believes the target is static.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from motion_graph.classify import KINDS
from planner import edge_rewards

from igraph_fight import sim
from igraph_fight.build.edge_features import edge_features
from igraph_fight.sim import SimTables
from igraph_fight.state import to_sample
from igraph_fight.search import child_buffers, expand_children
from igraph_fight.agents.common import as_style
from planner.rewards import style_params


def dummy_tables(tables: SimTables) -> tuple[SimTables, int]:
    """The tables with one more action: a dummy standing still in a guard pose, longer than any
    action, with no strikes, no defence and an empty menu. Returns (tables, dummy action id)."""
    A = tables.n_actions
    guard = [a for a in range(A) if KINDS[int(tables.kinds[a])] == "guard"]
    g = guard[0] if guard else 0
    L = int(tables.n_frames.max()) + 2
    f0 = int(tables.frame_offsets[g])  # frame 0 of the guard: root at the origin facing +Z
    t = replace(
        tables,
        n_frames=np.append(tables.n_frames, L),
        frame_offsets=np.append(tables.frame_offsets, tables.frame_offsets[-1] + L),
        path=np.ascontiguousarray(np.concatenate([tables.path, np.zeros((L, 3))])),
        eff=np.ascontiguousarray(np.concatenate([tables.eff, np.repeat(tables.eff[f0:f0 + 1], L, axis=0)])),
        tgt=np.ascontiguousarray(np.concatenate([tables.tgt, np.repeat(tables.tgt[f0:f0 + 1], L, axis=0)])),
        arms=(None if tables.arms is None else
              np.ascontiguousarray(np.concatenate([tables.arms, np.repeat(tables.arms[f0:f0 + 1], L, axis=0)]))),
        strike_offsets=np.append(tables.strike_offsets, tables.strike_offsets[-1]),
        defence_w0=np.append(tables.defence_w0, -1),
        defence_w1=np.append(tables.defence_w1, -1),
        kinds=np.append(tables.kinds, tables.kinds[g]),
        next_offsets=np.append(tables.next_offsets, tables.next_offsets[-1]),
        nextset=np.append(tables.nextset, int(tables.nextset.max()) + 1),
    )
    return t, A


@dataclass(frozen=True)
class StaticConfig:
    """Grid and discount of the value iteration (metres, radians)."""

    r_min: float = 0.4
    r_max: float = 4.0
    r_step: float = 0.1
    n_theta: int = 36
    gamma: float = 0.9
    tol: float = 1e-6
    max_iter: int = 2000


@dataclass
class StaticPolicy:
    """V over (Next-set, r bin, theta bin) and how it was trained."""

    V: np.ndarray
    r_grid: np.ndarray
    n_theta: int
    gamma: float
    style: str
    train_s: float
    states: int
    events: int
    iterations: int

    def value(self, nextset: np.ndarray, r: np.ndarray, th: np.ndarray) -> np.ndarray:
        idx, w = _bilinear(self.r_grid, self.n_theta, np.asarray(r, dtype=np.float64), np.asarray(th, dtype=np.float64))
        n = np.asarray(nextset, dtype=np.int64)[:, None]
        return np.sum(w * self.V[n, idx // self.n_theta, idx % self.n_theta], axis=1)


def _bilinear(r_grid: np.ndarray, n_theta: int, r: np.ndarray, th: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Flat (r bin * n_theta + theta bin) indices (N, 4) and weights (N, 4) of bilinear
    interpolation; r clamped to the grid, theta periodic (bin t centred on -pi + t * 2pi/n)."""
    step = r_grid[1] - r_grid[0]
    x = np.clip((r - r_grid[0]) / step, 0.0, len(r_grid) - 1 - 1e-9)
    i0 = np.floor(x).astype(np.int64)
    fr = x - i0
    i1 = np.minimum(i0 + 1, len(r_grid) - 1)
    y = ((th + np.pi) % (2 * np.pi)) / (2 * np.pi / n_theta)
    j0 = np.floor(y).astype(np.int64) % n_theta
    ft = y - np.floor(y)
    j1 = (j0 + 1) % n_theta
    idx = np.stack([i0 * n_theta + j0, i0 * n_theta + j1, i1 * n_theta + j0, i1 * n_theta + j1], axis=1)
    w = np.stack([(1 - fr) * (1 - ft), (1 - fr) * ft, fr * (1 - ft), fr * ft], axis=1)
    return idx, w


def train_static(tables: SimTables, style="infighter", config: StaticConfig = StaticConfig()) -> StaticPolicy:
    """Value iteration against the frozen dummy (module docstring). Deterministic."""
    t0 = time.perf_counter()
    st = as_style(style)
    dt, dummy = dummy_tables(tables)
    T = dt.kernel_tuple()
    n_sets = int(tables.nextset.max()) + 1
    rep = np.array([int(np.nonzero(tables.nextset == n)[0][0]) for n in range(n_sets)], dtype=np.int64)
    r_grid = np.arange(config.r_min, config.r_max + 1e-9, config.r_step)
    th_grid = -np.pi + np.arange(config.n_theta) * (2 * np.pi / config.n_theta)
    nR, nT = len(r_grid), config.n_theta
    # one canonical sample per grid state: (Next-set, r, theta)
    n_i, r_i, t_i = np.meshgrid(np.arange(n_sets), np.arange(nR), np.arange(nT), indexing="ij")
    n_i, r_i, t_i = n_i.ravel(), r_i.ravel(), t_i.ravel()
    S = len(n_i)
    si = np.zeros((S, sim.N_SI), dtype=np.int64)
    si[:, sim.SI_MSELF] = rep[n_i]
    si[:, sim.SI_MOTHER] = dummy
    sf = np.stack([r_grid[r_i], th_grid[t_i], np.zeros(S)], axis=1)
    menu_len = np.diff(tables.next_offsets)[rep[n_i]]
    parent = np.repeat(np.arange(S), menu_len)
    start = np.repeat(tables.next_offsets[rep[n_i]], menu_len)
    action = tables.next_ids[start + (np.arange(len(parent)) - np.repeat(np.cumsum(menu_len) - menu_len, menu_len))]
    ci, cf, ft, _ = sim.expand_samples(T, si, sf, parent, action)
    feats = edge_features(dt, np.full(len(action), dummy), action, ft)
    W, _ = edge_rewards(feats, st, list(KINDS))
    idx, w = _bilinear(r_grid, nT, cf[:, sim.SF_R], cf[:, sim.SF_TH_SELF])
    nxt = tables.nextset[action]
    flat = (nxt[:, None] * (nR * nT) + idx)
    V = np.zeros(n_sets * nR * nT)
    seg = np.cumsum(menu_len) - menu_len
    it = 0
    for it in range(1, config.max_iter + 1):
        Q = W + config.gamma * np.sum(w * V[flat], axis=1)
        Vn = np.maximum.reduceat(Q, seg)
        delta = float(np.max(np.abs(Vn - V)))
        V = Vn
        if delta < config.tol:
            break
    return StaticPolicy(V.reshape(n_sets, nR, nT), r_grid, nT, config.gamma, st.name, time.perf_counter() - t0, S,
                        len(action), it)


_CACHE: dict = {}


def static_policy(tables: SimTables, style="infighter", config: StaticConfig = StaticConfig()) -> StaticPolicy:
    """train_static, memoised per (tables, style, config) in this process."""
    import hashlib
    import json
    st = as_style(style)
    h = hashlib.sha1()
    for a in (tables.n_frames, tables.path, tables.eff, tables.tgt, tables.next_ids, tables.strike_w0):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps(tables.params.to_json(), sort_keys=True).encode())
    key = (h.hexdigest(), hash(st), config)
    if key not in _CACHE:
        _CACHE[key] = train_static(tables, st, config)
    return _CACHE[key]


@njit(cache=True)
def _act(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, V, r0, r_step, n_r, n_t, gamma, max_menu):
    """Best menu index: one simulated event per action against the dummy, W + gamma * V(landing)
    with V bilinear in (r, theta) (the _bilinear rule)."""
    CI, CF, FT, SW, W, DUR, KIND, OKIND, ORD, S, act, frm, mask, stats = child_buffers(1, max_menu)
    count = np.zeros(2, dtype=np.int64)
    k = expand_children(T, nxt_off, nxt_ids, kinds, P, pref, fps, si, sf, True, 0, False, CI, CF, FT, SW, W, DUR, KIND,
                OKIND, ORD, S, act, frm, mask, stats, count)
    best = -1
    bq = -np.inf
    two_pi = 2.0 * np.pi
    for j in range(k):
        x = (CF[0, j, sim.SF_R] - r0) / r_step
        x = min(max(x, 0.0), n_r - 1 - 1e-9)
        i0 = int(np.floor(x))
        fr = x - i0
        i1 = min(i0 + 1, n_r - 1)
        y = ((CF[0, j, sim.SF_TH_SELF] + np.pi) % two_pi) / (two_pi / n_t)
        j0 = int(np.floor(y)) % n_t
        ft = y - np.floor(y)
        j1 = (j0 + 1) % n_t
        n = CI[0, j, sim.SI_MSELF]
        v = ((1 - fr) * (1 - ft) * V[n, i0, j0] + (1 - fr) * ft * V[n, i0, j1] + fr * (1 - ft) * V[n, i1, j0]
             + fr * ft * V[n, i1, j1])
        q = W[0, j] + gamma * v
        if q > bq:
            bq = q
            best = j
    return best


class StaticAgent:
    """Approach-and-hit boxer trained against a static target (module docstring)."""

    def __init__(self, style="infighter", config: StaticConfig = StaticConfig(), name: str = "static",
                 policy: StaticPolicy | None = None) -> None:
        self.name = name
        self.style = as_style(style)
        self.config = config
        self.policy = policy
        self._tables = None
        self.decisions = 0
        self.decision_s = 0.0

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        self._prepare(game.tables)

    def _prepare(self, tables: SimTables) -> None:
        if self._tables is tables:
            return
        if self.policy is None:
            self.policy = static_policy(tables, self.style, self.config)
        from planner.rewards import kind_preferences
        self._tables = tables
        self._dt, self._dummy = dummy_tables(tables)
        self._T = self._dt.kernel_tuple()
        self._args = (np.asarray(self._dt.next_offsets, dtype=np.int64), np.asarray(self._dt.next_ids, dtype=np.int64),
                      np.asarray(self._dt.kinds, dtype=np.int32), style_params(self.style),
                      kind_preferences(self.style, list(KINDS)), float(tables.fps))
        # V indexed by the landing action's Next-set: V_by_action[a] = V[nextset[a]]
        pol = self.policy
        self._V = np.ascontiguousarray(pol.V[np.asarray(tables.nextset)])
        self._grid = (float(pol.r_grid[0]), float(pol.r_grid[1] - pol.r_grid[0]), len(pol.r_grid), pol.n_theta,
                      float(pol.gamma), int(np.diff(tables.next_offsets).max()))

    def step(self, state, player: int) -> int:
        t = time.perf_counter()
        tables = state.game.tables
        self._prepare(tables)
        si, sf = to_sample(tables, state.world, player)
        si = si.copy()
        si[sim.SI_MOTHER], si[sim.SI_FOTHER], si[sim.SI_MASK] = self._dummy, 0, 0  # the target stands still
        acts = tables.menu(int(si[sim.SI_MSELF]))
        j = _act(self._T, *self._args, si, np.ascontiguousarray(sf, dtype=np.float64), self._V, *self._grid)
        a = int(acts[max(j, 0)])
        self.decision_s += time.perf_counter() - t
        self.decisions += 1
        return a
