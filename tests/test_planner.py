"""planner: min-max and DP against brute force, roulette frequencies, style files, style rewards."""
from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import pytest

import planner
from planner import (
    ATTACK_KINDS, SearchGraph, Style, StyleError, compute_policy, cooperative_rewards, edge_rewards, load_style,
    minmax, roulette_probabilities, roulette_select, save_style, select_edge, synthetic_graph, value_iteration,
    value_iteration_pair)

#: Tolerance for float32 values (rewards of order 1, depth <= 5).
TOL = 2e-5

#: The kinds table of motion_graph.classify.KINDS (mirrored; test_attack_kinds_mirror checks it).
KINDS = ATTACK_KINDS + ("duck", "dodge", "step_forward", "step_back", "step_left", "step_right",
                        "turn_left", "turn_right", "guard")


def small_graph(seed: int, S: int = 12, max_deg: int = 3, dead: float = 0.15):
    """Random graph with dead ends and swaps; contract arrays + two random reward arrays."""
    rng = np.random.default_rng(seed)
    deg = rng.integers(1, max_deg + 1, S)
    deg[rng.random(S) < dead] = 0
    off = np.zeros(S + 1, dtype=np.int64)
    np.cumsum(deg, out=off[1:])
    E = int(off[-1])
    tgt = rng.integers(0, S, E).astype(np.int32)
    swap = (rng.random(E) < 0.5).astype(np.uint8)
    W_me = rng.normal(size=E)
    W_opp = rng.normal(size=E)
    return off, tgt, swap, W_me, W_opp


def brute_minmax(off, tgt, swap, W_me, W_opp, s, d, side, gamma, dead=0.0):
    """Plain recursive min-max: side 0 = controlled fighter (max), 1 = opponent (min)."""
    if d == 0:
        return 0.0
    lo, hi = off[s], off[s + 1]
    if lo == hi:
        return dead
    W = W_me if side == 0 else W_opp
    vals = [W[e] + gamma * brute_minmax(off, tgt, swap, W_me, W_opp, tgt[e], d - 1, side ^ int(swap[e]), gamma, dead)
            for e in range(lo, hi)]
    return max(vals) if side == 0 else min(vals)


# ---------------------------------------------------------------- min-max

@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("depth", [1, 2, 3, 4])
def test_minmax_equals_brute_force(seed, depth):
    off, tgt, swap, W_me, W_opp = small_graph(seed)
    S = len(off) - 1
    want_me = np.array([brute_minmax(off, tgt, swap, W_me, W_opp, s, depth, 0, 1.0) for s in range(S)])
    want_opp = np.array([brute_minmax(off, tgt, swap, W_me, W_opp, s, depth, 1, 1.0) for s in range(S)])
    # float32 values (the production path; float64 works the same, dtype=np.float64), 5 chunks.
    V_me, V_opp, b_me, b_opp = minmax(off, tgt, swap, W_me, W_opp, depth, n_chunks=5)
    np.testing.assert_allclose(V_me, want_me, atol=TOL)
    np.testing.assert_allclose(V_opp, want_opp, atol=TOL)
    perm = np.random.default_rng(seed).permutation(S)
    for ordering in planner.ORDERINGS + (perm,):
        sg = SearchGraph.from_arrays(off, tgt, swap, ordering=ordering)
        v_me, v_opp, bm, bo = sg.minmax(W_me, W_opp, depth, n_threads=1 + seed % 2)
        np.testing.assert_allclose(v_me, want_me, atol=TOL)
        np.testing.assert_allclose(v_opp, want_opp, atol=TOL)
        for best, side, want in ((bm, 0, want_me), (bo, 1, want_opp)):
            for s in range(S):
                if off[s] == off[s + 1]:
                    assert best[s] == -1
                    continue
                e = best[s]
                assert off[s] <= e < off[s + 1]
                W = W_me if side == 0 else W_opp
                q = W[e] + brute_minmax(off, tgt, swap, W_me, W_opp, tgt[e], depth - 1, side ^ int(swap[e]), 1.0)
                assert q == pytest.approx(want[s], abs=TOL)


