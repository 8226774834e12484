"""The batched tracking environment: N worlds of one scene stepped together, everything else
vectorised over the fighters of all worlds ("slots").

    env = BatchEnv(scene, n_envs=32, config=BatchConfig())
    obs = env.reset_all(refs, start_frames, rng)           # (B, obs_dim), B = n_envs * fighters per world
    obs, reward, done, info = env.step(targets, assist)    # targets (B, n_act) rad, assist (B, 6) or None

- Physics at the scene's rate (``ModelOptions.physics_hz``, 120 Hz by default for this env; 240 Hz
  selectable) and PD targets at ``control_hz`` (30 Hz): one ``mj_step(nstep)`` per world and control
  step is the only per-world Python; observations, rewards, fall checks, errors and the assist are
  numpy over the (B, ...) arrays gathered from the worlds. A game's single fighter is N = 1.
- Slot b = world * F + k (F fighters per world, all built from one skeleton). Each slot follows a
  Reference (tracker.track.reference), which a caller may keep writing ahead of time (a physics bout
  writes its online references); a slot's step counter ``t[b]`` indexes it.
- Actions are absolute PD position targets (actuator coordinates: ball joints' rotation-vector
  components relative to rest); the damping pulls towards zero joint velocity, or towards the
  reference's joint velocity with ``velocity_targets``.
- The assist (tracker.track.assist) is a wrench on each pelvis; it is clipped to the cap here and
  recorded per slot (``last_assist``, ``assist_force_mg``, ``assist_torque_mgm``, ``assist_at_cap``).
- Positions (bodies, joint sites, centre of mass) are refreshed after each step (mj_kinematics,
  mj_comPos, mj_subtreeVel); contacts are those of the last substep's collision (one substep old).
- Falls: tracker.body.fall's rule (a non-foot geom on the floor, or the pelvis more than
  ``pelvis_drop_m`` below the reference pelvis), vectorised.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import mujoco
import numpy as np

from motion_graph.rotations import wrap_angle
from tracker.body.fall import FallConfig
from tracker.body.humanoid import FighterScene, rest_frame
from tracker.track.assist import G, AssistConfig, clip_to_cap, fixed_wrench
from tracker.track.reference import Reference

#: fall reasons, as codes in ``info["fall"]``
FALL_NONE, FALL_PELVIS_LOW, FALL_FLOOR, FALL_UNSTABLE = 0, 1, 2, 3
FALL_NAMES = {FALL_NONE: None, FALL_PELVIS_LOW: "pelvis_low", FALL_FLOOR: "floor_contact", FALL_UNSTABLE: "unstable"}


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the tracking reward's terms (each term in [0, 1]) and the assist penalty."""

    pose: float = 0.5
    velocity: float = 0.05
    end_effector: float = 0.15
    #: scale (1/m^2) of the end-effector term's exponent: exp(-ee_scale * sum of squared hand and
    #: foot position errors in the facing frame)
    ee_scale: float = 40.0
    root: float = 0.2
    com: float = 0.1
    #: scale ((s/m)^2) of the centre-of-mass velocity term's exponent: exp(-com_scale * |v - v_ref|^2)
    #: (at 1, a 0.3 m/s lag still pays 91% of the term; at 10, 41%)
    com_scale: float = 1.0
    #: weight (1/m^2) of the pelvis's horizontal distance to its reference inside the root term's
    #: exponent (20 dz^2 + 5 (1 - up.up_ref) + 2 (1 - cos dyaw) + root_xy dxy^2)
    root_xy: float = 2.0
    #: weight of a joint-position term: exp(-sites_scale * mean squared distance (m^2) of the tracked
    #: joint sites to the reference's, in the world); off by default. The pose, end-effector and root
    #: terms read joint angles, the facing frame and the pelvis; this one reads what the protocol's
    #: joint error (MPJPE) measures
    sites: float = 0.0
    sites_scale: float = 20.0
    #: reward *= exp(-assist_penalty * (|F| / mg + |tau| / (mg m))): always positive (staying up pays),
    #: smaller the more the assist does
    assist_penalty: float = 2.0


@dataclass(frozen=True)
class BatchConfig:
    """Attributes:
        control_hz: control (and reference) rate.
        obs_future: control steps ahead at which the reference is observed.
        target_lead: PD targets are the reference this many steps ahead (the policy's residuals add to them).
        velocity_targets: damp every actuator towards the reference joint velocity (else towards
            zero); a controller may choose per actuator with ``BatchEnv.set_velocity_targets``.
        fall: the fall rule's parameters.
        terminate_on_fall: a fall ends the slot's episode (``done``).
        init_noise: std of the joint-velocity noise at reset (rad/s; reference-state initialisation).
        assist: the balance assist.
        reward: reward weights.
    """

    control_hz: float = 30.0
    obs_future: tuple[int, ...] = (1, 2, 4)
    target_lead: int = 1
    velocity_targets: bool = False
    fall: FallConfig = FallConfig()
    terminate_on_fall: bool = True
    init_noise: float = 0.0
    assist: AssistConfig = AssistConfig()
    reward: RewardWeights = RewardWeights()


