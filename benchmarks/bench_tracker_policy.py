"""Throughput of the learned tracker on one core: real-time factor with the policy in the loop.

    python benchmarks/bench_tracker_policy.py [--seconds 10] [--walks 3] [--ckpt CKPT] [--json]

Pinned to one CPU core with one BLAS / torch thread. For the shipped policy (or ``--ckpt``):
- policy inference alone (LearnedController.act: normalise, numpy MLP, clip), microseconds per call;
- the control loop (act + TrackingEnv.step, 30 Hz control, 240 Hz physics) of one fighter over
  library walks, and of two fighters in one scene (the policy batched over both), simulated for
  ``--seconds`` each without stopping at falls; PD-only in the same loop for comparison.
Target: >= 5x real time per fighter on one core.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import replace

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")


def control_loop(scene, refs, controller, seconds: float) -> dict:
    from tracker.track.env import EnvConfig, TrackingEnv
    env = TrackingEnv(scene, replace(EnvConfig(), terminate_on_fall=False))
    obs = env.reset(refs, 0)
    controller.reset(env)
    n = int(seconds * env.config.control_hz)
    t0 = time.perf_counter()
    t_act = 0.0
    falls = 0
    for _ in range(n):
        ta = time.perf_counter()
        a = controller.act(env, obs)
        t_act += time.perf_counter() - ta
        obs, _, done, info = env.step(a)
        falls += any(f is not None for f in info.fall)
        if done:
            break
    wall = time.perf_counter() - t0
    return {"simulated_s": env.sim_time, "wall_s": wall, "realtime_factor": env.sim_time / wall,
            "act_us_per_step": 1e6 * t_act / max(env.t, 1), "steps_fallen": falls}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--walks", type=int, default=3)
    ap.add_argument("--library", default=None)
    ap.add_argument("--ckpt", default=None, help="policy checkpoint (default: the shipped one)")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    except (AttributeError, OSError):
        pass
    from tracker.body.humanoid import ModelOptions, build_fighter_scene
    from tracker.body.spec import fighter_spec
    from tracker.track.env import TrackingEnv
    from tracker.track.evaluation import draw_walks
    from tracker.track.pd import PDController
    from tracker.track.policy_net import load_policy
    from tracker.track.reference import build_reference, placement_transform
    from tracker.track.walks import walk_source
    try:
        import torch
        torch.set_num_threads(1)
    except ImportError:
        pass
    src = walk_source(a.library)
    spec = fighter_spec(src.skeleton, src.calibration_motions())
    one = build_fighter_scene(spec, 1, ModelOptions())
    two = build_fighter_scene(spec, 2, ModelOptions())
    policy = load_policy(a.ckpt)
    walks = draw_walks(src, 2 * a.walks, 20, 1234)
    out: dict = {"ckpt": policy.ckpt_path, "seconds_per_run": a.seconds}

    ref = build_reference(src.sequence_motion(walks[0]), one, 0)
    env = TrackingEnv(one)
    obs = env.reset(ref, 0)
    policy.reset(env)
    reps = 2000
    t0 = time.perf_counter()
    for _ in range(reps):
        policy.act(env, obs)
    out["policy_act_us"] = 1e6 * (time.perf_counter() - t0) / reps

    for name, ctrl in (("learned", policy), ("pd", PDController())):
        runs = [control_loop(one, [build_reference(src.sequence_motion(walks[i]), one, 0)], ctrl, a.seconds)
                for i in range(a.walks)]
        sim, wall = sum(r["simulated_s"] for r in runs), sum(r["wall_s"] for r in runs)
        out[f"one_fighter_{name}"] = {"realtime_factor": sim / wall, "runs": runs}
        runs2 = []
        for i in range(a.walks):
            refs = [build_reference(src.sequence_motion(walks[2 * i + k]), two, k,
                                    placement=placement_transform(dx=1.5 * k)) for k in range(2)]
            runs2.append(control_loop(two, refs, ctrl, a.seconds))
        sim, wall = sum(r["simulated_s"] for r in runs2), sum(r["wall_s"] for r in runs2)
        out[f"two_fighters_{name}"] = {"realtime_factor_scene": sim / wall, "runs": runs2}

    if a.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"policy {out['ckpt']}: act() {out['policy_act_us']:.0f} us per call (one fighter)")
        for name in ("learned", "pd"):
            o, t = out[f"one_fighter_{name}"], out[f"two_fighters_{name}"]
            print(f"{name:8s} one fighter: {o['realtime_factor']:.1f}x real time; two-fighter scene: "
                  f"{t['realtime_factor_scene']:.1f}x (each fighter), {a.walks} walks x {a.seconds:g} s, one core")
    return 0


if __name__ == "__main__":
    sys.exit(main())