def test_minmax_discount_and_dead_ends():
    # Chain 0 -> 1 -> 2 -> 3 (dead end), reward 1 per edge, no swaps; plus brute force with gamma.
    off = np.array([0, 1, 2, 3, 3], dtype=np.int64)
    tgt = np.array([1, 2, 3], dtype=np.int32)
    swap = np.zeros(3, dtype=np.uint8)
    W = np.ones(3)
    V_me, V_opp, b_me, b_opp = minmax(off, tgt, swap, W, W, depth=5, gamma=0.5)
    np.testing.assert_allclose(V_me, [1 + 0.5 + 0.25, 1 + 0.5, 1, 0], atol=TOL)
    assert b_me.tolist() == [0, 1, 2, -1] and b_opp.tolist() == [0, 1, 2, -1]
    V_me, *_ = minmax(off, tgt, swap, W, W, depth=5, gamma=0.5, dead_end_value=-4.0)
    np.testing.assert_allclose(V_me, [1 + 0.5 + 0.25 - 0.5, 1 + 0.5 - 1.0, 1 - 2.0, -4.0], atol=TOL)
    for seed in range(3):
        off, tgt, swap, W_me, W_opp = small_graph(100 + seed)
        V_me, V_opp, _, _ = minmax(off, tgt, swap, W_me, W_opp, 4, gamma=0.7)
        want = [brute_minmax(off, tgt, swap, W_me, W_opp, s, 4, 1, 0.7) for s in range(len(off) - 1)]
        np.testing.assert_allclose(V_opp, want, atol=TOL)


def test_minmax_larger_graph_orderings_agree():
    g = synthetic_graph(3000, 12, seed=3, dead_end_fraction=0.02, state_order="shuffled")
    rng = np.random.default_rng(0)
    E = int(g["state_offsets"][-1])
    W_me, W_opp = rng.normal(size=E), rng.normal(size=E)
    ref = minmax(g["state_offsets"], g["edge_target"], g["edge_swap"], W_me, W_opp, 5)
    for ordering in planner.ORDERINGS:
        sg = SearchGraph.from_arrays(g["state_offsets"], g["edge_target"], g["edge_swap"], ordering=ordering)
        got = sg.minmax(W_me, W_opp, 5)
        np.testing.assert_allclose(got[0], ref[0], atol=TOL)
        np.testing.assert_allclose(got[1], ref[1], atol=TOL)
    dp_ref = value_iteration_pair(g["state_offsets"], g["edge_target"], g["edge_swap"], W_me, W_opp, 0.9, 1e-8)
    dp_got = sg.value_iteration_pair(W_me, W_opp, 0.9, 1e-8)
    np.testing.assert_allclose(dp_got[0], dp_ref[0], atol=1e-7)
    np.testing.assert_allclose(dp_got[1], dp_ref[1], atol=1e-7)
    with pytest.raises(ValueError, match="permutation"):
        SearchGraph.from_arrays(g["state_offsets"], g["edge_target"], g["edge_swap"], ordering=np.zeros(3000))


# ---------------------------------------------------------------- dynamic programming

def brute_dp_pair(off, tgt, swap, W_a, W_b, gamma, dead=0.0):
    """Enumerate every deterministic policy over the 2S nodes (state, side); exact linear solves."""
    S = len(off) - 1
    nodes = [(s, side) for side in (0, 1) for s in range(S)]
    choices = [list(range(off[s], off[s + 1])) or [None] for s, _ in nodes]
    best = np.full(2 * S, -np.inf)
    for pol in itertools.product(*choices):
        P = np.zeros((2 * S, 2 * S))
        R = np.zeros(2 * S)
        for i, ((s, side), e) in enumerate(zip(nodes, pol)):
            if e is None:
                R[i] = dead * (1 - gamma)  # V = dead at a terminal: V = R + gamma*V with self-loop
                P[i, i] = 1.0
                continue
            R[i] = (W_a if side == 0 else W_b)[e]
            P[i, (side ^ int(swap[e])) * S + tgt[e]] = 1.0
        V = np.linalg.solve(np.eye(2 * S) - gamma * P, R)
        best = np.maximum(best, V)
    return best[:S], best[S:]