@dataclass
class SlotLayout:
    """Addresses of fighter k's quantities (identical sizes for every fighter of the scene)."""

    qpos: np.ndarray          # (nq_f,) qpos addresses
    qvel: np.ndarray          # (nv_f,)
    ctrl: np.ndarray          # (n_act,)
    pelvis: int               # pelvis body id
    sites: np.ndarray         # (S,) site ids (joint sites)
    tracked: np.ndarray       # (S_t,) indices into sites: positions reproduced from qpos
    ee: np.ndarray            # indices into sites: fists, head, toes
    feet: np.ndarray          # (2,) ankle body ids (left, right)
    lateral: np.ndarray       # (3,) hip line in the pelvis frame
    mass: float               # kg
    ratio: np.ndarray = field(default_factory=lambda: np.zeros(0))   # (n_act,) kd / kp


def _layouts(scene: FighterScene) -> list[SlotLayout]:
    m = scene.model
    out = []
    for k, f in enumerate(scene.fighters):
        if f.joint_type != "ball":
            raise ValueError("BatchEnv: fighters with ball joints only (ModelOptions(joint_type='ball'))")
        parts = f.spec.parts
        ee = []
        for p in ("l_fist", "r_fist", "head_top", "head", "l_toe", "r_toe"):
            j = parts.get(p)
            if j is not None and j in set(f.site_joints.tolist()):
                ee.append(int(np.nonzero(f.site_joints == j)[0][0]))
        sp = f.spec
        lat = rest_frame(sp, sp.pelvis, parts["l_hip"])[0] - rest_frame(sp, sp.pelvis, parts["r_hip"])[0]
        feet = np.array([int(f.body_ids[list(f.body_joints).index(parts[p])]) for p in ("l_ankle", "r_ankle")])
        root = int(f.body_ids[0])
        mass = float(m.body_subtreemass[root])
        out.append(SlotLayout(np.arange(f.qpos_adr, f.qpos_adr + f.nq), np.arange(f.qvel_adr, f.qvel_adr + f.nv),
                              np.arange(f.act_adr, f.act_adr + f.n_act), root, np.asarray(f.site_ids, int),
                              np.nonzero(f.tracked)[0], np.array(sorted(set(ee)), int), feet,
                              lat / np.linalg.norm(lat), mass, f.kd / np.maximum(f.kp, 1e-9)))
    sizes = {(len(L.qpos), len(L.qvel), len(L.ctrl), len(L.sites)) for L in out}
    if len(sizes) != 1:
        raise ValueError("BatchEnv: every fighter of the scene must have the same skeleton layout")
    return out


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (w, x, y, z) -> (..., 3, 3) rotation matrices."""
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def quats_to_rotvecs(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternions (w, x, y, z) -> (..., 3) rotation vectors (shortest rotation)."""
    w = np.clip(q[..., 0], -1.0, 1.0)
    v = q[..., 1:]
    s = np.linalg.norm(v, axis=-1)
    ang = 2.0 * np.arctan2(s, w)
    ang = np.where(ang > np.pi, ang - 2.0 * np.pi, ang)
    scale = np.where(s > 1e-12, ang / np.maximum(s, 1e-12), 2.0)
    return v * scale[..., None]


