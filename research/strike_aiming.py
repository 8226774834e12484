"""Strike aiming (an experiment, not in the product: it did not raise the share of planned hits
realised; research/notes/BOUTS.md): the reference arm of a planned strike bent toward where the
opponent's body physically is (two-bone inverse kinematics on the reference pose), as games aim a
punch clip at its target.

    python -m research.strike_aiming --graph G.igz --seed0 1 --bouts 20 [--shift 0.1] [--depth 0] [--off]

The planner chooses a strike from the kinematic prediction; in physics the opponent is rarely
exactly there (it lags or leads its own reference, it leans) and the tracked fist lags its
reference. Without aiming, planned punches come within a median 3-12 cm of the target without
touching (docs/tracker.md). For every reference frame inside a planned strike's window the
aimer moves the reference fist toward the opponent's target by at most ``max_shift_m``:

1. The target point is the closest point of the opponent's head, chest or belly (the geom nearest
   the fist, chosen once per strike) to the fist, ``depth_m`` behind the target's surface,
   extrapolated by the opponent's pelvis velocity to the frame's time.
2. It is carried into the attacker's reference frame by the offset between the attacker's physical
   and reference pelvis (ground position, yaw and height) now: the tracker follows the reference's
   pose relative to its own pelvis, so the physical fist lands where the re-rooted reference fist is.
3. The elbow is opened or closed so the shoulder-to-fist distance is the target's (law of cosines,
   clipped to the arm's reach), then the shoulder swings the arm onto the target direction (the
   smallest rotation). Both corrections are world rotations turned into the joints' local
   quaternions (q' = q X^-1 R X, X the body's world orientation); the other joints are untouched.

Approximations: the lag offset is held constant over the few frames ahead; joint velocities of the
aimed frames are left as the clip's; joint ranges are not enforced on the aimed pose (PD pushes into
MuJoCo's soft limits).
"""
from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np


@dataclass(frozen=True)
class AimConfig:
    """Strike aiming's settings (metres, frames at the control rate).

    Attributes:
        max_shift_m: largest move of the reference fist from the clip's.
        depth_m: the aim point lies this far inside the target's surface (the tracked fist stops
            short of its reference).
        ramp_frames: the aim's weight rises linearly over this many frames at the window's start.
        extrapolate_s: the opponent's motion is extrapolated at most this far ahead.
    """

    max_shift_m: float = 0.30
    depth_m: float = 0.05
    ramp_frames: int = 2
    extrapolate_s: float = 0.2

    def __post_init__(self) -> None:
        if not self.max_shift_m >= 0 or not self.depth_m >= 0 or self.ramp_frames < 0 or not self.extrapolate_s >= 0:
            raise ValueError(f"AimConfig needs non-negative settings, got {self}")


def _quat_inv(q: np.ndarray) -> np.ndarray:
    return np.array([q[0], -q[1], -q[2], -q[3]])


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    out = np.zeros(4)
    mujoco.mju_mulQuat(out, a, b)
    return out


