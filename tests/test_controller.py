"""NPCController on a real (small) Interaction Graph of the CMU boxing library."""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from igraph_fight.controller import NPCController, Observation
from igraph_fight.locate import nextset_ids
from planner import roulette_probabilities


@pytest.fixture(scope="module")
def graph_lib(small_graph):
    return small_graph


@pytest.fixture(scope="module")
def ctrl(graph_lib):
    g, lib = graph_lib
    c = NPCController(g, lib, style="balanced", depth=3)
    yield c
    c.close()


@pytest.fixture(scope="module")
def nearest(graph_lib):
    g, lib = graph_lib
    c = NPCController(g, lib, style="balanced", depth=3, offgraph="nearest")
    yield c
    c.close()


def _state_obs(a, s) -> Observation:
    return Observation(float(a["state_r"][s]), float(a["state_theta_self"][s]), float(a["state_theta_other"][s]),
                       int(a["state_m_self"][s]), int(a["state_m_other"][s]), int(a["state_f_other"][s]),
                       int(a["state_mask_other"][s]))


def _observations(graph, lib, n=600, seed=0) -> list[Observation]:
    """Graph states, perturbed graph states, states with another frame / menu / opponent action,
    and random live states (r up to 5 m, any angles)."""
    a = graph.arrays
    rng = np.random.default_rng(seed)
    S, A = graph.n_states, lib.n_actions
    out = []
    for i in range(n):
        s = int(rng.integers(S))
        o = _state_obs(a, s)
        kind = i % 5
        if kind == 1:
            o = o._replace(r=o.r + rng.normal(0, 0.08), theta_self=o.theta_self + rng.normal(0, 0.2),
                           theta_other=o.theta_other + rng.normal(0, 0.2))
        elif kind == 2:
            o = o._replace(f_other=max(0, o.f_other + int(rng.integers(-25, 26))), r=o.r + rng.normal(0, 0.3))
        elif kind == 3:
            o = o._replace(m_self=int(rng.integers(A)), m_other=int(rng.integers(A)),
                           mask_other=int(rng.integers(0, 3)))
        elif kind == 4:
            o = Observation(float(rng.uniform(0.3, 5.0)), float(rng.uniform(-np.pi, np.pi)),
                            float(rng.uniform(-np.pi, np.pi)), int(rng.integers(A)), int(rng.integers(A)),
                            int(rng.integers(0, 70)), 0)
        out.append(o)
    return out


def _wrap(x):
    return x - 2.0 * np.pi * np.floor((x + np.pi) / (2.0 * np.pi))


def _brute_nearest(c: NPCController, o: Observation) -> tuple[int, float, int]:
    """The documented search by brute force: compatible group (same Next-set, M_other, mask and
    |F_other difference| < F0), then the same key at any frame, the same Next-set, anywhere;
    ties to the smallest state id (anywhere: the first in key order)."""
    a = c.graph.arrays
    ns = nextset_ids(c.library)[o.m_self]
    d = ((a["state_r"] - o.r) ** 2 * c._inv_sr2
         + (_wrap(a["state_theta_self"] - o.theta_self) ** 2 + _wrap(a["state_theta_other"] - o.theta_other) ** 2)
         * c._inv_st2)
    key = (a["state_nextset"] == ns) & (a["state_m_other"] == o.m_other) & (a["state_mask_other"] == o.mask_other)
    levels = [key & (np.abs(a["state_f_other"].astype(np.int64) - o.f_other) < c.f0), key, a["state_nextset"] == ns]
    for lv, sel in enumerate(levels):
        if sel.any():
            idx = np.nonzero(sel)[0]
            return int(idx[np.argmin(d[idx])]), float(d[idx].min()), lv
    A = c.library.n_actions
    mm = int(a["state_mask_other"].max()) + 2
    k = (a["state_nextset"].astype(np.int64) * (A + 1) + a["state_m_other"]) * mm + a["state_mask_other"]
    order = np.argsort(k, kind="stable")
    j = int(np.argmin(d[order]))
    return int(order[j]), float(d[order[j]]), 3


