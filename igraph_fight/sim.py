"""Coupled kinematic simulator of two fighting avatars: numba kernels on plain arrays.

World model (metres, radians, library frames at ``fps``): each avatar plays one library action
from a *start transform* S = (x, z, heading) on the ground plane; at its frame f its pelvis ground
point and fighting direction are S o path[f] and every joint is S o positions[f]. Heading 0 faces
+Z, +X is left; R(h) maps a local (x, z) to (c x + s z, -s x + c z).

One *event* advances both avatars frame by frame until one of them stands at the last frame of
its action (a decision instant). On every frame:

* the bodies are kept apart: when the pelvis ground distance is below ``min_distance_m`` both
  avatars are pushed apart along the joining line by half the overlap each (their start
  transforms move, so the push persists);
* hits are judged both ways: a strike of the attacker's action whose window [w0, w1) holds the
  attacker's frame, and that has not been resolved yet, resolves the first time its effector (a
  sphere of ``contact_radius_m``) touches a target sphere of the other (head centre 0.10 m,
  chest and belly 0.15 m: ``target_radius_m``). It is
  *avoided* (a working defence of the other) when the other's action is a defence whose window
  holds the other's frame at that instant, else it is a *hit* and deals the damage of its kind.
  Each strike resolves at most once (a bit in the attacker's ``mask``). For the sampler's
  interaction count J the event also counts strikes whose effector came within
  ``reach_margin_m`` of a target ("attacks in the reaching distance"), once per strike and event.
* the guard (optional, ``SimParams.guard_radius_m`` > 0; off by default): from ``guard_lead_s``
  before a strike's window to its end, the effector's path (the segment since the last frame,
  sampled at three points) is tested against the other's forearms (capsules from elbow to fist of
  ``guard_radius_m``). A strike whose fist meets a forearm before it touches a target resolves as
  *blocked*: a working defence of the other (counted as avoided), not a hit. Without it a punch
  passes through the arms that guard the head, which a physical opponent's arms do not allow
  (research/notes/BOUTS.md). An approximation: the forearm is posed
  at the current frame only, and the fist's path between frames is a straight line.

Avatars are not interrupted by hits: the library has no hit-reaction mocap, so an interruption
could only cut an action short and start another clip from a mid-motion pose. This is a design
choice (docs/protocols.md); the event features record every hit so rewards still see them.

The kernels take the library tables as one tuple (``SimTables.kernel_tuple``) so they compile once
and are cached on disk. Batches run on ``workers`` Python threads over nogil kernels, each thread
writing its own rows (numba's parallel=True compiled about three times slower and gave no more
speed here); everything is deterministic: no random numbers, no reductions across threads.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

import motion_graph.rotations
from igraph_fight.kernel_cache import drop_stale_caches
from motion_graph.rotations import wrap_angle_nb

drop_stale_caches(__file__, [motion_graph.rotations])

# Per-event statistics, avatar slots 0 and 1 (ST_* index into the stats vector).
ST_FRAMES = 0     # frames advanced
ST_HITS0 = 1      # hits landed by avatar 0
ST_HITS1 = 2
ST_DMG0 = 3       # damage received by avatar 0
ST_DMG1 = 4
ST_REACH0 = 5     # strikes of avatar 0 that reached a target (hit or avoided)
ST_REACH1 = 6
ST_DEF0 = 7       # strikes avoided by a defence of avatar 0 (working defences)
ST_DEF1 = 8
ST_SUMR = 9       # sum over advanced frames of the pelvis distance (m)
ST_PUSH = 10      # total push-apart distance (m)
ST_NEAR0 = 11     # strikes of avatar 0 whose effector came within reach_margin_m of a target
ST_NEAR1 = 12
N_STAT = 13

# Edge features from a canonical sample's decider (slot 0) perspective (FT_* columns).
FT_FRAMES = 0
FT_R = 1          # distance at the next decision (m)
FT_R_MEAN = 2     # mean distance over the event (m)
FT_TH_SELF = 3    # angle between slot 0's facing and the line to slot 1 at the next decision (rad)
FT_TH_OTHER = 4
FT_DMG_GIVEN = 5
FT_DMG_RECEIVED = 6
FT_DEF_SELF = 7
FT_DEF_OTHER = 8
FT_HITS_SELF = 9
FT_HITS_OTHER = 10
FT_REACH_SELF = 11
FT_REACH_OTHER = 12
FT_PUSH = 13
FT_NEAR_SELF = 14
FT_NEAR_OTHER = 15
N_FEAT = 16

# Canonical sample integer columns (SI_*) and float columns (SF_*).
SI_MSELF = 0      # action the decider just finished (its menu is Next(M_self))
SI_MOTHER = 1     # action the other avatar is playing
SI_FOTHER = 2     # the other's frame in it
SI_MASK = 3       # the other's strikes already resolved whose window is still open (bits)
N_SI = 4
SF_R = 0
SF_TH_SELF = 1
SF_TH_OTHER = 2
N_SF = 3

TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class SimParams:
    """Simulator options.

    contact_radius_m: radius of the striking effector (fist or foot), metres.
    target_radius_m: radius of each target sphere around its point (head centre, chest and belly
        joints), metres; an effector touches a target when the centres are closer than the sum.
    min_distance_m: pelvis ground distance under which the bodies are pushed apart.
    damage: damage per hit by attack kind (name in motion_graph.KINDS -> value); kinds not
        listed deal ``default_damage``.
    max_event_frames: safety bound on one event's length.
    guard_radius_m: radius of the forearm capsules (elbow to fist) that block strikes; 0 (the
        default) for no guard, the model of the graphs built before it.
    guard_lead_s: how long before a strike's window its fist may already be blocked (seconds).
    """

    contact_radius_m: float = 0.05
    target_radius_m: dict = field(default_factory=lambda: {"head": 0.10, "chest": 0.15, "belly": 0.15})
    reach_margin_m: float = 0.3
    min_distance_m: float = 0.4
    default_damage: float = 1.0
    damage: dict = field(default_factory=dict)
    max_event_frames: int = 100_000
    guard_radius_m: float = 0.0
    guard_lead_s: float = 0.2

    def __post_init__(self) -> None:
        if self.guard_radius_m < 0 or self.guard_lead_s < 0:
            raise ValueError(f"guard_radius_m and guard_lead_s must be >= 0, not {self.guard_radius_m} and "
                             f"{self.guard_lead_s}")

    def to_json(self) -> dict:
        d = {"contact_radius_m": self.contact_radius_m, "target_radius_m": dict(sorted(self.target_radius_m.items())),
             "reach_margin_m": self.reach_margin_m,
             "min_distance_m": self.min_distance_m,
             "default_damage": self.default_damage, "damage": dict(sorted(self.damage.items())),
             "max_event_frames": self.max_event_frames}
        if self.guard_radius_m > 0:  # graphs without a guard keep the header they always had
            d["guard_radius_m"] = self.guard_radius_m
            d["guard_lead_s"] = self.guard_lead_s
        return d


@dataclass
class SimTables:
    """Per-frame arrays precomputed once from an ActionLibrary (all in each action's frame).

    n_frames (A,) frames per action; frame_offsets (A+1,); path (F, 3) pelvis ground x, z (m) and
    fighting heading (rad); eff (F, E, 3) effector joints used by strikes; tgt (F, T, 3) target
    points (head centre, chest, belly); arms (F, 4, 3) left elbow, left fist, right elbow, right
    fist (the guard's forearms); strike tables (S,) with strike_eff an index into eff;
    defence windows (A,); kinds (A,); next_offsets/next_ids (menus); nextset (A,) id of the
    action's Next-set (actions with the same Next(a) share it); fps; params.
    """

    n_frames: np.ndarray
    frame_offsets: np.ndarray
    path: np.ndarray
    eff: np.ndarray
    tgt: np.ndarray
    strike_offsets: np.ndarray
    strike_eff: np.ndarray
    strike_w0: np.ndarray
    strike_w1: np.ndarray
    strike_damage: np.ndarray
    defence_w0: np.ndarray
    defence_w1: np.ndarray
    kinds: np.ndarray
    next_offsets: np.ndarray
    next_ids: np.ndarray
    nextset: np.ndarray
    fps: float
    params: SimParams
    target_names: tuple = ()
    arms: np.ndarray | None = None

    @classmethod
    def from_library(cls, lib, params: SimParams = SimParams()) -> "SimTables":
        """Precompute the simulator tables of ``lib`` (a motion_graph.ActionLibrary)."""
        from motion_graph.classify import KINDS

        P = np.asarray(lib.positions, dtype=np.float64)
        parts = lib.parts
        joints = sorted(set(int(j) for j in np.asarray(lib.strike_joint).tolist()))
        jmap = {j: i for i, j in enumerate(joints)}
        eff = np.ascontiguousarray(P[:, joints] if joints else np.zeros((len(P), 1, 3)))
        tg, names = [], []
        if "head" in parts:
            head = P[:, parts["head"]]
            if "head_top" in parts:
                head = 0.5 * (head + P[:, parts["head_top"]])
            tg.append(head)
            names.append("head")
        for name in ("chest", "belly"):
            if name in parts:
                tg.append(P[:, parts[name]])
                names.append(name)
        if not tg:
            raise ValueError("the library's skeleton has no head/chest/belly part to hit")
        tgt = np.ascontiguousarray(np.stack(tg, axis=1))
        arm_parts = ("l_elbow", "l_fist", "r_elbow", "r_fist")
        if params.guard_radius_m > 0 and any(n not in parts for n in arm_parts):
            missing = [n for n in arm_parts if n not in parts]
            raise ValueError(f"a guard needs the forearms, and the library's skeleton has no {', '.join(missing)}")
        arms = np.ascontiguousarray(P[:, [parts[n] for n in arm_parts]] if all(n in parts for n in arm_parts)
                                    else np.zeros((len(P), 4, 3)))
        kinds = np.asarray(lib.strike_kind, dtype=np.int64)
        dmg = np.array([params.damage.get(KINDS[k], params.default_damage) for k in kinds], dtype=np.float64)
        # Next-set ids: equal menus share an id (first action with that menu order).
        seen: dict[tuple, int] = {}
        nextset = np.empty(lib.n_actions, dtype=np.int64)
        for a in range(lib.n_actions):
            key = tuple(sorted(int(b) for b in lib.next(a)))
            nextset[a] = seen.setdefault(key, len(seen))
        return cls(
            n_frames=np.asarray(np.diff(lib.frame_offsets), dtype=np.int64),
            frame_offsets=np.asarray(lib.frame_offsets, dtype=np.int64),
            path=np.ascontiguousarray(lib.path, dtype=np.float64),
            eff=eff, tgt=tgt,
            strike_offsets=np.asarray(lib.strike_offsets, dtype=np.int64),
            strike_eff=np.array([jmap[int(j)] for j in lib.strike_joint], dtype=np.int64),
            strike_w0=np.asarray(lib.strike_w0, dtype=np.int64),
            strike_w1=np.asarray(lib.strike_w1, dtype=np.int64),
            strike_damage=dmg,
            defence_w0=np.asarray(lib.defence_w0, dtype=np.int64),
            defence_w1=np.asarray(lib.defence_w1, dtype=np.int64),
            kinds=np.asarray(lib.kinds, dtype=np.int64),
            next_offsets=np.asarray(lib.next_offsets, dtype=np.int64),
            next_ids=np.asarray(lib.next_ids, dtype=np.int64),
            nextset=nextset, fps=float(lib.fps), params=params, target_names=tuple(names), arms=arms,
        )

    @property
    def n_actions(self) -> int:
        return len(self.n_frames)

    def menu(self, a: int) -> np.ndarray:
        """Next(a): the actions the avatar may start after finishing a."""
        return self.next_ids[self.next_offsets[a]:self.next_offsets[a + 1]]

    def contact_radius2(self) -> np.ndarray:
        """(n_targets,) squared contact distance per target (effector + target radius), m^2."""
        p = self.params
        return np.array([(p.contact_radius_m + float(p.target_radius_m.get(n, 0.0))) ** 2
                         for n in self.target_names], dtype=np.float64)

    def kernel_tuple(self) -> tuple:
        """The tables as the tuple every kernel takes (unpacked at the top of ``advance_to_decision``); the
        guard's last three: arms, squared block distance (0: no guard), lead (frames)."""
        p = self.params
        arms = self.arms if self.arms is not None else np.zeros((len(self.path), 4, 3))
        guard2 = (p.contact_radius_m + p.guard_radius_m) ** 2 if p.guard_radius_m > 0 else 0.0
        lead = int(round(p.guard_lead_s * self.fps)) if p.guard_radius_m > 0 else 0
        return (self.n_frames, self.frame_offsets, self.path, self.eff, self.tgt, self.strike_offsets,
                self.strike_eff, self.strike_w0, self.strike_w1, self.strike_damage, self.defence_w0,
                self.defence_w1, self.contact_radius2(), float(p.min_distance_m),
                int(p.max_event_frames), float(max(p.reach_margin_m, float(np.sqrt(self.contact_radius2().max())))) ** 2,
                arms, float(guard2), lead)


# ---------------------------------------------------------------------------------------------
# Kernels
# ---------------------------------------------------------------------------------------------
@njit(cache=True, inline="always")
def _seg_point_d2(px, py, pz, ax, ay, az, bx, by, bz):
    """Squared distance from point p to segment ab (m^2)."""
    ux = bx - ax
    uy = by - ay
    uz = bz - az
    wx = px - ax
    wy = py - ay
    wz = pz - az
    uu = ux * ux + uy * uy + uz * uz
    t = 0.0
    if uu > 1e-12:
        t = min(1.0, max(0.0, (wx * ux + wy * uy + wz * uz) / uu))
    dx = wx - t * ux
    dy = wy - t * uy
    dz = wz - t * uz
    return dx * dx + dy * dy + dz * dz


@njit(cache=True, inline="always")
def strike_blocked(arms, guard2, e0, e1, c, s, sx, sz, go, co, so, ox, oz):
    """Whether the effector's path from e0 to e1 (action-frame points of the attacker, placed by
    cos/sin c, s and offset sx, sz) meets a forearm of the other's frame go (placed by co, so, ox,
    oz) within sqrt(guard2); the path is sampled at a third, two thirds and its end."""
    for j in range(1, 4):
        w = j / 3.0
        lx = e0[0] + w * (e1[0] - e0[0])
        ly = e0[1] + w * (e1[1] - e0[1])
        lz = e0[2] + w * (e1[2] - e0[2])
        ex = c * lx + s * lz + sx
        ez = -s * lx + c * lz + sz
        for side in range(2):
            a = arms[go, 2 * side]
            b = arms[go, 2 * side + 1]
            d2 = _seg_point_d2(ex, ly, ez, co * a[0] + so * a[2] + ox, a[1], -so * a[0] + co * a[2] + oz,
                               co * b[0] + so * b[2] + ox, b[1], -so * b[0] + co * b[2] + oz)
            if d2 < guard2:
                return True
    return False


@njit(cache=True)
def advance_to_decision(T, S, act, frm, mask, stats):
    """Advance both avatars to the next decision instant (in place).

    S (2, 3) start transforms (x, z, heading), act (2,), frm (2,), mask (2,) int64.
    stats (N_STAT,) accumulates. Stops at once when an avatar already stands at its last frame.
    """
    (n_frames, offs, path, eff, tgt, s_off, s_eff, s_w0, s_w1, s_dmg, d_w0, d_w1, rad2, dmin, max_frames, near2,
     arms, guard2, lead) = T
    nt = tgt.shape[1]
    near0 = np.int64(0)  # strikes already counted as near in this event (per avatar)
    near1 = np.int64(0)
    px = np.empty(2)
    pz = np.empty(2)
    c = np.empty(2)
    s = np.empty(2)
    steps = 0
    for i in range(2):  # headings do not change within an event (the push moves x, z only)
        c[i] = np.cos(S[i, 2])
        s[i] = np.sin(S[i, 2])
    while frm[0] < n_frames[act[0]] - 1 and frm[1] < n_frames[act[1]] - 1 and steps < max_frames:
        steps += 1
        for i in range(2):
            frm[i] += 1
            g = offs[act[i]] + frm[i]
            lx = path[g, 0]
            lz = path[g, 1]
            px[i] = c[i] * lx + s[i] * lz + S[i, 0]
            pz[i] = -s[i] * lx + c[i] * lz + S[i, 1]
        dx = px[1] - px[0]
        dz = pz[1] - pz[0]
        d = np.sqrt(dx * dx + dz * dz)
        if d < dmin:
            if d > 1e-9:
                ux = dx / d
                uz = dz / d
            else:  # coincident: push along avatar 0's facing
                ux = np.sin(S[0, 2] + path[offs[act[0]] + frm[0], 2])
                uz = np.cos(S[0, 2] + path[offs[act[0]] + frm[0], 2])
            h = 0.5 * (dmin - d)
            S[0, 0] -= ux * h
            S[0, 1] -= uz * h
            S[1, 0] += ux * h
            S[1, 1] += uz * h
            stats[ST_PUSH] += 2.0 * h
            d = dmin
        stats[ST_SUMR] += d
        # hits, both ways, on the same instant
        for i in range(2):
            o = 1 - i
            a = act[i]
            f = frm[i]
            nearm = near0 if i == 0 else near1
            for k in range(s_off[a], s_off[a + 1]):
                bit = np.int64(1) << np.int64(k - s_off[a])
                if f < s_w0[k] - lead or f >= s_w1[k]:
                    continue
                resolved = (mask[i] & bit) != 0
                e = eff[offs[a] + f, s_eff[k]]
                go = offs[act[o]] + frm[o]
                if guard2 > 0.0 and not resolved:
                    e0 = eff[offs[a] + f - 1, s_eff[k]] if f > 0 else e
                    if strike_blocked(arms, guard2, e0, e, c[i], s[i], S[i, 0], S[i, 1], go, c[o], s[o], S[o, 0], S[o, 1]):
                        mask[i] |= bit     # the fist meets a forearm first: a working defence of the other
                        resolved = True
                        stats[ST_REACH0 + i] += 1.0
                        stats[ST_DEF0 + o] += 1.0
                if f < s_w0[k]:
                    continue              # (the guard's lead: only blocks before the window)
                if resolved and (nearm & bit) != 0:
                    continue
                ex = c[i] * e[0] + s[i] * e[2] + S[i, 0]
                ey = e[1]
                ez = -s[i] * e[0] + c[i] * e[2] + S[i, 1]
                dbest = np.inf
                touch = False
                for t in range(nt):
                    q = tgt[go, t]
                    qx = c[o] * q[0] + s[o] * q[2] + S[o, 0]
                    qz = -s[o] * q[0] + c[o] * q[2] + S[o, 1]
                    ddx = ex - qx
                    ddy = ey - q[1]
                    ddz = ez - qz
                    dd = ddx * ddx + ddy * ddy + ddz * ddz
                    if dd < dbest:
                        dbest = dd
                    if dd < rad2[t]:
                        touch = True
                if dbest < near2 and (nearm & bit) == 0:
                    nearm |= bit
                    stats[ST_NEAR0 + i] += 1.0
                if touch and not resolved:
                    mask[i] |= bit
                    stats[ST_REACH0 + i] += 1.0
                    ao = act[o]
                    if d_w0[ao] >= 0 and d_w0[ao] <= frm[o] and frm[o] < d_w1[ao]:
                        stats[ST_DEF0 + o] += 1.0
                    else:
                        stats[ST_HITS0 + i] += 1.0
                        stats[ST_DMG0 + o] += s_dmg[k]
            if i == 0:
                near0 = nearm
            else:
                near1 = nearm
    stats[ST_FRAMES] += steps


@njit(cache=True, inline="always")
def root_pose(T, S, act, frm, i):
    """Current pelvis ground pose (x, z, heading) of avatar i."""
    offs = T[1]
    path = T[2]
    g = offs[act[i]] + frm[i]
    c = np.cos(S[i, 2])
    s = np.sin(S[i, 2])
    lx = path[g, 0]
    lz = path[g, 1]
    return c * lx + s * lz + S[i, 0], -s * lx + c * lz + S[i, 1], S[i, 2] + path[g, 2]


@njit(cache=True, inline="always")
def start_from_root(T, a, f, x, z, h):
    """Start transform that puts action a's frame f at root pose (x, z, h)."""
    offs = T[1]
    path = T[2]
    g = offs[a] + f
    sh = h - path[g, 2]
    c = np.cos(sh)
    s = np.sin(sh)
    return x - (c * path[g, 0] + s * path[g, 1]), z - (-s * path[g, 0] + c * path[g, 1]), sh


@njit(cache=True, inline="always")
def relative_pose(x0, z0, h0, x1, z1, h1):
    """(r, theta_self, theta_other) of avatar 0 with respect to avatar 1 (rad, wrapped)."""
    dx = x1 - x0
    dz = z1 - z0
    r = np.sqrt(dx * dx + dz * dz)
    b01 = np.arctan2(dx, dz)
    return r, wrap_angle_nb(b01 - h0), wrap_angle_nb(b01 + np.pi - h1)


@njit(cache=True, inline="always")
def open_strike_mask(T, a, f, m):
    """Keep the bits of action a's strikes whose window has frames left after frame f."""
    s_off = T[5]
    s_w1 = T[8]
    out = np.int64(0)
    for k in range(s_off[a], s_off[a + 1]):
        bit = np.int64(1) << np.int64(k - s_off[a])
        if (m & bit) != 0 and f + 1 < s_w1[k]:
            out |= bit
    return out


@njit(cache=True, inline="always")
def sample_world(T, si, sf, action, S, act, frm, mask):
    """World of a canonical sample whose decider (slot 0, at the origin facing +Z) starts
    ``action``; slot 1 is the other avatar in its action at its frame."""
    S[0, 0] = 0.0
    S[0, 1] = 0.0
    S[0, 2] = 0.0
    act[0] = action
    frm[0] = 0
    mask[0] = 0
    r = sf[SF_R]
    ts = sf[SF_TH_SELF]
    x1 = r * np.sin(ts)
    z1 = r * np.cos(ts)
    h1 = wrap_angle_nb(ts + np.pi - sf[SF_TH_OTHER])
    b = si[SI_MOTHER]
    f = si[SI_FOTHER]
    sx, sz, sh = start_from_root(T, b, f, x1, z1, h1)
    S[1, 0] = sx
    S[1, 1] = sz
    S[1, 2] = sh
    act[1] = b
    frm[1] = f
    mask[1] = si[SI_MASK]


@njit(cache=True, inline="always")
def _canonical(T, S, act, frm, mask, d, out_i, out_f):
    """Canonical sample of the world from avatar d's perspective (d about to decide)."""
    o = 1 - d
    x0, z0, h0 = root_pose(T, S, act, frm, d)
    x1, z1, h1 = root_pose(T, S, act, frm, o)
    r, ts, to = relative_pose(x0, z0, h0, x1, z1, h1)
    out_i[SI_MSELF] = act[d]
    out_i[SI_MOTHER] = act[o]
    out_i[SI_FOTHER] = frm[o]
    out_i[SI_MASK] = open_strike_mask(T, act[o], frm[o], mask[o])
    out_f[SF_R] = r
    out_f[SF_TH_SELF] = ts
    out_f[SF_TH_OTHER] = to


@njit(cache=True, inline="always")
def _next_decider(T, act, frm):
    """Who decides now: the avatar at its last frame; when both are, the one that did not just
    start (slot 1), then slot 0 right after it with a zero-length event. -1 if none."""
    n_frames = T[0]
    if frm[1] >= n_frames[act[1]] - 1:
        return 1
    if frm[0] >= n_frames[act[0]] - 1:
        return 0
    return -1


@njit(cache=True)
def expand_one(T, si, sf, action, ci, cf, feat, S, act, frm, mask, stats):
    """Simulate a canonical sample's decider starting ``action`` up to the next decision.
    Writes the child's canonical sample (ci, cf) and the event features (slot-0 perspective);
    returns the next decider (0: the same avatar, 1: the other)."""
    sample_world(T, si, sf, action, S, act, frm, mask)
    for k in range(N_STAT):
        stats[k] = 0.0
    advance_to_decision(T, S, act, frm, mask, stats)
    d = _next_decider(T, act, frm)
    if d < 0:
        d = 0
    _canonical(T, S, act, frm, mask, d, ci, cf)
    x0, z0, h0 = root_pose(T, S, act, frm, 0)
    x1, z1, h1 = root_pose(T, S, act, frm, 1)
    r, ts, to = relative_pose(x0, z0, h0, x1, z1, h1)
    n = stats[ST_FRAMES]
    feat[FT_FRAMES] = n
    feat[FT_R] = r
    feat[FT_R_MEAN] = stats[ST_SUMR] / n if n > 0 else r
    feat[FT_TH_SELF] = ts
    feat[FT_TH_OTHER] = to
    feat[FT_DMG_GIVEN] = stats[ST_DMG1]
    feat[FT_DMG_RECEIVED] = stats[ST_DMG0]
    feat[FT_DEF_SELF] = stats[ST_DEF0]
    feat[FT_DEF_OTHER] = stats[ST_DEF1]
    feat[FT_HITS_SELF] = stats[ST_HITS0]
    feat[FT_HITS_OTHER] = stats[ST_HITS1]
    feat[FT_REACH_SELF] = stats[ST_REACH0]
    feat[FT_REACH_OTHER] = stats[ST_REACH1]
    feat[FT_PUSH] = stats[ST_PUSH]
    feat[FT_NEAR_SELF] = stats[ST_NEAR0]
    feat[FT_NEAR_OTHER] = stats[ST_NEAR1]
    return d


@njit(cache=True, nogil=True)
def _expand_range(T, si, sf, parent, action, ci, cf, feat, swap, lo, hi):
    S = np.empty((2, 3))
    act = np.empty(2, dtype=np.int64)
    frm = np.empty(2, dtype=np.int64)
    mask = np.empty(2, dtype=np.int64)
    stats = np.empty(N_STAT)
    for k in range(lo, hi):
        p = parent[k]
        swap[k] = expand_one(T, si[p], sf[p], action[k], ci[k], cf[k], feat[k], S, act, frm, mask, stats)


def expand_samples(T: tuple, si: np.ndarray, sf: np.ndarray, parent: np.ndarray, action: np.ndarray,
                   workers: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batch: for each k simulate sample parent[k]'s decider starting action[k].

    Returns child ints (K, N_SI), child floats (K, N_SF), features (K, N_FEAT) and the next
    decider (K,) int8 (1: the other avatar decides at the child, an edge 'swap'). ``workers``
    threads share the rows; the result does not depend on it.
    """
    K = len(parent)
    ci = np.empty((K, N_SI), dtype=np.int64)
    cf = np.empty((K, N_SF), dtype=np.float64)
    feat = np.empty((K, N_FEAT), dtype=np.float64)
    swap = np.empty(K, dtype=np.int8)
    parallel_for(_expand_range, K, workers, T, si, sf, np.ascontiguousarray(parent, dtype=np.int64),
                 np.ascontiguousarray(action, dtype=np.int64), ci, cf, feat, swap)
    return ci, cf, feat, swap


def parallel_for(kernel, n: int, workers: int, *args, min_chunk: int = 2048) -> None:
    """Run ``kernel(*args, lo, hi)`` (a nogil numba kernel writing disjoint rows) over [0, n)
    in contiguous chunks on ``workers`` threads (None or 0: all cores)."""
    w = resolve_workers(workers)
    if w <= 1 or n < 2 * min_chunk:
        kernel(*args, 0, n)
        return
    step = max(min_chunk, -(-n // (4 * w)))
    bounds = [(lo, min(n, lo + step)) for lo in range(0, n, step)]
    from concurrent.futures import ThreadPoolExecutor
    with ThreadPoolExecutor(max_workers=w) as ex:
        for f in [ex.submit(kernel, *args, lo, hi) for lo, hi in bounds]:
            f.result()


def resolve_workers(workers: int | None) -> int:
    """Threads to use: ``workers``, or all cores for None / 0."""
    import os
    if not workers:
        return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))
    return max(1, int(workers))


@njit(cache=True)
def advance_worlds(T, pose, act, frm, mask):
    """Batch: advance N coupled worlds to their next decision instant.

    pose (N, 2, 3) current root poses (x, z, heading) -- updated in place, as are act (N, 2),
    frm (N, 2), mask (N, 2). Returns stats (N, N_STAT).
    """
    N = pose.shape[0]
    stats = np.zeros((N, N_STAT))
    S = np.empty((2, 3))
    for n in range(N):
        for i in range(2):
            sx, sz, sh = start_from_root(T, act[n, i], frm[n, i], pose[n, i, 0], pose[n, i, 1], pose[n, i, 2])
            S[i, 0] = sx
            S[i, 1] = sz
            S[i, 2] = sh
        advance_to_decision(T, S, act[n], frm[n], mask[n], stats[n])
        for i in range(2):
            x, z, h = root_pose(T, S, act[n], frm[n], i)
            pose[n, i, 0] = x
            pose[n, i, 1] = z
            pose[n, i, 2] = wrap_angle_nb(h)
    return stats
