"""Offscreen pictures: reference and simulation panels both show a body (not blank frames)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from motion_graph.io import load_motion
from tracker.body.humanoid import build_fighter_scene
from tracker.track.pd import PDController
from tracker.track.reference import build_reference
from tracker.track.render import image_stats, record_rollout, render_frames, save_contact_sheet
from tracker.body.spec import fighter_spec

pytestmark = pytest.mark.realdata


def test_contact_sheet_shows_two_bodies(mocap_root, tmp_path):
    m = load_motion(Path(mocap_root) / "cmu/boxing/13_18.bvh").slice(0, 2 * 120)
    scene = build_fighter_scene(fighter_spec(m.skeleton, [m]), 1)
    ref = build_reference(m, scene, fps=30.0)
    ro = record_rollout(scene, ref, PDController(), max_s=1.0)
    assert len(ro.qpos) == 31
    try:
        frames = render_frames(scene, ref, ro, [0, 30], width=160, height=120)
    except RuntimeError as e:  # no offscreen OpenGL on this machine
        pytest.skip(str(e))
    out = save_contact_sheet(frames, tmp_path / "sheet.png")
    assert out.stat().st_size > 1000
    for ref_img, sim_img in frames:
        assert ref_img.shape == (120, 160, 3)
        # A body covers a few percent of each panel; a blank frame covers none.
        for img in (ref_img, sim_img):
            assert image_stats(img)["foreground_share"] > 0.02
    # Frame 0 starts on the reference: the two panels look alike; later they may differ.
    a, b = frames[0]
    assert np.mean(np.abs(a[20:].astype(int) - b[20:].astype(int))) < 10
