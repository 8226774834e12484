"""The `igraph-fight play` server (aiohttp): the game page and the network NPC service.

Endpoints:
  GET  /          the game page (web/index.html; its scripts under /static/, three.js under
                  /vendor/three/ from web/node_modules: no CDN, works offline)
  GET  /health    {"status": "ok", "version", "graph": content hash, ...}
  POST /decide    one protocol request per HTTP request (decide, info, health), JSON reply
  GET  /ws        the NPC service's WebSocket (igraph_fight.play.service, docs/npc_service.md)
  GET  /game      the page's WebSocket: a live bout (igraph_fight.play.session) streamed at the
                  library's 30 frames a second, the player's commands, saving and replays

Every message is validated (igraph_fight.play.protocol); a refused one gets an ``error`` reply
and the connection stays up. Limits (protocol.py): MAX_MESSAGE_BYTES a message, a token bucket
of RATE_PER_S / RATE_BURST per WebSocket connection or HTTP client address, MAX_CONNECTIONS,
MAX_GAME_SESSIONS; WebSocket frames beyond WS_MAX_FRAME_BYTES close the connection (1009).
Browsers' cross-site requests are refused: a request with an Origin header must come from the
server's own origin, and a server bound to loopback answers only requests addressed to
127.0.0.1 / localhost / ::1 (no DNS rebinding). The server binds 127.0.0.1 unless told otherwise.
"""
from __future__ import annotations

import asyncio
import logging
import re
import threading
import time
from collections import OrderedDict
from pathlib import Path
from urllib.parse import urlsplit

from aiohttp import WSMsgType, web

from igraph_fight.play.protocol import (
    GAME_DEPTH_RANGE, GAME_RATE_BURST, GAME_RATE_PER_S, MAX_CONNECTIONS, MAX_GAME_SESSIONS, MAX_MESSAGE_BYTES, PROTOCOL_VERSION, RATE_BURST, RATE_PER_S,
    WS_MAX_FRAME_BYTES, ProtocolError, TokenBucket, dumps, error_reply, parse)

log = logging.getLogger("igraph_fight.play")

WEB_DIR = Path(__file__).resolve().parent / "web"
THREE_DIR = WEB_DIR / "node_modules" / "three" / "build"
#: how the project installs the page's three.js (README, .ci/run)
NPM_STEP = "npm ci --prefix igraph_fight/play/web"
#: depth of the policy that rates the player's menu (its values at depth - 1 enter the rating)
RATER_DEPTH = 3
#: HTTP client addresses whose rate buckets are kept
MAX_HTTP_CLIENTS = 4096
#: names of this machine a loopback-bound server answers to
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
_HOST_RE = re.compile(r"^[A-Za-z0-9.\-]+(:[0-9]{1,5})?$|^\[[0-9A-Fa-f:.]+\](:[0-9]{1,5})?$")


def _hostname(host: str) -> str:
    """The name part of a Host header value (``[::1]:8765`` -> ``::1``)."""
    try:
        return urlsplit("//" + host).hostname or ""
    except ValueError:
        return ""


def web_assets_missing(web_dir: Path = WEB_DIR) -> str | None:
    """None when the page's three.js is installed, else the one line that says how to install it."""
    if (web_dir / "node_modules" / "three" / "build" / "three.module.js").is_file():
        return None
    return f"the game page needs three.js from npm: run `{NPM_STEP}` in the checkout (Node.js 18 or newer)"


