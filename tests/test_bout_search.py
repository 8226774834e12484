"""The search tracker inside physics bouts (research/bout_search.py): its searches run on one-fighter
copies and leave the bout untouched (one candidate = the plain policy's bout, bit for bit), a copy
reproduces the bout's own continuation, a real search is deterministic and changes the bout, and
the tracker spec parses; the cheaper search variants (SearchSettings.early_accept)."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from helpers import facing_start, walk_qpos

from research.bout_search import load_search_tracker
from research.search_controller import SearchSettings


def test_search_tracker_spec():
    t = load_search_tracker("search")
    assert (t.s.candidates, t.s.lookahead, t.s.early_accept, t.s.reuse, t.s.heading_weight) == (16, 45, False, False, 1.0)
    t = load_search_tracker("search:4,12:full:reuse:heading=0.5:yawtol=0.2")
    assert (t.s.candidates, t.s.lookahead, t.s.early_accept, t.s.reuse) == (4, 12, False, True)
    assert (t.s.heading_weight, t.s.yaw_tol) == (0.5, 0.2)
    t = load_search_tracker("search:early:incr:first")
    assert (t.s.early_accept, t.s.incremental, t.s.first_kept, t.s.reuse) == (True, True, True, False)
    assert not t.s.up_first and load_search_tracker("search:early:upfirst").s.up_first
    with pytest.raises(ValueError, match="needs a number"):
        load_search_tracker("search:heading=x")
    with pytest.raises(ValueError, match="candidates >= 1"):
        load_search_tracker("search:0,12")
    with pytest.raises(FileNotFoundError):
        load_search_tracker("search:2,3:/nonexistent/policy.pt")


@pytest.fixture(scope="module")
def setup(boxing_library):
    from tracker.bouts.setup import BoutSetup
    return BoutSetup.create(boxing_library)


def _guard_bout(setup, tracker, seconds=1.0, distance=3.0):
    from tracker.bouts.setup import BoutConfig
    from tracker.bouts.agents import MenuAgent
    from tracker.bouts.physics_bout import PhysicsBout
    lib = setup.library
    guards = [g for g in range(lib.n_actions) if lib.labels[g] == "guard"]
    bout = PhysicsBout(setup, [MenuAgent(guards, "a"), MenuAgent(guards, "b")], tracker, BoutConfig(seconds=seconds))
    bout.start(seed=0, initial=facing_start(setup, guards[0], distance=distance))
    return bout


def _trace(bout, steps):
    out = []
    for _ in range(steps):
        bout.step()
        out.append(bout.env.data.qpos.copy())
    return np.array(out)


@pytest.mark.realdata
def test_one_candidate_search_is_the_plain_bout_and_search_is_deterministic(setup):
    from research.bout_search import BoutSearchTracker
    from tracker.track.policy_net import load_policy
    plain = _trace(_guard_bout(setup, load_policy()), 18)
    one = _trace(_guard_bout(setup, BoutSearchTracker(load_policy(), SearchSettings(candidates=1, lookahead=3))), 18)
    np.testing.assert_array_equal(plain, one)         # the searches never touch the bout's own state
    s = SearchSettings(candidates=3, lookahead=3, seed=1)
    a = _trace(_guard_bout(setup, BoutSearchTracker(load_policy(), s)), 18)
    b = _trace(_guard_bout(setup, BoutSearchTracker(load_policy(), s)), 18)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, plain)               # offsets were chosen and played


@pytest.mark.realdata
def test_one_fighter_copy_reproduces_the_bout(setup):
    """Fighters 3 m apart (no contact between them): the copy's three steps with the played offsets
    land within a millimetre of the bout's own three steps."""
    import mujoco

    from research.bout_search import BoutSearchTracker
    from tracker.track.policy_net import load_policy
    trk = BoutSearchTracker(load_policy(), SearchSettings(candidates=3, lookahead=3, seed=0))
    bout = _guard_bout(setup, trk)
    _trace(bout, 3)
    env = bout.env
    snap = mujoco.MjData(env.model)
    mujoco.mj_copyData(snap, env.model, env.data)
    t0 = env.t
    _trace(bout, 3)                                    # a search at t0, its offsets played 3 steps
    after = env.data.qpos.copy()
    t1 = env.t
    for k in range(2):
        mujoco.mj_copyData(env.data, env.model, snap)
        env.t = t0
        solo, sc = trk._solos[k], trk.searchers[k]
        o = trk._load(env, k)
        for _ in range(3):
            o, *_ = solo.step(sc._apply(solo, o, sc.delta))
        fm = env.scene.fighters[k]
        assert np.abs(solo.data.qpos - after[fm.qpos_slice]).max() < 1e-3
    env.t = t1


