"""Where the assisted tracker's joint error lives on the walk protocol: the mean tracked-joint
distance to the reference re-rooted at *every* control step (the reference pelvis's ground
position and yaw put on the simulated pelvis's: what is left once root drift is removed), by body
region, beside the protocol's own figures (re-rooted once per action start); and how far the
reference's own feet slide while they are down (the toe joints within 1.5 cm of their lowest
height in the walk, horizontal travel per contact run: a simulated foot that sticks cannot follow),
and the pelvis's horizontal speed error by how fast the slower planted reference toe slides.

    python -m research.probes.mpjpe_breakdown [--ckpt A.pt] [--walks 30] [--seed 0] [--friction 0.5]

``--friction``: the floor's and bodies' sliding friction (1.0 in the product, where the policy trained).
"""
from __future__ import annotations

import argparse
import json

import numpy as np

REGIONS = {"legs": ("upleg", "leg", "foot", "toe", "femur", "tibia"),
           "arms": ("shoulder", "arm", "hand", "humerus", "radius", "wrist", "finger", "thumb", "clavicle"),
           "trunk and head": ("hips", "spine", "back", "thorax", "neck", "head", "root")}


def region_of(name: str) -> str:
    low = name.lower()
    for r, keys in REGIONS.items():       # in this order: "upleg" before "arm"-free leg names
        if any(k in low for k in keys):
            return r
    return "other"


class StepErrors:
    """A controller wrapper that records, before each action, every live slot's per-site error to
    its reference re-rooted at this step (the wrapped controller acts unchanged)."""

    batched = True

    def __init__(self, inner, toes: list[int] | None = None) -> None:
        self.inner = inner
        self.name = inner.name
        self.physics_hz = inner.physics_hz
        self.errors: list[np.ndarray] = []
        self.toes = list(toes or [])
        self.slide: list[tuple[float, float]] = []    # (reference toe slide speed, pelvis speed error), m/s
        self._down: dict = {}

    def reset(self, env) -> None:
        self.inner.reset(env)

    def assist_config(self):
        return self.inner.assist_config()

    def act(self, env, obs):
        from tracker.track.batch_env import yaws_of
        from tracker.track.walk_protocol import rerooted_site_errors
        for b in range(env.B):
            ref = env.refs[b]
            if ref is None or env.done[b]:
                continue
            t = int(env.t[b])
            anchor = (env.qpos[b, :2], float(yaws_of(env.R[b:b + 1], env.lateral[b])[0]), ref.qpos[t, :2],
                      float(env.tables[b]["yaw"][t]))
            self.errors.append(rerooted_site_errors(env, b, anchor))
            if self.toes and t + 1 < ref.n_frames:
                cached = self._down.get(id(ref))
                if cached is None or cached[0] is not ref:        # ids of dropped references recur
                    cached = self._down[id(ref)] = (ref, toes_down(ref, self.toes))
                on = cached[1][t] & cached[1][t + 1]
                if on.any():
                    v = np.linalg.norm(ref.sites[t + 1, self.toes, :2] - ref.sites[t, self.toes, :2], axis=1) * ref.fps
                    self.slide.append((float(v[on].min()),
                                       float(np.linalg.norm(env.qvel[b, :2] - ref.qvel[t, :2]))))
        return self.inner.act(env, obs)


def toes_down(ref, toe_sites: list[int]) -> np.ndarray:
    """(T, toes) bool: the toe joint within 1.5 cm of its lowest height in the reference (5th percentile)."""
    z = ref.sites[:, toe_sites, 2]
    return z < np.percentile(z, 5, axis=0) + 0.015


def foot_slide(ref, toe_sites: list[int], fps: float) -> tuple[list[float], list[float]]:
    """(travel per contact run in m, horizontal speed in m/s at contact frames) of the reference's toes."""
    runs, speeds = [], []
    down_all = toes_down(ref, toe_sites)
    for i, j in enumerate(toe_sites):
        p = ref.sites[:, j]
        down = down_all[:, i]
        step = np.linalg.norm(np.diff(p[:, :2], axis=0), axis=1)
        both = down[1:] & down[:-1]
        speeds += list(step[both] * fps)
        travel = 0.0
        for k, on in enumerate(both):
            if on:
                travel += step[k]
            elif travel > 0:
                runs.append(travel)
                travel = 0.0
        if travel > 0:
            runs.append(travel)
    return runs, speeds


