"""Benchmark `igraph-fight play`: the NPC service's round trips and the game page in headless Chromium.

    python benchmarks/bench_npc_service.py --graph G.igz [--seconds 10] [--rate 30] [--json out.json]

Starts the server as its own process (`igraph-fight play --port 0`), then measures:
  A. decision round trip (client send -> reply received, WebSocket /ws on loopback) p50 / p99 /
     max at 1, 10 and 100 concurrent clients; each client asks for one decision of a live
     observation (recorded in IG-vs-IG kinematic bouts), waits for the answer, and keeps a pace of
     ``--rate`` requests a second (an engine asks at its NPCs' decision instants, 1-2 a second;
     30 is a generous ceiling); also the server's own decision time (decision_us) and the
     closed-loop throughput of 100 clients without pacing. Target: p99 <= 2 ms at 100 clients.
  B. the page in headless Chromium (1280x720, /usr/bin/chromium, software WebGL): frames per
     second measured in the page (requestAnimationFrame) after a warm-up, and the render
     resolution its dynamic scaling settled at (with --screenshot, also the fps of the page held
     at full resolution while the picture is taken). Target: >= 30 fps.
  C. key press -> A's next decision: keys pressed at random instants; for each, the wall time
     from the press (in the page) to the decision's arrival (in the page) and from the server's
     receipt to the decision, against A's decision interval (the duration of A's action the key
     fell into). Target: every press reaches A's next decision, within one decision interval.
Client and server share the machine: the figures include the client's own cost and the
neighbours' load (printed first). With two or more CPUs, part A runs twice: with the server's
process on one CPU and the clients on another (``pinned``: neither waits for the other's
time slice, as when an engine and the NPC service run on separate cores), then unpinned, both free
to run anywhere. Nothing is asserted.
"""
from __future__ import annotations

import argparse
import asyncio
import gc
import json
import os
import random
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


def machine() -> str:
    try:
        load = " ".join(open("/proc/loadavg").read().split()[:3])
    except OSError:
        load = "?"
    cpu = "?"
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, load {load}"


def set_cpus(pid: int, cpus: set[int]) -> None:
    """Every thread of process ``pid`` (0: this one) allowed on ``cpus`` only."""
    tasks = Path(f"/proc/{pid or os.getpid()}/task")
    for tid in ([int(t.name) for t in tasks.iterdir()] if tasks.is_dir() else [pid]):
        try:
            os.sched_setaffinity(tid, cpus)
        except (ProcessLookupError, PermissionError):
            pass


def start_server(graph: str, save_dir: str) -> tuple[subprocess.Popen, str]:
    cmd = [sys.executable, "-m", "igraph_fight", "play", "--graph", graph, "--port", "0", "--save-dir", save_dir]
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    t0 = time.monotonic()
    for line in p.stdout:
        m = re.search(r"open (http://\S+/) ", line)
        if m:
            return p, m.group(1)
        if time.monotonic() - t0 > 120:
            break
    p.kill()
    raise RuntimeError("the server did not start")


def observations(graph: str, n: int = 400) -> tuple[list[dict], float]:
    """Live observations of the decision instants of kinematic bouts between two Interaction Graph
    fighters (balanced vs outboxer, depth 3, no snapping, as the play session plays), and the share
    of them that is off the graph."""
    from igraph_fight.controller import NPCController, observe
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.graph import load_graph

    g = load_graph(graph)
    lib = g.load_library()
    npc = [NPCController(g, lib, style=s, depth=3) for s in ("balanced", "outboxer")]
    game = FightGame(lib, GameConfig(max_seconds=60.0, sim=g.sim_params()), tables=npc[0].tables)
    out, off = [], 0
    seed = 0
    while len(out) < n:
        st = game.new_initial_state(np.random.default_rng(seed))
        seed += 1
        while len(out) < n and st.current_player() >= 0:
            p = st.current_player()
            o = observe(st, p)
            d = npc[p].act(o)
            off += int(d.off_graph)
            out.append({"r": o.r, "theta_self": o.theta_self, "theta_other": o.theta_other, "m_self": o.m_self,
                        "m_other": o.m_other, "f_other": o.f_other, "mask_other": o.mask_other})
            st.apply_action(int(d.action))
    for c in npc:
        c.close()
    return out, off / len(out)


