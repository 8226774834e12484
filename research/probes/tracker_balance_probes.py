"""Probes of balance levers around the virtual-force layer (issue 7); none adopted.

    python -m research.probes.tracker_balance_probes gravcomp [--walks N] [--forces vertical|free]
    python -m research.probes.tracker_balance_probes split    [--walks N]
    python -m research.probes.tracker_balance_probes mass     [--walks N]
    python -m research.probes.tracker_balance_probes armvel   [--walks N]

Random 20-action library walks of seed 100 (the tuning seed), no force on the root; controllers:
PD, PD + the balance layer (tracker/track/vforce.py, default gains), the shipped policy (over the layer).
Results: research/notes/TRAINING.md.

- gravcomp: a gravity feed-forward (static inverse dynamics) on every actuator: the joint torques
  that would hold the current pose still with the stance feet carrying the body,
  tau = bias - sum_c J_c^T f_c, the contact forces f_c chosen to balance the free joint's six rows
  (``vertical``: one non-negative vertical force per foot-floor contact point, non-negative least
  squares; ``free``: a 3-d force per contact point, ridge least squares), added to the PD targets
  as tau / kp before every physics substep. Also on held frames (one frame of each walk held still).
- split: the layer's wrench shared between the stance feet by their measured contact normal
  forces instead of equally (``load``), and additionally capped per foot (``cap``: horizontal force
  <= 0.6 x that foot's normal force), with the default gains and with the first search's skating
  gains (3300, 720, 750, 75, 130); time to fall and foot sliding (tracker_vforce_cem.sliding).
- mass: 50% of the arms' and / or the head's mass (and inertia) moved to the pelvis (the model's
  centre of mass moves back and down; total mass unchanged).
- armvel: the arm actuators damping towards the reference joint velocity (PDController /
  EnvConfig ``arm_velocity_targets``) instead of towards zero.
"""
from __future__ import annotations

import argparse
import sys
import time

import mujoco
import numpy as np
from scipy.optimize import nnls


from tracker.track.evaluation import draw_walks, make_setup, walk_reference
from tracker.track.pd import PDController
from tracker.track.policy_net import LearnedController, load_checkpoint
from tracker.track.vforce import BalanceGains, VirtualForceBalance
from tracker.track.walks import walk_source
from tracker.track.policy_net import DEFAULT_CKPT  # noqa: E402

SHIPPED = str(DEFAULT_CKPT)
SKATING = (3300.0, 720.0, 750.0, 75.0, 130.0)


# ------------------------------------------------------------------------------ gravity feed-forward
class GravityFeedforward:
    """Sits in the env's balance slot (wrapping the layer, if any): before each physics substep the
    targets are the controller's plus the layer's (re-applied) plus tau / kp of the static
    inverse dynamics above. Quantities one substep old (after mj_step); ``pre`` is the offset the
    run loop adds to the controller's targets so that the first substep carries it too."""

    active = True

    def __init__(self, env, inner: VirtualForceBalance | None, forces: str = "vertical", ridge: float = 1e-4) -> None:
        self.env, self.inner, self.forces, self.ridge = env, inner, forces, ridge
        m = env.model
        self.kp = np.maximum(m.actuator_gainprm[:, 0], 1e-9)
        self.fighters = []
        for f in env.scene.fighters:
            ids = np.arange(f.ctrl_slice.start, f.ctrl_slice.stop)
            cols = np.array([int(f.joint_qvel[int(j)]) + int(a) for j, a in zip(f.act_joint, f.act_axis)])
            feet = {int(g) for g in f.foot_geoms}
            self.fighters.append((ids, cols, int(f.qvel_adr), feet))
        self.pre = np.zeros(m.nu)
        self.base = np.zeros(m.nu)
        self._jp = np.zeros((3, m.nv))

    def torques(self, d: mujoco.MjData) -> np.ndarray:
        """(nu,) target offsets tau / kp for the current (one substep old) state."""
        m, floor = self.env.model, self.env.scene.floor_geom
        out = np.zeros(m.nu)
        for ids, cols, v0, feet in self.fighters:
            jac = []
            for i in range(d.ncon):
                c = d.contact[i]
                g = int(c.geom2) if c.geom1 == floor else int(c.geom1) if c.geom2 == floor else -1
                if g in feet:
                    mujoco.mj_jac(m, d, self._jp, None, c.pos, int(m.geom_bodyid[g]))
                    jac.append(self._jp.copy())
            tau = d.qfrc_bias.copy()
            if jac:
                b = tau[v0:v0 + 6]
                if self.forces == "vertical":
                    A = np.stack([J[2, v0:v0 + 6] for J in jac], axis=1)
                    n = A.shape[1]
                    lam, _ = nnls(np.vstack([A, np.sqrt(self.ridge) * np.eye(n)]), np.r_[b, np.zeros(n)])
                    for J, f in zip(jac, lam):
                        tau -= J[2] * f
                else:
                    A = np.concatenate([J[:, v0:v0 + 6].T for J in jac], axis=1)
                    lam = np.linalg.solve(A.T @ A + self.ridge * np.eye(A.shape[1]), A.T @ b)
                    for j, J in enumerate(jac):
                        tau -= J.T @ lam[3 * j:3 * j + 3]
            out[ids] = tau[cols] / self.kp[ids]
        return out

    def substep(self, env, d: mujoco.MjData, s: int) -> None:
        if s == 0:
            self.base[:] = d.ctrl - self.pre
        d.ctrl[:] = self.base
        if self.inner is not None and self.inner.active:
            self.inner.substep(env, d, s)
        self.pre = self.torques(d)
        d.ctrl += self.pre


