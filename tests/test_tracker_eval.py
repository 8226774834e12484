"""Walk evaluation: the PD baseline's figures are reproducible with a fixed seed; the CLI's JSON."""
from __future__ import annotations

import json

import numpy as np
import pytest

from tracker.track.evaluation import draw_walks, evaluate_walks, make_setup
from tracker.track.pd import PDController
from tracker.track.walks import ClipWindows, LibraryWalks

pytestmark = pytest.mark.realdata

REQUIRED = ("completion_rate", "mean_time_to_fall_s", "mpjpe_cm", "root_drift_cm", "realtime_factor", "controller")
TIMING = ("realtime_factor", "wall_s")


def test_pd_baseline_reproducible_with_fixed_seed(boxing_library_file):
    from motion_graph.library import load_library
    src = LibraryWalks(load_library(boxing_library_file))
    a = evaluate_walks(make_setup(src), PDController(), n_walks=3, n_actions=4, seed=11)
    b = evaluate_walks(make_setup(src), PDController(), n_walks=3, n_actions=4, seed=11)
    strip = lambda m: {k: v for k, v in m.items() if k not in TIMING}  # noqa: E731
    assert strip(a) == strip(b)
    for k in REQUIRED:
        assert k in a
    assert 0.0 <= a["completion_rate"] <= 1.0 and a["mean_time_to_fall_s"] > 0
    assert a["reference_error_cm"] < 1.0
    # The walks depend on the seed only, not on the controller or the setup.
    assert draw_walks(src, 3, 4, 11) == draw_walks(src, 3, 4, 11) != draw_walks(src, 3, 4, 12)


def test_clip_windows_source(boxing_files):
    from motion_graph.io import load_motion
    m = load_motion(boxing_files[1])
    src = ClipWindows([m.slice(0, 8 * 120)])
    walk = src.random_walk(3, np.random.default_rng(0))
    motion = src.sequence_motion(walk)
    assert motion.fps == 30.0 and motion.n_frames == 91


def test_cli_eval_json(boxing_library_file, capsys):
    from igraph_fight.cli import main
    rc = main(["tracker", "eval", "--library", boxing_library_file, "--walks", "2", "--actions", "3", "--seed", "4", "--json"])
    assert rc == 0
    out = json.loads(capsys.readouterr().out)
    for k in REQUIRED:
        assert k in out
    assert out["controller"] == "pd" and out["n_walks"] == 2 and out["n_actions"] == 3
    assert main(["tracker", "eval", "--library", boxing_library_file, "--walks", "1", "--controller", "nope"]) == 2
