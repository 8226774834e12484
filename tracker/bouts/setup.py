"""Physics bouts' set-up and bookkeeping: the rules (BoutConfig), what every bout of one library
shares (BoutSetup: the calibrated two-fighter scene, its environment, the kinematic simulator's
tables, cached per-action references) and per-fighter state (FighterState: the online reference
buffer, planned action segments, falls, hits, rewards). The bout itself: tracker.bouts.physics_bout."""
from __future__ import annotations

from dataclasses import dataclass, replace

import mujoco
import numpy as np

from tracker.body.frames import ground_yaws
from tracker.body.humanoid import FighterScene, ModelOptions, build_fighter_scene
from tracker.bouts.results import zero_reward
from tracker.track.env import EnvConfig, TrackingEnv
from tracker.track.reference import FootPenetration, Reference, build_reference

# ----------------------------------------------------------------------------------------------
# configuration (agents: tracker.bouts.agents; results: tracker.bouts.results)


@dataclass(frozen=True)
class BoutConfig:
    """Rules of a physics bout (see the module doc). Times in seconds, distances in metres,
    forces in newtons, frames at the control rate (= the library rate, 30 Hz).

    Attributes:
        seconds: bout length.
        hit_force_n: a fist contact on a target counts from this normal force.
        force_clip_n: forces are clipped here for the damage sum / match reward.
        window_slack: (before, after) frames added to a strike window for the physical hit.
        fall_pause_s: how long a fallen fighter lies before it is reset.
        reset_min_distance_m: a reset fighter is put at least this far (pelvis ground distance)
            from the opponent.
        reset_place: where a fallen fighter gets up: "reference" (its reference pelvis when the fall
            was detected: where its motion had taken it, the topple undone) or "fall" (its
            physical pelvis then, already displaced by the topple).
        reset_facing: which way a reset fighter faces: "opponent" (towards the opponent's pelvis, as
            a boxer gets up facing the other: the fighters close in and plan strikes) or "fall" (its
            fighting direction when the fall was detected: they stay apart; docs/tracker.md).
        blend_frames: pose blend from the previous action's end (ActionLibrary.sequence_motion).
        init_distance_m: initial distance range (the kinematic game's).
        physics_hz: physics rate.
        w_close, w_facing, w_energy, w_penalty: the competitive-sports paper's reward weights.
        record_qpos: keep qpos per control step (needed for the video).
    """

    seconds: float = 60.0
    hit_force_n: float = 1.0
    force_clip_n: float = 200.0
    window_slack: tuple[int, int] = (1, 4)
    fall_pause_s: float = 1.0
    reset_min_distance_m: float = 0.6
    reset_place: str = "reference"
    reset_facing: str = "opponent"
    blend_frames: int = 4
    init_distance_m: tuple[float, float] = (1.0, 3.0)
    physics_hz: float = 240.0
    w_close: float = 0.2
    w_facing: float = 0.05
    w_energy: float = 0.001
    w_penalty: float = 30.0
    record_qpos: bool = True

    def __post_init__(self) -> None:
        if self.reset_place not in ("reference", "fall"):
            raise ValueError(f"BoutConfig.reset_place must be 'reference' or 'fall', not {self.reset_place!r}")
        if self.reset_facing not in ("fall", "opponent"):
            raise ValueError(f"BoutConfig.reset_facing must be 'fall' or 'opponent', not {self.reset_facing!r}")


# ----------------------------------------------------------------------------------------------
# set-up shared by bouts (model, scene, environment)


