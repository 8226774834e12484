"""The batched tracking environment, the grounded reference, the balance assist and the stance."""
from __future__ import annotations

import numpy as np
import pytest

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def setup(boxing_library):
    from tracker.track.evaluation import make_setup
    from tracker.track.pd import batched_model_options
    from tracker.track.walks import LibraryWalks
    s = make_setup(LibraryWalks(boxing_library), batched_model_options())
    return s


@pytest.fixture(scope="module")
def refs(setup):
    from tracker.track.evaluation import draw_walks, walk_reference
    return [walk_reference(setup, w, lift="ground")[1] for w in draw_walks(setup.source, 3, 3, 7)]


def _env(setup, n, mode="none", cap=0.5):
    from tracker.track.assist import AssistConfig
    from tracker.track.batch_env import BatchConfig, BatchEnv
    from tracker.track.pd import STANCE_GAINS, PDTracker
    env = BatchEnv(setup.scene, n, BatchConfig(assist=AssistConfig(mode, cap)))
    PDTracker(class_scale=STANCE_GAINS).reset(env)
    return env


@pytest.mark.parametrize("mode", ["none", "fixed", "learned"])
def test_batched_env_equals_single_envs_step_for_step(setup, refs, mode):
    """Three worlds stepped together give exactly what three one-world envs give."""
    rng = np.random.default_rng(0)
    batch = _env(setup, 3, mode)
    singles = [_env(setup, 1, mode) for _ in range(3)]
    batch.reset(np.arange(3), refs)
    for i, e in enumerate(singles):
        e.reset([0], [refs[i]])
    for _ in range(20):
        noise = rng.normal(0.0, 0.05, (3, batch.n_act))
        assist = rng.uniform(-1.0, 1.0, (3, 6)) if mode == "learned" else None
        ob, rb, db, ib = batch.step(batch.reference_targets() + noise, assist)
        for i, e in enumerate(singles):
            o, r, d, info = e.step(e.reference_targets() + noise[i:i + 1], None if assist is None else assist[i:i + 1])
            assert np.array_equal(e.qpos[0], batch.qpos[i])
            assert np.array_equal(o[0], ob[i]) and r[0] == rb[i] and d[0] == db[i]
            assert info["fall"][0] == ib["fall"][i]


@pytest.mark.parametrize("mode", ["fixed", "learned"])
def test_the_assist_never_exceeds_its_cap(setup, refs, mode):
    """However large the policy's output or the error, |F| <= c m g and |tau| <= c m g * 1 m, as
    reported and as applied to the pelvis."""
    from tracker.track.assist import G
    rng = np.random.default_rng(1)
    cap = 0.2
    env = _env(setup, 3, mode, cap)
    env.reset(np.arange(3), refs)
    for d in env.datas:                       # push every pelvis 30 cm off its reference: a large error
        d.qpos[0] += 0.3
    env.refresh()
    mg = env.mass * G
    seen_cap = False
    for _ in range(15):
        assist = rng.normal(0.0, 50.0, (3, 6)) if mode == "learned" else None
        env.step(env.reference_targets(), assist)
        assert (env.assist_force_mg <= cap + 1e-12).all() and (env.assist_torque_mgm <= cap + 1e-12).all()
        for b, d in enumerate(env.datas):
            w = d.xfrc_applied[env.layouts[0].pelvis]
            assert np.linalg.norm(w[:3]) <= cap * mg[b] * (1 + 1e-9)
            assert np.linalg.norm(w[3:]) <= cap * mg[b] * (1 + 1e-9)
        seen_cap |= bool(env.assist_at_cap.any())
    assert seen_cap                            # the bound was reached, not just respected


