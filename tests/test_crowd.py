"""The crowd simulator (igraph_fight.crowd) on the real CMU boxing graph."""
from __future__ import annotations

import numpy as np
import pytest

from igraph_fight import crowd as C
from igraph_fight import sim
from igraph_fight.controller import NPCController
from motion_graph.rotations import wrap_angle_nb


@pytest.fixture(scope="module")
def ctrls(small_graph):
    graph, lib = small_graph
    cs = [NPCController(graph, lib, style="infighter", depth=3), NPCController(graph, lib, style="outboxer", depth=3)]
    yield cs
    for c in cs:
        c.close()


class _Checked(C.Crowd):
    """Records every decision and checks it is legal (in Next of the action just finished)."""

    checked = 0

    def _decide(self, who):
        old = self.act[who].copy()
        opp_team = self.team[self.opp[who]]
        assert np.all(opp_team != self.team[who]), "an opponent of the same team"
        out = super()._decide(who)
        for k, i in enumerate(who):
            assert self.act[i] in self.tables.menu(int(old[k])), (i, old[k], self.act[i])
            assert self.frm[i] == 0
        self.checked += len(who)
        return out


def test_crowd_runs_with_legal_decisions_and_is_deterministic(ctrls):
    reps = []
    for _ in range(2):
        crowd = _Checked(ctrls, 12, seed=3, record_every=5)
        rep = crowd.run(4.0)
        assert crowd.checked == rep.decisions > 12  # everybody decided at the start and again later
        reps.append((rep, crowd))
    (a, ca), (b, cb) = reps
    assert np.array_equal(ca.pose, cb.pose) and np.array_equal(ca.act, cb.act) and np.array_equal(ca.opp, cb.opp)
    assert np.array_equal(a.hits, b.hits) and a.decisions == b.decisions
    assert a.rtf > 0 and a.seconds == pytest.approx(4.0, abs=1 / 30)
    assert a.frames.shape[1:] == (12, 3) and len(a.frames) == len(a.frame_t)
    assert 0.3 < a.mean_opponent_distance_m < 4.0
    s = a.summary()
    assert {"rtf", "decisions_per_s", "off_graph_fraction", "switches", "max_attackers"} <= set(s)


def test_nearest_enemy_switches_only_when_clearly_closer():
    team = np.array([0, 1, 1])
    opp = np.full(3, -1)
    pose = np.array([[0.0, 0.0, 0.0], [0.0, 1.0, np.pi], [0.0, 3.0, np.pi]])
    C._nearest_enemies(pose, team, opp, 0.15)
    assert list(opp) == [1, 0, 0]
    pose[2, 1] = -0.95           # closer than fighter 1, but by less than the margin: keep
    assert C._nearest_enemies(pose, team, opp, 0.15) == 0 and opp[0] == 1
    pose[2, 1] = -0.6            # clearly closer: switch
    assert C._nearest_enemies(pose, team, opp, 0.15) == 1 and opp[0] == 2
    # fighters 1 and 2 both fight fighter 0 (one fighter against two)
    assert list(opp[1:]) == [0, 0]


@pytest.mark.parametrize("guard_m", [0.0, 0.05])
def test_two_fighter_crowd_frames_reproduce_the_pair_simulator(ctrls, guard_m):
    """Frame by frame, two fighters that are each other's opponent move, push and hit exactly as
    the coupled simulator's event (sim.advance_worlds) does; with a guard, blocks too."""
    tables = ctrls[0].tables
    if guard_m:
        tables = sim.SimTables.from_library(ctrls[0].library, sim.SimParams(guard_radius_m=guard_m))
    T = tables.kernel_tuple()
    lib = ctrls[0].library
    punches = [a for a in range(lib.n_actions) if lib.labels[a] in ("straight", "jab")]
    rng = np.random.default_rng(0)
    total_hits = total_blocks = 0
    for trial in range(20):
        a0, a1 = (int(x) for x in rng.choice(punches, 2))
        r = rng.uniform(0.35, 0.9)
        pose0 = np.array([[[0.0, 0.0, rng.normal(0, 0.2)], [0.0, r, np.pi + rng.normal(0, 0.2)]]])
        act = np.array([[a0, a1]], dtype=np.int64)
        frm = np.array([[0, int(rng.integers(0, 5))]], dtype=np.int64)
        mask = np.zeros((1, 2), dtype=np.int64)
        # reference: one event of the pair simulator
        pose_ref, act_ref, frm_ref, mask_ref = pose0.copy(), act.copy(), frm.copy(), mask.copy()
        stats = sim.advance_worlds(T, pose_ref, act_ref, frm_ref, mask_ref)[0]
        # crowd: the same two fighters, frame by frame until one of them stands at its last frame
        S = np.array([sim.start_from_root(T, act[0, i], frm[0, i], *pose0[0, i]) for i in (0, 1)])
        c_act, c_frm, c_mask = act[0].copy(), frm[0].copy(), mask[0].copy()
        opp, team = np.array([1, 0]), np.array([0, 1])
        hits, dfd, pose = np.zeros(2), np.zeros(2), np.zeros((2, 3))
        deciders = 0
        while deciders == 0:
            deciders = C._frame(T, S, c_act, c_frm, c_mask, opp, team, hits, dfd, pose)
        assert np.array_equal(c_frm, frm_ref[0])
        assert np.array_equal(c_mask, mask_ref[0])
        assert hits[0] == stats[sim.ST_HITS0] and hits[1] == stats[sim.ST_HITS1]
        assert dfd[0] == stats[sim.ST_DEF0] and dfd[1] == stats[sim.ST_DEF1]
        np.testing.assert_allclose(pose[:, :2], pose_ref[0, :, :2], atol=1e-9)
        np.testing.assert_allclose(np.cos(pose[:, 2] - pose_ref[0, :, 2]), 1.0, atol=1e-12)
        total_hits += hits.sum()
        total_blocks += dfd.sum()
    assert total_hits > 0  # the comparison covered hits
    assert total_blocks > 0 if guard_m else total_blocks == 0   # (no punch here has a defence window)


def test_snapping_moves_on_graph_deciders_onto_their_state(ctrls):
    crowd = C.Crowd(ctrls, 2, seed=1, snap=True)
    who = np.array([0])
    actions = np.array([int(crowd.tables.menu(int(crowd.act[0]))[0])])
    C._start(crowd.T, crowd.S, crowd.act, crowd.frm, crowd.mask, crowd.opp, who, actions, np.array([True]),
             np.array([1.25]), np.array([0.1]))
    pose = np.zeros((2, 3))
    C._poses(crowd.T, crowd.S, crowd.act, crowd.frm, pose)
    d = pose[1, :2] - pose[0, :2]
    assert np.hypot(*d) == pytest.approx(1.25, abs=1e-9)
    b = np.arctan2(d[0], d[1])
    assert wrap_angle_nb(b - pose[0, 2]) == pytest.approx(0.1, abs=1e-9)
