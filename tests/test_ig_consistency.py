"""Consistency of the Interaction Graph's model with the game it is used in (small real graph).

The graph's edges, its min-max and the IG fighter's runtime must describe the same game as the
simulator and the game API, from either avatar slot:

* every stored edge is what the game gives when its action is launched from the state's centroid
  (world rebuilt from the canonical sample, moved rigidly, the decider in slot 0 or slot 1):
  damage given / received, duration, who decides next (swap), the distance and angles at the
  next decision and the target's compatible group;
* the min-max continuation value of an edge's target is the exact depth-1 value at the target's
  centroid over the target's edges (max for the controlled fighter, min of its reward for the
  opponent);
* snap_full puts a live state exactly on its graph state from either slot, and then the depth-1
  table answer is the exact depth-1 best among the state's edges;
* with ``first_ply="exact"`` a depth-1 controller answers what the exact depth-1 search answers
  over the whole menu, and the IG fighter does not snap such answers (it did before: the world was
  moved after the action had been chosen for the unsnapped one).
"""
from __future__ import annotations

import numpy as np
import pytest

from igraph_fight import sim
from igraph_fight.agents import IGAgent
from igraph_fight.agents.gametree import GameTreeSearch
from igraph_fight.controller import NPCController, observe
from igraph_fight.build.edge_features import edge_features
from igraph_fight.game import FightGame, GameConfig
from igraph_fight.state import WorldState, from_sample, to_sample
from motion_graph.classify import KINDS
from planner import edge_rewards

pytestmark = pytest.mark.realdata

STYLE = "infighter"


@pytest.fixture(scope="module")
def setup(small_graph):
    g, lib = small_graph
    ctl = NPCController(g, lib, style=STYLE, depth=2)
    game = FightGame(lib, GameConfig(max_seconds=1e9), tables=ctl.tables)
    a = g.arrays
    si = np.stack([a["state_m_self"], a["state_m_other"], a["state_f_other"], a["state_mask_other"]], 1).astype(np.int64)
    sf = np.stack([a["state_r"], a["state_theta_self"], a["state_theta_other"]], 1)
    yield g, lib, ctl, game, si, sf
    ctl.close()


def _wrap(x):
    return (np.asarray(x) + np.pi) % (2 * np.pi) - np.pi


def _world(tables, si, sf, slot, rng) -> WorldState:
    """The state's world (decider in ``slot``), moved by a random rigid motion of the ground."""
    w = from_sample(tables, si, sf)
    ang = rng.uniform(-np.pi, np.pi)
    c, s = np.cos(ang), np.sin(ang)
    tx, tz = rng.uniform(-2, 2, 2)
    w = WorldState(c * w.x + s * w.z + tx, -s * w.x + c * w.z + tz, w.heading + ang, w.action, w.frame, w.resolved)
    return w.swapped() if slot == 1 else w


