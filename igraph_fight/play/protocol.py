"""The versioned JSON protocol of `igraph-fight play`: limits, parsing and validation of every
message the server reads, and the replies' shapes.

Messages are JSON objects with ``"v": 1`` and a ``"type"``; the JSON Schema
docs/npc_protocol.schema.json describes them all (the NPC service's requests and replies, the
game page's requests). ``parse`` turns raw text into a validated dict or raises ProtocolError
with an error code of the schema's ``rep_error``: the server answers it and keeps the connection.
Library-dependent ranges (action ids, frames) are checked by ``observation_from``.

Validation runs on every message in two steps: a predicate compiled from the schema's own
keywords (``compile_check``: a few microseconds, where jsonschema takes a hundred or more)
accepts the valid ones; whatever it refuses goes to jsonschema, which has the last word and
names the error. tests/test_play_commands.py checks that the two agree on valid and hostile
messages.
"""
from __future__ import annotations

import json
import math
from functools import lru_cache
from pathlib import Path

PROTOCOL_VERSION = 1
#: the schema file (in the checkout's docs/: `play` runs from a checkout, like its web assets)
SCHEMA_PATH = Path(__file__).resolve().parents[2] / "docs" / "npc_protocol.schema.json"

#: largest message (text frame or HTTP body) the server parses; larger ones get a ``too_large`` error
MAX_MESSAGE_BYTES = 256 * 1024
#: largest WebSocket frame the server receives at all (beyond it the connection is closed, code 1009)
WS_MAX_FRAME_BYTES = 16 * 1024 * 1024
#: observations in one ``decide`` batch (also in the schema)
MAX_BATCH = 1024
#: per-connection (WebSocket) or per-address (HTTP) token bucket: messages a second, burst
RATE_PER_S = 1000.0
RATE_BURST = 2000.0
#: the same for the game page's channel (key presses, menu changes)
GAME_RATE_PER_S = 100.0
GAME_RATE_BURST = 200.0
#: min-max depths the service accepts (the game's slider: 1-5)
DEPTH_RANGE = (1, 8)
GAME_DEPTH_RANGE = (1, 5)
#: style files larger than this are refused
MAX_STYLE_FILE_BYTES = 64 * 1024
#: policy tables kept (style, depth), least recently used evicted
MAX_POLICIES = 8
#: simultaneous connections (NPC and game together); game sessions
MAX_CONNECTIONS = 512
MAX_GAME_SESSIONS = 8
#: policy computations a connection may have under way; the whole server
MAX_PENDING_POLICIES = 2
MAX_PENDING_TABLES = 4
#: longest error message sent back
MAX_ERROR_CHARS = 300

#: request types by channel ("npc": /ws and POST /decide; "game": the page's /game socket)
REQUEST_DEFS = {
    "npc": {"decide": "req_decide", "set_style": "req_set_style", "set_depth": "req_set_depth",
            "info": "req_info", "health": "req_health"},
    "game": {"command": "game_command", "release": "game_release", "set_style": "game_set_style",
             "set_depth": "game_set_depth", "new_bout": "game_new_bout", "save": "game_save",
             "list_bouts": "game_list_bouts", "replay": "game_replay", "pause": "game_pause"},
}
ERROR_CODES = ("bad_json", "too_large", "binary", "invalid", "bad_observation", "bad_style", "bad_request",
               "rate_limited", "busy", "internal")


class ProtocolError(Exception):
    """A message the server refuses: ``code`` (one of ERROR_CODES), a message, the client's tag."""

    def __init__(self, code: str, message: str, tag=None) -> None:
        super().__init__(message)
        self.code = code if code in ERROR_CODES else "internal"
        self.message = message[:MAX_ERROR_CHARS]
        self.tag = tag

    def reply(self) -> dict:
        return error_reply(self.code, self.message, self.tag)


def error_reply(code: str, message: str, tag=None) -> dict:
    """An ``error`` reply (schema rep_error)."""
    out = {"v": PROTOCOL_VERSION, "type": "error", "code": code, "message": str(message)[:MAX_ERROR_CHARS]}
    if tag is not None:
        out["id"] = tag
    return out


@lru_cache(maxsize=1)
def schema() -> dict:
    """The protocol's JSON Schema (docs/npc_protocol.schema.json)."""
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


#: annotation keywords the checker ignores; any other keyword not handled by ``compile_check`` is refused
_ANNOTATIONS = {"description", "title", "$comment", "$schema", "$id", "examples", "default"}


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _is_integer(x) -> bool:
    return (isinstance(x, int) and not isinstance(x, bool)) or (isinstance(x, float) and x.is_integer())


_TYPES = {"object": lambda x: isinstance(x, dict), "array": lambda x: isinstance(x, list),
          "string": lambda x: isinstance(x, str), "boolean": lambda x: isinstance(x, bool),
          "number": _is_number, "integer": _is_integer, "null": lambda x: x is None}


