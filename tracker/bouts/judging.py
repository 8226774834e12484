"""Hit judging of a physics bout: fist-on-target contacts read after physics substeps, judged as
hits inside the attacker's strike windows (the rules are in tracker.bouts.physics_bout's module doc).

    judge = HitJudge(model, scene.fighters, library, bout_config)
    judge.clear()                             # before a control step's physics
    env.substep_hook = judge.substep          # contacts after every substep
    judge.judge(t, fighters, planned, hits, touches)   # after the step: hit and touch events
    judge.step_force                          # (2,) clipped force each fighter gave this step (N)
"""
from __future__ import annotations

import mujoco
import numpy as np

from tracker.body.humanoid import EFFECTOR_LABELS, TARGET_LABELS


class HitJudge:
    """Geom tables of the fists and targets of every fighter, the contacts of the current control
    step, and the hit rule. ``config`` is a tracker.bouts.physics_bout.BoutConfig (hit_force_n, force_clip_n,
    window_slack); ``fighters`` in judge() are the bout's per-fighter states (segments, realised,
    resolved, down, touching)."""

    def __init__(self, model: mujoco.MjModel, body_maps: list, library, config) -> None:
        self.model = model
        self.lib = library
        self.config = config
        n = model.ngeom
        self.fist_owner = np.full(n, -1, dtype=np.int64)
        self.fist_side = np.full(n, -1, dtype=np.int64)
        self.target_owner = np.full(n, -1, dtype=np.int64)
        self.target_kind = np.full(n, -1, dtype=np.int64)
        self.fist_geoms, self.target_geoms = [], []
        for f in body_maps:
            fg, tg = [], []
            for side, lab in enumerate(EFFECTOR_LABELS):
                for g in f.geom_label.get(lab, []):
                    self.fist_owner[g] = f.index
                    self.fist_side[g] = side
                    fg.append(int(g))
            for j, lab in enumerate(TARGET_LABELS):
                for g in f.geom_label.get(lab, []):
                    self.target_owner[g] = f.index
                    self.target_kind[g] = j
                    tg.append(int(g))
            self.fist_geoms.append(np.array(fg, dtype=np.int64))
            self.target_geoms.append(np.array(tg, dtype=np.int64))
        self._fist_geo = [(g, model.geom_size[g, 0].copy()) for g in self.fist_geoms]
        self._side_geo = [[(g[self.fist_side[g] == sd], model.geom_size[g[self.fist_side[g] == sd], 0].copy())
                           for sd in (0, 1)] for g in self.fist_geoms]
        self._target_geo = [target_geometry(model, g) for g in self.target_geoms]
        # strike effector joint -> fist side (0 left, 1 right, -1 other)
        parts = library.parts
        side_of = {parts.get("l_fist", -9): 0, parts.get("l_wrist", -9): 0, parts.get("r_fist", -9): 1,
                   parts.get("r_wrist", -9): 1}
        self.strike_side = np.array([side_of.get(int(j), -1) for j in library.strike_joint], dtype=np.int64)
        self.step_force = np.zeros(2)      # max over substeps of the clipped force given (this step)
        self.sub_hits: list[tuple] = []    # (attacker, side, defender, target kind, force) this step
        self._f6 = np.zeros(6)

    def clear(self) -> None:
        """Forget the contacts of the previous control step."""
        self.sub_hits.clear()
        self.step_force[:] = 0.0

    def substep(self, d: mujoco.MjData, s: int = 0) -> None:
        """Read the fist-on-opponent-target contacts after one physics substep (TrackingEnv.substep_hook)."""
        n = d.ncon
        if n == 0:
            return
        g = d.contact.geom[:n]
        g0, g1 = g[:, 0], g[:, 1]
        fo0, fo1 = self.fist_owner[g0], self.fist_owner[g1]
        to0, to1 = self.target_owner[g0], self.target_owner[g1]
        m1 = (fo0 >= 0) & (to1 >= 0) & (fo0 != to1)
        m2 = (fo1 >= 0) & (to0 >= 0) & (fo1 != to0)
        idx = np.nonzero(m1 | m2)[0]
        if len(idx) == 0:
            return
        f6 = self._f6
        tot = np.zeros(2)
        clip = self.config.force_clip_n
        for i in idx:
            mujoco.mj_contactForce(self.model, d, int(i), f6)
            force = abs(float(f6[0]))
            if m1[i]:
                fg, tg = int(g0[i]), int(g1[i])
            else:
                fg, tg = int(g1[i]), int(g0[i])
            a = int(self.fist_owner[fg])
            self.sub_hits.append((a, int(self.fist_side[fg]), int(self.target_owner[tg]), int(self.target_kind[tg]),
                                  force))
            tot[a] += min(force, clip)
        np.maximum(self.step_force, tot, out=self.step_force)

    def judge(self, t: int, fighters: list, planned_events: list[dict], hit_events: list[dict],
              touch_events: list[dict]) -> None:
        """Turn this step's contacts into hit events (one per strike window, marked realised on the
        attacker) and touch events (a fist on a target outside a strike window); sets each
        fighter's ``touching``. No hits by or on a fighter that is down."""
        cfg = self.config
        lib = self.lib
        touching = [False, False]
        if self.sub_hits:
            judged = set()
            for (a, side, b, tk, force) in self.sub_hits:
                if fighters[a].down or fighters[b].down or force < cfg.hit_force_n:
                    continue
                touching[a] = True
                if (a, side) in judged:
                    continue
                hit = self.strike_for(fighters[a], side, t)
                if hit is None:
                    continue
                seg, j = hit
                judged.add((a, side))
                bit = 1 << j
                fa = fighters[a]
                fa.realised[seg.inst] = fa.realised.get(seg.inst, 0) | bit
                fa.resolved[seg.inst] = fa.resolved.get(seg.inst, 0) | bit
                planned = any(p["attacker"] == a and p["inst"] == seg.inst and p["strike"] == j
                              for p in planned_events)
                hit_events.append({"t": round(t / 30.0, 4), "frame": t, "attacker": a, "victim": b,
                                   "action": seg.action, "kind": lib.labels[seg.action], "strike": j,
                                   "inst": seg.inst, "target": TARGET_LABELS[tk], "fist": EFFECTOR_LABELS[side],
                                   "force_n": round(force, 2), "planned": bool(planned)})
            for a in (0, 1):
                if touching[a] and not fighters[a].touching and not any(
                        h["attacker"] == a and h["frame"] == t for h in hit_events):
                    best = max((x for x in self.sub_hits if x[0] == a), key=lambda x: x[4])
                    touch_events.append({"t": round(t / 30.0, 4), "attacker": a, "victim": 1 - a,
                                         "target": TARGET_LABELS[best[3]], "fist": EFFECTOR_LABELS[best[1]],
                                         "force_n": round(best[4], 2)})
        for a in (0, 1):
            fighters[a].touching = touching[a]

    def strike_for(self, fighter, side: int, t: int):
        """(segment, strike index) of the fighter's strike whose (widened) window holds step t and
        that has not landed yet, for fist ``side``; looks at the current and the previous action
        instance."""
        lo, hi = self.config.window_slack
        lib = self.lib
        segs = [s for s in fighter.segments[-3:] if s.t0 <= t and not s.hold and s.inst >= 0]
        for seg in reversed(segs):
            fr = t - seg.t0
            a_id = seg.action
            s0, s1 = int(lib.strike_offsets[a_id]), int(lib.strike_offsets[a_id + 1])
            done = fighter.realised.get(seg.inst, 0)
            for j in range(s1 - s0):
                k = s0 + j
                if done >> j & 1:
                    continue
                if self.strike_side[k] >= 0 and self.strike_side[k] != side:
                    continue
                if int(lib.strike_w0[k]) - lo <= fr < int(lib.strike_w1[k]) + hi:
                    return seg, j
        return None

    def nearest_target(self, d: mujoco.MjData, b: int, point: np.ndarray) -> int:
        """The geom id of fighter b's head, chest or belly geom nearest to ``point`` (world, m)."""
        tg, tr, thl = self._target_geo[b]
        gaps = [float(np.linalg.norm(point - self._axis_point(d, int(g), h, point))) - r for g, r, h in zip(tg, tr, thl)]
        return int(tg[int(np.argmin(gaps))])

    def target_point(self, d: mujoco.MjData, g: int, point: np.ndarray, depth_m: float) -> np.ndarray:
        """The point ``depth_m`` inside target geom g's surface on the way from ``point`` to its
        axis (its centre at the most), world m."""
        i = int(np.flatnonzero(self._target_geo[self.target_owner[g]][0] == g)[0])
        _, tr, thl = self._target_geo[self.target_owner[g]]
        c = self._axis_point(d, g, float(thl[i]), point)
        u = point - c
        n = float(np.linalg.norm(u))
        return c if n < 1e-9 else c + u / n * max(float(tr[i]) - depth_m, 0.0)

    @staticmethod
    def _axis_point(d: mujoco.MjData, g: int, half: float, point: np.ndarray) -> np.ndarray:
        axis = d.geom_xmat[g][[2, 5, 8]]
        c = d.geom_xpos[g]
        return c + float(np.clip((point - c) @ axis, -half, half)) * axis

    def fist_target_distance(self, d: mujoco.MjData, a: int, b: int, side: int = -1) -> float:
        """Closest distance (m, >= 0) between a's fist spheres (both, or ``side`` 0 left / 1 right)
        and b's head/chest/belly geoms (spheres, or capsules as segments with a radius)."""
        fg, fr = self._fist_geo[a] if side < 0 else self._side_geo[a][side]
        tg, tr, thl = self._target_geo[b]
        return fist_gap(d.geom_xpos[fg], fr, d.geom_xpos[tg], d.geom_xmat[tg][:, [2, 5, 8]], tr, thl)


