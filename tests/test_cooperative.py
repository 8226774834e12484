"""Cooperative DP on the real CMU boxing graph (igraph_fight.coop): midpoint features by
simulation, value iteration per direction, and DP beating random play on the objective."""
from __future__ import annotations

import numpy as np
import pytest

from igraph_fight import coop
from igraph_fight.agents import RandomAgent
from igraph_fight.controller import NPCController
from igraph_fight.game import FightGame, GameConfig
from planner import cooperative_rewards

SECONDS = 15.0
SEEDS = (0, 1)
TARGET = 1.2
SPEED = 0.3


@pytest.fixture(scope="module")
def setup(small_graph):
    graph, lib = small_graph
    ctrl = NPCController(graph, lib, style="balanced", depth=1)
    mf = coop.midpoint_features(graph, ctrl.tables, workers=2)
    feats = dict(graph.arrays)
    feats.update(mf)
    game = FightGame(lib, GameConfig(max_seconds=SECONDS, sim=graph.sim_params()),
                     tables=ctrl.tables)
    yield graph, ctrl, mf, feats, game
    ctrl.close()


def test_midpoint_features_come_from_the_same_simulation_as_the_graph(setup):
    graph, ctrl, mf, feats, _ = setup
    # the re-simulated edges land exactly where the graph's features say
    assert mf["check"]["max_abs_r_diff_m"] < 1e-9 and mf["check"]["max_abs_duration_diff_s"] < 1e-9
    dx, dz = mf["feat_mid_dx"], mf["feat_mid_dz"]
    assert dx.shape == dz.shape == (graph.n_edges,) and np.all(np.isfinite(dx)) and np.all(np.isfinite(dz))
    speed = np.hypot(dx, dz) / np.maximum(graph.arrays["feat_duration"], 1e-3)
    assert np.median(speed) > 0.01 and np.percentile(speed, 99) < 3.0  # the pair moves, at walking speeds
    # by hand for a few edges: the decider at the origin facing +Z, the other at (r, theta_self)
    from igraph_fight import sim
    a = graph.arrays
    T = ctrl.tables.kernel_tuple()
    for s in (0, len(a["state_r"]) // 2, len(a["state_r"]) - 1):
        for e in range(int(a["state_offsets"][s]), int(a["state_offsets"][s + 1]))[:3]:
            si = np.array([a["state_m_self"][s], a["state_m_other"][s], a["state_f_other"][s],
                           a["state_mask_other"][s]], dtype=np.int64)
            sf = np.array([a["state_r"][s], a["state_theta_self"][s], a["state_theta_other"][s]])
            S, act, frm, mask = np.empty((2, 3)), np.empty(2, np.int64), np.empty(2, np.int64), np.empty(2, np.int64)
            sim.sample_world(T, si, sf, int(a["edge_action"][e]), S, act, frm, mask)
            x0 = [sim.root_pose(T, S, act, frm, i)[:2] for i in (0, 1)]
            sim.advance_to_decision(T, S, act, frm, mask, np.zeros(sim.N_STAT))
            x1 = [sim.root_pose(T, S, act, frm, i)[:2] for i in (0, 1)]
            dm = 0.5 * (np.add(*x1) - np.add(*x0))
            b = a["state_theta_self"][s]
            assert dm @ [np.cos(b), -np.sin(b)] == pytest.approx(dx[e], abs=1e-12)
            assert dm @ [np.sin(b), np.cos(b)] == pytest.approx(dz[e], abs=1e-12)


def test_value_iteration_policy_is_greedy_in_its_values(setup):
    graph, _, _, feats, _ = setup
    pol = coop.cooperative_policy(graph, feats, 2, TARGET, SPEED, gamma=0.9, n_threads=1)
    assert pol.error < 1e-3
    W_a, W_b = cooperative_rewards(feats, TARGET, 2, SPEED)
    np.testing.assert_array_equal(pol.W_a, W_a)
    off = graph.arrays["state_offsets"]
    for s in range(0, graph.n_states, max(1, graph.n_states // 50)):
        lo, hi = int(off[s]), int(off[s + 1])
        if lo == hi:
            continue
        assert pol.best_a[s] == lo + int(np.argmax(pol.Q_a[lo:hi]))
        assert pol.V_a[s] == pytest.approx(pol.Q_a[lo:hi].max(), abs=1e-3)
        assert pol.V_b[s] == pytest.approx(pol.Q_b[lo:hi].max(), abs=1e-3)


def test_dp_beats_random_on_the_cooperative_objective(setup):
    graph, ctrl, _, feats, game = setup
    rand = [coop.play(game, [RandomAgent(), RandomAgent()], SECONDS, s, TARGET) for s in SEEDS]
    dp_r, rn_r, dp_t, rn_t = [], [], [], []
    for k in range(8):
        pol = coop.cooperative_policy(graph, feats, k, TARGET, SPEED, gamma=0.9, n_threads=1)
        for i, s in enumerate(SEEDS):
            m, _ = coop.run_pair(game, [coop.CoopAgent(ctrl, pol, 0), coop.CoopAgent(ctrl, pol, 1)], SECONDS, s, pol)
            r = coop.measure(rand[i], pol)
            dp_r.append(m["reward_per_decision"])
            rn_r.append(r["reward_per_decision"])
            dp_t.append(m["travel_m"])
            rn_t.append(r["travel_m"])
    dp_r, rn_r, dp_t, rn_t = map(np.array, (dp_r, rn_r, dp_t, rn_t))
    # the common reward the DP maximises, earned per decision, averaged over 8 directions x 2 bouts
    print(f"reward/decision DP {dp_r.mean():.3f} random {rn_r.mean():.3f}; travel DP {dp_t.mean():.3f} "
          f"random {rn_t.mean():.3f}; DP wins {np.mean(dp_r > rn_r):.2f}")
    assert dp_r.mean() > rn_r.mean() + 0.2, (dp_r.mean(), rn_r.mean())
    # travel along the commanded direction (random play averages out over the 8 directions)
    assert abs(rn_t.mean()) < 0.1
    assert dp_t.mean() > rn_t.mean() + 0.15, (dp_t.mean(), rn_t.mean())
    assert np.mean(dp_r > rn_r) >= 0.6