@pytest.mark.parametrize("seed", range(4))
def test_dp_equals_brute_force(seed):
    off, tgt, swap, W_a, W_b = small_graph(200 + seed, S=4, max_deg=3, dead=0.2)
    gamma = 0.8
    want_a, want_b = brute_dp_pair(off, tgt, swap, W_a, W_b, gamma)
    V_a, V_b, b_a, b_b, it, err = value_iteration_pair(off, tgt, swap, W_a, W_b, gamma, tol=1e-10)
    assert err < 1e-10 and it < 10_000
    np.testing.assert_allclose(V_a, want_a, atol=1e-8)
    np.testing.assert_allclose(V_b, want_b, atol=1e-8)
    for s in range(len(off) - 1):
        if off[s] == off[s + 1]:
            assert b_a[s] == -1
            continue
        e = b_a[s]
        nxt = V_b if swap[e] else V_a
        assert W_a[e] + gamma * nxt[tgt[e]] == pytest.approx(V_a[s], abs=1e-8)
    # One-table form: no swaps.
    V, best, it, err = value_iteration(off, tgt, W_a, gamma, tol=1e-10)
    w1, _ = brute_dp_pair(off, tgt, np.zeros_like(swap), W_a, W_a, gamma)
    np.testing.assert_allclose(V, w1, atol=1e-8)


def test_dp_max_iter_and_bad_gamma():
    off, tgt, swap, W_a, W_b = small_graph(7)
    V, best, it, err = value_iteration(off, tgt, W_a, 0.99, tol=1e-12, max_iter=3)
    assert it == 3 and err > 1e-12
    with pytest.raises(ValueError, match="gamma"):
        value_iteration(off, tgt, W_a, 1.0)


# ---------------------------------------------------------------- roulette

def chi2(counts, probs):
    n = counts.sum()
    exp = probs * n
    return float(((counts - exp) ** 2 / exp).sum())


@pytest.mark.parametrize("mode,temp", [("softmax", 1.0), ("linear", 0.5)])
def test_roulette_frequencies_follow_scores(mode, temp):
    scores = np.array([0.0, 1.0, 2.0, 0.5])
    p = roulette_probabilities(scores, temp, mode)
    assert np.all(np.diff(p[[0, 3, 1, 2]]) > 0)           # increasing in the score
    rng = np.random.default_rng(1234)
    n = 20_000
    counts = np.bincount([roulette_select(scores, rng, temp, mode) for _ in range(n)], minlength=4)
    assert chi2(counts, p) < 16.27                         # chi-square, 3 dof, 99.9 %
    # The usage penalty lowers the often-used best edge's share, as the formula says.
    usage = np.array([0, 0, 20, 0])
    p2 = roulette_probabilities(scores, temp, mode, usage, penalty=0.5)
    assert p2[2] < p[2] / 5
    rng = np.random.default_rng(99)
    counts2 = np.bincount([roulette_select(scores, rng, temp, mode, usage, 0.5) for _ in range(n)], minlength=4)
    assert chi2(counts2, p2) < 16.27
    assert counts2[2] < counts[2] / 5
    # Deterministic given the seed.
    a = [roulette_select(scores, np.random.default_rng(5), temp, mode) for _ in range(3)]
    assert a == [roulette_select(scores, 5, temp, mode)] * 3


