"""Offline sampling search (SAMCON-like) for open-loop corrections of the PD targets.

Used for the route comparison (tracker/MEASUREMENTS.md, issue 7) and as the expert of
tracker.imitation. Not used at run time (it is ~40x slower than real time).

For a reference, every ``segment`` control steps the search keeps ``elites`` simulation states.
From each it samples offsets (residual PD targets, constant over the segment, Gaussian around
``carry`` x the parent's offset), simulates the segment, and scores the end state with a tracking
cost (pose, end effectors, root position with a root-drift weight, root orientation, centre of
mass, velocity). The best ``elites`` of all samples survive. When every sample of a segment
falls, the search backtracks one segment and retries with twice the samples (up to
``max_backtracks`` times), else it stops there. The result is the best chain: per control step
the state's observation and the residual that was applied.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import mujoco
import numpy as np


@dataclass
class SearchConfig:
    samples: int = 200          # samples per segment (over all elites)
    elites: int = 10
    segment: int = 3            # control steps per segment (0.1 s)
    sigma: float = 0.15         # offset std (rad)
    sigma_legs: float = 0.25    # offset std on hip/knee/ankle/toe actuators
    carry: float = 0.7          # sample mean = carry * the parent's offset
    max_backtracks: int = 12      # in total over the search
    lookahead: int = 6            # control steps simulated past the segment (same offset) to score it
    w_pose: float = 1.0
    w_ee: float = 4.0
    w_root: float = 8.0         # horizontal root drift (m^2)
    w_root_z: float = 10.0
    w_up: float = 2.0           # root orientation (1 - cos tilt difference)
    w_com: float = 10.0
    w_vel: float = 0.01


@dataclass
class SearchResult:
    steps: int                       # control steps tracked
    fell: bool
    obs: np.ndarray                  # (steps, obs_dim) observation before each step
    actions: np.ndarray              # (steps, n_act) residual applied
    mpjpe_m: np.ndarray              # (steps,)
    sim_steps: int                   # control steps simulated in total (cost)
    wall_s: float
    elite_obs: list = field(default_factory=list)     # extra (obs, action) pairs from other elites
    elite_actions: list = field(default_factory=list)


class _Node:
    __slots__ = ("state", "offset", "parent", "obs", "acts", "errs", "cost")

    def __init__(self, state, offset, parent, obs, acts, errs, cost):
        self.state, self.offset, self.parent = state, offset, parent
        self.obs, self.acts, self.errs, self.cost = obs, acts, errs, cost


def _leg_mask(env) -> np.ndarray:
    f = env.scene.fighters[0]
    return np.array([c in ("thigh", "shin", "foot", "toe", "hip", "knee", "ankle") for c in f.act_class])


def search_reference(env, ref, com_ref: np.ndarray, cfg: SearchConfig, rng: np.random.Generator,
                     start: int = 0, n_steps: int | None = None) -> SearchResult:
    """Search corrections for ``ref`` from ``start`` for ``n_steps`` control steps (default: to the end).
    ``env`` must be a one-fighter TrackingEnv with residual actions and the PD gains already set."""
    m, d = env.model, env.data
    sig = np.where(_leg_mask(env), cfg.sigma_legs, cfg.sigma)
    n_act = env.n_act
    spec = mujoco.mjtState.mjSTATE_INTEGRATION
    size = mujoco.mj_stateSize(m, spec)

    def get_state():
        s = np.empty(size)
        mujoco.mj_getState(m, d, s, spec)
        return (s, env.t)

    def set_state(st):
        mujoco.mj_setState(m, d, st[0], spec)
        env.t = st[1]
        env.done = False
        mujoco.mj_forward(m, d)

    obs0 = env.reset(ref, start)
    vt = env.velocity_targets
    T_end = ref.n_frames - 1 if n_steps is None else min(ref.n_frames - 1, start + n_steps)
    pel = env.scene.fighters[0].pelvis_body
    c = env._cache[0]
    t0 = time.perf_counter()
    sim_steps = 0
    root = _Node(get_state(), np.zeros(n_act), None, [], [], [], 0.0)
    layers = [[root]]
    backtracks = 0            # in total
    fails = 0                 # consecutive failed segments (doubles the samples)
    fell = False
    while True:
        t_now = layers[-1][0].state[1]
        if t_now >= T_end:
            break
        seg = min(cfg.segment, T_end - t_now)
        n = cfg.samples * (2 ** min(fails, 2))
        parents = layers[-1]
        children = []
        for j in range(n):
            p = parents[j % len(parents)]
            off = cfg.carry * p.offset + rng.normal(0.0, 1.0, n_act) * sig
            set_state(p.state)
            env.velocity_targets = vt
            obs_l, err_l = [], []
            dead = False
            o = env._obs_all()
            for _ in range(seg):
                obs_l.append(o)
                o, _, done, info = env.step(off)
                sim_steps += 1
                err_l.append(info.mpjpe_m[0])
                if info.fall[0] is not None:
                    dead = True
                    break
            if dead:
                continue
            cost = _cost(env, ref, com_ref, c, pel, cfg)
            state = get_state()
            for _ in range(min(cfg.lookahead, T_end - env.t)):   # score the future of the state too
                _, _, done, info = env.step(off)
                sim_steps += 1
                if info.fall[0] is not None:
                    cost += 100.0
                    break
                cost += _cost(env, ref, com_ref, c, pel, cfg) / max(1, cfg.lookahead)
            children.append(_Node(state, off, p, obs_l, [off] * seg, err_l, cost))
        if not children:
            if len(layers) > 1 and backtracks < cfg.max_backtracks:
                layers.pop()
                backtracks += 1
                fails += 1
                continue
            fell = True
            break
        children.sort(key=lambda x: x.cost)
        layers.append(children[:cfg.elites])
        fails = 0
    best = layers[-1][0]
    chain = []
    node = best
    while node is not None and node.parent is not None:
        chain.append(node)
        node = node.parent
    chain.reverse()
    obs = np.array([o for nd in chain for o in nd.obs]) if chain else np.zeros((0, obs0.shape[0]))
    acts = np.array([a for nd in chain for a in nd.acts]) if chain else np.zeros((0, n_act))
    errs = np.array([e for nd in chain for e in nd.errs])
    eo, ea = [], []
    for layer in layers[1:]:
        for nd in layer[1:]:
            eo.extend(nd.obs)
            ea.extend(nd.acts)
    return SearchResult(len(acts), fell, obs, acts, errs, sim_steps, time.perf_counter() - t0, eo, ea)


def _cost(env, ref, com_ref, c, pel, cfg: SearchConfig) -> float:
    d = env.data
    t = env.t
    q = d.qpos[c.qpos]
    qr = ref.qpos[t]
    qs = q[c.joint_q - c.qpos.start]
    qrr = qr[c.joint_q - c.qpos.start]
    dots = np.abs((qs * qrr).sum(axis=1)).clip(0.0, 1.0)
    ang = 2.0 * np.arccos(dots)
    pose = float((ang * ang).sum())
    ee = d.site_xpos[c.sites[c.ee_sites]] - ref.sites[t, c.ee_sites]
    ee_e = float((ee * ee).sum())
    dr = q[:3] - qr[:3]
    up_s = d.xmat[pel].reshape(3, 3)[2]
    R = np.empty(9)
    mujoco.mju_quat2Mat(R, qr[3:7])
    up_r = R.reshape(3, 3)[2]
    com = d.subtree_com[pel] - com_ref[t]
    v = d.qvel[c.qvel][6:] - ref.qvel[t, 6:]
    return (cfg.w_pose * pose + cfg.w_ee * ee_e + cfg.w_root * float(dr[:2] @ dr[:2]) + cfg.w_root_z * dr[2] ** 2
            + cfg.w_up * float(1.0 - up_s @ up_r) + cfg.w_com * float(com @ com) + cfg.w_vel * float(v @ v))
