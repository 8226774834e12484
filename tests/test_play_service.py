"""The network NPC service on loopback: the protocol's answers (WebSocket /ws and HTTP POST
/decide), their schema, the errors it replies instead of failing, 100 concurrent clients for 10 s
while 10,000 garbage frames arrive, rate and size limits. Correctness only: no timings asserted
(benchmarks/bench_npc_service.py measures them)."""
from __future__ import annotations

import asyncio
import json
import random

import aiohttp
import numpy as np
import pytest

from igraph_fight.controller import NPCController, observe
from igraph_fight.play import protocol as pr
from igraph_fight.play.server import PlayServer, ServerThread

pytestmark = pytest.mark.realdata


@pytest.fixture(scope="module")
def served(small_graph, tmp_path_factory):
    graph, lib = small_graph
    srv = PlayServer(graph, style="balanced", depth=3, save_dir=tmp_path_factory.mktemp("bouts"))
    th = ServerThread(srv).start()
    yield srv, th
    th.stop()


@pytest.fixture(scope="module")
def observations(small_graph):
    """Observations of real decision instants (a seeded bout of random legal actions)."""
    from igraph_fight.game import FightGame, GameConfig
    graph, lib = small_graph
    game = FightGame(lib, GameConfig(max_seconds=1e6, sim=graph.sim_params()))
    rng = np.random.default_rng(0)
    st = game.new_initial_state(rng)
    out = []
    while len(out) < 200:
        p = st.current_player()
        o = observe(st, p)
        out.append({"r": o.r, "theta_self": o.theta_self, "theta_other": o.theta_other, "m_self": o.m_self,
                    "m_other": o.m_other, "f_other": o.f_other, "mask_other": o.mask_other})
        st.apply_action(int(rng.choice(st.legal_actions(p))))
    return out


def _run(coro):
    return asyncio.run(coro)


async def _ws_roundtrip(url: str, msgs: list, binary: bool = False) -> list[dict]:
    async with aiohttp.ClientSession() as s, s.ws_connect(url + "ws", max_msg_size=0) as ws:
        out = []
        for m in msgs:
            if isinstance(m, (bytes, bytearray)):
                await ws.send_bytes(bytes(m))
            else:
                await ws.send_str(m if isinstance(m, str) else json.dumps(m))
            out.append(json.loads((await ws.receive(timeout=30)).data))
        return out


def _valid_reply(r: dict) -> bool:
    return pr.validator("reply").is_valid(r)


def test_info_health_and_decisions_follow_the_schema_and_the_library(served, observations, small_graph):
    srv, th = served
    graph, lib = small_graph
    ref = NPCController(graph, lib, style="balanced", depth=3)
    obs = observations[:20]
    msgs = [{"v": 1, "type": "info", "id": 1}, {"v": 1, "type": "health"}]
    msgs += [{"v": 1, "type": "decide", "id": f"d{k}", "obs": o} for k, o in enumerate(obs)]
    msgs += [{"v": 1, "type": "decide", "id": "batch", "batch": obs}]
    rep = _run(_ws_roundtrip(th.url, msgs))
    assert all(_valid_reply(r) for r in rep), [r for r in rep if not _valid_reply(r)][:2]
    info, health = rep[0], rep[1]
    assert info["id"] == 1 and info["library"]["n_actions"] == lib.n_actions and info["graph"]["content_hash"] == graph.content_hash
    assert info["library"]["n_frames"] == np.diff(lib.frame_offsets).tolist() and info["limits"]["max_batch"] == pr.MAX_BATCH
    assert health["status"] == "ok" and health["graph"] == graph.content_hash
    from igraph_fight.controller import Observation
    for k, (o, r) in enumerate(zip(obs, rep[2:-1])):
        want = ref.act(Observation(**o))
        assert r["id"] == f"d{k}" and r["action"] == want.action and r["off_graph"] == want.off_graph
        assert r["action"] in lib.next(o["m_self"]) and r["label"] == lib.labels[r["action"]]
        assert r["decision_us"] >= 0 and (r["style"], r["depth"]) == ("balanced", 3)
    batch = rep[-1]
    assert batch["type"] == "decisions" and [d["action"] for d in batch["decisions"]] == [r["action"] for r in rep[2:-1]]
    ref.close()


