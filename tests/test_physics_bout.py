"""Physics bouts (tracker.bouts.physics_bout): hits counted from fist contacts in a scripted scene, a short bout
that is deterministic for a seed and writes its artifacts, and the coupled state read from physics
agreeing with the kinematic simulator when the bodies follow their references."""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
from helpers import facing_start

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def setup(boxing_library):
    from tracker.bouts.setup import BoutSetup
    return BoutSetup.create(boxing_library)


def _strike_action(lib):
    """A straight punch whose first strike is thrown with a fist, and that strike's side."""
    parts = lib.parts
    for a in range(lib.n_actions):
        if lib.labels[a] in ("straight", "jab") and lib.is_attack(a):
            k = int(lib.strike_offsets[a])
            j = int(lib.strike_joint[k])
            if j in (parts["r_fist"], parts["r_wrist"], parts["l_fist"], parts["l_wrist"]):
                return a, k, ("r_fist" if j in (parts["r_fist"], parts["r_wrist"]) else "l_fist")
    pytest.skip("no fist strike in the library")


def _scripted_punch(setup, overlap_m: float, arrive: str = "window"):
    """Drive A's punching fist kinematically (A's whole body teleported along a line, every control
    step, with the matching velocity) towards B's head until the fist sphere overlaps the head
    sphere by ``overlap_m`` (negative: stops that far short). B is simulated (PD). Returns the bout."""
    import mujoco

    from tracker.bouts.setup import BoutConfig
    from tracker.bouts.agents import MenuAgent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.track.pd import PDController
    lib = setup.library
    a, k, fist = _strike_action(lib)
    calm = [g for g in range(lib.n_actions) if lib.labels[g] == "guard"]
    bout = PhysicsBout(setup, [MenuAgent([a], "puncher"), MenuAgent(calm, "target")], PDController(),
                       BoutConfig(seconds=2.0))
    bout.start(seed=0, initial=facing_start(setup, a))
    assert bout.decisions[0]["action"] == a
    m, d = bout.model, bout.env.data
    fA = bout.scene.fighters[0]
    g_fist = int(fA.geom_label[fist][0])
    g_head = int(bout.scene.fighters[1].geom_label["head"][0])
    w0, w1 = int(lib.strike_w0[k]), int(lib.strike_w1[k])
    # in the window: a steady approach arriving mid-window; late: stand off until the (widened)
    # window is over, then close in over 5 steps
    t_go = 0 if arrive == "window" else w1 + bout.config.window_slack[1] + 1
    t_arrive = (w0 + w1) // 2 if arrive == "window" else t_go + 5
    r_sum = float(m.geom_size[g_head, 0] + m.geom_size[g_fist, 0])
    state = {}

    def drive(b):
        """Move A rigidly so the fist-to-head surface gap shrinks linearly to -overlap at t_arrive
        (following B's head as B moves), with the matching root velocity."""
        t = b.env.t
        mujoco.mj_kinematics(m, d)
        v = d.geom_xpos[g_head] - d.geom_xpos[g_fist]
        dist = float(np.linalg.norm(v))
        gap = dist - r_sum
        state.setdefault("g0", gap)
        g0 = state["g0"]
        want = g0 + (-overlap_m - g0) * float(np.clip((t + 1 - t_go) / (t_arrive - t_go), 0.0, 1.0))
        u = v / dist
        q = d.qpos[fA.qpos_slice].copy()
        q[:3] += u * (gap - want) * 0.5           # half now, the velocity covers the rest of the step
        d.qpos[fA.qpos_slice] = q
        d.qvel[fA.qvel_slice] = 0.0
        d.qvel[fA.qvel_adr:fA.qvel_adr + 3] = u * (gap - want) * 0.5 * 30.0
        mujoco.mj_forward(m, d)

    for _ in range(t_arrive + 8):
        bout.step(before_physics=drive)
    return bout, bout.finish()


def test_scripted_fist_into_head_counts_one_hit(setup):
    bout, res = _scripted_punch(setup, overlap_m=0.03)
    hits = [h for h in res.hit_events if h["attacker"] == 0]
    assert len(hits) == 1, res.hit_events            # contact lasts several steps: debounced to one hit
    h = hits[0]
    assert h["target"] == "head" and h["victim"] == 1
    assert h["force_n"] >= bout.config.hit_force_n
    assert res.hits[1] == 0


