"""Strategy swap on the real CMU boxing graph (examples/strategy_swap.py): a mid-bout switch from
outboxer to infighter shortens the distance the fighter keeps, measured against same-seed control
bouts in which it stays an outboxer (identical up to the swap, so only the swap differs)."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

_EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "strategy_swap.py"

SECONDS = 40.0          # 20 s per phase
SEEDS = range(1, 11)    # ten swap bouts + ten control bouts, aggregated
MARGIN_M = 0.05         # required mean shortening of the distance after the swap (metres)


def _example():
    spec = importlib.util.spec_from_file_location("strategy_swap_example", _EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def ex():
    return _example()


@pytest.fixture(scope="module")
def setup(ex, small_graph):
    graph, lib = small_graph
    s = ex.SwapSetup(graph, lib, opponent="infighter", depth=5, seconds=SECONDS)
    yield s
    s.close()


def test_library_punch_kinds_are_reported(ex, small_graph):
    _, lib = small_graph
    kinds = ex.library_punch_kinds(lib)
    assert set(kinds) == {"jab", "straight", "hook", "uppercut"}
    # what the shared CMU data holds (the classifier finds jabs and straights only)
    assert kinds["jab"] > 0 and kinds["straight"] > 0


def test_outboxer_keeps_a_larger_distance_than_after_switching_to_infighter(ex, setup, small_graph):
    exp = ex.swap_experiment(setup, "outboxer", "infighter", SEEDS, SECONDS / 2, skip=2.0)
    # identical up to the swap: the first phases agree exactly (the comparison is paired)
    for r in exp["rows"]:
        assert r["swap"]["before"]["mean_distance_m"] == r["control"]["before"]["mean_distance_m"]
    d = exp["after_distance_control_minus_swap_m"]
    assert d > MARGIN_M, (d, exp["after_distance_diffs_m"])
    assert np.mean(np.array(exp["after_distance_diffs_m"]) > 0) >= 0.6, exp["after_distance_diffs_m"]
    # the infighter throws a larger share of hooks/uppercuts (the outboxer of straights) where the
    # library holds both groups; the CMU takes hold jabs and straights only (then every punch is
    # a straight in both phases and there is nothing to compare)
    _, lib = small_graph
    kinds = ex.library_punch_kinds(lib)
    if kinds["hook"] + kinds["uppercut"] > 0 and kinds["jab"] + kinds["straight"] > 0:
        assert exp["control_after"]["straight_share"] > exp["swap_after"]["straight_share"]
    else:
        assert exp["swap_after"]["hook_uppercut_share"] in (0.0,) or np.isnan(exp["swap_after"]["hook_uppercut_share"])


def test_the_distance_assertion_fails_when_the_styles_are_equal(ex, setup):
    """The margin is not met by chance: a real swap (policy recomputed and swapped in) to a style
    with the outboxer's weights under another name changes nothing."""
    from dataclasses import replace

    from planner import load_style

    same = replace(load_style("outboxer"), name="outboxer_again")
    exp = ex.swap_experiment(setup, "outboxer", same, list(SEEDS)[:3], SECONDS / 2, skip=2.0)
    assert setup.swap_ms  # the swap happened
    assert exp["after_distance_control_minus_swap_m"] == 0.0
    assert not exp["after_distance_control_minus_swap_m"] > MARGIN_M
