"""Walk evaluation: random walks through the action graph, tracked in MuJoCo by a controller.

Protocol (docs/protocols.md, "Tracking"): ``n_walks`` random walks of ``n_actions`` actions drawn
with ``np.random.default_rng(seed)`` (the same walks for every controller), each played with the
library's root placement and short blends (ActionLibrary.sequence_motion), converted to a
Reference at the control rate, and tracked from the walk's first frame (reference-state start)
until the end or a fall (tracker.body.fall.detect_fall). No force acts on the root.

Metrics (``evaluate_walks`` returns them in a dict; ``--json`` prints it):
- completion_rate: share of walks finished without a fall.
- mean_time_to_fall_s: mean over walks of the time tracked before falling, a completed walk
  counting its full duration (censored); mean_time_to_fall_fallen_s: over fallen walks only.
- mpjpe_cm: mean global joint position error (cm) over the tracked joints and the control steps
  before the fall, averaged per walk then over walks.
- root_drift_cm: horizontal distance (cm) between the simulated and reference pelvis at the
  end of the run (the fall or the walk's end), mean over walks.
- realtime_factor: simulated seconds per wall-clock second of the control loop (controller.act +
  env.step, one fighter, one process; with ``workers`` > 1, per process).
- mpjpe_first_1s_cm: the same over the first second only (tracking before balance is lost).
- reference_error_cm: largest distance between a reference joint site and the walk's forward
  kinematics (the conversion accuracy); reference foot penetration (p95 per walk averaged, max over
  walks) before and after the reference is lifted (build_reference lift="auto").
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from igraph_fight.stats import mean_ci

from tracker.track.controllers import Controller
from tracker.track.env import EnvConfig, TrackingEnv
from tracker.body.humanoid import ModelOptions, build_fighter_scene
from tracker.track.reference import build_reference, kinematic_error
from tracker.body.spec import FighterSpec, fighter_spec


@dataclass
class WalkResult:
    walk: list[int]
    duration_s: float
    time_s: float
    fell: bool
    fall_reason: str | None
    mpjpe_m: float
    mpjpe_1s_m: float
    root_drift_m: float
    ref_error_max_m: float
    ref_penetration_p95_m: float
    ref_penetration_max_m: float
    ref_penetration_before_lift_p95_m: float
    ref_penetration_before_lift_max_m: float
    ref_lift_m: float
    sim_s: float
    wall_s: float


@dataclass
class EvalSetup:
    """What an evaluation runs on: the walk source, the fighter spec and scene, the env."""

    source: object
    spec: FighterSpec
    options: ModelOptions = field(default_factory=ModelOptions)
    config: EnvConfig = field(default_factory=EnvConfig)

    def __post_init__(self) -> None:
        self.scene = build_fighter_scene(self.spec, 1, self.options)
        self.env = TrackingEnv(self.scene, self.config)


def make_setup(source, options: ModelOptions = ModelOptions(), config: EnvConfig = EnvConfig(),
               mass_kg: float = 70.0) -> EvalSetup:
    """Calibrate the fighter on the source's frames and build the one-fighter scene."""
    spec = fighter_spec(source.skeleton, source.calibration_motions(), mass_kg=mass_kg)
    return EvalSetup(source, spec, options, config)


def walk_reference(setup: EvalSetup, walk: list[int], lift: str = "auto", blend_frames: int = 4):
    """The walk's motion (resampled to the control rate) and its Reference (tracker.track.reference)."""
    motion = setup.source.sequence_motion(walk, blend_frames)
    ctrl_hz = setup.config.control_hz
    if abs(motion.fps - ctrl_hz) > 1e-9:
        motion = motion.resample(ctrl_hz)
    return motion, build_reference(motion, setup.scene, 0, lift=lift)


def track_reference(env: TrackingEnv, controller: Controller, ref) -> tuple[list[float], str | None, float]:
    """Track ``ref`` from its first frame until its end or a fall: the global joint position error
    (m) of every control step, the fall's reason (None when the reference ran out) and the wall
    seconds of the loop. The env is left at the last step (env.t, env.sim_time, env.data)."""
    obs = env.reset(ref, 0)
    controller.reset(env)
    errs = []
    t0 = time.perf_counter()
    while True:
        obs, _, done, info = env.step(controller.act(env, obs))
        errs.append(info.mpjpe_m[0])
        if done:
            return errs, info.fall[0], time.perf_counter() - t0