def test_scripted_fist_stopping_short_counts_nothing(setup):
    _, res = _scripted_punch(setup, overlap_m=-0.05)
    assert res.hits.sum() == 0 and not res.touch_events


def test_fist_contact_outside_a_strike_window_is_a_touch_not_a_hit(setup):
    _, res = _scripted_punch(setup, overlap_m=0.03, arrive="late")
    assert res.hits[0] == 0
    assert any(t["attacker"] == 0 and t["target"] == "head" for t in res.touch_events)


def _bout_args(graph, out, seed=3, seconds=3.0):
    return argparse.Namespace(graph=str(graph), library=None, a="infighter", b="outboxer", depth_a=2, depth_b=2,
                              swap_a=None, seconds=seconds, seed=seed, out=str(out), json=True, physics=True,
                              tracker="pd", video=False, video_fps=15.0)


def test_short_physics_bout_is_deterministic_and_writes_artifacts(tiny_graph_file, tmp_path, capsys):
    from tracker.bouts.cli import cmd_physics_fight
    runs = []
    for i in range(2):
        assert cmd_physics_fight(_bout_args(tiny_graph_file, tmp_path / f"run{i}")) == 0
        runs.append(json.loads(capsys.readouterr().out))
    s0, s1 = runs
    for key in ("falls_a", "falls_b", "planned_hits", "realised_hits", "score", "realtime_factor", "artifacts"):
        assert key in s0
    assert s0["realtime_factor"] > 0
    volatile = {"wall_s", "realtime_factor", "artifacts", "machine_load"}
    assert {k: v for k, v in s0.items() if k not in volatile} == {k: v for k, v in s1.items() if k not in volatile}
    log0 = (tmp_path / "run0" / "log.jsonl").read_text()
    assert log0 == (tmp_path / "run1" / "log.jsonl").read_text()
    lines = [json.loads(l) for l in log0.splitlines()]
    assert {"action", "distance"} <= {l["type"] for l in lines}
    assert s0["decisions_a"] >= 2 and s0["decisions_b"] >= 2
    for name in ("log", "summary", "plot", "plot_physics"):
        assert (tmp_path / "run0").joinpath(s0["artifacts"][name].split("/")[-1]).is_file()


def test_wall_clock_budget_cuts_the_bout_and_the_summary_covers_what_was_played(tiny_graph_file, tmp_path, capsys):
    from tracker.bouts.cli import cmd_physics_fight
    args = _bout_args(tiny_graph_file, tmp_path / "cut")
    args.max_wall_s = 1e-9                   # exceeded after the first control step
    assert cmd_physics_fight(args) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["seconds"] == pytest.approx(1 / 30) and s["sim_s"] == pytest.approx(1 / 30)
    dist = [json.loads(l) for l in (tmp_path / "cut" / "log.jsonl").read_text().splitlines()
            if json.loads(l)["type"] == "distance"]
    assert len(dist) == 1                    # the trace holds the start only (it is sampled every 0.1 s)
    from tracker.bouts.physics_bout import PhysicsBout
    with pytest.raises(ValueError, match="max_wall_s"):
        PhysicsBout.run(None, max_wall_s=0.0)


def test_bout_video_renders(setup, tmp_path):
    """The MP4 of a short bout (offscreen MuJoCo: EGL, else OSMesa)."""
    from tracker.bouts.setup import BoutConfig
    from tracker.bouts.agents import MenuAgent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.media import render_bout_video
    from tracker.track.pd import PDController
    bout = PhysicsBout(setup, [MenuAgent(name="a"), MenuAgent(name="b")], PDController(), BoutConfig(seconds=1.0))
    res = bout.run(seed=1)
    try:
        p = render_bout_video(bout, res, tmp_path / "bout.mp4", fps=10.0, width=160, height=120)
    except RuntimeError as e:
        pytest.skip(f"no offscreen rendering here: {e}")
    assert p.stat().st_size > 1000