def test_set_style_and_depth_change_the_policy(served, observations):
    srv, th = served
    o = observations[0]
    rep = _run(_ws_roundtrip(th.url, [
        {"v": 1, "type": "set_style", "style": "infighter", "id": "s"},
        {"v": 1, "type": "decide", "obs": o},
        {"v": 1, "type": "set_depth", "depth": 2},
        {"v": 1, "type": "decide", "obs": o},
        {"v": 1, "type": "set_style", "style": "no_such_style"},
        {"v": 1, "type": "set_style", "style": "/etc/passwd"},
        {"v": 1, "type": "decide", "obs": o, "style": "outboxer", "depth": 1},
    ]))
    assert all(_valid_reply(r) for r in rep)
    assert rep[0]["type"] == "policy" and rep[0]["style"] == "infighter" and rep[0]["id"] == "s"
    assert 0.0 < rep[0]["changed_share"] <= 1.0
    assert (rep[1]["style"], rep[1]["depth"]) == ("infighter", 3)
    assert rep[2]["type"] == "policy" and (rep[3]["style"], rep[3]["depth"]) == ("infighter", 2)
    assert rep[4]["code"] == "bad_style" and rep[5]["code"] == "bad_style"
    assert (rep[6]["style"], rep[6]["depth"]) == ("outboxer", 1)


def test_refused_messages_get_error_replies_and_the_connection_stays(served, observations, small_graph):
    srv, th = served
    graph, lib = small_graph
    o = observations[0]
    nf = int(np.diff(lib.frame_offsets)[o["m_other"]])
    before = srv.counters["internal_errors"]
    rep = _run(_ws_roundtrip(th.url, [
        "nonsense", b"\x00\x01binary", {"v": 1, "type": "decide", "obs": {**o, "m_self": lib.n_actions}},
        {"v": 1, "type": "decide", "obs": {**o, "f_other": nf}}, {"v": 1, "type": "decide", "obs": {**o, "r": -1}},
        "x" * (pr.MAX_MESSAGE_BYTES + 10), {"v": 1, "type": "health", "id": "still-up"},
    ]))
    assert [r.get("code") for r in rep[:6]] == ["bad_json", "binary", "bad_observation", "bad_observation", "invalid",
                                                "too_large"]
    assert rep[6]["type"] == "health" and rep[6]["id"] == "still-up"
    assert all(_valid_reply(r) for r in rep) and srv.counters["internal_errors"] == before


def test_a_controller_value_error_becomes_an_error_reply(served, observations):
    srv, th = served

    class ObservationError(ValueError):
        pass

    def refuse(obs):
        raise ObservationError("out-of-range observation")
    c = srv.pool.cached("balanced", 3)
    c.act = refuse
    try:
        rep = _run(_ws_roundtrip(th.url, [{"v": 1, "type": "decide", "obs": observations[0], "id": 5},
                                          {"v": 1, "type": "health"}]))
    finally:
        del c.act
    assert rep[0]["code"] == "bad_observation" and "out-of-range" in rep[0]["message"] and rep[0]["id"] == 5
    assert rep[1]["status"] == "ok"


def test_http_decide(served, observations):
    srv, th = served

    async def go():
        out = []
        async with aiohttp.ClientSession() as s:
            async def post(body, **kw):
                async with s.post(th.url + "decide", data=body, **kw) as r:
                    out.append((r.status, await r.json()))
            await post(json.dumps({"v": 1, "type": "decide", "obs": observations[1], "id": 9}))
            await post(json.dumps({"v": 1, "type": "decide", "batch": observations[:5], "style": "outboxer"}))
            await post("garbage")
            await post(b"{" + b" " * (pr.MAX_MESSAGE_BYTES + 1) + b"}")
            await post(json.dumps({"v": 1, "type": "set_style", "style": "outboxer"}))
            await post(json.dumps({"v": 1, "type": "health"}), headers={"Origin": "http://evil.example"})
            async with s.get(th.url + "health") as r:
                out.append((r.status, await r.json()))
            async with s.get(th.url + "health", headers={"Host": "rebound.example:8765"}) as r:
                out.append((r.status, await r.json()))
        return out
    res = _run(go())
    assert res[0][0] == 200 and res[0][1]["type"] == "decision" and res[0][1]["id"] == 9
    assert res[1][0] == 200 and len(res[1][1]["decisions"]) == 5 and res[1][1]["style"] == "outboxer"
    assert [r[0] for r in res[2:6]] == [400, 413, 400, 403]
    assert res[2][1]["code"] == "bad_json" and res[3][1]["code"] == "too_large" and res[4][1]["code"] == "bad_request"
    assert res[6][0] == 200 and {"status", "version", "graph"} <= set(res[6][1])
    assert res[7][0] == 421 and res[7][1]["code"] == "bad_request"  # a loopback server answers loopback names only


def test_rate_limit_answers_with_errors(served):
    srv, th = served
    srv.rate = (5.0, 10.0)
    try:
        rep = _run(_ws_roundtrip(th.url, [{"v": 1, "type": "health"}] * 30))
    finally:
        srv.rate = (pr.RATE_PER_S, pr.RATE_BURST)
    codes = [r.get("code") for r in rep]
    assert codes[:10] == [None] * 10 and "rate_limited" in codes[10:]


