"""Coupled world state of two avatars and the paper's per-avatar state I_A / I_B (section 5.2).

A world state holds, for each avatar i in {0, 1}: its pelvis ground position x[i], z[i] (m), its
fighting heading[i] (rad, 0 faces +Z, +X left), the library action it plays and its frame in it,
and ``resolved[i]``: bits of that action's strikes already resolved (hit or avoided), so that a
strike counts at most once.

The paper's state of avatar A about to choose is I_A = (r, theta_A, theta_B, Next(M_A), M_B, F_B):
r the pelvis ground distance, theta_A (theta_B) the wrapped angle between A's (B's) facing and the
line A->B (B->A), M_A the action A just finished (its menu is Next(M_A)), M_B and F_B the action
and frame B is at. ``perspective(world, i)`` gives it for either avatar from the one world state.
A *canonical sample* is the same information as plain arrays (sim.SI_*, sim.SF_*), with the
other's open resolved-strike bits; it determines the world up to a rigid motion of the ground.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from motion_graph.rotations import wrap_angle

from igraph_fight import sim
from igraph_fight.sim import SimTables


class PaperState(NamedTuple):
    """I = (r, theta_self, theta_other, Next(M_self), M_other, F_other) of one avatar.

    r in metres, angles in radians wrapped to [-pi, pi); m_self the action the avatar just
    finished (when it is not at a decision instant: the action it is playing); next_self its menu.
    """

    r: float
    theta_self: float
    theta_other: float
    next_self: tuple[int, ...]
    m_self: int
    m_other: int
    f_other: int


@dataclass(frozen=True)
class WorldState:
    """Both avatars of a bout at one instant (arrays of shape (2,))."""

    x: np.ndarray
    z: np.ndarray
    heading: np.ndarray
    action: np.ndarray
    frame: np.ndarray
    resolved: np.ndarray

    @classmethod
    def new(cls, x: tuple[float, float], z: tuple[float, float], heading: tuple[float, float],
            action: tuple[int, int], frame: tuple[int, int] = (0, 0)) -> "WorldState":
        """A world with nothing resolved yet (positions m, headings rad)."""
        return cls(np.asarray(x, dtype=np.float64), np.asarray(z, dtype=np.float64),
                   np.asarray(heading, dtype=np.float64), np.asarray(action, dtype=np.int64),
                   np.asarray(frame, dtype=np.int64), np.zeros(2, dtype=np.int64))

    def swapped(self) -> "WorldState":
        """The same world with the two avatars' slots exchanged."""
        return WorldState(*(np.ascontiguousarray(a[::-1]) for a in
                            (self.x, self.z, self.heading, self.action, self.frame, self.resolved)))

    def pose_array(self) -> np.ndarray:
        return np.stack([self.x, self.z, self.heading], axis=1)[None].copy()


@dataclass(frozen=True)
class EventResult:
    """What happened between two decision instants (seconds, metres, damage units).

    deciders: the avatars standing at the last frame of their action now (must choose next).
    hits[i]: hits landed by avatar i; damage[i]: damage received by i; reached[i]: strikes of i
    that touched a target (hit or avoided); defended[i]: strikes avoided by a defence of i;
    r_mean: mean pelvis distance over the event; push_m: total push-apart distance.
    """

    frames: int
    duration_s: float
    deciders: tuple[int, ...]
    hits: tuple[float, float]
    damage: tuple[float, float]
    reached: tuple[float, float]
    defended: tuple[float, float]
    r_mean: float
    push_m: float

    @property
    def interactions(self) -> float:
        """J of the event: strikes that reached plus defences that worked, both avatars."""
        return float(sum(self.reached) + sum(self.defended))