def test_nearest_state_is_the_exact_minimum_at_every_level(ctrl, graph_lib):
    g, lib = graph_lib
    levels = np.zeros(4, int)
    for o in _observations(g, lib, 500, seed=1):
        s, dist, _ = ctrl.locate(o)
        bs, bd, lv = _brute_nearest(ctrl, o)
        levels[lv] += 1
        assert s == bs, (o, s, bs, dist, np.sqrt(bd), lv)
        assert dist == pytest.approx(np.sqrt(bd), abs=1e-12)
    assert levels[0] > 100 and levels[1] + levels[2] > 20  # the fallbacks were exercised


def test_act_returns_legal_actions(ctrl, nearest, graph_lib):
    g, lib = graph_lib
    obs = _observations(g, lib, 400)
    for c in (ctrl, nearest):
        for o in obs:
            d = c.act(o)
            assert d.action in lib.next(o.m_self), (o, d)
            if d.edge >= 0:
                assert g.arrays["edge_action"][d.edge] == d.action
    # a graph state's answer is its policy's best edge (when legal, as it is for its own menu)
    a = g.arrays
    pol = ctrl.policy
    for s in range(0, g.n_states, max(1, g.n_states // 200)):
        d = ctrl.act(_state_obs(a, s))
        if pol.best_me[s] >= 0:
            assert d.state == s and d.edge == pol.best_me[s] and not d.off_graph


def test_act_batch_equals_act(ctrl, nearest, graph_lib):
    g, lib = graph_lib
    obs = _observations(g, lib, 500, seed=2)
    cols = [np.array([getattr(o, f) for o in obs]) for f in Observation._fields]
    # table answers (offgraph="nearest"): act and act_batch agree everywhere
    acts, states, off = nearest.act_batch(*cols)
    ref = [nearest.act(o) for o in obs]
    assert [int(x) for x in acts] == [d.action for d in ref]
    assert [int(x) for x in states] == [d.state for d in ref]
    assert [bool(x) for x in off] == [d.off_graph for d in ref]
    # with the off-graph lookahead: act_batch(lookahead=True) == act everywhere ...
    acts_la, states_la, off_la = ctrl.act_batch(*cols, lookahead=True)
    ref_la = [ctrl.act(o) for o in obs]
    assert [int(x) for x in acts_la] == [d.action for d in ref_la]
    assert [bool(x) for x in off_la] == [d.off_graph for d in ref_la]
    assert 0.1 < off_la.mean() < 0.95
    # ... and the table answers agree with act on the graph
    acts_t, _, off_t = ctrl.act_batch(*cols)
    on = ~off_t
    assert np.array_equal(acts_t[on], acts_la[on])
    # large batches run in parallel: same answers
    big = [np.tile(x, 10) for x in cols]
    acts_big, states_big, _ = nearest.act_batch(*big)
    assert np.array_equal(acts_big, np.tile(acts, 10)) and np.array_equal(states_big, np.tile(states, 10))


def test_off_graph_flag(ctrl, graph_lib):
    g, lib = graph_lib
    a = g.arrays
    rng = np.random.default_rng(3)
    for s in rng.integers(0, g.n_states, 100):
        o = _state_obs(a, int(s))
        d = ctrl.act(o)
        assert not d.off_graph and d.state == s and d.distance == 0.0
        far = o._replace(r=o.r + 2.5)
        d = ctrl.act(far)
        assert d.off_graph and d.distance > 1.0 and d.edge == -1  # answered by the lookahead
        assert d.action in lib.next(o.m_self)
    # in general: off the graph iff the nearest state is not in the compatible group or lies
    # beyond the graph's tolerance in r, theta_self or theta_other
    for o in _observations(g, lib, 300, seed=5):
        d = ctrl.act(o)
        bs, _, lv = _brute_nearest(ctrl, o)
        beyond = (abs(a["state_r"][bs] - o.r) > ctrl.tol_r
                  or abs(_wrap(a["state_theta_self"][bs] - o.theta_self)) > ctrl.tol_theta
                  or abs(_wrap(a["state_theta_other"][bs] - o.theta_other)) > ctrl.tol_theta)
        assert d.off_graph == (lv > 0 or beyond), (o, d, lv)


def test_set_style_swaps_atomically_under_a_reader(graph_lib):
    g, lib = graph_lib
    obs = _observations(g, lib, 300, seed=4)
    old = NPCController(g, lib, style="outboxer", depth=5, offgraph="nearest")
    new = NPCController(g, lib, style="infighter", depth=5, offgraph="nearest")
    ans_old = [old.act(o).action for o in obs]
    ans_new = [new.act(o).action for o in obs]
    differ = [i for i in range(len(obs)) if ans_old[i] != ans_new[i]]
    assert len(differ) > 10
    new.close()
    c = old  # swapped from outboxer to infighter under the reader
    reads: list[tuple[float, int, int]] = []
    errors: list[BaseException] = []
    stop = threading.Event()

    def reader():
        k = 0
        try:
            while not stop.is_set():
                i = differ[k % len(differ)]
                t = time.perf_counter()
                reads.append((t, i, c.act(obs[i]).action))
                k += 1
        except BaseException as e:  # noqa: BLE001
            errors.append(e)

    th = threading.Thread(target=reader)
    th.start()
    time.sleep(0.05)
    t_request = time.perf_counter()
    fut = c.set_style("infighter")
    while not fut.done():
        time.sleep(0.0005)
    t_live = time.perf_counter()
    time.sleep(0.05)
    stop.set()
    th.join()
    assert not errors
    assert c.style == "infighter" and fut.result().style == "infighter" and c.last_swap_ms > 0
    kinds = []
    for t, i, a in reads:
        assert a in (ans_old[i], ans_new[i])
        kinds.append("old" if a == ans_old[i] else "new")
        if t < t_request:
            assert kinds[-1] == "old"
        if t > t_live:
            assert kinds[-1] == "new"
    # one switch: old answers until the new policy is live, then new ones only
    first_new = kinds.index("new")
    assert "new" not in kinds[:first_new] and "old" not in kinds[first_new:]
    c.close()


def test_set_depth_changes_the_policy(graph_lib):
    g, lib = graph_lib
    c = NPCController(g, lib, style="balanced", depth=1, offgraph="nearest")
    obs = [_state_obs(g.arrays, s) for s in range(0, g.n_states, 7)]
    a1 = [c.act(o).action for o in obs]
    best1 = c.policy.best_me.copy()
    c.set_depth(5, wait=True)
    assert c.depth == 5 and c.policy.depth == 5 and c.style == "balanced"
    a5 = [c.act(o).action for o in obs]
    assert not np.array_equal(best1, c.policy.best_me)
    assert sum(x != y for x, y in zip(a1, a5)) > 0.05 * len(obs)
    c.close()


def test_roulette_is_reproducible_and_follows_the_scores(graph_lib):
    g, lib = graph_lib
    a = g.arrays
    off = a["state_offsets"]
    # a graph state with several legal edges whose scores are spread out
    base = NPCController(g, lib, style="balanced", depth=3, offgraph="nearest")
    pick = None
    for s in range(g.n_states):
        lo, hi = int(off[s]), int(off[s + 1])
        q = base._table.q_me[lo:hi].astype(np.float64)
        if hi - lo >= 4 and 0.3 < np.ptp(q) < 3.0:
            pick = s
            break
    assert pick is not None
    base.close()
    s = pick
    o = _state_obs(a, s)
    lo, hi = int(off[s]), int(off[s + 1])
    T = 0.5

    def draws(seed, n, peek=False):
        c = NPCController(g, lib, style="balanced", depth=3, offgraph="nearest", stochastic=True, temperature=T,
                          seed=seed, usage_penalty=0.5 if peek else 0.0)
        out = []
        for _ in range(n):
            if peek:   # peek: the best edge's action, no draw taken, no usage counted
                assert c.peek(o) == int(c._edge_action[lo + int(np.argmax(c._table.q_me[lo:hi]))])
                assert not c._usage
            out.append(c.act(o).edge)
            if peek:
                c._usage.clear()
        q = c._table.q_me[lo:hi].astype(np.float64)
        c.close()
        return np.array(out), q

    e1, q = draws(7, 3000)
    e2, _ = draws(7, 3000, peek=True)
    e3, _ = draws(8, 3000)
    assert np.array_equal(e1, e2) and not np.array_equal(e1, e3)
    assert np.all((e1 >= lo) & (e1 < hi))
    p = roulette_probabilities(q, T)
    freq = np.bincount(e1 - lo, minlength=hi - lo) / len(e1)
    np.testing.assert_allclose(freq, p, atol=0.035)
    # more often the better the score
    top, low = int(np.argmax(q)), int(np.argmin(q))
    assert freq[top] > freq[low]


def test_parallel_and_serial_batch_kernels_have_distinct_cache_entries():
    """numba's disk cache is keyed by qualified name and line, not by compile flags: the parallel
    and serial batch kernels must be distinct functions or one silently serves both."""
    from igraph_fight import controller as C
    names = {C._act_batch.py_func.__qualname__, C._act_batch_serial.py_func.__qualname__}
    assert len(names) == 2
    assert C._act_batch.targetoptions.get("parallel") and not C._act_batch_serial.targetoptions.get("parallel")


def _exact2_reference(c: NPCController, o: Observation) -> np.ndarray:
    """Q of every menu action under first_ply="exact2", in Python from the simulator and Eq. 4:
    W(a) + gamma * opt_b [W(b) + gamma * V(nearest state of the landing sample)]."""
    from motion_graph.classify import KINDS
    from planner import edge_rewards

    from igraph_fight import sim
    from igraph_fight.build.edge_features import edge_features
    t = c._table
    style, g = t.style_obj, float(t.policy.gamma)

    def children(si, sf):
        acts = c.tables.menu(int(si[sim.SI_MSELF])).astype(np.int64)
        ci, cf, ft, sw = sim.expand_samples(c.kernel_tables, si[None], sf[None], np.zeros(len(acts), np.int64), acts)
        w_me, w_opp = edge_rewards(edge_features(c.tables, np.full(len(acts), si[sim.SI_MOTHER]), acts, ft), style,
                                   list(KINDS))
        return acts, ci, cf, sw, w_me, w_opp

    si = np.array([o.m_self, o.m_other, o.f_other, o.mask_other], dtype=np.int64)
    sf = np.array([o.r, o.theta_self, o.theta_other], dtype=np.float64)
    acts, ci, cf, sw, w_me, _ = children(si, sf)
    q = np.array(w_me, dtype=np.float64)
    for k in range(len(acts)):
        me = sw[k] == 0
        a2, c2i, c2f, sw2, w2me, w2opp = children(ci[k], cf[k])
        if not len(a2):
            continue
        vals = []
        for j in range(len(a2)):
            s, _, _ = c.locate(Observation(c2f[j, 0], c2f[j, 1], c2f[j, 2], int(c2i[j, 0]), int(c2i[j, 1]),
                                           int(c2i[j, 2]), int(c2i[j, 3])))
            leaf_me = me == (sw2[j] == 0)
            v = float(t.la[0][s] if leaf_me else t.la[1][s]) if s >= 0 else 0.0
            vals.append((w2me[j] if me else w2opp[j]) + g * v)
        q[k] += g * (max(vals) if me else min(vals))
    return acts, q


def test_exact2_searches_two_exact_plies_over_the_graph_values(graph_lib):
    g, lib = graph_lib
    c = NPCController(g, lib, style="infighter", depth=3, first_ply="exact2")
    obs = [o for i, o in enumerate(_observations(g, lib, n=60, seed=5)) if i % 5 in (0, 1)]
    for o in obs:
        acts, q = _exact2_reference(c, o)
        a, qa = c._exact2(c._table, o)
        assert a in set(int(x) for x in acts) and c.act(o).action == a
        assert qa == pytest.approx(q.max(), abs=1e-6)   # the kernel's best is a best of the reference
        assert q[list(acts).index(a)] == pytest.approx(q.max(), abs=1e-6)
    with pytest.raises(ValueError, match="first_ply"):
        NPCController(g, lib, first_ply="exact3")
    c.close()
