"""Artifacts of a physics bout (tracker.bouts.physics_bout): the JSONL log and summary in the kinematic bouts'
format with the physics lines added, plots, and the ring-side MP4."""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

if TYPE_CHECKING:
    from tracker.bouts.physics_bout import PhysicsBout
    from tracker.bouts.results import PhysicsBoutResult



def to_bout_result(res: PhysicsBoutResult):
    """The result as igraph_fight.match.BoutResult (for the kinematic bouts' artifact writer)."""
    from igraph_fight.match import BoutResult
    tr = res.trace
    trace = {"t": tr["t"], "pose": tr["pose"], "action": tr["action"], "frame": tr["frame"], "distance": tr["distance"]}
    hits = [{k: h[k] for k in ("t", "frame", "attacker", "victim", "action", "kind")} for h in res.hit_events]
    return BoutResult(res.names, res.seconds, res.hits.copy(), np.zeros(2), np.zeros(2), res.decisions, hits,
                      float(np.mean(tr["distance"])) if len(tr["distance"]) else float("nan"), res.wall_s, trace,
                      list(res.notes))


def write_physics_artifacts(bout: PhysicsBout, res: PhysicsBoutResult, out: str | os.PathLike, title: str = "bout",
                            video: bool = True, video_fps: float = 15.0, width: int = 640, height: int = 360,
                            backend: str | None = None) -> dict:
    """Write log.jsonl and summary.json (the kinematic bouts' format, with physics lines and fields
    added), distance.png (the kinematic plot), physics.png (distance, cumulative realised and planned
    hits, falls) and bout.mp4 (ring-side camera). Returns the summary (with ``artifacts``)."""
    from igraph_fight.match import write_bout_artifacts
    from motion_graph.atomic import atomic_write_text
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = write_bout_artifacts(bout.setup.game, to_bout_result(res), out, title=title, plots=True, html=False,
                                 bvh=False)
    # the physics lines: every hit with its force / target / planned flag, planned hits, falls, touches
    lines = [json.loads(l) for l in (out / "log.jsonl").read_text().splitlines() if l.strip()]
    lines = [l for l in lines if l["type"] != "hit"]
    for h in res.hit_events:
        lines.append({"type": "hit", **h})
    for p in res.planned_events:
        lines.append({"type": "planned_hit", **p})
    for f in res.fall_events:
        lines.append({"type": "fall", **f})
    for tch in res.touch_events:
        lines.append({"type": "touch", **tch})
    lines.sort(key=lambda l: l["t"])
    atomic_write_text(out / "log.jsonl", "\n".join(json.dumps(l) for l in lines) + "\n")
    _plot_physics(res, out / "physics.png", title)
    paths["plot_physics"] = str(out / "physics.png")
    if video:
        try:
            render_bout_video(bout, res, out / "bout.mp4", fps=video_fps, width=width, height=height, backend=backend)
            paths["video"] = str(out / "bout.mp4")
        except RuntimeError as e:   # no GL or no ffmpeg: the rest of the artifacts still stand
            paths["video_error"] = str(e)
    summary = res.summary()
    summary["artifacts"] = dict(paths)
    summary["artifacts"]["summary"] = str(out / "summary.json")
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1))
    return summary


def _plot_physics(res: PhysicsBoutResult, path: Path, title: str) -> None:
    from igraph_fight.bout_plot import cumulative_steps, distance_and_hits_figure, save_figure
    tr = res.trace
    fig, ax0, ax1 = distance_and_hits_figure(
        tr["t"], tr["distance"], "pelvis distance (m)",
        f"{title if res.physics in title else f'{title} ({res.physics})'}: {res.names[0]} (A) vs {res.names[1]} (B), "
        f"score {res.score:+.0f}", height=6.5)
    cols = ("#e4572e", "#3fa7d6")
    for who in (0, 1):
        ts = [h["t"] for h in res.hit_events if h["attacker"] == who]
        cumulative_steps(ax1, ts, res.seconds, color=cols[who], label=f"realised hits by {'AB'[who]} ({res.names[who]})")
        tp = [p["t"] for p in res.planned_events if p["attacker"] == who]
        cumulative_steps(ax1, tp, res.seconds, color=cols[who], ls="--", lw=1, label=f"planned hits by {'AB'[who]}")
        for f in res.fall_events:
            if f["player"] == who:
                for ax in (ax0, ax1):
                    ax.axvspan(f["t"], f["reset_t"], color=cols[who], alpha=0.15, lw=0)
    ax1.set_xlabel(f"time (s); shaded: fallen (A {int(res.falls[0])} falls, B {int(res.falls[1])} falls)")
    ax1.legend(loc="upper left", fontsize=8)
    save_figure(fig, path)