def _garbage(rng: random.Random, o: dict, n_actions: int) -> tuple[object, set]:
    """A hostile frame and the error codes it may get."""
    k = rng.randrange(9)
    if k == 0:
        return "".join(chr(rng.randrange(32, 0x2FF)) for _ in range(rng.randrange(1, 60))), {"bad_json"}
    if k == 1:
        return json.dumps(rng.choice([[], 3, "s", None, True, {"v": 1}, {"type": 5}])), {"bad_json", "invalid"}
    if k == 2:
        return json.dumps({"v": 1, "type": "decide", "obs": {**o, "r": rng.choice(["x", None, [1], {}])}}), {"invalid"}
    if k == 3:
        return '{"v": 1, "type": "decide", "obs": {"r": 1e400}}', {"invalid"}
    if k == 4:
        return '{"v": 1, "type": "info", "id": ' + "9" * rng.randrange(5000, 9000) + "}", {"bad_json"}
    if k == 5:
        return json.dumps({"v": 1, "type": "decide", "obs": {**o, "m_other": n_actions + rng.randrange(10 ** 6)}}), \
            {"bad_observation"}
    if k == 6:
        return bytes(rng.randrange(256) for _ in range(rng.randrange(1, 64))), {"binary"}
    if k == 7:
        return '{"v": 1, "type": "decide", "obs": NaN}', {"bad_json"}
    return "[" * 3000 + "]" * 3000, {"bad_json"}


@pytest.mark.slow
def test_100_clients_for_10_s_while_10000_garbage_frames_arrive(served, observations, small_graph):
    srv, th = served
    graph, lib = small_graph
    menus = {m: set(lib.next(m).tolist()) for m in range(lib.n_actions)}
    before = dict(srv.counters)
    n_clients, seconds, n_garbage_conns, per_conn = 100, 10.0, 10, 1000
    huge = "{" + " " * (10 * 1024 * 1024) + "}"   # a 10 MB message
    stats = {"answered": 0, "wrong": [], "garbage_replies": 0, "garbage_wrong": []}

    async def client(k: int, s: aiohttp.ClientSession) -> int:
        rng = random.Random(k)
        n = 0
        async with s.ws_connect(th.ws_url + "ws") as ws:
            t_end = asyncio.get_running_loop().time() + seconds
            while asyncio.get_running_loop().time() < t_end:
                if rng.random() < 0.1:
                    batch = rng.sample(observations, 4)
                    await ws.send_str(json.dumps({"v": 1, "type": "decide", "id": n, "batch": batch}))
                    r = json.loads((await ws.receive(timeout=30)).data)
                    ok = r.get("id") == n and [d["action"] in menus[o["m_self"]] for o, d in zip(batch, r["decisions"])]
                    ok = ok and all(ok)
                else:
                    o = rng.choice(observations)
                    await ws.send_str(json.dumps({"v": 1, "type": "decide", "id": n, "obs": o}))
                    r = json.loads((await ws.receive(timeout=30)).data)
                    ok = r.get("id") == n and r.get("type") == "decision" and r["action"] in menus[o["m_self"]]
                if not ok:
                    stats["wrong"].append(r)
                n += 1
                await asyncio.sleep(0.05)
        stats["answered"] += n
        return n

    async def garbage(k: int, s: aiohttp.ClientSession) -> None:
        rng = random.Random(1000 + k)
        frames = [_garbage(rng, rng.choice(observations), lib.n_actions) for _ in range(per_conn - 1)]
        frames.insert(rng.randrange(per_conn), (huge, {"too_large"}))
        async with s.ws_connect(th.ws_url + "ws") as ws:
            async def send():
                for f, _ in frames:
                    if isinstance(f, bytes):
                        await ws.send_bytes(f)
                    else:
                        await ws.send_str(f)
                    await asyncio.sleep(0)
            sender = asyncio.ensure_future(send())
            for f, codes in frames:
                r = json.loads((await ws.receive(timeout=60)).data)
                stats["garbage_replies"] += 1
                if r.get("type") != "error" or r.get("code") not in codes:
                    stats["garbage_wrong"].append((str(f)[:80], r))
            await sender
            await ws.send_str(json.dumps({"v": 1, "type": "health", "id": "after"}))
            r = json.loads((await ws.receive(timeout=30)).data)
            assert r.get("id") == "after" and r.get("status") == "ok"

    async def main():
        conn = aiohttp.TCPConnector(limit=0)
        async with aiohttp.ClientSession(connector=conn) as s:
            jobs = [client(k, s) for k in range(n_clients)] + [garbage(k, s) for k in range(n_garbage_conns)]
            return await asyncio.gather(*jobs)
    res = _run(main())
    per_client = res[:n_clients]
    assert not stats["wrong"], stats["wrong"][:3]
    assert all(n > 0 for n in per_client)
    assert stats["garbage_replies"] == n_garbage_conns * per_conn and not stats["garbage_wrong"], stats["garbage_wrong"][:3]
    assert srv.counters["internal_errors"] == before["internal_errors"] == 0
    assert srv.counters["errors_replied"] - before["errors_replied"] >= n_garbage_conns * per_conn
