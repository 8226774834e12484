"""Widening a trained policy's observation to more reference horizons (tracker.learn.widen): the widened
policy computes exactly what the trained one did, the stored labels follow, and a resumed search
run trains the widened policy."""
from __future__ import annotations

import numpy as np
import pytest

from tracker.track.evaluation import make_setup
from tracker.track.walks import LibraryWalks

pytestmark = pytest.mark.realdata

torch = pytest.importorskip("torch")


@pytest.fixture(scope="module")
def source(boxing_library_file):
    from motion_graph.library import load_library
    return LibraryWalks(load_library(boxing_library_file))


def test_widened_shipped_policy_acts_exactly_as_before(source):
    """The shipped policy widened from horizons (1, 2, 4) to (1, 2, 4, 8, 12, 16) gives the same PD
    targets along a tracked walk (its new inputs are read, with zero weights), although its
    observation is 3 blocks longer and the environment observes only (1, 2, 4)."""
    from tracker.track.evaluation import draw_walks
    from tracker.track.policy_net import DEFAULT_CKPT, LearnedController, load_checkpoint
    from tracker.track.reference import build_reference
    from tracker.learn.widen import widen_checkpoint
    ck = load_checkpoint(DEFAULT_CKPT)
    old = LearnedController(ck)
    wide = LearnedController(widen_checkpoint(ck, (1, 2, 4, 8, 12, 16))[0])
    assert wide.obs_future == (1, 2, 4, 8, 12, 16)
    assert wide.obs_dim == old.obs_dim + 3 * (old.act_dim + 8)
    setup = make_setup(source)
    env = setup.env
    ref = build_reference(source.sequence_motion(draw_walks(source, 1, 4, 3)[0]), setup.scene, 0)
    obs = env.reset(ref, 5)
    old.reset(env)
    wide.reset(env)
    for _ in range(20):
        a_old, a_wide = old.act(env, obs), wide.act(env, obs)
        np.testing.assert_allclose(a_wide, a_old, atol=1e-9)
        obs, _, done, _ = env.step(a_old)
        if done:
            break
    # the environment observes the policy's horizons when asked (+ 32 balance features)
    x = np.atleast_2d(env.observe(0, wide.obs_future))
    assert x.shape[1] + 32 == wide.obs_dim


def test_widening_keeps_every_trained_horizon():
    from tracker.learn.widen import column_map
    with pytest.raises(ValueError, match="drops the trained horizons"):
        column_map(100, 10, (1, 2, 4), (1, 8), True)
    src, new = column_map(10 + 2 * 18 + 32, 10, (1, 4), (1, 2, 4), True)
    assert len(src) == 10 + 3 * 18 + 32 and new.sum() == 18
    # horizon 2 borrows the statistics of horizon 1 (the nearest), horizon 4 keeps its own columns
    assert list(src[10 + 18:10 + 36]) == list(range(10, 28)) and list(src[10 + 36:10 + 54]) == list(range(28, 46))


def test_resumed_search_run_widens_policy_and_labels(boxing_library_file, tmp_path):
    """A search run resumed with more horizons keeps its labels (widened) and trains the widened
    policy, whose new first-layer weights move away from zero."""
    from tracker.learn.search_labels import LabelBuffer, labels_path
    from tracker.track.policy_net import load_checkpoint
    from tracker.learn.train_tracker import TrainConfig, train
    cfg = TrainConfig(seed=1, algo="search", n_workers=1, envs_per_worker=1, walks_per_worker=1, walk_actions=2,
                      refresh_walks=0, hidden=(32, 32), critic_hidden=(16, 16), init_noise=0.0, eval_every_min=0,
                      candidates=3, segment=3, lookahead=3, search_segments=4, distill_steps=5)
    ck = tmp_path / "w.pt"
    train(cfg, boxing_library_file, 10.0, str(ck), max_iterations=1, progress=False, log=lambda *a: None)
    ck0 = load_checkpoint(ck)
    n0 = len(np.load(labels_path(ck))["obs"])
    logs: list[str] = []
    train(cfg, boxing_library_file, 10.0, str(ck), resume=str(ck), max_iterations=1, progress=False,
          log=logs.append, overrides={"obs_future": (1, 2, 4, 8)})
    ck1 = load_checkpoint(ck)
    s = ck0["policy"]["log_std"].shape[0] + 8
    d0 = ck0["policy"]["mu.0.weight"].shape[1]
    assert tuple(ck1["config"]["obs_future"]) == (1, 2, 4, 8)
    assert ck1["policy"]["mu.0.weight"].shape[1] == d0 + s
    assert any("widened" in m for m in logs) and any(f"resumed {n0} labels" in m for m in logs)
    buf = LabelBuffer(10_000)
    assert buf.load(labels_path(ck), d0 + s, s - 8) and len(buf) > n0
    new_cols = ck1["policy"]["mu.0.weight"][:, d0 - 32:d0 - 32 + s]
    assert float(new_cols.abs().max()) > 0.0
