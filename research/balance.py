"""A low-dimensional balance feedback on the PD targets, its gains learned by a cross-entropy search.

Why: PD tracking topples as a whole within ~1.5 s (MEASUREMENTS), PPO's gradient estimate on 66
residuals is too noisy for the samples this machine affords, and a deterministic simulator lets a
derivative-free search compare a few gains exactly (common start states). The feedback:

- features (facing frame of the pelvis, per fighter): centre-of-mass offset from the feet's
  midpoint minus the reference's (e_p, forward and lateral), the same for the COM velocity (e_v),
  the pelvis tilt error (rotation taking the simulated pelvis up-axis to the reference's, t) and
  the pelvis angular velocity (w);
- corrections, each a rotation about the horizontal facing axes applied in world terms to a joint's
  PD target (the child segment is turned by it):
  ankles of feet that touch the floor  <- ka_p * e_p + ka_v * e_v   (ankle strategy)
  hips of legs whose foot touches       <- kh_t * t + kh_w * w + kh_p * e_p   (hip / pelvis control)
  lower back and spine                   <- kt_t * t
  with separate gains for the sagittal and lateral axes: 2 x 7 = 14 numbers (GAINS). Zero gains = PD.

``optimize_gains`` runs the cross-entropy method over them: each generation, every candidate is
scored on the same RSI starts of random walks (time to fall, capped), over both cores.

The feedback's structured action space also trains the learned policy (``--set action_space=balance``)
and labels it as a teacher (``--set algo=teacher --set teacher_gains=...``): the tracker's trainer
with ``BalanceWorker`` (``python -m research.balance train ...``, the options of `igraph-fight
tracker train`); ``load_balance_policy`` runs such a checkpoint. Measured in research/notes/TRAINING.md.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import mujoco
import numpy as np

from tracker.learn.train_tracker import Worker

#: Gain names, each for the (sagittal, lateral) axis pair.
GAIN_NAMES = ("ka_p", "ka_v", "kh_t", "kh_w", "kh_p", "kt_t", "kh_v")
N_GAINS = 2 * len(GAIN_NAMES)


def _rotvec_mat(v: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(v))
    if th < 1e-12:
        return np.eye(3)
    k = v / th
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(th) * K + (1.0 - np.cos(th)) * (K @ K)


def _mat_rotvec(R: np.ndarray) -> np.ndarray:
    q = np.empty(4)
    mujoco.mju_mat2Quat(q, R.reshape(9))
    if q[0] < 0:
        q = -q
    s = np.linalg.norm(q[1:])
    if s < 1e-12:
        return np.zeros(3)
    ang = 2.0 * np.arctan2(s, q[0])
    return q[1:] / s * ang


@dataclass
class _Joints:
    hips: list[int]
    ankles: list[int]
    trunk: list[int]
    acts: dict          # joint index -> (actuator ids, axes)


def _joints(f) -> _Joints:
    sp = f.spec
    idx = {int(j): i for i, j in enumerate(f.dof_joints)}

    def ji(part):
        j = sp.parts.get(part)
        return idx.get(int(j)) if j is not None else None
    hips = [ji("l_hip"), ji("r_hip")]
    ankles = [ji("l_ankle"), ji("r_ankle")]
    names = [sp.skeleton.names[int(j)] for j in f.dof_joints]
    belly = ji("belly")
    trunk = [i for i in range(len(names)) if i == belly or names[i] in ("LowerBack", "Spine", "Spine1")]
    acts = {}
    for i in set(hips + ankles + trunk):
        a = np.nonzero(f.act_joint == i)[0]
        acts[i] = (a, f.act_axis[a])
    return _Joints(hips, ankles, trunk, acts)


def feedback_action(env, k: int, feats: np.ndarray, gains: np.ndarray) -> np.ndarray:
    """(N_BALANCE_ACTIONS,) structured action (see structured_offsets) of the balance feedback for
    fighter k: ``feats`` = tracker.track.policy_net.balance_features(env, k), ``gains`` (N_GAINS,)."""
    from tracker.body.frames import ground_yaw, quat_matrix
    d = env.data
    c = env._cache[k]
    G = dict(zip(GAIN_NAMES, np.asarray(gains, float).reshape(len(GAIN_NAMES), 2)))
    R = d.xmat[c.pelvis].reshape(3, 3)
    yaw = ground_yaw(R, c.lateral)
    cy, sy = np.cos(yaw), np.sin(yaw)
    Ry = np.array([[cy, sy, 0.0], [-sy, cy, 0.0], [0.0, 0.0, 1.0]])       # world -> facing
    # features: sim com-feet (0:3), sim com vel (3:6), feet (6:12), touch (12:14), ref block (14:26),
    # sim minus ref: com-feet (26:29), com velocity (29:32)
    e_p, e_v = feats[26:29], feats[29:32]
    touch = (feats[12:14] > 0.5).astype(float)
    ref = env.refs[k]
    kf = min(env.t + env.config.target_lead, env.t_end)
    tilt = Ry @ np.cross(R[:, 2], quat_matrix(ref.qpos[kf, 3:7])[:, 2])     # sim up -> ref up (facing)
    w = Ry @ (R @ d.qvel[c.qvel][3:6])                                     # pelvis angular velocity (facing)

    # sagittal rotation: about the facing x axis (the hip line), driven by forward (y) errors;
    # lateral rotation: about the facing y axis, driven by sideways (x) errors
    def rot(name, ex, ey):
        return np.array([G[name][0] * ey, G[name][1] * ex])
    th_ankle = rot("ka_p", e_p[0], e_p[1]) + rot("ka_v", e_v[0], e_v[1])
    th_hip = (G["kh_t"] * tilt[:2] + G["kh_w"] * w[:2] + rot("kh_p", e_p[0], e_p[1]) + rot("kh_v", e_v[0], e_v[1]))
    th_trunk = G["kt_t"] * tilt[:2]
    a = np.concatenate([touch[0] * th_ankle, touch[1] * th_ankle, touch[0] * th_hip, touch[1] * th_hip, th_trunk])
    return np.clip(a, -0.6, 0.6)


def feedback_offsets(env, k: int, feats: np.ndarray, gains: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(n_act,) offsets of fighter k's PD targets ``targets`` from the balance feedback."""
    return structured_offsets(env, k, feedback_action(env, k, feats, gains), targets)


