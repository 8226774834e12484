"""The tracker's commands under `igraph-fight tracker` (bouts, rl, hit-model beside eval, render,
train, model), the product's refusal of research-only trackers, and the physics DecisionContext's
share of the agent protocol (legal_actions)."""
from __future__ import annotations

import numpy as np
import pytest

from igraph_fight.cli import main


@pytest.mark.parametrize("cmd", [["tracker", "bouts", "fight"], ["tracker", "bouts", "series"],
                                 ["tracker", "rl", "train"], ["tracker", "rl", "eval"],
                                 ["tracker", "hit-model", "collect"], ["tracker", "hit-model", "kinds"],
                                 ["tracker", "hit-model", "train"], ["tracker", "eval"], ["tracker", "train"]])
def test_tracker_subcommands_parse(cmd, capsys):
    with pytest.raises(SystemExit) as e:
        main([*cmd, "--help"])
    assert e.value.code == 0 and "usage: igraph-fight " + " ".join(cmd) in capsys.readouterr().out


def test_product_tracker_loader_points_search_specs_to_research():
    from tracker.bouts.loaders import load_tracker
    with pytest.raises(ValueError, match="research.bout_search"):
        load_tracker("search:4,12")
    obj = object()
    assert load_tracker(obj) is obj                       # a tracker object is used as it is


def test_decision_context_answers_legal_actions():
    from tracker.bouts.agents import DecisionContext
    menu = np.array([3, 5, 8])
    ctx = DecisionContext(1, 0.0, None, menu, None, np.zeros(14), {}, 0)
    assert ctx.legal_actions(1) is menu
    with pytest.raises(ValueError):
        ctx.legal_actions(0)


@pytest.mark.realdata
def test_ground_report_puts_the_lower_foot_on_the_floor(capsys, boxing_library_file):
    import json
    assert main(["tracker", "ground", "--library", boxing_library_file, "--walks", "2", "--actions", "4",
                 "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["before"]["lower_foot_p90_cm"] > 1.5                   # the captured feet float ...
    assert abs(rep["after"]["lower_foot_median_cm"]) <= 1.0            # ... the grounded ones stand
    assert rep["after"]["both_up_share"] < 0.1 < rep["before"]["both_up_share"]


def test_loader_default_is_the_assisted_tracker_when_shipped(monkeypatch):
    from tracker.bouts.loaders import load_tracker
    from tracker.track.assisted_policy import DEFAULT_ASSISTED_CKPT
    monkeypatch.delenv("IGRAPH_FIGHT_TRACKER", raising=False)
    if not DEFAULT_ASSISTED_CKPT.is_file():
        pytest.skip("no shipped assisted tracker")
    trk = load_tracker(None)
    assert trk.name == "learned" and not trk.assist_off and "assisted" in trk.describe()
    assert load_tracker("assisted-off").assist_config().label() == "physics (no assist)"
