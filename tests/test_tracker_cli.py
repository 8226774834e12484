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