def rotation_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Smallest rotation (wxyz quaternion) taking direction u onto direction v."""
    u = u / max(np.linalg.norm(u), 1e-12)
    v = v / max(np.linalg.norm(v), 1e-12)
    c = float(np.clip(u @ v, -1.0, 1.0))
    axis = np.cross(u, v)
    s = np.linalg.norm(axis)
    if s < 1e-9:
        if c > 0:
            return np.array([1.0, 0.0, 0.0, 0.0])
        axis = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        s = np.linalg.norm(axis)
    q = np.zeros(4)
    mujoco.mju_axisAngle2Quat(q, axis / s, float(np.arctan2(s, c)))
    return q


def local_update(q_joint: np.ndarray, x_body: np.ndarray, r_world: np.ndarray) -> np.ndarray:
    """A ball joint's new local quaternion when its body's world orientation x_body is pre-rotated
    by r_world about the joint (q' = q X^-1 R X)."""
    out = _quat_mul(q_joint, _quat_mul(_quat_inv(x_body), _quat_mul(r_world, x_body)))
    return out / np.linalg.norm(out)


class StrikeAimer:
    """Two-bone IK of either arm on reference poses of one fighter body (the module doc).

    ``scene``: the bout's tracker.body.humanoid.FighterScene; poses are qpos rows of one fighter
    (fighter 0's layout, as every fighter's reference is)."""

    def __init__(self, scene, parts: dict, config: AimConfig = AimConfig()) -> None:
        self.model = scene.model
        self.config = config
        fm = scene.fighters[0]
        self.fm = fm
        self.data = mujoco.MjData(self.model)
        body_of = {int(j): int(b) for b, j in zip(fm.body_ids, fm.body_joints)}
        self.arms = []
        for side, pre in enumerate(("l", "r")):
            try:
                sh, el = body_of[int(parts[f"{pre}_shoulder"])], body_of[int(parts[f"{pre}_elbow"])]
            except KeyError as e:
                raise ValueError(f"strike aiming needs the {pre} shoulder and elbow in the body ({e})") from None
            fist = fm.geom_label.get(f"{pre}_fist")
            if fist is None or len(fist) == 0:
                raise ValueError(f"strike aiming needs a {pre}_fist geom on the body")
            adr = []
            for b in (sh, el):
                if self.model.body_jntnum[b] != 1 or self.model.jnt_type[self.model.body_jntadr[b]] != mujoco.mjtJoint.mjJNT_BALL:
                    raise ValueError(f"strike aiming needs ball joints at the shoulder and elbow (body {b})")
                adr.append(int(self.model.jnt_qposadr[self.model.body_jntadr[b]]) - fm.qpos_adr)
            self.arms.append((sh, el, int(fist[0]), adr[0], adr[1]))

    def fist_position(self, qpos: np.ndarray, side: int) -> np.ndarray:
        """World position (m) of the fist centre of a reference pose."""
        self._fk(qpos)
        return self.data.geom_xpos[self.arms[side][2]].copy()

    def _fk(self, qpos: np.ndarray) -> None:
        self.data.qpos[self.fm.qpos_slice] = qpos
        mujoco.mj_kinematics(self.model, self.data)

    def aim(self, qpos: np.ndarray, side: int, point: np.ndarray, weight: float = 1.0) -> np.ndarray:
        """The pose ``qpos`` with arm ``side`` (0 left, 1 right) bent so its fist moves toward
        ``point`` (world, m) by ``weight`` of the way, at most ``max_shift_m``; a new array."""
        sh, el, fist, a_sh, a_el = self.arms[side]
        self._fk(qpos)
        d = self.data
        S, E, W = d.xpos[sh].copy(), d.xpos[el].copy(), d.geom_xpos[fist].copy()
        shift = (np.asarray(point, float) - W) * float(np.clip(weight, 0.0, 1.0))
        n = np.linalg.norm(shift)
        if n > self.config.max_shift_m:
            shift *= self.config.max_shift_m / n
        P = W + shift
        if np.linalg.norm(shift) < 1e-4:
            return qpos.copy()
        out = qpos.copy()
        u, v = S - E, W - E
        a, b = np.linalg.norm(u), np.linalg.norm(v)
        dist = float(np.clip(np.linalg.norm(P - S), abs(a - b) + 1e-3, a + b - 1e-3))
        cos_now = float(np.clip(u @ v / max(a * b, 1e-12), -1.0, 1.0))
        cos_new = float(np.clip((a * a + b * b - dist * dist) / max(2 * a * b, 1e-12), -1.0, 1.0))
        turn = float(np.arccos(cos_new) - np.arccos(cos_now))      # > 0 opens the elbow
        axis = np.cross(u, v)
        if np.linalg.norm(axis) < 1e-9:                            # straight arm: bend sideways
            axis = np.cross(u, [0.0, 0.0, 1.0])
        axis /= max(np.linalg.norm(axis), 1e-12)
        r_el = np.zeros(4)
        mujoco.mju_axisAngle2Quat(r_el, axis, turn)
        out[a_el:a_el + 4] = local_update(qpos[a_el:a_el + 4], d.xquat[el].copy(), r_el)
        v_new = np.zeros(3)
        mujoco.mju_rotVecQuat(v_new, v, r_el)
        r_sh = rotation_between(E + v_new - S, P - S)
        out[a_sh:a_sh + 4] = local_update(qpos[a_sh:a_sh + 4], d.xquat[sh].copy(), r_sh)
        return out


def aiming_bout(setup, agents, tracker, config, aim: AimConfig):
    """A tracker.bouts.physics_bout.PhysicsBout whose ``step`` aims the planned strikes afterwards:
    the reference frames the tracker will see next (up to ``lead`` + 1 steps ahead) inside an open
    planned strike's window get the strike's arm bent toward the opponent's physical target, each
    frame once per written action (a decision that rewrites a frame has it aimed again)."""
    from motion_graph.rotations import wrap_angle
    from tracker.body.frames import z_rotation
    from tracker.bouts.physics_bout import PhysicsBout

    class _Bout(PhysicsBout):
        def start(self, seed=0, initial=None):
            self.aimer = StrikeAimer(self.setup.scene, self.lib.parts, aim)
            self.aim_rows: dict = {}
            self.aimed_frames = 0
            self.last_written = [None, None]
            super().start(seed, initial)

        def step(self, before_physics=None):
            super().step(before_physics)
            if self.aim_step(self.env.t):
                self._obs = self.env._obs_all()      # the observation of the edited references

        def aim_step(self, t: int) -> bool:
            if self.F[0].down or self.F[1].down:
                return False
            d = self.env.data
            changed = False
            hz = float(self.env.config.control_hz)
            for k in (0, 1):
                o, f = 1 - k, self.F[k]
                # frames are aimed once per written reference: a new segment resets them
                seg = f.segments[-1]
                stamp = (seg.t0, seg.inst)
                if self.last_written[k] != stamp:
                    self.last_written[k] = stamp
                    self.aim_rows[k] = set(tt for tt in self.aim_rows.get(k, set()) if tt < seg.t0)
                done = self.aim_rows.setdefault(k, set())
                for w0, w1, side in self.planned_windows(k, t):
                    rows = [tt for tt in range(max(t + 1, w0 - aim.ramp_frames), min(w1, t + self.lead + 2, self.T))
                            if tt not in done]
                    if not rows:
                        continue
                    adr = self.fms[k].qpos_adr
                    phys = d.qpos[adr:adr + 3].copy()
                    Rz = z_rotation(float(wrap_angle(f.ref_yaw[t] - self.physical_yaw(k))))
                    ov = d.qvel[self.fms[o].qvel_adr:self.fms[o].qvel_adr + 3].copy()
                    ov[2] = 0.0
                    for tt in rows:
                        done.add(tt)
                        new = f.ref.qpos[tt]
                        for sd in ((side,) if side >= 0 else (0, 1)):
                            fist_phys = Rz.T @ (self.aimer.fist_position(new, sd) - f.ref.qpos[t, :3]) + phys
                            g = self.judge.nearest_target(d, o, fist_phys)
                            ahead = min((tt - t) / hz, aim.extrapolate_s)
                            tgt = self.judge.target_point(d, g, fist_phys, aim.depth_m) + ov * ahead
                            wgt = min(1.0, (tt - (w0 - aim.ramp_frames)) / (aim.ramp_frames + 1.0))
                            new = self.aimer.aim(new, sd, Rz @ (tgt - phys) + f.ref.qpos[t, :3], wgt)
                        self.replace_frame(k, tt, new)
                        self.aimed_frames += 1
                        changed = True
            return changed

        def replace_frame(self, k: int, tt: int, qpos: np.ndarray) -> None:
            f = self.F[k]
            f.ref.qpos[tt] = qpos
            f.ref.ctrl[tt] = self.setup.ctrl_of(qpos[None])[0]
            f.ref.sites[tt] = self.setup.sites_of(qpos[None])[0]
            tab = f.ref.meta.get(f"batch_tables_{k}")
            if tab is not None:
                b = self.setup.tables_of(qpos[None])
                for key in ("R", "yaw", "up", "ee", "com", "com_feet"):
                    tab[key][tt] = b[key][0]

    return _Bout(setup, agents, tracker, config)


def main(argv=None) -> int:
    import argparse
    import json

    from igraph_fight.graph import load_graph
    from tracker.bouts.loaders import load_tracker, make_agent
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.setup import BoutConfig, BoutSetup

    ap = argparse.ArgumentParser(description="physics bouts with strike aiming (infighter vs outboxer)")
    ap.add_argument("--graph", required=True)
    ap.add_argument("--tracker", default="assisted")
    ap.add_argument("--seed0", type=int, default=1)
    ap.add_argument("--bouts", type=int, default=20)
    ap.add_argument("--shift", type=float, default=AimConfig.max_shift_m)
    ap.add_argument("--depth", type=float, default=AimConfig.depth_m)
    ap.add_argument("--off", action="store_true", help="the same bouts without aiming")
    a = ap.parse_args(argv)
    g = load_graph(a.graph)
    lib = g.load_library()
    trk = load_tracker(a.tracker)
    setup = BoutSetup.create(lib, sim_params=g.sim_params(), tracker=trk)
    agents = [make_agent("infighter", g, lib, 5), make_agent("outboxer", g, lib, 5)]
    cfg = BoutConfig(record_qpos=False)
    aim = AimConfig(max_shift_m=a.shift, depth_m=a.depth)
    planned = realised = 0.0
    for seed in range(a.seed0, a.seed0 + a.bouts):
        bout = PhysicsBout(setup, agents, trk, cfg) if a.off else aiming_bout(setup, agents, trk, cfg, aim)
        s = bout.run(seed=seed).summary()
        planned += s["planned_hits"]
        realised += s["planned_realised"]
        print(f"seed {seed}: planned {s['planned_hits']:.0f} realised {s['planned_realised']:.0f} falls "
              f"{s['falls_a']}-{s['falls_b']}", flush=True)
    print(json.dumps({"aim": None if a.off else aim.__dict__, "seed0": a.seed0, "bouts": a.bouts,
                      "planned_hits": planned, "planned_realised": realised,
                      "ratio": realised / planned if planned else None}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