class PlayServer:
    """The server's state: graph, library, policy pool, NPC service, defaults of new bouts."""

    def __init__(self, graph, *, style: str = "balanced", depth: int = 3, seconds: float = 60.0,
                 player_style: str = "balanced", idle: str = "guard", save_dir: str | Path | None = "out/play",
                 web_dir: Path = WEB_DIR, physics=None) -> None:
        """``physics``: None for kinematic games, else the tracker package's physics play (an object
        whose ``session(npc, rater, config, graph_hash, npc_style)`` makes a game session and whose
        ``label`` names the physics), or a callable ``(library, sim_params) -> that object``."""
        from igraph_fight.controller import NPCController
        from igraph_fight.game import FightGame, GameConfig
        from igraph_fight.graph import InteractionGraph, load_graph
        from igraph_fight.play.policies import PolicyPool
        from igraph_fight.play.service import NPCService

        from planner import load_style

        load_style(player_style)  # a StyleError (ValueError) now rather than at the first page
        if idle not in ("guard", "best"):
            raise ValueError(f"idle must be 'guard' or 'best', not {idle!r}")
        if not isinstance(graph, InteractionGraph):
            graph = load_graph(graph)
        self.graph = graph
        self.library = graph.load_library()
        base = NPCController(graph, self.library, style=style, depth=depth)
        self.pool = PolicyPool(base, style)
        self.service = NPCService(self.pool, style, depth)
        self.game = FightGame(self.library, GameConfig(max_seconds=seconds, sim=graph.sim_params()), tables=base.tables)
        self.defaults = {"style": style, "depth": int(depth), "seconds": float(seconds), "player_style": player_style,
                         "idle": idle}
        self.save_dir = Path(save_dir) if save_dir is not None else None
        self.web_dir = Path(web_dir)
        #: (messages a second, burst) of each new connection's / client address's token bucket
        self.rate = (RATE_PER_S, RATE_BURST)
        #: host names a request's Host header may carry (None: any; serve() sets it for loopback binds)
        self.allowed_hosts: set[str] | None = None
        self.counters = {"requests": 0, "errors_replied": 0, "internal_errors": 0, "connections": 0,
                         "game_sessions": 0}
        self._http_buckets: OrderedDict[str, TokenBucket] = OrderedDict()
        from igraph_fight.graph import library_fingerprint
        self.library_fp = library_fingerprint(self.library)
        self.physics = physics(self.library, graph.sim_params()) if callable(physics) else physics
        self.warm_up()

    def warm_up(self) -> None:
        """One decision of each kind (table, batch, menu rating) and a few simulated frames, so that
        loading the compiled kernels is not in the first requests' time."""
        import numpy as np

        from igraph_fight.controller import observe
        from igraph_fight.play.session import BoutPlayer

        from igraph_fight.play.protocol import REQUEST_DEFS, fast_check, validator

        for defs in REQUEST_DEFS.values():
            for name in defs.values():
                fast_check(name)
                validator(name)
        c = self.pool.base
        st = self.game.new_initial_state(np.random.default_rng(0))
        obs = observe(st, 0)
        c.act(obs)
        c.act_batch(*(np.array([v]) for v in obs[:6]), lookahead=True)
        c.menu_terms(obs)
        bp = BoutPlayer(st, 1.0, lambda s, p: (int(s.legal_actions(p)[0]), {}))
        while bp.step() is not None:
            pass

    # ----- the aiohttp application -----------------------------------------------------------------
    def app(self) -> web.Application:
        app = web.Application(client_max_size=MAX_MESSAGE_BYTES + 1024, middlewares=[self.check_host])
        app.router.add_get("/", self.index)
        app.router.add_get("/favicon.ico", self.no_icon)
        app.router.add_get("/health", self.health)
        app.router.add_post("/decide", self.http_decide)
        app.router.add_get("/ws", self.ws_npc)
        app.router.add_get("/game", self.ws_game)
        app.router.add_static("/static/", self.web_dir / "static", follow_symlinks=False, show_index=False)
        three = self.web_dir / "node_modules" / "three" / "build"
        if three.is_dir():
            app.router.add_static("/vendor/three/", three, follow_symlinks=False, show_index=False)
        return app

    @web.middleware
    async def check_host(self, request: web.Request, handler):
        """Refuse requests whose Host header names another machine than the one bound (DNS
        rebinding: a web site whose name resolves to 127.0.0.1 would otherwise pass the Origin check)."""
        if self.allowed_hosts is not None and _hostname(request.host) not in self.allowed_hosts:
            return web.json_response(error_reply("bad_request", "unexpected Host header"), status=421)
        return await handler(request)

    async def index(self, request: web.Request) -> web.StreamResponse:
        html = (self.web_dir / "index.html").read_text(encoding="utf-8")
        host = request.host if _HOST_RE.match(request.host) else "localhost"
        csp = (f"default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self' data: blob:; "
               f"connect-src 'self' ws://{host}")
        return web.Response(text=html, content_type="text/html",
                            headers={"Content-Security-Policy": csp, "Cache-Control": "no-store"})

    async def no_icon(self, request: web.Request) -> web.Response:
        return web.Response(status=204)

    async def health(self, request: web.Request) -> web.Response:
        return web.json_response(self.service.health(self.counters), dumps=dumps)

    @staticmethod
    def origin_ok(request: web.Request) -> bool:
        """True without an Origin header (engines, scripts) or when it is the server's own."""
        origin = request.headers.get("Origin")
        if not origin:
            return True
        try:
            return urlsplit(origin).netloc == request.host
        except ValueError:
            return False

    def error(self, e: ProtocolError) -> dict:
        """The error reply of a refused message (counted)."""
        self.counters["errors_replied"] += 1
        return e.reply()

    def internal(self, where: str) -> dict:
        """The error reply of an unexpected failure (counted and logged)."""
        self.counters["internal_errors"] += 1
        log.exception("internal error in %s", where)
        return error_reply("internal", "internal server error")

    # ----- HTTP one-shot requests ------------------------------------------------------------------
    async def http_decide(self, request: web.Request) -> web.Response:
        if not self.origin_ok(request):
            return web.json_response(error_reply("bad_request", "cross-origin request refused"), status=403)
        peer = request.remote or "?"
        b = self._http_buckets.get(peer)
        if b is None:
            b = self._http_buckets[peer] = TokenBucket(*self.rate)
            while len(self._http_buckets) > MAX_HTTP_CLIENTS:
                self._http_buckets.popitem(last=False)
        self._http_buckets.move_to_end(peer)
        self.counters["requests"] += 1
        if not b.take(time.monotonic()):
            return web.json_response(self.error(ProtocolError("rate_limited", "too many requests")), status=429)
        too_large = (request.content_length or 0) > MAX_MESSAGE_BYTES
        body = b""
        try:
            while not too_large:  # read at most MAX_MESSAGE_BYTES + 1 bytes, whatever the headers say
                chunk = await request.content.read(64 * 1024)
                if not chunk:
                    break
                body += chunk
                too_large = len(body) > MAX_MESSAGE_BYTES
        except Exception:  # noqa: BLE001 - a broken upload
            return web.json_response(self.error(ProtocolError("bad_request", "could not read the body")), status=400)
        if too_large:
            return web.json_response(self.error(ProtocolError("too_large", f"body of more than {MAX_MESSAGE_BYTES} "
                                                                            "bytes")), status=413)
        from igraph_fight.play.service import Connection
        try:
            msg = parse(body, "npc")
            if msg["type"] in ("set_style", "set_depth"):
                raise ProtocolError("bad_request", "HTTP is stateless: name style / depth in the decide request, or "
                                                   "use the WebSocket /ws", msg.get("id"))
            conn = Connection(self.defaults["style"], self.defaults["depth"])
            reply = await self.service.handle(msg, conn, self.counters)
            return web.json_response(reply, dumps=dumps)
        except ProtocolError as e:
            return web.json_response(self.error(e), status=429 if e.code == "rate_limited" else 400, dumps=dumps)
        except Exception:  # noqa: BLE001 - any failure becomes an error reply
            return web.json_response(self.internal("POST /decide"), status=500, dumps=dumps)

    # ----- the NPC service's WebSocket ---------------------------------------------------------------
    async def ws_npc(self, request: web.Request) -> web.StreamResponse:
        if not self.origin_ok(request):
            return web.json_response(error_reply("bad_request", "cross-origin connection refused"), status=403)
        if self.counters["connections"] >= MAX_CONNECTIONS:
            return web.json_response(error_reply("busy", "too many connections"), status=503)
        from igraph_fight.play.service import Connection

        ws = web.WebSocketResponse(max_msg_size=WS_MAX_FRAME_BYTES, heartbeat=30.0, compress=False)
        await ws.prepare(request)
        self.counters["connections"] += 1
        conn = Connection(self.defaults["style"], self.defaults["depth"])
        bucket = TokenBucket(*self.rate)
        lock = asyncio.Lock()
        tasks: set[asyncio.Task] = set()

        async def send(reply: dict) -> None:
            if ws.closed:
                return
            try:
                async with lock:
                    await ws.send_str(dumps(reply))
            except (ConnectionError, RuntimeError):
                pass

        async def answer(msg: dict) -> None:
            try:
                reply = await self.service.handle(msg, conn, self.counters)
            except ProtocolError as e:
                reply = self.error(e)
            except Exception:  # noqa: BLE001
                reply = self.internal("/ws")
            await send(reply)

        try:
            async for m in ws:
                self.counters["requests"] += 1
                if m.type == WSMsgType.TEXT:
                    raw = m.data
                elif m.type == WSMsgType.BINARY:
                    await send(self.error(ProtocolError("binary", "binary frames are not part of the protocol: "
                                                                   "send JSON text")))
                    continue
                else:
                    break
                if not bucket.take(time.monotonic()):
                    await send(self.error(ProtocolError("rate_limited", "too many messages on this connection")))
                    continue
                try:
                    msg = parse(raw, "npc")
                except ProtocolError as e:
                    await send(self.error(e))
                    continue
                except Exception:  # noqa: BLE001
                    await send(self.internal("/ws parse"))
                    continue
                slow = msg["type"] in ("set_style", "set_depth") or (
                    msg["type"] == "decide" and self.pool.cached(msg.get("style", conn.style),
                                                                 msg.get("depth", conn.depth)) is None)
                if slow:  # a policy to compute: answer later, keep reading
                    t = asyncio.ensure_future(answer(msg))
                    tasks.add(t)
                    t.add_done_callback(tasks.discard)
                else:
                    await answer(msg)
        finally:
            for t in list(tasks):
                t.cancel()
            self.counters["connections"] -= 1
        return ws

    # ----- the game page's WebSocket ---------------------------------------------------------------
    async def ws_game(self, request: web.Request) -> web.StreamResponse:
        if not self.origin_ok(request):
            return web.json_response(error_reply("bad_request", "cross-origin connection refused"), status=403)
        if self.counters["game_sessions"] >= MAX_GAME_SESSIONS:
            return web.json_response(error_reply("busy", "too many game sessions"), status=503)
        ws = web.WebSocketResponse(max_msg_size=WS_MAX_FRAME_BYTES, heartbeat=30.0, compress=False)
        await ws.prepare(request)
        self.counters["game_sessions"] += 1
        try:
            game = GameChannel(self, ws)
            await game.run()
        finally:
            self.counters["game_sessions"] -= 1
        return ws