def yaws_of(R: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """(B,) yaw about world z of the body-fixed hip line ``lateral`` ((B, 3) or (3,)) of (B, 3, 3) bodies."""
    w = np.einsum("bij,bj->bi", R, np.broadcast_to(lateral, (R.shape[0], 3)))
    return np.arctan2(w[:, 1], w[:, 0])


def facing_rotations(yaw: np.ndarray) -> np.ndarray:
    """(B, 3, 3) world -> facing rotations (x along the facing yaw)."""
    c, s = np.cos(yaw), np.sin(yaw)
    R = np.zeros(yaw.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 1], R[..., 1, 0], R[..., 1, 1], R[..., 2, 2] = c, s, -s, c, 1.0
    return R


def reference_tables(ref: Reference, layout: SlotLayout, scene: FighterScene, fighter: int) -> dict:
    """Per-frame quantities of a reference that observations and rewards read, computed once and
    cached on ``ref.meta``: pelvis rotation, yaw and up vector, end effectors relative to the pelvis
    in the facing frame, centre of mass relative to the feet and its velocity (facing frame)."""
    key = f"batch_tables_{fighter}"
    tab = ref.meta.get(key)
    if tab is not None and tab["n"] == ref.n_frames:
        return tab
    T = ref.n_frames
    R = quats_to_matrices(ref.qpos[:, 3:7])
    yaw = yaws_of(R, layout.lateral)
    Ry = facing_rotations(yaw)
    ee = np.einsum("tij,tej->tei", Ry, ref.sites[:, layout.ee] - ref.qpos[:, None, :3])
    m = scene.model
    d = mujoco.MjData(m)
    f = scene.fighters[fighter]
    com = np.zeros((T, 3))
    feet = np.zeros((T, 2, 3))
    for t in range(T):
        d.qpos[f.qpos_slice] = ref.qpos[t]
        mujoco.mj_kinematics(m, d)
        mujoco.mj_comPos(m, d)
        com[t] = d.subtree_com[layout.pelvis]
        feet[t] = d.xpos[layout.feet]
    com_vel = np.gradient(com, 1.0 / ref.fps, axis=0) if T > 1 else np.zeros_like(com)
    com_feet = np.einsum("tij,tj->ti", Ry, com - feet.mean(axis=1))
    com_vel_f = np.einsum("tij,tj->ti", Ry, com_vel)
    tab = dict(n=T, R=R, yaw=yaw, up=R[:, 2, :].copy(), ee=ee, com=com, com_vel=com_vel, com_feet=com_feet,
               com_vel_f=com_vel_f)
    ref.meta[key] = tab
    return tab


def place_reference(ref: Reference, frame: int, from_xy: np.ndarray, to_xy: np.ndarray, dyaw: float) -> Reference:
    """A copy of ``ref`` whose frames from ``frame`` on are moved on the ground: rotated by ``dyaw``
    (rad) about the vertical through ``from_xy`` (m), then carried to ``to_xy``; earlier frames stay.
    Root positions and orientations, world velocities, joint sites and the cached batch tables move
    with it; joint angles, PD targets, the world vertical in the pelvis frame (``up``) and the
    facing-frame quantities are invariant (a game placing the next clip under its character)."""
    if not 0 <= frame < ref.n_frames:
        raise ValueError(f"place_reference: frame {frame} outside [0, {ref.n_frames - 1}]")
    c, s = np.cos(dyaw), np.sin(dyaw)
    R2 = np.array([[c, -s], [s, c]])
    R3 = np.eye(3)
    R3[:2, :2] = R2
    fx, tx = np.asarray(from_xy, dtype=np.float64), np.asarray(to_xy, dtype=np.float64)
    qpos, qvel, sites = ref.qpos.copy(), ref.qvel.copy(), ref.sites.copy()
    sl = slice(frame, None)
    qpos[sl, :2] = (qpos[sl, :2] - fx) @ R2.T + tx
    qz = np.array([np.cos(dyaw / 2), 0.0, 0.0, np.sin(dyaw / 2)])     # yaw quaternion (w, x, y, z)
    w1, v1 = qz[0], qz[1:]
    q = qpos[sl, 3:7].copy()
    w2, v2 = q[:, 0], q[:, 1:]
    qpos[sl, 3] = w1 * w2 - v2 @ v1
    qpos[sl, 4:7] = w1 * v2 + w2[:, None] * v1 + np.cross(v1, v2)
    qvel[sl, :3] = qvel[sl, :3] @ R3.T                                  # world linear velocity
    sites[sl, :, :2] = (sites[sl, :, :2] - fx) @ R2.T + tx
    meta = {}
    for key, val in ref.meta.items():
        if key.startswith("batch_tables_") and isinstance(val, dict):
            tab = dict(val)
            tab["R"] = val["R"].copy()
            tab["R"][sl] = np.einsum("ij,tjk->tik", R3, val["R"][sl])
            tab["yaw"] = val["yaw"].copy()
            tab["yaw"][sl] = wrap_angle(val["yaw"][sl] + dyaw)
            tab["com"] = val["com"].copy()
            tab["com"][sl, :2] = (val["com"][sl, :2] - fx) @ R2.T + tx
            tab["com_vel"] = val["com_vel"].copy()
            tab["com_vel"][sl] = val["com_vel"][sl] @ R3.T
            val = tab
        meta[key] = val
    return Reference(ref.fps, qpos, qvel, ref.ctrl, ref.ctrl_vel, sites, ref.penetration, ref.source, meta)


class BatchEnv:
    """See the module docstring."""

    def __init__(self, scene: FighterScene, n_envs: int = 1, config: BatchConfig = BatchConfig()) -> None:
        if n_envs < 1:
            raise ValueError(f"n_envs must be >= 1, not {n_envs}")
        self.scene = scene
        self.model = scene.model
        self.config = config
        self.n_envs = int(n_envs)
        self.F = len(scene.fighters)
        self.B = self.n_envs * self.F
        hz = scene.options.physics_hz
        n = hz / config.control_hz
        if abs(n - round(n)) > 1e-6 or round(n) < 1:
            raise ValueError(f"physics rate {hz} Hz is not a multiple of the control rate {config.control_hz} Hz")
        self.substeps = int(round(n))
        self.datas = [mujoco.MjData(self.model) for _ in range(self.n_envs)]
        self.layouts = _layouts(scene)
        L0 = self.layouts[0]
        self.n_act = len(L0.ctrl)
        self.nq_f, self.nv_f = len(L0.qpos), len(L0.qvel)
        self.n_joints = (self.nq_f - 7) // 4
        f0 = scene.fighters[0]
        self.act_joint, self.act_axis = np.asarray(f0.act_joint), np.asarray(f0.act_axis)
        # slot b = world * F + k
        self.env_of = np.repeat(np.arange(self.n_envs), self.F)
        self.fighter_of = np.tile(np.arange(self.F), self.n_envs)
        self._qidx = np.stack([self.layouts[k].qpos for k in self.fighter_of])
        self._vidx = np.stack([self.layouts[k].qvel for k in self.fighter_of])
        self._pel = np.array([self.layouts[k].pelvis for k in self.fighter_of])
        self._sites = np.stack([self.layouts[k].sites for k in self.fighter_of])
        self._feet = np.stack([self.layouts[k].feet for k in self.fighter_of])
        self.lateral = np.stack([self.layouts[k].lateral for k in self.fighter_of])
        self.mass = np.array([self.layouts[k].mass for k in self.fighter_of])
        self.ratio = np.stack([self.layouts[k].ratio for k in self.fighter_of])
        self.tracked = L0.tracked
        self.ee = L0.ee
        # geom tables for contacts: fighter of each geom (-1: none), non-foot collision geom, foot side
        ng = self.model.ngeom
        self._geom_fighter = np.full(ng, -1)
        self._geom_fall = np.zeros(ng, bool)
        self._geom_side = np.full(ng, -1)
        for k, f in enumerate(scene.fighters):
            for g in f.fall_geoms:
                self._geom_fighter[g], self._geom_fall[g] = k, True
            for s, lab in enumerate(("l_foot", "r_foot")):
                for g in f.geom_label.get(lab, []):
                    self._geom_fighter[g], self._geom_side[g] = k, s
        self.floor = scene.floor_geom
        self.refs: list[Reference | None] = [None] * self.B
        self.tables: list[dict | None] = [None] * self.B
        self.t = np.zeros(self.B, dtype=np.int64)
        self.t_end = np.zeros(self.B, dtype=np.int64)
        self.done = np.ones(self.B, dtype=bool)
        self.last_assist = np.zeros((self.B, 6))       # in cap units, facing frame (what the policy sees)
        self.assist_force_mg = np.zeros(self.B)
        self.assist_torque_mgm = np.zeros(self.B)
        self.assist_at_cap = np.zeros(self.B, dtype=bool)
        #: per slot: the assist may act (a physics bout turns it off for a fighter that is down)
        self.assist_enabled = np.ones(self.B, dtype=bool)
        #: (B, n_act) 1.0 where an actuator damps towards the reference joint velocity, else 0.0
        self.vt_mask = np.full((self.B, self.n_act), 1.0 if config.velocity_targets else 0.0)
        self._bad = np.zeros(self.n_envs, dtype=np.int64)   # MuJoCo's bad-acceleration warnings seen per world
        self.unstable = np.zeros(self.B, dtype=bool)       # the world's integration diverged at the last step
        self.sim_time = 0.0
        self.wall_time = 0.0
        #: optional callable(world, data, substep) after every physics substep (e.g. hit judging); with
        #: it set, each world's control step runs substep by substep
        self.substep_hook = None
        self._gather()

    # ------------------------------------------------------------------ gains
    def set_gains(self, kp: np.ndarray, kd: np.ndarray, fighter: int | None = None) -> None:
        """Write PD gains (N m / rad, N m s / rad; (n_act,)) into the model (every world shares it)."""
        for k in (range(self.F) if fighter is None else [fighter]):
            ids = self.layouts[k].ctrl
            self.model.actuator_gainprm[ids, 0] = kp
            self.model.actuator_biasprm[ids, 1] = -kp
            self.model.actuator_biasprm[ids, 2] = -kd
            self.layouts[k].ratio = np.broadcast_to(kd / np.maximum(kp, 1e-9), (self.n_act,)).copy()
        self.ratio = np.stack([self.layouts[k].ratio for k in self.fighter_of])

    def set_velocity_targets(self, mask: np.ndarray, fighter: int | None = None) -> None:
        """Per actuator (n_act,), 1 to damp towards the reference joint velocity, 0 towards zero
        (the position target is shifted by kd / kp times the reference velocity). With the config's
        ``velocity_targets`` every actuator stays on whatever the mask."""
        m = np.asarray(mask, dtype=np.float64)
        if m.shape != (self.n_act,) or not np.all((m == 0.0) | (m == 1.0)):
            raise ValueError(f"velocity-target mask must be ({self.n_act},) of 0 and 1, got shape {m.shape}")
        m = np.maximum(m, float(self.config.velocity_targets))
        for k in (range(self.F) if fighter is None else [fighter]):
            self.vt_mask[self.fighter_of == k] = m

    def place_on_body(self, slots) -> None:
        """Re-place each slot's reference from its current step on under its simulated pelvis: the
        reference pelvis's ground position and yaw there moved onto the body's (place_reference), as
        a game places the next clip under its character. The env's reference becomes the placed copy."""
        for b in np.atleast_1d(np.asarray(slots, dtype=np.int64)):
            ref, tab = self.refs[b], self.tables[b]
            if ref is None:
                raise ValueError(f"place_on_body: slot {b} has no reference")
            t = int(self.t[b])
            k = int(self.fighter_of[b])
            sim_yaw = float(yaws_of(self.R[b:b + 1], self.lateral[b])[0])
            dyaw = float(wrap_angle(sim_yaw - float(tab["yaw"][t])))
            placed = place_reference(ref, t, ref.qpos[t, :2], self.qpos[b, :2], dyaw)
            self.refs[b] = placed
            self.tables[b] = reference_tables(placed, self.layouts[k], self.scene, k)

    def set_torque_limits(self, limit: np.ndarray, fighter: int | None = None) -> None:
        for k in (range(self.F) if fighter is None else [fighter]):
            ids = self.layouts[k].ctrl
            self.model.actuator_forcerange[ids, 0] = -limit
            self.model.actuator_forcerange[ids, 1] = limit

    # ------------------------------------------------------------------ state
    def _gather(self) -> None:
        """Stack every world's state into (B, ...) arrays (after the positions were refreshed)."""
        ds = self.datas
        e = self.env_of
        Q = np.stack([d.qpos for d in ds])
        V = np.stack([d.qvel for d in ds])
        self.qpos = Q[e[:, None], self._qidx]
        self.qvel = V[e[:, None], self._vidx]
        XM = np.stack([d.xmat for d in ds])
        XP = np.stack([d.xpos for d in ds])
        SX = np.stack([d.site_xpos for d in ds])
        SC = np.stack([d.subtree_com for d in ds])
        SV = np.stack([d.subtree_linvel for d in ds])
        self.R = XM[e, self._pel].reshape(self.B, 3, 3)
        self.pelvis_pos = XP[e, self._pel]
        self.site_pos = SX[e[:, None], self._sites]
        self.feet_pos = XP[e[:, None], self._feet]
        self.com = SC[e, self._pel]
        self.com_vel = SV[e, self._pel]
        # contacts of every world: floor touches by fall geoms and by each foot
        self.floor_fall = np.zeros(self.B, dtype=bool)
        self.foot_touch = np.zeros((self.B, 2))
        for w, d in enumerate(ds):
            n = d.ncon
            if not n:
                continue
            g = d.contact.geom[:n]
            other = np.where(g[:, 0] == self.floor, g[:, 1], np.where(g[:, 1] == self.floor, g[:, 0], -1))
            other = other[other >= 0]
            if not len(other):
                continue
            k = self._geom_fighter[other]
            fall = self._geom_fall[other]
            side = self._geom_side[other]
            for kk in np.unique(k[k >= 0]):
                b = w * self.F + kk
                sel = k == kk
                self.floor_fall[b] |= bool(fall[sel].any())
                s = side[sel]
                self.foot_touch[b, 0] = float((s == 0).any())
                self.foot_touch[b, 1] = float((s == 1).any())

    def reset(self, slots, refs: list[Reference], start_frames=None, rng: np.random.Generator | None = None
              ) -> np.ndarray:
        """Start the given slots on their references (reference-state initialisation at
        ``start_frames``, default 0); every fighter of a world resets with it when the slots cover
        the world, else only the slot's fighter is placed. Returns the observation of all slots."""
        slots = np.atleast_1d(np.asarray(slots, dtype=np.int64))
        if len(refs) != len(slots):
            raise ValueError(f"reset: {len(slots)} slots need {len(slots)} references, got {len(refs)}")
        starts = np.zeros(len(slots), dtype=np.int64) if start_frames is None else np.asarray(start_frames, np.int64)
        worlds = sorted(set(int(self.env_of[b]) for b in slots))
        full = {w for w in worlds if set(range(w * self.F, (w + 1) * self.F)) <= set(slots.tolist())}
        for w in full:
            mujoco.mj_resetData(self.model, self.datas[w])
        for b, ref, s in zip(slots, refs, starts):
            if abs(ref.fps - self.config.control_hz) > 1e-6:
                raise ValueError(f"reference at {ref.fps} fps; the environment controls at {self.config.control_hz} Hz")
            if not 0 <= s < ref.n_frames - 1:
                raise ValueError(f"start frame {s} outside [0, {ref.n_frames - 2}]")
            w, k = int(self.env_of[b]), int(self.fighter_of[b])
            d = self.datas[w]
            L = self.layouts[k]
            d.qpos[L.qpos] = ref.qpos[s]
            d.qvel[L.qvel] = ref.qvel[s]
            if self.config.init_noise > 0 and rng is not None:
                d.qvel[L.qvel[6:]] += rng.normal(0.0, self.config.init_noise, len(L.qvel) - 6)
            d.xfrc_applied[L.pelvis] = 0.0
            self.refs[b] = ref
            self.tables[b] = reference_tables(ref, L, self.scene, k)
            self.t[b] = s
            self.t_end[b] = ref.n_frames - 1
            self.done[b] = False
            self.last_assist[b] = 0.0
            self.assist_force_mg[b] = self.assist_torque_mgm[b] = 0.0
            self.assist_at_cap[b] = False
        for w in worlds:
            mujoco.mj_forward(self.model, self.datas[w])
            mujoco.mj_subtreeVel(self.model, self.datas[w])
        self._gather()
        return self.observe()

    def refresh(self) -> None:
        """Recompute positions and the gathered arrays after a caller edited a world's qpos/qvel."""
        for d in self.datas:
            mujoco.mj_forward(self.model, d)
            mujoco.mj_subtreeVel(self.model, d)
        self._gather()

    # ------------------------------------------------------------------ reference rows
    def _rows(self, offset: int) -> tuple[np.ndarray, ...]:
        """Reference rows at t + offset (clamped to each slot's end): qpos, qvel, ctrl, ctrl_vel."""
        B = self.B
        qp = np.empty((B, self.nq_f))
        qv = np.empty((B, self.nv_f))
        ct = np.empty((B, self.n_act))
        cv = np.empty((B, self.n_act))
        for b in range(B):
            r = self.refs[b]
            if r is None:
                qp[b], qv[b], ct[b], cv[b] = self.qpos[b], self.qvel[b], 0.0, 0.0
                continue
            i = min(int(self.t[b]) + offset, int(self.t_end[b]))
            qp[b], qv[b], ct[b], cv[b] = r.qpos[i], r.qvel[i], r.ctrl[i], r.ctrl_vel[i]
        return qp, qv, ct, cv

    def _table_rows(self, name: str, offset: int) -> np.ndarray:
        """(B, ...) rows of a reference table at t + offset (zeros for a slot not started yet)."""
        shape = {"R": (3, 3), "yaw": (), "ee": (len(self.ee), 3)}.get(name, (3,))
        out = np.zeros((self.B,) + shape)
        for b in range(self.B):
            tab = self.tables[b]
            if tab is not None:
                out[b] = tab[name][min(int(self.t[b]) + offset, int(self.t_end[b]), tab["n"] - 1)]
        return out

    def reference_targets(self, lead: int | None = None) -> np.ndarray:
        """(B, n_act) reference PD position targets for the coming step."""
        return self._rows(self.config.target_lead if lead is None else lead)[2]

    # ------------------------------------------------------------------ step
    def fixed_assist(self, frac: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
        """The fixed mode's unclipped world wrench (B, 3) force, (B, 3) torque toward the reference
        root pose at ``frac`` of the way from the current control step to the next (the reference
        interpolated linearly), from the gathered state."""
        qp0, qv0, _, _ = self._rows(0)
        qp1, qv1, _, _ = self._rows(1)
        u = float(frac)
        ref_R = quats_to_matrices(qp1[:, 3:7])
        ref_omega = np.einsum("bij,bj->bi", ref_R, (1 - u) * qv0[:, 3:6] + u * qv1[:, 3:6])
        omega = np.einsum("bij,bj->bi", self.R, self.qvel[:, 3:6])
        if self.config.assist.com:
            pos, vel = self.com, self.com_vel
            rpos = (1 - u) * self._table_rows("com", 0) + u * self._table_rows("com", 1)
            rvel = (1 - u) * self._table_rows("com_vel", 0) + u * self._table_rows("com_vel", 1)
        else:
            pos, vel = self.qpos[:, :3], self.qvel[:, :3]
            rpos, rvel = (1 - u) * qp0[:, :3] + u * qp1[:, :3], (1 - u) * qv0[:, :3] + u * qv1[:, :3]
        ryaw = self._table_rows("yaw", 0) + u * wrap_angle(self._table_rows("yaw", 1) - self._table_rows("yaw", 0))
        yaw_err = wrap_angle(ryaw - yaws_of(self.R, self.lateral))
        return fixed_wrench(self.config.assist, self.mass, pos, vel, self.R, omega, rpos, rvel, ref_R, ref_omega,
                            yaw_err)

    def _light_gather(self) -> None:
        """Refresh the root and centre-of-mass state between substeps (what the fixed assist reads)."""
        ds = self.datas
        e = self.env_of
        Q = np.stack([d.qpos for d in ds])
        V = np.stack([d.qvel for d in ds])
        self.qpos = Q[e[:, None], self._qidx]
        self.qvel = V[e[:, None], self._vidx]
        self.R = quats_to_matrices(self.qpos[:, 3:7])
        SC = np.stack([d.subtree_com for d in ds])
        SV = np.stack([d.subtree_linvel for d in ds])
        self.com = SC[e, self._pel]
        self.com_vel = SV[e, self._pel]

    def assist_wrench(self, assist: np.ndarray | None, frac: float = 1.0) -> np.ndarray:
        """(B, 6) world wrench (N, N m) the assist applies this step: the fixed PD (mode "fixed"), the
        policy's output ``assist`` (mode "learned": (B, 6) in cap units, facing frame), or zeros; clipped."""
        cfg = self.config.assist
        wrench = np.zeros((self.B, 6))
        if not cfg.active:
            self.last_assist[:] = 0.0
            self.assist_force_mg[:] = self.assist_torque_mgm[:] = 0.0
            self.assist_at_cap[:] = False
            return wrench
        mg = self.mass * G
        if cfg.mode == "fixed":
            force, torque = self.fixed_assist(frac)
        else:
            if assist is None:
                raise ValueError("assist mode 'learned' needs the policy's assist output")
            a = np.asarray(assist, dtype=np.float64).reshape(self.B, 6)
            Ryt = np.swapaxes(facing_rotations(yaws_of(self.R, self.lateral)), 1, 2)   # facing -> world
            force = np.einsum("bij,bj->bi", Ryt, a[:, :3]) * (cfg.cap * mg)[:, None]
            torque = np.einsum("bij,bj->bi", Ryt, a[:, 3:]) * (cfg.cap * mg)[:, None]
        on = self.assist_enabled[:, None]
        force, torque = np.where(on, force, 0.0), np.where(on, torque, 0.0)
        force, torque, at_cap = clip_to_cap(force, torque, cfg.cap * mg, cfg.cap * mg * 1.0)
        wrench[:, :3], wrench[:, 3:] = force, torque
        Ry = facing_rotations(yaws_of(self.R, self.lateral))
        scale = (cfg.cap * mg)[:, None]
        self.last_assist[:, :3] = np.einsum("bij,bj->bi", Ry, force) / scale
        self.last_assist[:, 3:] = np.einsum("bij,bj->bi", Ry, torque) / scale
        self.assist_force_mg[:] = np.linalg.norm(force, axis=1) / mg
        self.assist_torque_mgm[:] = np.linalg.norm(torque, axis=1) / mg
        self.assist_at_cap[:] = at_cap
        return wrench

    def step(self, targets: np.ndarray, assist: np.ndarray | None = None
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """One control step of every world with PD position targets (B, n_act) and the policy's
        assist output (mode "learned"). The fixed assist is recomputed at every physics substep (a
        stiff feedback held over a control step would go unstable); the learned one is held. Slots
        already done are held (their world still steps when other fighters of it are live).
        Returns obs (B, D), reward (B,), done (B,), info."""
        t0 = time.perf_counter()
        targets = np.asarray(targets, dtype=np.float64).reshape(self.B, self.n_act)
        _, _, _, cv = self._rows(self.config.target_lead)
        if self.vt_mask.any():
            targets = targets + self.ratio * self.vt_mask * cv
        hook = self.substep_hook
        run = [w for w in range(self.n_envs) if not all(self.done[w * self.F:(w + 1) * self.F]) or hook is not None]
        for w in run:
            d = self.datas[w]
            for k in range(self.F):
                d.ctrl[self.layouts[k].ctrl] = targets[w * self.F + k]
        per_substep = self.config.assist.active and self.config.assist.mode == "fixed"
        if per_substep:
            fs, ts, caps = [], [], []
            for s in range(self.substeps):
                wrench = self.assist_wrench(None, frac=(s + 0.5) / self.substeps)
                fs.append(self.assist_force_mg.copy())
                ts.append(self.assist_torque_mgm.copy())
                caps.append(self.assist_at_cap.copy())
                for w in run:
                    d = self.datas[w]
                    for k in range(self.F):
                        d.xfrc_applied[self.layouts[k].pelvis] = wrench[w * self.F + k]
                    mujoco.mj_step(self.model, d)
                    if hook is not None:
                        hook(w, d, s)
                    mujoco.mj_subtreeVel(self.model, d)
                self._light_gather()
            self.assist_force_mg[:] = np.mean(fs, axis=0)
            self.assist_torque_mgm[:] = np.mean(ts, axis=0)
            self.assist_at_cap[:] = np.mean(caps, axis=0) > 0.5
        else:
            wrench = self.assist_wrench(assist)
            for w in run:
                d = self.datas[w]
                for k in range(self.F):
                    d.xfrc_applied[self.layouts[k].pelvis] = wrench[w * self.F + k]
                if hook is None:
                    mujoco.mj_step(self.model, d, nstep=self.substeps)
                else:
                    for s in range(self.substeps):
                        mujoco.mj_step(self.model, d)
                        hook(w, d, s)
        self.unstable[:] = False
        for w in run:
            d = self.datas[w]
            mujoco.mj_kinematics(self.model, d)
            mujoco.mj_comPos(self.model, d)
            mujoco.mj_subtreeVel(self.model, d)
            nbad = int(d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number)
            if nbad > self._bad[w]:        # MuJoCo reset the world after a diverged step: a fall of its fighters
                self._bad[w] = nbad
                self.unstable[w * self.F:(w + 1) * self.F] = True
        live = ~self.done
        self.t = np.where(live, np.minimum(self.t + 1, self.t_end), self.t)
        self.sim_time += 1.0 / self.config.control_hz
        self._gather()
        fall = self.falls()
        err = self.mpjpe()
        reward = self.reward()
        end = self.t >= self.t_end
        newly = live & (end | (self.config.terminate_on_fall & (fall != FALL_NONE)))
        self.done = self.done | newly
        self.wall_time += time.perf_counter() - t0
        info = {"fall": fall, "mpjpe_m": err, "end": end, "live": live}
        return self.observe(), np.where(live, reward, 0.0), self.done.copy(), info

    # ------------------------------------------------------------------ checks and errors
    def falls(self) -> np.ndarray:
        """(B,) fall code per slot (FALL_*): pelvis too low, or a non-foot geom on the floor."""
        out = np.full(self.B, FALL_NONE)
        qp, _, _, _ = self._rows(0)
        low = self.pelvis_pos[:, 2] < qp[:, 2] - self.config.fall.pelvis_drop_m
        out[low] = FALL_PELVIS_LOW
        if self.config.fall.floor_touch:
            out[(~low) & self.floor_fall] = FALL_FLOOR
        out[self.unstable] = FALL_UNSTABLE
        return out

    def site_offsets(self) -> np.ndarray:
        """(B, tracked sites, 3) world offsets (m) of the tracked joint sites from the reference's at
        the current step (zero for a slot not started yet)."""
        sites = np.stack([self.refs[b].sites[int(self.t[b])] if self.refs[b] is not None else self.site_pos[b]
                          for b in range(self.B)])
        return self.site_pos[:, self.tracked] - sites[:, self.tracked]

    def mpjpe(self) -> np.ndarray:
        """(B,) mean distance (m) of the tracked joint sites to the reference's at the current step."""
        diff = self.site_offsets()
        return np.sqrt((diff * diff).sum(axis=2)).mean(axis=1)

    def joint_coordinates(self) -> np.ndarray:
        """(B, n_act) joint coordinates in the PD's terms (rotation-vector components relative to rest)."""
        q = self.qpos[:, 7:].reshape(self.B, self.n_joints, 4)
        rv = quats_to_rotvecs(q)
        return rv[:, self.act_joint, self.act_axis]

    # ------------------------------------------------------------------ reward
    def reward(self) -> np.ndarray:
        """(B,) DeepMimic-style tracking reward in [0, 1] (RewardWeights), scaled down by the assist."""
        w = self.config.reward
        qp, qv, _, _ = self._rows(0)
        B, D = self.B, self.n_joints
        qs = self.qpos[:, 7:].reshape(B, D, 4)
        qr = qp[:, 7:].reshape(B, D, 4)
        ang = 2.0 * np.arccos(np.clip(np.abs((qs * qr).sum(axis=2)), 0.0, 1.0))
        pose_err = (ang * ang).sum(axis=1)
        dv = self.qvel[:, 6:] - qv[:, 6:]
        vel_err = (dv * dv).sum(axis=1)
        yaw = yaws_of(self.R, self.lateral)
        Ry = facing_rotations(yaw)
        ee = np.einsum("bij,bej->bei", Ry, self.site_pos[:, self.ee] - self.qpos[:, None, :3])
        ee_err = ((ee - self._table_rows("ee", 0)) ** 2).sum(axis=(1, 2))
        dp = self.qpos[:, :3] - qp[:, :3]
        dyaw = wrap_angle(yaw - self._table_rows("yaw", 0))
        up_dot = (self.R[:, 2, :] * self._table_rows("up", 0)).sum(axis=1)
        root_err = (20.0 * dp[:, 2] ** 2 + 5.0 * (1.0 - up_dot) + 2.0 * (1.0 - np.cos(dyaw))
                    + w.root_xy * (dp[:, :2] ** 2).sum(1))
        dc = self.com_vel - self._table_rows("com_vel", 0)
        com_err = (dc * dc).sum(axis=1)
        r = (w.pose * np.exp(-2.0 * pose_err) + w.velocity * np.exp(-0.1 * vel_err) + w.end_effector
             * np.exp(-w.ee_scale * ee_err) + w.root * np.exp(-root_err)
             + w.com * np.exp(-w.com_scale * com_err))
        if w.sites > 0.0:
            ds = self.site_offsets()
            r = r + w.sites * np.exp(-w.sites_scale * (ds * ds).sum(axis=2).mean(axis=1))
        if self.config.assist.active:
            r = r * np.exp(-w.assist_penalty * (self.assist_force_mg + self.assist_torque_mgm))
        return r

    # ------------------------------------------------------------------ observation
    def observe(self) -> np.ndarray:
        """(B, obs_dim) observation: proprioception in the facing frame, balance (centre of mass and
        feet, foot contacts), the reference at ``obs_future`` steps ahead, and the assist (its last
        output and what the fixed PD would apply now, both in cap units, facing frame)."""
        B = self.B
        yaw = yaws_of(self.R, self.lateral)
        Ry = facing_rotations(yaw)
        joints = self.joint_coordinates()
        parts = [self.qpos[:, 2:3], self.R[:, 2, :], np.einsum("bij,bj->bi", Ry, self.qvel[:, :3]),
                 self.qvel[:, 3:6], joints, self.qvel[:, 6:]]
        feet_mid = self.feet_pos.mean(axis=1)
        com_feet = np.einsum("bij,bj->bi", Ry, self.com - feet_mid)
        com_vel = np.einsum("bij,bj->bi", Ry, self.com_vel)
        feet_rel = np.einsum("bij,bkj->bki", Ry, self.feet_pos - self.com[:, None, :]).reshape(B, 6)
        ref_cf = self._table_rows("com_feet", 1)
        ref_cv = self._table_rows("com_vel_f", 1)
        parts += [com_feet, com_vel, feet_rel, self.foot_touch, ref_cf, ref_cv, com_feet - ref_cf, com_vel - ref_cv]
        for h in self.config.obs_future:
            qp, _, ct, _ = self._rows(h)
            parts.append(ct - joints)
            parts.append(np.einsum("bij,bj->bi", Ry, qp[:, :3] - self.qpos[:, :3]))
            dyaw = wrap_angle(self._table_rows("yaw", h) - yaw)
            parts.append(np.stack([np.sin(dyaw), np.cos(dyaw)], axis=1))
            parts.append(self._table_rows("up", h))
        cfg = self.config.assist
        fixed = np.zeros((B, 6))
        if cfg.active:
            f, tq = self.fixed_assist()
            mg = self.mass * G
            f, tq, _ = clip_to_cap(f, tq, cfg.cap * mg, cfg.cap * mg)
            fixed[:, :3] = np.einsum("bij,bj->bi", Ry, f) / (cfg.cap * mg)[:, None]
            fixed[:, 3:] = np.einsum("bij,bj->bi", Ry, tq) / (cfg.cap * mg)[:, None]
        parts += [self.last_assist, fixed]
        return np.concatenate(parts, axis=1)

    @property
    def obs_dim(self) -> int:
        return int(self.observe().shape[1])

    @property
    def realtime_factor(self) -> float:
        """Simulated seconds per wall-clock second of step() so far (every world together)."""
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("nan")
