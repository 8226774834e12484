"""Baseline agents on the game API: game tree, static, human proxy, RL (real boxing library)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from igraph_fight import sim
from igraph_fight.agents import RandomAgent
from igraph_fight.agents.common import EventReward, as_style
from igraph_fight.agents.gametree import GameTreeAgent, GameTreeSearch
from igraph_fight.agents.human import HumanConfig, HumanProxyAgent
from igraph_fight.agents.static import StaticAgent, dummy_tables, static_policy
from igraph_fight.build.edge_features import edge_features
from igraph_fight.game import FightGame, FightState, GameConfig
from igraph_fight.state import WorldState, to_sample
from motion_graph.classify import KINDS
from planner import edge_rewards


@pytest.fixture(scope="module")
def lib(boxing_files):
    from motion_graph.library import build_library
    return build_library(boxing_files)


@pytest.fixture(scope="module")
def game(lib):
    return FightGame(lib, GameConfig(max_seconds=20.0))


def _random_states(game, n, seed=0):
    """Decision states reached by random play from random starts: (state, player)."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < n:
        st = game.new_initial_state(rng)
        for _ in range(int(rng.integers(1, 10))):
            p = st.current_player()
            st.apply_action(int(rng.choice(st.legal_actions(p))))
        out.append((st, st.current_player()))
    return out


def _children(game, si, sf):
    """Every menu action of a canonical sample simulated once; rewards (W_me, W_opp) as the planner computes them."""
    T = game.tables.kernel_tuple()
    acts = game.tables.menu(int(si[0])).astype(np.int64)
    ci, cf, ft, sw = sim.expand_samples(T, si[None], sf[None], np.zeros(len(acts), dtype=np.int64), acts)
    feats = edge_features(game.tables, np.full(len(acts), si[sim.SI_MOTHER]), acts, ft)
    return acts, ci, cf, sw, edge_rewards(feats, as_style("infighter"), list(KINDS))


def _minimax(game, si, sf, depth, me):
    """Plain recursive min-max with the planner's rewards (reference for the numba search)."""
    acts, ci, cf, sw, (w_me, w_opp) = _children(game, si, sf)
    W = w_me if me else w_opp
    vals = []
    for k in range(len(acts)):
        v = W[k]
        if depth > 1:
            v += _minimax(game, ci[k], cf[k], depth - 1, me if sw[k] == 0 else not me)[0]
        vals.append(v)
    vals = np.array(vals)
    j = int(np.argmax(vals)) if me else int(np.argmin(vals))
    return float(vals[j]), int(acts[j])


# ----- game tree ---------------------------------------------------------------------------------
def test_gametree_depth1_picks_the_best_immediate_reward(game):
    gs = GameTreeSearch(game.tables, "infighter", depth=1)
    for st, p in _random_states(game, 12):
        si, sf = to_sample(game.tables, st.world, p)
        acts, _, _, _, (w_me, _) = _children(game, si, sf)
        a, v = gs.search(si, sf)
        assert a == int(acts[int(np.argmax(w_me))])
        assert v == pytest.approx(float(w_me.max()), abs=1e-9)


def test_gametree_depth2_equals_plain_minimax_with_the_planner_reward(game):
    gs = GameTreeSearch(game.tables, "infighter", depth=2)
    for st, p in _random_states(game, 4, seed=1):
        si, sf = to_sample(game.tables, st.world, p)
        v_ref, a_ref = _minimax(game, si, sf, 2, True)
        a, v = gs.search(si, sf)
        assert v == pytest.approx(v_ref, abs=1e-6)
        assert a == a_ref


def test_alpha_beta_gives_the_unpruned_decision_and_value(game):
    pruned = GameTreeSearch(game.tables, "infighter", depth=3, prune=True)
    plain = GameTreeSearch(game.tables, "infighter", depth=3, prune=False)
    for st, p in _random_states(game, 6, seed=2):
        si, sf = to_sample(game.tables, st.world, p)
        a1, v1 = pruned.search(si, sf)
        a2, v2 = plain.search(si, sf)
        assert a1 == a2 and v1 == pytest.approx(v2, abs=1e-9)
    assert pruned.count[0] < plain.count[0]  # it does prune


def test_gametree_agent_plays_legal_actions_and_times_itself(game):
    st = game.new_initial_state(np.random.default_rng(3))
    ag = GameTreeAgent(2)
    ag.reset(game, 0, np.random.default_rng(0))
    for _ in range(6):
        p = st.current_player()
        a = ag.step(st, p)
        assert a in st.legal_actions(p)
        st.apply_action(a)
    assert ag.decisions == 6 and ag.decision_s > 0 and ag.events > 0


