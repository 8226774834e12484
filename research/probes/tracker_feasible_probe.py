"""Is a physically feasible reference easy to track? (issue 7 probe)

1. Run the strong search teacher (the shipped policy over its balance layer, 16 candidate offsets
   per 0.1 s, each scored over a 1.5 s lookahead: run M's teacher, whose own episodes go 10 s and
   more between falls) closed-loop along one protocol-style walk, from its first frame, until it
   falls or ``--seconds`` pass. Record the states it visits (30 Hz).
2. Turn that executed trajectory into a Reference ("feasible": the simulator produced it, so its
   contacts, centre of mass and accelerations are consistent): qpos / qvel as visited, PD targets
   from the visited poses (tracker.track.reference.ctrl_targets), sites by forward kinematics.
3. Track both the feasible reference and the original (mocap) walk over the same span, from
   several start frames (reference-state initialisation, optional joint-velocity noise), with PD,
   PD + the balance layer and the shipped policy (which includes the layer): time to fall.

If feasibility were what the tracker lacks, the feasible reference would be tracked far longer.

    python -m research.probes.tracker_feasible_probe --seed 100 --walk 0 [--seconds 10] [--out F.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from tracker.track.evaluation import draw_walks, walk_reference
from tracker.body.humanoid import leg_mask
from tracker.track.pd import PDController
from tracker.track.policy_net import NumpyMLP, RunningNorm, Actor, load_checkpoint, load_policy
from tracker.track.reference import FootPenetration, Reference, ctrl_targets, site_positions
from tracker.track.tracking_reward import RewardRef
from tracker.learn.train_tracker import TrainConfig, Worker

CKPT = "tracker/checkpoints/boxing_cmu13.pt"


def searched_trajectory(w: Worker, ck: dict, ref: Reference, seconds: float, candidates: int, lookahead: int,
                        rng: np.random.Generator, log=print, record: dict | None = None,
                        bias_sigma: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, str]:
    """Closed-loop search along ``ref`` from frame 0 (module doc, step 1): visited (qpos, qvel), end reason.
    ``record`` (a dict) receives "states" (full MuJoCo integration states before each step) and
    "actions" (the env actions executed), for research/probes/tracker_tvlqr_probe.py. ``bias_sigma``
    (6 numbers): search over the balance layer's targets instead of the joint residuals
    (tracker.track.vforce steering; research/probes/tracker_lowd_probe.py)."""
    cfg = w.cfg
    env = w.envs[0]
    d = env.data
    actor = Actor(w.obs.shape[1], w.act_dim, cfg.hidden, cfg.init_log_std)
    actor.load_state_dict(ck["policy"])
    net = NumpyMLP(actor.mu)
    norm = RunningNorm(w.obs.shape[1])
    norm.load(ck)
    sig = np.where(leg_mask(w.scene), cfg.search_sigma_legs, cfg.search_sigma)
    holder = None
    if bias_sigma is not None:
        sig = np.asarray(bias_sigma, float)
    get_state, set_state = env.get_state, env.set_state

    obs = env.reset(ref, 0)
    w.pd.reset(env)
    if bias_sigma is not None:
        holder = layer_bias(env)
    env._reward_ref = RewardRef.build(env, w.scene, ref)
    o0 = w.policy_obs(env, obs)
    c = env._cache[0]
    qs, vs = [d.qpos[c.qpos].copy()], [d.qvel[c.qvel].copy()]
    n_steps = min(int(round(seconds * 30)), ref.n_frames - 1)
    reason = "end"
    t0 = time.time()
    while env.t < n_steps:
        s0 = get_state()
        best = None
        for k in range(candidates):
            if k:
                set_state(s0)
            delta = np.zeros(len(sig)) if k == 0 else rng.normal(0.0, 1.0, len(sig)) * sig
            o, ret, disc, seg, after = o0, 0.0, 1.0, [], None
            for j in range(cfg.segment + lookahead):
                a = net(norm(o[None]))[0]
                if holder is not None:
                    holder["b"] = delta if j < cfg.segment else None
                if j < cfg.segment:
                    if holder is None:
                        a = a + delta
                    st = get_state()[0]
                u = w.to_residual(env, a)
                o, _, done, info = env.step(u)
                o = w.policy_obs(env, o)
                term = info.fall[0] is not None or w.lost(env, info)
                if j < cfg.segment:
                    seg.append((d.qpos[c.qpos].copy(), d.qvel[c.qvel].copy(), st, u.copy()))
                if not term:
                    ret += disc * w.reward(env)
                disc *= cfg.search_gamma
                if j == cfg.segment - 1 or ((term or done) and j < cfg.segment):
                    after = (get_state(), o, term, done, list(seg))
                if term or done:
                    break
            if best is None or ret > best[0]:
                best = (ret, after)
        state, o_next, term, done, seg = best[1]
        set_state(state)
        o0 = o_next
        qs += [s[0] for s in seg]
        vs += [s[1] for s in seg]
        if record is not None:
            record.setdefault("states", []).extend(s[2] for s in seg)
            record.setdefault("actions", []).extend(s[3] for s in seg)
        if term:
            reason = "fall"
            break
        if done:
            break
    log(f"  search: {len(qs) / 30:.2f} s visited ({reason}), {time.time() - t0:.0f} s wall")
    return np.array(qs), np.array(vs), reason


def layer_bias(env) -> dict:
    """holder["b"] (6 numbers or None) is written to fighter 0's balance-layer steering
    (tracker.track.vforce, ``bias``: facing-frame shifts of its targets) before each step."""
    holder: dict = {"b": None}
    orig = env.step

    def step(action):
        env.balance.bias[0] = 0.0 if holder["b"] is None else holder["b"]
        return orig(action)

    env.step = step
    return holder


def feasible_reference(w: Worker, qpos: np.ndarray, qvel: np.ndarray) -> Reference:
    """Step 2 of the module doc."""
    fm = w.scene.fighters[0]
    ctrl, ctrl_vel = ctrl_targets(qpos, qvel, fm)
    sites, _ = site_positions(w.scene, fm, qpos)
    return Reference(30.0, qpos, qvel, ctrl, ctrl_vel, sites, FootPenetration.from_depths(np.zeros(len(qpos))),
                     "searched")


def time_tracked(env, controller, ref: Reference, start: int, noise: float, rng: np.random.Generator) -> float:
    """Seconds tracked from ``start`` until a fall or the reference's end."""
    obs = env.reset(ref, start)
    if noise > 0:
        c = env._cache[0]
        env.data.qvel[c.qvel.start + 6:c.qvel.stop] += rng.normal(0.0, noise, c.qvel.stop - c.qvel.start - 6)
        mujoco.mj_forward(env.model, env.data)
        obs = env._obs_all()
    controller.reset(env)
    n = 0
    while True:
        obs, _, done, info = env.step(controller.act(env, obs))
        n += 1
        if info.fall[0] is not None:
            return n / 30.0
        if done:
            return n / 30.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=100, help="seed of the walks (tracker.track.evaluation.draw_walks)")
    ap.add_argument("--walk", type=int, default=0, help="which of the seed's walks")
    ap.add_argument("--actions", type=int, default=20)
    ap.add_argument("--seconds", type=float, default=10.0, help="longest search run (s)")
    ap.add_argument("--candidates", type=int, default=16)
    ap.add_argument("--lookahead", type=int, default=45, help="control steps (45 = 1.5 s)")
    ap.add_argument("--starts", type=int, default=8, help="start frames per reference, evenly spaced")
    ap.add_argument("--noise", type=float, default=0.0, help="joint-velocity noise at the start (rad/s)")
    ap.add_argument("--out", default="")
    a = ap.parse_args(argv)
    ck = load_checkpoint(CKPT)
    cfg = TrainConfig.from_dict({**ck["config"], "init_noise": 0.0, "envs_per_worker": 1, "walks_per_worker": 1,
                                 "push_prob": 0.0})
    w = Worker(cfg, None, 0, a.seed)
    walk = draw_walks(w.src, a.walk + 1, a.actions, a.seed)[a.walk]
    _, ref = walk_reference(w.setup, walk)
    rng = np.random.default_rng([a.seed, a.walk])
    qpos, qvel, reason = searched_trajectory(w, ck, ref, a.seconds, a.candidates, a.lookahead, rng)
    T = len(qpos)
    feas = feasible_reference(w, qpos, qvel)
    orig = Reference(ref.fps, ref.qpos[:T], ref.qvel[:T], ref.ctrl[:T], ref.ctrl_vel[:T], ref.sites[:T],
                     ref.penetration, ref.source)
    dev = np.linalg.norm(feas.sites[:, w.scene.fighters[0].tracked] - orig.sites[:, w.scene.fighters[0].tracked],
                         axis=-1).mean()
    controllers = {"pd": PDController(cfg.kp_scale, cfg.kd_ratio, cfg.torque_scale, cfg.velocity_targets),
                   "pd+layer": w.pd, "policy": load_policy(CKPT)}
    starts = np.linspace(0, max(0, T - 31), a.starts).astype(int)
    env = w.envs[0]
    rows = {}
    for rname, r in (("mocap", orig), ("feasible", feas)):
        for cname, ctl in controllers.items():
            rr = np.random.default_rng(7)
            ts = [time_tracked(env, ctl, r, int(s), a.noise, rr) for s in starts]
            left = [(T - 1 - s) / 30.0 for s in starts]
            rows[f"{rname}/{cname}"] = dict(mean_s=float(np.mean(ts)), completed=int(sum(t >= l - 1e-9 for t, l in zip(ts, left))),
                                            times=[round(t, 3) for t in ts])
            print(f"{rname:9s} {cname:9s} mean {np.mean(ts):5.2f} s  completed {rows[f'{rname}/{cname}']['completed']}/{len(ts)}"
                  f"  (span {np.mean(left):.2f} s)", flush=True)
    out = dict(seed=a.seed, walk=a.walk, search_s=T / 30.0, search_end=reason, candidates=a.candidates,
               lookahead=a.lookahead, noise=a.noise, starts=starts.tolist(), feasible_vs_mocap_cm=100 * float(dev),
               rows=rows)
    print(f"feasible reference {T / 30:.2f} s, {100 * dev:.1f} cm from the mocap's joint sites")
    if a.out:
        Path(a.out).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
