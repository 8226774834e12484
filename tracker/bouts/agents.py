"""What a physics bout's agent sees when it must choose its next action (DecisionContext), and the
bout's own agents: a scripted one (MenuAgent) and the closing rule around another (ClosingAgent).

Every agent plays the one protocol of igraph_fight.agents.base.Agent: ``reset(bout, player, rng)``,
``step(ctx, player) -> int`` (ctx a DecisionContext, player == ctx.k), optional ``peek(ctx, player)``
(what step would answer, without side effects: the bout's foresight) and ``finish(player, reward,
steps)`` (the reward terms accumulated since its last decision, at the bout's end). The Interaction
Graph fighter is igraph_fight.agents.ig.IGAgent (``snap=False`` in physics); the physics RL baseline
tracker.bouts.rl_agent.PhysicsRLAgent; agents from a name: tracker.bouts.loaders.make_agent.
"""
from __future__ import annotations

import copy
from typing import NamedTuple

import numpy as np


class DecisionContext(NamedTuple):
    """What an agent sees when it must choose (fighter ``k``, at bout time ``t_s`` s).

    obs: the coupled state as igraph_fight.controller.Observation (predicted at the action's end).
    menu: the legal actions Next(M_self) (library ids). world: the predicted coupled WorldState.
    features: physical features of the decider and the opponent (PhysicsBout.features).
    reward: the paper's reward terms accumulated for this fighter since its previous decision.
    steps: control steps since its previous decision.

    Like the kinematic FightState, it answers ``legal_actions(player)`` (the decider's menu), and an
    agent reads its Observation with igraph_fight.agents.base.observation(ctx, player).
    """

    k: int
    t_s: float
    obs: object
    menu: np.ndarray
    world: object
    features: np.ndarray
    reward: dict
    steps: int

    def legal_actions(self, player: int) -> np.ndarray:
        """The legal next actions of ``player`` (only the decider's, ``k``, are known here)."""
        if player != self.k:
            raise ValueError(f"a DecisionContext holds fighter {self.k}'s menu, not fighter {player}'s")
        return self.menu


class MenuAgent:
    """Scripted: a fixed preference list (first legal one wins), else a random legal action."""

    def __init__(self, prefer: list[int] | None = None, name: str = "scripted") -> None:
        self.prefer = list(prefer or [])
        self.name = name
        self.rng = np.random.default_rng(0)

    def reset(self, bout, player: int, rng: np.random.Generator) -> None:
        self.rng = np.random.default_rng(rng.integers(1 << 31))

    def step(self, ctx: DecisionContext, player: int) -> int:
        return self._choose(ctx, self.rng)

    def peek(self, ctx: DecisionContext, player: int) -> int:
        """What step(ctx) would answer (its generator copied, so none of its draws is used)."""
        return self._choose(ctx, copy.deepcopy(self.rng))

    def _choose(self, ctx: DecisionContext, rng: np.random.Generator) -> int:
        menu = set(int(a) for a in ctx.menu)
        for a in self.prefer:
            if a in menu:
                return a
        return int(rng.choice(ctx.menu))


class ClosingAgent:
    """An agent that closes in by a geometric rule (igraph_fight.closing.ClosingRule) while the
    fighter faces away from its opponent or stands out of range, and lets ``inner`` decide once it
    is engaged. Counts the decisions the rule took (``closing``); other attributes (controller,
    decisions, off_graph, set_style) are the inner agent's."""

    def __init__(self, inner, library, rule=None) -> None:
        from igraph_fight.closing import ClosingRule
        self.inner = inner
        self.library = library
        self.rule = rule if rule is not None else ClosingRule()
        bad = [a for a in self.rule.avoid if not 0 <= a < library.n_actions]
        if bad:
            raise ValueError(f"closing rule: avoid names actions {bad} outside the library's 0..{library.n_actions - 1}")
        self.name = f"{inner.name}+close"
        self.closing = 0
        self._last = None

    def __getattr__(self, name: str):
        if name == "inner":                   # not set yet (copy, pickle): no recursion
            raise AttributeError(name)
        return getattr(self.inner, name)

    def reset(self, bout, player: int, rng: np.random.Generator) -> None:
        self.closing = 0
        self._last = None
        self.inner.reset(bout, player, rng)

    def _rule(self, ctx: DecisionContext) -> int | None:
        # the last answer kept: peek() may be asked every control step about the same decision
        key = (np.asarray(ctx.menu).tobytes(), float(ctx.obs.r), float(ctx.obs.theta_self))
        if self._last is None or self._last[0] != key:
            self._last = (key, self.rule.choose(ctx.menu, key[1], key[2], self.library))
        return self._last[1]

    def step(self, ctx: DecisionContext, player: int) -> int:
        a = self._rule(ctx)
        if a is None:
            return int(self.inner.step(ctx, player))
        self.closing += 1
        return a

    def peek(self, ctx: DecisionContext, player: int) -> int:
        """What step() would answer, without side effects (the inner agent's peek when engaged)."""
        a = self._rule(ctx)
        return int(self.inner.peek(ctx, player)) if a is None else a