def compile_check(node: dict, defs: dict):
    """A fast predicate ``f(instance) -> bool`` equivalent to JSON Schema validation of ``node`` for
    the keywords this protocol's schema uses (type, const, enum, required, properties,
    additionalProperties false, minimum / maximum, min/maxLength, min/maxItems, items, pattern,
    oneOf, allOf, not, $ref into ``defs``). Raises ValueError for any other keyword, so that the
    schema cannot grow past what the checker understands. Tests check it against jsonschema."""
    import re

    checks = []
    for k, v in node.items():
        if k in _ANNOTATIONS:
            continue
        if k == "$ref":
            name = v.rsplit("/", 1)[-1]
            if not v.startswith("#/$defs/") or name not in defs:
                raise ValueError(f"unsupported $ref {v!r}")
            sub = compile_check(defs[name], defs)
            checks.append(sub)
        elif k == "type":
            t = _TYPES[v]
            checks.append(t)
        elif k == "const":
            checks.append(lambda x, c=v: type(x) is type(c) and x == c if not _is_number(c) else _is_number(x) and x == c)
        elif k == "enum":
            checks.append(lambda x, e=tuple(v): isinstance(x, str) and x in e)
            if not all(isinstance(e, str) for e in v):
                raise ValueError("enum of non-strings")
        elif k == "required":
            checks.append(lambda x, r=tuple(v): not isinstance(x, dict) or all(n in x for n in r))
        elif k == "properties":
            checks.append(_properties({n: compile_check(sub, defs) for n, sub in v.items()}))
        elif k == "additionalProperties":
            if v is not False:
                raise ValueError("additionalProperties other than false")
            allowed = frozenset(node.get("properties", {}))
            checks.append(lambda x, a=allowed: not isinstance(x, dict) or all(n in a for n in x))
        elif k == "minimum":
            checks.append(lambda x, m=v: not _is_number(x) or x >= m)
        elif k == "maximum":
            checks.append(lambda x, m=v: not _is_number(x) or x <= m)
        elif k == "minLength":
            checks.append(lambda x, m=v: not isinstance(x, str) or len(x) >= m)
        elif k == "maxLength":
            checks.append(lambda x, m=v: not isinstance(x, str) or len(x) <= m)
        elif k == "minItems":
            checks.append(lambda x, m=v: not isinstance(x, list) or len(x) >= m)
        elif k == "maxItems":
            checks.append(lambda x, m=v: not isinstance(x, list) or len(x) <= m)
        elif k == "items":
            f = compile_check(v, defs)
            checks.append(lambda x, f=f: not isinstance(x, list) or all(f(i) for i in x))
        elif k == "pattern":
            rx = re.compile(v)
            checks.append(lambda x, rx=rx: not isinstance(x, str) or rx.search(x) is not None)
        elif k == "oneOf":
            fs = [compile_check(sub, defs) for sub in v]
            checks.append(lambda x, fs=fs: sum(1 for f in fs if f(x)) == 1)
        elif k == "allOf":
            fs = [compile_check(sub, defs) for sub in v]
            checks.append(lambda x, fs=fs: all(f(x) for f in fs))
        elif k == "not":
            f = compile_check(v, defs)
            checks.append(lambda x, f=f: not f(x))
        else:
            raise ValueError(f"schema keyword {k!r} is not supported by compile_check")
    if len(checks) == 1:
        return checks[0]
    checks = tuple(checks)

    def check(x) -> bool:
        for c in checks:
            if not c(x):
                return False
        return True
    return check


def _properties(props: dict):
    items = tuple(props.items())

    def check(x) -> bool:
        if not isinstance(x, dict):
            return True
        for n, f in items:
            if n in x and not f(x[n]):
                return False
        return True
    return check


@lru_cache(maxsize=64)
def fast_check(definition: str):
    """compile_check of one definition of the schema."""
    defs = schema()["$defs"]
    return compile_check(defs[definition], defs)


@lru_cache(maxsize=64)
def validator(definition: str):
    """A jsonschema validator of one definition of the schema (``$defs`` name)."""
    from jsonschema import Draft202012Validator

    s = schema()
    return Draft202012Validator({"$schema": s["$schema"], "$defs": s["$defs"], "$ref": f"#/$defs/{definition}"})


def _reject_constant(name: str):
    raise ValueError(f"{name} is not JSON")


def _tag_of(msg) -> object:
    """The client's tag if it is a valid one (echoed in errors), else None."""
    if isinstance(msg, dict):
        t = msg.get("id")
        if isinstance(t, str) and len(t) <= 64:
            return t
        if isinstance(t, int) and not isinstance(t, bool) and abs(t) <= 9007199254740991:
            return t
    return None


