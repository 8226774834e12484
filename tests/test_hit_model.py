"""Physically measured hit odds (tracker.bouts.hit_model): the controller's per-action terms are the
lookahead's, labels come from the right action instance and window, training recovers a planted
rule, the agent scores with the odds, and collection -> training -> a physics bout runs end to end."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from tracker.bouts.hit_model import HitModel
from tracker.learn.train_hit_model import HitModelConfig, label_decisions, load_data, train


def test_labels_given_by_action_instance_and_received_inside_the_action_span():
    nf = np.array([10, 20])
    rows = [("x0", 0, 0, 1), ("x1", 10, 1, 2), ("x2", 95, 1, 3)]      # (x, decision step, action, instance)
    hits = [{"attacker": 0, "victim": 1, "inst": 2, "frame": 12},       # fighter 0's 2nd instance lands
            {"attacker": 1, "victim": 0, "inst": 7, "frame": 9},        # fighter 0 hit during its 1st action
            {"attacker": 1, "victim": 0, "inst": 8, "frame": 30}]       # ... at its 2nd action's last step + 0
    falls = [{"player": 0, "t": 11 / 30}, {"player": 1, "t": 1 / 30}]
    X, y, acts = label_decisions(rows, 0, hits, nf, n_steps=100, falls=falls)
    assert X == ["x0", "x1"]                       # the third runs past the bout's end: dropped
    # frame 30 = 10 + 20: outside [10, 30); fighter 0 fell at step 11, during its 2nd action
    assert y == [(False, True, False), (True, False, True)]
    assert acts == [0, 1]


def _synthetic(n=4000, seed=0, n_actions=6, n_kinds=12):
    rng = np.random.default_rng(seed)
    d = n_actions + 14 + 4 + n_kinds + 14
    X = rng.normal(size=(n, d))
    X[:, :n_actions] = 0
    X[np.arange(n), rng.integers(n_actions, size=n)] = 1
    fist = X[:, -2]                                   # the decider's fist-to-target distance column
    given = (fist < -0.8) & (X[:, 2] == 1)            # only action 2 lands, and only when close
    recv = rng.random(n) < 0.1                        # noise: nothing to learn
    y = np.stack([given, recv], 1).astype(np.int8)
    return {"X": X, "y": y, "action": X[:, :n_actions].argmax(1), "seed": rng.integers(0, 50, size=n),
            "rl": np.zeros(n, np.int8), "meta": {}}


def test_training_recovers_a_planted_rule_on_held_out_bouts():
    data = _synthetic()
    model, rep = train(data, HitModelConfig(epochs=25, seed=1), n_actions=6, log=lambda s: None)
    assert rep["given"]["auc_model"] > 0.95
    assert 0.35 < rep["received"]["auc_model"] < 0.65       # noise stays noise
    assert rep["given"]["log_loss"] < rep["given"]["log_loss_base_rate"]
    p = model.predict(data["X"][:5])
    assert p.shape == (5, 2) and ((p >= 0) & (p <= 1)).all()


def test_calibrated_style_scales_the_hit_terms_by_the_held_out_realisation_rates():
    from planner import load_style
    from tracker.bouts.hit_model import calibrated_style
    st = load_style("infighter")
    m = HitModel(None, np.zeros(1), np.ones(1), {"report": {"given": {"rate_when_kinematic_predicts": 0.2},
                                                            "received": {"rate_when_kinematic_predicts": 0.5}}})
    c = calibrated_style(st, m)
    assert c.w_dmg_given == pytest.approx(0.2 * st.w_dmg_given) and c.w_dmg_received == pytest.approx(0.5 * st.w_dmg_received)
    assert c.w_def == pytest.approx(0.5 * st.w_def) and (c.d_p, c.w_d, c.w_theta) == (st.d_p, st.w_d, st.w_theta)
    assert c.kind_pref == st.kind_pref


def test_kind_table_rates_per_action_kind():
    from types import SimpleNamespace
    from tracker.learn.train_hit_model import kind_table
    lib = SimpleNamespace(n_frames=[30, 15], labels=["jab", "guard"])
    data = {"action": np.array([0, 0, 1, 1]), "y": np.array([[1, 0, 1], [0, 0, 0], [0, 1, 1], [0, 0, 0]])}
    jab, guard = sorted(kind_table(data, lib), key=lambda r: r["kind"] != "jab")
    assert (jab["n"], jab["mean_s"], jab["given"], jab["received"], jab["fell"]) == (2, 1.0, 0.5, 0.0, 0.5)
    assert jab["falls_per_min"] == pytest.approx(30.0)          # one fall in 2 s of jabs
    assert guard["falls_per_min"] == pytest.approx(60.0)        # one in 1 s of guard
    assert "fell" not in kind_table({"action": data["action"], "y": data["y"][:, :2]}, lib)[0]


def test_physical_edge_features_expect_hits_at_the_measured_rates():
    from tracker.bouts.hit_model import physical_edge_features
    kind_names = ["jab", "guard"]
    action_kinds = np.array([0, 0, 1])            # two jab actions, one guard
    # per action: decisions / landed with a kinematic prediction, then without
    rates = [[10, 2, 100, 5], [10, 3, 100, 5], [0, 0, 50, 0]]
    m = HitModel(None, np.zeros(1), np.ones(1), {"action_rates": rates,
                                                 "report": {"received": {"rate_when_kinematic_predicts": 0.2}}})
    arrays = {"feat_kind": np.array([0, 0, 1, -1]), "feat_dmg_given": np.array([2.0, 0.0, 0.0, 1.0], np.float32),
              "feat_dmg_received": np.array([0.0, 1.0, 3.0, 0.0], np.float32)}
    f = physical_edge_features(arrays, m, action_kinds, kind_names)
    # a predicted jab hit: 5/20 of it; a jab the simulator says misses: 10/200; a guard: nothing;
    # an edge without a kind keeps its value
    assert f["feat_dmg_given"] == pytest.approx([0.5, 0.05, 0.0, 1.0])
    assert f["feat_dmg_received"] == pytest.approx([0.0, 0.2, 0.6, 0.0])
    assert f["feat_dmg_given"].dtype == np.float32
    with pytest.raises(ValueError, match="per-action rates"):
        physical_edge_features(arrays, HitModel(None, np.zeros(1), np.ones(1), {}), action_kinds, kind_names)


def test_bad_sample_file_is_named(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="bad.npz"):
        load_data(bad)


@pytest.mark.realdata
def test_menu_terms_score_is_the_lookahead_and_the_agent_uses_the_odds(tiny_graph_file):
    from igraph_fight.controller import (
        MT_ACTION, MT_DEF, MT_GIVEN, MT_POS, MT_RECEIVED, MT_VALUE, NPCController, Observation)
    from motion_graph.classify import KINDS
    from tracker.bouts.agents import DecisionContext
    from tracker.bouts.hit_model import PhysIGAgent
    npc = NPCController(tiny_graph_file, style="infighter", depth=3)
    A = npc.library.n_actions
    rng = np.random.default_rng(0)
    for _ in range(40):
        o = Observation(float(rng.uniform(0.5, 3)), float(rng.uniform(-3, 3)), float(rng.uniform(-3, 3)),
                        int(rng.integers(A)), int(rng.integers(A)), 3, 0)
        la, q = npc._lookahead(npc._table, o)
        mt = npc.menu_terms(o)
        sc = -mt[:, MT_POS] + mt[:, MT_GIVEN] - mt[:, MT_RECEIVED] + mt[:, MT_DEF] + mt[:, MT_VALUE]
        j = int(np.argmax(sc))
        assert int(mt[j, MT_ACTION]) == la and sc[j] == pytest.approx(q)
    # a model that is sure action `a` lands and nothing else does: a's score rises by exactly
    # w_dmg_given * pref(kind of a) over a model that says nothing lands
    o = Observation(1.0, 0.1, -0.2, 0, 0, 3, 0)
    menu = npc.library.next(0)
    a = int(menu[len(menu) // 2])
    n_in = A + 14 + 4 + len(KINDS) + 14

    def model(logit_a: float) -> HitModel:
        net = torch.nn.Linear(n_in, 2)
        with torch.no_grad():
            net.weight.zero_()
            net.bias[:] = -40.0
            net.weight[0, a] = logit_a
        return HitModel(net, np.zeros(n_in), np.ones(n_in), {"n_actions": A, "n_kinds": len(KINDS)})

    ctx = DecisionContext(0, 0.0, o, np.asarray(menu), None, np.zeros(14), {}, 0)
    mt0, p0, q0 = PhysIGAgent(npc, model(0.0)).scores(ctx)
    mt1, p1, q1 = PhysIGAgent(npc, model(80.0)).scores(ctx)
    j = int(np.nonzero(mt1[:, MT_ACTION] == a)[0][0])
    st = npc.style_def
    k = npc.action_kinds[a]
    from planner import kind_preferences
    pref = kind_preferences(st, npc.kind_names)[k] if k >= 0 else 1.0
    assert p1[j, 0] == pytest.approx(1.0) and p0[j, 0] == pytest.approx(0.0, abs=1e-12)
    assert q1[j] - q0[j] == pytest.approx(st.w_dmg_given * pref)
    others = np.arange(len(q0)) != j
    assert np.allclose(q1[others], q0[others])
    sure = PhysIGAgent(npc, model(80.0))
    assert sure.peek(ctx, 0) == sure.step(ctx, 0) == int(mt1[int(np.argmax(q1)), MT_ACTION])   # peek: step, uncounted
    assert sure.decisions == 1
    with pytest.raises(ValueError, match="future must be one of"):
        PhysIGAgent(npc, model(0.0), future="later")
    assert PhysIGAgent(npc, model(0.0), future="none").scores(ctx)[2] == pytest.approx(
        q0 - mt0[:, MT_VALUE])                                          # no later plies: the values drop out
    with pytest.raises(ValueError, match="trained on 5 actions"):
        PhysIGAgent(npc, HitModel(torch.nn.Linear(3, 2), np.zeros(3), np.ones(3), {"n_actions": 5, "n_kinds": 12}))
    npc.close()


@pytest.mark.realdata
def test_collect_train_and_play_a_physics_bout(tiny_default_graph_file, tmp_path):
    from tracker.learn.train_hit_model import collect
    from tracker.bouts.hit_model import load_hit_model
    from tracker.bouts.rl_eval import evaluate_vs_rl
    out = tmp_path / "hits.npz"
    r = collect(str(tiny_default_graph_file), 2, out, seconds=2.0, seed0=5, workers=1, tracker="pd")
    d = load_data(out)
    from motion_graph.classify import KINDS
    assert r["samples"] == len(d["X"]) > 0 and d["X"].shape[1] == 119 + 14 + 4 + len(KINDS) + 14
    assert set(np.unique(d["seed"])) <= {5, 6} and d["y"].shape == (len(d["X"]), 3)
    assert (d["rl"] == 1).any() and (d["rl"] == 0).any()       # seed 6: IG vs the RL baseline, both recorded
    model, _ = train(d, HitModelConfig(epochs=2, holdout=0.0), log=lambda s: None)
    model.save(tmp_path / "hm.pt")
    back = load_hit_model(tmp_path / "hm.pt")
    assert np.allclose(back.predict(d["X"][:3]), model.predict(d["X"][:3]))
    res = evaluate_vs_rl(str(tiny_default_graph_file), None, ["outboxer"], n_bouts=1, seconds=1.0, depth=2, tracker="pd",
                         log=lambda s: None, hit_model=str(tmp_path / "hm.pt"), future="kinematic")
    assert res["hit_model"] == str(tmp_path / "hm.pt") and res["styles"]["outboxer"]["bouts"][0]["decisions_a"] >= 1
    with pytest.raises(ValueError, match="no held-out report"):      # calibration needs the held-out rates
        evaluate_vs_rl(str(tiny_default_graph_file), None, ["outboxer"], n_bouts=1, seconds=1.0, depth=2, tracker="pd",
                       log=lambda s: None, hit_model=str(tmp_path / "hm.pt"), future="calibrated")
    with pytest.raises(ValueError, match="hm_bad.pt"):
        (tmp_path / "hm_bad.pt").write_bytes(b"junk")
        load_hit_model(tmp_path / "hm_bad.pt")


@pytest.mark.realdata
def test_shipped_hit_model_beats_the_kinematic_prediction_on_its_held_out_bouts(default_library, tiny_default_graph_file,
                                                                                  tiny_graph_file, boxing_library):
    from planner import load_style
    from tracker.bouts.loaders import make_agent
    from tracker.bouts.hit_model import calibrated_style, load_hit_model
    m = load_hit_model()
    assert m.meta["n_actions"] == default_library.n_actions
    # the documented data (docs/tracker.md): 720 bouts of 60 s in four rounds, 20% of them held out
    assert m.meta["samples"] > 75_000 and len(m.meta["held_out_seeds"]) == 144
    rep = m.meta["report"]
    for head in ("given", "received"):
        assert rep[head]["auc_model"] > rep[head]["auc_kinematic"] + 0.25
        assert rep[head]["log_loss"] < rep[head]["log_loss_base_rate"]
        assert 0.05 < rep[head]["rate_when_kinematic_predicts"] < 0.5
    assert calibrated_style(load_style("infighter"), m).w_dmg_given < load_style("infighter").w_dmg_given
    agent = make_agent("infighter+phys", str(tiny_default_graph_file), default_library, 2)   # the shipped model by default
    assert agent.future == "calibrated" and agent.name == "infighter(2, phys)"
    assert agent.controller.style == "infighter~phys"          # the table of calibrated_style
    agent.set_style("outboxer")                                # a run-time swap keeps the calibration
    assert agent.style.name == "outboxer" and agent.controller.style == "outboxer~phys"
    agent.controller.close()
    from tracker.bouts.hit_model import phys_fighter
    pf = phys_fighter(str(tiny_default_graph_file), default_library, "infighter", 2, m, future="physical")
    g = pf.controller.graph.arrays
    strike = np.isin(g["feat_kind"], [0, 1]) & (g["feat_dmg_given"] == 0)    # jabs / straights the simulator says miss
    assert strike.any() and (pf.controller._arrays["feat_dmg_given"][strike] > 0).all()
    pf.controller.close()
    from igraph_fight.controller import NPCController
    with pytest.raises(ValueError, match="edge_features"):
        NPCController(str(tiny_graph_file), boxing_library, edge_features={"feat_dmg_given": np.zeros(3)})
    with pytest.raises(ValueError, match="STYLE\\+phys"):
        make_agent("infighter+magic", str(tiny_graph_file), boxing_library, 2)