def slide_table(S: np.ndarray) -> dict:
    """Mean pelvis horizontal speed error (cm/s) and step count, by how fast the slower of the
    reference's planted toes slides (cm/s bins)."""
    out = {}
    for lo, hi in ((0, 5), (5, 20), (20, 50), (50, 1e9)):
        m = (S[:, 0] * 100 >= lo) & (S[:, 0] * 100 < hi) if len(S) else np.zeros(0, bool)
        out[f"{lo}-{hi:g}" if hi < 1e9 else f">{lo}"] = {"steps": int(m.sum()),
                                                          "mean": round(100 * float(S[m, 1].mean()), 1) if m.any() else None}
    return out


def main(argv=None) -> int:
    import mujoco

    from tracker.track.assisted_policy import load_assisted
    from tracker.track.batch_env import BatchConfig
    from tracker.track.evaluation import draw_walks, make_setup, walk_reference
    from tracker.track.pd import batched_model_options
    from tracker.track.walk_protocol import run_walks
    from tracker.track.walks import walk_source

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ckpt", default=None)
    ap.add_argument("--walks", type=int, default=30)
    ap.add_argument("--actions", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--friction", type=float, default=None)
    a = ap.parse_args(argv)
    ctrl = load_assisted(a.ckpt)
    src = walk_source()
    opts = batched_model_options(ctrl.physics_hz)
    if a.friction is not None:
        from dataclasses import replace
        opts = replace(opts, friction=a.friction)
    setup = make_setup(src, opts)
    walks = draw_walks(src, a.walks, a.actions, a.seed)
    f = setup.scene.fighters[0]
    names = [mujoco.mj_id2name(setup.scene.model, mujoco.mjtObj.mjOBJ_SITE, int(i)) for i in f.site_ids]
    probe = StepErrors(ctrl, [i for i, n in enumerate(names) if n.endswith("ToeBase")])
    runs, _ = run_walks(setup, probe, walks, BatchConfig(assist=ctrl.assist_config()), parallel=8)
    tracked = [names[i] for i in np.nonzero(f.tracked)[0]]
    E = np.array(probe.errors)
    toes = [i for i, n in enumerate(names) if n.endswith("ToeBase")]
    slide_runs, slide_speed = [], []
    for w in walks:
        _, ref = walk_reference(setup, w, lift="ground")
        r, v = foot_slide(ref, toes, ref.fps)
        slide_runs += r
        slide_speed += v
    regions = np.array([region_of(n) for n in tracked])
    out = {"walks": a.walks, "friction": opts.friction, "completed": int(sum(not r.fell for r in runs)),
           "protocol_rerooted_cm": 100 * float(np.mean([r.mpjpe_rerooted_m for r in runs])),
           "protocol_global_cm": 100 * float(np.mean([r.mpjpe_m for r in runs])),
           "per_step_rerooted_cm": 100 * float(E.mean()),
           "by_region_cm": {r: round(100 * float(E[:, regions == r].mean()), 2) for r in sorted(set(regions))},
           "sites_per_region": {r: int((regions == r).sum()) for r in sorted(set(regions))},
           "reference_toe_slide_per_contact_cm": {"median": round(100 * float(np.median(slide_runs)), 2),
                                                  "p90": round(100 * float(np.percentile(slide_runs, 90)), 2)},
           "reference_toe_speed_down_cm_s": {"median": round(100 * float(np.median(slide_speed)), 2),
                                             "p90": round(100 * float(np.percentile(slide_speed, 90)), 2)},
           "pelvis_speed_error_by_reference_slide_cm_s": slide_table(np.array(probe.slide)),
           "worst_sites_cm": dict(sorted(((n, round(100 * float(E[:, i].mean()), 2)) for i, n in enumerate(tracked)),
                                         key=lambda kv: -kv[1])[:8])}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
