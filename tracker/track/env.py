"""Tracking environment: one or more fighters in a ring scene follow their References.

Interface for controllers and for an RL / imitation trainer:
    env = TrackingEnv(scene, EnvConfig())
    obs = env.reset(refs, start_frame, rng)          # reference-state initialisation
    obs, reward, done, info = env.step(pd_targets)   # one control step (physics substeps inside)

- Control at ``config.control_hz`` (30 Hz); physics at the scene's rate (``physics_hz``); each step
  calls ``mj_step(model, data, nstep)`` once, so Python runs once per control step.
- Actions are absolute PD position targets (n_act per fighter, concatenated over fighters) in the
  actuators' coordinates (ball joint: rotation-vector components relative to rest), or residuals
  on the reference targets when ``config.residual_actions``. The velocity target of the PD is the
  reference's (when ``env.velocity_targets``): force = kp (target - q) + kd (ref_qdot - qdot),
  realised by offsetting ctrl by (kd / kp) ref_qdot; ``env.arm_velocity_targets`` does this for the
  arm actuators only (clavicles, shoulders, elbows, wrists, fists), the rest damping towards zero.
- Observation per fighter (``observe``): proprioception in the facing frame (pelvis height, up
  vector, root velocity, joint rotation vectors and velocities) plus the reference at
  ``config.obs_future`` control steps ahead (joint targets, root offset and heading offset).
- Reward: DeepMimic-style imitation (pose, velocity, end effectors, root), in [0, 1].
- Early termination on a fall (tracker.body.fall.detect_fall) or at the end of the reference.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import mujoco
import numpy as np

from motion_graph.rotations import wrap_angle

from tracker.body.fall import FallConfig, detect_fall, fall_geom_mask
from tracker.body.frames import facing_rotation, ground_yaw, quat_matrix
from tracker.body.humanoid import FighterScene, rest_frame
from tracker.track.reference import Reference


#: Segment classes (tracker.body.humanoid's gain table) whose actuators ``arm_velocity_targets`` covers.
ARM_CLASSES = ("clavicle", "upper_arm", "forearm", "hand", "fist")


@dataclass(frozen=True)
class EnvConfig:
    """Attributes:
        control_hz: control (and reference) rate.
        residual_actions: interpret actions as offsets on the reference PD targets.
        velocity_targets: use the reference joint velocities as the PD's velocity target (else the
            PD damps towards zero velocity); the initial value of ``env.velocity_targets``, which a
            controller may set in its reset().
        arm_velocity_targets: the same for the arm actuators only (when velocity_targets is off):
            fast punches lag less, the legs and trunk keep the damping measured better for balance.
        target_lead: PD targets are the reference this many control steps ahead (1: the pose the
            step should end in).
        obs_future: control steps ahead at which the reference is observed.
        fall: the fall definition's parameters.
        terminate_on_fall: end the episode at a fall (early termination); False keeps simulating
            (rendering a fall), info.fall still reports it.
        init_noise: std of the noise added to joint qpos/qvel at reset (rad, rad/s); 0 = exact RSI.
        reward_weights: pose, velocity, end effector, root.
    """

    control_hz: float = 30.0
    residual_actions: bool = False
    velocity_targets: bool = True
    arm_velocity_targets: bool = False
    target_lead: int = 1
    obs_future: tuple[int, ...] = (1, 2, 4)
    fall: FallConfig = FallConfig()
    terminate_on_fall: bool = True
    init_noise: float = 0.0
    reward_weights: tuple[float, float, float, float] = (0.65, 0.1, 0.15, 0.1)


@dataclass
class StepInfo:
    """Per-step diagnostics (one entry per fighter where it applies)."""

    t: int
    time_s: float
    fall: list[str | None]
    mpjpe_m: list[float]
    end: bool = False


@dataclass
class _FighterCache:
    act: slice
    qpos: slice
    qvel: slice
    pelvis: int
    sites: np.ndarray
    tracked_sites: np.ndarray
    fall_mask: np.ndarray
    ee_sites: np.ndarray        # indices into the fighter's sites: fists, head top, toes
    ratio: np.ndarray           # kd / kp per actuator
    arm: np.ndarray             # (n_act,) 1.0 for arm actuators (ARM_CLASSES), else 0.0
    joint_q: np.ndarray         # qpos addresses (D, 4) of ball joints, or (D, 3) hinges
    ball: bool
    n_act: int
    lateral: np.ndarray         # (3,) unit right-to-left hip direction in the pelvis frame


class TrackingEnv:
    """See module doc. ``scene`` comes from tracker.body.humanoid.build_fighter_scene."""

    def __init__(self, scene: FighterScene, config: EnvConfig = EnvConfig()) -> None:
        self.scene = scene
        self.model = scene.model
        self.data = mujoco.MjData(self.model)
        self.config = config
        hz = scene.options.physics_hz
        n = hz / config.control_hz
        if abs(n - round(n)) > 1e-6 or round(n) < 1:
            raise ValueError(f"physics rate {hz} Hz is not a multiple of the control rate {config.control_hz} Hz")
        self.substeps = int(round(n))
        self.refs: list[Reference] = []
        self._assist = False
        self.velocity_targets = config.velocity_targets   # a controller may choose (Controller.reset)
        self.arm_velocity_targets = config.arm_velocity_targets
        self.t = 0
        self.sim_time = 0.0
        self.wall_time = 0.0
        # Optional callable(data, substep) run after every physics substep (e.g. tracker.bouts.physics_bout reads
        # fist contacts of every substep, not only the last one); None: one mj_step(nstep) call.
        self.substep_hook = None
        # Optional virtual-force balance layer (tracker.track.vforce), set by a controller's reset.
        self.balance = None
        self._cache = [self._make_cache(k) for k in range(len(scene.fighters))]
        self.n_act = sum(c.n_act for c in self._cache)

    # ------------------------------------------------------------------ set-up
    def _make_cache(self, k: int) -> _FighterCache:
        f = self.scene.fighters[k]
        parts = f.spec.parts
        ee = []
        for p in ("l_fist", "r_fist", "head_top", "head", "l_toe", "r_toe"):
            j = parts.get(p)
            if j is not None and j in set(f.site_joints.tolist()):
                ee.append(int(np.nonzero(f.site_joints == j)[0][0]))
        ee = sorted(set(ee))
        ball = f.joint_type == "ball"
        per = 4 if ball else 3
        jq = np.array([np.arange(a, a + per) for a in f.joint_qpos]) if len(f.joint_qpos) else np.zeros((0, per), int)
        sp = f.spec
        lat = rest_frame(sp, sp.pelvis, parts["l_hip"])[0] - rest_frame(sp, sp.pelvis, parts["r_hip"])[0]
        lat = lat / np.linalg.norm(lat)
        return _FighterCache(f.ctrl_slice, f.qpos_slice, f.qvel_slice, f.pelvis_body, f.site_ids,
                             np.nonzero(f.tracked)[0], fall_geom_mask(self.model, f), np.array(ee, int),
                             f.kd / np.maximum(f.kp, 1e-9),
                             np.array([c in ARM_CLASSES for c in f.act_class], float), jq, ball, f.n_act, lat)

    @property
    def n_fighters(self) -> int:
        return len(self.scene.fighters)

    def set_gains(self, kp: np.ndarray, kd: np.ndarray, fighter: int | None = None) -> None:
        """Write PD gains (N m / rad, N m s / rad) into the model's actuators (all fighters when None)."""
        ks = range(self.n_fighters) if fighter is None else [fighter]
        for k in ks:
            c = self._cache[k]
            ids = np.arange(c.act.start, c.act.stop)
            self.model.actuator_gainprm[ids, 0] = kp
            self.model.actuator_biasprm[ids, 1] = -kp
            self.model.actuator_biasprm[ids, 2] = -kd
            c.ratio = np.broadcast_to(kd / np.maximum(kp, 1e-9), (c.n_act,)).copy()

    def set_torque_limits(self, limit: np.ndarray, fighter: int | None = None) -> None:
        ks = range(self.n_fighters) if fighter is None else [fighter]
        for k in ks:
            c = self._cache[k]
            ids = np.arange(c.act.start, c.act.stop)
            self.model.actuator_forcerange[ids, 0] = -limit
            self.model.actuator_forcerange[ids, 1] = limit

    def set_balance(self, gains, fighter: int | None = None) -> None:
        """Turn the virtual-force balance layer (tracker.track.vforce) on with ``gains`` (a BalanceGains, five
        numbers or a dict), or off with None, for one fighter or all. Internal joint torques through the
        leg actuators, no force on the root. Takes effect at once (controllers call it in reset); clears
        the layer's steering (``balance.bias``)."""
        from tracker.track.vforce import BalanceGains, VirtualForceBalance
        g = BalanceGains.parse(gains)
        if self.balance is None:
            if g is None:
                return
            self.balance = VirtualForceBalance(self)
        for k in (range(self.n_fighters) if fighter is None else [fighter]):
            self.balance.gains[k] = g
            self.balance.bias[k] = 0.0          # steering (a balance head's) starts from none

    def set_root_assist(self, on: bool) -> None:
        """Hold each pelvis on its reference with a weld (needs ModelOptions(root_assist=True)).
        A diagnostic / curriculum aid, not physics: an evaluation with it on does not measure falls."""
        m = self.model
        for k in range(self.n_fighters):
            eid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_EQUALITY, f"f{k}_root_assist")
            if eid < 0:
                raise ValueError("set_root_assist: build the scene with ModelOptions(root_assist=True)")
            self.data.eq_active[eid] = 1 if on else 0
        self._assist = bool(on)
        if on and self.refs:
            self._move_root_targets(self.t)

    def _move_root_targets(self, frame: int) -> None:
        m = self.model
        for k, r in enumerate(self.refs):
            bid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"f{k}_root_target")
            mid = m.body_mocapid[bid]
            self.data.mocap_pos[mid] = r.qpos[frame, :3]
            self.data.mocap_quat[mid] = r.qpos[frame, 3:7]

    # ------------------------------------------------------------------ episode
    def reset(self, refs: Reference | list[Reference], start_frame: int = 0,
              rng: np.random.Generator | None = None) -> np.ndarray:
        """Start at a reference frame (reference-state initialisation) and return the observation."""
        refs = [refs] if isinstance(refs, Reference) else list(refs)
        if len(refs) != self.n_fighters:
            raise ValueError(f"reset: {self.n_fighters} fighters need {self.n_fighters} references, got {len(refs)}")
        for r in refs:
            if abs(r.fps - self.config.control_hz) > 1e-6:
                raise ValueError(f"reference at {r.fps} fps; the environment controls at {self.config.control_hz} Hz")
        T = min(r.n_frames for r in refs)
        if not 0 <= start_frame < T - 1:
            raise ValueError(f"start_frame {start_frame} outside [0, {T - 2}]")
        self.refs = refs
        self.t = start_frame
        self.t_end = T - 1
        d = self.data
        assist = d.eq_active.copy()
        mujoco.mj_resetData(self.model, d)
        d.eq_active[:] = assist
        for c, r in zip(self._cache, refs):
            d.qpos[c.qpos] = r.qpos[start_frame]
            d.qvel[c.qvel] = r.qvel[start_frame]
            if self.config.init_noise > 0 and rng is not None:
                nv = c.qvel.stop - c.qvel.start
                d.qvel[c.qvel.start + 6:c.qvel.stop] += rng.normal(0.0, self.config.init_noise, nv - 6)
        if self._assist:
            self._move_root_targets(self.t)
        mujoco.mj_forward(self.model, d)
        self.sim_time = 0.0
        self.wall_time = 0.0
        self.done = False
        return self._obs_all()

    def get_state(self) -> tuple[np.ndarray, int, bool]:
        """The integration state (MuJoCo's mjSTATE_INTEGRATION) with the step counter and done flag,
        for a search that tries several continuations from one state (``set_state``). Derived
        quantities (contacts, velocities of bodies) are not part of it: use an observation taken
        before, or mj_copyData of the whole MjData (research/search_controller.py)."""
        spec = mujoco.mjtState.mjSTATE_INTEGRATION
        s = np.empty(mujoco.mj_stateSize(self.model, spec))
        mujoco.mj_getState(self.model, self.data, s, spec)
        return s, self.t, self.done

    def set_state(self, state: tuple[np.ndarray, int, bool]) -> None:
        """Back to a state from ``get_state`` (body poses recomputed)."""
        mujoco.mj_setState(self.model, self.data, state[0], mujoco.mjtState.mjSTATE_INTEGRATION)
        self.t, self.done = state[1], state[2]
        mujoco.mj_kinematics(self.model, self.data)

    def reference_targets(self, lead: int | None = None) -> np.ndarray:
        """(n_act,) reference PD position targets for the coming step (all fighters)."""
        k = min(self.t + (self.config.target_lead if lead is None else lead), self.t_end)
        return np.concatenate([r.ctrl[k] for r in self.refs])

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float | np.ndarray, bool, StepInfo]:
        """Advance one control step with PD targets (or residuals), see module doc."""
        if self.done:
            raise RuntimeError("step() after the episode ended; call reset()")
        t0 = time.perf_counter()
        d = self.data
        k_ref = min(self.t + self.config.target_lead, self.t_end)
        off = 0
        for c, r in zip(self._cache, self.refs):
            a = action[off:off + c.n_act]
            off += c.n_act
            target = r.ctrl[k_ref] + a if self.config.residual_actions else a
            if self.velocity_targets:
                target = target + c.ratio * r.ctrl_vel[k_ref]
            elif self.arm_velocity_targets:
                target = target + (c.ratio * c.arm) * r.ctrl_vel[k_ref]
            d.ctrl[c.act] = target
        if self._assist:
            self._move_root_targets(min(self.t + 1, self.t_end))   # where the step should end
        balance = self.balance if self.balance is not None and self.balance.active else None
        if self.substep_hook is None and balance is None:
            mujoco.mj_step(self.model, d, nstep=self.substeps)
        else:
            for s in range(self.substeps):
                mujoco.mj_step(self.model, d)
                if balance is not None:
                    balance.substep(self, d, s)
                if self.substep_hook is not None:
                    self.substep_hook(d, s)
        # mj_step leaves position-dependent quantities one substep old: refresh body and site poses
        # (contacts stay one substep old, which the fall check tolerates).
        mujoco.mj_kinematics(self.model, d)
        self.t += 1
        self.sim_time += 1.0 / self.config.control_hz
        falls, errs = [], []
        for c, r in zip(self._cache, self.refs):
            pz = d.xpos[c.pelvis, 2]
            falls.append(detect_fall(d, self.scene.floor_geom, c.fall_mask, pz, r.qpos[self.t, 2], self.config.fall))
            diff = d.site_xpos[c.sites[c.tracked_sites]] - r.sites[self.t, c.tracked_sites]
            errs.append(float(np.sqrt((diff * diff).sum(axis=1)).mean()))
        end = self.t >= self.t_end
        self.done = end or (self.config.terminate_on_fall and any(f is not None for f in falls))
        self.wall_time += time.perf_counter() - t0
        rew = self.reward()
        info = StepInfo(self.t, self.sim_time, falls, errs, end)
        return self._obs_all(), rew, self.done, info

    # ------------------------------------------------------------------ reward
    def reward(self) -> float | np.ndarray:
        """DeepMimic-style imitation reward per fighter at the current step, in [0, 1]."""
        out = []
        w = self.config.reward_weights
        d = self.data
        for c, r in zip(self._cache, self.refs):
            t = self.t
            q = d.qpos[c.qpos]
            qr = r.qpos[t]
            if c.ball:
                base = c.qpos.start
                qs = q[c.joint_q - base]
                qrr = qr[(c.joint_q - base)]
                dots = np.abs((qs * qrr).sum(axis=1)).clip(0.0, 1.0)
                ang = 2.0 * np.arccos(dots)
                pose_err = float((ang * ang).sum())
            else:
                base = c.qpos.start
                dq = q[c.joint_q - base] - qr[c.joint_q - base]
                pose_err = float((dq * dq).sum())
            v = d.qvel[c.qvel][6:] - r.qvel[t, 6:]
            vel_err = float((v * v).sum())
            ee = d.site_xpos[c.sites[c.ee_sites]] - r.sites[t, c.ee_sites]
            ee_err = float((ee * ee).sum())
            root = q[:3] - qr[:3]
            root_err = float((root * root).sum())
            out.append(w[0] * np.exp(-2.0 * pose_err) + w[1] * np.exp(-0.1 * vel_err)
                       + w[2] * np.exp(-40.0 * ee_err) + w[3] * np.exp(-10.0 * root_err))
        return out[0] if len(out) == 1 else np.array(out)

    # ------------------------------------------------------------------ observation
    def _obs_all(self) -> np.ndarray:
        obs = [self.observe(k) for k in range(self.n_fighters)]
        return obs[0] if len(obs) == 1 else np.stack(obs)

    def observe(self, k: int = 0, future: tuple[int, ...] | None = None) -> np.ndarray:
        """Observation of fighter k (see module doc); a flat float64 vector. ``future``: reference
        horizons (control steps) instead of ``config.obs_future`` (a policy trained with others)."""
        c = self._cache[k]
        r = self.refs[k]
        d = self.data
        q = d.qpos[c.qpos]
        v = d.qvel[c.qvel]
        # Facing frame: x along the hip line (right to left hip) projected on the ground.
        R = d.xmat[c.pelvis].reshape(3, 3)
        yaw = ground_yaw(R, c.lateral)
        Ry = facing_rotation(yaw)  # world -> facing
        up = R[2]  # world z in pelvis axes
        lin = Ry @ v[:3]
        ang = v[3:6]
        joints = self.joint_coordinates(k)
        jvel = v[6:]
        parts = [np.array([q[2]]), up, lin, ang, joints, jvel]
        for h in (self.config.obs_future if future is None else future):
            kf = min(self.t + h, self.t_end)
            parts.append(r.ctrl[kf] - joints)
            parts.append(Ry @ (r.qpos[kf, :3] - q[:3]))
            Rr = quat_matrix(r.qpos[kf, 3:7])
            dyaw = wrap_angle(ground_yaw(Rr, c.lateral) - yaw)
            parts.append(np.array([np.sin(dyaw), np.cos(dyaw)]))
            parts.append(Rr[2])
        return np.concatenate(parts)

    def joint_coordinates(self, k: int = 0) -> np.ndarray:
        """(n_act,) current joint coordinates in the PD's terms (ball joint: rotation vector relative
        to rest; hinge: angle), computed from qpos (equal to MuJoCo's actuator_length)."""
        c = self._cache[k]
        f = self.scene.fighters[k]
        q = self.data.qpos[c.joint_q]
        if c.ball:
            w = np.clip(q[:, 0], -1.0, 1.0)
            v = q[:, 1:]
            s = np.linalg.norm(v, axis=1)
            ang = 2.0 * np.arctan2(s, w)
            ang = np.where(ang > np.pi, ang - 2.0 * np.pi, ang)   # shortest rotation
            scale = np.where(s > 1e-12, ang / np.maximum(s, 1e-12), 2.0)
            rv = v * scale[:, None]
        else:
            rv = q[:, ::-1]                                     # hinges stored z, y, x
        return rv[f.act_joint, f.act_axis]

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second of step() so far (all fighters together)."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("nan")
