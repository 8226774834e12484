"""Throughput of the batched tracking environment with a policy in the loop, one core.

    python benchmarks/bench_batch_env.py [--envs 32] [--steps 300] [--physics-hz 120] [--json]

Control steps per second (every world's steps together) of the batched env (tracker.track.batch_env)
with the assisted tracker's policy (its shipped checkpoint, else a random network of the same
shape) choosing every step's residuals and wrench, against the legacy single-world environment
(tracker.track.env.TrackingEnv at 240 Hz with its learned policy) in the same run, and the
batched env's N = 1 (a game's single fighter). Walks: random 20-action library walks (seed 0),
grounded; a slot whose walk ends or falls restarts on the next walk. Prints figures and ratios.
"""
from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")


def batched_rate(setup, refs, n_envs: int, steps: int) -> float:
    import numpy as np

    from tracker.track.assist import AssistConfig
    from tracker.track.batch_env import BatchConfig, BatchEnv
    ctrl = _policy(setup)
    env = BatchEnv(setup.scene, n_envs, BatchConfig(assist=AssistConfig("learned", ctrl.cap)))
    ctrl.reset(env)
    nxt = 0
    obs = env.reset(np.arange(n_envs), [refs[(i + nxt) % len(refs)] for i in range(n_envs)])
    nxt = n_envs
    t0 = time.perf_counter()
    done_steps = 0
    for _ in range(steps):
        targets, assist = ctrl.act(env, obs)
        obs, _, done, _ = env.step(targets, assist)
        done_steps += int((~done).sum()) + int(done.sum())
        for b in np.nonzero(done)[0]:
            env.reset([b], [refs[nxt % len(refs)]])
            nxt += 1
        if done.any():
            obs = env.observe()
    return done_steps / (time.perf_counter() - t0)


def legacy_rate(source, steps: int) -> float:
    from tracker.track.evaluation import draw_walks, make_setup, walk_reference
    from tracker.track.policy_net import load_default_policy
    setup = make_setup(source)
    ctrl = load_default_policy()
    walks = draw_walks(source, 4, 20, 0)
    env = setup.env
    n, i = 0, 0
    obs = env.reset(walk_reference(setup, walks[0])[1], 0)
    ctrl.reset(env)
    t0 = time.perf_counter()
    while n < steps:
        obs, _, done, _ = env.step(ctrl.act(env, obs))
        n += 1
        if done:
            i += 1
            obs = env.reset(walk_reference(setup, walks[i % len(walks)])[1], 0)
            ctrl.reset(env)
    return n / (time.perf_counter() - t0)


def _policy(setup):
    """The shipped assisted tracker, or an untrained one of the same shape."""
    from tracker.track.assisted_policy import DEFAULT_ASSISTED_CKPT, load_assisted
    if DEFAULT_ASSISTED_CKPT.is_file():
        return load_assisted()
    import numpy as np

    from tracker.track.assisted_policy import FORMAT, VERSION, AssistedController
    from tracker.track.batch_env import BatchConfig, BatchEnv
    env = BatchEnv(setup.scene, 1, BatchConfig())
    od, na = env.obs_dim, env.n_act + 6
    rng = np.random.default_rng(0)
    sizes = [od, 512, 256, na]
    actor = {}
    for i in range(3):
        actor[f"mu.{2 * i}.weight"] = rng.normal(0, 0.01, (sizes[i + 1], sizes[i]))
        actor[f"mu.{2 * i}.bias"] = np.zeros(sizes[i + 1])
    return AssistedController({"format": FORMAT, "version": VERSION, "actor": actor, "obs_mean": np.zeros(od),
                               "obs_var": np.ones(od), "config": {}, "cap": 0.5}, "(untrained)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--envs", type=int, default=32, help="worlds stepped together (default 32)")
    ap.add_argument("--steps", type=int, default=300, help="control steps of the batch to time (default 300)")
    ap.add_argument("--physics-hz", type=float, default=120.0)
    ap.add_argument("--no-legacy", action="store_true", help="skip the legacy environment")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    from tracker.track.evaluation import draw_walks, make_setup, walk_reference
    from tracker.track.pd import batched_model_options
    from tracker.track.walks import default_library, LibraryWalks
    src = LibraryWalks(default_library(None))
    setup = make_setup(src, batched_model_options(a.physics_hz))
    refs = [walk_reference(setup, w, lift="ground")[1] for w in draw_walks(src, max(8, a.envs), 20, 0)]
    out = {"envs": a.envs, "physics_hz": a.physics_hz,
           "batched_steps_per_s": batched_rate(setup, refs, a.envs, a.steps),
           "batched_n1_steps_per_s": batched_rate(setup, refs, 1, max(60, a.steps // 4))}
    if not a.no_legacy:
        out["legacy_steps_per_s"] = legacy_rate(src, max(60, a.steps // 4))
        out["ratio_batched_to_legacy"] = out["batched_steps_per_s"] / out["legacy_steps_per_s"]
    out["realtime_factor_n1"] = out["batched_n1_steps_per_s"] / 30.0
    if a.json:
        print(json.dumps(out))
        return
    print(f"batched env, {a.envs} worlds at {a.physics_hz:g} Hz, policy in the loop: "
          f"{out['batched_steps_per_s']:.0f} control steps/s on one core")
    print(f"batched env, one world (a game's fighter): {out['batched_n1_steps_per_s']:.0f} steps/s "
          f"= {out['realtime_factor_n1']:.1f}x real time")
    if "legacy_steps_per_s" in out:
        print(f"legacy env (240 Hz, learned policy): {out['legacy_steps_per_s']:.0f} steps/s; ratio "
              f"{out['ratio_batched_to_legacy']:.1f}x")


if __name__ == "__main__":
    main()