def target_geometry(model: mujoco.MjModel, geoms: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(geom ids, radii, half-lengths: 0 for a sphere) of target geoms, as fist_gap takes them."""
    cap = mujoco.mjtGeom.mjGEOM_CAPSULE
    return geoms, model.geom_size[geoms, 0].copy(), np.where(model.geom_type[geoms] == cap, model.geom_size[geoms, 1], 0.0)


def fist_gap(fist_xyz: np.ndarray, fist_r: np.ndarray, tgt_xyz: np.ndarray, tgt_axis: np.ndarray,
             tgt_r: np.ndarray, tgt_half: np.ndarray) -> float:
    """Closest distance (m, >= 0) between fist spheres (F, 3 centres; F radii) and target geoms
    (G, 3 centres; G, 3 unit axes; G radii; G half-lengths, 0 for a sphere, capsules as segments
    with a radius)."""
    rel = fist_xyz[:, None, :] - tgt_xyz[None, :, :]                   # (F, G, 3)
    s = np.clip((rel * tgt_axis[None]).sum(-1), -tgt_half[None], tgt_half[None])
    q = rel - s[..., None] * tgt_axis[None]
    dist = np.sqrt((q * q).sum(-1)) - fist_r[:, None] - tgt_r[None, :]
    return max(float(dist.min()), 0.0)