def test_select_edge_and_policy_scores():
    g = synthetic_graph(400, 6, seed=11, dead_end_fraction=0.05)
    pol = compute_policy(g, "balanced", depth=3, kinds_table=KINDS, ordering="rcm")
    assert pol.style == "balanced" and pol.depth == 3 and pol.compute_ms > 0
    off, tgt, swap = g["state_offsets"], g["edge_target"], g["edge_swap"]
    ref = minmax(off, tgt, swap, pol.W_me, pol.W_opp, 3)
    np.testing.assert_allclose(pol.V_me, ref[0], atol=1e-5)
    np.testing.assert_allclose(pol.V_opp, ref[1], atol=1e-5)
    rng = np.random.default_rng(0)
    usage = np.zeros(len(tgt), dtype=np.int64)
    for s in range(0, 400, 7):
        for side, best, V in ((0, pol.best_me, pol.V_me), (1, pol.best_opp, pol.V_opp)):
            if off[s] == off[s + 1]:
                assert best[s] == -1 and pol.select(s, off, tgt, swap, rng, side) == -1
                continue
            q = pol.scores(s, off, tgt, swap, side)
            assert off[s] + int(np.argmax(q)) == best[s] or q.max() == pytest.approx(q[best[s] - off[s]])
            assert (q.max() if side == 0 else -q.max()) == pytest.approx(V[s], abs=1e-4)
            e = pol.select(s, off, tgt, swap, rng, side, temperature=0.1, usage=usage, penalty=1.0)
            assert off[s] <= e < off[s + 1]
            usage[e] += 1
    e1 = select_edge(5, off, tgt, swap, pol.W_me, pol.V_me_next, pol.V_opp_next, 42)
    assert e1 == select_edge(5, off, tgt, swap, pol.W_me, pol.V_me_next, pol.V_opp_next, 42)


# ---------------------------------------------------------------- styles

def test_attack_kinds_mirror():
    from motion_graph.classify import ATTACK_KINDS as MG_ATTACK, KINDS as MG_KINDS
    assert ATTACK_KINDS == MG_ATTACK
    assert KINDS == MG_KINDS


def test_presets_and_round_trip(tmp_path: Path):
    assert set(planner.list_presets()) >= {"infighter", "outboxer", "balanced"}
    inf, out = load_style("infighter"), load_style("outboxer")
    assert 0.6 <= inf.d_p <= 0.8 and 1.2 <= out.d_p <= 1.5
    assert inf.pref("hook") > inf.pref("straight") and out.pref("straight") > out.pref("hook")
    assert out.w_dmg_received > inf.w_dmg_received
    for suffix in (".toml", ".json"):
        p = tmp_path / f"x{suffix}"
        save_style(inf, p)
        assert load_style(p) == inf


def test_valid_user_files(tmp_path: Path):
    t = tmp_path / "mine.toml"
    t.write_text('name = "mine"\nbase = "outboxer"\nd_p = 1.2\nw_d = 2\n[kind_pref]\nhook = 2.0\n')
    st = load_style(t)
    assert st.name == "mine" and st.d_p == 1.2 and st.w_d == 2.0
    assert st.pref("hook") == 2.0 and st.pref("jab") == load_style("outboxer").pref("jab")
    assert st.w_dmg_received == load_style("outboxer").w_dmg_received
    j = tmp_path / "mine.json"
    j.write_text(json.dumps({"name": "j", "d_p": 0.9, "kind_pref": {"uppercut": 3}, "per_second": True}))
    st = load_style(j)
    assert st.d_p == 0.9 and st.pref("uppercut") == 3.0 and st.per_second and st.pref("kick") == 1.0


@pytest.mark.parametrize("body,field", [
    ('name = "x"\nd_p = 1.0\nspeed = 3\n', "speed"),                       # unknown field
    ('name = "x"\nd_p = 1.0\nw_d = "big"\n', "w_d"),                       # wrong type
    ('name = "x"\nd_p = 1.0\nw_d = true\n', "w_d"),                        # bool is not a number
    ('name = "x"\nd_p = -0.5\n', "d_p"),                                   # negative distance
    ('name = "x"\nd_p = 1.0\nw_theta = -1\n', "w_theta"),                  # negative weight
    ('name = "x"\nd_p = 1.0\n[kind_pref]\nelbow = 2.0\n', "kind_pref.elbow"),  # unknown attack kind
    ('name = "x"\nd_p = 1.0\n[kind_pref]\njab = "a lot"\n', "kind_pref.jab"),
    ('name = "x"\nd_p = 1.0\nkind_pref = 3\n', "kind_pref"),
    ('name = "x"\nd_p = 1.0\ndistance = "far"\n', "distance"),
    ('d_p = 1.0\n', "name"),                                               # missing
    ('name = "x"\n', "d_p"),
    ('name = "x"\nbase = "nosuchpreset"\n', "base"),
])
def test_bad_style_files(tmp_path: Path, body: str, field: str):
    p = tmp_path / "bad.toml"
    p.write_text(body)
    with pytest.raises(StyleError) as ei:
        load_style(p)
    assert ei.value.field == field
    assert str(p) in str(ei.value) and repr(field) in str(ei.value)
    assert isinstance(ei.value, ValueError)


