"""Offscreen pictures of reference vs simulation, rendered by MuJoCo (EGL, else OSMesa).

- ``record_rollout``: run a controller on a Reference and keep the simulated qpos per control step
  (it goes on for a moment after a fall so the fall is visible).
- ``render_frames``: for chosen steps, one panel of the reference posed kinematically and one of
  the simulation, each with a camera following its own pelvis.
- ``save_contact_sheet`` (PNG: top row reference, bottom row simulation, columns in time) and
  ``save_video`` (MP4, side by side, needs the ``imageio-ffmpeg`` package).

The GL backend is chosen here, not through MUJOCO_GL: EGL (headless GPU or Mesa) first, then
OSMesa (``apt-get install libosmesa6``); ``backend`` forces one.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from tracker.track.env import EnvConfig, TrackingEnv
from tracker.body.humanoid import FighterScene
from tracker.track.reference import Reference


@dataclass
class Rollout:
    """Simulated qpos (T, nq) at the reference's control steps 0..T-1, and the fall step (or None)."""

    qpos: np.ndarray
    fall_step: int | None
    fall_reason: str | None


def record_rollout(scene: FighterScene, ref: Reference, controller, config: EnvConfig = EnvConfig(),
                   after_fall_s: float = 1.5, max_s: float | None = None) -> Rollout:
    """Track ref with controller from its first frame; keep going ``after_fall_s`` past a fall."""
    from dataclasses import replace
    env = TrackingEnv(scene, replace(config, terminate_on_fall=False))
    obs = env.reset(ref, 0)
    controller.reset(env)
    qs = [env.data.qpos.copy()]
    fall_step, reason = None, None
    end = ref.n_frames - 1 if max_s is None else min(ref.n_frames - 1, int(max_s * ref.fps))
    while env.t < end:
        obs, _, done, info = env.step(controller.act(env, obs))
        qs.append(env.data.qpos.copy())
        if fall_step is None and info.fall[0] is not None:
            fall_step, reason = env.t, info.fall[0]
        if fall_step is not None and env.t >= fall_step + after_fall_s * ref.fps:
            break
        if done:
            break
    return Rollout(np.array(qs), fall_step, reason)


class OffscreenRenderer:
    """A minimal offscreen renderer on an explicit GL context (EGL or OSMesa)."""

    def __init__(self, model: mujoco.MjModel, width: int = 480, height: int = 360, backend: str | None = None) -> None:
        self.model = model
        self.width = min(width, int(model.vis.global_.offwidth))
        self.height = min(height, int(model.vis.global_.offheight))
        self.backend, self.ctx = _gl_context(self.width, self.height, backend)
        self.ctx.make_current()
        self.scene = mujoco.MjvScene(model, maxgeom=4000)
        self.con = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_150)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self.con)
        self.opt = mujoco.MjvOption()
        self.pert = mujoco.MjvPerturb()
        self.cam = mujoco.MjvCamera()
        self.cam.type = mujoco.mjtCamera.mjCAMERA_FREE
        self.viewport = mujoco.MjrRect(0, 0, self.width, self.height)

    def render(self, data: mujoco.MjData, lookat: np.ndarray, azimuth: float = 135.0, elevation: float = -10.0,
               distance: float = 3.0) -> np.ndarray:
        self.ctx.make_current()
        self.cam.lookat[:] = lookat
        self.cam.azimuth, self.cam.elevation, self.cam.distance = azimuth, elevation, distance
        mujoco.mjv_updateScene(self.model, data, self.opt, self.pert, self.cam, mujoco.mjtCatBit.mjCAT_ALL, self.scene)
        mujoco.mjr_render(self.viewport, self.scene, self.con)
        rgb = np.empty((self.height, self.width, 3), np.uint8)
        mujoco.mjr_readPixels(rgb, None, self.viewport, self.con)
        return np.flipud(rgb).copy()

    def close(self) -> None:
        try:
            self.con.free()
        except Exception:  # noqa: BLE001
            pass
        try:
            self.ctx.free()
        except Exception:  # noqa: BLE001
            pass