def test_grounded_reference_meets_its_tolerance(setup):
    """Grounding puts the lower foot on the floor (within [-0.5, 1] cm) in every supported frame,
    where the constant lift left it floating centimetres up."""
    from tracker.track.evaluation import draw_walks
    from tracker.track.grounding import GroundConfig, foot_heights, ground_heights
    from tracker.track.reference import motion_qpos
    w = draw_walks(setup.source, 1, 10, 3)[0]
    motion = setup.source.sequence_motion(w)
    fm = setup.scene.fighters[0]
    q = motion_qpos(motion, fm)
    low, com = foot_heights(setup.scene, fm, q)
    off = ground_heights(low, com, motion.fps)
    z = np.convolve(np.pad(com[:, 2], 2, mode="edge"), np.ones(5) / 5, mode="valid")
    acc = np.gradient(np.gradient(z, 1 / motion.fps), 1 / motion.fps)
    supported = acc > -GroundConfig().flight_acc
    lower = (low + off[:, None]).min(axis=1)[supported]
    assert supported.mean() > 0.9
    assert lower.min() >= -0.005 - 1e-9 and lower.max() <= 0.01 + 1e-9
    before = low.min(axis=1) - np.percentile(low.min(axis=1), 10)   # the legacy constant lift
    assert np.mean(before > 0.015) > 0.2                              # which floated in many frames


def test_quiet_stance_holds_ten_seconds_without_assist(setup):
    """With the stance gains the body stands still 10 s, no assist; at the table's gains it falls."""
    from tracker.track.batch_env import BatchConfig, BatchEnv
    from tracker.track.pd import STANCE_GAINS, PDTracker
    from tracker.track.stance import quiet_stance
    ref = quiet_stance(setup.scene, 10.0)
    stood = {}
    for name, gains in (("stance", STANCE_GAINS), ("table", ())):
        env = BatchEnv(setup.scene, 1, BatchConfig())
        PDTracker(class_scale=gains).reset(env)
        env.reset([0], [ref])
        n = 0
        while not env.done[0]:
            _, _, _, info = env.step(env.reference_targets())
            n += 1
        stood[name] = (n / 30.0, int(info["fall"][0]))
    assert stood["stance"][1] == 0 and stood["stance"][0] >= 10.0 - 1e-9, stood
    assert stood["table"][1] != 0, stood


def test_protocol_reports_the_assist(setup):
    """The walk protocol's summary carries the assist figures and labels the physics."""
    from tracker.track.assist import AssistConfig
    from tracker.track.batch_env import BatchConfig
    from tracker.track.evaluation import draw_walks
    from tracker.track.pd import STANCE_GAINS, PDTracker
    from tracker.track.walk_protocol import run_walks, summarise
    walks = draw_walks(setup.source, 2, 3, 0)
    cfg = BatchConfig(assist=AssistConfig("fixed", 0.5))
    ctrl = PDTracker(class_scale=STANCE_GAINS)
    runs, timing = run_walks(setup, ctrl, walks, cfg, parallel=2)
    m = summarise(runs, ctrl, cfg, timing, 3, 0, 70.0)
    for k in ("controller", "assist", "cap_mg", "completion_rate", "mean_time_to_fall_s", "mpjpe_cm",
              "mpjpe_rerooted_cm", "assist_force_mean_mg", "assist_force_p95_mg", "assist_torque_mean_mgm",
              "assist_at_cap_share", "realtime_factor"):
        assert k in m
    assert m["assist"] == "fixed" and m["cap_mg"] == 0.5 and "assisted physics" in m["physics"]
    assert 0.0 < m["assist_force_mean_mg"] <= 0.5


def _one_term_rewards(setup, refs, seed: int, keep: str, configs: dict) -> dict:
    """reward() of a body moved off its reference, with every term but ``keep`` weighted 0, under
    the reward weights of each AssistedTrainConfig in ``configs`` (key -> config)."""
    from dataclasses import replace

    from tracker.learn.train_assisted import reward_weights
    env = _env(setup, 1)
    env.reset([0], refs[:1])
    rng = np.random.default_rng(seed)
    for _ in range(5):  # move off the reference so the error is not zero
        env.step(env.reference_targets() + rng.normal(0.0, 0.3, (1, env.n_act)), None)
    off = {t: 0.0 for t in ("pose", "velocity", "end_effector", "root", "com", "sites") if t != keep}
    got = {}
    for key, cfg in configs.items():
        env.config = replace(env.config, reward=replace(reward_weights(cfg), **off))
        got[key] = float(env.reward()[0])
    return got