async def round_trips(url: str, obs: list[dict], clients: int, seconds: float, rate: float | None) -> dict:
    import aiohttp

    rtts: list[float] = []
    server_us: list[float] = []
    errors = 0

    async def client(k: int, s) -> None:
        nonlocal errors
        rng = random.Random(k)
        loop = asyncio.get_running_loop()
        async with s.ws_connect(url.replace("http://", "ws://") + "ws") as ws:
            await asyncio.sleep(rng.random() * (1.0 / rate if rate else 0.01))
            t_end = loop.time() + seconds
            nxt = loop.time()
            i = 0
            while loop.time() < t_end:
                msg = json.dumps({"v": 1, "type": "decide", "id": i, "obs": rng.choice(obs)})
                t0 = time.perf_counter()
                await ws.send_str(msg)
                r = json.loads((await ws.receive()).data)
                rtts.append((time.perf_counter() - t0) * 1e3)
                if r.get("type") != "decision":
                    errors += 1
                else:
                    server_us.append(r["decision_us"])
                i += 1
                if rate:
                    nxt += 1.0 / rate
                    await asyncio.sleep(max(0.0, nxt - loop.time()))

    conn = aiohttp.TCPConnector(limit=0)
    async with aiohttp.ClientSession(connector=conn) as s:
        t0 = time.perf_counter()
        await asyncio.gather(*(client(k, s) for k in range(clients)))
        wall = time.perf_counter() - t0
    a = np.array(rtts)
    return {"clients": clients, "rate_per_client": rate, "requests": len(a), "errors": errors,
            "throughput_per_s": len(a) / wall, "p50_ms": float(np.percentile(a, 50)),
            "p99_ms": float(np.percentile(a, 99)), "max_ms": float(a.max()),
            "server_decision_us_p50": float(np.median(server_us)) if server_us else None,
            "server_decision_us_p99": float(np.percentile(server_us, 99)) if server_us else None}


CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def page(url: str, seconds: float, presses: int, shot: str | None = None) -> dict:
    from playwright.sync_api import sync_playwright

    def ev(pg, expr):
        return pg.evaluate(f"() => {expr}")

    out: dict = {}
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
        pg = b.new_page(viewport={"width": 1280, "height": 720})
        pg.goto(url)
        t0 = time.monotonic()
        while not ev(pg, "!!(window.__play && window.__play.framesReceived > 10)"):
            time.sleep(0.1)
            if time.monotonic() - t0 > 60:
                raise RuntimeError("the page did not start")
        time.sleep(5.0)  # warm-up: the dynamic resolution settles
        fps = []
        for _ in range(int(seconds)):
            time.sleep(1.0)
            fps.append(ev(pg, "window.__play.fps"))
        out["fps_samples"] = [round(f, 1) for f in fps]
        out["fps_median"] = statistics.median(fps)
        out["fps_min"] = min(fps)
        out["render_scale"] = ev(pg, "window.__play.scale")
        out["render_ms"] = ev(pg, "window.__play.renderMs")
        # C: key presses at random instants
        rng = random.Random(1)
        keys = [("KeyJ", "jab"), ("KeyK", "straight"), ("KeyL", "dodge"), ("KeyF", "guard")]
        res = []
        for i in range(presses):
            time.sleep(rng.uniform(0.6, 2.2))
            key, cmd = rng.choice(keys)
            n0 = ev(pg, "window.__play.decisions.length")
            t_press = ev(pg, "performance.now()")
            pg.keyboard.down(key)
            pg.keyboard.up(key)
            d = None
            t_wait = time.monotonic()
            while d is None and time.monotonic() - t_wait < 10:
                d = ev(pg, f"window.__play.decisions.slice({n0}).find(d => d.player === 0 && d.source === 'key')")
                time.sleep(0.02)
            if d is None:
                res.append({"command": cmd, "reached": False})
                continue
            prev = ev(pg, f"window.__play.decisions.slice(0, {n0}).filter(d => d.player === 0).map(d => d.t).pop()")
            interval_ms = (d["t"] - prev) * 1000.0 if prev is not None else None
            res.append({"command": cmd, "reached": d["command"] == cmd, "page_ms": d["at"] - t_press,
                        "server_ms": d.get("latency_ms"), "interval_ms": interval_ms,
                        "within": interval_ms is not None and d["at"] - t_press <= interval_ms + 1000.0 / 30})
        out["presses"] = res
        ok = [r for r in res if r.get("reached")]
        out["reached"] = f"{len(ok)}/{len(res)}"
        out["within_interval"] = f"{sum(r['within'] for r in ok)}/{len(res)}"
        if ok:
            out["page_ms_median"] = statistics.median(r["page_ms"] for r in ok)
            out["page_ms_max"] = max(r["page_ms"] for r in ok)
            out["interval_ms_median"] = statistics.median(r["interval_ms"] for r in ok if r["interval_ms"])
        if shot:
            out["fps_full_resolution"] = take_picture(b, url, shot)
        b.close()
    return out


