"""PD baseline: track the reference pose with MuJoCo PD actuators, no learning.

Targets are the reference joint rotations one control step ahead; gains are the model's segment
table (tracker.body.humanoid.KP) scaled by ``kp_scale``, with kd = ``kd_ratio`` * kp; the damping pulls
towards zero joint velocity (``velocity_targets=False``: measured better for balance than damping
towards the reference velocity, 1.55 s vs 1.25 s mean time to fall on 40 tuning walks). Damping is implicit in MuJoCo's implicitfast integrator,
so high gains stay stable at 240 Hz (the "stable PD" property). Defaults are the best measured
settings (docs/tracker.md).
"""
from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from tracker.body.humanoid import KP, TORQUE
from tracker.track.env import ARM_CLASSES


@dataclass
class PDController:
    """Attributes:
        kp_scale: multiplies the segment stiffness table.
        kd_ratio: kd = kd_ratio * kp (seconds).
        torque_scale: multiplies the segment torque-limit table.
        velocity_targets: damp towards the reference joint velocity instead of zero.
        arm_velocity_targets: the same for the arm actuators only (tracker.track.env.ARM_CLASSES).
        balance: virtual-force balance gains (tracker.track.vforce.BalanceGains: five numbers or a dict)
            turned on in the env at reset; None (default, the plain PD baseline): off.
    """

    kp_scale: float = 1.0
    kd_ratio: float = 0.2
    torque_scale: float = 1.0
    velocity_targets: bool = False
    name: str = "pd"
    balance: tuple | dict | None = None
    arm_velocity_targets: bool = False

    @classmethod
    def from_ckpt(cls, ckpt: str | None) -> "PDController":
        """Default gains, or gains from a JSON file {"kp_scale": .., "kd_ratio": .., "torque_scale": ..}."""
        if not ckpt:
            return cls()
        data = json.loads(Path(ckpt).read_text())
        kw = {k: float(v) for k, v in data.items() if k in ("kp_scale", "kd_ratio", "torque_scale")}
        for k in ("velocity_targets", "arm_velocity_targets"):
            if k in data:
                kw[k] = bool(data[k])
        if data.get("balance"):
            kw["balance"] = data["balance"]
            kw["name"] = "balance"
        return cls(**kw)

    @classmethod
    def balanced(cls, gains=None) -> "PDController":
        """PD plus the virtual-force balance layer (default gains unless given)."""
        from tracker.track.vforce import BalanceGains
        g = BalanceGains.parse(gains) if gains is not None else BalanceGains()
        return cls(balance=g.as_tuple(), name="balance")

    def to_json(self) -> str:
        return json.dumps({k: v for k, v in asdict(self).items() if k != "name"})

    def gains(self, env) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        out = []
        for f in env.scene.fighters:
            s2 = (f.spec.height_m / 1.7) ** 2
            kp = np.array([KP.get(c, KP["other"]) for c in f.act_class]) * self.kp_scale * s2
            tq = np.array([TORQUE.get(c, TORQUE["other"]) for c in f.act_class]) * self.torque_scale * s2
            out.append((kp, kp * self.kd_ratio, tq))
        return out

    def reset(self, env) -> None:
        env.velocity_targets = self.velocity_targets
        env.arm_velocity_targets = self.arm_velocity_targets
        for k, (kp, kd, tq) in enumerate(self.gains(env)):
            env.set_gains(kp, kd, k)
            env.set_torque_limits(tq, k)
        env.set_balance(self.balance)

    def act(self, env, obs: np.ndarray) -> np.ndarray:
        if env.config.residual_actions:
            return np.zeros(env.n_act)
        return env.reference_targets()


@dataclass
class PDTracker:
    """PD tracking on the batched environment (tracker.track.batch_env): the reference's joint
    targets one control step ahead, no residuals; the env's assist mode decides any wrench.

    Attributes:
        kp_scale, kd_ratio, torque_scale: as PDController's.
        class_scale: extra stiffness and torque factors per segment class (tracker.body.humanoid.KP
            keys), e.g. (("foot", 2.0),): the stance gains a body needs to stand still.
        arm_velocity_targets: the arm actuators (tracker.track.env.ARM_CLASSES) damp towards the
            reference joint velocity, the others towards zero: a punch is not braked by its own
            damping (kd = 0.2 s kp lags a joint moving at v rad/s by about 0.2 v rad).
    """

    kp_scale: float = 1.0
    kd_ratio: float = 0.2
    torque_scale: float = 1.0
    class_scale: tuple = ()
    arm_velocity_targets: bool = False
    name: str = "pd"
    assist_mode: str = "none"
    assist_cap: float = 0.0

    def gains(self, fighter) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kp, kd, torque limit) per actuator of a BodyMap."""
        s2 = (fighter.spec.height_m / 1.7) ** 2
        extra = dict(self.class_scale)
        kp = np.array([KP.get(c, KP["other"]) * extra.get(c, 1.0) for c in fighter.act_class]) * self.kp_scale * s2
        tq = np.array([TORQUE.get(c, TORQUE["other"]) * extra.get(c, 1.0) for c in fighter.act_class]) \
            * self.torque_scale * s2
        return kp, kp * self.kd_ratio, tq

    batched = True

    def reset(self, env) -> None:
        for k, f in enumerate(env.scene.fighters):
            kp, kd, tq = self.gains(f)
            env.set_gains(kp, kd, k)
            env.set_torque_limits(tq, k)
            arm = np.array([c in ARM_CLASSES for c in f.act_class], dtype=np.float64)
            env.set_velocity_targets(arm if self.arm_velocity_targets else np.zeros_like(arm), k)

    def act(self, env, obs: np.ndarray) -> tuple[np.ndarray, None]:
        return env.reference_targets(), None

    def assist_config(self):
        """The assist this controller runs with: none, or the env's fixed PD at its cap."""
        from tracker.track.assist import AssistConfig
        return AssistConfig(self.assist_mode, self.assist_cap)

    def describe(self) -> str:
        extra = ", ".join([f"{c} x{v:g}" for c, v in self.class_scale]
                          + (["arm velocity targets"] if self.arm_velocity_targets else []))
        a = f", fixed assist cap {self.assist_cap:g} mg" if self.assist_mode == "fixed" else ""
        return f"PD tracking (kp x{self.kp_scale:g}{', ' + extra if extra else ''}){a}"


#: the stance gains of the batched trackers (factors on the KP and TORQUE tables): ankles and toes
#: stiff enough to carry the body (a quiet stance held 10 s with no assist, where the table's gains
#: fall in 1.6 s: tests/test_batch_env.py) with the protocol walks under plain PD no worse than at
#: the table's gains (docs/results.md)
STANCE_GAINS = (("foot", 4.0), ("toe", 4.0))


def batched_model_options(physics_hz: float = 120.0):
    """The humanoid's options for the batched trackers: 120 Hz physics and the joint armature
    (0.05 kg m^2) that keeps the stance gains stable at that rate."""
    from tracker.body.humanoid import ModelOptions
    return ModelOptions(physics_hz=physics_hz, armature=0.05)