def _scripted_search(settings, outcomes):
    """A SearchController whose rollouts are scripted: outcomes[k] = (return, kept, steps up) of
    candidate k; the env's state is not touched. Returns the controller and the candidates' offsets."""
    from research.search_controller import SearchController
    sc = SearchController(None, settings)
    sc.rng, sc.sig, sc.delta, sc._tail, sc.extra = np.random.default_rng(0), np.ones(2), np.zeros(2), None, None
    sc.stats = {"searches": 0, "full": 0, "none_up": 0, "fallen_chosen": 0}
    tried = []

    def score(env, obs, delta, keep_tail=False):
        tried.append(delta.copy())
        return outcomes[len(tried) - 1]
    sc._score, sc._save, sc._restore = score, lambda env: None, lambda env, st: None
    return sc, tried


def test_up_first_ranks_a_rollout_that_stays_up_above_a_better_return_that_falls():
    from research.search_controller import UP
    # the plain policy falls at step 20; candidate 1 pays more but falls at step 40; candidate 2 stays up
    outcomes = [(5.0, False, 20), (9.0, False, 40), (6.0, True, UP)]
    sc, tried = _scripted_search(SearchSettings(candidates=3), outcomes)
    np.testing.assert_array_equal(sc._search(None, None), tried[1])          # the best return, though it falls
    assert sc.stats == {"searches": 1, "full": 1, "none_up": 0, "fallen_chosen": 1}
    sc, tried = _scripted_search(SearchSettings(candidates=3, up_first=True), outcomes)
    np.testing.assert_array_equal(sc._search(None, None), tried[2])
    assert sc.stats == {"searches": 1, "full": 1, "none_up": 0, "fallen_chosen": 0}
    # when every candidate falls, the one that stays up longest; an early acceptance is no full search
    sc, tried = _scripted_search(SearchSettings(candidates=3, up_first=True), [(5.0, False, 20), (9.0, False, 10),
                                                                              (1.0, False, 30)])
    np.testing.assert_array_equal(sc._search(None, None), tried[2])
    assert sc.stats["none_up"] == 1
    sc, tried = _scripted_search(SearchSettings(candidates=3, early_accept=True), [(5.0, True, UP)] * 3)
    assert not np.any(sc._search(None, None)) and len(tried) == 1
    assert sc.stats == {"searches": 1, "full": 0, "none_up": 0, "fallen_chosen": 0}
    # what a bout's summary and a series' or RL evaluation's rows carry: copies, one per fighter
    from types import SimpleNamespace

    from tracker.bouts.run import search_stats
    stats = search_stats(SimpleNamespace(searchers=[sc, sc]))
    assert stats == [sc.stats, sc.stats] and stats[0] is not sc.stats
    assert search_stats(load_search_tracker("pd")) is None


@pytest.mark.realdata
def test_early_accept_keeps_the_plain_policy_when_it_stays_up(boxing_library):
    """A 4-step look-ahead from a reference start never sees a fall: with early_accept every search
    stops at the plain candidate, so the walk is the plain policy's exactly."""
    from tracker.track.evaluation import draw_walks, make_setup
    from tracker.track.policy_net import load_policy
    from research.search_controller import SearchController
    from tracker.track.walks import LibraryWalks
    st = make_setup(LibraryWalks(boxing_library))
    walk = draw_walks(st.source, 1, 3, 4)[0]
    plain = walk_qpos(st, load_policy(), walk, steps=24)
    early = walk_qpos(st, SearchController(load_policy(), SearchSettings(candidates=3, lookahead=4, seed=2, early_accept=True)),
                  walk, steps=24)
    full = walk_qpos(st, SearchController(load_policy(), SearchSettings(candidates=3, lookahead=4, seed=2)), walk, steps=24)
    np.testing.assert_array_equal(plain[0], early[0])
    assert not np.array_equal(plain[0], full[0])
    # a heading reward without a yaw tolerance does not stop early acceptance (it once did: cos(inf))
    early_h = walk_qpos(st, SearchController(load_policy(), SearchSettings(candidates=3, lookahead=4, seed=2, early_accept=True,
                                                                       heading_weight=1.0)), walk, steps=24)
    np.testing.assert_array_equal(plain[0], early_h[0])


