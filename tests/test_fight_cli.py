"""`igraph-fight fight` (kinematic): artifacts, determinism, the decision-rule options."""
from __future__ import annotations

import json
from pathlib import Path


def test_fight_writes_deterministic_artifacts_with_either_decision_rule(tiny_graph_file, tmp_path, capsys):
    from igraph_fight.cli import main
    runs = []
    for i, rule in enumerate(("exact2", "exact2", "table")):
        out = tmp_path / f"run{i}"
        assert main(["fight", "--graph", str(tiny_graph_file), "--a", "infighter", "--b", "outboxer", "--depth-a", "3",
                     "--depth-b", "2", "--first-ply-a", rule, "--seconds", "4", "--seed", "2", "--out", str(out),
                     "--json"]) == 0
        s = json.loads(capsys.readouterr().out)
        assert set(s["artifacts"]) == {"log", "summary", "plot", "animation", "bvh_a", "bvh_b"}
        for p in s["artifacts"].values():
            assert Path(p).is_file() and Path(p).stat().st_size > 0 and Path(p).parent == out
        runs.append(s)
    assert runs[0]["a"].endswith("+exact2") and not runs[2]["a"].endswith("+exact2")
    drop = ("artifacts", "wall_s", "style_swap_ms")
    same = {k: v for k, v in runs[0].items() if k not in drop}
    assert same == {k: v for k, v in runs[1].items() if k not in drop}
    # physics bouts decide from the policy table: the option is refused there, with a message
    assert main(["fight", "--graph", str(tiny_graph_file), "--physics", "--first-ply-a", "exact2",
                 "--out", str(tmp_path / "p")]) == 2
    assert "kinematic bouts only" in capsys.readouterr().err
    # and the get-up rule belongs to physics bouts: refused on a kinematic one
    assert main(["fight", "--graph", str(tiny_graph_file), "--reset-place", "fall", "--out", str(tmp_path / "k")]) == 2
    assert main(["fight", "--graph", str(tiny_graph_file), "--tracker", "search", "--out", str(tmp_path / "k")]) == 2
    assert "physics bouts only" in capsys.readouterr().err
    assert main(["fight", "--graph", str(tiny_graph_file), "--reset-facing", "fall", "--out", str(tmp_path / "k")]) == 2
    assert "physics bouts only" in capsys.readouterr().err
