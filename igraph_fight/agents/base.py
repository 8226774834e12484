"""The one agent protocol: every fighter, kinematic or physical, IG, baseline or learned, plays it.

An agent is asked for an action when its fighter stands at a decision instant:

- in the kinematic game (igraph_fight.game), ``arena`` is the FightGame and ``view`` the FightState;
- in a physics bout (tracker.bouts), ``arena`` is the PhysicsBout and ``view`` its DecisionContext
  (the coupled state predicted at the action's end, the legal menu, physical features).

Both views answer ``legal_actions(player)``; an agent that needs the Interaction Graph's
Observation reads it with :func:`igraph_fight.agents.base.observation`.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Agent(Protocol):
    """A fighter: ``step`` returns a legal action for ``player`` at a decision instant.

    Optional methods: ``peek(view, player)``, what step would answer without side effects (a guess
    at a future decision); ``finish(player, reward, steps)``, called at a physics bout's end with
    the reward terms accumulated since the agent's last decision (learning agents)."""

    name: str

    def reset(self, arena, player: int, rng: np.random.Generator) -> None: ...

    def step(self, view, player: int) -> int: ...


def observation(view, player: int):
    """The controller Observation of ``player`` at a decision instant: the one a physics
    DecisionContext carries (``view.obs``), else computed from a FightState."""
    obs = getattr(view, "obs", None)
    if obs is not None:
        return obs
    from igraph_fight.controller import observe
    return observe(view, player)


class RandomAgent:
    """Uniformly random legal actions."""

    def __init__(self, name: str = "random") -> None:
        self.name = name
        self._rng = np.random.default_rng(0)

    def reset(self, arena, player: int, rng: np.random.Generator) -> None:
        self._rng = rng

    def step(self, view, player: int) -> int:
        return int(self._rng.choice(view.legal_actions(player)))
