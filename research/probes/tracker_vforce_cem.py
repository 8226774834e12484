"""Cross-entropy search over the virtual-force balance gains (tracker/track/vforce.py) under PD tracking.

Each candidate (com_kp, com_kd, root_kp, root_kd, torque_clip; searched in log space) is scored by
the mean time to fall over the same random 20-action walks of the tuning seed (100), no force on
the root, minus ``slide_penalty`` x (the feet's sliding speed above ``slide_target``): the
contact-force-weighted horizontal speed of the foot geoms touching the floor (m/s; PD 0.17). Both
cores evaluate candidates (research/notes/TRAINING.md). The first search, on time to fall
only, found gains that balance by skating (0.71 m/s); BalanceGains' defaults come from the second:

    python -m research.probes.tracker_vforce_cem --walks 24 --slide-penalty 0 --start 4000,800,1000,100,150 --seed 0
    python -m research.probes.tracker_vforce_cem --walks 12 --slide-penalty 4 --slide-target 0.25 --seed 1   # the defaults

``--arm-velocity-targets`` searches under PD with the arms damped towards the reference velocity
(gains for that setting: TRAINING.md). ``--policy CKPT`` searches under a learned
tracker instead of PD (the checkpoint's ``vf_gains`` replaced by each candidate):

    python -m research.probes.tracker_vforce_cem --policy tracker/checkpoints/boxing_cmu13.pt --walks 12 \
        --slide-penalty 4 --slide-target 0.32 --start 3200,500,280,100,58 --seed 3
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import time

import mujoco
import numpy as np


from tracker.track.evaluation import draw_walks, make_setup, track_reference, walk_reference
from tracker.track.pd import PDController
from tracker.track.walks import walk_source

_SETUP = None
_WALKS: list = []
_PENALTY = (0.0, 0.25)      # (slide_penalty, slide_target), set in the workers by _init
_ARM_VEL = False            # PD with arm velocity targets (tracker.track.env), set by _init
_POLICY = None              # a loaded learned-tracker checkpoint (dict) to search under, set by _init


def _init(n_walks: int, seed: int, penalty: tuple[float, float] = (0.0, 0.25), arm_vel: bool = False,
          policy: str | None = None) -> None:
    global _SETUP, _WALKS, _PENALTY, _ARM_VEL, _POLICY
    _SETUP = make_setup(walk_source(None))
    _WALKS = draw_walks(_SETUP.source, n_walks, 20, seed)
    _PENALTY = penalty
    _ARM_VEL = arm_vel
    if policy:
        import torch
        torch.set_num_threads(1)
        from tracker.track.policy_net import load_checkpoint
        _POLICY = load_checkpoint(policy)


def controller(gains):
    """PD (or the learned tracker of ``--policy``) over the balance layer with ``gains`` (None: without it)."""
    if _POLICY is None:
        return PDController(balance=gains, arm_velocity_targets=_ARM_VEL)
    from tracker.track.policy_net import LearnedController
    ck = dict(_POLICY)
    ck["config"] = dict(_POLICY["config"], vf_gains=list(gains) if gains else [])
    return LearnedController(ck)


def sliding(ctrl) -> tuple[float, float]:
    """(mean time to fall s, contact-force-weighted sliding speed of the feet on the floor m/s) of a
    controller on the walks."""
    env, scene = _SETUP.env, _SETUP.scene
    m, floor = scene.model, scene.floor_geom
    feet = {int(g) for g in scene.fighters[0].foot_geoms}
    acc = np.zeros(2)
    v6, fr = np.zeros(6), np.zeros(6)

    def hook(d, s) -> None:
        for i in range(d.ncon):
            c = d.contact[i]
            g = int(c.geom2) if c.geom1 == floor else int(c.geom1) if c.geom2 == floor else -1
            if g in feet:
                mujoco.mj_contactForce(m, d, i, fr)
                mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_GEOM, g, v6, 0)
                acc[:] += (fr[0] * np.linalg.norm(v6[3:5]), fr[0])
    times = []
    env.substep_hook = hook                  # kept by env.reset: the evaluation's own tracking loop
    try:
        for w in _WALKS:
            track_reference(env, ctrl, walk_reference(_SETUP, w)[1])
            times.append(env.sim_time)
    finally:
        env.substep_hook = None
    return float(np.mean(times)), float(acc[0] / max(acc[1], 1e-9))


def score(log_gains: np.ndarray) -> tuple[float, float, float]:
    """(score, time to fall s, sliding m/s) of PD + the balance layer with exp(log_gains)."""
    t, sl = sliding(controller(tuple(float(g) for g in np.exp(log_gains))))
    pen, target = _PENALTY
    return t - pen * max(0.0, sl - target), t, sl


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--walks", type=int, default=24)
    ap.add_argument("--generations", type=int, default=8)
    ap.add_argument("--population", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0, help="sampling seed (the walks are always of seed 100)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--slide-penalty", type=float, default=4.0, help="score = time to fall - this x excess sliding")
    ap.add_argument("--slide-target", type=float, default=0.25, help="sliding speed (m/s) that costs nothing")
    ap.add_argument("--start", default="2000,500,750,75,60", help="first mean of the search (five gains)")
    ap.add_argument("--arm-velocity-targets", action="store_true", help="the PD's arm actuators damp towards the reference velocity")
    ap.add_argument("--policy", default=None, help="search under this learned-tracker checkpoint instead of PD")
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    start = np.array([float(x) for x in a.start.split(",")])
    mu, sd = np.log(start), np.full(len(start), 0.5)
    pen = (a.slide_penalty, a.slide_target)
    _init(a.walks, 100, pen, a.arm_velocity_targets, a.policy)
    base = "the policy alone" if a.policy else "PD"
    t_pd, sl_pd = sliding(controller(None))
    print(f"{a.walks} walks of seed 100: {base} {t_pd:.2f} s, sliding {sl_pd:.2f} m/s", flush=True)
    if a.policy:
        t0, s0 = sliding(controller(tuple(float(x) for x in start)))
        print(f"  over the start gains {a.start}: {t0:.2f} s, sliding {s0:.2f} m/s", flush=True)
    with mp.get_context("fork").Pool(a.workers, initializer=_init,
                                      initargs=(a.walks, 100, pen, a.arm_velocity_targets, a.policy)) as pool:
        for gen in range(a.generations):
            t0 = time.time()
            X = mu + sd * rng.standard_normal((a.population, len(mu)))
            R = np.array(pool.map(score, list(X)))
            elite = X[np.argsort(-R[:, 0])[:max(3, a.population // 4)]]
            mu, sd = elite.mean(0), np.maximum(elite.std(0), 0.1)
            i = int(np.argmax(R[:, 0]))
            print(f"generation {gen}: best score {R[i, 0]:.2f} (time to fall {R[i, 1]:.2f} s, sliding {R[i, 2]:.2f} m/s) "
                  f"at {np.round(np.exp(X[i]))}; mean gains {np.round(np.exp(mu))} ({time.time() - t0:.0f} s)", flush=True)
    s, t, sl = score(mu)
    print(f"final mean gains {np.round(np.exp(mu))}: time to fall {t:.2f} s, sliding {sl:.2f} m/s ({base} {t_pd:.2f} s, "
          f"{sl_pd:.2f} m/s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
