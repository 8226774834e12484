"""The agent interface shared by the IG fighter, the baselines and RL."""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Agent(Protocol):
    """A fighter: ``step`` returns a legal action for ``player`` in a game.FightState."""

    name: str

    def reset(self, game, player: int, rng: np.random.Generator) -> None: ...

    def step(self, state, player: int) -> int: ...


class RandomAgent:
    """Uniformly random legal actions."""

    def __init__(self, name: str = "random") -> None:
        self.name = name
        self._rng = np.random.default_rng(0)

    def reset(self, game, player: int, rng: np.random.Generator) -> None:
        self._rng = rng

    def step(self, state, player: int) -> int:
        return int(self._rng.choice(state.legal_actions(player)))
