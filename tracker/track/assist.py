"""Balance assist: a bounded, reported residual wrench on each fighter's pelvis ("assisted physics").

The motion capture was performed by a person whose body, feet and floor the model reproduces only
approximately; a small external wrench on the root supplies what the model's contacts cannot
(residual force control, Yuan & Kitani 2020; games call it a pin force). It is always bounded and
always reported: with the assist on, a figure is *assisted physics (cap c mg)*, never plain physics.

The wrench is applied at the pelvis body's centre of mass (MuJoCo ``xfrc_applied``), in world axes:
a force F (N) and a torque tau (N m). The cap c bounds both, |F| <= c m g and |tau| <= c m g * 1 m
(m the fighter's mass, g = 9.81 m/s^2), by scaling the vector down to the bound (direction kept).

Modes:
- ``none``: no wrench (plain physics).
- ``fixed``: a critically damped PD toward the reference, no learning, recomputed at every physics
  substep: force F = m (w^2 e + 2 w de) on the centre of mass's error e and velocity error de (the
  height too with ``vertical``), tilt torque tau = I (w^2 e_rot + 2 w de_rot) on the pelvis's
  rotation-vector error (its horizontal part) and angular velocity error, with w = 2 pi ``freq_hz``
  and I = m * ``radius_m``^2, and a yaw torque I w_y^2 e_yaw toward the reference's facing at a
  softer ``yaw_freq_hz``.
- ``learned``: the policy's output (six numbers in units of the cap, in the facing frame), clipped to the cap.

``AssistStats`` accumulates what every evaluation and bout reports per fighter: mean and p95 of
|F|/(m g) and |tau|/(m g m), the share of control steps at the cap, and the impulse per second
(N s per simulated second, i.e. the mean |F| in N, and its torque analogue).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

G = 9.81
MODES = ("none", "fixed", "learned")


@dataclass(frozen=True)
class AssistConfig:
    """Attributes:
        mode: "none", "fixed" or "learned".
        cap: c, the bound in body weights (force) and body weights times one metre (torque).
        freq_hz: natural frequency of the fixed PD (critically damped).
        vertical: the fixed PD also holds the centre of mass's height (else horizontal force only).
        torque: the fixed PD also applies a torque toward the reference orientation.
        radius_m: the fixed PD's torque treats the body as inertia I = m * radius_m^2.
        com: the fixed PD's force acts on the centre of mass's error (else the pelvis origin's).
        yaw_torque: the fixed PD also turns the body about the vertical toward the reference's
            facing yaw (hip line), at its own, softer ``yaw_freq_hz``; the tilt part never resists
            the motion's twists.
    """

    mode: str = "none"
    cap: float = 0.5
    freq_hz: float = 2.0
    vertical: bool = True
    torque: bool = True
    radius_m: float = 0.3
    com: bool = True
    yaw_torque: bool = True
    yaw_freq_hz: float = 1.0

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"assist mode must be one of {', '.join(MODES)}, not {self.mode!r}")
        if not (np.isfinite(self.cap) and 0.0 <= self.cap <= 2.0):
            raise ValueError(f"assist cap must lie in [0, 2] body weights, not {self.cap!r}")
        if not (np.isfinite(self.freq_hz) and self.freq_hz > 0):
            raise ValueError(f"assist freq_hz must be positive, not {self.freq_hz!r}")

    @property
    def active(self) -> bool:
        return self.mode != "none" and self.cap > 0.0

    def label(self) -> str:
        """How a figure with this assist is named."""
        if not self.active:
            return "physics (no assist)"
        return f"assisted physics ({self.mode} assist, cap {self.cap:g} mg)"


def clip_to_cap(force: np.ndarray, torque: np.ndarray, cap_n: np.ndarray, cap_nm: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scale each (B, 3) force and torque down to its bound (N, N m; (B,) arrays). Returns the
    clipped force, torque and (B,) bool: the bound was reached (either vector scaled)."""
    fn = np.linalg.norm(force, axis=1)
    tn = np.linalg.norm(torque, axis=1)
    sf = np.minimum(1.0, cap_n / np.maximum(fn, 1e-12))
    st = np.minimum(1.0, cap_nm / np.maximum(tn, 1e-12))
    at_cap = (fn >= cap_n * (1.0 - 1e-9)) | (tn >= cap_nm * (1.0 - 1e-9))
    return force * sf[:, None], torque * st[:, None], at_cap & (cap_n > 0)


def rotvec_between(R_from: np.ndarray, R_to: np.ndarray) -> np.ndarray:
    """(B, 3) world rotation vectors taking orientations R_from to R_to ((B, 3, 3) each)."""
    Rd = R_to @ np.swapaxes(R_from, 1, 2)
    tr = np.clip((np.trace(Rd, axis1=1, axis2=2) - 1.0) * 0.5, -1.0, 1.0)
    ang = np.arccos(tr)
    v = np.stack([Rd[:, 2, 1] - Rd[:, 1, 2], Rd[:, 0, 2] - Rd[:, 2, 0], Rd[:, 1, 0] - Rd[:, 0, 1]], axis=1)
    s = np.sin(ang)
    small = s < 1e-6
    scale = np.where(small, 0.5, ang / (2.0 * np.where(small, 1.0, s)))
    return v * scale[:, None]


def fixed_wrench(cfg: AssistConfig, mass: np.ndarray, pos: np.ndarray, vel: np.ndarray, R: np.ndarray,
                 omega: np.ndarray, ref_pos: np.ndarray, ref_vel: np.ndarray, ref_R: np.ndarray,
                 ref_omega: np.ndarray, yaw_error: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The fixed mode's unclipped wrench (world force N, torque N m; (B, 3) each) from the pelvis
    state (position m, velocity m/s, rotation matrix, angular velocity rad/s in world axes) and the
    reference's."""
    w = 2.0 * np.pi * cfg.freq_hz
    kp, kd = w * w, 2.0 * w
    e = ref_pos - pos
    de = ref_vel - vel
    acc = kp * e + kd * de
    if not cfg.vertical:
        acc[:, 2] = 0.0
    force = mass[:, None] * acc
    if cfg.torque:
        er = rotvec_between(R, ref_R)
        torque = (mass * cfg.radius_m ** 2)[:, None] * (kp * er + kd * (ref_omega - omega))
        torque[:, 2] = 0.0
        if cfg.yaw_torque and yaw_error is not None:
            wy = 2.0 * np.pi * cfg.yaw_freq_hz
            # no damping on the yaw rate: a boxer's pelvis twists back and forth with every punch
            torque[:, 2] = mass * cfg.radius_m ** 2 * wy * wy * yaw_error
    else:
        torque = np.zeros_like(force)
    return force, torque


class AssistStats:
    """Per-fighter accumulator of the applied wrench, one row per control step."""

    def __init__(self, n_fighters: int) -> None:
        self.f: list[list[float]] = [[] for _ in range(n_fighters)]
        self.t: list[list[float]] = [[] for _ in range(n_fighters)]
        self.cap: list[list[bool]] = [[] for _ in range(n_fighters)]

    def add(self, k: int, force_mg: float, torque_mgm: float, at_cap: bool) -> None:
        self.f[k].append(float(force_mg))
        self.t[k].append(float(torque_mgm))
        self.cap[k].append(bool(at_cap))

    def extend(self, k: int, force_mg, torque_mgm, at_cap) -> None:
        self.f[k].extend(np.asarray(force_mg, float).tolist())
        self.t[k].extend(np.asarray(torque_mgm, float).tolist())
        self.cap[k].extend(np.asarray(at_cap, bool).tolist())

    def summary(self, k: int, mass_kg: float, cap: float) -> dict:
        """The reported figures of fighter k (module docstring); zeros when no step was recorded."""
        return summarise_assist(np.asarray(self.f[k]), np.asarray(self.t[k]), np.asarray(self.cap[k]), mass_kg, cap)


def summarise_assist(force_mg: np.ndarray, torque_mgm: np.ndarray, at_cap: np.ndarray, mass_kg: float,
                     cap: float) -> dict:
    """mean / p95 of |F|/mg and |tau|/(mg m), share of steps at the cap, impulse per second (N s/s
    and N m s/s) over control steps."""
    n = len(force_mg)
    if n == 0:
        return {"cap_mg": float(cap), "steps": 0, "force_mean_mg": 0.0, "force_p95_mg": 0.0, "torque_mean_mgm": 0.0,
                "torque_p95_mgm": 0.0, "at_cap_share": 0.0, "impulse_n_s_per_s": 0.0, "angular_impulse_nm_s_per_s": 0.0}
    mg = mass_kg * G
    return {"cap_mg": float(cap), "steps": int(n),
            "force_mean_mg": float(force_mg.mean()), "force_p95_mg": float(np.percentile(force_mg, 95)),
            "torque_mean_mgm": float(torque_mgm.mean()), "torque_p95_mgm": float(np.percentile(torque_mgm, 95)),
            "at_cap_share": float(np.mean(at_cap)),
            # impulse per simulated second: sum |F| dt / (n dt) = mean |F| (N)
            "impulse_n_s_per_s": float(force_mg.mean() * mg), "angular_impulse_nm_s_per_s": float(torque_mgm.mean() * mg)}