class GameChannel:
    """One page's game: a live GameSession or a replay, its ticker and its message handler."""

    def __init__(self, server: PlayServer, ws: web.WebSocketResponse) -> None:
        self.server = server
        self.ws = ws
        self.lock = asyncio.Lock()
        self.session = None
        self.replay = None          # (Streamer, expected dict) while a replay plays
        self.mode = "live"
        self.tasks: set[asyncio.Task] = set()
        self.bucket = TokenBucket(GAME_RATE_PER_S, GAME_RATE_BURST)

    async def send(self, msg: dict) -> None:
        if self.ws.closed:
            return
        try:
            async with self.lock:
                await self.ws.send_str(dumps(msg))
        except (ConnectionError, RuntimeError):
            pass

    async def run(self) -> None:
        from igraph_fight.play.commands import fallback_table
        from igraph_fight.play.session import GameSession, PlayConfig

        srv = self.server
        d = srv.defaults
        npc, _ = await srv.pool.get(d["style"], d["depth"])
        rater, _ = await srv.pool.get(d["player_style"], RATER_DEPTH)
        cfg = PlayConfig(seconds=d["seconds"], style=d["style"], depth=d["depth"], player_style=d["player_style"],
                         idle=d["idle"])
        if srv.physics is not None:
            self.session = srv.physics.session(npc, rater, cfg, srv.graph.content_hash, npc_style=d["style"])
        else:
            self.session = GameSession(srv.game, npc, rater, cfg, srv.graph.content_hash, npc_style=d["style"])
        from planner import list_presets
        await self.send({"v": PROTOCOL_VERSION, "type": "hello", "drawing": self.session.drawing,
                         "commands": fallback_table(), "styles": list_presets(), "depth_range": list(GAME_DEPTH_RANGE),
                         "fps": float(srv.game.fps), "graph": {"content_hash": srv.graph.content_hash,
                                                                "n_states": int(srv.graph.n_states)},
                         "saving": srv.save_dir is not None})
        await self.send(self.session.status())
        ticker = asyncio.ensure_future(self.tick_loop())
        try:
            async for m in self.ws:
                if m.type == WSMsgType.TEXT:
                    await self.on_message(m.data)
                elif m.type == WSMsgType.BINARY:
                    await self.send(self.server.error(ProtocolError("binary", "send JSON text")))
                else:
                    break
        finally:
            ticker.cancel()
            for t in list(self.tasks):
                t.cancel()

    def _spawn(self, coro) -> None:
        t = asyncio.ensure_future(coro)
        self.tasks.add(t)
        t.add_done_callback(self.tasks.discard)

    async def tick_loop(self) -> None:
        loop = asyncio.get_running_loop()
        fps = float(self.server.game.fps)
        nxt = loop.time()
        while not self.ws.closed:
            now = loop.time()
            try:
                await self.tick(now)
            except asyncio.CancelledError:
                raise
            except ValueError as e:  # a replay that does not replay
                await self.send(self.server.error(ProtocolError("bad_request", f"replay stopped: {e}")))
                self.replay = None
                self.mode = "over"
                await self.send(self.session.status("over"))
            except Exception:  # noqa: BLE001
                await self.send(self.server.internal("game tick"))
                self.mode = "over"
            nxt += 1.0 / fps
            if nxt < now - 0.5:
                nxt = now
            await asyncio.sleep(max(0.0, nxt - loop.time()))

    async def tick(self, now: float) -> None:
        if self.mode == "live":
            for msg in self.session.tick(now):
                await self.send(msg)
            if self.session.over:
                self.mode = "over"
                if self.server.save_dir is not None and self.session.player.done and self.session.saved_as is None \
                        and getattr(self.session, "saveable", True):
                    await self.save()
                await self.send(self.session.status("over"))
        elif self.mode == "replay" and self.replay is not None:
            streamer, expected = self.replay
            for msg in streamer.tick(now):
                await self.send(msg)
            if streamer.player.done:
                got = [int(x) for x in streamer.player.hits]
                await self.send({"type": "replay_end", "hits": got, "log_hits": [int(x) for x in expected["hits"]],
                                 "matches_log": got == [int(x) for x in expected["hits"]],
                                 "decisions": len(streamer.player.decisions), "seconds": streamer.player.time_s})
                self.replay = None
                self.mode = "over"
                await self.send(self.session.status("over"))

    async def save(self) -> None:
        from igraph_fight.play.bouts import save_bout
        if self.server.save_dir is None:
            await self.send(self.server.error(ProtocolError("bad_request", "this server does not save bouts")))
            return
        try:
            name, folder = save_bout(self.session, self.server.save_dir)
        except ValueError as e:       # a session that is not saved (physics)
            await self.send(self.server.error(ProtocolError("bad_request", str(e))))
            return
        except OSError as e:
            await self.send(self.server.error(ProtocolError("bad_request", f"could not save: {e}")))
            return
        await self.send({"type": "saved", "name": name, "folder": str(folder), "complete": self.session.player.done,
                         "hits": [int(x) for x in self.session.player.hits], "seconds": self.session.player.time_s})

    async def on_message(self, raw: str) -> None:
        srv = self.server
        if not self.bucket.take(time.monotonic()):
            await self.send(srv.error(ProtocolError("rate_limited", "too many messages")))
            return
        try:
            msg = parse(raw, "game")
            await self.handle(msg)
        except ProtocolError as e:
            await self.send(srv.error(e))
        except Exception:  # noqa: BLE001
            await self.send(srv.internal("/game"))

    async def handle(self, msg: dict) -> None:
        from igraph_fight.play.policies import changed_share
        from igraph_fight.play.session import Streamer

        kind = msg["type"]
        s = self.session
        if kind == "command":
            if self.mode == "live":
                s.command(msg["command"], bool(msg.get("held", False)))
        elif kind == "release":
            s.release(msg["command"])
        elif kind in ("set_style", "set_depth"):
            style = msg.get("style", s.npc_style)
            depth = int(msg.get("depth", s.npc_depth))

            async def switch() -> None:
                try:
                    c, ms = await self.server.pool.get(style, depth)
                except ProtocolError as e:
                    await self.send(self.server.error(e))
                    return
                old = s.npc
                s.set_npc(c, style)
                await self.send({"v": PROTOCOL_VERSION, "type": "policy", "style": style, "depth": int(c.depth),
                                 "policy_ms": round(ms, 1), "changed_share": round(changed_share(old, c), 6),
                                 "t": round(s.player.time_s, 3)})
                await self.send(s.status(self.mode if self.mode != "live" else None))
            self._spawn(switch())
        elif kind == "new_bout":
            self.replay = None
            s.new_bout(msg.get("seconds"), msg.get("seed"))
            self.mode = "live"
            await self.send(s.status())
        elif kind == "save":
            if self.mode == "replay":
                raise ProtocolError("bad_request", "a replay is playing: nothing new to save")
            await self.save()
        elif kind == "list_bouts":
            from igraph_fight.play.bouts import list_bouts
            items = list_bouts(self.server.save_dir) if self.server.save_dir is not None else []
            await self.send({"type": "bouts", "bouts": items})
        elif kind == "replay":
            from igraph_fight.play.bouts import ReplayError, bout_folder, replay_player
            if self.server.save_dir is None:
                raise ProtocolError("bad_request", "this server does not save bouts")
            try:
                folder = bout_folder(self.server.save_dir, msg["bout"])
                player, expected = replay_player(folder, self.server.game, self.server.library_fp)
            except ReplayError as e:
                raise ProtocolError("bad_request", str(e)) from None
            st = Streamer(player, s.drawing["joints"])
            st.speed = float(msg.get("speed", 1.0))
            self.replay = (st, expected)
            self.mode = "replay"
            meta = expected["meta"]
            await self.send({"type": "status", "mode": "replay", "bout": msg["bout"], "style": meta.get("npc_style"),
                             "depth": meta.get("npc_depth"), "seconds": meta.get("played_s"), "queued": None,
                             "held": [], "player_style": meta.get("player_style"), "idle": meta.get("idle"),
                             "saved_as": msg["bout"]})
        elif kind == "pause":
            if self.mode == "live":
                s.streamer.paused = bool(msg["paused"])
                await self.send(s.status())