def take_picture(browser, url: str, path: str) -> float:
    """The README's picture: the page at full resolution, a few commands in, caught while A punches
    at close range (the view frozen for the shot; at most a minute)."""
    pg = browser.new_page(viewport={"width": 1280, "height": 720})
    pg.goto(url + "?scale=1")
    t0 = time.monotonic()
    while not pg.evaluate("() => !!(window.__play && window.__play.framesReceived > 10)"):
        time.sleep(0.1)
    keys = ["KeyW", "KeyJ", "KeyK"]
    t_key = 0.0
    while time.monotonic() - t0 < 60:
        if time.monotonic() - t_key > 0.9:
            key = keys.pop(0)
            keys.append(key)
            pg.keyboard.down(key)
            pg.keyboard.up(key)
            t_key = time.monotonic()
        hud = pg.evaluate("() => window.__play.hud")
        lab = hud.get("labels")
        if time.monotonic() - t0 > 8 and lab and lab[0] in ("jab", "straight") and hud.get("distance", 9) < 1.4:
            break
        time.sleep(0.05)
    fps = pg.evaluate("() => window.__play.fps")
    pg.evaluate("() => (window.__play.frozen = true)")
    time.sleep(0.3)
    pg.screenshot(path=path)
    pg.close()
    print(f"   picture: {path} (the page at full resolution ran at {fps:.1f} fps)")
    return fps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", default=None, help="graph file (default: the cached demo graph of igraph-fight play)")
    ap.add_argument("--seconds", type=float, default=10.0, help="seconds per load level (default 10)")
    ap.add_argument("--rate", type=float, default=30.0, help="requests a second per client (default 30)")
    ap.add_argument("--page-seconds", type=float, default=15.0, help="fps samples of the page (default 15)")
    ap.add_argument("--presses", type=int, default=12, help="key presses (default 12)")
    ap.add_argument("--no-page", action="store_true", help="skip the browser parts (B, C)")
    ap.add_argument("--no-pin", action="store_true", help="measure A unpinned only")
    ap.add_argument("--json", default=None, help="write the figures to this JSON file")
    ap.add_argument("--screenshot", default=None, help="also save a picture of the page (e.g. docs/media/play.png)")
    a = ap.parse_args()
    graph = a.graph
    if graph is None:
        from igraph_fight.play.demo_graph import ensure_demo_graph
        graph = str(ensure_demo_graph())
    print(f"machine: {machine()}")
    print(f"graph: {graph}")
    import tempfile
    save = tempfile.mkdtemp(prefix="bench_play_")
    obs, off_share = observations(graph)
    proc, url = start_server(graph, save)
    results: dict = {"machine": machine(), "graph": graph, "rate_per_client": a.rate, "off_graph_share": off_share}
    try:
        print(f"\nA. decision round trip on loopback (WebSocket /ws); {len(obs)} observations of IG-vs-IG bouts, "
              f"{100 * off_share:.0f}% off the graph")
        print("   clients  paced  requests  req/s   p50 ms  p99 ms  max ms  server us p50/p99  errors")
        rows = []
        gc.collect()
        gc.freeze()  # the setup's objects (graph, bouts) out of the collector's passes while measuring
        cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
        modes = (["pinned"] if len(cpus) >= 2 and not a.no_pin else []) + ["unpinned"]
        asyncio.run(round_trips(url, obs, 4, 1.0, None))  # warm-up
        for mode in modes:
            if mode == "pinned":
                set_cpus(proc.pid, {cpus[0]})
                set_cpus(0, {cpus[1]})
            print(f"   {mode}" + (f": server on CPU {cpus[0]}, clients on CPU {cpus[1]}" if mode == "pinned" else ""))
            for clients, rate in ((1, a.rate), (10, a.rate), (100, a.rate), (100, None)):
                r = asyncio.run(round_trips(url, obs, clients, a.seconds, rate))
                r["cpus"] = mode
                rows.append(r)
                print(f"   {clients:7d}  {('%g/s' % rate) if rate else 'no':>5s}  {r['requests']:8d}  "
                      f"{r['throughput_per_s']:5.0f}  {r['p50_ms']:7.3f} {r['p99_ms']:7.3f} {r['max_ms']:7.2f}  "
                      f"{r['server_decision_us_p50']:6.1f}/{r['server_decision_us_p99']:6.1f}  {r['errors']:6d}")
            if mode == "pinned":
                set_cpus(proc.pid, set(cpus))
                set_cpus(0, set(cpus))
        results["round_trips"] = rows
        if not a.no_page:
            if not Path("/usr/bin/chromium").is_file():
                print("\nB, C skipped: /usr/bin/chromium missing")
            else:
                print("\nB. the page in headless Chromium (1280x720)")
                pr = page(url, a.page_seconds, a.presses, a.screenshot)
                results["page"] = pr
                print(f"   fps median {pr['fps_median']:.1f}, min {pr['fps_min']:.1f} (samples {pr['fps_samples']}), "
                      f"render scale {pr['render_scale']}, renderer.render {pr['render_ms']:.2f} ms")
                print("C. key press -> A's next decision")
                print(f"   reached {pr['reached']}, within one decision interval {pr['within_interval']}; "
                      f"press -> decision in the page: median {pr.get('page_ms_median', float('nan')):.0f} ms, max "
                      f"{pr.get('page_ms_max', float('nan')):.0f} ms; A's decision interval median "
                      f"{pr.get('interval_ms_median', float('nan')):.0f} ms")
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
    if a.json:
        Path(a.json).write_text(json.dumps(results, indent=1))
        print(f"\nwrote {a.json}")


if __name__ == "__main__":
    main()