def run(env, ctrl, ref, gravcomp: str | None = None) -> float:
    """Seconds tracked from frame 0 until the fall or the reference's end (the evaluation's loop),
    with the gravity feed-forward (forces ``gravcomp``) when given."""
    obs = env.reset(ref, 0)
    ctrl.reset(env)
    inner = env.balance
    ff = GravityFeedforward(env, inner, gravcomp) if gravcomp else None
    if ff is not None:
        ff.pre = ff.torques(env.data) if env.data.ncon else ff.pre
        env.balance = ff
    try:
        while True:
            u = ctrl.act(env, obs)
            if ff is not None:
                u = u + ff.pre
            obs, _, done, _ = env.step(u)
            if done:
                return env.sim_time
    finally:
        env.balance = inner


def held(setup, ref, k: int, frames: int = 150):
    from research.probes.tracker_probes import held as held_ref
    return held_ref(ref, setup.scene, setup.scene.fighters[0], k, frames)


def controllers(which: list[str], **pd_kw) -> dict:
    out = {}
    for w in which:
        if w == "pd":
            out[w] = PDController(**pd_kw)
        elif w == "layer":
            out[w] = PDController(balance=BalanceGains().as_tuple(), **pd_kw)
        else:
            ck = load_checkpoint(SHIPPED)
            ck["config"].update(pd_kw)
            out[w] = LearnedController(ck)
    return out


def gravcomp(walks: int, forces: str) -> None:
    setup = make_setup(walk_source(None))
    env = setup.env
    refs = [walk_reference(setup, w)[1] for w in draw_walks(setup.source, walks, 20, 100)]
    rng = np.random.default_rng(0)
    helds = [held(setup, r, int(rng.integers(0, r.n_frames))) for r in refs]
    for name, ctrl in controllers(["pd", "layer", "policy"]).items():
        for kind, rs in (("walks", refs), ("held frames", helds)):
            t0 = np.mean([run(env, ctrl, r) for r in rs])
            t1 = np.mean([run(env, ctrl, r, forces) for r in rs])
            print(f"{name:7s} {kind:12s} mean time to fall: without {t0:.3f} s, with gravity feed-forward ({forces}) {t1:.3f} s",
                  flush=True)