def test_the_end_effector_term_follows_its_weight_and_scale(setup, refs):
    """reward() with only the hands-and-feet term: weight * exp(-scale * squared error), so a
    smaller scale pays more for the same pose error, and scale 0 pays the whole weight."""
    from tracker.learn.train_assisted import AssistedTrainConfig
    got = _one_term_rewards(setup, refs, 3, "end_effector", {
        scale: AssistedTrainConfig(end_effector_weight=0.3, end_effector_scale=scale) for scale in (40.0, 10.0, 0.0)})
    assert got[0.0] == pytest.approx(0.3)
    assert 0.0 < got[40.0] < got[10.0] < got[0.0]
    assert np.log(got[40.0] / 0.3) == pytest.approx(4.0 * np.log(got[10.0] / 0.3), rel=1e-9)


def test_the_com_velocity_term_follows_its_weight_and_scale(setup, refs):
    """reward() with only the centre-of-mass velocity term: weight * exp(-scale * |v - v_ref|^2),
    so a larger scale pays less for the same lag, and scale 0 pays the whole weight."""
    from tracker.learn.train_assisted import AssistedTrainConfig
    got = _one_term_rewards(setup, refs, 4, "com", {
        scale: AssistedTrainConfig(com_weight=0.3, com_scale=scale) for scale in (10.0, 1.0, 0.0)})
    assert got[0.0] == pytest.approx(0.3)
    assert 0.0 < got[10.0] < got[1.0] < got[0.0]
    assert np.log(got[10.0] / 0.3) == pytest.approx(10.0 * np.log(got[1.0] / 0.3), rel=1e-9)


def test_arm_velocity_targets_shift_only_the_arm_targets(setup, refs):
    """With arm velocity targets the arm actuators' targets carry (kd / kp) x the reference joint
    velocity and every other target is the plain one; a mask of the wrong shape is refused."""
    from tracker.track.env import ARM_CLASSES
    from tracker.track.pd import STANCE_GAINS, PDTracker
    ctrl = {}
    for arms in (False, True):
        env = _env(setup, 1)
        PDTracker(class_scale=STANCE_GAINS, arm_velocity_targets=arms).reset(env)
        env.reset(np.arange(1), refs[:1])
        targets = env.reference_targets()
        env.step(targets, None)
        ctrl[arms] = env.datas[0].ctrl[env.layouts[0].ctrl] - targets[0]
    arm = np.array([c in ARM_CLASSES for c in setup.scene.fighters[0].act_class])
    assert np.all(ctrl[False] == 0.0)
    assert np.all(ctrl[True][~arm] == 0.0) and np.abs(ctrl[True][arm]).max() > 1e-4
    with pytest.raises(ValueError, match="velocity-target mask"):
        env.set_velocity_targets(np.ones(3))


def test_the_joint_position_term_follows_its_weight_and_scale(setup, refs):
    """reward() with only the world joint-position term: weight * exp(-scale * mean squared site
    distance), so a larger scale pays less for the same error; weight 0 (the default) adds nothing."""
    from tracker.learn.train_assisted import AssistedTrainConfig
    got = _one_term_rewards(setup, refs, 5, "sites", {
        scale: AssistedTrainConfig(sites_weight=0.3, sites_scale=scale) for scale in (40.0, 10.0, 0.0)})
    assert got[0.0] == pytest.approx(0.3)
    assert 0.0 < got[40.0] < got[10.0] < got[0.0]
    assert np.log(got[40.0] / 0.3) == pytest.approx(4.0 * np.log(got[10.0] / 0.3), rel=1e-9)
    assert _one_term_rewards(setup, refs, 5, "sites", {0: AssistedTrainConfig()})[0] == 0.0


