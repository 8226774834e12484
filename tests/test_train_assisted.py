"""The assisted tracker's training route: a checkpoint torch reads weights-only, that the
controller loads, and that a resumed run continues (budget, curve and curriculum carried over)."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.realdata


def test_train_writes_a_resumable_checkpoint(tmp_path, boxing_library_file):
    import torch

    from tracker.learn.train_assisted import AssistedTrainConfig, train
    from tracker.track.assisted_policy import load_assisted
    cfg = AssistedTrainConfig(n_envs=2, horizon=8, pool_walks=2, walk_actions=2, hidden=(32, 32),
                              critic_hidden=(32, 32), minibatch=8)
    out = tmp_path / "a.pt"
    r1 = train(str(out), 5.0, cfg, library=boxing_library_file, progress=False, log=None, max_iterations=2)
    assert out.is_file() and (tmp_path / "a.pt.png").is_file()
    ck = torch.load(str(out), map_location="cpu", weights_only=True)      # no pickled objects
    assert ck["budget"]["samples"] == 2 * 2 * 8 and ck["budget"]["runs"] == 1 and len(ck["curve"]) == 2
    ctrl = load_assisted(out)
    assert ctrl.n_act + 6 == ctrl.act_dim and 0 < ctrl.cap <= cfg.cap_start
    obs = np.zeros((3, ctrl.obs_dim))
    assert ctrl.policy_output(obs).shape == (3, ctrl.act_dim)
    r2 = train(str(out), 5.0, cfg, library=boxing_library_file, resume=str(out), progress=False, log=None,
               max_iterations=1)
    ck2 = torch.load(str(out), map_location="cpu", weights_only=True)
    assert ck2["budget"]["samples"] == r1["budget"]["samples"] + 16 and ck2["budget"]["runs"] == 2
    assert len(ck2["curve"]) == 3 and ck2["budget"]["cpu_s"] > ck["budget"]["cpu_s"]
    assert r2["budget"]["iterations"] == 3


def test_pushes_act_on_the_upper_body_and_end(boxing_library_file):
    """With push_prob 1 every slot is pushed at once on a body above the pelvis with a horizontal
    force in the configured range of body weights; the force is removed after push_steps steps
    and when the slot's episode restarts."""
    from motion_graph.library import load_library
    from tracker.learn.train_assisted import AssistedTrainConfig, Rollouts
    cfg = AssistedTrainConfig(n_envs=2, pool_walks=2, walk_actions=2, push_prob=1.0, push_force_mg=(0.2, 0.3),
                              push_steps=(2, 2))
    roll = Rollouts(cfg, load_library(boxing_library_file), seed=0)
    env = roll.env
    pel = env.layouts[0].pelvis
    assert len(roll.push_bodies) >= 4 and pel not in roll.push_bodies
    roll.push()
    for b in range(2):
        f = env.datas[b].xfrc_applied
        body = int(roll.push_body[b])
        mg = env.mass[b] * 9.81
        assert body in roll.push_bodies and f[body, 2] == 0.0
        assert 0.2 * mg <= np.hypot(f[body, 0], f[body, 1]) <= 0.3 * mg
        assert np.count_nonzero(np.abs(f).sum(1)) == 1          # only that body (the assist is on the pelvis)
    env.step(env.reference_targets(), np.zeros((2, 6)))
    roll.push()                                                  # second step of the push: held
    assert all(np.abs(env.datas[b].xfrc_applied[roll.push_body[b]]).sum() > 0 for b in range(2))
    roll.push()                                                  # ended, and a new one may start
    roll._start(0)
    assert np.abs(env.datas[0].xfrc_applied).sum() == 0.0 and roll.push_left[0] == 0