def test_coupled_state_from_physics_matches_the_kinematic_simulator(setup):
    """With the pelvises held on their references (root assist: a diagnostic, not physics), the
    coupled state the agents see equals the kinematic game's for the same actions."""
    from igraph_fight.controller import observe

    from tracker.bouts.setup import BoutConfig, BoutSetup
    from tracker.bouts.agents import MenuAgent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.track.pd import PDController
    lib = setup.library
    assisted = BoutSetup(lib, *_assisted_parts(setup))
    seen = []

    class Rec(MenuAgent):
        def step(self, ctx, player):
            a = super().step(ctx, player)
            seen.append((ctx.k, ctx.obs))
            return a

    bout = PhysicsBout(assisted, [Rec(name="a"), Rec(name="b")], PDController(), BoutConfig(seconds=3.0))
    res = bout.run(seed=5)
    st = setup.game.new_initial_state(np.random.default_rng(5))
    assert len(res.decisions) >= 4
    for d, (k, ob) in zip(res.decisions[:6], seen):
        assert st.current_player() == d["player"] == k
        kin = observe(st, k)
        assert (kin.m_self, kin.m_other, kin.f_other) == (ob.m_self, ob.m_other, ob.f_other)
        assert abs(kin.r - ob.r) < 0.05
        assert abs(np.angle(np.exp(1j * (kin.theta_self - ob.theta_self)))) < 0.15
        assert abs(np.angle(np.exp(1j * (kin.theta_other - ob.theta_other)))) < 0.15
        st.apply_action(d["action"])


def _assisted_parts(setup):
    """(scene, env, lift, tables, game, root_assist) of a root-assisted copy of ``setup``."""
    from tracker.bouts.setup import BoutSetup
    a = BoutSetup.create(setup.library, root_assist=True)
    return a.scene, a.env, a.lift_m, a.tables, a.game, True


def _guarding_pd_bout(setup, **rules):
    """A started 6 s bout of two PD-tracked fighters that only guard, 3 m apart (they fall within
    seconds), under BoutConfig(**rules)."""
    from tracker.bouts.setup import BoutConfig
    from tracker.bouts.agents import MenuAgent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.track.pd import PDController
    lib = setup.library
    guards = [g for g in range(lib.n_actions) if lib.labels[g] == "guard"]
    bout = PhysicsBout(setup, [MenuAgent(guards, "a"), MenuAgent(guards, "b")], PDController(),
                       BoutConfig(seconds=6.0, **rules))
    bout.start(seed=0, initial=facing_start(setup, guards[0], distance=3.0))
    return bout


@pytest.mark.parametrize("facing", ["opponent", "fall"])
def test_fallen_fighter_gets_up_facing_the_way_the_rule_says(setup, facing):
    """At the reset the fallen fighter's fighting direction points at the opponent's pelvis
    (reset_facing="opponent", the default) or is its fighting direction at the fall ("fall")."""
    bout = _guarding_pd_bout(setup, reset_facing=facing)
    fallen = {}
    for _ in range(bout.n_steps):
        n_events = len(bout.fall_events)
        bout.step()
        for e in bout.fall_events[n_events:]:
            fallen[e["player"]] = (e["reset_t"], bout.F[e["player"]].fall_pose[1])
        for k, (rt, h_fall) in fallen.items():
            if bout.env.t / 30.0 >= rt + 1e-9 and not bout.F[k].down:
                h = bout.fighting_heading(k, bout.env.t)
                v = bout.pelvis_xy(1 - k) - bout.pelvis_xy(k)
                to_opp = np.arctan2(v[0], -v[1])       # mocap heading h faces (sin h, -cos h) in MuJoCo (x, y)
                want = to_opp if facing == "opponent" else h_fall
                assert abs(np.angle(np.exp(1j * (h - want)))) < 0.1, (h, want)
                if facing == "fall":
                    assert abs(np.angle(np.exp(1j * (h - to_opp)))) > 0.1     # the two rules differ here
                return
    pytest.fail("no fighter fell and got up within the bout")


