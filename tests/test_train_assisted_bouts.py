"""Training the assisted tracker inside physics bouts: one short bout continues the shipped
checkpoint into a checkpoint of the same format, with its bout curve and budget."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.realdata


def test_one_bout_continues_the_shipped_checkpoint(tmp_path, small_graph):
    from igraph_fight.checkpoint import load_checkpoint
    from tracker.learn.train_assisted_bouts import BoutTrainConfig, train_in_bouts
    from tracker.track.assisted_policy import DEFAULT_ASSISTED_CKPT, FORMAT, VERSION, load_assisted
    graph, _ = small_graph
    before = load_checkpoint(DEFAULT_ASSISTED_CKPT, FORMAT, (VERSION,), "assisted-tracker checkpoint")
    out = tmp_path / "a.pt"
    r = train_in_bouts(str(out), 1.0, graph, bout_cfg=BoutTrainConfig(depth=2, bout_seconds=2.0, walks_per_bout=1),
                       overrides={"n_envs": 4, "horizon": 8, "pool_walks": 3, "walk_actions": 3},
                       progress=False, log=None, max_iterations=2)
    assert r["bouts"] == 2 and out.is_file() and (tmp_path / "a.pt.png").is_file()
    ck = load_checkpoint(out, FORMAT, (VERSION,), "assisted-tracker checkpoint")
    assert ck["budget"]["runs"] == before["budget"]["runs"] + 1
    n0 = len(before.get("bout_curve", []))              # the run continues the checkpoint's bout curve
    rows = ck["bout_curve"][n0:]
    assert [row["bout"] for row in rows] == [n0, n0 + 1]
    assert [row["a"] for row in rows] == (["infighter", "outboxer"] if n0 % 2 == 0 else ["outboxer", "infighter"])
    # a fighter's standing steps of a 2 s bout (60 control steps each) are the samples, then one
    # walk iteration of 4 slots x 8 steps per bout
    assert 0 < rows[0]["bout_samples"] <= 120 and all(row["walk_samples"] == 32 for row in rows)
    assert ck["budget"]["samples"] - before["budget"]["samples"] == \
        sum(row["bout_samples"] + row["walk_samples"] for row in rows)
    assert ck["budget"]["iterations"] - before["budget"]["iterations"] == 4
    assert ck["cap"] == before["cap"] and ck["config"]["bout_training"]["bout_seconds"] == 2.0
    moved = any(not np.array_equal(np.asarray(ck["actor"][k]), np.asarray(before["actor"][k])) for k in ck["actor"])
    assert moved                                    # the PPO step changed the policy
    ctrl = load_assisted(out)                       # the runtime reads it like any assisted checkpoint
    assert ctrl.n_act == 66 and ctrl.cap == before["cap"]


def test_bout_training_refuses_a_bad_style_pair(tmp_path, small_graph):
    from tracker.learn.train_assisted_bouts import BoutTrainConfig, train_in_bouts
    graph, _ = small_graph
    with pytest.raises(ValueError, match="two fighters"):
        train_in_bouts(str(tmp_path / "a.pt"), 1.0, graph, bout_cfg=BoutTrainConfig(styles=("infighter",)),
                       progress=False, log=None, max_iterations=1)
    with pytest.raises(ValueError, match="walks_per_bout"):
        train_in_bouts(str(tmp_path / "a.pt"), 1.0, graph, bout_cfg=BoutTrainConfig(walks_per_bout=-1),
                       progress=False, log=None, max_iterations=1)
