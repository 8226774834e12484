"""The game page end to end in headless Chromium (the Python playwright package driving
/usr/bin/chromium): it loads, both fighters render (a screenshot saved under the test's tmp
folder), key presses make A perform actions of the pressed category, B answers, the HUD updates,
switching B's style and depth changes the policy (the server says so), a saved bout replays.

Skipped when /usr/bin/chromium or the page's three.js (npm) is missing, except on CI (CI=true),
where that fails."""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

from igraph_fight.play.commands import categories
from igraph_fight.play.server import NPM_STEP, PlayServer, ServerThread, web_assets_missing

pytestmark = pytest.mark.realdata

CHROMIUM = Path("/usr/bin/chromium")
#: the flags the page's tests launch Chromium with (no sandbox in containers; without the
#: background-networking flags Chromium floods a closed network)
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def _need(ok: bool, why: str) -> None:
    if not ok:
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(why)


@pytest.fixture(scope="module")
def page(small_graph, tmp_path_factory):
    _need(CHROMIUM.is_file(), f"{CHROMIUM} missing (apt-get install -y chromium chromium-driver)")
    _need(web_assets_missing() is None, f"three.js missing ({NPM_STEP})")
    try:
        from playwright import sync_api
    except ImportError:
        sync_api = None
    _need(sync_api is not None, "the playwright package is missing (pip install -e '.[test]')")
    graph, _ = small_graph
    srv = PlayServer(graph, style="balanced", depth=3, seconds=60.0, save_dir=tmp_path_factory.mktemp("bouts"))
    th = ServerThread(srv).start()
    pw = sync_api.sync_playwright().start()
    browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
    pg = browser.new_page(viewport={"width": 1280, "height": 720})
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    pg.goto(th.url)
    yield pg, srv, errors
    browser.close()
    pw.stop()
    th.stop()


def _state(pg, expr: str):
    return pg.evaluate(f"() => {expr}")


def _wait(pg, expr: str, timeout: float = 20.0):
    """Poll a JavaScript expression until truthy (the page's CSP forbids playwright's wait_for_function)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        v = _state(pg, expr)
        if v:
            return v
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {expr}")


def test_the_page_loads_and_both_fighters_render(page, tmp_path):
    from matplotlib.image import imread

    pg, srv, errors = page
    _wait(pg, "window.__play && window.__play.framesReceived > 15 && window.__play.rendered > 5")
    try:
        for _ in range(20):                               # a hit's white flash hides a fighter's colour
            _state(pg, "(window.__play.frozen = true)")    # hold the view still: the trunks stay where measured
            time.sleep(0.3)
            if not any(_state(pg, "window.__play.flashing")):
                break
            _state(pg, "(window.__play.frozen = false)")
            time.sleep(0.2)
        trunk = _state(pg, "window.__play.trunk")
        shot = tmp_path / "play.png"
        pg.screenshot(path=str(shot))
    finally:
        _state(pg, "(window.__play.frozen = false)")      # the other tests need a live view
    img = imread(str(shot))[..., :3]
    assert shot.stat().st_size > 20_000
    for who, (want, other) in enumerate(((0, 2), (2, 0))):   # A red, B blue
        votes = 0
        for x, y in trunk[who]:
            patch = img[max(int(y) - 2, 0):int(y) + 3, max(int(x) - 2, 0):int(x) + 3].reshape(-1, 3)
            votes += int(np.mean(patch[:, want] - patch[:, other]) > 0.15)
        assert votes >= 2, f"fighter {'AB'[who]} not drawn at {trunk[who]} (screenshot {shot})"
    hud = _state(pg, "document.getElementById('hits-a').textContent + '|' + document.getElementById('style-b').textContent")
    assert hud.split("|")[1] == "balanced"
    keys = _state(pg, "document.querySelectorAll('#key-table tr').length")
    assert keys == 11
    _state(pg, "(window.__play.frozen = false)")
    assert not errors, errors


def test_key_presses_drive_a_and_b_answers(page):
    pg, srv, errors = page
    _wait(pg, "window.__play.framesReceived > 5")
    t_left0 = _state(pg, "window.__play.hud.time_left")
    results = []
    for key, cmd in (("KeyJ", "jab"), ("KeyL", "dodge"), ("KeyK", "straight")):
        n0 = _state(pg, "window.__play.decisions.length")
        pg.keyboard.down(key)
        pg.keyboard.up(key)
        d = _wait(pg, f"window.__play.decisions.slice({n0}).find(d => d.player === 0 && d.source === 'key')", 10)
        assert d["command"] == cmd
        if d["level"] >= 0:
            assert d["category"] == categories(cmd)[d["level"]] == d["label"]
        results.append(d)
        # the HUD shows A's new action
        _wait(pg, f"window.__play.hud.labels && window.__play.hud.labels[0] === {d['label']!r}", 10)
    assert any(d["level"] == 0 for d in results), results
    b = _state(pg, "window.__play.decisions.filter(d => d.player === 1)")
    assert len(b) >= 2 and all("off_graph" in d for d in b)
    assert _state(pg, "window.__play.hud.time_left") < t_left0
    assert _state(pg, "document.getElementById('cmd-a').textContent").startswith(("jab", "dodge", "straight", "no command"))
    assert not errors, errors


def test_switching_b_style_and_depth_changes_the_policy(page):
    pg, srv, errors = page
    n0 = _state(pg, "window.__play.policies.length")
    pg.select_option("#style-select", "outboxer")
    p = _wait(pg, f"window.__play.policies[{n0}]", 20)
    assert p["style"] == "outboxer" and p["depth"] == 3 and p["changed_share"] > 0
    _wait(pg, "document.getElementById('style-b').textContent === 'outboxer'")
    pg.evaluate("() => { const d = document.getElementById('depth'); d.value = 4; d.dispatchEvent(new Event('change')); }")
    p = _wait(pg, f"window.__play.policies[{n0 + 1}]", 20)
    assert p["depth"] == 4 and p["style"] == "outboxer" and p["changed_share"] > 0
    _wait(pg, "document.getElementById('depth-b').textContent === '4'")
    t = _state(pg, "window.__play.status")
    assert (t["style"], t["depth"]) == ("outboxer", 4)
    assert not errors, errors


def test_a_saved_bout_replays_in_the_page(page):
    pg, srv, errors = page
    pg.click("#save")
    saved = _wait(pg, "window.__play.saved", 10)
    assert (Path(saved["folder"]) / "log.jsonl").is_file()
    _wait(pg, f"window.__play.bouts && window.__play.bouts.some(b => b.name === {saved['name']!r})", 10)
    pg.select_option("#bouts", saved["name"])
    pg.select_option("#speed", "4")
    pg.click("#replay")
    _wait(pg, "window.__play.status.mode === 'replay'", 10)
    assert _state(pg, "document.getElementById('banner').textContent") == "REPLAY"
    end = _wait(pg, "window.__play.replayEnd", 30)
    assert end["matches_log"] and end["hits"] == saved["hits"]
    assert abs(end["seconds"] - saved["seconds"]) < 1e-6
    assert not errors, errors