@pytest.mark.realdata
def test_incremental_early_search_is_the_early_search_exactly(boxing_library):
    """Extending the kept plain rollout one segment at a time gives the same walk as simulating the
    whole look-ahead again at every search (the walk's env is the one played, the policy
    deterministic); and some searches did try candidates (not all plain)."""
    from tracker.track.evaluation import draw_walks, make_setup
    from tracker.track.policy_net import load_policy
    from research.search_controller import SearchController
    from tracker.track.walks import LibraryWalks
    st = make_setup(LibraryWalks(boxing_library))
    walk = draw_walks(st.source, 1, 3, 4)[0]
    s = SearchSettings(candidates=3, lookahead=9, seed=2, early_accept=True)
    outcomes = []

    class Counting(SearchController):
        def _extend(self, env):
            outcomes.append(super()._extend(env))
            return outcomes[-1]

    early = walk_qpos(st, SearchController(load_policy(), s), walk, steps=45)
    incr = walk_qpos(st, Counting(load_policy(), replace(s, incremental=True)), walk, steps=45)
    plain = walk_qpos(st, load_policy(), walk, steps=45)
    np.testing.assert_array_equal(early[0], incr[0])
    assert early[1:] == incr[1:]
    assert not np.array_equal(early[0], plain[0])
    assert True in outcomes and False in outcomes, outcomes      # both paths taken


@pytest.mark.realdata
def test_incremental_first_kept_search_extends_the_chosen_offset_exactly(boxing_library):
    """With first_kept, the chosen offset's rollout (the offset for one segment, the plain policy
    after it) is kept and extended like the plain one: the same walk as without incremental checks,
    with at least one extension made right after an offset was played."""
    from tracker.track.evaluation import draw_walks, make_setup
    from tracker.track.policy_net import load_policy
    from research.search_controller import SearchController
    from tracker.track.walks import LibraryWalks
    st = make_setup(LibraryWalks(boxing_library))
    walk = draw_walks(st.source, 1, 3, 1)[0]
    s = SearchSettings(candidates=4, lookahead=24, seed=2, early_accept=True, first_kept=True)
    after_offset = []

    class Counting(SearchController):
        def _extend(self, env):
            played = bool(np.any(self.delta))
            ok = super()._extend(env)
            after_offset.append((played, ok))
            return ok

    ref = walk_qpos(st, SearchController(load_policy(), s), walk, steps=60)
    incr = walk_qpos(st, Counting(load_policy(), replace(s, incremental=True)), walk, steps=60)
    np.testing.assert_array_equal(ref[0], incr[0])
    assert ref[1:] == incr[1:]
    assert (True, True) in after_offset, after_offset


@pytest.mark.realdata
def test_a_fallen_fighter_loses_its_kept_rollout(setup):
    """A rollout kept for incremental checks describes the body before its fall: a fighter that is
    down (idle) forgets it, the other keeps its own."""
    from research.bout_search import BoutSearchTracker
    from tracker.track.policy_net import load_policy
    s = SearchSettings(candidates=2, lookahead=3, seed=1, early_accept=True, incremental=True)
    tracker = BoutSearchTracker(load_policy(), s)
    bout = _guard_bout(setup, tracker)
    _trace(bout, 3)                                   # one search each; the guards stand, plain accepted
    assert all(sc._tail is not None for sc in tracker.searchers)
    tracker.idle = [True, False]
    tracker.act(bout.env, bout._obs)                  # the next search boundary
    assert tracker.searchers[0]._tail is None and tracker.searchers[1]._tail is not None


def test_aim_and_duel_spec():
    t = load_search_tracker("search:4,9:aim=2:duel")
    assert (t.aim, t.duel, t.s.candidates) == (2.0, True, 4)
    assert "opponent in the rollouts" in t.describe() and "aimed" in t.describe()
    t = load_search_tracker("search")
    assert (t.aim, t.duel, t.touch, t.aiming) == (0.0, False, 0.0, False)
    with pytest.raises(ValueError, match="aim= needs a number"):
        load_search_tracker("search:aim=x")
    t = load_search_tracker("search:touch=10:spread=2")
    assert (t.aim, t.touch, t.aim_spread, t.aiming) == (0.0, 10.0, 2.0, True)
    assert "touch 10" in t.describe()
    with pytest.raises(ValueError, match="touch weight >= 0"):
        load_search_tracker("search:touch=-1")
    t = load_search_tracker("search:lead=2")
    assert (t.lead, t.aiming) == (2.0, True) and "pelvis lead 2" in t.describe()
    with pytest.raises(ValueError, match="lead weight >= 0"):
        load_search_tracker("search:lead=-1")


