"""The player's commands: the category rule, its fallback table, the key map, and the protocol's
schema (every documented message validates, malformed ones are refused with an error code)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from motion_graph.classify import KINDS

from igraph_fight.play import commands as cm
from igraph_fight.play import protocol as pr


def test_every_command_has_a_kind_a_fallback_row_and_a_key():
    assert set(cm.COMMANDS) == set(cm.FALLBACK)
    for c, kind in cm.COMMANDS.items():
        assert kind in KINDS
        assert all(k in KINDS for k in cm.FALLBACK[c]), c
        assert kind not in cm.FALLBACK[c]
    assert set(cm.KEYS.values()) == set(cm.COMMANDS)
    rows = cm.fallback_table()
    assert [r["command"] for r in rows] == list(cm.COMMANDS) and all(r["keys"] for r in rows)
    # the schema's command enum is the same list
    assert pr.schema()["$defs"]["command"]["enum"] == list(cm.COMMANDS)


def test_resolve_takes_the_best_rated_action_of_the_category():
    kinds = np.array([KINDS.index(k) for k in ("jab", "jab", "straight", "guard", "dodge")])
    acts = np.array([0, 1, 2, 3, 4])
    scores = np.array([0.1, 0.5, 2.0, 0.0, -1.0])
    r = cm.resolve("jab", acts, scores, kinds)
    assert (r.action, r.kind, r.level) == (1, "jab", 0)
    assert cm.resolve("straight", acts, scores, kinds).action == 2


def test_resolve_falls_back_along_the_table_then_to_the_best_action():
    kinds = np.array([KINDS.index(k) for k in ("straight", "guard", "dodge", "step_back")])
    acts = np.array([10, 11, 12, 13])
    kind_of = np.full(20, -1)
    kind_of[acts] = kinds
    scores = np.array([1.0, 0.0, 3.0, 2.0])
    # forward: no step_forward, step_left, step_right -> straight (third entry of the row)
    r = cm.resolve("forward", acts, scores, kind_of)
    assert (r.action, r.kind) == (10, "straight") and r.level == cm.categories("forward").index("straight")
    # duck: no duck -> dodge
    assert cm.resolve("duck", acts, scores, kind_of).kind == "dodge"
    # turn_left: nothing of its row (turn_left, step_left, guard) but guard -> guard
    assert cm.resolve("turn_left", acts, scores, kind_of).kind == "guard"
    # a menu with none of the row: the best-rated action of any kind, level -1
    only = np.array([12, 13])
    r = cm.resolve("jab", only, np.array([0.5, 0.7]), kind_of)
    assert (r.action, r.level) == (13, -1)
    with pytest.raises(ValueError):
        cm.resolve("jab", np.array([], dtype=np.int64), np.array([]), kind_of)
    with pytest.raises(ValueError):
        cm.resolve("kick_the_bucket", acts, scores, kind_of)


OBS = {"r": 1.4, "theta_self": 0.1, "theta_other": -0.2, "m_self": 1, "m_other": 2, "f_other": 3}


@pytest.mark.parametrize("msg", [
    {"v": 1, "type": "decide", "obs": OBS},
    {"v": 1, "type": "decide", "id": "x", "batch": [OBS, {**OBS, "mask_other": 3}], "style": "outboxer", "depth": 2},
    {"v": 1, "type": "set_style", "style": "infighter"},
    {"v": 1, "type": "set_depth", "depth": 5, "id": 7},
    {"v": 1, "type": "info"},
    {"v": 1, "type": "health"},
])
def test_documented_requests_validate(msg):
    assert pr.parse(json.dumps(msg)) == msg


@pytest.mark.parametrize("raw, code", [
    ("not json", "bad_json"),
    ("[1, 2]", "bad_json"),
    ('{"v": 1, "type": "decide", "obs": {"r": NaN}}', "bad_json"),
    ("[" * 5000 + "]" * 5000, "bad_json"),
    ('{"v": 1, "type": "decide"}', "invalid"),
    (json.dumps({"v": 1, "type": "decide", "obs": OBS, "batch": [OBS]}), "invalid"),
    (json.dumps({"v": 2, "type": "info"}), "invalid"),
    (json.dumps({"type": "info"}), "invalid"),
    (json.dumps({"v": 1, "type": "launch_missiles"}), "invalid"),
    (json.dumps({"v": 1, "type": "decide", "obs": {**OBS, "r": 1e300}}), "invalid"),
    ('{"v": 1, "type": "decide", "obs": {"r": 1e400}}', "invalid"),
    (json.dumps({"v": 1, "type": "decide", "obs": {**OBS, "m_self": 10 ** 30}}), "invalid"),
    ('{"v": 1, "type": "info", "id": ' + "9" * 5000 + "}", "bad_json"),
    (json.dumps({"v": 1, "type": "decide", "obs": {**OBS, "m_self": "1"}}), "invalid"),
    (json.dumps({"v": 1, "type": "decide", "batch": [OBS] * (pr.MAX_BATCH + 1)}), "invalid"),
    (json.dumps({"v": 1, "type": "info", "pad": "x" * (pr.MAX_MESSAGE_BYTES + 1)}), "too_large"),
    (b"\xff\xfe{}", "bad_json"),
])
def test_malformed_requests_get_their_error_code(raw, code):
    with pytest.raises(pr.ProtocolError) as e:
        pr.parse(raw)
    assert e.value.code == code
    rep = e.value.reply()
    assert pr.validator("rep_error").is_valid(rep) and len(rep["message"]) <= pr.MAX_ERROR_CHARS


def test_game_channel_requests():
    assert pr.parse('{"v": 1, "type": "command", "command": "jab", "held": true}', "game")["command"] == "jab"
    for bad in ('{"v": 1, "type": "command", "command": "fly"}', '{"v": 1, "type": "replay", "bout": "../etc"}',
                '{"v": 1, "type": "set_depth", "depth": 6}', '{"v": 1, "type": "decide", "obs": {}}'):
        with pytest.raises(pr.ProtocolError):
            pr.parse(bad, "game")


def test_the_schema_is_valid_and_the_token_bucket_limits():
    from jsonschema import Draft202012Validator
    Draft202012Validator.check_schema(pr.schema())
    b = pr.TokenBucket(rate=10.0, burst=3.0)
    assert [b.take(0.0) for _ in range(4)] == [True, True, True, False]
    assert b.take(0.1) and not b.take(0.1)


def _mutations(rng, msg):
    """Hostile variants of a valid message: fields dropped, retyped, out of range, added, nested."""
    import copy
    junk = [None, True, False, 0, 1, 1.0, -1, 2.5, 1e300, -1e300, 10 ** 20, "", "x" * 600, "decide", [], [1], {},
            {"a": 1}, [OBS], OBS, 7.0, 2 ** 31, 2 ** 53, -(2 ** 53), 0.0, 9.5, "../x", "ok_name-1.2", 600, 0.1]
    out = []
    for _ in range(40):
        m = copy.deepcopy(msg)
        node, path = m, []
        while isinstance(node, (dict, list)) and node and rng.random() < 0.6:
            key = rng.choice(list(node)) if isinstance(node, dict) else rng.randrange(len(node))
            path.append((node, key))
            node = node[key]
        op = rng.randrange(4)
        if not path:
            m[rng.choice(["x", "obs", "batch", "style", "depth", "id", "seconds", "speed", "held"])] = rng.choice(junk)
        else:
            parent, key = path[-1]
            if op == 0 and isinstance(parent, dict):
                del parent[key]
            elif op == 1 and isinstance(parent, dict):
                parent["extra_" + str(rng.randrange(3))] = rng.choice(junk)
            else:
                parent[key] = rng.choice(junk)
        out.append(m)
    return out


def test_the_fast_checker_agrees_with_jsonschema():
    import random
    rng = random.Random(0)
    valid = {
        "req_decide": [{"v": 1, "type": "decide", "obs": OBS}, {"v": 1, "type": "decide", "batch": [OBS, OBS], "id": 3,
                                                                  "style": "infighter", "depth": 4}],
        "req_set_style": [{"v": 1, "type": "set_style", "style": "outboxer", "id": "a"}],
        "req_set_depth": [{"v": 1, "type": "set_depth", "depth": 2}],
        "req_info": [{"v": 1, "type": "info"}], "req_health": [{"v": 1, "type": "health", "id": 0}],
        "game_command": [{"v": 1, "type": "command", "command": "jab", "held": True}],
        "game_release": [{"v": 1, "type": "release", "command": "duck"}],
        "game_set_style": [{"v": 1, "type": "set_style", "style": "balanced"}],
        "game_set_depth": [{"v": 1, "type": "set_depth", "depth": 5}],
        "game_new_bout": [{"v": 1, "type": "new_bout", "seconds": 30, "seed": 4}],
        "game_save": [{"v": 1, "type": "save"}], "game_list_bouts": [{"v": 1, "type": "list_bouts"}],
        "game_replay": [{"v": 1, "type": "replay", "bout": "20260101-000000-balanced-d3", "speed": 2}],
        "game_pause": [{"v": 1, "type": "pause", "paused": False}],
        "rep_decision": [{"v": 1, "type": "decision", "action": 3, "label": "jab", "off_graph": False, "decision_us": 4.0,
                          "style": "balanced", "depth": 3}],
        "rep_error": [{"v": 1, "type": "error", "code": "invalid", "message": "m"}],
    }
    n = agree = 0
    for name, msgs in valid.items():
        fast, slow = pr.fast_check(name), pr.validator(name)
        for m in msgs:
            assert fast(m) and slow.is_valid(m), (name, m)
            for x in _mutations(rng, m) + [None, [], "s", 3, {"v": 1}]:
                n += 1
                a, b = fast(x), slow.is_valid(x)
                assert a == b, (name, x, a, b)
                agree += int(not a)
    assert n > 500 and agree > n // 3   # most mutations are refused, by both
    with pytest.raises(ValueError):
        pr.compile_check({"format": "email"}, {})