def test_a_placed_reference_is_the_clip_moved_on_the_ground(setup, refs):
    """place_reference moves the frames from t on rigidly on the ground (pelvis pose, world
    velocities, joint sites) and leaves the earlier frames and the joint angles; its moved batch
    tables equal the tables computed afresh from the moved reference."""
    from dataclasses import replace

    from tracker.track.batch_env import place_reference, quats_to_matrices, reference_tables
    env = _env(setup, 1)
    env.reset([0], refs[:1])
    ref, t, dyaw = env.refs[0], 10, 0.7
    to = np.array([1.5, -2.0])
    placed = place_reference(ref, t, ref.qpos[t, :2], to, dyaw)
    c, s = np.cos(dyaw), np.sin(dyaw)
    R3 = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    assert np.array_equal(placed.qpos[:t], ref.qpos[:t]) and np.array_equal(placed.sites[:t], ref.sites[:t])
    assert np.array_equal(placed.qpos[:, 7:], ref.qpos[:, 7:]) and np.array_equal(placed.ctrl, ref.ctrl)
    assert np.allclose(placed.qpos[t, :2], to) and np.allclose(placed.qpos[:, 2], ref.qpos[:, 2])
    assert np.allclose(quats_to_matrices(placed.qpos[t:, 3:7]), R3 @ quats_to_matrices(ref.qpos[t:, 3:7]))
    rel = lambda r: r.sites[t:] - r.qpos[t:, None, :3]                          # noqa: E731
    assert np.allclose(rel(placed), rel(ref) @ R3.T)
    assert np.allclose(placed.qvel[t:, :3], ref.qvel[t:, :3] @ R3.T)
    moved = placed.meta["batch_tables_0"]
    fresh = reference_tables(replace(placed, meta={}), env.layouts[0], setup.scene, 0)
    for k in ("R", "up", "com", "com_vel", "ee", "com_feet", "com_vel_f"):
        assert np.allclose(moved[k][t + 1:], fresh[k][t + 1:], atol=1e-9), k
    assert np.allclose(np.cos(moved["yaw"] - fresh["yaw"])[t:], 1.0)
    assert np.allclose(moved["com"][t], fresh["com"][t], atol=1e-9)
    with pytest.raises(ValueError, match="outside"):
        place_reference(ref, ref.n_frames, ref.qpos[0, :2], to, 0.0)


def test_body_placement_puts_the_next_clip_under_the_body(setup, refs):
    """place_on_body: the reference pelvis's ground position and yaw at the current step become
    the simulated pelvis's; the walk protocol with placement "body" runs and says so."""
    from tracker.track.batch_env import BatchConfig, yaws_of
    from tracker.track.evaluation import draw_walks
    from tracker.track.pd import STANCE_GAINS, PDTracker
    from tracker.track.walk_protocol import run_walks, summarise
    env = _env(setup, 1)
    env.reset([0], refs[:1])
    rng = np.random.default_rng(6)
    for _ in range(15):
        env.step(env.reference_targets() + rng.normal(0.0, 0.2, (1, env.n_act)), None)
    t = int(env.t[0])
    assert np.linalg.norm(env.refs[0].qpos[t, :2] - env.qpos[0, :2]) > 1e-3
    env.place_on_body([0])
    assert np.allclose(env.refs[0].qpos[t, :2], env.qpos[0, :2])
    sim_yaw = yaws_of(env.R[:1], env.lateral[0])[0]
    assert np.cos(env.tables[0]["yaw"][t] - sim_yaw) == pytest.approx(1.0)
    walks = draw_walks(setup.source, 1, 3, 0)
    ctrl = PDTracker(class_scale=STANCE_GAINS)
    runs, timing = run_walks(setup, ctrl, walks, BatchConfig(), parallel=1, placement="body")
    m = summarise(runs, ctrl, BatchConfig(), timing, 3, 0, 70.0)
    assert m["placement"] == "body" and m["mpjpe_rerooted_cm"] > 0.0
    with pytest.raises(ValueError, match="placement"):
        run_walks(setup, ctrl, walks, BatchConfig(), parallel=1, placement="game")
