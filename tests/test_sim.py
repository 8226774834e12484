"""Coupled kinematic simulator: symmetry, determinism, hits and defences on the real boxing library."""
from __future__ import annotations

import numpy as np
import pytest

from igraph_fight import sim, state
from igraph_fight.sim import SimParams, SimTables
from motion_graph.classify import KINDS


@pytest.fixture(scope="module")
def lib(boxing_library):
    return boxing_library


@pytest.fixture(scope="module")
def tables(lib) -> SimTables:
    return SimTables.from_library(lib)


def _random_worlds(tables: SimTables, n: int, seed: int):
    rng = np.random.default_rng(seed)
    A = tables.n_actions
    act = rng.integers(0, A, (n, 2))
    frm = np.floor(rng.random((n, 2)) * (tables.n_frames[act] - 1)).astype(np.int64)
    d = rng.uniform(0.3, 1.5, n)
    b = rng.uniform(-np.pi, np.pi, n)
    pose = np.zeros((n, 2, 3))
    pose[:, 0, 0] = rng.uniform(-2, 2, n)
    pose[:, 0, 1] = rng.uniform(-2, 2, n)
    pose[:, 0, 2] = rng.uniform(-np.pi, np.pi, n)
    pose[:, 1, 0] = pose[:, 0, 0] + d * np.sin(b)
    pose[:, 1, 1] = pose[:, 0, 1] + d * np.cos(b)
    pose[:, 1, 2] = rng.uniform(-np.pi, np.pi, n)
    return pose, act, frm, np.zeros((n, 2), dtype=np.int64)


def _run(tables, pose, act, frm, mask):
    pose, act, frm, mask = pose.copy(), act.copy(), frm.copy(), mask.copy()
    st = sim.advance_worlds(tables.kernel_tuple(), pose, act, frm, mask)
    return pose, act, frm, mask, st


def _swap_stats(st):
    out = st.copy()
    for a, b in ((sim.ST_HITS0, sim.ST_HITS1), (sim.ST_DMG0, sim.ST_DMG1), (sim.ST_REACH0, sim.ST_REACH1),
                 (sim.ST_DEF0, sim.ST_DEF1), (sim.ST_NEAR0, sim.ST_NEAR1)):
        out[:, a], out[:, b] = st[:, b], st[:, a]
    return out


def test_swapping_the_avatars_swaps_the_outcome(tables):
    pose, act, frm, mask = _random_worlds(tables, 3000, seed=1)
    p1, a1, f1, m1, s1 = _run(tables, pose, act, frm, mask)
    p2, a2, f2, m2, s2 = _run(tables, pose[:, ::-1].copy(), act[:, ::-1].copy(), frm[:, ::-1].copy(),
                              mask[:, ::-1].copy())
    assert np.array_equal(a1, a2[:, ::-1]) and np.array_equal(f1, f2[:, ::-1]) and np.array_equal(m1, m2[:, ::-1])
    np.testing.assert_allclose(p1, p2[:, ::-1], atol=1e-9)
    np.testing.assert_allclose(s1, _swap_stats(s2), atol=1e-9)
    # the sample exercises pushes and strikes, so the symmetry is not vacuous
    assert (s1[:, sim.ST_PUSH] > 0).sum() > 10
    assert (s1[:, sim.ST_NEAR0] + s1[:, sim.ST_NEAR1] > 0).sum() > 10


def test_same_input_same_result_and_batch_matches_single(tables):
    pose, act, frm, mask = _random_worlds(tables, 200, seed=2)
    r1 = _run(tables, pose, act, frm, mask)
    r2 = _run(tables, pose, act, frm, mask)
    for x, y in zip(r1, r2):
        assert np.array_equal(x, y)
    for n in (0, 57, 199):
        w = state.WorldState(pose[n, :, 0].copy(), pose[n, :, 1].copy(), pose[n, :, 2].copy(), act[n].copy(),
                             frm[n].copy(), mask[n].copy())
        w2, ev = state.advance(tables, w)
        np.testing.assert_allclose(np.stack([w2.x, w2.z, w2.heading], 1), r1[0][n], atol=1e-12)
        assert ev.frames == r1[4][n, sim.ST_FRAMES]
        assert set(ev.deciders) <= {0, 1} and ev.deciders