@dataclass
class BoutSetup:
    """The fighter model calibrated on the library, the two-fighter scene and its environment;
    built once and reused by every bout (RL workers run hundreds of bouts on one setup)."""

    library: object
    scene: FighterScene
    env: TrackingEnv
    lift_m: float
    tables: object          # igraph_fight.sim.SimTables (the kinematic simulator of planned hits)
    game: object            # igraph_fight.game.FightGame (initial states, guard actions)
    root_assist: bool = False
    batched: bool = False   # the env is a tracker.bouts.bout_env.BoutEnv (assisted tracker, PD tracker)

    @classmethod
    def create(cls, library, physics_hz: float = 240.0, sim_params=None, root_assist: bool = False,
               tracker=None, reward=None) -> "BoutSetup":
        """root_assist: hold each pelvis on its reference with a weld (ModelOptions.root_assist):
        NOT physics (a fighter cannot fall), a labelled diagnostic only. ``tracker``: a batched
        tracker (``batched`` true: the assisted tracker, PDTracker) gets the batched environment at
        its physics rate with its assist and grounded per-action references; ``reward``: that env's
        tracker.track.batch_env.RewardWeights (a trainer's; default the env's)."""
        from igraph_fight.game import FightGame, GameConfig
        from igraph_fight.sim import SimParams, SimTables

        from tracker.body.spec import fighter_spec
        from tracker.track.walks import LibraryWalks
        src = LibraryWalks(library)
        if abs(src.fps - 30.0) > 1e-6:
            raise ValueError(f"physics bouts need a 30 fps library (control rate), got {src.fps}")
        spec = fighter_spec(src.skeleton, src.calibration_motions())
        sp = sim_params if sim_params is not None else SimParams()
        tables = SimTables.from_library(library, sp)
        game = FightGame(library, GameConfig(sim=sp), tables=tables)
        if getattr(tracker, "batched", False):
            from tracker.bouts.bout_env import BoutEnv
            from tracker.track.batch_env import BatchConfig
            if root_assist:
                raise ValueError("the root weld is a diagnostic of the legacy tracker, not of batched trackers")
            hz = float(getattr(tracker, "physics_hz", 120.0))
            from tracker.track.pd import batched_model_options
            scene = build_fighter_scene(spec, 2, batched_model_options(hz))
            bcfg = BatchConfig(assist=tracker.assist_config())
            env = BoutEnv(scene, bcfg if reward is None else replace(bcfg, reward=reward))
            return cls(library, scene, env, 0.0, tables, game, False, True)
        scene = build_fighter_scene(spec, 2, ModelOptions(physics_hz=physics_hz, root_assist=root_assist))
        env = TrackingEnv(scene, EnvConfig(terminate_on_fall=False))
        # One constant lift for every action (per-action "auto" lifts would make the reference
        # jump vertically at transitions): the lift "auto" finds on the whole library.
        lift = build_reference(src.calibration_motions()[0], scene, 0, lift="auto").penetration.lift_m
        return cls(library, scene, env, float(lift), tables, game, root_assist)

    def __post_init__(self) -> None:
        self._refs: dict[int, dict] = {}
        fm = self.scene.fighters[0]
        if fm.joint_type != "ball":
            raise ValueError("physics bouts need ball joints (ModelOptions(joint_type='ball'))")
        base = fm.qpos_adr
        self.quat_cols = np.concatenate([np.arange(3, 7)] + [np.arange(a - base, a - base + 4) for a in fm.joint_qpos])

    def action_reference(self, a: int) -> dict:
        """Reference of action ``a`` alone at the origin placement (frame 0 pelvis on the ground
        origin, fighting direction 0), lifted by ``lift_m`` (grounded frame by frame for a batched
        env); cached. Placement-invariant parts (joints, PD targets, balance features in the facing
        frame) are reused as they are."""
        c = self._refs.get(a)
        if c is None and self.batched:
            from tracker.track.batch_env import reference_tables
            mo = self.library.sequence_motion([int(a)], 0)
            ref = build_reference(mo, self.scene, 0, lift="ground")
            tab = reference_tables(ref, self.env.batch.layouts[0], self.scene, 0)
            c = {"qpos": ref.qpos, "qvel": ref.qvel, "ctrl": ref.ctrl, "ctrl_vel": ref.ctrl_vel, "sites": ref.sites,
                 "balance": np.zeros((ref.n_frames, 12)), "yaw": tab["yaw"], "tables": tab}
            self._refs[a] = c
        if c is None:
            from tracker.track.policy_net import reference_balance
            mo = self.library.sequence_motion([int(a)], 0)
            ref = build_reference(mo, self.scene, 0, lift=self.lift_m)
            try:
                bal = reference_balance(self.env, 0, ref)
            except Exception:  # noqa: BLE001 - torch missing: PD bouts do not need them
                bal = np.zeros((ref.n_frames, 12))
            c = {"qpos": ref.qpos, "qvel": ref.qvel, "ctrl": ref.ctrl, "ctrl_vel": ref.ctrl_vel, "sites": ref.sites,
                 "balance": bal, "yaw": ground_yaws(ref.qpos[:, 3:7], self.env._cache[0].lateral)}
            self._refs[a] = c
        return c

    def tables_of(self, qpos: np.ndarray) -> dict:
        """The batched env's per-frame reference tables (tracker.track.batch_env.reference_tables)
        of qpos rows of one fighter (blended frames of an online reference)."""
        from tracker.track.batch_env import reference_tables
        fm = self.scene.fighters[0]
        ref = Reference(30.0, qpos, np.zeros((len(qpos), fm.nv)), np.zeros((len(qpos), fm.n_act)),
                        np.zeros((len(qpos), fm.n_act)), self.sites_of(qpos), FootPenetration.from_depths(np.zeros(1)))
        return reference_tables(ref, self.env.batch.layouts[0], self.scene, 0)

    def sites_of(self, qpos: np.ndarray) -> np.ndarray:
        """Joint-site world positions (N, S, 3) of qpos rows of one fighter."""
        fm = self.scene.fighters[0]
        if not hasattr(self, "_scratch"):
            self._scratch = mujoco.MjData(self.scene.model)
        d = self._scratch
        out = np.zeros((len(qpos), len(fm.site_ids), 3))
        for i, q in enumerate(qpos):
            d.qpos[fm.qpos_slice] = q
            mujoco.mj_kinematics(self.scene.model, d)
            out[i] = d.site_xpos[fm.site_ids]
        return out

    def ctrl_of(self, qpos: np.ndarray) -> np.ndarray:
        """PD position targets (N, n_act) of qpos rows (one fighter): rotation vectors of the joints."""
        fm = self.scene.fighters[0]
        base = fm.qpos_adr
        q = np.stack([qpos[:, a - base:a - base + 4] for a in fm.joint_qpos], axis=1)   # (N, D, 4)
        w = np.clip(q[..., 0], -1.0, 1.0)
        v = q[..., 1:]
        sn = np.linalg.norm(v, axis=-1)
        ang = 2.0 * np.arctan2(sn, w)
        ang = np.where(ang > np.pi, ang - 2.0 * np.pi, ang)
        scale = np.where(sn > 1e-12, ang / np.maximum(sn, 1e-12), 2.0)
        rv = v * scale[..., None]
        return rv[:, fm.act_joint, fm.act_axis]


