"""The walk protocol on the batched environment: random walks through the action graph tracked in
MuJoCo by a controller, with or without the balance assist (docs/protocols.md, "Tracking").

``n_walks`` walks of ``n_actions`` actions drawn with ``np.random.default_rng(seed)`` (the same
walks for every controller), each played with the library's root placement and short blends,
converted to a grounded Reference at the control rate (tracker.track.grounding), and tracked from
its first frame until its end or a fall. Walks run ``parallel`` at a time in one BatchEnv (every
world is independent: the figures do not depend on ``parallel`` except the wall-clock ones).

Per walk: whether it completed, the time tracked, the global joint position error (the mean over
tracked joints and steps before the fall, cm), the re-rooted error (the reference re-anchored to
the simulated pelvis, position on the ground and yaw, at each action's start: as a game places the
next clip), the root drift at the end (cm) and the applied assist (tracker.track.assist). The
summary (``summarise``) carries the figures ``igraph-fight tracker eval --json`` prints.

Placement (``placement``): ``"world"`` tracks the walk as drawn, its root path fixed in the world,
so the controller also corrects the drift it accumulated in earlier actions; ``"body"`` places each
action's clip under the simulated pelvis at the action's start (BatchEnv.place_on_body), as a game
and the physics bouts do, so the controller tracks the re-rooted reference itself. The global error
is always measured against the walk as drawn, the re-rooted one against the placed clip.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from tracker.track.assist import summarise_assist
from tracker.track.batch_env import BatchConfig, BatchEnv, yaws_of


@dataclass
class WalkRun:
    """One tracked walk."""

    walk: list[int]
    duration_s: float
    time_s: float
    fell: bool
    fall_reason: str | None
    mpjpe_m: float
    mpjpe_rerooted_m: float
    root_drift_m: float
    force_mg: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    torque_mgm: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    at_cap: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0, bool))
    floor_after: dict = field(default_factory=dict)
    floor_before: dict = field(default_factory=dict)


def action_starts(library, walk: list[int]) -> np.ndarray:
    """Frame of each action's start in the walk's motion (ActionLibrary.sequence_motion shares the
    boundary frame between consecutive actions)."""
    lengths = np.array([library.frame_offsets[a + 1] - library.frame_offsets[a] for a in walk])
    return np.concatenate([[0], np.cumsum(lengths - 1)[:-1]]).astype(np.int64)


def rerooted_site_errors(env: BatchEnv, b: int, anchor: tuple[np.ndarray, float, np.ndarray, float]) -> np.ndarray:
    """(tracked sites,) distances (m) of slot b's tracked joints to its reference re-anchored by
    ``anchor`` = (simulated ground xy, simulated yaw, reference ground xy, reference yaw): the
    reference's ground position and yaw there mapped onto the simulation's."""
    ref = env.refs[b]
    t = int(env.t[b])
    sim_xy, sim_yaw, ref_xy, ref_yaw = anchor
    dyaw = sim_yaw - ref_yaw
    c, s = np.cos(dyaw), np.sin(dyaw)
    R = np.array([[c, -s], [s, c]])
    sites = ref.sites[t, env.tracked].copy()
    sites[:, :2] = (sites[:, :2] - ref_xy) @ R.T + sim_xy
    return site_distances(env, b, sites)


def site_distances(env: BatchEnv, b: int, sites: np.ndarray) -> np.ndarray:
    """(tracked sites,) distances (m) of slot b's tracked joints to ``sites`` (tracked sites, 3)."""
    d = env.site_pos[b, env.tracked] - sites
    return np.sqrt((d * d).sum(axis=1))


def _rerooted_error(env: BatchEnv, b: int, anchor: tuple[np.ndarray, float, np.ndarray, float]) -> float:
    """Mean tracked-joint distance (m) of slot b to its reference re-anchored at the action start."""
    return float(rerooted_site_errors(env, b, anchor).mean())


PLACEMENTS = ("world", "body")


