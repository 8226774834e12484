"""Throughput of the physics tracker on one core: real-time factor with the controller in the loop.

    python benchmarks/bench_tracker.py [--seconds 10] [--physics-hz 240] [--json]

Measures, pinned to one CPU core (os.sched_setaffinity) with one BLAS thread:
- bare mj_step rate of one fighter (steps/s) standing on its reference pose;
- the control loop (PDController.act + TrackingEnv.step at 30 Hz, physics substeps inside) for one
  fighter and for two fighters in one scene, over library walks, simulated for ``--seconds`` each
  without stopping at falls (so fallen bodies with many floor contacts are included);
- real-time factor = simulated seconds / wall seconds; "per fighter" for the two-fighter scene
  is the scene's factor (both fighters advance together).
Target: >= 5x per fighter with the controller in the loop.
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

import numpy as np


def control_loop(scene, refs, seconds: float) -> dict:
    from tracker.track.env import EnvConfig, TrackingEnv
    from tracker.track.pd import PDController
    env = TrackingEnv(scene, replace(EnvConfig(), terminate_on_fall=False))
    pd = PDController()
    obs = env.reset(refs, 0)
    pd.reset(env)
    n = int(seconds * env.config.control_hz)
    t0 = time.perf_counter()
    falls = 0
    for _ in range(n):
        obs, _, done, info = env.step(pd.act(env, obs))
        falls += any(f is not None for f in info.fall)
        if done:
            break
    wall = time.perf_counter() - t0
    return {"simulated_s": env.sim_time, "wall_s": wall, "realtime_factor": env.sim_time / wall,
            "control_steps_per_s": env.t / wall, "steps_fallen": falls}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--physics-hz", type=float, default=240.0)
    ap.add_argument("--walks", type=int, default=3)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    except (AttributeError, OSError):
        pass
    import mujoco

    from tracker.body.humanoid import ModelOptions, build_fighter_scene
    from tracker.body.spec import fighter_spec
    from tracker.track.evaluation import draw_walks
    from tracker.track.reference import build_reference, placement_transform
    from tracker.track.walks import LibraryWalks, default_library
    src = LibraryWalks(default_library())
    spec = fighter_spec(src.skeleton, src.calibration_motions())
    opts = replace(ModelOptions(), physics_hz=a.physics_hz)
    one = build_fighter_scene(spec, 1, opts)
    two = build_fighter_scene(spec, 2, opts)
    walks = draw_walks(src, 2 * a.walks, 20, 1234)
    out: dict = {"physics_hz": a.physics_hz, "control_hz": 30.0, "seconds_per_run": a.seconds}

    # Bare physics of one fighter holding its first reference pose.
    ref = build_reference(src.sequence_motion(walks[0]), one, 0)
    m, d = one.model, mujoco.MjData(one.model)
    d.qpos[:] = ref.qpos[0]
    d.ctrl[:] = ref.ctrl[0]
    mujoco.mj_forward(m, d)
    n = int(2 * a.physics_hz)
    t0 = time.perf_counter()
    mujoco.mj_step(m, d, nstep=n)
    out["bare_steps_per_s"] = n / (time.perf_counter() - t0)

    r1 = []
    for w in walks[:a.walks]:
        r1.append(control_loop(one, [build_reference(src.sequence_motion(w), one, 0)], a.seconds))
    out["one_fighter_rtf"] = float(np.sum([r["simulated_s"] for r in r1]) / np.sum([r["wall_s"] for r in r1]))
    out["one_fighter_control_steps_per_s"] = float(np.mean([r["control_steps_per_s"] for r in r1]))
    r2 = []
    for k in range(a.walks):
        refs = [build_reference(src.sequence_motion(walks[a.walks + k - j]), two, j,
                                placement=placement_transform(dx=1.0 * j, heading=np.pi * j)) for j in range(2)]
        r2.append(control_loop(two, refs, a.seconds))
    out["two_fighter_scene_rtf"] = float(np.sum([r["simulated_s"] for r in r2]) / np.sum([r["wall_s"] for r in r2]))
    out["two_vs_one_cost"] = out["one_fighter_rtf"] / out["two_fighter_scene_rtf"]
    out["target_rtf_per_fighter"] = 5.0
    if a.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"one core, {a.physics_hz:g} Hz physics, 30 Hz control, PD in the loop, {a.seconds:g} s per run "
              f"(falls included):")
        print(f"  bare mj_step, one fighter:        {out['bare_steps_per_s']:8.0f} steps/s "
              f"({out['bare_steps_per_s'] / a.physics_hz:.0f}x real time)")
        print(f"  control loop, one fighter:        {out['one_fighter_rtf']:8.1f}x real time "
              f"({out['one_fighter_control_steps_per_s']:.0f} control steps/s)")
        print(f"  control loop, two-fighter scene:  {out['two_fighter_scene_rtf']:8.1f}x real time "
              f"(cost {out['two_vs_one_cost']:.2f}x one fighter)")
        print("  target: >= 5x per fighter")
    return 0


if __name__ == "__main__":
    sys.exit(main())
