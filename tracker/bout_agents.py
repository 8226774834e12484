"""Agents of a physics bout (tracker.bout): what a fighter sees when it must choose its next action
(DecisionContext), the Agent protocol, the Interaction Graph fighter, a scripted one, and the
loaders the command line uses (tracking controller, agent from a name)."""
from __future__ import annotations

import copy
import os
import re
import sys
from typing import NamedTuple, Protocol

import numpy as np


class DecisionContext(NamedTuple):
    """What an agent sees when it must choose (fighter ``k``, at bout time ``t_s`` s).

    obs: the coupled state as igraph_fight.controller.Observation (predicted at the action's end).
    menu: the legal actions Next(M_self) (library ids). world: the predicted coupled WorldState.
    features: physical features of the decider and the opponent (PhysicsBout.features).
    reward: the paper's reward terms accumulated for this fighter since its previous decision.
    steps: control steps since its previous decision.
    """

    k: int
    t_s: float
    obs: object
    menu: np.ndarray
    world: object
    features: np.ndarray
    reward: dict
    steps: int


class Agent(Protocol):
    """An action chooser. Optional: ``finish(k, reward, steps)``, called at the bout's end with the
    reward terms accumulated since the agent's last decision (learning agents); ``peek(ctx)``, what
    decide(ctx) would answer, without side effects (a guess at a future decision: PhysicsBout's
    foresight for a search tracker's look-ahead)."""

    name: str

    def reset(self, bout, k: int, rng: np.random.Generator) -> None: ...  # bout: tracker.bout.PhysicsBout

    def decide(self, ctx: DecisionContext) -> int: ...


class IGAgent:
    """An Interaction Graph fighter: the NPCController's answer for the live coupled state."""

    def __init__(self, controller, name: str | None = None) -> None:
        self.controller = controller
        self.name = name or f"{controller.style}({controller.depth})"
        self.decisions = 0
        self.off_graph = 0

    def reset(self, bout, k, rng) -> None:
        self.decisions = 0
        self.off_graph = 0

    def set_style(self, style) -> None:
        """Switch style at run time (the policy table recomputed; blocks until it is live)."""
        self.controller.set_style(style, wait=True)

    def decide(self, ctx: DecisionContext) -> int:
        d = self.controller.act(ctx.obs)
        self.decisions += 1
        self.off_graph += int(d.off_graph)
        return int(d.action)

    def peek(self, ctx: DecisionContext) -> int:
        """What decide() would answer for ``ctx``, without side effects (NPCController.peek)."""
        return self.controller.peek(ctx.obs)


class MenuAgent:
    """Scripted: a fixed preference list (first legal one wins), else a random legal action."""

    def __init__(self, prefer: list[int] | None = None, name: str = "scripted") -> None:
        self.prefer = list(prefer or [])
        self.name = name
        self.rng = np.random.default_rng(0)

    def reset(self, bout, k, rng) -> None:
        self.rng = np.random.default_rng(rng.integers(1 << 31))

    def decide(self, ctx: DecisionContext) -> int:
        return self._choose(ctx, self.rng)

    def peek(self, ctx: DecisionContext) -> int:
        """What decide(ctx) would answer (its generator copied, so none of its draws is used)."""
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

    def reset(self, bout, k, rng) -> None:
        self.closing = 0
        self._last = None
        self.inner.reset(bout, k, rng)

    def _rule(self, ctx: DecisionContext) -> int | None:
        # the last answer kept: peek() may be asked every control step about the same decision
        key = (np.asarray(ctx.menu).tobytes(), float(ctx.obs.r), float(ctx.obs.theta_self))
        if self._last is None or self._last[0] != key:
            self._last = (key, self.rule.choose(ctx.menu, key[1], key[2], self.library))
        return self._last[1]

    def decide(self, ctx: DecisionContext) -> int:
        a = self._rule(ctx)
        if a is None:
            return int(self.inner.decide(ctx))
        self.closing += 1
        return a

    def peek(self, ctx: DecisionContext) -> int:
        """What decide() would answer, without side effects (the inner agent's peek when engaged)."""
        a = self._rule(ctx)
        return int(self.inner.peek(ctx)) if a is None else a