def run_walks(setup, controller, walks: list[list[int]], config: BatchConfig = BatchConfig(), parallel: int = 16,
              lift: str = "ground", progress: bool = False, placement: str = "world") -> tuple[list[WalkRun], dict]:
    """Track every walk (module docstring). ``setup``: a tracker.track.evaluation.EvalSetup-like
    object with ``source`` (the walk source), ``scene`` (a one-fighter scene) and ``config.control_hz``.
    ``placement``: "world" or "body" (module docstring). Returns the runs and the timing (simulated
    seconds, wall seconds of the control loop)."""
    from tracker.track.evaluation import walk_reference
    if placement not in PLACEMENTS:
        raise ValueError(f"run_walks: placement must be one of {PLACEMENTS}, got {placement!r}")
    if not walks:
        return [], {"sim_s": 0.0, "wall_s": 0.0}
    lib = getattr(setup.source, "library", None)
    n = min(int(parallel), len(walks))
    env = BatchEnv(setup.scene, n, config)
    controller.reset(env)
    queue = list(range(len(walks)))
    runs: list[WalkRun | None] = [None] * len(walks)
    slot_walk = [-1] * n
    drawn: list = [None] * n                  # each slot's walk reference as drawn (global errors)
    acc: list[dict] = [dict() for _ in range(n)]
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=len(walks), desc="walks", unit="walk")
    wall = 0.0
    sim = 0.0

    def start(b: int) -> None:
        i = queue.pop(0)
        _, ref = walk_reference(setup, walks[i], lift=lift)
        starts = action_starts(lib, walks[i]) if lib is not None else np.array([0])
        env.reset([b], [ref])
        drawn[b] = ref
        slot_walk[b] = i
        acc[b] = dict(err=[], rr=[], f=[], tq=[], cap=[], starts=set(int(x) for x in starts), anchor=None, fall=None,
                      floor=ref.meta.get("floor_after", {}), floor0=ref.meta.get("floor_before", {}))

    for b in range(n):
        start(b)
    obs = env.observe()
    while any(w >= 0 for w in slot_walk):
        t0 = time.perf_counter()
        anchors_due = [b for b in range(n) if slot_walk[b] >= 0 and int(env.t[b]) in acc[b]["starts"]]
        placed = [b for b in anchors_due if int(env.t[b]) > 0] if placement == "body" else []
        if placed:                          # the next clip goes under the body before the controller sees it
            env.place_on_body(placed)
            obs = env.observe()
        targets, assist = controller.act(env, obs)
        for b in anchors_due:               # the action starts now: anchor the reference here
            ref = env.refs[b]
            t = int(env.t[b])
            acc[b]["anchor"] = (env.qpos[b, :2].copy(), float(yaws_of(env.R[b:b + 1], env.lateral[b])[0]),
                                ref.qpos[t, :2].copy(), float(env.tables[b]["yaw"][t]))
        obs, _, done, info = env.step(targets, assist)
        wall += time.perf_counter() - t0
        live = info["live"]
        for b in np.nonzero(live)[0]:
            a = acc[b]
            if placement == "body":         # the global error is against the walk as drawn
                a["err"].append(float(site_distances(env, b, drawn[b].sites[int(env.t[b]), env.tracked]).mean()))
            else:
                a["err"].append(float(info["mpjpe_m"][b]))
            if a["anchor"] is not None:
                a["rr"].append(_rerooted_error(env, b, a["anchor"]))
            a["f"].append(float(env.assist_force_mg[b]))
            a["tq"].append(float(env.assist_torque_mgm[b]))
            a["cap"].append(bool(env.assist_at_cap[b]))
            if info["fall"][b] and a["fall"] is None:
                a["fall"] = int(info["fall"][b])
            sim += 1.0 / config.control_hz
            if done[b]:
                i = slot_walk[b]
                ref = drawn[b]
                from tracker.track.batch_env import FALL_NAMES
                runs[i] = WalkRun(list(walks[i]), ref.n_frames / ref.fps, len(a["err"]) / config.control_hz,
                                  a["fall"] is not None, FALL_NAMES.get(a["fall"]), float(np.mean(a["err"])),
                                  float(np.mean(a["rr"])) if a["rr"] else float(np.mean(a["err"])),
                                  float(np.linalg.norm(env.qpos[b, :2] - ref.qpos[int(env.t[b]), :2])),
                                  np.asarray(a["f"]), np.asarray(a["tq"]), np.asarray(a["cap"], bool), a["floor"],
                                  a["floor0"])
                slot_walk[b] = -1
                if bar is not None:
                    bar.update(1)
                if queue:
                    start(b)
                    obs = env.observe()
    if bar is not None:
        bar.close()
    return [r for r in runs if r is not None], {"sim_s": sim, "wall_s": wall, "parallel": n, "placement": placement}