# ------------------------------------------------------------------------------ wrench split
class SplitBalance(VirtualForceBalance):
    """The layer with its wrench shared by the feet's contact normal forces; ``cap``: each foot's
    horizontal share at most ``mu`` x its normal force."""

    def __init__(self, env, cap: bool, mu: float = 0.6) -> None:
        super().__init__(env)
        self.cap, self.mu = cap, mu
        self._fr = np.zeros(6)

    def split(self, d, k, feet, F, T):
        load = dict.fromkeys(feet, 0.0)
        for i in range(d.ncon):
            c = d.contact[i]
            o = (self.foot_of(c.geom2) if c.geom1 == self.floor else
                 self.foot_of(c.geom1) if c.geom2 == self.floor else None)
            if o is not None and o[0] == k and o[1] in load:
                mujoco.mj_contactForce(self.model, d, i, self._fr)
                load[o[1]] += max(self._fr[0], 0.0)
        total = sum(load.values())
        out = []
        for side in feet:
            share = load[side] / total if total > 1e-6 else 1.0 / len(feet)
            Fs = F * share
            h = float(np.linalg.norm(Fs[:2]))
            if self.cap and h > self.mu * load[side]:
                Fs[:2] *= self.mu * load[side] / h
            out.append((side, Fs, T * share))
        return out


def split(walks: int) -> None:
    from research.probes import tracker_vforce_cem as cem
    cem._init(walks, 100)
    env = cem._SETUP.env
    for label, gains in (("default gains", BalanceGains().as_tuple()), ("skating gains", SKATING)):
        for mode in ("equal", "load", "cap"):
            env.balance = None if mode == "equal" else SplitBalance(env, cap=(mode == "cap"))
            t, sl = cem.sliding(PDController(balance=gains))
            print(f"PD + layer, {label}, split {mode:5s}: mean time to fall {t:.3f} s, feet sliding {sl:.3f} m/s", flush=True)
    env.balance = None


# ------------------------------------------------------------------------------ mass distribution
def mass(walks: int) -> None:
    setup = make_setup(walk_source(None))
    env, m = setup.env, setup.scene.model
    f = setup.scene.fighters[0]
    refs = [walk_reference(setup, w)[1] for w in draw_walks(setup.source, walks, 20, 100)]
    names = [m.body(b).name for b in range(m.nbody)]
    arms = [b for b in range(m.nbody) if any(k in names[b] for k in ("Arm", "Hand", "Finger"))]
    head = [b for b in range(m.nbody) if any(k in names[b] for k in ("Head", "Neck"))]
    m0, i0 = m.body_mass.copy(), m.body_inertia.copy()
    pel = f.pelvis_body
    print(f"arms {m0[arms].sum():.1f} kg, head and neck {m0[head].sum():.1f} kg, pelvis {m0[pel]:.1f} kg")
    for label, groups in (("as built", []), ("arms x0.5", [arms]), ("head x0.5", [head]), ("arms and head x0.5", [arms, head])):
        m.body_mass[:], m.body_inertia[:] = m0, i0
        moved = 0.0
        for g in groups:
            moved += 0.5 * m0[g].sum()
            m.body_mass[g] *= 0.5
            m.body_inertia[g] *= 0.5
        m.body_mass[pel] += moved
        m.body_inertia[pel] *= (m0[pel] + moved) / m0[pel]
        mujoco.mj_setConst(m, env.data)
        res = {n: np.mean([run(env, c, r) for r in refs]) for n, c in controllers(["pd", "layer"]).items()}
        print(f"{label:20s} mean time to fall: PD {res['pd']:.3f} s, PD + layer {res['layer']:.3f} s", flush=True)
    m.body_mass[:], m.body_inertia[:] = m0, i0
    mujoco.mj_setConst(m, env.data)


def armvel(walks: int) -> None:
    setup = make_setup(walk_source(None))
    env = setup.env
    refs = [walk_reference(setup, w)[1] for w in draw_walks(setup.source, walks, 20, 100)]
    for arm in (False, True):
        for name, c in controllers(["pd", "layer", "policy"], arm_velocity_targets=arm).items():
            print(f"arm velocity targets {arm!s:5s} {name:7s} mean time to fall {np.mean([run(env, c, r) for r in refs]):.3f} s",
                  flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("probe", choices=("gravcomp", "split", "mass", "armvel"))
    ap.add_argument("--walks", type=int, default=24)
    ap.add_argument("--forces", choices=("vertical", "free"), default="vertical")
    a = ap.parse_args(argv)
    t0 = time.time()
    if a.probe == "gravcomp":
        gravcomp(a.walks, a.forces)
    elif a.probe == "split":
        split(a.walks)
    elif a.probe == "mass":
        mass(a.walks)
    else:
        armvel(a.walks)
    print(f"({time.time() - t0:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