def test_event_stops_when_an_avatar_finishes(tables):
    pose, act, frm, mask = _random_worlds(tables, 500, seed=3)
    _, a, f, _, st = _run(tables, pose, act, frm, mask)
    at_end = f >= tables.n_frames[a] - 1
    assert np.all(at_end.any(axis=1))
    assert np.all(st[:, sim.ST_FRAMES] == np.min(tables.n_frames[act] - 1 - frm, axis=1))


def test_both_perspectives_from_one_world(tables):
    w = state.WorldState.new((0.0, 0.3), (0.0, 1.0), (0.2, np.pi - 0.1), (3, 5), (tables.n_frames[3] - 1, 4))
    ia, ib = state.both_perspectives(tables, w)
    assert ia.r == pytest.approx(ib.r) == pytest.approx(np.hypot(0.3, 1.0))
    bearing = np.arctan2(0.3, 1.0)
    assert ia.theta_self == pytest.approx(bearing - 0.2)
    assert ia.theta_self == pytest.approx(ib.theta_other) and ia.theta_other == pytest.approx(ib.theta_self)
    assert (ia.m_self, ia.m_other, ia.f_other) == (3, 5, 4)
    assert (ib.m_self, ib.m_other, ib.f_other) == (5, 3, tables.n_frames[3] - 1)
    assert ia.next_self == tuple(int(b) for b in tables.menu(3))
    # the canonical sample round-trips through the world state
    si, sf = state.to_sample(tables, w, 0)
    np.testing.assert_allclose(sf, [ia.r, ia.theta_self, ia.theta_other], atol=1e-12)
    w2 = state.from_sample(tables, si, sf)
    np.testing.assert_allclose(state.relative(w2, 0), state.relative(w, 0), atol=1e-9)


# ---- hits and defences ------------------------------------------------------------------------
def _place_target_at_fist(lib, tables, a: int, s: int, b: int, fb: int, extra_m: float = 0.0):
    """World where avatar 0 starts attack a (strike s) at the origin facing +Z and avatar 1 plays b
    from frame fb, facing avatar 0, placed so that at the strike's peak its nearest-in-height target
    point lies on the fist (pushed back by extra_m along +Z)."""
    p = int(lib.strike_peak[s])
    g0 = lib.frame_offsets[a] + p
    fist = tables.eff[g0, tables.strike_eff[s]]
    gb = lib.frame_offsets[b] + fb + p
    tg = tables.tgt[gb]
    t = int(np.argmin(np.abs(tg[:, 1] - fist[1])))
    # avatar 1's start transform: heading pi, target (rotated by pi) on the fist
    sh = np.pi
    c, sn = np.cos(sh), np.sin(sh)
    sx = fist[0] - (c * tg[t, 0] + sn * tg[t, 2])
    sz = fist[2] - (-sn * tg[t, 0] + c * tg[t, 2]) + extra_m
    # its root pose at frame fb
    pb = lib.path[lib.frame_offsets[b] + fb]
    x1 = c * pb[0] + sn * pb[1] + sx
    z1 = -sn * pb[0] + c * pb[1] + sz
    return state.WorldState.new((0.0, x1), (0.0, z1), (0.0, sh + pb[2]), (a, b), (0, fb)), abs(tg[t, 1] - fist[1])


def _play_attack(tables, w, until: int):
    """Advance to the next decision (avatar 1 must not finish before avatar 0 reaches frame
    ``until``); returns (hits, defended) per avatar."""
    w2, ev = state.advance(tables, w)
    assert w2.frame[0] >= until or 0 in ev.deciders, "the other avatar finished first"
    return np.array(ev.hits), np.array(ev.defended), ev