@pytest.mark.parametrize("place", ["reference", "fall"])
def test_fallen_fighter_gets_up_where_the_rule_says(setup, place):
    """PD-only fighters fall within seconds; at the reset the fallen fighter's pelvis is put on its
    reference pelvis at the fall (reset_place="reference": the topple undone) or on its physical
    pelvis then ("fall"); the two places differ (a topple carries the pelvis away)."""
    bout = _guarding_pd_bout(setup, reset_place=place)
    at_fall = {}
    for _ in range(bout.n_steps):
        n_events = len(bout.fall_events)
        t = bout.env.t
        ref_next = [bout.F[k].ref.qpos[t + 1, :2].copy() for k in (0, 1)]   # before a fall holds it
        bout.step()
        for e in bout.fall_events[n_events:]:
            k = e["player"]
            at_fall[k] = (ref_next[k], bout.pelvis_xy(k), e["reset_t"])
        done = [k for k, (_, _, rt) in at_fall.items() if bout.env.t / 30.0 >= rt + 1e-9 and not bout.F[k].down]
        if done:
            k = done[0]
            ref_xy, phys_xy, _ = at_fall[k]
            got = bout.pelvis_xy(k)
            assert np.linalg.norm(ref_xy - phys_xy) > 0.1           # the rules put it in different places
            want = ref_xy if place == "reference" else phys_xy
            assert np.linalg.norm(got - want) < 0.05, (got, want)
            return
    pytest.fail("no fighter fell and got up within the bout")


def test_planned_hit_windows_and_how_near_the_fist_came(setup):
    """A punch the kinematic simulator plans to land: its strike window is offered to the tracker
    (PhysicsBout.planned_windows: the library window widened by window_slack, the strike's fist)
    while it is open and not after; once it has passed, the planned event records how near the fist
    came (closest_m: 0 if it landed) and the summary lists it."""
    from tracker.bouts.setup import BoutConfig
    from tracker.bouts.agents import MenuAgent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.track.policy_net import load_policy
    lib = setup.library
    calm = [g for g in range(lib.n_actions) if lib.labels[g] == "guard"]
    lo, hi = BoutConfig().window_slack
    policy = load_policy()
    found = None
    for a in [x for x in range(lib.n_actions) if lib.labels[x] in ("straight", "jab")][:8]:
        k = int(lib.strike_offsets[a])
        side = int(setup_side(lib, k))
        w = (int(lib.strike_w0[k]) - lo, int(lib.strike_w1[k]) + hi)
        for d in (0.6, 0.7, 0.8, 0.9):
            bout = PhysicsBout(setup, [MenuAgent([a], "puncher"), MenuAgent(calm, "target")], policy, BoutConfig(seconds=3.0))
            bout.start(seed=0, initial=facing_start(setup, a, distance=d))
            offered = []
            while bout.env.t < w[1] + 2:
                offered.append(bout.planned_windows(0, bout.env.t))
                bout.step()
            first = [p for p in bout.planned_events if p["attacker"] == 0 and p["inst"] == 1 and p["strike"] == 0]
            if first:
                found = (bout, first[0], w, side, offered)
                break
        if found:
            break
    if found is None:
        pytest.skip("no planned hit of a first strike at these distances")
    bout, p, w, side, offered = found
    assert (w[0], w[1], side) in [x for o in offered for x in o]
    assert bout.planned_windows(0, w[1]) == []                         # passed: not offered any more
    # the miss anatomy at the predicted instant: the physical distance splits into the references'
    # (the prediction) and the two lags along the line (the rest is sideways)
    along = p["ref_distance_m"] + p["lag_attacker_m"] + p["lag_victim_m"]
    assert p["distance_m"] + 1e-3 >= along > p["distance_m"] - 0.1, p
    res = bout.finish()
    s = res.summary()
    assert len(s["planned_closest_m"]) == len(res.planned_events)
    if p.get("realised"):
        assert s["planned_closest_m"][res.planned_events.index(p)] == 0.0
    else:
        assert 0.0 <= p["closest_m"] < 1.0


def setup_side(lib, k: int) -> int:
    """Fist side of strike k as the judge reads it (0 left, 1 right, -1 other)."""
    parts = lib.parts
    j = int(lib.strike_joint[k])
    return 0 if j in (parts.get("l_fist"), parts.get("l_wrist")) else 1 if j in (parts.get("r_fist"), parts.get("r_wrist")) else -1