# ----- running it ---------------------------------------------------------------------------------
async def serve(server: PlayServer, host: str, port: int, ready=None) -> None:
    """Serve until cancelled; ``ready(url)`` is called once listening."""
    if host in LOOPBACK_HOSTS:
        server.allowed_hosts = set(LOOPBACK_HOSTS)
    runner = web.AppRunner(server.app(), access_log=None, handle_signals=False)
    await runner.setup()
    site = web.TCPSite(runner, host, port, reuse_address=True)
    await site.start()
    addrs = runner.addresses
    real_port = addrs[0][1] if addrs else port
    url = f"http://{host if ':' not in host else f'[{host}]'}:{real_port}/"
    if ready is not None:
        ready(url)
    try:
        await asyncio.Event().wait()
    finally:
        await runner.cleanup()


class ServerThread:
    """A PlayServer served from a background thread (tests, benchmarks): ``url`` once started;
    ``stop()`` shuts it down."""

    def __init__(self, server: PlayServer, host: str = "127.0.0.1", port: int = 0) -> None:
        self.server = server
        self.url: str | None = None
        self._ready = threading.Event()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task = None
        self._error: BaseException | None = None
        self._thread = threading.Thread(target=self._run, args=(host, port), daemon=True, name="play-server")

    def _run(self, host: str, port: int) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        asyncio.set_event_loop(loop)

        def ready(url: str) -> None:
            self.url = url
            self._ready.set()
        self._task = loop.create_task(serve(self.server, host, port, ready))
        try:
            loop.run_until_complete(self._task)
        except asyncio.CancelledError:
            pass
        except BaseException as e:  # noqa: BLE001 - reported by start()
            self._error = e
            self._ready.set()
        finally:
            loop.close()

    def start(self, timeout: float = 30.0) -> "ServerThread":
        self._thread.start()
        if not self._ready.wait(timeout) or self.url is None:
            raise RuntimeError(f"the play server did not start: {self._error!r}")
        return self

    def stop(self) -> None:
        if self._loop is not None and self._task is not None:
            self._loop.call_soon_threadsafe(self._task.cancel)
        self._thread.join(10)

    @property
    def ws_url(self) -> str:
        return self.url.replace("http://", "ws://")