#: The structured ("balance") action space of the learned policy: per side (left, right) a rotation
#: of the ankle and of the hip target about the facing frame's two horizontal axes, and one for the
#: trunk (lower back and spine, shared): 2 x 2 x 2 + 2 = 10 numbers, radians.
N_BALANCE_ACTIONS = 10


def structured_offsets(env, k: int, action: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """(n_act,) PD-target offsets of fighter k for a structured action (N_BALANCE_ACTIONS,):
    [l_ankle x, l_ankle y, r_ankle x, r_ankle y, l_hip x, l_hip y, r_hip x, r_hip y, trunk x, trunk y]
    rotations (rad) about the pelvis facing frame's axes (x: the hip line, y: horizontal, normal to it),
    each turning the child segment's target orientation in world terms. ``targets``: fighter k's
    PD targets before the offsets."""
    from tracker.body.frames import ground_yaw
    d = env.data
    c = env._cache[k]
    f = env.scene.fighters[k]
    if not hasattr(c, "_bal_joints"):
        c._bal_joints = _joints(f)
    J = c._bal_joints
    R = d.xmat[c.pelvis].reshape(3, 3)
    yaw = ground_yaw(R, c.lateral)
    cy, sy = np.cos(yaw), np.sin(yaw)
    Ry = np.array([[cy, sy, 0.0], [-sy, cy, 0.0], [0.0, 0.0, 1.0]])
    a = np.asarray(action, float)
    todo = [(J.ankles[0], a[0:2]), (J.ankles[1], a[2:4]), (J.hips[0], a[4:6]), (J.hips[1], a[6:8])]
    for i in J.trunk:
        todo.append((i, a[8:10] / max(1, len(J.trunk))))
    out = np.zeros(c.n_act)
    for i, th2 in todo:
        if i is None:
            continue
        _turn(d, f, c, J, i, Ry.T @ np.array([th2[0], th2[1], 0.0]), targets, out)
    return out


def _turn(d, f, c, J, i: int, th_world: np.ndarray, targets: np.ndarray, out: np.ndarray) -> None:
    """Add to ``out`` the change of joint i's target that turns its child by th_world (world rotvec)."""
    if not np.any(th_world):
        return
    a, axes = J.acts[i]
    body = int(f.body_ids[i + 1])
    qa = int(f.joint_qpos[i])
    Rc = d.xmat[body].reshape(3, 3)
    Rq = np.empty(9)
    mujoco.mju_quat2Mat(Rq, d.qpos[qa:qa + 4])
    P = Rc @ Rq.reshape(3, 3).T                          # the joint's parent-side frame (world)
    rv_t = np.zeros(3)
    rv_t[axes] = targets[a - c.act.start]
    Rn = P.T @ _rotvec_mat(th_world) @ P @ _rotvec_mat(rv_t)
    out[a - c.act.start] += _mat_rotvec(Rn)[axes] - rv_t[axes]


# ----------------------------------------------------------------------------------------------
# cross-entropy search over the gains
_W: dict = {}


def _init_worker(library: str | None, seed: int) -> None:
    from tracker.track.env import EnvConfig, TrackingEnv
    from tracker.track.evaluation import make_setup
    from tracker.track.pd import PDController
    from tracker.track.walks import walk_source
    import os
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    src = walk_source(library)
    setup = make_setup(src, config=EnvConfig(residual_actions=True))
    _W.update(src=src, setup=setup, env=TrackingEnv(setup.scene, EnvConfig(residual_actions=True)), pd=PDController(),
              refs={})


def _ref(walk: tuple):
    from tracker.track.reference import build_reference
    refs = _W["refs"]
    if walk not in refs:
        src, setup = _W["src"], _W["setup"]
        m = src.sequence_motion(list(walk))
        if abs(m.fps - 30.0) > 1e-9:
            m = m.resample(30.0)
        refs[walk] = build_reference(m, setup.scene, 0, lift="auto")
        if len(refs) > 64:
            refs.pop(next(iter(refs)))
    return refs[walk]


def episode_time(gains: np.ndarray, walk: tuple, start: int, cap_s: float) -> tuple[float, float]:
    """(time survived, mean MPJPE) of PD + feedback from ``start`` of ``walk`` (capped)."""
    from tracker.track.policy_net import balance_features
    env, pd = _W["env"], _W["pd"]
    ref = _ref(walk)
    start = min(start, ref.n_frames - 3)
    env.reset(ref, start)
    pd.reset(env)
    n = int(cap_s * 30)
    errs = []
    for _ in range(n):
        feats = balance_features(env, 0)
        a = feedback_offsets(env, 0, feats, gains, env.reference_targets())
        _, _, done, info = env.step(a)
        errs.append(info.mpjpe_m[0])
        if done:
            break
    return env.sim_time, float(np.mean(errs)) if errs else 0.0


def _score(args):
    gains, episodes, cap = args
    out = [episode_time(gains, w, s, cap) for w, s in episodes]
    return float(np.mean([o[0] for o in out])), float(np.mean([o[1] for o in out]))


def optimize_gains(library: str | None, generations: int = 25, population: int = 16, elites: int = 4,
                   episodes: int = 8, cap_s: float = 6.0, sigma0: float = 0.3, seed: int = 0, workers: int = 2,
                   log=print, init: np.ndarray | None = None) -> dict:
    """Cross-entropy search over the feedback gains; returns the best mean and the history."""
    import multiprocessing as mp
    rng = np.random.default_rng(seed)
    _init_worker(library, seed)
    src = _W["src"]
    mean = np.zeros(N_GAINS) if init is None else np.asarray(init, float).copy()
    std = np.full(N_GAINS, sigma0)
    hist = []
    t0 = time.time()
    ctx = mp.get_context("fork")
    with ctx.Pool(workers, initializer=_init_worker, initargs=(library, seed)) as pool:
        for gen in range(generations):
            eps = []
            for _ in range(episodes):
                w = tuple(src.random_walk(6, rng))
                eps.append((w, int(rng.integers(0, 120))))
            cands = [mean.copy()] + [mean + std * rng.standard_normal(N_GAINS) for _ in range(population - 1)]
            scores = pool.map(_score, [(c, eps, cap_s) for c in cands])
            ttf = np.array([s[0] for s in scores])
            order = np.argsort(-ttf)
            el = np.array([cands[i] for i in order[:elites]])
            hist.append({"generation": gen, "mean_ttf": float(ttf[0]), "best_ttf": float(ttf[order[0]]),
                         "pop_ttf": float(ttf.mean()), "wall_s": time.time() - t0})
            log(f"gen {gen}: current mean {ttf[0]:.2f}s, best {ttf[order[0]]:.2f}s, population {ttf.mean():.2f}s, "
                f"std {std.mean():.3f}, {time.time() - t0:.0f}s")
            mean = el.mean(0)
            std = np.maximum(0.7 * std + 0.3 * el.std(0), 0.02)
    return {"gains": mean, "history": hist}


# ----------------------------------------------------------------------------------------------
# the structured action space and the feedback teacher in the tracker's trainer


def teacher_labels(worker, gains: np.ndarray, horizon: int) -> dict:
    """Roll the balance-feedback teacher (feedback_action with ``gains``) in every env of the
    worker for ``horizon`` steps, with DART noise (TrainConfig.teacher_noise) on the executed
    action; label each policy observation with the teacher's (noise-free) action."""
    from tracker.track.policy_net import N_BALANCE
    cfg = worker.cfg
    obs_out, act_out = [], []
    episodes = []
    sim_steps = 0
    t0 = time.process_time()
    for _ in range(horizon):
        for i, env in enumerate(worker.envs):
            o = worker.obs[i]
            a = feedback_action(env, 0, o[-N_BALANCE:], gains)
            obs_out.append(o)
            act_out.append(a)
            noisy = a + worker.rng.normal(0.0, cfg.teacher_noise, a.shape)
            o2, _, done, info = env.step(worker.to_residual(env, noisy))
            sim_steps += 1
            worker.ep_len[i] += 1
            fell = info.fall[0] is not None or worker.lost(env, info)
            if done or fell or worker.ep_len[i] >= worker.max_steps:
                episodes.append((int(worker.ep_len[i]), 0.0, "fall" if fell else "cut"))
                worker.ep_len[i] = 0
                worker.obs[i] = worker._reset(i)
            else:
                worker.obs[i] = worker.policy_obs(env, o2)
    return {"obs": np.array(obs_out, np.float32), "act": np.array(act_out, np.float32),
            "w": np.ones(len(obs_out), np.float32), "episodes": episodes, "sim_steps": sim_steps,
            "gain": 0.0, "cpu_s": time.process_time() - t0}


class BalanceWorker(Worker):
    """tracker.learn.train_tracker.Worker with the structured ("balance") action space
    (structured_offsets) and the balance-feedback teacher (``algo="teacher"``, TrainConfig.teacher_gains)."""

    ACTION_SPACES = ("joints", "balance")

    def action_dim(self) -> int:
        return N_BALANCE_ACTIONS if self.cfg.action_space == "balance" else super().action_dim()

    def to_residual(self, env, a: np.ndarray) -> np.ndarray:
        a = super().to_residual(env, a)
        if self.cfg.action_space == "balance":
            return structured_offsets(env, 0, a, env.reference_targets())
        return a

    def teacher_labels(self, gains: np.ndarray, horizon: int) -> dict:
        return teacher_labels(self, gains, horizon)


def load_balance_policy(path: str):
    """A LearnedController for a checkpoint trained in the structured action space (or any other)."""
    from tracker.track.policy_net import LearnedController, load_checkpoint
    ck = load_checkpoint(path)
    amap = structured_offsets if ck["config"].get("action_space", "joints") == "balance" else None
    return LearnedController(ck, str(path), action_map=amap)


def main(argv: list[str] | None = None) -> int:
    """``python -m research.balance train ...``: the tracker's trainer (`igraph-fight tracker train`'s
    options) with BalanceWorker."""
    import argparse

    from tracker.cli import add_train_arguments
    from tracker.learn.train_tracker import main_args
    p = argparse.ArgumentParser(prog="python -m research.balance", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    t = sub.add_parser("train", help="train the tracking policy with the structured action space / the feedback teacher")
    add_train_arguments(t)
    a = p.parse_args(argv)
    return main_args(a, worker_cls=BalanceWorker)


if __name__ == "__main__":
    import sys
    sys.exit(main())