def load_tracker(spec: str | None = None):
    """The tracking controller: ``"pd"``, a checkpoint path, None for the shipped learned policy
    (tracker/checkpoints/boxing_cmu13.pt; PD with a warning on stderr when it is missing), or
    ``"search[:C,L][:early|full][:reuse][:incr][:first][:upfirst][:heading=W][:yawtol=RAD][:aim=W][:touch=W][:lead=W][:spread=F][:duel][:foresee][:CKPT]"``: that
    policy steered by a run-time search (tracker.bout_search; default tracker.bout_search.BOUT_SEARCH;
    C candidates, L look-ahead control steps, early acceptance on or off, and the other knobs of
    tracker.search_controller.SearchSettings; aim=W: the planned strikes aimed with weight W (touch=W: and
    each rollout step with the strike's fist on a target rewarded with W; lead=W: the striker's pelvis
    kept on its reference from 0.5 s before each planned strike's window to its end; spread=F:
    the arm offsets' sigma times F while aiming); duel:
    the rollouts in a copy of the whole bout, the opponent on its plain policy; foresee: the look-ahead
    past a fighter's current action reads the actions its agent would choose next (PhysicsBout._foresee)
    instead of the action's last frame held still;
    offline quality, slower than real time).
    The environment variable IGRAPH_FIGHT_TRACKER gives the default."""
    spec = spec or os.environ.get("IGRAPH_FIGHT_TRACKER") or None
    if spec is not None and (spec == "search" or spec.startswith("search:")):
        return load_bout_search(spec)
    if spec == "pd":
        from .pd import PDController
        return PDController()
    from .policy import DEFAULT_CKPT, load_policy
    if spec is None and not DEFAULT_CKPT.is_file():
        from .pd import PDController
        print(f"tracker.bout: no learned tracker at {DEFAULT_CKPT}; tracking with PD "
              "(give a checkpoint with IGRAPH_FIGHT_TRACKER=PATH)", file=sys.stderr)
        return PDController()
    return load_policy(spec)


# spec tokens -> SearchSettings flags
_FLAGS = {"reuse": "reuse", "incr": "incremental", "first": "first_kept", "upfirst": "up_first"}


def load_bout_search(spec: str):
    """``search[:C,L][:early|full][:reuse][:incr][:first][:upfirst][:heading=W][:yawtol=RAD][:aim=W][:touch=W][:lead=W][:spread=F][:duel][:foresee][:CKPT]`` ->
    tracker.bout_search.BoutSearchTracker (see load_tracker)."""
    from dataclasses import replace

    from .bout_search import BOUT_SEARCH, BoutSearchTracker
    from .policy import load_policy
    settings, ckpt, duel, foresee = BOUT_SEARCH, None, False, False
    aimed = {"aim": 0.0, "touch": 0.0, "lead": 0.0, "spread": 1.0}
    for tok in spec.split(":")[1:]:
        c, comma, la = tok.partition(",")
        if comma and c.isdigit() and la.isdigit():
            if int(c) < 1 or int(la) < 0:
                raise ValueError(f"tracker {spec!r}: candidates >= 1 and look-ahead >= 0 control steps")
            settings = replace(settings, candidates=int(c), lookahead=int(la))
        elif tok in ("early", "full"):
            settings = replace(settings, early_accept=tok == "early")
        elif tok in _FLAGS:
            settings = replace(settings, **{_FLAGS[tok]: True})
        elif tok == "duel":
            duel = True
        elif tok == "foresee":
            foresee = True
        elif tok.startswith(("aim=", "touch=", "lead=", "spread=")):
            name, _, val = tok.partition("=")
            try:
                aimed[name] = float(val)
            except ValueError:
                raise ValueError(f"tracker {spec!r}: {name}= needs a number") from None
        elif tok.startswith(("heading=", "yawtol=")):
            name, _, val = tok.partition("=")
            try:
                settings = replace(settings, **{"heading_weight" if name == "heading" else "yaw_tol": float(val)})
            except ValueError:
                raise ValueError(f"tracker {spec!r}: {name}= needs a number") from None
        elif tok:
            ckpt = tok
    return BoutSearchTracker(load_policy(ckpt), settings, aim=aimed["aim"], duel=duel, aim_spread=aimed["spread"],
                             touch=aimed["touch"], lead=aimed["lead"], foresee=foresee)