@pytest.mark.realdata
def test_duel_copy_leaves_the_bout_alone_and_reproduces_it_with_fighters_in_contact(setup):
    """Duel rollouts (the whole bout copied, both fighters simulated): one candidate is the plain
    policy's bout bit for bit; fighters 0.6 m apart (in contact), the copy's three steps with the
    played offsets land within a millimetre of the bout's own."""
    import mujoco

    from research.bout_search import BoutSearchTracker
    from tracker.track.policy_net import load_policy
    plain = _trace(_guard_bout(setup, load_policy(), distance=0.6), 12)
    one = _trace(_guard_bout(setup, BoutSearchTracker(load_policy(), SearchSettings(candidates=1, lookahead=3),
                                                      duel=True), distance=0.6), 12)
    np.testing.assert_array_equal(plain, one)
    trk = BoutSearchTracker(load_policy(), SearchSettings(candidates=3, lookahead=3, seed=0), duel=True)
    bout = _guard_bout(setup, trk, distance=0.6)
    _trace(bout, 3)
    env = bout.env
    snap = mujoco.MjData(env.model)
    mujoco.mj_copyData(snap, env.model, env.data)
    t0 = env.t
    _trace(bout, 3)
    after = env.data.qpos.copy()
    assert env.data.ncon > 0
    mujoco.mj_copyData(env.data, env.model, snap)
    env.t = t0
    du = trk._duel
    o = trk._load_duel(env)
    delta = np.concatenate([sc.delta for sc in trk.searchers])
    base = 0.0 if du.config.residual_actions else None
    for _ in range(3):
        b = base if base is not None else du.reference_targets()
        a = np.clip(trk.policy.act(du, o) - b + delta, -trk.policy.action_clip, trk.policy.action_clip) + b
        o, *_ = du.step(a)
    assert np.abs(du.data.qpos - after).max() < 1e-3


@pytest.mark.realdata
def test_aim_reward_rewards_a_fist_on_the_target(setup):
    """The aim term of a strike window: about its weight with the fist on the opponent's head (plus
    the touch weight: the fist on it), about zero 0.5 m away; none outside the window (duel
    rollouts: the opponent's live geoms)."""
    import mujoco

    from research.bout_search import BoutSearchTracker
    from tracker.track.policy_net import load_policy
    trk = BoutSearchTracker(load_policy(), SearchSettings(candidates=1, lookahead=3), aim=2.0, duel=True, touch=5.0)
    bout = _guard_bout(setup, trk, distance=1.0)
    env = bout.env
    trk.aims = [[(env.t, env.t + 5, 1)], []]
    assert trk._aim_reward(env, 1) is None                  # fighter 1 aims nothing
    f = trk._aim_reward(env, 0)
    du = trk._duel
    trk._load_duel(env)
    from tracker.body.humanoid import EFFECTOR_LABELS
    for e in EFFECTOR_LABELS:      # one-fighter copies share the bout's fighter-0 fist ids (the solo aim reads them)
        assert np.array_equal(trk._solos[1].scene.fighters[0].geom_label[e], env.scene.fighters[0].geom_label[e])
    head = int(env.scene.fighters[1].geom_label["head"][0])
    fist = int(env.scene.fighters[0].geom_label["r_fist"][0])
    r = [f(du)]
    # move fighter 0 bodily so that its right fist sits on fighter 1's head
    m, d = du.model, du.data
    a = env.scene.fighters[0].qpos_adr
    d.qpos[a:a + 3] += d.geom_xpos[head] - d.geom_xpos[fist]
    mujoco.mj_kinematics(m, d)
    r.append(f(du))
    d.qpos[a:a + 2] -= 0.5 * (d.geom_xpos[head, :2] - d.qpos[a:a + 2]) / np.linalg.norm(d.geom_xpos[head, :2] - d.qpos[a:a + 2])
    mujoco.mj_kinematics(m, d)
    r.append(f(du))
    du.t += 10
    r.append(f(du))                                       # past the window
    assert r[0] < 2.0 and 6.9 < r[1] <= 7.0 and r[2] < 0.1 * r[1] and r[3] == 0.0, r


