"""The run-time search controller (research/search_controller.py) and parallel walk evaluation:
a one-candidate search is the plain policy exactly (the search restores the state it starts
from), a search run is deterministic, and ``evaluate_walks(workers=2)`` gives a serial run's
metrics."""
from __future__ import annotations

import numpy as np
import pytest
from helpers import walk_qpos

from tracker.track.evaluation import draw_walks, evaluate_walks, make_setup
from tracker.track.pd import PDController
from tracker.track.policy_net import load_policy
from research.search_controller import SearchController, SearchSettings, make_search_controller
from tracker.track.walks import LibraryWalks

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def setup(boxing_library):
    return make_setup(LibraryWalks(boxing_library))


def test_one_candidate_is_the_plain_policy_and_search_is_deterministic(setup):
    walk = draw_walks(setup.source, 1, 3, 4)[0]
    plain = walk_qpos(setup, load_policy(), walk)
    one = walk_qpos(setup, SearchController(load_policy(), SearchSettings(candidates=1, lookahead=6)), walk)
    np.testing.assert_array_equal(plain[0], one[0])
    assert plain[1:] == one[1:]                      # the env's step counter and clock restored too
    s = SearchSettings(candidates=3, lookahead=4, seed=2)
    a = walk_qpos(setup, SearchController(load_policy(), s), walk)
    b = walk_qpos(setup, SearchController(load_policy(), s), walk)
    np.testing.assert_array_equal(a[0], b[0])
    assert not np.array_equal(a[0], plain[0])        # the search did choose offsets
    lay = walk_qpos(setup, SearchController(load_policy(), SearchSettings(candidates=3, lookahead=4, space="layer")), walk)
    assert not np.array_equal(lay[0], plain[0])


def test_search_controller_by_name_and_errors():
    assert make_search_controller("search").name == "search"
    fast = make_search_controller("search-fast")
    assert (fast.s.early_accept, fast.s.incremental, fast.s.first_kept) == (True, True, True)
    with pytest.raises(ValueError, match="'joints' or 'layer'"):
        SearchController(None, SearchSettings(space="hips"))


def test_parallel_walks_match_serial(setup):
    kw = dict(n_walks=3, n_actions=3, seed=6)
    one = evaluate_walks(setup, PDController(), **kw)
    two = evaluate_walks(setup, PDController(), workers=2, **kw)
    for k in ("mean_time_to_fall_s", "completion_rate", "mpjpe_cm", "root_drift_cm", "simulated_s"):
        assert one[k] == two[k], k