def summarise(runs: list[WalkRun], controller, config: BatchConfig, timing: dict, n_actions: int, seed: int,
              mass_kg: float) -> dict:
    """The protocol's figures (``tracker eval --json``)."""
    fell = np.array([r.fell for r in runs])
    t = np.array([r.time_s for r in runs])
    a = config.assist
    allf = np.concatenate([r.force_mg for r in runs]) if runs else np.zeros(0)
    allt = np.concatenate([r.torque_mgm for r in runs]) if runs else np.zeros(0)
    allc = np.concatenate([r.at_cap for r in runs]) if runs else np.zeros(0, bool)
    st = summarise_assist(allf, allt, allc, mass_kg, a.cap if a.active else 0.0)
    reasons: dict = {}
    for r in runs:
        if r.fall_reason:
            reasons[r.fall_reason] = reasons.get(r.fall_reason, 0) + 1
    floors = [r.floor_after for r in runs if r.floor_after]
    floors0 = [r.floor_before for r in runs if r.floor_before]
    return {
        "controller": getattr(controller, "name", type(controller).__name__),
        "describe": controller.describe() if hasattr(controller, "describe") else "",
        "assist": a.mode if a.active else "none", "cap_mg": float(a.cap) if a.active else 0.0,
        "physics": a.label(),
        "n_walks": len(runs), "n_actions": n_actions, "seed": seed, "placement": timing.get("placement", "world"),
        "completion_rate": float(np.mean(~fell)) if runs else float("nan"),
        "mean_time_to_fall_s": float(t.mean()) if runs else float("nan"),
        "mean_time_to_fall_fallen_s": float(t[fell].mean()) if fell.any() else None,
        "mean_walk_duration_s": float(np.mean([r.duration_s for r in runs])) if runs else float("nan"),
        "mpjpe_cm": 100 * float(np.mean([r.mpjpe_m for r in runs])) if runs else float("nan"),
        "mpjpe_rerooted_cm": 100 * float(np.mean([r.mpjpe_rerooted_m for r in runs])) if runs else float("nan"),
        "root_drift_cm": 100 * float(np.mean([r.root_drift_m for r in runs])) if runs else float("nan"),
        "assist_force_mean_mg": st["force_mean_mg"], "assist_force_p95_mg": st["force_p95_mg"],
        "assist_torque_mean_mgm": st["torque_mean_mgm"], "assist_torque_p95_mgm": st["torque_p95_mgm"],
        "assist_at_cap_share": st["at_cap_share"], "assist_impulse_n_s_per_s": st["impulse_n_s_per_s"],
        "fall_reasons": reasons,
        "reference_floor": {k: float(np.mean([f[k] for f in floors])) for k in floors[0]} if floors else {},
        "reference_floor_before_grounding": ({k: float(np.mean([f[k] for f in floors0])) for k in floors0[0]}
                                             if floors0 else {}),
        "physics_hz": None, "parallel": timing.get("parallel"),
        "realtime_factor": timing["sim_s"] / timing["wall_s"] if timing.get("wall_s") else float("nan"),
    }


def format_summary(m: dict) -> str:
    """The protocol's figures as a few human-readable lines."""
    fallen = m.get("mean_time_to_fall_fallen_s")
    lines = [
        f"{m['describe'] or m['controller']}: {m['physics']}",
        f"{m['n_walks']} walks of {m['n_actions']} actions (seed {m['seed']}): {100 * m['completion_rate']:.0f}% completed, "
        f"mean time to fall {m['mean_time_to_fall_s']:.2f} s" + (f" ({fallen:.2f} s over the fallen)" if fallen else ""),
        f"joint error {m['mpjpe_cm']:.1f} cm global, {m['mpjpe_rerooted_cm']:.1f} cm re-rooted per action "
        f"(clips placed {'under the body' if m.get('placement') == 'body' else 'on the drawn walk'}); "
        f"root drift {m['root_drift_cm']:.1f} cm",
    ]
    if m["assist"] != "none":
        lines.append(f"assist: |F| mean {m['assist_force_mean_mg']:.3f} mg (p95 {m['assist_force_p95_mg']:.3f}), |tau| mean "
                     f"{m['assist_torque_mean_mgm']:.3f} mg m (p95 {m['assist_torque_p95_mgm']:.3f}), "
                     f"{100 * m['assist_at_cap_share']:.1f}% of steps at the cap")
    lines.append(f"real time: {m['realtime_factor']:.1f}x (simulated fighter-seconds per wall second, "
                 f"{m['parallel']} walks side by side)")
    return "\n".join(lines)