# ----- Eq. 4 reward of game events -----------------------------------------------------------------
@pytest.mark.parametrize("style", ["infighter", "outboxer"])
def test_event_reward_equals_the_planner_reward(game, style):
    st_obj = as_style(style)
    rew = EventReward(st_obj, game.tables)
    for st, p in _random_states(game, 30, seed=4):
        si, sf = to_sample(game.tables, st.world, p)
        acts, ci, cf, sw, _ = _children(game, si, sf)
        a = int(acts[len(acts) // 2])
        T = game.tables.kernel_tuple()
        _, _, ft, _ = sim.expand_samples(T, si[None], sf[None], np.zeros(1, dtype=np.int64), np.array([a]))
        w_me, w_opp = edge_rewards(edge_features(game.tables, np.array([si[sim.SI_MOTHER]]), np.array([a]), ft),
                                   st_obj, list(KINDS))
        m_other = int(st.world.action[1 - p])
        s2 = st.clone()
        ev = s2.apply_action(a)
        assert rew.reward(p, p, a, m_other, ev, s2.world) == pytest.approx(float(w_me[0]), abs=1e-6)
        assert rew.reward(1 - p, p, a, m_other, ev, s2.world) == pytest.approx(float(w_opp[0]), abs=1e-6)


# ----- static ------------------------------------------------------------------------------------
class _GuardOnly:
    name = "guard"

    def reset(self, game, player, rng):
        pass

    def step(self, state, player):
        menu = state.legal_actions(player)
        g = [a for a in menu if state.game.library.labels[a] == "guard"]
        return int(g[0] if g else menu[0])


def test_static_approaches_and_hits_a_target_that_does_not_fight_back(game):
    from igraph_fight.match import run_bout
    pol = static_policy(game.tables)
    assert pol.V.shape[0] == int(game.tables.nextset.max()) + 1 and pol.iterations > 1
    st = game.initial_state((0.0, 0.0), (0.0, 2.5), (0.0, math.pi), (0, 0))  # 2.5 m apart, facing each other
    res = run_bout(game, [StaticAgent(policy=pol), _GuardOnly()], 20.0, np.random.default_rng(0), initial=st)
    assert res.hits[0] >= 3 and res.hits[1] == 0
    assert res.mean_distance_m < 1.5


def test_static_has_no_notion_of_the_opponents_action(game):
    pol = static_policy(game.tables)
    ag = StaticAgent(policy=pol)
    nf = game.tables.n_frames
    kinds = game.tables.kinds
    punch = int(np.nonzero(kinds == KINDS.index("straight"))[0][0])
    guard = int(np.nonzero(kinds == KINDS.index("guard"))[0][0])
    w = dict(x=(0.0, 0.0), z=(0.0, 0.9), heading=(0.0, math.pi))
    a1 = ag.step(FightState(game, WorldState.new(**w, action=(guard, punch), frame=(int(nf[guard]) - 1, 5))), 0)
    a2 = ag.step(FightState(game, WorldState.new(**w, action=(guard, guard), frame=(int(nf[guard]) - 1, 5))), 0)
    assert a1 == a2


def test_dummy_tables_hold_a_motionless_target_longer_than_any_action(game):
    dt, d = dummy_tables(game.tables)
    assert dt.n_actions == game.tables.n_actions + 1 and dt.n_frames[d] > game.tables.n_frames.max()
    assert len(dt.menu(d)) == 0 and np.all(dt.path[dt.frame_offsets[d]:] == 0.0)


# ----- human proxy -------------------------------------------------------------------------------
def _punch_state(game, frame_other):
    """The proxy (slot 0, at a decision, in guard) faces an opponent 0.9 m away playing a straight."""
    kinds = game.tables.kinds
    punch = int(np.nonzero(kinds == KINDS.index("straight"))[0][0])
    nf = game.tables.n_frames
    # a guard whose menu holds a defence, so that a dodge is possible
    defence = np.isin(kinds, [KINDS.index("duck"), KINDS.index("dodge")])
    guard = next(a for a in range(game.tables.n_actions) if KINDS[kinds[a]] == "guard"
                 and defence[game.tables.menu(a)].any())
    w = WorldState.new((0.0, 0.0), (0.0, 0.9), (0.0, math.pi), (guard, punch), (int(nf[guard]) - 1, frame_other))
    return FightState(game, w), punch


def test_human_proxy_reacts_only_after_its_delay(game):
    cfg = HumanConfig(p_random=0.0, p_dodge=1.0, r_noise_m=0.0, theta_noise_deg=0.0)
    d = int(round(cfg.delay_s * game.fps))
    defence = [KINDS.index("duck"), KINDS.index("dodge")]
    for f, expect_dodge in ((2, False), (d - 1, False), (d + 1, True)):
        st, punch = _punch_state(game, f)
        assert f < game.library.strike_w1[game.library.strike_offsets[punch]]  # the punch is still coming
        h = HumanProxyAgent(cfg)
        h.reset(game, 0, np.random.default_rng(0))
        a = h.step(st, 0)
        assert (int(game.tables.kinds[a]) in defence) == expect_dodge, (f, game.library.labels[a])
        assert a in st.legal_actions(0)


def test_human_proxy_perceives_the_positions_of_its_delay_ago(game):
    from igraph_fight.state import advance, relative
    nf = game.tables.n_frames
    long_ = np.argsort(nf)[-2:]  # two long actions: nobody finishes within the delay
    h = HumanProxyAgent()
    d = int(round(h.config.delay_s * game.fps))
    w0 = WorldState.new((0.0, 0.3), (0.0, 2.0), (0.2, math.pi - 0.4), (int(long_[0]), int(long_[1])), (3, 5))
    w = w0
    for _ in range(d):
        w, ev = advance(game.trace_tables, w)
        assert ev.frames == 1 and ev.push_m == 0.0
    st = FightState(game, w)
    h.reset(game, 0, np.random.default_rng(0))
    r, ts, to, m, f = h.perceive(st, 0)
    r0, ts0, to0 = relative(w0, 0)
    assert (r, ts, to) == pytest.approx((r0, ts0, to0), abs=1e-9)
    assert (m, f) == (int(long_[1]), 5)
    assert relative(w, 0)[0] != pytest.approx(r0, abs=1e-3)  # they did move meanwhile


# ----- every baseline plays legal moves through a bout ------------------------------------------------
def test_baselines_play_a_short_bout(game, tmp_path):
    from igraph_fight.match import run_bout
    from igraph_fight.learn.train_rl import RLConfig, train
    from igraph_fight.agents.rl import RLAgent

    ck = train(game, RLConfig(total_decisions=64, num_envs=2, num_steps=32, episode_seconds=4.0,
                              opponents={"self": 0.5, "random": 0.5}), out=tmp_path / "rl.pt", progress=False)
    assert ck["budget"]["decisions"] == 64 and (tmp_path / "rl.pt").stat().st_size < 2_000_000
    agents = [RandomAgent(), StaticAgent(), HumanProxyAgent(), GameTreeAgent(2), RLAgent(tmp_path / "rl.pt")]
    for k, a in enumerate(agents):
        b = agents[(k + 1) % len(agents)]
        res = run_bout(game, [a, b], 4.0, np.random.default_rng(k))
        assert len(res.decisions) > 2
        for d in res.decisions:
            assert d["action"] >= 0


def test_static_acting_kernel_matches_the_numpy_reference(game):
    pol = static_policy(game.tables)
    ag = StaticAgent(policy=pol)
    ag.reset(game, 0, np.random.default_rng(0))
    dt, dummy = dummy_tables(game.tables)
    T = dt.kernel_tuple()
    for st, p in _random_states(game, 15, seed=6):
        si, sf = to_sample(game.tables, st.world, p)
        si[1:] = (dummy, 0, 0)
        acts = game.tables.menu(int(si[0])).astype(np.int64)
        _, cf, ft, _ = sim.expand_samples(T, si[None], sf[None], np.zeros(len(acts), dtype=np.int64), acts)
        W, _ = edge_rewards(edge_features(dt, np.full(len(acts), dummy), acts, ft), as_style("infighter"), list(KINDS))
        q = W + pol.gamma * pol.value(game.tables.nextset[acts], cf[:, sim.SF_R], cf[:, sim.SF_TH_SELF])
        assert ag.step(st, p) == int(acts[int(np.argmax(q))])


def test_root_q_values_agree_with_the_search(game):
    gs = GameTreeSearch(game.tables, "infighter", depth=3)
    for st, p in _random_states(game, 4, seed=7):
        si, sf = to_sample(game.tables, st.world, p)
        acts, q = gs.root_q(si, sf)
        a, v = gs.search(si, sf)
        assert q.max() == pytest.approx(v, abs=1e-9) and a == int(acts[int(np.argmax(q))])


def test_shipped_rl_checkpoints_document_their_budget():
    from igraph_fight.agents.rl import default_checkpoint, load_checkpoint
    found = [p for p in (default_checkpoint("infighter"), default_checkpoint("outboxer")) if p.is_file()]
    if not found:
        pytest.skip("no shipped RL checkpoint")
    for p in found:
        assert p.stat().st_size < 2_000_000
        ck = load_checkpoint(p)
        b = ck["budget"]
        assert b["cpu_minutes"] > 0 and b["decisions"] > 0 and ck["curve"] and ck["config"]["style"] == ck["style"]
        assert len(ck["library_fingerprint"]) == 64


def test_rl_features_and_mask(game):
    from igraph_fight.agents.rl import RLFeatures
    f = RLFeatures(game.tables)
    st = game.new_initial_state(np.random.default_rng(8))
    p = st.current_player()
    x = f(st, p)
    A = game.tables.n_actions
    assert x.shape == (10 + 2 * A,) and x.dtype == np.float32
    assert x[10 + int(st.world.action[p])] == 1.0 and x[10:10 + A].sum() == 1.0 and x[10 + A:].sum() == 1.0
    assert x[0] == pytest.approx(st.relative(p)[0] / 4.0, rel=1e-5)
    m = f.legal_mask(st, p)
    assert set(np.nonzero(m)[0]) == set(int(a) for a in st.legal_actions(p))
