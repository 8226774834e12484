"""The live game without a browser: the streamed joint positions, a key press reaching A's next
decision by the category rule, the NPC answering, saving in the `fight` log format, exact
replays, hostile logs, the human column of Table 1, the cached demo graph and the CLI."""
from __future__ import annotations

import json
import os

import numpy as np
import pytest

from igraph_fight.controller import NPCController, observe
from igraph_fight.game import FightGame, GameConfig
from igraph_fight.play.bouts import ReplayError, bout_folder, list_bouts, replay_player, save_bout
from igraph_fight.play.commands import categories, rate_menu, resolve
from igraph_fight.play.session import GameSession, PlayConfig

pytestmark = pytest.mark.realdata

DT = 1.0 / 30.0


@pytest.fixture(scope="module")
def setup(small_graph):
    graph, lib = small_graph
    npc = NPCController(graph, lib, style="balanced", depth=3)
    game = FightGame(lib, GameConfig(sim=graph.sim_params()), tables=npc.tables)
    return graph, lib, npc, game


def _session(setup, seconds=4.0, seed=3, idle="guard", npc=None):
    graph, lib, base, game = setup
    cfg = PlayConfig(seconds=seconds, style="balanced", depth=3, idle=idle, seed=seed)
    return GameSession(game, npc or base, base, cfg, graph.content_hash)


def _run(session, until=None, max_frames=10_000):
    """Tick the session on a synthetic clock (one frame a tick) until done or ``until(msgs)``."""
    msgs = []
    now = getattr(session, "_test_now", 0.0)
    for _ in range(max_frames):
        now += DT
        new = session.tick(now)
        msgs += new
        if session.over or (until is not None and until(new)):
            break
    session._test_now = now
    return msgs