def _gl_context(width: int, height: int, backend: str | None):
    order = [backend] if backend else ["egl", "osmesa"]
    errors = []
    for b in order:
        try:
            if b == "egl":
                from mujoco.egl import GLContext
            elif b == "osmesa":
                from mujoco.osmesa import GLContext
            elif b == "glfw":
                from mujoco.glfw import GLContext
            else:
                raise ValueError(f"unknown GL backend {b!r}")
            ctx = GLContext(width, height)
            return b, ctx
        except Exception as e:  # noqa: BLE001 - try the next backend
            errors.append(f"{b}: {e}")
    raise RuntimeError("no offscreen OpenGL: " + "; ".join(errors) +
                       " (install Mesa EGL, or `apt-get install -y libosmesa6`)")


def render_frames(scene: FighterScene, ref: Reference, rollout: Rollout, steps: list[int], width: int = 480,
                  height: int = 360, backend: str | None = None, labels: bool = True) -> list[tuple[np.ndarray, np.ndarray]]:
    """[(reference image, simulation image)] for the given control steps (H, W, 3 uint8 each)."""
    m = scene.model
    fm = scene.fighters[0]
    r = OffscreenRenderer(m, width, height, backend)
    d_ref, d_sim = mujoco.MjData(m), mujoco.MjData(m)
    out = []
    try:
        for t in steps:
            tr = min(t, ref.n_frames - 1)
            ts = min(t, len(rollout.qpos) - 1)
            d_ref.qpos[fm.qpos_slice] = ref.qpos[tr]
            mujoco.mj_kinematics(m, d_ref)
            d_sim.qpos[:] = rollout.qpos[ts]
            mujoco.mj_kinematics(m, d_sim)
            look_ref = d_ref.xpos[fm.pelvis_body].copy()
            look_sim = d_sim.xpos[fm.pelvis_body].copy()
            look_ref[2] = look_sim[2] = 0.9
            a = r.render(d_ref, look_ref)
            b = r.render(d_sim, look_sim)
            if labels:
                sec = t / ref.fps
                fell = rollout.fall_step is not None and t >= rollout.fall_step
                a = caption(a, f"reference  t={sec:.2f}s")
                b = caption(b, f"simulation t={sec:.2f}s" + ("  FALLEN" if fell else ""))
            out.append((a, b))
    finally:
        r.close()
    return out


def caption(img: np.ndarray, text: str) -> np.ndarray:
    """``img`` with ``text`` written in white on a black band at its top left."""
    from PIL import Image, ImageDraw
    im = Image.fromarray(img)
    dr = ImageDraw.Draw(im)
    dr.rectangle([0, 0, 8 + 7 * len(text), 18], fill=(0, 0, 0))
    dr.text((4, 3), text, fill=(255, 255, 255))
    return np.asarray(im)


def save_contact_sheet(frames: list[tuple[np.ndarray, np.ndarray]], path: str | os.PathLike) -> Path:
    """PNG: top row reference, bottom row simulation, one column per frame."""
    from PIL import Image
    top = np.concatenate([a for a, _ in frames], axis=1)
    bottom = np.concatenate([b for _, b in frames], axis=1)
    sheet = np.concatenate([top, np.full((4, top.shape[1], 3), 255, np.uint8), bottom], axis=0)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(sheet).save(path)
    return path


def save_video(frames: list[tuple[np.ndarray, np.ndarray]], path: str | os.PathLike, fps: float) -> Path:
    """MP4 (H.264) of the side-by-side frames; needs imageio-ffmpeg."""
    try:
        import imageio_ffmpeg
    except ImportError:
        raise RuntimeError("MP4 output needs the imageio-ffmpeg package (pip install imageio-ffmpeg); "
                           "or write a .png contact sheet") from None
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    h, w = frames[0][0].shape[0], frames[0][0].shape[1] * 2
    w2, h2 = w - w % 2, h - h % 2
    writer = imageio_ffmpeg.write_frames(str(path), (w2, h2), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                         macro_block_size=1, quality=7)
    writer.send(None)
    for a, b in frames:
        writer.send(np.ascontiguousarray(np.concatenate([a, b], axis=1)[:h2, :w2]))
    writer.close()
    return path


def image_stats(img: np.ndarray) -> dict:
    """How much of an image is not background: share of pixels far from the image's median colour."""
    med = np.median(img.reshape(-1, 3), axis=0)
    diff = np.abs(img.astype(np.int16) - med.astype(np.int16)).sum(axis=-1)
    return {"std": float(img.std()), "foreground_share": float(np.mean(diff > 60))}
