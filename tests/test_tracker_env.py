"""The tracking environment: falls are detected when the body is dropped, not while it is held;
steps, observations, rewards and the controller interface behave."""
from __future__ import annotations

from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import mujoco
import numpy as np
import pytest

from motion_graph.io import load_motion
from tracker.track.controllers import Controller, make_controller
from tracker.track.env import EnvConfig, TrackingEnv
from tracker.body.fall import detect_fall, fall_geom_mask
from tracker.body.humanoid import ModelOptions, build_fighter_scene
from tracker.track.pd import PDController
from tracker.track.reference import build_reference
from tracker.body.spec import fighter_spec

pytestmark = pytest.mark.realdata


@lru_cache(maxsize=None)
def _setup(path: str, assist: bool = False):
    m = load_motion(path).slice(0, 4 * 120)
    spec = fighter_spec(m.skeleton, [m])
    scene = build_fighter_scene(spec, 1, ModelOptions(root_assist=assist))
    ref = build_reference(m, scene, fps=30.0)
    return scene, ref


def _boxing(mocap_root, assist=False):
    return _setup(str(Path(mocap_root) / "cmu/boxing/13_18.bvh"), assist)


class Limp:
    """A controller with no strength: zero gains (the body drops like a rag doll)."""

    name = "limp"

    def reset(self, env):
        f = env.scene.fighters[0]
        env.set_gains(np.zeros(f.n_act), np.zeros(f.n_act))

    def act(self, env, obs):
        return env.reference_targets()


def _run(env, ctrl, ref, seconds):
    obs = env.reset(ref, 0)
    ctrl.reset(env)
    info = None
    while env.t < int(seconds * ref.fps):
        obs, _, done, info = env.step(ctrl.act(env, obs))
        if done:
            break
    return info


def test_fall_detected_when_the_body_is_dropped(mocap_root):
    scene, ref = _boxing(mocap_root)
    env = TrackingEnv(scene)
    info = _run(env, Limp(), ref, 3.0)
    assert info.fall[0] in ("floor_contact", "pelvis_low")
    assert env.done and env.sim_time < 2.0
    # Dropped from 1 m above the reference, upside down, limp: it lands on a non-foot part.
    env.reset(ref, 0)
    Limp().reset(env)
    d = env.data
    d.qpos[2] += 1.0
    q = np.zeros(4)
    mujoco.mju_mulQuat(q, np.array([0.0, 1.0, 0.0, 0.0]), d.qpos[3:7].copy())   # head down
    d.qpos[3:7] = q
    mujoco.mj_forward(env.model, d)
    for _ in range(60):
        _, _, done, info = env.step(env.reference_targets())
        if done:
            break
    assert done and info.fall[0] is not None and not info.end
    # At that moment a non-foot part (the head) is on the floor, whatever the pelvis height.
    mask = fall_geom_mask(env.model, scene.fighters[0])
    assert detect_fall(d, scene.floor_geom, mask, 10.0, 0.0) == "floor_contact"


def test_no_fall_while_the_root_is_held(mocap_root):
    scene, ref = _boxing(mocap_root, assist=True)
    env = TrackingEnv(scene)
    env.set_root_assist(True)
    info = _run(env, PDController(), ref, 2.0)
    assert info.fall[0] is None and not env.done
    assert np.mean(info.mpjpe_m) < 0.15
    env.set_root_assist(False)


def test_detect_fall_definition(mocap_root):
    scene, ref = _boxing(mocap_root)
    m, d = scene.model, mujoco.MjData(scene.model)
    f = scene.fighters[0]
    mask = fall_geom_mask(m, f)
    assert not mask[f.foot_geoms].any() and mask[f.fall_geoms].all()
    d.qpos[:] = ref.qpos[0]
    mujoco.mj_forward(m, d)
    z = d.xpos[f.pelvis_body, 2]
    assert detect_fall(d, scene.floor_geom, mask, z, ref.qpos[0, 2]) is None
    assert detect_fall(d, scene.floor_geom, mask, z - 0.5, ref.qpos[0, 2]) == "pelvis_low"
    # Lower the whole body until the knees/pelvis reach the floor: a floor contact of a non-foot geom.
    d.qpos[2] -= 0.6
    mujoco.mj_forward(m, d)
    assert detect_fall(d, scene.floor_geom, mask, 10.0, 0.0) == "floor_contact"