def run_walk(setup: EvalSetup, controller: Controller, walk: list[int], lift: str = "auto",
             blend_frames: int = 4) -> WalkResult:
    """Track one walk with a controller; see the module doc for the metrics."""
    env = setup.env
    motion, ref = walk_reference(setup, walk, lift, blend_frames)
    fm = setup.scene.fighters[0]
    kin = kinematic_error(motion, ref, fm)
    errs, fall, wall = track_reference(env, controller, ref)
    pel = env.data.qpos[fm.qpos_adr:fm.qpos_adr + 2]
    drift = float(np.linalg.norm(pel - ref.qpos[env.t, :2]))
    before = ref.meta.get("penetration_before_lift", {})
    first = errs[:int(round(setup.config.control_hz))]
    return WalkResult(list(walk), ref.duration, env.sim_time, fall is not None, fall, float(np.mean(errs)),
                      float(np.mean(first)), drift, float(kin.max()), ref.penetration.p95_m, ref.penetration.max_m,
                      before.get("p95_cm", 0.0) / 100.0, before.get("max_cm", 0.0) / 100.0, ref.penetration.lift_m,
                      env.sim_time, wall)


def draw_walks(source, n_walks: int, n_actions: int, seed: int) -> list[list[int]]:
    """The walks of an evaluation: a function of (source, n_walks, n_actions, seed) only."""
    rng = np.random.default_rng(seed)
    return [source.random_walk(n_actions, rng) for _ in range(n_walks)]


def evaluate_walks(setup: EvalSetup, controller: Controller, n_walks: int = 100, n_actions: int = 20,
                   seed: int = 0, progress: bool = False, lift: str = "auto", workers: int = 1) -> dict:
    """Run the protocol and return the metrics dict (module doc). ``workers`` > 1 tracks the walks in
    that many processes (each its own scene; every walk is independent and deterministic, so the
    metrics equal a serial run's except the wall-clock figures)."""
    walks = draw_walks(setup.source, n_walks, n_actions, seed)
    results = run_walks(setup, controller, walks, lift, workers, progress)
    return summarise(results, controller, setup, n_actions, seed)


def run_walks(setup: EvalSetup, controller: Controller, walks: list, lift: str = "auto", workers: int = 1,
              progress: bool = False) -> list[WalkResult]:
    """``run_walk`` for each walk, in order; ``workers`` > 1 spreads them over that many processes
    (each builds its scene once; the results equal a serial run's except the wall-clock figures)."""
    if workers <= 1 or len(walks) <= 1:
        it = walks
        if progress:
            from tqdm import tqdm
            it = tqdm(walks, desc=f"walks ({controller.name})", unit="walk")
        return [run_walk(setup, controller, w, lift) for w in it]
    import multiprocessing as mp
    jobs = [(controller, i, w, lift) for i, w in enumerate(walks)]
    out: list = [None] * len(walks)
    init = (setup.source, setup.spec, setup.options, setup.config)
    with mp.get_context("spawn").Pool(min(workers, len(walks)), initializer=_init_worker, initargs=init) as pool:
        it = pool.imap_unordered(_walk_job, jobs)
        if progress:
            from tqdm import tqdm
            it = tqdm(it, total=len(jobs), desc=f"walks ({controller.name}, {workers} processes)", unit="walk")
        for i, r in it:
            out[i] = r
    return out


_WORKER_SETUP: EvalSetup | None = None     # the scene of a run_walks worker process (_init_worker)


def _init_worker(source, spec, options, config) -> None:
    import torch
    torch.set_num_threads(1)
    global _WORKER_SETUP
    _WORKER_SETUP = EvalSetup(source, spec, options, config)


def _walk_job(args) -> tuple[int, WalkResult]:
    controller, i, walk, lift = args
    return i, run_walk(_WORKER_SETUP, controller, walk, lift)


def paired_comparison(setup: EvalSetup, controller: Controller, baseline: Controller, n_walks: int = 100,
                      n_actions: int = 20, seed: int = 0) -> dict:
    """Both controllers on the protocol's same walks: mean time to fall (s) of each, the ratio of
    the means, the paired difference (controller - baseline) with a 95% interval (normal
    approximation), on how many walks the controller lasted longer / shorter, and MPJPE (cm)."""
    t0 = time.time()
    walks = draw_walks(setup.source, n_walks, n_actions, seed)
    base = [run_walk(setup, baseline, w) for w in walks]
    pol = [run_walk(setup, controller, w) for w in walks]
    base_t, pol_t = np.array([r.time_s for r in base]), np.array([r.time_s for r in pol])
    d = pol_t - base_t
    ci = mean_ci(d, normal=True)
    return {"walks": n_walks, "actions": n_actions, "seed": seed, "baseline_ttf_s": float(base_t.mean()),
            "policy_ttf_s": float(pol_t.mean()), "ratio": float(pol_t.mean() / base_t.mean()),
            "diff_s": float(d.mean()), "diff_ci95_s": [ci["ci_low"], ci["ci_high"]],
            "policy_better_walks": int((d > 0).sum()), "policy_worse_walks": int((d < 0).sum()),
            "baseline_mpjpe_cm": 100 * float(np.mean([r.mpjpe_m for r in base])),
            "policy_mpjpe_cm": 100 * float(np.mean([r.mpjpe_m for r in pol])), "wall_s": time.time() - t0}


