"""A Python client of the NPC service of `igraph-fight play` (protocol: docs/npc_service.md).

    igraph-fight play --graph graph.igz &          # the server (prints its URL)
    python examples/npc_client.py --url ws://127.0.0.1:8765/ws

It asks the server what it serves (``info``), then plays the engine's part for a few decisions:
an observation of the NPC's live state in, the action id to launch out (with its label, the
off-graph flag and the server's decision time), a batch for a crowd, a style switch, and the
same request over HTTP. The observations here are made up from the library's ranges; a game
sends its real coupled state (distance, both facing angles, actions and frame).
"""
from __future__ import annotations

import argparse
import asyncio
import json
import random
import time

import aiohttp


class NPCClient:
    """One WebSocket connection to the NPC service; requests are answered in order."""

    def __init__(self, ws: aiohttp.ClientWebSocketResponse) -> None:
        self.ws = ws
        self.n = 0

    async def request(self, type_: str, **fields) -> dict:
        """Send one request (``type_`` and its fields) and return the reply (raises on an error reply)."""
        self.n += 1
        await self.ws.send_str(json.dumps({"v": 1, "type": type_, "id": self.n, **fields}))
        reply = json.loads((await self.ws.receive(timeout=30)).data)
        if reply.get("type") == "error":
            raise RuntimeError(f"{reply['code']}: {reply['message']}")
        return reply

    async def decide(self, obs: dict, **fields) -> dict:
        return await self.request("decide", obs=obs, **fields)


def made_up_observation(info: dict, rng: random.Random) -> dict:
    """A plausible observation within the library's ranges (a game sends its real state)."""
    lib = info["library"]
    m_other = rng.randrange(lib["n_actions"])
    return {"r": rng.uniform(0.8, 2.0), "theta_self": rng.uniform(-0.5, 0.5), "theta_other": rng.uniform(-0.5, 0.5),
            "m_self": rng.randrange(lib["n_actions"]), "m_other": m_other,
            "f_other": rng.randrange(lib["n_frames"][m_other])}


async def main(url: str, n: int, style: str) -> None:
    rng = random.Random(0)
    async with aiohttp.ClientSession() as client, client.ws_connect(url) as ws:
        npc = NPCClient(ws)
        info = await npc.request("info")
        g, lib = info["graph"], info["library"]
        print(f"server {info['version']}: graph {g['content_hash'][:12]} ({g['n_states']} states), "
              f"{lib['n_actions']} actions, style {info['style']}, depth {info['depth']}")
        for _ in range(n):
            obs = made_up_observation(info, rng)
            t0 = time.perf_counter()
            d = await npc.decide(obs)
            rtt = (time.perf_counter() - t0) * 1e3
            print(f"  m_self {obs['m_self']:3d} r {obs['r']:.2f} m -> action {d['action']:3d} ({d['label']}), "
                  f"off graph {d['off_graph']}, server {d['decision_us']:.0f} us, round trip {rtt:.2f} ms")
        crowd = [made_up_observation(info, rng) for _ in range(8)]
        b = await npc.request("decide", batch=crowd)
        print(f"  a crowd of {len(crowd)}: {[x['action'] for x in b['decisions']]} in {b['decision_us']:.0f} us")
        p = await npc.request("set_style", style=style)
        print(f"  style {p['style']} live after {p['policy_ms']:.0f} ms "
              f"({100 * p.get('changed_share', 0):.1f}% of the states changed their best action)")
        d = await npc.decide(crowd[0])
        print(f"  now: action {d['action']} ({d['label']}) under {d['style']}")
        http = url.replace("ws://", "http://").replace("wss://", "https://").rsplit("/ws", 1)[0] + "/decide"
        async with client.post(http, json={"v": 1, "type": "decide", "obs": crowd[0], "style": style}) as r:
            print(f"  HTTP POST {http}: {r.status} {await r.json()}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--url", default="ws://127.0.0.1:8765/ws", help="the service's WebSocket (default %(default)s)")
    ap.add_argument("--n", type=int, default=5, help="single decisions to ask for (default 5)")
    ap.add_argument("--style", default="outboxer", help="style to switch to (default outboxer)")
    a = ap.parse_args()
    asyncio.run(main(a.url, a.n, a.style))
