"""The player's high-level commands (paper section 7.1) and how each becomes a library action.

A command names a category of actions (an action kind of motion_graph.classify.KINDS). At the
player's decision instant the command is resolved over Next(M), the legal menu:

1. every legal action is rated for the player by the Interaction Graph (``rate_menu``: the
   NPCController's ``menu_terms`` for the player's side under the player's own style, score =
   -positional cost + damage given - damage received + defence + gamma * graph value where the
   action lands: what the controller's lookahead maximises);
2. the best-rated legal action whose kind is the command's category is chosen;
3. when the menu holds no action of that category, the next category of the command's row in
   ``FALLBACK`` is tried, in order ("nearest": closest in purpose: another step for a step,
   another punch for a punch, another defence for a defence, then the guard);
4. when no category of the row is legal either, the best-rated legal action of any kind.

Without a queued or held command the player's fighter plays the ``idle`` command (``guard``
by default: the player stays in control; ``best`` lets the graph choose the whole menu).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from motion_graph.classify import KINDS

#: command -> the action kind it asks for
COMMANDS: dict[str, str] = {
    "forward": "step_forward",
    "back": "step_back",
    "left": "step_left",
    "right": "step_right",
    "turn_left": "turn_left",
    "turn_right": "turn_right",
    "jab": "jab",
    "straight": "straight",
    "dodge": "dodge",
    "duck": "duck",
    "guard": "guard",
}

#: command -> the categories tried, in order, when the menu has no action of the command's own kind
FALLBACK: dict[str, tuple[str, ...]] = {
    "forward": ("step_left", "step_right", "straight", "jab", "guard"),
    "back": ("dodge", "duck", "step_left", "step_right", "guard"),
    "left": ("turn_left", "step_forward", "step_back", "guard"),
    "right": ("turn_right", "step_forward", "step_back", "guard"),
    "turn_left": ("step_left", "guard"),
    "turn_right": ("step_right", "guard"),
    "jab": ("straight", "hook", "uppercut", "guard"),
    "straight": ("jab", "hook", "uppercut", "guard"),
    "dodge": ("duck", "step_back", "guard"),
    "duck": ("dodge", "step_back", "guard"),
    "guard": ("dodge", "duck", "step_back"),
}

#: KeyboardEvent.code -> command (the page shows this map; one home)
KEYS: dict[str, str] = {
    "KeyW": "forward", "ArrowUp": "forward",
    "KeyS": "back", "ArrowDown": "back",
    "KeyA": "left",
    "KeyD": "right",
    "KeyQ": "turn_left", "ArrowLeft": "turn_left",
    "KeyE": "turn_right", "ArrowRight": "turn_right",
    "KeyJ": "jab",
    "KeyK": "straight",
    "KeyL": "dodge",
    "Space": "duck",
    "KeyF": "guard",
}

#: what the player's fighter does without a command
IDLE_MODES = ("guard", "best")


class Resolution(NamedTuple):
    """A command resolved: the action, the kind it has, the fallback level used (0: the command's
    own kind, k: the k-th category of its FALLBACK row, -1: the best-rated action of any kind)
    and the action's rating."""

    action: int
    kind: str
    level: int
    score: float


def categories(command: str) -> tuple[str, ...]:
    """The command's own kind followed by its fallback row."""
    if command not in COMMANDS:
        raise ValueError(f"unknown command {command!r} (known: {', '.join(COMMANDS)})")
    return (COMMANDS[command],) + FALLBACK[command]


def rate_menu(controller, obs) -> tuple[np.ndarray, np.ndarray]:
    """(legal actions, their ratings) for the fighter whose Observation is ``obs``, under the
    controller's style (NPCController.menu_terms: one simulated event per legal action)."""
    from igraph_fight.controller import MT_ACTION, MT_DEF, MT_GIVEN, MT_POS, MT_RECEIVED, MT_VALUE

    t = controller.menu_terms(obs)
    score = -t[:, MT_POS] + t[:, MT_GIVEN] - t[:, MT_RECEIVED] + t[:, MT_DEF] + t[:, MT_VALUE]
    return t[:, MT_ACTION].astype(np.int64), score


def resolve(command: str, actions: np.ndarray, scores: np.ndarray, action_kinds: np.ndarray) -> Resolution:
    """The action a command launches from a rated menu (module docstring). ``action_kinds`` maps a
    library action id to its KINDS index. Raises ValueError for an empty menu or an unknown command."""
    if len(actions) == 0:
        raise ValueError("empty menu: no legal action")
    kinds = np.asarray(action_kinds)[np.asarray(actions, dtype=np.int64)]
    for level, cat in enumerate(categories(command)):
        if cat not in KINDS:
            continue
        sel = np.nonzero(kinds == KINDS.index(cat))[0]
        if len(sel):
            j = int(sel[int(np.argmax(scores[sel]))])
            return Resolution(int(actions[j]), cat, level, float(scores[j]))
    j = int(np.argmax(scores))
    k = int(kinds[j])
    return Resolution(int(actions[j]), KINDS[k] if 0 <= k < len(KINDS) else "?", -1, float(scores[j]))


def fallback_table() -> list[dict]:
    """The command table as the page and the docs show it: command, kind, fallback row, keys."""
    keys: dict[str, list[str]] = {}
    for code, cmd in KEYS.items():
        keys.setdefault(cmd, []).append(code)
    return [{"command": c, "kind": k, "fallback": list(FALLBACK[c]), "keys": keys.get(c, [])} for c, k in COMMANDS.items()]