def start_action(tables: SimTables, world: WorldState, who: int, action: int) -> WorldState:
    """Avatar ``who`` starts ``action`` from its current root pose (its frame 0 is placed there)."""
    if not 0 <= action < tables.n_actions:
        raise ValueError(f"action {action} out of range (library has {tables.n_actions})")
    a = world.action.copy()
    f = world.frame.copy()
    m = world.resolved.copy()
    a[who] = action
    f[who] = 0
    m[who] = 0
    # frame 0 of every action is its start frame (path[0] = (0, 0, 0)): the root pose is kept
    return replace(world, action=a, frame=f, resolved=m)


def advance(tables: SimTables, world: WorldState) -> tuple[WorldState, EventResult]:
    """Advance both avatars to the next decision instant (see sim.advance_to_decision for the rules)."""
    pose = world.pose_array()
    act = world.action[None].copy()
    frm = world.frame[None].copy()
    mask = world.resolved[None].copy()
    st = sim.advance_worlds(tables.kernel_tuple(), pose, act, frm, mask)[0]
    nxt = WorldState(pose[0, :, 0].copy(), pose[0, :, 1].copy(), pose[0, :, 2].copy(), act[0].copy(),
                     frm[0].copy(), mask[0].copy())
    deciders = tuple(i for i in (0, 1) if nxt.frame[i] >= tables.n_frames[nxt.action[i]] - 1)
    n = int(st[sim.ST_FRAMES])
    r_now = float(np.hypot(nxt.x[1] - nxt.x[0], nxt.z[1] - nxt.z[0]))
    ev = EventResult(
        frames=n, duration_s=n / tables.fps, deciders=deciders,
        hits=(float(st[sim.ST_HITS0]), float(st[sim.ST_HITS1])),
        damage=(float(st[sim.ST_DMG0]), float(st[sim.ST_DMG1])),
        reached=(float(st[sim.ST_REACH0]), float(st[sim.ST_REACH1])),
        defended=(float(st[sim.ST_DEF0]), float(st[sim.ST_DEF1])),
        r_mean=float(st[sim.ST_SUMR] / n) if n else r_now, push_m=float(st[sim.ST_PUSH]))
    return nxt, ev


def relative(world: WorldState, who: int) -> tuple[float, float, float]:
    """(r, theta_self, theta_other) of avatar ``who`` (m, rad wrapped to [-pi, pi))."""
    o = 1 - who
    dx = world.x[o] - world.x[who]
    dz = world.z[o] - world.z[who]
    b = np.arctan2(dx, dz)
    return (float(np.hypot(dx, dz)), float(wrap_angle(b - world.heading[who])),
            float(wrap_angle(b + np.pi - world.heading[o])))


def perspective(tables: SimTables, world: WorldState, who: int) -> PaperState:
    """The paper's state I of avatar ``who`` (0 or 1) from the one coupled world state."""
    o = 1 - who
    r, ts, to = relative(world, who)
    m = int(world.action[who])
    return PaperState(r, ts, to, tuple(int(b) for b in tables.menu(m)), m, int(world.action[o]),
                      int(world.frame[o]))


def both_perspectives(tables: SimTables, world: WorldState) -> tuple[PaperState, PaperState]:
    """(I_A, I_B) of the world: avatar 0's and avatar 1's states."""
    return perspective(tables, world, 0), perspective(tables, world, 1)


