"""A crowd of Interaction Graph fighters in two teams (paper section 7.1).

Each fighter fights the nearest fighter of the other team and switches when another one comes
closer (by more than ``switch_margin_m``, a hysteresis against flicker), so a fighter may face
several attackers at once. Decisions are taken for all fighters at a decision instant in one
call of the controller's batch API (``NPCController.act_batch``, with the off-graph lookahead by
default), from each fighter's view of its current opponent; the motion and contact rules are
the coupled simulator's (igraph_fight.sim), stepped frame by frame for everybody at once.

Approximations (the game API and the simulator are for two fighters):

* Pairs: a fighter's observation (the paper's state I) is taken against its current opponent
  only; other fighters nearby are not part of its state.
* Hits: a strike is judged against the attacker's current opponent only (its head, chest and
  belly spheres, its defence window), not against bystanders; it resolves at most once, as in
  the pair simulator.
* Bodies: every pair of fighters closer than ``SimParams.min_distance_m`` is pushed apart (half
  the overlap each, in index order), not only opponents.
* Simultaneous decisions: fighters that stand at a decision instant on the same frame choose
  together from the same snapshot (in a two-fighter bout the second one sees the first's new
  action at frame 0).
* Snapping (``snap=True``): an on-graph decider is moved along the line to its opponent to the
  state's distance and turned to its angle, like ``IGAgent(snap=True)``.

``Crowd.run(seconds)`` returns a report with the real-time factor (simulated / wall seconds).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from igraph_fight.controller import NPCController
from igraph_fight.sim import strike_blocked, open_strike_mask, relative_pose, root_pose, start_from_root
from motion_graph.rotations import wrap_angle_nb


@dataclass
class CrowdReport:
    """What a crowd run did. Seconds, metres; ``rtf`` = simulated seconds / wall seconds."""

    n: int
    seconds: float
    wall_s: float
    rtf: float
    decisions: int
    off_graph: int
    hits: np.ndarray                 # (2,) hits landed by team 0 / team 1
    defended: np.ndarray             # (2,) strikes avoided by a defence of team 0 / team 1
    switches: int                    # opponent switches
    mean_opponent_distance_m: float
    max_attackers: int               # most fighters that had the same fighter as opponent at once
    timings_s: dict = field(default_factory=dict)
    frames: np.ndarray | None = None  # (K, N, 3) recorded root poses (x, z, heading)
    frame_t: np.ndarray | None = None

    def summary(self) -> dict:
        return {"n": self.n, "seconds": self.seconds, "wall_s": round(self.wall_s, 3), "rtf": round(self.rtf, 2),
                "decisions": self.decisions, "decisions_per_s": round(self.decisions / max(self.wall_s, 1e-9), 1),
                "off_graph_fraction": round(self.off_graph / max(self.decisions, 1), 3),
                "hits_team0": float(self.hits[0]), "hits_team1": float(self.hits[1]),
                "defended_team0": float(self.defended[0]), "defended_team1": float(self.defended[1]),
                "switches": self.switches, "mean_opponent_distance_m": round(self.mean_opponent_distance_m, 3),
                "max_attackers": self.max_attackers,
                "timings_s": {k: round(v, 3) for k, v in self.timings_s.items()}}


# ----- kernels -----------------------------------------------------------------------------------
@njit(cache=True)
def _poses(T, S, act, frm, out):
    """Root poses (x, z, heading) of every fighter."""
    for i in range(S.shape[0]):
        x, z, h = root_pose(T, S[i:i + 1], act[i:i + 1], frm[i:i + 1], 0)
        out[i, 0] = x
        out[i, 1] = z
        out[i, 2] = h


@njit(cache=True)
def _nearest_enemies(pose, team, opp, margin):
    """Update each fighter's opponent: the nearest fighter of the other team, switching only when
    it is closer than the current one by more than ``margin``. Returns the number of switches."""
    n = pose.shape[0]
    switches = 0
    for i in range(n):
        best = -1
        bd = np.inf
        for j in range(n):
            if team[j] == team[i]:
                continue
            dx = pose[j, 0] - pose[i, 0]
            dz = pose[j, 1] - pose[i, 1]
            d = dx * dx + dz * dz
            if d < bd:
                bd = d
                best = j
        o = opp[i]
        if o < 0:
            opp[i] = best
        elif best != o and best >= 0:
            dx = pose[o, 0] - pose[i, 0]
            dz = pose[o, 1] - pose[i, 1]
            if np.sqrt(bd) < np.sqrt(dx * dx + dz * dz) - margin:
                opp[i] = best
                switches += 1
    return switches


@njit(cache=True)
def _observe(T, S, act, frm, mask, opp, who, out_f, out_i):
    """Observations of fighters ``who`` against their opponents (r, theta_self, theta_other;
    m_self, m_other, f_other, open mask of the opponent's resolved strikes)."""
    for k in range(who.shape[0]):
        i = who[k]
        o = opp[i]
        x0, z0, h0 = root_pose(T, S[i:i + 1], act[i:i + 1], frm[i:i + 1], 0)
        x1, z1, h1 = root_pose(T, S[o:o + 1], act[o:o + 1], frm[o:o + 1], 0)
        r, ts, to = relative_pose(x0, z0, h0, x1, z1, h1)
        out_f[k, 0] = r
        out_f[k, 1] = ts
        out_f[k, 2] = to
        out_i[k, 0] = act[i]
        out_i[k, 1] = act[o]
        out_i[k, 2] = frm[o]
        out_i[k, 3] = open_strike_mask(T, act[o], frm[o], mask[o])


@njit(cache=True)
def _start(T, S, act, frm, mask, opp, who, actions, snap, snap_r, snap_ts):
    """Deciders ``who`` launch ``actions`` from their current root pose; with snap[k] the decider
    is first moved along the line to its opponent to distance snap_r[k] and turned so that its
    angle to that line is snap_ts[k]. Returns the total snapping displacement (m)."""
    moved = 0.0
    for k in range(who.shape[0]):
        i = who[k]
        x, z, h = root_pose(T, S[i:i + 1], act[i:i + 1], frm[i:i + 1], 0)
        if snap[k]:
            o = opp[i]
            xo, zo, _ = root_pose(T, S[o:o + 1], act[o:o + 1], frm[o:o + 1], 0)
            b = np.arctan2(xo - x, zo - z)
            nx = xo - snap_r[k] * np.sin(b)
            nz = zo - snap_r[k] * np.cos(b)
            moved += np.sqrt((nx - x) ** 2 + (nz - z) ** 2)
            x = nx
            z = nz
            h = b - snap_ts[k]
        a = actions[k]
        sx, sz, sh = start_from_root(T, a, 0, x, z, wrap_angle_nb(h))
        S[i, 0] = sx
        S[i, 1] = sz
        S[i, 2] = sh
        act[i] = a
        frm[i] = 0
        mask[i] = 0
    return moved


@njit(cache=True)
def _frame(T, S, act, frm, mask, opp, team, hits, defended, pose):
    """Advance every fighter one frame; push overlapping bodies apart; judge every active strike
    against the attacker's opponent (sim.advance_to_decision's rules). Fills ``pose``; returns the
    deciders' count (fighters now at the last frame of their action)."""
    (n_frames, offs, path, eff, tgt, s_off, s_eff, s_w0, s_w1, s_dmg, d_w0, d_w1, rad2, dmin, max_frames, near2,
     arms, guard2, lead) = T
    n = S.shape[0]
    nt = tgt.shape[1]
    for i in range(n):
        if frm[i] < n_frames[act[i]] - 1:
            frm[i] += 1
    for i in range(n):
        x, z, h = root_pose(T, S[i:i + 1], act[i:i + 1], frm[i:i + 1], 0)
        pose[i, 0] = x
        pose[i, 1] = z
        pose[i, 2] = h
    # bodies apart (every pair; moves the start transforms so that the push persists)
    for i in range(n):
        for j in range(i + 1, n):
            dx = pose[j, 0] - pose[i, 0]
            dz = pose[j, 1] - pose[i, 1]
            d2 = dx * dx + dz * dz
            if d2 >= dmin * dmin:
                continue
            d = np.sqrt(d2)
            if d > 1e-9:
                ux = dx / d
                uz = dz / d
            else:
                ux = np.sin(pose[i, 2])
                uz = np.cos(pose[i, 2])
            hh = 0.5 * (dmin - d)
            S[i, 0] -= ux * hh
            S[i, 1] -= uz * hh
            S[j, 0] += ux * hh
            S[j, 1] += uz * hh
            pose[i, 0] -= ux * hh
            pose[i, 1] -= uz * hh
            pose[j, 0] += ux * hh
            pose[j, 1] += uz * hh
    # strikes against the opponent
    for i in range(n):
        o = opp[i]
        if o < 0:
            continue
        a = act[i]
        f = frm[i]
        ci = np.cos(S[i, 2])
        si = np.sin(S[i, 2])
        co = np.cos(S[o, 2])
        so = np.sin(S[o, 2])
        go = offs[act[o]] + frm[o]
        for k in range(s_off[a], s_off[a + 1]):
            bit = np.int64(1) << np.int64(k - s_off[a])
            if f < s_w0[k] - lead or f >= s_w1[k] or (mask[i] & bit) != 0:
                continue
            e = eff[offs[a] + f, s_eff[k]]
            if guard2 > 0.0:
                e0 = eff[offs[a] + f - 1, s_eff[k]] if f > 0 else e
                if strike_blocked(arms, guard2, e0, e, ci, si, S[i, 0], S[i, 1], go, co, so, S[o, 0], S[o, 1]):
                    mask[i] |= bit    # a forearm of the opponent blocks it (sim.advance_to_decision's guard)
                    defended[o] += 1
                    continue
            if f < s_w0[k]:
                continue
            ex = ci * e[0] + si * e[2] + S[i, 0]
            ey = e[1]
            ez = -si * e[0] + ci * e[2] + S[i, 1]
            touch = False
            for t in range(nt):
                q = tgt[go, t]
                qx = co * q[0] + so * q[2] + S[o, 0]
                qz = -so * q[0] + co * q[2] + S[o, 1]
                dd = (ex - qx) ** 2 + (ey - q[1]) ** 2 + (ez - qz) ** 2
                if dd < rad2[t]:
                    touch = True
                    break
            if touch:
                mask[i] |= bit
                ao = act[o]
                if d_w0[ao] >= 0 and d_w0[ao] <= frm[o] and frm[o] < d_w1[ao]:
                    defended[o] += 1
                else:
                    hits[i] += 1
    count = 0
    for i in range(n):
        if frm[i] >= n_frames[act[i]] - 1:
            count += 1
    return count


# ----- simulator ---------------------------------------------------------------------------------
class Crowd:
    """N fighters in two teams on one Interaction Graph.

    Args:
        controllers: one NPCController per team (or one for both); their styles are the teams'.
        n: number of fighters (team 0 gets the extra one when odd).
        seed: jitter of the start layout and start actions.
        spacing_m: distance between neighbouring pairs of the start grid; gap_m: distance between
            the two fighters of a pair at the start.
        switch_margin_m: hysteresis of the opponent switch.
        lookahead: off-graph deciders use the controller's simulated lookahead (else the nearest
            state's table entry).
        snap: snap on-graph deciders onto their graph state (distance and angle to the opponent).
        record_every: keep the root poses every this many frames (0: none), for plots.
    """

    def __init__(self, controllers, n: int, seed: int = 0, spacing_m: float = 3.0, gap_m: float = 1.4,
                 switch_margin_m: float = 0.15, lookahead: bool = True, snap: bool = True,
                 record_every: int = 0) -> None:
        if isinstance(controllers, NPCController):
            controllers = [controllers, controllers]
        if len(controllers) != 2:
            raise ValueError("one controller per team (two) or one for both")
        if n < 2:
            raise ValueError("a crowd needs at least two fighters")
        self.ctrl = list(controllers)
        self.tables = self.ctrl[0].tables
        self.T = self.tables.kernel_tuple()
        self.fps = self.tables.fps
        self.n = int(n)
        self.lookahead = lookahead
        self.snap = snap
        self.switch_margin_m = float(switch_margin_m)
        self.record_every = int(record_every)
        rng = np.random.default_rng(seed)
        team = np.zeros(n, dtype=np.int64)
        team[(n + 1) // 2:] = 1
        self.team = team
        # pairs on a grid (a melee): pair k stands at a grid point, its team-0 fighter at
        # z - gap/2 facing +Z, its team-1 fighter at z + gap/2 facing -Z; the grid's spacing
        # leaves room to move, so neighbours' fights mix and fighters switch opponents
        pose = np.zeros((n, 3))
        idx0 = np.nonzero(team == 0)[0]
        idx1 = np.nonzero(team == 1)[0]
        cols = int(np.ceil(np.sqrt(len(idx0))))
        for k, i in enumerate(idx0):
            row, col = divmod(k, cols)
            cx = (col - (cols - 1) / 2) * spacing_m
            cz = (row - (cols - 1) / 2) * spacing_m
            pose[i] = (cx + rng.normal(0, 0.1), cz - gap_m / 2 + rng.normal(0, 0.1), rng.normal(0, 0.3))
            if k < len(idx1):
                j = idx1[k]
                pose[j] = (cx + rng.normal(0, 0.1), cz + gap_m / 2 + rng.normal(0, 0.1), np.pi + rng.normal(0, 0.3))
        lib = self.ctrl[0].library
        guard = np.array([a for a in range(lib.n_actions) if lib.labels[a] == "guard"] or list(range(lib.n_actions)))
        self.act = rng.choice(guard, size=n).astype(np.int64)
        nf = self.tables.n_frames
        self.frm = (nf[self.act] - 1).astype(np.int64)
        self.mask = np.zeros(n, dtype=np.int64)
        self.S = np.zeros((n, 3))
        for i in range(n):
            self.S[i] = start_from_root(self.T, self.act[i], self.frm[i], pose[i, 0], pose[i, 1], pose[i, 2])
        self.opp = np.full(n, -1, dtype=np.int64)
        self.pose = pose.copy()
        self.hits = np.zeros(n)
        self.defended = np.zeros(n)
        self.frames = 0
        _nearest_enemies(self.pose, self.team, self.opp, self.switch_margin_m)

    @property
    def time_s(self) -> float:
        return self.frames / self.fps

    def _decide(self, who: np.ndarray) -> tuple[int, float]:
        """Batch decisions of fighters ``who`` (per team controller). Returns (off-graph count,
        snapping displacement)."""
        obs_f = np.empty((len(who), 3))
        obs_i = np.empty((len(who), 4), dtype=np.int64)
        _observe(self.T, self.S, self.act, self.frm, self.mask, self.opp, who, obs_f, obs_i)
        actions = np.empty(len(who), dtype=np.int64)
        snap = np.zeros(len(who), dtype=np.bool_)
        snap_r = np.zeros(len(who))
        snap_ts = np.zeros(len(who))
        off_count = 0
        for t in (0, 1):
            sel = np.nonzero(self.team[who] == t)[0]
            if len(sel) == 0:
                continue
            c = self.ctrl[t]
            a, s, off = c.act_batch(obs_f[sel, 0], obs_f[sel, 1], obs_f[sel, 2], obs_i[sel, 0], obs_i[sel, 1],
                                    obs_i[sel, 2], obs_i[sel, 3], lookahead=self.lookahead)
            actions[sel] = a
            off_count += int(off.sum())
            if self.snap:
                ok = (~off) & (s >= 0)
                snap[sel] = ok
                g = c.graph.arrays
                snap_r[sel[ok]] = g["state_r"][s[ok]]
                snap_ts[sel[ok]] = g["state_theta_self"][s[ok]]
        moved = _start(self.T, self.S, self.act, self.frm, self.mask, self.opp, who, actions, snap, snap_r, snap_ts)
        return off_count, moved

    def run(self, seconds: float, progress: bool = False) -> CrowdReport:
        """Simulate ``seconds``; returns the report (real-time factor, decisions, hits...)."""
        n_frames = int(round(seconds * self.fps))
        nf = self.tables.n_frames
        t_dec = t_frame = t_opp = 0.0
        decisions = off = switches = 0
        dist_sum = 0.0
        max_att = 0
        rec, rec_t = [], []
        t0 = time.perf_counter()
        for k in range(n_frames):
            t = time.perf_counter()
            who = np.nonzero(self.frm >= nf[self.act] - 1)[0]
            if len(who):
                o, _ = self._decide(who)
                decisions += len(who)
                off += o
            t_dec += time.perf_counter() - t
            t = time.perf_counter()
            _frame(self.T, self.S, self.act, self.frm, self.mask, self.opp, self.team, self.hits, self.defended,
                   self.pose)
            self.frames += 1
            t_frame += time.perf_counter() - t
            t = time.perf_counter()
            switches += _nearest_enemies(self.pose, self.team, self.opp, self.switch_margin_m)
            t_opp += time.perf_counter() - t
            d = self.pose[self.opp, :2] - self.pose[:, :2]
            dist_sum += float(np.hypot(d[:, 0], d[:, 1]).mean())
            max_att = max(max_att, int(np.bincount(self.opp, minlength=self.n).max()))
            if self.record_every and k % self.record_every == 0:
                rec.append(self.pose.copy())
                rec_t.append(self.time_s)
        wall = time.perf_counter() - t0
        hits = np.array([self.hits[self.team == 0].sum(), self.hits[self.team == 1].sum()])
        dfd = np.array([self.defended[self.team == 0].sum(), self.defended[self.team == 1].sum()])
        return CrowdReport(self.n, n_frames / self.fps, wall, (n_frames / self.fps) / max(wall, 1e-9), decisions,
                           off, hits, dfd, switches, dist_sum / max(n_frames, 1), max_att,
                           {"decisions": t_dec, "frames": t_frame, "opponents": t_opp},
                           np.array(rec) if rec else None, np.array(rec_t) if rec_t else None)


def plot_crowd(report: CrowdReport, team: np.ndarray, path, title: str = "crowd") -> None:
    """Top-down PNG: every fighter's pelvis track (faint) and its final position and facing."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fr = report.frames
    fig, ax = plt.subplots(figsize=(7, 7))
    cols = np.where(team == 0, "#e4572e", "#3fa7d6")
    lw = 0.6 if len(team) <= 100 else 0.25
    for i in range(fr.shape[1]):
        ax.plot(fr[:, i, 0], fr[:, i, 1], color=cols[i], lw=lw, alpha=0.5)
    last = fr[-1]
    ax.scatter(last[:, 0], last[:, 1], c=cols, s=max(4, 60 / np.sqrt(len(team))), zorder=3)
    L = 0.3 if len(team) <= 100 else 0.15
    ax.quiver(last[:, 0], last[:, 1], L * np.sin(last[:, 2]), L * np.cos(last[:, 2]), color=cols, angles="xy",
              scale_units="xy", scale=1, width=0.002, zorder=4)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("z (m)")
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def animate_crowd(report: CrowdReport, team: np.ndarray, path, max_frames: int = 150) -> None:
    """Top-down GIF of the recorded poses (dots and facing ticks), at most ``max_frames`` frames,
    played in real time."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    fr = report.frames
    step = max(1, int(np.ceil(len(fr) / max_frames)))
    fr = fr[::step]
    ts = report.frame_t[::step]
    cols = np.where(team == 0, "#e4572e", "#3fa7d6")
    fig, ax = plt.subplots(figsize=(5, 5))
    lo = report.frames[:, :, :2].min(axis=(0, 1)) - 0.5
    hi = report.frames[:, :, :2].max(axis=(0, 1)) + 0.5
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    sc = ax.scatter(fr[0, :, 0], fr[0, :, 1], c=cols, s=max(3, 50 / np.sqrt(len(team))))
    L = 0.3 if len(team) <= 100 else 0.15
    qv = ax.quiver(fr[0, :, 0], fr[0, :, 1], L * np.sin(fr[0, :, 2]), L * np.cos(fr[0, :, 2]), color=cols,
                   angles="xy", scale_units="xy", scale=1, width=0.003)
    txt = ax.set_title("")

    def update(k):
        sc.set_offsets(fr[k, :, :2])
        qv.set_offsets(fr[k, :, :2])
        qv.set_UVC(L * np.sin(fr[k, :, 2]), L * np.cos(fr[k, :, 2]))
        txt.set_text(f"{len(team)} fighters, t = {ts[k]:.1f} s")
        return sc, qv, txt

    anim = FuncAnimation(fig, update, frames=len(fr), blit=False)
    dt = float(ts[1] - ts[0]) if len(ts) > 1 else 0.1
    anim.save(str(path), writer=PillowWriter(fps=max(1.0, 1.0 / dt)))
    plt.close(fig)