def parse(raw, channel: str = "npc") -> dict:
    """A validated request from raw text (str or bytes) of ``channel`` ("npc" or "game").

    Raises ProtocolError: too_large (over MAX_MESSAGE_BYTES), bad_json (not UTF-8, not JSON, NaN
    or Infinity, too deeply nested, not an object), invalid (schema violation, unknown type).
    """
    n = len(raw) if not isinstance(raw, str) or raw.isascii() else len(raw.encode("utf-8", "replace"))
    if n > MAX_MESSAGE_BYTES:
        raise ProtocolError("too_large", f"message of more than {MAX_MESSAGE_BYTES} bytes")
    try:
        if isinstance(raw, (bytes, bytearray)):
            raw = bytes(raw).decode("utf-8")
        msg = json.loads(raw, parse_constant=_reject_constant)
    except RecursionError:
        raise ProtocolError("bad_json", "JSON nested too deeply") from None
    except (ValueError, TypeError) as e:
        raise ProtocolError("bad_json", f"not JSON: {e}") from None
    if not isinstance(msg, dict):
        raise ProtocolError("bad_json", "a message is a JSON object")
    tag = _tag_of(msg)
    kind = msg.get("type")
    defs = REQUEST_DEFS[channel]
    if not isinstance(kind, str) or kind not in defs:
        raise ProtocolError("invalid", f"unknown type {str(kind)[:40]!r} (known: {', '.join(defs)})", tag)
    try:
        ok = fast_check(defs[kind])(msg)
    except RecursionError:
        ok = False
    if ok:
        return msg
    err = _first_error(validator(defs[kind]), msg)  # jsonschema decides and names the error
    if err is not None:
        raise ProtocolError("invalid", err, tag)
    return msg


def _first_error(v, msg) -> str | None:
    """The most relevant schema error of ``msg`` as a short text, or None when valid."""
    from jsonschema.exceptions import best_match

    try:
        e = best_match(v.iter_errors(msg))
    except RecursionError:
        return "message nested too deeply"
    if e is None:
        return None
    where = "/".join(str(p) for p in e.absolute_path) or "message"
    return f"{where}: {e.message[:200]}"


def observation_from(d: dict, n_actions: int, n_frames) -> "object":
    """An igraph_fight.Observation from a schema-valid observation object, its ids checked against
    the library (m_self, m_other < n_actions; 0 <= f_other < frames of m_other). Raises
    ProtocolError("bad_observation")."""
    from igraph_fight.controller import Observation

    for k in ("r", "theta_self", "theta_other"):
        if not math.isfinite(float(d[k])):
            raise ProtocolError("bad_observation", f"{k} is not finite")
    for k in ("m_self", "m_other"):
        if not 0 <= int(d[k]) < n_actions:
            raise ProtocolError("bad_observation", f"{k} = {d[k]} is not an action id (0..{n_actions - 1})")
    nf = int(n_frames[int(d["m_other"])])
    if not 0 <= int(d["f_other"]) < nf:
        raise ProtocolError("bad_observation", f"f_other = {d['f_other']} is not a frame of action {d['m_other']} "
                                               f"(0..{nf - 1})")
    return Observation(float(d["r"]), float(d["theta_self"]), float(d["theta_other"]), int(d["m_self"]),
                       int(d["m_other"]), int(d["f_other"]), int(d.get("mask_other", 0)))


def dumps(msg: dict) -> str:
    """A reply as compact JSON (non-finite numbers become null)."""
    try:
        return json.dumps(msg, separators=(",", ":"), allow_nan=False)
    except ValueError:
        return json.dumps(_finite(msg), separators=(",", ":"))


def _finite(x):
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_finite(v) for v in x]
    return x


class TokenBucket:
    """A rate limit: ``rate`` tokens a second up to ``burst``; ``take()`` False when empty."""

    def __init__(self, rate: float = RATE_PER_S, burst: float = RATE_BURST) -> None:
        self.rate = float(rate)
        self.burst = float(burst)
        self.tokens = float(burst)
        self.t = None

    def take(self, now: float, n: float = 1.0) -> bool:
        if self.t is not None:
            self.tokens = min(self.burst, self.tokens + (now - self.t) * self.rate)
        self.t = now
        if self.tokens >= n:
            self.tokens -= n
            return True
        return False


def limits() -> dict:
    """The documented limits, as ``info`` reports them."""
    return {"max_message_bytes": MAX_MESSAGE_BYTES, "ws_max_frame_bytes": WS_MAX_FRAME_BYTES, "max_batch": MAX_BATCH,
            "rate_per_s": RATE_PER_S, "rate_burst": RATE_BURST, "max_connections": MAX_CONNECTIONS,
            "max_style_file_bytes": MAX_STYLE_FILE_BYTES, "max_policies": MAX_POLICIES,
            "max_pending_policies": MAX_PENDING_POLICIES, "max_pending_tables": MAX_PENDING_TABLES}