def _straight_strikes(lib):
    ids = [KINDS.index("straight"), KINDS.index("jab")]
    return [s for s in range(len(lib.strike_kind)) if lib.strike_kind[s] in ids]


def _action_of_strike(lib, s):
    return int(np.searchsorted(lib.strike_offsets, s, side="right") - 1)


def test_straight_punch_at_reach_hits_and_beyond_reach_misses(lib, tables):
    guard = KINDS.index("guard")
    idle = [b for b in range(lib.n_actions) if lib.kinds[b] == guard]
    b = max(idle, key=lambda x: lib.n_frames[x])
    tried = 0
    for s in _straight_strikes(lib):
        a = _action_of_strike(lib, s)
        if lib.strike_offsets[a + 1] - lib.strike_offsets[a] != 1 or lib.n_frames[b] <= lib.strike_w1[s] + 1:
            continue
        w, dy = _place_target_at_fist(lib, tables, a, s, b, 0)
        if dy > 0.6 * float(np.sqrt(tables.contact_radius2().min())):
            continue
        tried += 1
        hits, defended, ev = _play_attack(tables, w, int(lib.strike_w1[s]))
        assert hits[0] == 1 and defended.sum() == 0 and hits[1] == 0
        w_far, _ = _place_target_at_fist(lib, tables, a, s, b, 0, extra_m=0.6)
        hits, defended, _ = _play_attack(tables, w_far, int(lib.strike_w1[s]))
        assert hits.sum() == 0 and defended.sum() == 0
        if tried >= 3:
            break
    assert tried >= 1, "no single-strike straight punch suitable for the test in the library"


def test_dodge_inside_its_window_avoids_the_punch(lib, tables):
    defences = [d for d in range(lib.n_actions) if lib.defence_w0[d] >= 0]
    done = 0
    for s in _straight_strikes(lib):
        a = _action_of_strike(lib, s)
        if lib.strike_offsets[a + 1] - lib.strike_offsets[a] != 1:
            continue
        w0, w1 = int(lib.strike_w0[s]), int(lib.strike_w1[s])
        for d in defences:
            dw0, dw1 = int(lib.defence_w0[d]), int(lib.defence_w1[d])
            fb = dw0 - w0  # the dodge window covers the whole strike window
            if fb < 0 or fb + w1 > dw1 or fb + w1 + 1 >= lib.n_frames[d]:
                continue
            w, dy = _place_target_at_fist(lib, tables, a, s, d, fb)
            if dy > 0.6 * float(np.sqrt(tables.contact_radius2().min())):
                continue
            hits, defended, _ = _play_attack(tables, w, w1)
            assert hits[0] == 0 and defended[1] == 1
            # the same geometry without a defence window is a hit
            no_def = SimTables.from_library(lib)
            no_def.defence_w0 = np.full_like(no_def.defence_w0, -1)
            no_def.defence_w1 = np.full_like(no_def.defence_w1, -1)
            hits, defended, _ = _play_attack(no_def, w, w1)
            assert hits[0] == 1 and defended.sum() == 0
            done += 1
            break
        if done >= 2:
            break
    assert done >= 1, "no (punch, dodge) pair suitable for the test in the library"


def test_damage_per_kind_and_contact_radius_are_parameters(lib):
    t_big = SimTables.from_library(lib, SimParams(contact_radius_m=0.3, damage={"straight": 3.0},
                                                  target_radius_m={"head": 0.1, "chest": 0.2, "belly": 0.0}))
    radii = {"head": 0.1, "chest": 0.2, "belly": 0.0}
    assert t_big.kernel_tuple()[12] == pytest.approx([(0.3 + radii[n]) ** 2 for n in t_big.target_names])
    ks = np.array(lib.strike_kind)
    assert np.all(t_big.strike_damage[ks == KINDS.index("straight")] == 3.0)
    assert np.all(t_big.strike_damage[ks != KINDS.index("straight")] == 1.0)