def worlds_to_samples(tables: SimTables, pose: np.ndarray, act: np.ndarray, frm: np.ndarray, mask: np.ndarray,
                      decider: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World arrays (pose (N, 2, 3) root x, z, heading; act, frm, mask (N, 2)) -> canonical samples
    (ints (N, N_SI), floats (N, N_SF)) from the perspective of decider[n] (0 or 1)."""
    n = np.arange(len(pose))
    d = np.asarray(decider, dtype=np.int64)
    o = 1 - d
    dx = pose[n, o, 0] - pose[n, d, 0]
    dz = pose[n, o, 1] - pose[n, d, 1]
    b = np.arctan2(dx, dz)
    sf = np.stack([np.hypot(dx, dz), wrap_angle(b - pose[n, d, 2]), wrap_angle(b + np.pi - pose[n, o, 2])], axis=1)
    ao, fo = act[n, o].astype(np.int64), frm[n, o].astype(np.int64)
    si = np.stack([act[n, d], ao, fo, open_mask(tables, ao, fo, mask[n, o])], axis=1).astype(np.int64)
    return si, sf


def samples_to_worlds(tables: SimTables, si: np.ndarray, sf: np.ndarray):
    """Canonical samples -> world arrays (pose (N, 2, 3), act, frm, mask (N, 2)): the decider in
    slot 0 at the origin facing +Z at the last frame of M_self, the other in slot 1."""
    si = np.atleast_2d(si)
    sf = np.atleast_2d(sf)
    N = len(si)
    pose = np.zeros((N, 2, 3))
    r, ts, to = sf[:, sim.SF_R], sf[:, sim.SF_TH_SELF], sf[:, sim.SF_TH_OTHER]
    pose[:, 1, 0] = r * np.sin(ts)
    pose[:, 1, 1] = r * np.cos(ts)
    pose[:, 1, 2] = wrap_angle(ts + np.pi - to)
    act = np.stack([si[:, sim.SI_MSELF], si[:, sim.SI_MOTHER]], axis=1).astype(np.int64)
    frm = np.stack([tables.n_frames[si[:, sim.SI_MSELF]] - 1, si[:, sim.SI_FOTHER]], axis=1).astype(np.int64)
    mask = np.zeros((N, 2), dtype=np.int64)
    mask[:, 1] = si[:, sim.SI_MASK]
    return pose, act, frm, mask


def open_mask(tables: SimTables, a: np.ndarray, f: np.ndarray, m: np.ndarray) -> np.ndarray:
    """Keep the resolved-strike bits of action a whose window has frames left after frame f."""
    a, f, m = np.asarray(a), np.asarray(f), np.asarray(m, dtype=np.int64)
    out = np.zeros_like(m)
    so = tables.strike_offsets
    for j in range(int(np.diff(so).max()) if len(so) > 1 else 0):
        k = so[a] + j
        ok = k < so[a + 1]
        bit = np.int64(1) << np.int64(j)
        keep = ok & ((m & bit) != 0) & (f + 1 < tables.strike_w1[np.minimum(k, len(tables.strike_w1) - 1)])
        out |= np.where(keep, bit, 0)
    return out


def to_sample(tables: SimTables, world: WorldState, who: int) -> tuple[np.ndarray, np.ndarray]:
    """Canonical sample (ints (N_SI,), floats (N_SF,)) of the world seen by decider ``who``."""
    si, sf = worlds_to_samples(tables, world.pose_array(), world.action[None], world.frame[None],
                               world.resolved[None], np.array([who]))
    return si[0], sf[0]


def from_sample(tables: SimTables, si: np.ndarray, sf: np.ndarray) -> WorldState:
    """World of a canonical sample: the decider in slot 0 at the origin facing +Z, at the last
    frame of M_self; the other in slot 1."""
    pose, act, frm, mask = samples_to_worlds(tables, np.asarray(si, dtype=np.int64)[None],
                                             np.asarray(sf, dtype=np.float64)[None])
    return WorldState(pose[0, :, 0].copy(), pose[0, :, 1].copy(), pose[0, :, 2].copy(), act[0].copy(),
                      frm[0].copy(), mask[0].copy())


def group_key(tables: SimTables, si: np.ndarray, f0: int) -> np.ndarray:
    """Clustering-group key columns (N, 4): Next-set id of M_self, M_other, F_other // f0 and the
    other's open resolved-strike bits. The paper's distance is infinite between samples whose
    Next-set, M_other or bits differ or whose F_other differ by f0 frames or more."""
    si = np.atleast_2d(si)
    return np.stack([tables.nextset[si[:, sim.SI_MSELF]], si[:, sim.SI_MOTHER], si[:, sim.SI_FOTHER] // f0,
                     si[:, sim.SI_MASK]], axis=1)