def _states(g, n, seed):
    """States with several edges, half of them at punching range."""
    a = g.arrays
    deg = np.diff(a["state_offsets"])
    rng = np.random.default_rng(seed)
    near = np.nonzero((a["state_r"] < 0.9) & (deg > 3))[0]
    rest = np.nonzero(deg > 3)[0]
    return np.concatenate([rng.choice(near, n // 2, replace=False), rng.choice(rest, n - n // 2, replace=False)])


@pytest.mark.parametrize("slot", [0, 1])
def test_stored_edges_are_what_the_game_gives_from_the_centroid(setup, slot):
    g, lib, ctl, game, si, sf = setup
    a, off, f0 = g.arrays, g.arrays["state_offsets"], int(g.header["options"]["f0"])
    tables = game.tables
    rng = np.random.default_rng(slot)
    n = 0
    for s in _states(g, 30, 1):
        w = _world(tables, si[s], sf[s], slot, rng)
        for e in range(off[s], off[s + 1]):
            st = game.initial_state((0.0, 1.0), (0.0, 0.0), (0.0, 0.0), (0, 0))
            st.world = w
            st.last_player = 1 - slot  # when both stand at a decision instant, ``slot`` chooses first
            assert st.current_player() == slot
            st.apply_action(int(a["edge_action"][e]))
            if not st.deciders():
                st._advance()
            given, received = float(st.damage[1 - slot]), float(st.damage[slot])
            assert given == pytest.approx(float(a["feat_dmg_given"][e]), abs=1e-9)
            assert received == pytest.approx(float(a["feat_dmg_received"][e]), abs=1e-9)
            assert st.frames / tables.fps == pytest.approx(float(a["feat_duration"][e]), abs=1e-9)
            nxt = st.current_player()
            assert (nxt != slot) == bool(a["edge_swap"][e])
            r, ts, to = st.relative(slot)
            assert r == pytest.approx(float(a["feat_r"][e]), abs=1e-6)
            assert abs(_wrap(ts - a["feat_theta_self"][e])) < 1e-6
            assert abs(_wrap(to - a["feat_theta_other"][e])) < 1e-6
            ci, _ = to_sample(tables, st.world, nxt)
            t = int(a["edge_target"][e])
            assert tables.nextset[ci[sim.SI_MSELF]] == a["state_nextset"][t]
            assert ci[sim.SI_MOTHER] == a["state_m_other"][t] and ci[sim.SI_MASK] == a["state_mask_other"][t]
            assert abs(int(ci[sim.SI_FOTHER]) - int(a["state_f_other"][t])) < f0
            n += 1
    assert n > 300


def _exact_depth1(ctl, style, si, sf, me: bool, restrict) -> float:
    """max (me) / min (opponent) of the controlled fighter's Eq. 4 reward over ``restrict`` actions
    simulated exactly from a canonical sample."""
    acts = ctl.tables.menu(int(si[sim.SI_MSELF])).astype(np.int64)
    keep = np.isin(acts, list(restrict))
    acts = acts[keep]
    _, _, ft, _ = sim.expand_samples(ctl.tables.kernel_tuple(), si[None], sf[None], np.zeros(len(acts), np.int64),
                                     acts)
    w_me, w_opp = edge_rewards(edge_features(ctl.tables, np.full(len(acts), si[sim.SI_MOTHER]), acts, ft), style,
                               list(KINDS))
    return float(w_me.max()) if me else float(w_opp.min())


def test_minmax_continuation_is_the_exact_depth1_value_at_the_target(setup):
    g, lib, ctl, game, si, sf = setup
    a, off = g.arrays, g.arrays["state_offsets"]
    pol = ctl.policy  # depth 2: V_*_next are depth-1 values
    style = ctl._table.style_obj
    checked = {0: 0, 1: 0}
    for s in _states(g, 20, 2):
        for e in range(off[s], off[s + 1]):
            t = int(a["edge_target"][e])
            me = not a["edge_swap"][e]
            v_graph = float(pol.V_me_next[t] if me else pol.V_opp_next[t])
            linked = set(a["edge_action"][off[t]:off[t + 1]].tolist())
            assert v_graph == pytest.approx(_exact_depth1(ctl, style, si[t], sf[t], me, linked), abs=1e-3)
            checked[int(not me)] += 1
    assert checked[0] > 10 and checked[1] > 10


@pytest.mark.parametrize("slot", [0, 1])
def test_snap_full_lands_on_the_state_and_the_table_is_exact_there(setup, slot):
    g, lib, _, game, si, sf = setup
    a, off = g.arrays, g.arrays["state_offsets"]
    ctl = NPCController(g, lib, style=STYLE, depth=1)
    ex1 = GameTreeSearch(game.tables, STYLE, 1)
    rng = np.random.default_rng(10 + slot)
    n = 0
    for s in _states(g, 40, 3):
        w = _world(game.tables, si[s], sf[s], slot, rng)
        # perturb the live state within the tolerance around the state (both fighters, the other's clip)
        o = 1 - slot
        st = game.initial_state((0.0, 1.0), (0.0, 0.0), (0.0, 0.0), (0, 0))
        st.world = w
        st.last_player = 1 - slot
        st.snap(slot, float(sf[s, 0]) + rng.uniform(-0.05, 0.05), float(sf[s, 1]) + rng.uniform(-0.1, 0.1))
        nf = int(game.tables.n_frames[st.world.action[o]])
        if st.world.frame[o] < nf - 1:
            fr = st.world.frame.copy()
            fr[o] = int(np.clip(fr[o] + rng.integers(-3, 4), 0, nf - 2))
            hd = st.world.heading.copy()
            hd[o] += rng.uniform(-0.1, 0.1)
            from dataclasses import replace
            st.world = replace(st.world, frame=fr, heading=hd)
        d = ctl.act(observe(st, slot))
        if d.off_graph or d.state < 0 or d.edge < 0:
            continue
        t = d.state
        agent = IGAgent(ctl, snap="full")
        act = agent.step(st, slot)
        assert act == d.action
        ob = observe(st, slot)
        assert ob.r == pytest.approx(float(a["state_r"][t]), abs=1e-9)
        assert abs(_wrap(ob.theta_self - a["state_theta_self"][t])) < 1e-9
        assert abs(_wrap(ob.theta_other - a["state_theta_other"][t])) < 1e-9
        if int(a["state_f_other"][t]) < int(game.tables.n_frames[ob.m_other]) - 1:
            assert ob.f_other == int(a["state_f_other"][t])
            # on the snapped world the depth-1 table answer is the exact best among the state's edges
            acts, q = ex1.root_q(*to_sample(game.tables, st.world, slot))
            linked = np.isin(acts, a["edge_action"][off[t]:off[t + 1]])
            assert q[acts == act][0] == pytest.approx(q[linked].max(), abs=1e-4)
            n += 1
    ctl.close()
    assert n >= 10


def test_exact_first_ply_answers_the_exact_depth1_search_and_is_not_snapped(setup):
    g, lib, _, game, si, sf = setup
    ctl = NPCController(g, lib, style=STYLE, depth=1, first_ply="exact")
    table = NPCController(g, lib, style=STYLE, depth=1)
    ex1 = GameTreeSearch(game.tables, STYLE, 1)
    rng = np.random.default_rng(5)
    on_graph = differs = 0
    for s in _states(g, 40, 4):
        slot = int(rng.integers(2))
        st = game.initial_state((0.0, 1.0), (0.0, 0.0), (0.0, 0.0), (0, 0))
        st.world = _world(game.tables, si[s], sf[s], slot, rng)
        st.last_player = 1 - slot
        st.snap(slot, float(sf[s, 0]) + rng.uniform(-0.1, 0.1), float(sf[s, 1]) + rng.uniform(-0.3, 0.3))
        obs = observe(st, slot)
        want, _ = ex1.search(*to_sample(game.tables, st.world, slot))
        d = ctl.act(obs)
        assert d.action == want and d.edge == -1
        on_graph += int(not d.off_graph)
        differs += int(table.act(obs).action != want)
        before = st.world
        assert IGAgent(ctl, snap="full").step(st, slot) == want
        assert st.world is before  # a lookahead answer is not snapped
    ctl.close()
    table.close()
    assert on_graph >= 5
    with pytest.raises(ValueError):
        NPCController(g, lib, style=STYLE, depth=1, first_ply="bogus")
