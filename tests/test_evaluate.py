"""`igraph-fight evaluate` on a tiny graph: the JSON contract, determinism across worker counts."""
from __future__ import annotations

import json

import numpy as np
import pytest

from igraph_fight.evaluate.config import EvalConfig
from igraph_fight.evaluate.runner import evaluate, tasks_for
from igraph_fight.stats import mean_ci


@pytest.fixture(scope="module")
def tiny(boxing_files, tmp_path_factory):
    """A small graph (with its library) and two tiny RL checkpoints (infighter, outboxer retrain)."""
    from igraph_fight.build.pipeline import BuildOptions, build_graph
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.learn.train_rl import RLConfig, train
    from motion_graph.library import build_library

    d = tmp_path_factory.mktemp("eval")
    lib = build_library(boxing_files)
    g, _ = build_graph(lib, BuildOptions(max_samples=6_000, n_initial=32, chunk_parents=128, seed_bouts=0), seed=0, workers=1)
    g.save(d / "tiny.igz")
    game = FightGame(lib, GameConfig())
    small = dict(num_envs=2, num_steps=16, episode_seconds=3.0, opponents={"self": 0.5, "random": 0.5})
    train(game, RLConfig(total_decisions=32, **small), out=d / "rl.pt", progress=False)
    train(game, RLConfig(style="outboxer", total_decisions=32, init_from=str(d / "rl.pt"), **small),
          out=d / "rl_out.pt", progress=False)
    return d


def _cfg(tiny, **kw):
    base = dict(graph=str(tiny / "tiny.igz"), opponents=("random", "static", "gametree3", "rl"), depths=(1, 2),
                exact2_depths=(2,),
                bouts=2, seconds=3.0, seed=3, workers=1, rl_checkpoint=str(tiny / "rl.pt"),
                rl_outboxer_checkpoint=str(tiny / "rl_out.pt"), head_to_head=("random",), progress=False)
    base.update(kw)
    return EvalConfig(**base)


def test_evaluate_writes_the_contract_and_is_independent_of_workers(tiny, tmp_path):
    r1 = evaluate(_cfg(tiny, workers=1), tmp_path / "w1")
    r2 = evaluate(_cfg(tiny, workers=2), tmp_path / "w2")
    for k in ("table", "coverage", "decision_us", "rl", "style_swap_ms", "kinds", "results_digest", "machine",
              "package_version", "command"):
        assert k in r1
    cell = r1["table"]["IG(2)"]["gametree3"]
    assert set(("mean", "ci_low", "ci_high", "bouts")) <= set(cell) and cell["bouts"] == 2
    assert cell["ci_low"] <= cell["mean"] <= cell["ci_high"]
    for k in ("train_minutes", "decisions", "retrain_minutes_new_style"):
        assert r1["rl"][k] is not None
    assert r1["style_swap_ms"] > 0 and 0.0 <= r1["coverage"] <= 1.0
    assert set(r1["decision_us"]) >= {"IG(1)", "IG(2)", "IG(2)+exact2", "random", "static", "gametree3", "rl",
                                      "rl_outboxer"}
    assert r1["table"]["IG(2)+exact2"]["gametree3"]["paper"] is None  # no paper value for the hybrid row
    assert r1["results_digest"] == r2["results_digest"]
    assert r1["table"] == r2["table"] and r1["kinds"] == r2["kinds"]
    on_disk = json.loads((tmp_path / "w1" / "results.json").read_text())
    assert on_disk["results_digest"] == r1["results_digest"]
    md = (tmp_path / "w1" / "report.md").read_text()
    assert "Table 1" in md and "[+34]" in md and "[-53]" in md  # paper values beside the IG(1) cells
    assert (tmp_path / "w1" / "rl_curve.png").stat().st_size > 0 and (tmp_path / "w1" / "kinds.png").stat().st_size > 0
    # common random numbers and slot alternation
    bouts = r1["bouts"]
    assert {b["slot"] for b in bouts} == {0, 1}
    assert all(b["slot"] == b["i"] % 2 for b in bouts)
    # another seed, other bouts (the initial distance differs, so the mean distance does)
    r3 = evaluate(_cfg(tiny, seed=4, opponents=("random",), depths=(1,), exact2_depths=(), head_to_head=()),
                  tmp_path / "s4")
    d1 = [b["mean_distance_m"] for b in bouts if b["row"] == "IG(1)" and b["col"] == "random"]
    d3 = [b["mean_distance_m"] for b in r3["bouts"]]
    assert len(d3) == 2 and d1 != d3


def test_tasks_cover_every_cell_with_the_same_bout_indices():
    cfg = EvalConfig(graph="g", opponents=("human", "static"), depths=(1, 3, 5), bouts=4, head_to_head=("random",))
    tasks = tasks_for(cfg)
    table = [t for t in tasks if t["kind"] == "table"]
    assert len(table) == 4 * 2 * 4 and sorted(t["id"] for t in tasks) == list(range(len(tasks)))
    for r in ("IG(1)", "IG(3)", "IG(5)", "IG(5)+exact2"):
        for c in ("human", "static"):
            assert sorted(t["i"] for t in table if t["row"] == r and t["col"] == c) == [0, 1, 2, 3]


def test_mean_ci_is_a_student_t_interval():
    x = np.array([1.0, 2.0, 3.0, 4.0])
    c = mean_ci(x)
    assert c["mean"] == 2.5 and c["bouts"] == 4
    assert c["ci_high"] - c["mean"] == pytest.approx(3.182446 * np.std(x, ddof=1) / 2, rel=1e-5)
    assert mean_ci([5.0])["ci_low"] == 5.0


def test_cli_has_the_commands():
    from igraph_fight.cli import build_parser
    p = build_parser()
    a = p.parse_args(["evaluate", "--graph", "g.igz", "--depths", "1,3", "--workers", "2", "--json"])
    assert a.depths == "1,3" and a.workers == 2 and a.json
    a = p.parse_args(["train-rl", "--graph", "g.igz", "--out", "x.pt", "--style", "outboxer"])
    assert a.style == "outboxer"
