"""The physics RL baseline (tracker.bouts.rl_agent): the semi-MDP advantage estimate by hand, a short
self-play run that writes a checkpoint and resumes from it, the checkpoint's library check, the
override parser's errors, and an evaluation bout of a planner fighter against the trained policy."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from tracker.bouts.rl_agent import RLConfig, load_rl_agent, load_rl_checkpoint
from tracker.learn.train_physics_rl import gae, parse_overrides


def test_gae_discounts_by_the_decisions_length_and_stops_at_episode_ends():
    cfg = RLConfig(gamma_step=0.9, lam=0.5)
    data = {"reward": np.array([1.0, 2.0, 3.0]), "value": np.array([0.5, 1.0, 4.0]),
            "steps": np.array([2, 1, 3]), "last": np.array([False, True, True])}
    adv, ret = gae(data, cfg)
    # episode 1: two decisions, the first 2 control steps long (discount 0.81), the second ends it
    d1 = 2.0 - 1.0                       # no bootstrap after the last decision
    d0 = 1.0 + 0.81 * 1.0 - 0.5
    # episode 2: one decision
    d2 = 3.0 - 4.0
    assert adv == pytest.approx([d0 + 0.81 * 0.5 * d1, d1, d2])
    assert ret == pytest.approx(adv + data["value"])


def test_override_parser_names_bad_fields_and_values():
    assert parse_overrides(["lr=1e-4", "hidden=64,32", "n_workers=1"]) == {"lr": 1e-4, "hidden": (64, 32), "n_workers": 1}
    with pytest.raises(ValueError, match="unknown RLConfig field 'lr_actor'"):
        parse_overrides(["lr_actor=1"])
    with pytest.raises(ValueError, match="n_workers=.*int"):
        parse_overrides(["n_workers=two"])
    with pytest.raises(ValueError, match="KEY=VALUE"):
        parse_overrides(["lr"])


@pytest.mark.realdata
def test_short_self_play_run_writes_a_checkpoint_that_resumes(tiny_graph_file, tmp_path):
    from tracker.learn.train_physics_rl import train
    cfg = RLConfig(n_workers=1, decisions_per_worker=6, episode_s=2.0, epochs=1, minibatch=8, snapshot_every=1,
                   ckpt_every_min=100.0, seed=3)
    out = tmp_path / "rl.pt"
    train(str(tiny_graph_file), "pd", str(out), minutes=10.0, cfg=cfg, max_iterations=2, log=lambda s: None)
    ck = load_rl_checkpoint(out)
    assert ck["final"] and ck["budget"]["iterations"] == 2 and len(ck["history"]) == 2
    assert ck["budget"]["decisions"] >= 12 and ck["budget"]["sim_s"] > 0
    assert len(ck["pool"]) == 2                      # a snapshot per iteration kept for self-play
    assert (out.parent / "rl.pt.png").is_file()
    w0 = {k: v.clone() for k, v in ck["model"].items()}
    train(str(tiny_graph_file), "pd", str(out), minutes=10.0, cfg=cfg, resume=str(out), max_iterations=1,
          log=lambda s: None)
    ck2 = load_rl_checkpoint(out)
    assert ck2["budget"]["iterations"] == 3 and len(ck2["history"]) == 3
    assert ck2["budget"]["decisions"] > ck["budget"]["decisions"]
    assert len(ck2["pool"]) == 3
    assert any(not torch.equal(w0[k], ck2["model"][k]) for k in w0)   # the resumed run updated the policy

    # the checkpoint as a bout agent: library size checked, missing file named
    lib_wrong = SimpleNamespace(n_actions=int(ck["n_actions"]) + 1, n_frames=np.ones(int(ck["n_actions"]) + 1))
    with pytest.raises(ValueError, match="rl.pt was trained on"):
        load_rl_agent(out, lib_wrong)
    with pytest.raises(FileNotFoundError, match="nope.pt"):
        load_rl_agent(tmp_path / "nope.pt", lib_wrong)

    # planner + tracker against it: one short bout per style, score = IG hits - RL hits
    from tracker.bouts.rl_eval import evaluate_vs_rl
    res = evaluate_vs_rl(str(tiny_graph_file), str(out), ["infighter"], n_bouts=1, seconds=2.0, depth=2,
                         tracker="pd", log=lambda s: None)
    row = res["styles"]["infighter"]["bouts"][0]
    assert row["score"] == row["hits_a"] - row["hits_b"]
    assert res["styles"]["infighter"]["wins"] + res["styles"]["infighter"]["draws"] + res["styles"]["infighter"]["losses"] == 1
    for side in ("kind_share_ig", "kind_share_rl"):          # what each side chose, pooled over the bouts
        shares = res["styles"]["infighter"][side]
        assert shares and sum(shares.values()) == pytest.approx(1.0, abs=1e-3)
    # two worker processes play the same bouts (a bout depends on its seed only)
    r1 = evaluate_vs_rl(str(tiny_graph_file), str(out), ["infighter"], n_bouts=2, seconds=1.0, depth=2,
                        tracker="pd", log=lambda s: None)
    r2 = evaluate_vs_rl(str(tiny_graph_file), str(out), ["infighter"], n_bouts=2, seconds=1.0, depth=2,
                        tracker="pd", log=lambda s: None, workers=2)
    strip = lambda rows: [{k: v for k, v in r.items() if k != "realtime_factor"} for r in rows]  # noqa: E731
    assert strip(r2["styles"]["infighter"]["bouts"]) == strip(r1["styles"]["infighter"]["bouts"])
    # the IG fighters can search their first two plies exactly (NPCController's first_ply)
    res2 = evaluate_vs_rl(str(tiny_graph_file), str(out), ["infighter"], n_bouts=1, seconds=1.0, depth=2,
                          tracker="pd", log=lambda s: None, first_ply="exact2")
    assert res2["first_ply"] == "exact2" and res2["styles"]["infighter"]["bouts"][0]["decisions_a"] >= 1
    with pytest.raises(ValueError, match="first_ply"):                  # the option reaches the controller
        evaluate_vs_rl(str(tiny_graph_file), str(out), ["infighter"], n_bouts=1, seconds=1.0, depth=2,
                       tracker="pd", log=lambda s: None, first_ply="bogus")


@pytest.mark.realdata
def test_shipped_checkpoint_loads_for_the_default_library(default_library):
    from tracker.bouts.rl_agent import DEFAULT_RL_CKPT
    agent = load_rl_agent(None, default_library)
    ck = load_rl_checkpoint(DEFAULT_RL_CKPT)
    assert agent.n_actions == default_library.n_actions == ck["n_actions"]
    # the documented budget (docs/tracker.md): 40 minutes on two workers, 1.12 CPU-hours, 113,376 decisions
    assert ck["final"] and ck["budget"]["worker_cpu_s"] >= 3600 and ck["budget"]["decisions"] >= 90_000
    assert ck["config"]["w_energy"] == 1e-5