# ----------------------------------------------------------------------------------------------
# per-fighter bookkeeping


@dataclass
class ActionSegment:
    """One planned action of a fighter in the bout: from control step ``t0`` (its frame 0)."""

    t0: int            # control step of the action's frame 0
    action: int
    inst: int          # action instance id (per fighter)
    hold: bool = False  # a fallen fighter's placeholder: frame 0 held


class FighterState:
    """Per-fighter bookkeeping of a bout: the online reference buffer, planned action segments,
    falls and resets, resolved and realised strikes, reward terms."""

    def __init__(self, k: int, T: int, fm, setup: BoutSetup) -> None:
        self.k = k
        nq, nv, na, ns = fm.nq, fm.nv, fm.n_act, len(fm.site_ids)
        pen = FootPenetration.from_depths(np.zeros(1))
        self.ref = Reference(30.0, np.zeros((T, nq)), np.zeros((T, nv)), np.zeros((T, na)), np.zeros((T, na)),
                             np.zeros((T, ns, 3)), pen, "physics bout", {f"_balance_f{k}": np.zeros((T, 12))})
        self.ref.qpos[:, 3] = 1.0
        if setup.batched:       # the batched observation's tables, written with the reference
            ne = len(setup.env.batch.ee)
            self.ref.meta[f"batch_tables_{k}"] = dict(
                n=T, R=np.tile(np.eye(3), (T, 1, 1)), yaw=np.zeros(T), up=np.tile([0.0, 0.0, 1.0], (T, 1)),
                ee=np.zeros((T, ne, 3)), com=np.zeros((T, 3)), com_vel=np.zeros((T, 3)), com_feet=np.zeros((T, 3)),
                com_vel_f=np.zeros((T, 3)))
        self.fight_heading = np.zeros(T)   # reference fighting direction per step (mocap heading, rad)
        self.ref_yaw = np.zeros(T)         # reference pelvis hip-line yaw (MuJoCo, rad)
        self.segments: list[ActionSegment] = []
        self.t_dec_end = 0                 # last frame of the last planned action
        self.n_inst = 0
        self.down = False
        self.reset_at = -1
        self.resolved: dict[int, int] = {}   # instance -> strike bits resolved (planned or realised)
        self.realised: dict[int, int] = {}   # instance -> strike bits that landed physically
        self.touching = False
        self.reward = zero_reward()
        self.steps_since = 0
        self.reward_total = zero_reward()

    def segment_at(self, t: int) -> ActionSegment | None:
        for s in reversed(self.segments):
            if s.t0 <= t:
                return s
        return None

    def action_frame(self, t: int, nf: np.ndarray) -> tuple[int, int, int]:
        """(action, frame, instance) at control step t (frames clamped to the action's last)."""
        s = self.segment_at(t)
        if s is None:
            return -1, 0, -1
        f = 0 if s.hold else min(t - s.t0, int(nf[s.action]) - 1)
        return s.action, f, s.inst
