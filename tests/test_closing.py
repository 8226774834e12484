"""The closing rule (igraph_fight.closing) and its physics-bout wrapper (tracker.bouts.agents.ClosingAgent)."""
from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from igraph_fight.closing import ClosingRule, end_geometry
from igraph_fight.state import relative


@pytest.mark.realdata
def test_end_geometry_is_the_coupled_state_after_the_action_placed_as_the_library_places_it(boxing_library):
    lib = boxing_library
    rng = np.random.default_rng(3)
    for _ in range(50):
        a = int(rng.integers(lib.n_actions))
        x, z, h = rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-np.pi, np.pi)
        ox, oz = rng.uniform(-2, 2), rng.uniform(-2, 2)
        before = SimpleNamespace(x=np.array([x, ox]), z=np.array([z, oz]), heading=np.array([h, 0.0]))
        r, th, _ = relative(before, 0)
        # the action continues from (x, z, h) as ActionLibrary.sequence_motion places it
        c, s = np.cos(h), np.sin(h)
        after = SimpleNamespace(x=np.array([x + c * lib.dx[a] + s * lib.dz[a], ox]),
                                z=np.array([z - s * lib.dx[a] + c * lib.dz[a], oz]),
                                heading=np.array([h + lib.dheading[a], 0.0]))
        r_want, th_want, _ = relative(after, 0)
        r1, th1 = end_geometry(r, th, lib.dx[[a]], lib.dz[[a]], lib.dheading[[a]])
        assert r1[0] == pytest.approx(r_want, abs=1e-9)
        assert abs((th1[0] - th_want + np.pi) % (2 * np.pi) - np.pi) < 1e-9


@pytest.mark.realdata
def test_the_rule_leaves_an_engaged_fighter_to_the_graph_and_brings_a_far_one_round_and_in(boxing_library):
    lib = boxing_library
    rule = ClosingRule()
    assert rule.choose(lib.next(0), 1.2, 0.3, lib) is None              # engaged: the graph decides
    with pytest.raises(ValueError, match="engage_r_m"):
        ClosingRule(engage_r_m=0.0)
    # from every action, 3 m away and facing away either way, the opponent standing still: the
    # rule's actions played one after another engage the fighter (a one-action greedy rule,
    # ClosingRule(depth=1), gets caught in the graph's loops and fails from some of these starts)
    times = []
    for m0 in range(lib.n_actions):
        for th0 in (-2.8, 2.8):
            t, r, th, played = rule.rollout(lib, m0, 3.0, th0, max_s=30.0)
            assert rule.engaged(r, th), f"not engaged after {t:.1f} s from action {m0}, theta {th0}"
            for prev, a in zip([m0, *played], played):
                assert a in lib.next(prev)                                  # always a legal action
            times.append(t)
    assert np.mean(times) < 10.0 and max(times) < 20.0                    # measured: 8.4 s, 17.0 s


@pytest.mark.realdata
def test_closing_agent_takes_the_rule_when_disengaged_and_the_inner_agent_otherwise(boxing_library):
    from igraph_fight.controller import Observation
    from tracker.bouts.agents import ClosingAgent, DecisionContext, MenuAgent

    lib = boxing_library
    inner = MenuAgent([], "inner")
    inner.reset(None, 0, np.random.default_rng(1))
    agent = ClosingAgent(inner, lib)
    agent.reset(None, 0, np.random.default_rng(1))
    menu = lib.next(0)

    def ctx(r, th):
        obs = Observation(r=r, theta_self=th, theta_other=0.0, m_self=0, m_other=0, f_other=0)
        return DecisionContext(0, 0.0, obs, menu, None, np.zeros(1), {}, 0)

    far = ctx(3.0, 2.5)
    want = ClosingRule().choose(menu, 3.0, 2.5, lib)
    assert agent.peek(far, 0) == want and agent.closing == 0                  # peek counts nothing
    assert agent.step(far, 0) == want and agent.closing == 1
    near = ctx(1.0, 0.1)
    guess = agent.peek(near, 0)                                              # the inner agent's peek
    assert agent.step(near, 0) == guess and agent.closing == 1
    assert agent.name == "inner+close"