def test_guard_blocks_strikes_and_changes_nothing_else(lib, tables):
    """With forearms that block (SimParams.guard_radius_m), the same worlds end in the same poses
    and frames; a strike either hits as without the guard or is blocked (a defence of the other),
    so hits only drop, strikes that reached a target or a forearm only grow; blocks do happen."""
    guarded = SimTables.from_library(lib, SimParams(guard_radius_m=0.05))
    assert guarded.params.to_json()["guard_radius_m"] == 0.05 and "guard_radius_m" not in tables.params.to_json()
    pose, act, frm, mask = _random_worlds(tables, 3000, seed=5)
    p0, a0, f0, _, s0 = _run(tables, pose, act, frm, mask)
    p1, a1, f1, _, s1 = _run(guarded, pose, act, frm, mask)
    np.testing.assert_array_equal(p0, p1)
    assert np.array_equal(a0, a1) and np.array_equal(f0, f1)
    for h, r, d in ((sim.ST_HITS0, sim.ST_REACH0, sim.ST_DEF1), (sim.ST_HITS1, sim.ST_REACH1, sim.ST_DEF0)):
        assert np.all(s1[:, h] <= s0[:, h]) and np.all(s1[:, r] >= s0[:, r]) and np.all(s1[:, d] >= s0[:, d])
        assert np.all(s1[:, r] - s1[:, d] == s1[:, h])      # reached = hit, or avoided (dodged or blocked)
    blocked = (s1[:, sim.ST_DEF0] + s1[:, sim.ST_DEF1]) - (s0[:, sim.ST_DEF0] + s0[:, sim.ST_DEF1])
    assert (blocked > 0).sum() > 10
    assert (s0[:, sim.ST_HITS0] > s1[:, sim.ST_HITS0]).sum() > 0    # some of them were hits without the guard
    with pytest.raises(ValueError, match="guard_radius_m"):
        SimParams(guard_radius_m=-0.1)


def test_bodies_do_not_interpenetrate(tables):
    pose, act, frm, mask = _random_worlds(tables, 2000, seed=4)
    p, _, _, _, st = _run(tables, pose, act, frm, mask)
    d = np.hypot(p[:, 1, 0] - p[:, 0, 0], p[:, 1, 1] - p[:, 0, 1])
    assert d.min() >= tables.params.min_distance_m - 1e-9
    assert (st[:, sim.ST_PUSH] > 0).any()


def test_sample_kernel_agrees_with_the_world_state_api(tables):
    rng = np.random.default_rng(7)
    N = 300
    A = tables.n_actions
    si = np.zeros((N, sim.N_SI), dtype=np.int64)
    si[:, sim.SI_MSELF] = rng.integers(0, A, N)
    si[:, sim.SI_MOTHER] = rng.integers(0, A, N)
    si[:, sim.SI_FOTHER] = np.floor(rng.random(N) * (tables.n_frames[si[:, sim.SI_MOTHER]] - 1))
    sf = np.stack([rng.uniform(0.5, 1.2, N), rng.uniform(-1, 1, N), rng.uniform(-1, 1, N)], 1)
    action = np.array([rng.choice(tables.menu(m)) for m in si[:, sim.SI_MSELF]])
    ci, cf, feat, swap = sim.expand_samples(tables.kernel_tuple(), si, sf, np.arange(N), action, workers=2)
    for n in range(N):
        w = state.start_action(tables, state.from_sample(tables, si[n], sf[n]), 0, int(action[n]))
        w2, ev = state.advance(tables, w)
        d = 1 if 1 in ev.deciders else 0
        assert d == swap[n]
        s2i, s2f = state.to_sample(tables, w2, d)
        assert np.array_equal(s2i, ci[n])
        np.testing.assert_allclose(s2f, cf[n], atol=1e-9)
        assert ev.frames == feat[n, sim.FT_FRAMES] and ev.damage == (feat[n, sim.FT_DMG_RECEIVED], feat[n, sim.FT_DMG_GIVEN])