def test_style_base_file_chain(tmp_path: Path):
    (tmp_path / "parent.json").write_text(json.dumps({"name": "p", "d_p": 0.8, "w_def": 3.0}))
    (tmp_path / "child.toml").write_text('name = "c"\nbase = "parent.json"\nw_d = 1.5\n')
    st = load_style(tmp_path / "child.toml")
    assert (st.name, st.d_p, st.w_def, st.w_d) == ("c", 0.8, 3.0, 1.5)
    (tmp_path / "parent.json").write_text(json.dumps({"name": "p", "d_p": 0.8, "w_def": -1}))
    with pytest.raises(StyleError) as ei:
        load_style(tmp_path / "child.toml")
    assert ei.value.field == "w_def" and "parent.json" in ei.value.path
    (tmp_path / "parent.json").write_text(json.dumps({"name": "p", "d_p": 0.8, "base": "child.toml"}))
    with pytest.raises(StyleError, match="circular"):
        load_style(tmp_path / "child.toml")


def test_bad_style_file_format(tmp_path: Path):
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(StyleError, match="bad.json"):
        load_style(p)
    with pytest.raises(StyleError, match="nosuch"):
        load_style("nosuch")
    with pytest.raises(StyleError, match="no such file"):
        load_style(tmp_path / "missing.toml")
    with pytest.raises(StyleError, match="d_p"):
        Style(name="x", d_p=0.0)


# ---------------------------------------------------------------- rewards

def feats(**cols):
    """Edge features with neutral defaults for the columns not given."""
    n = len(next(iter(cols.values())))
    base = {k: np.zeros(n) for k in planner.FIGHT_FEATURES}
    base["feat_duration"] = np.full(n, 0.5)
    base["feat_kind"] = np.full(n, KINDS.index("guard"), dtype=np.int32)
    base["feat_other_kind"] = np.full(n, KINDS.index("guard"), dtype=np.int32)
    base["feat_r"] = np.full(n, 1.0)
    base["feat_r_mean"] = np.full(n, 1.0)
    for k, v in cols.items():
        base[k] = np.asarray(v)
    return base


def test_styles_order_edges_as_intended():
    # Edge 0: short-distance hook that lands; edge 1: long-distance straight that lands.
    f = feats(feat_r=[0.7, 1.4], feat_kind=np.array([KINDS.index("hook"), KINDS.index("straight")], np.int32),
              feat_dmg_given=[1.0, 1.0])
    inf_me, _ = edge_rewards(f, load_style("infighter"), KINDS)
    out_me, _ = edge_rewards(f, load_style("outboxer"), KINDS)
    assert inf_me[0] > inf_me[1]
    assert out_me[1] > out_me[0]
    # Damage received costs the outboxer more.
    g = feats(feat_dmg_received=[0.0, 1.0])
    assert np.diff(edge_rewards(g, load_style("outboxer"), KINDS)[0])[0] < np.diff(edge_rewards(g, load_style("infighter"), KINDS)[0])[0]


