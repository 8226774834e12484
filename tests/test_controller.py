"""NPCController on a real (small) Interaction Graph of the CMU boxing library."""
from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import pytest

from igraph_fight.controller import NPCController, Observation
from igraph_fight.locate import GRID_PER_UNIT, nextset_ids, on_grid
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
    and random live states (r up to 5 m, any angles); all within the controller's input contract
    (frames of the opponent's action, bits of its strikes)."""
    a = graph.arrays
    rng = np.random.default_rng(seed)
    S, A = graph.n_states, lib.n_actions
    nf = np.diff(lib.frame_offsets)
    bits = np.diff(lib.strike_offsets)
    out = []
    for i in range(n):
        s = int(rng.integers(S))
        o = _state_obs(a, s)
        kind = i % 5
        if kind == 1:
            o = o._replace(r=o.r + rng.normal(0, 0.08), theta_self=o.theta_self + rng.normal(0, 0.2),
                           theta_other=o.theta_other + rng.normal(0, 0.2))
        elif kind == 2:
            o = o._replace(f_other=max(0, o.f_other + int(rng.integers(-25, 26))), r=abs(o.r + rng.normal(0, 0.3)))
        elif kind == 3:
            o = o._replace(m_self=int(rng.integers(A)), m_other=int(rng.integers(A)),
                           mask_other=int(rng.integers(0, 3)))
        elif kind == 4:
            o = Observation(float(rng.uniform(0.3, 5.0)), float(rng.uniform(-np.pi, np.pi)),
                            float(rng.uniform(-np.pi, np.pi)), int(rng.integers(A)), int(rng.integers(A)),
                            int(rng.integers(0, 70)), 0)
        o = o._replace(f_other=min(o.f_other, int(nf[o.m_other]) - 1),
                       mask_other=o.mask_other & ((1 << int(bits[o.m_other])) - 1))
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
    r, ts, to = on_grid(a["state_r"]), on_grid(a["state_theta_self"]), on_grid(a["state_theta_other"])
    d = ((r - on_grid(o.r)) ** 2 * c._inv_sr2
         + (_wrap(ts - on_grid(o.theta_self)) ** 2 + _wrap(to - on_grid(o.theta_other)) ** 2) * c._inv_st2)
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


def test_lookup_compares_on_the_grid(ctrl, graph_lib):
    """Queries within half a grid step of the same grid point get the same state and the same
    distance, bit for bit (the NPC export relies on it); a full step apart, the distance moves."""
    g, lib = graph_lib
    h = 0.49 / GRID_PER_UNIT
    for o in _observations(g, lib, 100, seed=7):
        o = o._replace(r=float(on_grid(o.r + 0.3)), theta_self=float(on_grid(o.theta_self)),
                       theta_other=float(on_grid(o.theta_other)))
        ref = ctrl.locate(o)
        for dr, dts, dto in ((h, 0, 0), (-h, h, -h), (0, -h, h)):
            assert ctrl.locate(o._replace(r=o.r + dr, theta_self=o.theta_self + dts,
                                          theta_other=o.theta_other + dto)) == ref
        moved = ctrl.locate(o._replace(r=o.r + 1.0 / GRID_PER_UNIT))
        assert moved[0] != ref[0] or moved[1] != ref[1]


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
        g_r, g_ts, g_to = (on_grid(x) for x in (o.r, o.theta_self, o.theta_other))
        beyond = (abs(on_grid(a["state_r"][bs]) - g_r) > ctrl.tol_r
                  or abs(_wrap(on_grid(a["state_theta_self"][bs]) - g_ts)) > ctrl.tol_theta
                  or abs(_wrap(on_grid(a["state_theta_other"][bs]) - g_to)) > ctrl.tol_theta)
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


# ----- the input contract ---------------------------------------------------------------------------
#: the fields of an Observation, in order
FIELDS = Observation._fields


def invalid_cases(n_frames, n_strikes, seed: int = 0, n_scalar: int = 420, n_batch: int = 120) -> list[tuple]:
    """Observations and batches outside the controller's input contract, from a fixed-seed
    generator: (entry point, first_ply, payload, field the error must name, row or None).
    Scalar payloads are 7-tuples (one field corrupted: ids out of range, non-finite or negative
    numbers, wrong types); batch payloads are 7 lists/arrays (one row corrupted, mismatched
    lengths, 2-d arrays, non-integer ids, object arrays). Entry points: act, peek, locate,
    menu_terms (scalar), act_batch and act_batch+lookahead (batch)."""
    rng = np.random.default_rng(seed)
    nf = [int(x) for x in n_frames]
    A = len(nf)
    lim = [1 << int(k) for k in n_strikes]
    big = [2 ** 31, 2 ** 32, 2 ** 40, 2 ** 62, 2 ** 63 - 1, -2 ** 31, -2 ** 63]

    def valid(r=None):
        mo = int(rng.integers(A))
        return [float(rng.uniform(0.2, 4.0)) if r is None else r, float(rng.uniform(-np.pi, np.pi)),
                float(rng.uniform(-np.pi, np.pi)), int(rng.integers(A)), mo, int(rng.integers(nf[mo])),
                int(rng.integers(lim[mo]))]

    def bad_value(field: str, o: list):
        k = int(rng.integers(8))
        if field in ("m_self", "m_other"):
            return [-1, A, A + 1, A + int(rng.integers(1, 1000)), *big][int(rng.integers(4 + len(big)))] if k < 6 \
                else [3.0, "3", None, True, 2.5 + 0j][int(rng.integers(5))]
        if field == "f_other":
            n = nf[o[4]]
            return [-1, n, n + 1, n + int(rng.integers(1, 100)), *big][int(rng.integers(4 + len(big)))] if k < 6 \
                else [1.0, "1", None, False][int(rng.integers(4))]
        if field == "mask_other":
            m = lim[o[4]]
            return [-1, m, m + 1, 2 ** 40, 2 ** 63 - 1, -2 ** 63][int(rng.integers(6))] if k < 6 else \
                [0.0, "0", None][int(rng.integers(3))]
        if field == "r":
            return [np.nan, np.inf, -np.inf, -0.1, -1e-9, -1e300, 1e300, 1e7, "1.0", None, 1j, 10 ** 400][
                int(rng.integers(12))]
        return [np.nan, np.inf, -np.inf, 1e300, -1e300, 1e7, "0.1", None, [0.1]][int(rng.integers(9))]

    cases = []
    entries = ("act", "act", "act", "peek", "locate", "menu_terms")
    plies = ("table", "exact", "exact2")
    for i in range(n_scalar):
        o = valid()
        field = FIELDS[i % 7]
        o[i % 7] = bad_value(field, o)
        cases.append((entries[int(rng.integers(len(entries)))], plies[(i // 7) % 3], tuple(o), field, None))
    for i in range(n_batch):
        n = int(rng.integers(1, 40))
        rows = [valid() for _ in range(n)]
        cols = [np.array([rw[k] for rw in rows]) for k in range(7)]
        entry = ("act_batch", "act_batch+lookahead")[i % 2]
        kind = i % 6
        k = int(rng.integers(7))
        field, row = FIELDS[k], None
        if kind in (0, 1, 2):         # one bad row: a number out of range, NaN or infinite
            row = int(rng.integers(n))
            v = bad_value(field, rows[row])
            fits = ((lambda x: type(x) is float or (type(x) is int and abs(x) < 1e300)) if k < 3
                    else (lambda x: type(x) is int and -2 ** 63 <= x < 2 ** 63))
            while not fits(v):
                v = bad_value(field, rows[row])
            cols[k][row] = v
        elif kind == 3:               # mismatched lengths
            k = max(k, 1)
            field = FIELDS[k]
            cols[k] = np.concatenate([cols[k], cols[k][:1]]) if rng.random() < 0.5 or n == 1 else cols[k][:-1]
        elif kind == 4:               # 2-d
            cols[k] = np.stack([cols[k], cols[k]], axis=1)
        else:                         # wrong dtype: float ids, object or string arrays, bools
            if k >= 3:
                cols[k] = cols[k].astype(np.float64) + (0.5 if rng.random() < 0.5 else 0.0)
            else:
                cols[k] = cols[k].astype(str) if rng.random() < 0.5 else np.array([None] * n, dtype=object)
        cases.append((entry, "table", cols, field, row))
    return cases


def run_case(ctrls: dict, case: tuple):
    """Run one invalid case on ``ctrls`` (first_ply -> NPCController); returns what came back."""
    entry, ply, payload, _, _ = case
    c = ctrls[ply]
    if entry.startswith("act_batch"):
        return c.act_batch(*payload, lookahead=entry.endswith("lookahead"))
    obs = Observation(*payload)
    return getattr(c, entry)(obs)


@pytest.fixture(scope="module")
def contract_ctrls(graph_lib):
    g, lib = graph_lib
    cs = {p: NPCController(g, lib, style="balanced", depth=2, first_ply=p) for p in ("table", "exact", "exact2")}
    yield cs
    for c in cs.values():
        c.close()


def test_every_invalid_observation_raises_an_observation_error(contract_ctrls, graph_lib):
    """Acceptance: 540 invalid observations and batches (fixed seed), every entry point: each
    raises ObservationError naming the corrupted field (and row), none crashes or answers. On the
    code before the contract (demo graph), 60 of these 540 cases killed the process, 386 answered
    an action and 94 raised assorted errors (``python tests/test_controller.py --old-code DIR``
    replays them on another source tree, restarting after each crash)."""
    from igraph_fight.controller import ObservationError
    _, lib = graph_lib
    cases = invalid_cases(np.diff(lib.frame_offsets), np.diff(lib.strike_offsets))
    assert len(cases) >= 500
    raised = 0
    for case in cases:
        with pytest.raises(ObservationError) as e:
            run_case(contract_ctrls, case)
        assert e.value.field == case[3], (case, e.value)
        if case[4] is not None:
            assert e.value.row == case[4], (case, e.value)
        assert str(e.value).startswith(f"observation {case[3]}") and "\n" not in str(e.value)
        raised += 1
    assert raised == len(cases)
    # the controllers still answer valid observations afterwards
    o = Observation(1.2, 0.1, -0.2, 0, 0, 0, 0)
    assert all(int(c.act(o).action) in set(int(x) for x in lib.next(0)) for c in contract_ctrls.values())


def test_observation_checks_accept_numpy_scalars_and_keep_answers(contract_ctrls, graph_lib):
    """numpy scalars are valid field values (converted exactly); boundary values are accepted."""
    g, lib = graph_lib
    c = contract_ctrls["table"]
    obs = _observations(g, lib, 50, seed=9)
    for o in obs:
        n = Observation(np.float64(o.r), np.float32(o.theta_self).item(), np.float64(o.theta_other), np.int64(o.m_self),
                        np.int32(o.m_other), np.int64(o.f_other), np.int64(o.mask_other))
        assert c.act(n) == c.act(o._replace(theta_self=float(np.float32(o.theta_self))))
    nf = np.diff(lib.frame_offsets)
    edge = Observation(0.0, -np.pi, np.pi, lib.n_actions - 1, 0, int(nf[0]) - 1, 0)
    c.act(edge)
    c.act(edge._replace(r=1e6, theta_self=1e6, theta_other=-1e6))


def test_set_style_and_set_depth_interleaved_lose_no_update(graph_lib):
    """Interleaved requests end with the last requested style and the last requested depth,
    whatever order the worker finishes them in; every future's table holds its request."""
    g, lib = graph_lib
    c = NPCController(g, lib, style="balanced", depth=1, offgraph="nearest")
    futs = [c.set_style("outboxer"), c.set_depth(3), c.set_style("infighter"), c.set_depth(2)]
    futs[-1].result()
    assert (c.style, c.depth) == ("infighter", 2)
    assert futs[0].result().style in ("outboxer", "infighter") and futs[1].result().depth in (3, 2)
    c.set_depth(4)
    c.set_style("outboxer", wait=True)
    assert (c.style, c.depth) == ("outboxer", 4)
    ref = NPCController(g, lib, style="outboxer", depth=4, offgraph="nearest")
    assert np.array_equal(c.policy.best_me, ref.policy.best_me)
    # a gamma given at construction survives the swaps
    cg = NPCController(g, lib, style="balanced", depth=2, gamma=0.8, offgraph="nearest")
    cg.set_style("infighter", wait=True)
    assert cg.policy.gamma == pytest.approx(0.8)
    for x in (c, ref, cg):
        x.close()


def test_depth_and_gamma_are_bounded(graph_lib):
    from igraph_fight.controller import MAX_DEPTH
    g, lib = graph_lib
    c = NPCController(g, lib, style="balanced", depth=1, offgraph="nearest")
    for bad in (0, -2, MAX_DEPTH + 1, 10 ** 6, 2.0, True, "3", None):
        with pytest.raises(ValueError, match="depth must be an integer"):
            c.set_depth(bad)
        with pytest.raises(ValueError, match="depth must be an integer"):
            NPCController(g, lib, depth=bad)
    for bad in (np.nan, np.inf, 0.0, -1.0, 5.0, 1.0000001, "0.5", True):
        with pytest.raises(ValueError, match="gamma must be a finite number"):
            NPCController(g, lib, depth=1, gamma=bad)
    assert c.depth == 1
    c.close()


def _replay_on_old_code(src: str, graph: str, out: str | None) -> dict:
    """Each invalid case on the controller of another source tree, in subprocesses (one restart
    per crash): counts of crashes (killed by a signal), exceptions and silent answers."""
    import json
    import subprocess
    import sys

    code = r'''
import sys, json, numpy as np
sys.path.insert(0, sys.argv[1]); sys.path.insert(1, sys.argv[4])
from test_controller import invalid_cases, run_case
from igraph_fight.controller import NPCController
from igraph_fight.graph import load_graph
g = load_graph(sys.argv[2]); lib = g.load_library()
cs = {p: NPCController(g, lib, style="balanced", depth=2, first_ply=p) for p in ("table", "exact", "exact2")}
cases = invalid_cases(np.diff(lib.frame_offsets), np.diff(lib.strike_offsets))
for i in range(int(sys.argv[3]), len(cases)):
    print(f"start {i}", flush=True)
    try:
        run_case(cs, cases[i]); print(f"done {i} answered", flush=True)
    except Exception as e:
        print(f"done {i} raised {type(e).__name__}", flush=True)
print("end", len(cases), flush=True)
'''
    here = str(Path(__file__).resolve().parent)
    start, outcome = 0, {}
    while True:
        try:
            p = subprocess.run([sys.executable, "-c", code, src, graph, str(start), here], capture_output=True,
                               text=True, timeout=600)
            stdout, rc, err = p.stdout, p.returncode, p.stderr
        except subprocess.TimeoutExpired as e:
            stdout, rc, err = (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or ""), None, ""
        last, total = None, None
        for line in stdout.splitlines():
            w = line.split()
            if w[0] == "start":
                last = int(w[1])
            elif w[0] == "done":
                outcome[int(w[1])] = " ".join(w[2:])
                last = None
            elif w[0] == "end":
                total = int(w[1])
        if total is not None:
            break
        if last is None:
            raise RuntimeError(err[-2000:])
        outcome[last] = ("hung (killed after 600 s)" if rc is None else f"crashed (signal {-rc})" if rc < 0
                         else f"exit {rc}")
        start = last + 1
    counts: dict = {}
    for v in outcome.values():
        key = v.split(" (")[0] if v.startswith("crashed") else v
        counts[key] = counts.get(key, 0) + 1
    res = {"cases": total, "counts": counts, "crashed": sorted(k for k, v in outcome.items() if v.startswith("crashed"))}
    if out:
        Path(out).write_text(json.dumps(res, indent=1))
    return res


if __name__ == "__main__":
    import argparse
    import json
    from pathlib import Path

    ap = argparse.ArgumentParser(description="replay the invalid-observation cases on another source tree")
    ap.add_argument("--old-code", required=True, help="source tree whose igraph_fight is tested (e.g. a copy of HEAD)")
    ap.add_argument("--graph", default="/tmp/base/demo/graph.igz")
    ap.add_argument("--out", default=None)
    a = ap.parse_args()
    print(json.dumps(_replay_on_old_code(a.old_code, a.graph, a.out), indent=1))


def test_masks_beyond_the_graphs_never_alias_another_opponent_action(ctrl, graph_lib):
    """The lookup key (Next-set, M_other, mask) keeps every valid mask (< 2 ** strikes of M_other)
    apart: an observation whose mask no graph state holds is never answered, on the graph, from a
    state of another opponent action (with a key stride of max graph mask + 2 it was, for masks
    at or above that stride)."""
    g, lib = graph_lib
    a = g.arrays
    stride = int(a["state_mask_other"].max()) + 2
    lim = 1 << np.diff(lib.strike_offsets)
    nf = np.diff(lib.frame_offsets)
    tried = 0
    for s in range(g.n_states):
        for j in (1, 2, 3):        # (M_other - j, mask + j * stride) had the key of (M_other, mask)
            mo = int(a["state_m_other"][s]) - j
            k = int(a["state_mask_other"][s]) + j * stride
            if mo < 0 or k >= lim[mo]:
                continue
            o = _state_obs(a, s)._replace(m_other=mo, f_other=min(int(a["state_f_other"][s]), int(nf[mo]) - 1),
                                          mask_other=k)
            st, _, off = ctrl.locate(o)
            assert off or int(a["state_m_other"][st]) == mo, (s, o, st)
            tried += 1
    assert tried >= 20, tried
