"""The balance layer's steering (tracker/track/vforce.py ``bias``) and the learned balance head
(research/layer_head.py): a steered target moves the body's centre of mass that way in the facing
frame, set_balance clears the steering, a checkpoint with a head steers the layer each step (and
needs the layer), and the search's labels come in sigma units within the head's range."""
from __future__ import annotations

import mujoco
import numpy as np
import pytest
import torch

from tracker.body.frames import ground_yaw
from tracker.track.evaluation import draw_walks, make_setup, walk_reference
from research.layer_head import Head, HeadConfig, collect, fit, load_head_policy, save_head
from tracker.track.pd import PDController
from tracker.track.policy_net import DEFAULT_CKPT, RunningNorm, load_checkpoint, load_policy
from tracker.track.walks import LibraryWalks

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def setup(boxing_library):
    return make_setup(LibraryWalks(boxing_library))


def _com_offset(env) -> np.ndarray:
    """Centre of mass minus the feet's midpoint, horizontal, in the facing frame."""
    m, d = env.model, env.data
    c = env._cache[0]
    mujoco.mj_comPos(m, d)
    f = env.scene.fighters[0]
    feet = [int(f.body_ids[list(f.body_joints).index(f.spec.parts[p])]) for p in ("l_ankle", "r_ankle")]
    off = d.subtree_com[c.pelvis] - d.xpos[feet].mean(0)
    yaw = ground_yaw(d.xmat[c.pelvis].reshape(3, 3), c.lateral)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array([[cy, sy], [-sy, cy]]) @ off[:2]


def _run(setup, walk, bias, steps=9):
    env = setup.env
    _, ref = walk_reference(setup, walk)
    obs = env.reset(ref, 0)
    ctrl = PDController.balanced()
    ctrl.reset(env)
    for _ in range(steps):
        env.balance.bias[0] = bias
        obs, _, done, _ = env.step(ctrl.act(env, obs))
    return _com_offset(env), env.data.qpos.copy()


def test_steering_moves_the_centre_of_mass_in_the_facing_frame(setup):
    walk = draw_walks(setup.source, 1, 4, 5)[0]
    base, q0 = _run(setup, walk, np.zeros(6))
    _, q_zero = _run(setup, walk, np.zeros(6))
    np.testing.assert_array_equal(q0, q_zero)
    for axis in (0, 1):
        b = np.zeros(6)
        b[axis] = 0.04
        moved = _run(setup, walk, b)[0] - base
        # the steered axis moves the right way, and more than the other axis
        assert moved[axis] > 0.003 and abs(moved[axis]) > abs(moved[1 - axis]), (axis, moved)


def test_set_balance_clears_the_steering(setup):
    env = setup.env
    PDController.balanced().reset(env)
    env.balance.bias[0] = 0.02
    PDController.balanced().reset(env)
    assert not env.balance.bias.any()


def test_a_checkpoint_with_a_head_steers_each_step(setup, tmp_path):
    ck = load_checkpoint(DEFAULT_CKPT)
    torch.manual_seed(0)
    head = Head(len(ck["obs_mean"]), (8,))
    with torch.no_grad():
        head.mu[-1].bias.fill_(0.5)                       # half a sigma on every output
    out = tmp_path / "h.pt"
    save_head(str(out), HeadConfig(hidden=(8,)), head.state_dict(), [])
    ctrl = load_head_policy(out)
    with pytest.raises(ValueError, match="balance head"):   # the product's loader does not run heads
        load_policy(out)
    assert ctrl.head is not None and "balance head" in ctrl.describe()
    env = setup.env
    _, ref = walk_reference(setup, draw_walks(setup.source, 1, 3, 2)[0])
    obs = env.reset(ref, 0)
    ctrl.reset(env)
    env.step(ctrl.act(env, obs))
    assert np.abs(env.balance.bias[0]).min() > 0      # the head's output reached the layer
    ck_nolayer = load_checkpoint(out)
    ck_nolayer["config"] = {**ck_nolayer["config"], "vf_gains": ()}
    torch.save(ck_nolayer, tmp_path / "bad.pt")
    with pytest.raises(ValueError, match="needs the balance layer"):
        load_head_policy(tmp_path / "bad.pt")


def test_search_labels_are_in_sigma_units_and_fit(boxing_library_file):
    cfg = HeadConfig(library=boxing_library_file, candidates=3, lookahead=3, walks_per_worker=1, walk_actions=3,
                     fit_steps=20, max_sigmas=2.0)
    out = collect(cfg, None, 2.0, 0, 0)
    n = len(out["obs"])
    assert n > 0 and out["label"].shape == (n, 6) and out["w"].shape == (n,)
    assert np.abs(out["label"]).max() <= 2.0 + 1e-6 and (out["w"] >= cfg.label_floor).all()
    ck = load_checkpoint(DEFAULT_CKPT)
    norm = RunningNorm(len(ck["obs_mean"]))
    norm.load(ck)
    state, loss = fit(cfg, norm, out["obs"], out["label"], out["w"])
    assert np.isfinite(loss) and set(state) == set(Head(out["obs"].shape[1], (128, 128)).state_dict())