def test_reward_formula_and_opponent_view():
    f = planner.random_features(50, seed=4, n_kinds=len(KINDS))
    st = Style(name="t", d_p=1.1, w_theta=0.3, w_d=2.0, w_dmg_given=7.0, w_dmg_received=5.0, w_def=1.5,
               kind_pref={"hook": 2.0, "jab": 0.5})
    W_me, W_opp = edge_rewards(f, st, KINDS)
    pref = np.array([st.pref(k) for k in KINDS])
    want = (-0.3 * f["feat_theta_self"] ** 2 - 2.0 * (f["feat_r"] - 1.1) ** 2
            + 7.0 * f["feat_dmg_given"] * pref[f["feat_kind"]] - 5.0 * f["feat_dmg_received"] + 1.5 * f["feat_def_self"])
    np.testing.assert_allclose(W_me, want, atol=1e-12)
    swapped = dict(f)
    for a, b in (("feat_theta_self", "feat_theta_other"), ("feat_dmg_given", "feat_dmg_received"),
                 ("feat_kind", "feat_other_kind"), ("feat_def_self", "feat_def_other")):
        swapped[a], swapped[b] = f[b], f[a]
    np.testing.assert_allclose(W_opp, edge_rewards(swapped, st, KINDS)[0], atol=1e-12)
    # per_second scales the position terms by the duration; "mean" reads feat_r_mean.
    st2 = Style(name="t2", d_p=1.1, w_theta=0.3, w_d=2.0, w_dmg_given=0, w_dmg_received=0, per_second=True,
                distance="mean")
    W2, _ = edge_rewards(f, st2, KINDS)
    np.testing.assert_allclose(W2, -(0.3 * f["feat_theta_self"] ** 2 + 2.0 * (f["feat_r_mean"] - 1.1) ** 2)
                               * f["feat_duration"], atol=1e-12)
    with pytest.raises(KeyError, match="feat_def_self"):
        edge_rewards({k: v for k, v in f.items() if k != "feat_def_self"}, st, KINDS)


def test_cooperative_rewards_direction():
    # Edge 0 moves the pair's midpoint +Z (towards A's partner), edge 1 moves it -Z; both at target distance.
    f = feats(feat_r=[1.0, 1.0], feat_mid_dx=[0.0, 0.0], feat_mid_dz=[0.25, -0.25])
    f["feat_duration"] = np.array([0.5, 0.5])
    W_a, W_b = cooperative_rewards(f, 1.0, direction_index=0, speed=0.5)
    assert W_a[0] == pytest.approx(0.0) and W_a[0] > W_a[1]
    assert W_b[1] == pytest.approx(0.0) and W_b[1] > W_b[0]       # same world direction seen from B
    W_a4, W_b4 = cooperative_rewards(f, 1.0, direction_index=4, speed=0.5)
    np.testing.assert_allclose(W_a4, W_b)
    W_a2, _ = cooperative_rewards(feats(feat_r=[1.0], feat_mid_dx=[0.25], feat_mid_dz=[0.0]), 1.0, 2, 0.5)
    assert W_a2[0] == pytest.approx(0.0)                            # direction 2 = +X (left)
    n0, n1 = cooperative_rewards(feats(feat_r=[1.0, 2.0]), 1.0, None)
    assert n0[0] > n0[1] and np.array_equal(n0, n1)
    # DP on a synthetic graph with the cooperative reward converges.
    g = synthetic_graph(300, 5, seed=2)
    W_a, W_b = cooperative_rewards(g, 1.0, 3)
    V_a, V_b, b_a, b_b, it, err = value_iteration_pair(g["state_offsets"], g["edge_target"], g["edge_swap"],
                                                       W_a, W_b, 0.9, tol=1e-6)
    assert err < 1e-6 and np.all(np.isfinite(V_a))


def test_synthetic_graph_contract():
    g = synthetic_graph(500, 8, seed=1, dead_end_fraction=0.1, state_order="shuffled")
    off = g["state_offsets"]
    assert off.dtype == np.int64 and off[0] == 0 and np.all(np.diff(off) >= 0)
    E = off[-1]
    assert g["edge_target"].dtype == np.int32 and g["edge_target"].shape == (E,)
    assert g["edge_swap"].dtype == np.uint8 and g["edge_action"].dtype == np.int32
    assert g["edge_target"].min() >= 0 and g["edge_target"].max() < 500
    for k in planner.FIGHT_FEATURES + planner.COOP_FEATURES:
        assert g[k].shape == (E,)
