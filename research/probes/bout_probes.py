"""Probes of physics bouts (issue 8): strike aiming (not adopted), why planned
hits miss, and the fall rule.

    python -m research.probes.bout_probes series [--bouts 30] [--seconds 60]   # planned hits realised, aim off / on
    python -m research.probes.bout_probes misses [--bouts 8]                   # why planned hits miss
    python -m research.probes.bout_probes falls  [--bouts 6]                   # falls by floor contact alone

Infighter vs outboxer (IG, depth 5), the shipped tracker, the default graph build (``--graph``,
default /tmp/g1k.igz: ``igraph-fight build --mocap ../shared/mocap/cmu/boxing --out /tmp/g1k.igz``),
seeds 1..N. Results: research/notes/BOUTS.md.

Strike aiming: the punching arm's PD targets bent so that the fist meets the opponent's body
where it physically is (the planned hits are predicted from the kinematic coupled state, the
tracked bodies drift off their references):

- For each strike of the fighter's current action (library strike windows, the strike's own fist)
  the reference is mapped onto the body through the upper trunk: T = (physical pose now) o
  (reference pose now)^-1. The opponent's head, chest and belly centres are mapped back through T
  into the reference's frame; the one nearest to the reference fist at the strike's peak frame is
  the aim point, and delta = aim point - reference fist at the peak (recomputed every control
  step, so it follows the opponent).
- delta longer than ``max_shift_m``: the strike is left as the mocap has it (out of reach).
- The fist's path is the reference's plus w(frame) delta, w rising from 0 ``ramp_frames`` before
  the peak to 1 at the peak, held to the end of the strike window, falling over ``ramp_frames``;
  a damped least-squares inverse kinematics (shoulder and elbow, position only) on the reference
  pose of the coming control step gives the arm joints; their difference to the reference's PD
  targets is added to the tracking controller's targets (both fighters). Joint torques only.

``falls`` counts falls by the issue's definition alone (a body other than the feet on the floor:
the pelvis-height rule of tracker.body.fall switched off) against both rules, same seeds.

``misses`` sorts every planned hit of aim-off and aim-on bouts: realised; a fighter down within
10 steps before to 5 after the planned step; no contact of the attacker's fists with the
opponent's targets in that span (with the aim's last |delta| for those); contact under 1 N;
contact not judged a hit (outside the window or the other fist).
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass

import mujoco
import numpy as np


from tracker.body.humanoid import EFFECTOR_LABELS, TARGET_LABELS


@dataclass(frozen=True)
class AimConfig:
    """Strike aiming (module doc). Distances in metres, frames at the control rate (30 Hz)."""

    max_shift_m: float = 0.35
    ramp_frames: int = 6
    ik_iters: int = 6
    ik_damping: float = 1e-3
    ik_step_rad: float = 0.3


class _Arm:
    def __init__(self, model: mujoco.MjModel, fm, side: int) -> None:
        sp = fm.spec
        pre = "lr"[side]
        dof = {int(j): i for i, j in enumerate(fm.dof_joints)}
        joints = [dof[sp.parts[f"{pre}_shoulder"]], dof[sp.parts[f"{pre}_elbow"]]]
        cols, acts = [], []
        for i in joints:
            ids = np.nonzero(fm.act_joint == i)[0]
            ids = ids[np.argsort(fm.act_axis[ids])]
            acts += list(ids)
            cols += [int(fm.joint_qvel[i]) + int(a) for a in fm.act_axis[ids]]
        self.acts = np.array(acts, dtype=np.int64)           # actuator indices within the fighter
        self.cols = np.array(cols, dtype=np.int64)           # dof columns in the model
        self.qadr = np.array([int(fm.joint_qpos[int(fm.act_joint[a])]) for a in acts], dtype=np.int64)
        self.axis = np.array([int(fm.act_axis[a]) for a in acts], dtype=np.int64)
        self.fist_geom = int(fm.geom_label[EFFECTOR_LABELS[side]][0])
        self.fist_body = int(model.geom_bodyid[self.fist_geom])
        sh_body = int(fm.body_ids[list(fm.body_joints).index(sp.parts[f"{pre}_shoulder"])])
        self.trunk_body = int(model.body_parentid[sh_body])


class StrikeAim:
    """Aim corrections for both fighters of a tracker.bouts.physics_bout.PhysicsBout (``adjust`` once per control
    step, after the tracking controller, before the physics)."""

    def __init__(self, bout, config: AimConfig = AimConfig()) -> None:
        self.config = config
        self.model = bout.model
        self.lib = bout.lib
        self.fms = bout.fms
        self.data = mujoco.MjData(self.model)
        self.data.qpos[:] = self.model.qpos0
        self.arms = [[_Arm(self.model, fm, s) for s in (0, 1)] for fm in self.fms]
        self.targets = [np.array([int(g) for lab in TARGET_LABELS for g in fm.geom_label.get(lab, [])], dtype=np.int64)
                        for fm in self.fms]
        self.strike_side = bout.judge.strike_side
        self._jp = np.zeros((3, self.model.nv))
        self._peak: dict[tuple, np.ndarray] = {}
        self.deltas: dict[tuple, float] = {}   # (fighter, instance, strike) -> last |delta| (m)
        self.n_aimed = 0               # control steps x strikes with a correction applied
        self.n_out_of_reach = 0        # ... left alone because delta > max_shift_m

    def clear(self) -> None:
        self._peak.clear()
        self.deltas.clear()
        self.n_aimed = 0
        self.n_out_of_reach = 0

    # ---------------------------------------------------------------- kinematics on the scratch data
    def _pose(self, fm, qpos: np.ndarray) -> None:
        self.data.qpos[fm.qpos_slice] = qpos
        mujoco.mj_kinematics(self.model, self.data)

    def _weight(self, fr: int, peak: int, w1: int) -> float:
        r = max(self.config.ramp_frames, 1)
        if fr <= peak:
            return float(np.clip((fr - (peak - r)) / r, 0.0, 1.0))
        end = max(w1 - 1, peak)
        if fr <= end:
            return 1.0
        return float(np.clip(1.0 - (fr - end) / r, 0.0, 1.0))

    def adjust(self, bout, act: np.ndarray) -> np.ndarray:
        """``act`` (the tracking controller's targets, both fighters) with the aim corrections added."""
        env = bout.env
        t = env.t
        k_ref = min(t + env.config.target_lead, env.t_end)
        lib = self.lib
        out = None
        d = env.data
        for k, f in enumerate(bout.F):
            o = 1 - k
            if f.down or bout.F[o].down:
                continue
            seg = f.segment_at(k_ref)
            if seg is None or seg.hold or seg.inst < 0:
                continue
            fr = k_ref - seg.t0
            a = seg.action
            for s in lib.strikes(a):
                side = int(self.strike_side[s])
                if side < 0:
                    continue
                peak, w1 = int(lib.strike_peak[s]), int(lib.strike_w1[s])
                w = self._weight(fr, peak, w1)
                if w <= 0.0:
                    continue
                t_peak = seg.t0 + peak
                if t_peak >= f.ref.qpos.shape[0]:
                    continue
                arm = self.arms[k][side]
                fm = self.fms[k]
                key = (k, seg.inst, int(s))
                p_peak = self._peak.get(key)
                if p_peak is None:
                    self._pose(fm, f.ref.qpos[t_peak])
                    p_peak = self.data.geom_xpos[arm.fist_geom].copy()
                    self._peak[key] = p_peak
                # map the opponent's targets into the reference frame through the upper trunk
                self._pose(fm, f.ref.qpos[t])
                Rr = self.data.xmat[arm.trunk_body].reshape(3, 3).copy()
                pr = self.data.xpos[arm.trunk_body].copy()
                Rp = d.xmat[arm.trunk_body].reshape(3, 3)
                pp = d.xpos[arm.trunk_body]
                tg = (d.geom_xpos[self.targets[o]] - pp) @ Rp @ Rr.T + pr
                aim = tg[int(np.argmin(((tg - p_peak) ** 2).sum(1)))]
                delta = aim - p_peak
                self.deltas[key] = float(np.linalg.norm(delta))
                if float(np.linalg.norm(delta)) > self.config.max_shift_m:
                    self.n_out_of_reach += 1
                    continue
                targets = self._ik(fm, arm, f.ref.qpos[k_ref], w * delta)
                if out is None:
                    out = np.array(act, dtype=np.float64, copy=True)
                ids = arm.acts
                out[fm.act_adr - self.fms[0].act_adr + ids] += targets - f.ref.ctrl[k_ref][ids]
                self.n_aimed += 1
        return act if out is None else out

    def _ik(self, fm, arm: _Arm, qpos: np.ndarray, shift: np.ndarray) -> np.ndarray:
        """PD targets of the arm's actuators that move its fist by ``shift`` from the pose ``qpos``."""
        m, dd, cfg = self.model, self.data, self.config
        self._pose(fm, qpos)
        goal = dd.geom_xpos[arm.fist_geom] + shift
        qv = np.zeros(m.nv)
        for _ in range(cfg.ik_iters):
            mujoco.mj_comPos(m, dd)
            e = goal - dd.geom_xpos[arm.fist_geom]
            mujoco.mj_jac(m, dd, self._jp, None, dd.geom_xpos[arm.fist_geom], arm.fist_body)
            J = self._jp[:, arm.cols]
            dq = J.T @ np.linalg.solve(J @ J.T + cfg.ik_damping * np.eye(3), e)
            mx = float(np.abs(dq).max())
            if mx > cfg.ik_step_rad:
                dq *= cfg.ik_step_rad / mx
            qv[:] = 0.0
            qv[arm.cols] = dq
            mujoco.mj_integratePos(m, dd.qpos, qv, 1.0)
            mujoco.mj_kinematics(m, dd)
        out = np.zeros(len(arm.acts))
        rv = np.zeros(3)
        for n, (adr, ax) in enumerate(zip(arm.qadr, arm.axis)):
            q = dd.qpos[adr:adr + 4]
            mujoco.mju_quat2Vel(rv, q if q[0] >= 0 else -q, 1.0)
            out[n] = rv[ax]
        return out


# ------------------------------------------------------------------------------ runs
class AimedTracker:
    """The tracking controller with the aim corrections added to its targets."""

    def __init__(self, inner, config: AimConfig) -> None:
        self.inner, self.config = inner, config
        self.bout = None
        self.aim: StrikeAim | None = None

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def attach(self, bout) -> None:
        self.bout = bout
        self.aim = StrikeAim(bout, self.config)

    def reset(self, env) -> None:
        self.aim.clear()
        self.inner.reset(env)

    def act(self, env, obs):
        return self.aim.adjust(self.bout, self.inner.act(env, obs))


def _setup(graph: str):
    from igraph_fight.graph import load_graph
    from tracker.bouts.loaders import load_tracker, make_agent
    from tracker.bouts.setup import BoutSetup
    g = load_graph(graph)
    lib = g.load_library()
    setup = BoutSetup.create(lib)
    agents = [make_agent("infighter", g, lib, 5), make_agent("outboxer", g, lib, 5)]
    return lib, setup, agents, load_tracker(None)


def _bout(setup, agents, trk, aim: AimConfig | None, seconds: float):
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.setup import BoutConfig
    tr = AimedTracker(trk, aim) if aim is not None else trk
    bout = PhysicsBout(setup, agents, tr, BoutConfig(seconds=seconds, record_qpos=False))
    if aim is not None:
        tr.attach(bout)
    return bout


def series(graph: str, bouts: int, seconds: float) -> None:
    lib, setup, agents, trk = _setup(graph)
    for label, aim in (("aim off", None), ("aim on, max shift 0.35 m", AimConfig()),
                       ("aim on, max shift 0.5 m", AimConfig(max_shift_m=0.5))):
        tot = dict(planned=0.0, realised=0.0, hits_a=0.0, hits_b=0.0, score=[], falls=0.0)
        for seed in range(1, bouts + 1):
            s = _bout(setup, agents, trk, aim, seconds).run(seed=seed).summary()
            tot["planned"] += s["planned_hits"]
            tot["realised"] += s["planned_realised"]
            tot["hits_a"] += s["hits_a"]
            tot["hits_b"] += s["hits_b"]
            tot["falls"] += s["falls_a"] + s["falls_b"]
            tot["score"].append(s["score"])
        mins = bouts * seconds / 60.0
        print(f"{label:26s}: planned hits {tot['planned']:.0f}, realised {tot['realised']:.0f} "
              f"({100 * tot['realised'] / max(tot['planned'], 1):.0f}%); hits {tot['hits_a']:.0f} - {tot['hits_b']:.0f}, "
              f"score {np.mean(tot['score']):+.2f} per bout; falls {tot['falls'] / (2 * mins):.1f} per fighter-minute",
              flush=True)


def misses(graph: str, bouts: int, seconds: float) -> None:
    lib, setup, agents, trk = _setup(graph)
    for label, aim in (("aim off", None), ("aim on", AimConfig())):
        cats: dict[str, int] = {}
        deltas = []
        for seed in range(1, bouts + 1):
            bout = _bout(setup, agents, trk, aim, seconds)
            bout.start(seed)
            subs, downs = [], []
            for _ in range(bout.n_steps):
                bout.step()
                subs.append(list(bout.judge.sub_hits))
                downs.append((bout.F[0].down, bout.F[1].down))
            bout.finish()
            downs = np.array(downs)
            hits = {(h["attacker"], h["inst"], h["strike"]) for h in bout.hit_events}
            for p in bout.planned_events:
                a, s = p["attacker"], p["step"]
                if s >= len(subs) - 6:
                    continue
                lo, hi = max(0, s - 10), min(len(subs), s + 6)
                con = [x for t in range(lo, hi) for x in subs[t] if x[0] == a]
                if (a, p["inst"], p["strike"]) in hits:
                    c = "realised"
                elif downs[lo:hi].any():
                    c = "a fighter down"
                elif not con:
                    c = "no fist contact"
                    if aim is not None:
                        key = (a, p["inst"], int(lib.strike_offsets[p["action"]]) + p["strike"])
                        deltas.append(bout.tracker.aim.deltas.get(key, np.nan))
                elif max(x[4] for x in con) < 1.0:
                    c = "contact under 1 N"
                else:
                    c = "contact not judged a hit"
                cats[c] = cats.get(c, 0) + 1
        print(f"{label}: planned hits by outcome {cats}", flush=True)
        if deltas:
            dl = np.array(deltas)
            print(f"  no-contact misses with aim: |delta| median {np.nanmedian(dl):.2f} m, over 0.35 m (left alone) "
                  f"{int(np.sum(dl > 0.35))} of {len(dl)}", flush=True)


def falls(graph: str, bouts: int, seconds: float) -> None:
    from dataclasses import replace
    from tracker.body.fall import FallConfig
    lib, setup, agents, trk = _setup(graph)
    env_config = setup.env.config
    for label, fc in (("both rules (as shipped)", env_config.fall),
                      ("floor contact alone", FallConfig(pelvis_drop_m=float("inf")))):
        setup.env.config = replace(env_config, fall=fc)
        n, reasons = 0, {}
        for seed in range(1, bouts + 1):
            s = _bout(setup, agents, trk, None, seconds).run(seed=seed).summary()
            n += s["falls_a"] + s["falls_b"]
            for k, v in s["fall_reasons"].items():
                reasons[k] = reasons.get(k, 0) + v
        print(f"{label:24s}: {n / (2 * bouts * seconds / 60.0):.1f} falls per fighter-minute, by reason {reasons}", flush=True)
    setup.env.config = env_config


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("probe", choices=("series", "misses", "falls"))
    ap.add_argument("--graph", default="/tmp/g1k.igz")
    ap.add_argument("--bouts", type=int, default=None)
    ap.add_argument("--seconds", type=float, default=60.0)
    a = ap.parse_args(argv)
    t0 = time.time()
    if a.probe == "series":
        series(a.graph, a.bouts or 30, a.seconds)
    elif a.probe == "misses":
        misses(a.graph, a.bouts or 8, a.seconds)
    else:
        falls(a.graph, a.bouts or 6, a.seconds)
    print(f"({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