def make_agent(spec: str, graph, library, depth: int, first_ply: str = "table", future: str = "calibrated"):
    """An agent from a name: a style (preset name or style file) gives an IG fighter at ``depth``
    (its NPCController's ``first_ply``); ``STYLE+phys`` or ``STYLE+phys:MODEL`` the IG fighter
    whose first ply uses physically measured hit odds (tracker.hit_model; default the shipped
    model; later plies by ``future``); ``rl`` or ``rl:CKPT`` the physics RL baseline
    (tracker.physics_rl). ``+close[=R,THETA][:avoid=A,B,...]`` after a style (with or without +phys)
    wraps the fighter in a ClosingAgent (igraph_fight.closing.ClosingRule: engaged within R metres
    and THETA radians of facing, defaults 1.6 m, 1.0 rad; avoid: library ids the rule does not
    launch, e.g. from ``python -m tracker.fall_odds``)."""
    if spec == "rl" or spec.startswith("rl:"):
        from .physics_rl import load_rl_agent
        return load_rl_agent(spec[3:] or None, library)
    from igraph_fight.controller import NPCController
    # options split off at "+phys" / "+close" only, so a style file's path may hold a "+"
    style, *opts = re.split(r"\+(?=(?:phys|close)(?:[:=]|$|\+))", spec)
    if "+" in style and not os.path.exists(style):
        opts = [style.split("+", 1)[1]] + opts              # an unknown option, not a style file
    phys, close = None, None
    for opt in opts:
        kind, arg = ("close", opt[5:]) if opt.startswith("close") else opt.partition(":")[::2]
        if kind == "phys" and phys is None:
            phys = arg
        elif kind == "close" and close is None:
            close = _closing_rule(arg, spec)
        else:
            raise ValueError(f"unknown or repeated fighter option {opt!r} in {spec!r} "
                             "(STYLE+phys[:MODEL], STYLE+close[=R,THETA][:avoid=A,B,...] or both)")
    if phys is not None:
        from .hit_model import phys_fighter
        ag = phys_fighter(graph, library, style, depth, phys or None, future)
    else:
        npc = NPCController(graph, library, style=style, depth=depth, first_ply=first_ply)
        ag = IGAgent(npc, f"{npc.style}({depth}{'' if first_ply == 'table' else ', ' + first_ply})")
    if close is None:
        return ag
    lib = library if library is not None else ag.controller.library
    try:
        return ClosingAgent(ag, lib, close)
    except ValueError:
        getattr(ag.controller, "close", lambda: None)()      # the inner fighter's policy worker
        raise


def _closing_rule(arg: str, spec: str):
    """What follows ``close`` in ``close[=R,THETA][:avoid=A,B,...]`` (metres, radians, library ids)
    -> igraph_fight.closing.ClosingRule."""
    from igraph_fight.closing import ClosingRule
    kw = {}
    head, *opts = arg.split(":")
    if head:
        try:
            if not head.startswith("="):
                raise ValueError(f"unexpected {head!r}")
            r, th = (float(v) for v in head[1:].split(","))
            kw.update(engage_r_m=r, engage_theta_rad=th)
        except ValueError as e:
            raise ValueError(f"fighter {spec!r}: close=R,THETA needs a distance in metres and an angle in radians "
                             f"({e})") from None
    for o in opts:
        name, _, val = o.partition("=")
        try:
            if name != "avoid" or "avoid" in kw:
                raise ValueError(f"unknown or repeated {o!r}")
            kw["avoid"] = tuple(int(v) for v in val.split(","))
        except ValueError as e:
            raise ValueError(f"fighter {spec!r}: close[=R,THETA][:avoid=A,B,...] takes library action ids after "
                             f"avoid= ({e})") from None
    try:
        return ClosingRule(**kw)
    except ValueError as e:
        raise ValueError(f"fighter {spec!r}: {e}") from None