def test_streamed_positions_are_the_bout_motion(setup):
    from igraph_fight.match import fighter_motion
    from igraph_fight.play.drawing import body_drawing, world_positions

    s = _session(setup, seconds=3.0, idle="best")
    _run(s)
    lib = setup[1]
    tr = s.player.trace_arrays()
    d = body_drawing(lib)
    assert len(d["bones"]) >= 12 and d["head"] >= 0 and min(d["fists"]) >= 0
    for who in (0, 1):
        ref = fighter_motion(s.bout_game, tr, who).positions()[:, d["joints"]]
        for k in (0, len(tr["t"]) // 2, len(tr["t"]) - 1):
            from igraph_fight.state import WorldState
            w = WorldState.new(tuple(tr["pose"][k, :, 0]), tuple(tr["pose"][k, :, 1]), tuple(tr["pose"][k, :, 2]),
                               tuple(tr["action"][k]), tuple(tr["frame"][k]))
            np.testing.assert_allclose(world_positions(lib, w, d["joints"])[who], ref[k], atol=1e-6)


def _until_a_decides(s):
    """Step the bout to an instant where A is the next to choose (its observation is then final)."""
    p = s.player
    for _ in range(5000):
        if not p.buffer and not p.done and p.state.current_player() == 0:
            return True
        p.step()
    return False


@pytest.mark.parametrize("command", ["jab", "straight", "guard", "dodge", "forward", "back", "turn_left"])
def test_a_key_press_launches_the_best_rated_action_of_its_category_at_the_next_decision(setup, command):
    graph, lib, npc, game = setup
    s = _session(setup, seconds=20.0, seed=11)
    assert _until_a_decides(s)
    s.command(command)
    acts, scores = rate_menu(npc, observe(s.player.state, 0))
    want = resolve(command, acts, scores, lib.kinds)
    n = len(s.player.decisions)
    s.player.step()
    d = next(x for x in s.player.decisions[n:] if x["player"] == 0)
    assert (d["command"], d["source"], d["action"]) == (command, "key", want.action)
    assert d["action"] in acts and d["category"] == lib.labels[d["action"]]
    assert d["category"] == categories(command)[d["level"]] if d["level"] >= 0 else True
    # the command was used once: A's next decision without a key is the idle guard
    assert _until_a_decides(s)
    s.player.step()
    d2 = [x for x in s.player.decisions if x["player"] == 0][-1]
    assert d2["source"] == "idle" and d2["command"] == "guard"


def test_a_held_key_repeats_and_b_answers_with_the_npc(setup):
    s = _session(setup, seconds=6.0, seed=5)
    s.command("jab", held=True)
    _run(s, max_frames=90)
    a = [d for d in s.player.decisions if d["player"] == 0]
    b = [d for d in s.player.decisions if d["player"] == 1]
    assert len(a) >= 2 and a[0]["source"] == "key" and all(d["source"] == "held" for d in a[1:])
    assert all(d["command"] == "jab" for d in a)
    assert b and all("off_graph" in d for d in b)
    s.release("jab")
    n = len(a)
    _run(s, max_frames=60)
    assert all(d["source"] == "idle" for d in [d for d in s.player.decisions if d["player"] == 0][n + 1:])


def test_frames_hits_and_hud_are_streamed(setup):
    s = _session(setup, seconds=8.0, seed=2, idle="best")
    msgs = _run(s)
    frames = [m for m in msgs if m["type"] == "frame"]
    assert len(frames) == int(round(8.0 * 30)) + 1 and [f["i"] for f in frames] == list(range(len(frames)))
    last = frames[-1]
    assert last["hits"] == [int(x) for x in s.player.hits] and last["score"] == last["hits"][0] - last["hits"][1]
    assert len(last["pose"][0]) == 3 * len(s.drawing["joints"]) and last["time_left"] == 0.0
    assert all(len(f["labels"]) == 2 for f in frames)
    hits = sum(len(f.get("hit_events", [])) for f in frames)
    assert hits == len(s.player.hit_events) == int(s.player.hits.sum())
    assert s.over and s.status()["mode"] == "over"


def test_save_writes_the_fight_log_and_a_replay_reproduces_the_bout(setup, tmp_path):
    graph, lib, npc, game = setup
    other = NPCController(graph, lib, style="infighter", depth=2)
    s = _session(setup, seconds=6.0, seed=9, idle="best")
    s.command("jab")
    _run(s, max_frames=60)
    s.set_npc(other, "infighter")
    _run(s)
    name, folder = save_bout(s, tmp_path)
    lines = [json.loads(x) for x in (folder / "log.jsonl").read_text().splitlines()]
    assert lines[0]["type"] == "meta" and {x["type"] for x in lines} >= {"meta", "action", "distance"}
    meta = lines[0]
    assert meta["complete"] and meta["npc_styles"] == ["balanced", "infighter"] and meta["npc_depths"] == [3, 2]
    assert meta["library"] and meta["graph"] == graph.content_hash
    summary = json.loads((folder / "summary.json").read_text())
    assert {"a", "b", "hits_a", "hits_b", "score", "artifacts"} <= set(summary)
    assert [summary["hits_a"], summary["hits_b"]] == s.player.hits.tolist()
    assert not any(p.name.startswith(".tmp") for p in tmp_path.iterdir())
    assert list_bouts(tmp_path)[0]["name"] == name
    # the replay re-simulates the logged decisions: the same frames, hits and decisions
    from igraph_fight.graph import library_fingerprint
    player, expected = replay_player(bout_folder(tmp_path, name), game, library_fingerprint(lib))
    while player.step() is not None:
        pass
    assert player.hits.tolist() == expected["hits"] == s.player.hits.tolist()
    live, rep = s.player.trace_arrays(), player.trace_arrays()
    np.testing.assert_array_equal(rep["action"], live["action"])
    np.testing.assert_allclose(rep["pose"], live["pose"])
    assert [(d["player"], d["action"]) for d in player.decisions] == \
        [(d["player"], d["action"]) for d in s.player.decisions if d["t"] <= s.player.time_s]
    other.close()


def test_a_partial_save_replays_to_where_it_was_saved(setup, tmp_path):
    graph, lib, npc, game = setup
    s = _session(setup, seconds=30.0, seed=4, idle="best")
    _run(s, max_frames=75)
    name, folder = save_bout(s, tmp_path)
    from igraph_fight.graph import library_fingerprint
    player, expected = replay_player(folder, game, library_fingerprint(lib))
    while player.step() is not None:
        pass
    assert player.played == s.player.played and player.hits.tolist() == s.player.hits.tolist()
    assert not json.loads((folder / "log.jsonl").read_text().splitlines()[0])["complete"]


def test_hostile_logs_do_not_replay(setup, tmp_path):
    graph, lib, npc, game = setup
    from igraph_fight.graph import library_fingerprint
    fp = library_fingerprint(lib)
    s = _session(setup, seconds=2.0, seed=1, idle="best")
    _run(s)
    name, folder = save_bout(s, tmp_path)
    good = (folder / "log.jsonl").read_text().splitlines()
    meta = json.loads(good[0])

    def variant(lines, tag):
        d = tmp_path / tag
        d.mkdir()
        (d / "log.jsonl").write_text("\n".join(lines) + "\n")
        return d

    actions = [i for i, x in enumerate(good) if json.loads(x)["type"] == "action"]
    bad_action = list(good)
    x = json.loads(good[actions[1]])
    x["action"] = 10 ** 9
    bad_action[actions[1]] = json.dumps(x)
    wrong_player = list(good)
    y = json.loads(good[actions[0]])
    y["player"] = 1 - y["player"]
    wrong_player[actions[0]] = json.dumps(y)
    cases = {
        "garbage": ["{not json"] + good[1:],
        "no_meta": good[1:],
        "other_library": [json.dumps({**meta, "library": "0" * 64})] + good[1:],
        "bad_start": [json.dumps({**meta, "start": {**meta["start"], "x": [1e400, 0]}})] + good[1:],
        "nan_start": [json.dumps({**meta, "start": {**meta["start"], "x": ["a", 0]}})] + good[1:],
        "bad_action": bad_action,
        "wrong_player": wrong_player,
        "too_long": [json.dumps({**meta, "played_s": 1e9})] + good[1:],
        "not_an_object": ["[1, 2, 3]"] + good[1:],
        "deep": ["[" * 100_000 + "]" * 100_000] + good[1:],
    }
    for tag, lines in cases.items():
        with pytest.raises(ReplayError):
            player, _ = replay_player(variant(lines, tag), game, fp)
            while player.step() is not None:
                pass
    for name in ("../x", "", "a/b", "x" * 200):
        with pytest.raises(ReplayError):
            bout_folder(tmp_path, name)


def test_human_bouts_feed_the_human_column_of_table_1(setup, small_graph, tmp_path):
    from igraph_fight.evaluate.config import EvalConfig
    from igraph_fight.evaluate.human_logs import human_table
    from igraph_fight.evaluate.runner import evaluate

    graph, lib, npc, game = setup
    logs = tmp_path / "logs"
    want: dict[int, list[float]] = {1: [], 3: []}
    for seed, depth in ((1, 1), (2, 1), (3, 3)):
        c = NPCController(graph, lib, style="outboxer", depth=depth)
        s = _session(setup, seconds=3.0, seed=seed, idle="best", npc=c)
        s.npc_style = "outboxer"
        s.styles_used = ["outboxer"]
        s.depths_used = [depth]
        _run(s)
        save_bout(s, logs)
        want[depth].append(float(s.player.hits[1] - s.player.hits[0]))
        c.close()
    partial = _session(setup, seconds=30.0, seed=7)
    _run(partial, max_frames=20)
    save_bout(partial, logs)
    (logs / "junk").mkdir()
    (logs / "junk" / "log.jsonl").write_text("garbage\n")
    h = human_table(logs, (1, 3, 5), graph.content_hash)
    assert h["rows"]["IG(1)"]["bouts"] == 2 and h["rows"]["IG(3)"]["bouts"] == 1 and h["rows"]["IG(5)"]["bouts"] == 0
    assert h["rows"]["IG(1)"]["mean"] == pytest.approx(np.mean(want[1]))
    assert h["rows"]["IG(3)"]["mean"] == pytest.approx(want[3][0])
    assert h["rows"]["IG(1)"]["styles"] == ["outboxer"] and h["other_graph"] == 0
    assert len(h["skipped"]) == 2  # the partial bout and the garbage log
    gpath = tmp_path / "g.igz"
    graph.save(gpath)
    rep = evaluate(EvalConfig(graph=str(gpath), opponents=("human",), depths=(1, 3), exact2_depths=(), bouts=2,
                              seconds=3.0, head_to_head=(), regret_every=0, progress=False, human_logs=str(logs)),
                   tmp_path / "eval")
    assert rep["human_logs"]["rows"]["IG(1)"]["bouts"] == 2
    md = (tmp_path / "eval" / "report.md").read_text()
    assert "people in `igraph-fight play` beside the scripted proxy" in md and "| IG(1) |" in md


def test_the_demo_graph_is_built_once_and_reused(boxing_files, tmp_path, monkeypatch):
    from igraph_fight.build.pipeline import BuildOptions
    from igraph_fight.play.demo_graph import ensure_demo_graph
    import io

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    mocap = str(boxing_files[0].parent.parent.parent)
    small = BuildOptions(max_samples=2000, n_initial=16, chunk_parents=64, seed_bouts=0)
    out = io.StringIO()
    p = ensure_demo_graph(mocap, progress=False, out=out, options=small)
    assert p == tmp_path / "igraph-fight" / "play" / "graph.igz" and p.is_file() and "building" in out.getvalue()
    mtime = p.stat().st_mtime_ns
    out2 = io.StringIO()
    assert ensure_demo_graph(mocap, progress=False, out=out2, options=small) == p
    assert out2.getvalue() == "" and p.stat().st_mtime_ns == mtime
    other = BuildOptions(max_samples=2500, n_initial=16, chunk_parents=64, seed_bouts=0)
    out3 = io.StringIO()
    ensure_demo_graph(mocap, progress=False, out=out3, options=other)
    assert "building" in out3.getvalue() and p.stat().st_mtime_ns != mtime


def test_cli_play_checks_its_options_and_says_how_to_install_three(tmp_path, monkeypatch, capsys):
    from igraph_fight.cli import build_parser, main
    from igraph_fight.play import server

    assert main(["play", "--tracker", "pd"]) == 2            # --tracker without --physics
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--physics" in err
    msg = server.web_assets_missing(tmp_path)
    assert msg is not None and server.NPM_STEP in msg
    monkeypatch.setattr(server, "web_assets_missing", lambda web_dir=None: msg)
    assert main(["play"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "npm ci --prefix igraph_fight/play/web" in err
    a = build_parser().parse_args(["play", "--graph", "g.igz", "--host", "0.0.0.0", "--port", "0", "--style", "outboxer",
                                   "--depth", "5"])
    assert (a.host, a.port, a.style, a.depth, a.physics) == ("0.0.0.0", 0, "outboxer", 5, False)
    assert os.path.isfile(server.WEB_DIR / "package-lock.json")
