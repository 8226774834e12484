"""`play --physics`: the game's session with both fighters simulated: simulated poses streamed, a
key press reaching A's next decision, the NPC answering, the physics labelled, no saving."""
from __future__ import annotations

import numpy as np
import pytest

from igraph_fight.controller import NPCController
from igraph_fight.play.session import PlayConfig

pytestmark = pytest.mark.realdata

DT = 1.0 / 30.0


@pytest.fixture(scope="module")
def physics(small_graph):
    from tracker.bouts.play_physics import physics_play
    graph, lib = small_graph
    return graph, lib, physics_play(lib, graph.sim_params(), "pd-fixed=0.4")


def _tick(session, n, now=0.0):
    msgs = []
    for _ in range(n):
        now += DT
        msgs += session.tick(now)
    return msgs, now


def test_physics_session_streams_simulated_poses_and_obeys_keys(physics):
    graph, lib, play = physics
    npc = NPCController(graph, lib, style="balanced", depth=3)
    s = play.session(npc, npc, PlayConfig(seconds=4.0, seed=5), graph.content_hash)
    st = s.status()
    assert st["physics"] == "assisted physics (fixed assist, cap 0.4 mg)" and len(st["assist"]) == 2
    n_j = len(s.drawing["joints"])
    msgs, now = _tick(s, 30)
    frames = [m for m in msgs if m["type"] == "frame"]
    assert len(frames) >= 25
    pose = np.array(frames[-1]["pose"]).reshape(2, n_j, 3)
    assert np.isfinite(pose).all()
    head = s.drawing["head"]
    first = np.array(frames[2]["pose"]).reshape(2, n_j, 3)
    assert (first[:, head, 1] > 1.2).all(), first[:, head]      # standing at the start: the head up (Y up)
    # the pose streamed is the simulated bodies' (the joint sites now, in the page's axes)
    from tracker.body.humanoid import C_MOCAP_TO_MJ
    xpos = s.player.bout.env.data.site_xpos
    for k in (0, 1):
        np.testing.assert_allclose(pose[k], xpos[s.player.sites[k]] @ C_MOCAP_TO_MJ, atol=1e-3)
    assert 0.3 < frames[-1]["distance"] < 6.0 and len(frames[-1]["down"]) == 2
    p0 = np.array(frames[0]["pose"]).reshape(2, n_j, 3)
    assert np.abs(pose - p0).max() > 0.01
    # a key press reaches A's next decision, resolved by the category rule
    from tracker.bouts.play_physics import HumanAgent
    human = s.player.bout.agents[0]
    assert isinstance(human, HumanAgent)
    n0 = len(human.choices)
    s.command("jab")
    msgs2, now = _tick(s, 60, now)
    assert len(human.choices) > n0 and s.queued is None
    first = human.choices[n0]
    assert first["command"] == "jab" and first["source"] == "key"
    assert first["category"] == "jab" or first["level"] > 0          # the nearest category when no jab is legal
    b_dec = [m for m in msgs + msgs2 if m["type"] == "decision" and m["player"] == 1]
    assert b_dec                                                      # the NPC answers
    with pytest.raises(ValueError, match="not saved"):
        s.result()


def test_physics_play_needs_a_batched_tracker_label(physics):
    _, _, play = physics
    assert play.assisted and play.cap == 0.4


def test_the_physics_page_renders_simulated_fighters(physics, tmp_path):
    """The page in headless Chromium with a physics server: both fighters drawn, the HUD names the
    physics (assisted, with its cap) and the live assist. Screenshot: play_physics.png in tmp_path."""
    import os
    import time
    from pathlib import Path

    from igraph_fight.play.server import PlayServer, ServerThread, web_assets_missing
    chromium = Path("/usr/bin/chromium")
    missing = None if chromium.is_file() else f"{chromium} missing"
    missing = missing or web_assets_missing()
    try:
        from playwright import sync_api
    except ImportError:
        missing = missing or "the playwright package is missing"
    if missing:
        if os.environ.get("CI") == "true":
            pytest.fail(missing)
        pytest.skip(missing)
    graph, _, play = physics
    srv = PlayServer(graph, style="balanced", depth=3, seconds=20.0, save_dir=None, physics=play)
    th = ServerThread(srv).start()
    pw = sync_api.sync_playwright().start()
    browser = pw.chromium.launch(executable_path=str(chromium),
                                 args=["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                                       "--disable-background-networking", "--disable-component-update"])
    try:
        pg = browser.new_page(viewport={"width": 1280, "height": 720})
        errors: list[str] = []
        pg.on("pageerror", lambda e: errors.append(str(e)))
        pg.goto(th.url)
        t0 = time.monotonic()
        while time.monotonic() - t0 < 30 and not pg.evaluate(
                "() => window.__play && window.__play.framesReceived > 30 && window.__play.rendered > 10"):
            time.sleep(0.1)
        hud = pg.evaluate("() => document.getElementById('physics').textContent")
        shot = tmp_path / "play_physics.png"
        pg.screenshot(path=str(shot))
        assert not errors, errors
        assert "assisted physics (fixed assist, cap 0.4 mg)" in hud and "assist now A" in hud, hud
        assert shot.stat().st_size > 20_000
        if os.environ.get("IGRAPH_FIGHT_SHOT_DIR"):
            import shutil
            shutil.copy(shot, Path(os.environ["IGRAPH_FIGHT_SHOT_DIR"]) / shot.name)
    finally:
        browser.close()
        pw.stop()
        th.stop()