def render_bout_video(bout: PhysicsBout, res: PhysicsBoutResult, path: str | os.PathLike, fps: float = 15.0,
                      width: int = 640, height: int = 360, backend: str | None = None,
                      max_seconds: float | None = None, shadows: bool = False) -> Path:
    """MP4 of the bout from a ring-side camera (MuJoCo offscreen, EGL else OSMesa), with a caption
    (time, hits, falls, the actions playing). The camera looks at the fighters' midpoint from the
    side of the line joining them (smoothed), backing off as they separate."""
    from tracker.track.render import OffscreenRenderer, caption
    try:
        import imageio_ffmpeg
    except ImportError:
        raise RuntimeError("MP4 output needs imageio-ffmpeg") from None
    tr = res.trace
    if not len(tr.get("qpos", [])):
        raise RuntimeError("the bout was run without BoutConfig.record_qpos")
    m = bout.model
    d = mujoco.MjData(m)
    step = max(1, int(round(30.0 / fps)))
    n = len(tr["qpos"]) if max_seconds is None else min(len(tr["qpos"]), int(max_seconds * 30) + 1)
    idx = list(range(0, n, step))
    r = OffscreenRenderer(m, width, height, backend)
    r.opt.geomgroup[4] = 0
    if not shadows:   # shadows cost 2-3x per frame on a software renderer (Mesa llvmpipe)
        r.scene.flags[mujoco.mjtRndFlag.mjRND_SHADOW] = False
    r.scene.flags[mujoco.mjtRndFlag.mjRND_REFLECTION] = False
    w2, h2 = r.width - r.width % 2, r.height - r.height % 2
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    writer = imageio_ffmpeg.write_frames(str(path), (w2, h2), fps=30.0 / step, codec="libx264", pix_fmt_out="yuv420p",
                                         macro_block_size=1, quality=6)
    writer.send(None)
    hits_t = [[h["t"] for h in res.hit_events if h["attacker"] == k] for k in (0, 1)]
    falls_t = [[f["t"] for f in res.fall_events if f["player"] == k] for k in (0, 1)]
    lib = bout.lib
    az = None
    look = None
    try:
        for i in idx:
            d.qpos[:] = tr["qpos"][i]
            mujoco.mj_kinematics(m, d)
            p0 = d.xpos[bout.fms[0].pelvis_body]
            p1 = d.xpos[bout.fms[1].pelvis_body]
            mid = 0.5 * (p0 + p1)
            mid[2] = 1.0
            sep = float(np.linalg.norm((p1 - p0)[:2]))
            line = np.degrees(np.arctan2(p1[1] - p0[1], p1[0] - p0[0]))
            want = line + 90.0
            if az is None:
                az, look = want, mid.copy()
            else:
                # the side of the line nearer the current azimuth, then smooth (about 1.5 s)
                cand = [want + 360.0 * j for j in (-2, -1, 0, 1, 2)] + [want + 180.0 + 360.0 * j for j in (-2, -1, 0, 1)]
                want = min(cand, key=lambda c: abs(c - az))
                a = 1.0 - np.exp(-step / 45.0)
                az += a * (want - az)
                look += (1.0 - np.exp(-step / 15.0)) * (mid - look)
            img = r.render(d, look, azimuth=az, elevation=-12.0, distance=max(3.2, 1.3 * sep + 2.2))
            t = tr["t"][i]
            acts = tr["action"][i]
            down = tr["down"][i]
            ha = [sum(1 for x in hits_t[k] if x <= t + 1e-9) for k in (0, 1)]
            fa = [sum(1 for x in falls_t[k] if x <= t + 1e-9) for k in (0, 1)]
            cap = (f"t={t:5.1f}s  A(red) {res.names[0]}: hits {ha[0]} falls {fa[0]}  |  "
                   f"B(blue) {res.names[1]}: hits {ha[1]} falls {fa[1]}")
            img = caption(img, cap)
            sub = "  ".join(f"{'AB'[k]}: {'DOWN' if down[k] else lib.labels[int(acts[k])]}" for k in (0, 1))
            flash = [k for k in (0, 1) if any(t - 0.3 < x <= t + 1e-9 for x in hits_t[k])]
            if flash:
                sub += "   " + " ".join(f"HIT by {'AB'[k]}" for k in flash)
            sub += f"   [{res.physics}]"
            img = _label_bottom(img, sub)
            writer.send(np.ascontiguousarray(img[:h2, :w2]))
    finally:
        writer.close()
        r.close()
    return path


def _label_bottom(img: np.ndarray, text: str) -> np.ndarray:
    from PIL import Image, ImageDraw
    im = Image.fromarray(img)
    dr = ImageDraw.Draw(im)
    h = im.size[1]
    dr.rectangle([0, h - 19, 8 + 7 * len(text), h], fill=(0, 0, 0))
    dr.text((4, h - 16), text, fill=(255, 255, 160))
    return np.asarray(im)


def machine_load() -> list[float] | None:
    """The machine's 1, 5 and 15 minute load averages (None where the platform has none)."""
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None
