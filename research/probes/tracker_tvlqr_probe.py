"""Does time-varying linear feedback hold a feasible trajectory? (issue 7 probe)

research/probes/tracker_feasible_probe.py showed that a trajectory the simulator itself produced (the
strong search teacher's, 10 s without a fall) is tracked barely longer than the mocap by PD, the
balance layer or the shipped policy: feasibility is not what they lack, feedback is. This probe
asks whether the textbook feedback for one trajectory, a time-varying LQR, holds it:

1. the search's trajectory along one walk, with the full MuJoCo states and the env actions it
   executed (residual PD targets over the balance layer), 10 s;
2. the control-step map x' = f(x, u) (8 physics substeps with the layer; x = tangent-space qpos
   and qvel, u = the 66 residual targets) linearised around every visited state by central finite
   differences, and the Riccati recursion backwards from the end (cost dx'Q dx + du'R du);
3. from perturbed start states (joint-velocity noise) at several frames, time to fall under the
   open-loop actions (u*), under u* + K dx, and under the shipped policy on the same feasible
   reference (for scale).

If the local feedback holds where the policy falls, guided policy search (local linear
controllers as low-noise, consistent teachers at perturbed states) is a route for the learned
tracker; if it does not, the contacts break the linearisation (as the mocap tvlqr probe found).

    python -m research.probes.tracker_tvlqr_probe --walk 0 [--seconds 10] [--noise 0.1 0.3] [--out F.json]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


import mujoco  # noqa: E402
import numpy as np  # noqa: E402

from tracker.track.evaluation import draw_walks, walk_reference
from tracker.track.policy_net import load_checkpoint, load_policy
from tracker.learn.train_tracker import TrainConfig, Worker
from research.probes.tracker_feasible_probe import CKPT, feasible_reference, searched_trajectory  # noqa: E402


class StepMap:
    """x' = f(x, u) of the env's control step, in tangent coordinates around given states."""

    def __init__(self, env) -> None:
        self.env = env
        self.m, self.d = env.model, env.data
        self.spec = mujoco.mjtState.mjSTATE_INTEGRATION
        self.nv = self.m.nv

    def set(self, state: np.ndarray, t: int) -> None:
        mujoco.mj_setState(self.m, self.d, state, self.spec)
        self.env.t, self.env.done = t, False
        mujoco.mj_kinematics(self.m, self.d)

    def diff(self, qpos: np.ndarray, qvel: np.ndarray, qpos0: np.ndarray, qvel0: np.ndarray) -> np.ndarray:
        dq = np.zeros(self.nv)
        mujoco.mj_differentiatePos(self.m, dq, 1.0, qpos0, qpos)
        return np.concatenate([dq, qvel - qvel0])

    def perturb(self, dx: np.ndarray) -> None:
        """Move the current state by a tangent vector (qpos on the manifold, qvel additively)."""
        q = self.d.qpos.copy()
        mujoco.mj_integratePos(self.m, q, dx[:self.nv], 1.0)
        self.d.qpos[:] = q
        self.d.qvel[:] += dx[self.nv:]

    def step(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        _, _, _, info = self.env.step(u)
        return self.d.qpos.copy(), self.d.qvel.copy(), info.fall[0] is not None

    def linearise(self, state: np.ndarray, t: int, u: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
        n, nu = 2 * self.nv, len(u)
        A = np.zeros((n, n))
        B = np.zeros((n, nu))
        self.set(state, t)
        ref_q, ref_v = self.d.qpos.copy(), self.d.qvel.copy()
        cols = []
        for i in range(n + nu):
            outs = []
            for sgn in (1.0, -1.0):
                self.set(state, t)
                uu = u
                if i < n:
                    dx = np.zeros(n)
                    dx[i] = sgn * eps
                    self.perturb(dx)
                else:
                    uu = u.copy()
                    uu[i - n] += sgn * eps
                q1, v1, _ = self.step(uu)
                outs.append(self.diff(q1, v1, ref_q, ref_v))
            cols.append((outs[0] - outs[1]) / (2 * eps))
        J = np.array(cols).T
        A[:] = J[:, :n]
        B[:] = J[:, n:]
        return A, B


def riccati(As: list, Bs: list, Q: np.ndarray, R: np.ndarray, Qf: np.ndarray) -> list[np.ndarray]:
    """Feedback gains K_t (u = u* + K_t dx) of the finite-horizon LQR."""
    P = Qf
    Ks = [None] * len(As)
    for t in range(len(As) - 1, -1, -1):
        A, B = As[t], Bs[t]
        BtP = B.T @ P
        K = -np.linalg.solve(R + BtP @ B, BtP @ A)
        P = Q + A.T @ P @ (A + B @ K)
        P = 0.5 * (P + P.T)
        Ks[t] = K
    return Ks


def run_local(sm: StepMap, states, qref, vref, actions, Ks, start: int, noise: float, clip: float,
              rng: np.random.Generator) -> float:
    """Seconds until a fall from ``start`` with joint-velocity noise, u = u* (+ K dx when Ks)."""
    sm.set(states[start], start)
    nv = sm.nv
    sm.d.qvel[6:] += rng.normal(0.0, noise, nv - 6)
    mujoco.mj_forward(sm.m, sm.d)
    for t in range(start, len(actions)):
        u = actions[t]
        if Ks is not None:
            dx = sm.diff(sm.d.qpos, sm.d.qvel, qref[t], vref[t])
            u = np.clip(u + Ks[t] @ dx, -clip, clip)
        _, _, fell = sm.step(u)
        if fell:
            return (t + 1 - start) / 30.0
    return (len(actions) - start) / 30.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seed", type=int, default=100)
    ap.add_argument("--walk", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--eps", type=float, default=1e-4)
    ap.add_argument("--q-pos", type=float, default=1.0, help="state cost on tangent positions")
    ap.add_argument("--q-vel", type=float, default=0.01, help="state cost on velocities")
    ap.add_argument("--r", type=float, nargs="+", default=[0.1], help="control costs per residual target (one LQR each)")
    ap.add_argument("--noise", type=float, nargs="+", default=[0.1, 0.3])
    ap.add_argument("--starts", type=int, default=6)
    ap.add_argument("--no-layer", action="store_true", help="search, linearise and run without the balance layer")
    ap.add_argument("--out", default="")
    a = ap.parse_args(argv)
    ck = load_checkpoint(CKPT)
    cfg = TrainConfig.from_dict({**ck["config"], "init_noise": 0.0, "envs_per_worker": 1, "walks_per_worker": 1,
                                 "push_prob": 0.0, **({"vf_gains": ()} if a.no_layer else {})})
    w = Worker(cfg, None, 0, a.seed)
    walk = draw_walks(w.src, a.walk + 1, 20, a.seed)[a.walk]
    _, ref = walk_reference(w.setup, walk)
    rec: dict = {}
    qpos, qvel, reason = searched_trajectory(w, ck, ref, a.seconds, 16, 45, np.random.default_rng([a.seed, a.walk]),
                                             record=rec)
    states, actions = rec["states"], rec["actions"]
    env = w.envs[0]
    env.reset(ref, 0)
    w.pd.reset(env)
    sm = StepMap(env)
    # full-model qpos / qvel along the trajectory (the scene has one fighter and nothing else movable)
    qref, vref = [], []
    for s in states:
        sm.set(s, 0)
        qref.append(sm.d.qpos.copy())
        vref.append(sm.d.qvel.copy())
    # open-loop replay from the exact start reproduces the trajectory (determinism check)
    sm.set(states[0], 0)
    for t, u in enumerate(actions):
        sm.step(u)
    end_err = float(np.abs(sm.d.qpos - qpos[-1] if sm.d.qpos.shape == qpos[-1].shape else 0).max())
    print(f"open-loop replay from the exact start: final qpos max |error| {end_err:.2e}")
    t0 = time.time()
    As, Bs = [], []
    for t, (s, u) in enumerate(zip(states, actions)):
        A, B = sm.linearise(s, t, u, a.eps)
        As.append(A)
        Bs.append(B)
    nv = sm.nv
    print(f"linearised {len(As)} steps in {time.time() - t0:.0f} s; |eig(A)| max median "
          f"{np.median([np.abs(np.linalg.eigvals(A)).max() for A in As[::10]]):.3f}")
    # linearisation check: small joint-velocity perturbations propagated by A against the simulator
    for scale in (0.01, 0.1):
        rng = np.random.default_rng(3)
        rel = []
        for t in range(0, len(As) - 1, 10):
            dx = np.zeros(2 * nv)
            dx[nv + 6:] = rng.normal(0.0, scale, nv - 6)
            sm.set(states[t], t)
            sm.perturb(dx)
            q1, v1, _ = sm.step(actions[t])
            true = sm.diff(q1, v1, qref[t + 1], vref[t + 1])
            rel.append(np.linalg.norm(true - As[t] @ dx) / max(np.linalg.norm(true), 1e-12))
        print(f"one-step prediction of a {scale} rad/s perturbation: relative error median {np.median(rel):.3f}, "
              f"max {np.max(rel):.3f}")
    qp = np.full(nv, a.q_pos)
    qp[:2] = 0.0          # the horizontal root position is a symmetry: no cost on it
    Q = np.diag(np.r_[qp, np.full(nv, a.q_vel)])
    gains = {}
    for r in a.r:
        gains[r] = riccati(As, Bs, Q, r * np.eye(len(actions[0])), 10 * Q)
        print(f"r {r}: gain norms median {np.median([np.linalg.norm(K, 2) for K in gains[r]]):.2f}")
    feas = feasible_reference(w, qpos, qvel)
    pol = load_policy(CKPT)
    from research.probes.tracker_feasible_probe import time_tracked
    T = len(actions)
    starts = np.linspace(0, max(0, T - 31), a.starts).astype(int)
    rows = {}
    for noise in a.noise:
        for name in ["open-loop", "policy (feasible ref)"] + [f"tvlqr r={r}" for r in a.r]:
            rr = np.random.default_rng(11)
            if name == "policy (feasible ref)":
                ts = [time_tracked(env, pol, feas, int(s), noise, rr) for s in starts]
                w.pd.reset(env)
            else:
                Ks = gains[float(name.split("=")[1])] if name.startswith("tvlqr") else None
                ts = [run_local(sm, states, qref, vref, actions, Ks, int(s), noise,
                                cfg.action_clip, rr) for s in starts]
            left = [(T - s) / 30.0 for s in starts]
            done = int(sum(t >= l - 1e-6 for t, l in zip(ts, left)))
            rows[f"{noise}/{name}"] = dict(mean_s=float(np.mean(ts)), completed=done, times=[round(x, 3) for x in ts])
            print(f"noise {noise:4.2f} rad/s  {name:22s} mean {np.mean(ts):5.2f} s  completed {done}/{len(ts)} "
                  f"(mean span {np.mean(left):.2f} s)", flush=True)
    if a.out:
        Path(a.out).write_text(json.dumps(dict(seed=a.seed, walk=a.walk, search_s=len(qpos) / 30, end=reason,
                                               eps=a.eps, q_pos=a.q_pos, q_vel=a.q_vel, r=list(a.r),
                                               replay_err=end_err, rows=rows), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