def summarise(results: list[WalkResult], controller: Controller, setup: EvalSetup, n_actions: int, seed: int) -> dict:
    fell = np.array([r.fell for r in results])
    t = np.array([r.time_s for r in results])
    sim = sum(r.sim_s for r in results)
    wall = sum(r.wall_s for r in results)
    return {
        "controller": controller.name,
        "n_walks": len(results),
        "n_actions": n_actions,
        "seed": seed,
        "completion_rate": float(np.mean(~fell)) if len(results) else float("nan"),
        "mean_time_to_fall_s": float(t.mean()) if len(t) else float("nan"),
        "mean_time_to_fall_fallen_s": float(t[fell].mean()) if fell.any() else None,
        "median_time_to_fall_s": float(np.median(t)) if len(t) else float("nan"),
        "mean_walk_duration_s": float(np.mean([r.duration_s for r in results])) if results else float("nan"),
        "mpjpe_cm": 100.0 * float(np.mean([r.mpjpe_m for r in results])) if results else float("nan"),
        "mpjpe_first_1s_cm": 100.0 * float(np.mean([r.mpjpe_1s_m for r in results])) if results else float("nan"),
        "root_drift_cm": 100.0 * float(np.mean([r.root_drift_m for r in results])) if results else float("nan"),
        "realtime_factor": sim / wall if wall > 0 else float("nan"),
        "fall_reasons": _counts([r.fall_reason for r in results if r.fell]),
        "reference_error_cm": 100.0 * max((r.ref_error_max_m for r in results), default=0.0),
        "reference_penetration_p95_cm": 100.0 * float(np.mean([r.ref_penetration_p95_m for r in results])) if results else 0.0,
        "reference_penetration_max_cm": 100.0 * max((r.ref_penetration_max_m for r in results), default=0.0),
        "reference_penetration_before_lift_p95_cm": 100.0 * float(np.mean([r.ref_penetration_before_lift_p95_m
                                                                            for r in results])) if results else 0.0,
        "reference_penetration_before_lift_max_cm": 100.0 * max((r.ref_penetration_before_lift_max_m for r in results),
                                                                 default=0.0),
        "reference_lift_cm": 100.0 * float(np.mean([r.ref_lift_m for r in results])) if results else 0.0,
        "physics_hz": setup.options.physics_hz,
        "control_hz": setup.config.control_hz,
        "source": setup.source.describe() if hasattr(setup.source, "describe") else type(setup.source).__name__,
        "simulated_s": sim,
        "wall_s": wall,
    }


def _counts(xs: list) -> dict:
    out: dict = {}
    for x in xs:
        out[str(x)] = out.get(str(x), 0) + 1
    return out


def format_report(m: dict) -> str:
    """Human-readable summary of evaluate_walks' dict."""
    lines = [
        f"controller {m['controller']}: {m['n_walks']} walks x {m['n_actions']} actions (seed {m['seed']}), "
        f"mean walk {m['mean_walk_duration_s']:.1f} s; {m['source']}",
        f"  completed without a fall: {100 * m['completion_rate']:.1f}%",
        f"  mean time to fall:        {m['mean_time_to_fall_s']:.2f} s (median {m['median_time_to_fall_s']:.2f} s)",
        f"  mean joint error:         {m['mpjpe_cm']:.1f} cm (first second: {m['mpjpe_first_1s_cm']:.1f} cm)",
        f"  root drift:               {m['root_drift_cm']:.1f} cm",
        f"  real-time factor:         {m['realtime_factor']:.1f}x (one fighter, {m['physics_hz']:g} Hz physics, "
        f"{m['control_hz']:g} Hz control)",
        f"  falls by reason:          {m['fall_reasons']}",
        f"  reference: max joint error {m['reference_error_cm']:.4f} cm; foot penetration p95 "
        f"{m['reference_penetration_before_lift_p95_cm']:.1f} cm, max {m['reference_penetration_before_lift_max_cm']:.1f} cm; "
        f"after a mean lift of {m['reference_lift_cm']:.1f} cm: p95 {m['reference_penetration_p95_cm']:.1f} cm, "
        f"max {m['reference_penetration_max_cm']:.1f} cm",
    ]
    return "\n".join(lines)