@pytest.mark.realdata
def test_lead_reward_keeps_the_striker_on_its_reference(setup):
    """The lead term: about its weight with the striker's pelvis on its reference, from LEAD_IN_STEPS
    before the strike window to its end; near zero with the pelvis 0.3 m off; none earlier."""
    from research.bout_search import LEAD_IN_STEPS, BoutSearchTracker
    from tracker.track.policy_net import load_policy
    trk = BoutSearchTracker(load_policy(), SearchSettings(candidates=1, lookahead=30), duel=True, lead=2.0)
    bout = _guard_bout(setup, trk, distance=1.0)
    env = bout.env
    t = env.t
    trk.aims = [[(t + 20, t + 25, 1)], []]
    f = trk._aim_reward(env, 0)
    du = trk._duel
    trk._load_duel(env)
    a = env.scene.fighters[0].qpos_adr
    du.data.qpos[a:a + 2] = env.refs[0].qpos[t + 20 - LEAD_IN_STEPS, :2]
    du.t = t + 20 - LEAD_IN_STEPS
    on = f(du)
    du.data.qpos[a] += 0.3
    off = f(du)
    du.t = t + 20 - LEAD_IN_STEPS - 1
    early = f(du)
    assert abs(on - 2.0) < 1e-9 and off < 0.01 and early == 0.0, (on, off, early)


def test_foresee_spec():
    t = load_search_tracker("search:4,9:foresee")
    assert t.foresee_steps == t.s.segment + 9 + 2 and "next actions foreseen" in t.describe()
    assert load_search_tracker("search").foresee_steps == 0


class _Foreseeing:
    """The shipped policy with the bout's foresight asked for (nothing searched: it must not change
    the bout)."""

    def __init__(self, policy, steps: int) -> None:
        self.policy, self.foresee_steps, self.obs_future = policy, steps, policy.obs_future

    def reset(self, env) -> None:
        self.policy.reset(env)

    def act(self, env, obs):
        return self.policy.act(env, obs)


@pytest.mark.realdata
def test_foresight_guesses_the_next_actions_and_leaves_the_bout_alone(setup):
    """Foresight writes the scripted agents' next actions past their current ones (their peek
    copies the generator, so the guesses are the real decisions), and the bout played with it is
    the bout without it, bit for bit (the tracking policy never reads the guessed frames)."""
    from tracker.bouts.setup import BoutConfig
    from tracker.bouts.agents import MenuAgent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.track.policy_net import load_policy

    class Logged(MenuAgent):
        def __init__(self, name):
            super().__init__(name=name)
            self.peeks = []

        def peek(self, ctx, player):
            a = super().peek(ctx, player)
            self.peeks.append((round(ctx.t_s, 4), a))
            return a

    lib = setup.library
    guards = [g for g in range(lib.n_actions) if lib.labels[g] == "guard"]
    traces, bouts = [], []
    for steps in (0, 48):
        bout = PhysicsBout(setup, [Logged("a"), Logged("b")], _Foreseeing(load_policy(), steps), BoutConfig(seconds=2.0))
        bout.start(seed=3, initial=facing_start(setup, guards[0], distance=2.5))
        f = bout.F[0]
        moving = np.abs(f.ref.qvel[f.t_dec_end + 1:f.t_dec_end + 20]).max()
        assert (moving > 0.05) == bool(steps), moving          # guessed motion, else the last frame held
        traces.append(_trace(bout, 58))
        bouts.append(bout)
    np.testing.assert_array_equal(traces[0], traces[1])
    plain = [{k: v for k, v in d.items() if k != "foreseen"} for d in bouts[1].decisions]
    assert bouts[0].decisions == plain and not bouts[0].agents[0].peeks
    # every decision after the first of each fighter was guessed, and guessed right
    assert len(plain) >= 4
    assert [d["foreseen"] for d in bouts[1].decisions if "foreseen" in d] == [True] * (len(plain) - 2)
    for k in (0, 1):
        real = [(d["t"], d["action"]) for d in bouts[1].decisions if d["player"] == k][1:]
        peeks = dict(bouts[1].agents[k].peeks)
        assert all(peeks.get(t) == a for t, a in real), (real, peeks)