@pytest.mark.realdata
def test_make_agent_reads_the_close_option(boxing_library, tiny_graph_file, tmp_path):
    import planner.presets
    from tracker.bouts.agents import ClosingAgent
    from tracker.bouts.loaders import make_agent
    ag = make_agent("infighter+close=1.4,0.8", str(tiny_graph_file), boxing_library, 2)
    assert isinstance(ag, ClosingAgent) and ag.rule == ClosingRule(engage_r_m=1.4, engage_theta_rad=0.8)
    assert ag.controller.style == "infighter"                              # the inner fighter's attributes
    ag.controller.close()
    styled = tmp_path / "my+infighter.toml"                                # a "+" inside a style file's path
    styled.write_text((Path(planner.presets.__file__).parent / "infighter.toml").read_text())
    ag = make_agent(f"{styled}+close", str(tiny_graph_file), boxing_library, 2)
    assert isinstance(ag, ClosingAgent) and ag.rule == ClosingRule()
    ag.controller.close()
    ag = make_agent("infighter+close=1.4,0.8:avoid=60,7", str(tiny_graph_file), boxing_library, 2)
    assert ag.rule == ClosingRule(engage_r_m=1.4, engage_theta_rad=0.8, avoid=(60, 7))
    ag.controller.close()
    with pytest.raises(ValueError, match="outside the library"):
        make_agent(f"infighter+close:avoid={boxing_library.n_actions}", str(tiny_graph_file), boxing_library, 2)
    for bad in ("infighter+close=near", "infighter+close+close", "infighter+close:avoid=jab", "infighter+close:near=1"):
        with pytest.raises(ValueError, match="close"):
            make_agent(bad, str(tiny_graph_file), boxing_library, 2)


@pytest.mark.realdata
def test_the_rule_does_not_launch_avoided_actions_unless_nothing_else_is_legal(boxing_library):
    lib = boxing_library
    plain = ClosingRule()
    menu = lib.next(0)
    first = plain.choose(menu, 3.0, 2.5, lib)
    avoiding = ClosingRule(avoid=(first,))
    second = avoiding.choose(menu, 3.0, 2.5, lib)
    assert second is not None and second != first and second in menu
    assert avoiding.choose(np.array([first]), 3.0, 2.5, lib) == first      # the only legal action
    t, r, th, played = avoiding.rollout(lib, 0, 3.0, 2.5, max_s=30.0)
    assert avoiding.engaged(r, th) and first not in played[:1]


def test_fall_odds_counts_falls_in_and_right_after_each_action(tmp_path):
    import json

    from research.fall_odds import fall_odds, main
    log = [  # fighter 0 plays 5 (0-1 s), 7 (1-2 s), 5 (2-3 s), 9 (3-4 s); falls at 1.5 s and 3.2 s
        {"type": "action", "t": 0.0, "player": 0, "action": 5}, {"type": "action", "t": 0.0, "player": 1, "action": 7},
        {"type": "action", "t": 1.0, "player": 0, "action": 7}, {"type": "fall", "t": 1.5, "player": 0},
        {"type": "action", "t": 2.0, "player": 0, "action": 5}, {"type": "action", "t": 3.0, "player": 0, "action": 9},
        {"type": "fall", "t": 3.2, "player": 0}, {"type": "fall", "t": 3.5, "player": 1}]
    d = tmp_path / "bout"
    d.mkdir()
    (d / "log.jsonl").write_text("\n".join(json.dumps(e) for e in log))
    (d / "summary.json").write_text(json.dumps({"seconds": 4.0}))
    fo = fall_odds([d], player=0, n_actions=10)
    assert fo.plays[[5, 7, 9]].tolist() == [2, 1, 1] and fo.plays.sum() == 4
    assert fo.falls_in[[5, 7, 9]].tolist() == [0, 1, 1]
    assert fo.falls_next[[5, 7, 9]].tolist() == [2, 0, 0]     # 5 came right before both falls
    assert fo.seconds[5] == pytest.approx(2.0) and fo.mean() == pytest.approx(4 / 4)
    assert fo.suggest_avoid(min_plays=2, factor=1.0) == [5]
    assert fall_odds([d], player=1).plays[7] == 1
    assert main([str(tmp_path / "missing")]) == 2


def test_physics_rl_styles_keep_the_closing_rules_commas():
    from tracker.bouts.rl_eval import split_styles
    assert split_styles("infighter,outboxer") == ["infighter", "outboxer"]
    assert split_styles("infighter+close=1.4,0.8:avoid=7,60,outboxer+phys+close") == [
        "infighter+close=1.4,0.8:avoid=7,60", "outboxer+phys+close"]