def test_step_observation_reward_and_end(mocap_root):
    scene, ref = _boxing(mocap_root)
    env = TrackingEnv(scene, EnvConfig())
    obs = env.reset(ref, ref.n_frames - 5)
    assert obs.ndim == 1 and np.all(np.isfinite(obs))
    pd = PDController()
    pd.reset(env)
    n = 0
    while True:
        obs2, r, done, info = env.step(pd.act(env, obs))
        n += 1
        assert obs2.shape == obs.shape and 0.0 <= r <= 1.0
        if done:
            break
    assert n == 4 and info.end                      # the reference ran out, no fall
    # Observed joint coordinates are MuJoCo's actuator lengths (the PD's own coordinates).
    mujoco.mj_forward(env.model, env.data)
    f = scene.fighters[0]
    assert np.allclose(env.joint_coordinates(0), env.data.actuator_length[f.ctrl_slice], atol=1e-9)
    with pytest.raises(RuntimeError):
        env.step(pd.act(env, obs))
    # Residual actions: zero residual is the PD baseline, bit for bit.
    env2 = TrackingEnv(scene, replace(EnvConfig(), residual_actions=True))
    o1, o2 = env.reset(ref, 3), env2.reset(ref, 3)
    pd.reset(env), pd.reset(env2)
    for _ in range(5):
        o1, *_ = env.step(pd.act(env, o1))
        o2, *_ = env2.step(pd.act(env2, o2))
    assert np.array_equal(env.data.qpos, env2.data.qpos)


def test_controller_interface():
    assert isinstance(PDController(), Controller)
    assert isinstance(make_controller("pd"), PDController)
    with pytest.raises(ValueError):
        make_controller("no-such-controller")


def test_reset_rejects_wrong_rate(mocap_root):
    scene, ref = _boxing(mocap_root)
    env = TrackingEnv(scene, replace(EnvConfig(), control_hz=60.0))
    with pytest.raises(ValueError):
        env.reset(ref, 0)


def test_arm_velocity_targets_offset_only_the_arm_actuators(mocap_root, tmp_path):
    """arm_velocity_targets: the arm actuators' targets carry (kd / kp) x the reference velocity,
    every other actuator's target is the plain PD's; velocity_targets offsets all of them."""
    from tracker.track.env import ARM_CLASSES
    scene, ref = _boxing(mocap_root)
    f = scene.fighters[0]
    arm = np.array([c in ARM_CLASSES for c in f.act_class])
    assert arm.any() and not arm.all()
    k = 40
    ctrls = {}
    for name, pd in (("plain", PDController()), ("arms", PDController(arm_velocity_targets=True)),
                     ("all", PDController(velocity_targets=True))):
        env = TrackingEnv(scene, EnvConfig())
        env.reset(ref, k)
        pd.reset(env)
        env.step(pd.act(env, None))
        ctrls[name] = env.data.ctrl[f.ctrl_slice].copy()
    vel = ref.ctrl_vel[k + 1] * (f.kd / f.kp)
    assert np.abs(vel[arm]).max() > 1e-3                     # the arms move at that frame
    np.testing.assert_allclose(ctrls["arms"] - ctrls["plain"], np.where(arm, vel, 0.0), atol=1e-12)
    np.testing.assert_allclose(ctrls["all"] - ctrls["plain"], vel, atol=1e-12)
    p = tmp_path / "gains.json"
    p.write_text('{"arm_velocity_targets": true}')
    assert PDController.from_ckpt(str(p)).arm_velocity_targets is True
    # the "balance" controller keeps a gains file's PD knobs and adds the layer's default gains
    from tracker.track.vforce import BalanceGains
    b = make_controller("balance", str(p))
    assert b.arm_velocity_targets is True and b.balance == BalanceGains().as_tuple()
