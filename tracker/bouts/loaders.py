"""Loaders the command lines use: the tracking controller of a physics bout (load_tracker), an
agent from a name (make_agent) and the action library of a graph or library file (bout_library)."""
from __future__ import annotations

import os
import re
import sys

from igraph_fight.agents.ig import IGAgent

from tracker.bouts.agents import ClosingAgent


def load_tracker(spec=None):
    """The tracking controller of a physics bout:
    - None (the default): the shipped learned assisted tracker
      (tracker/checkpoints/assisted_cmu13.pt; assisted physics, its bounded wrench reported), else,
      when that file is missing, the legacy policy, else PD (a warning on stderr);
    - ``"assisted"`` or ``"assisted:CKPT"``: the learned assisted tracker (tracker.track.assisted_policy),
      ``"assisted-off[:CKPT]"`` the same policy with its assist off (plain physics);
      ``"assisted+hold=H[:CKPT]"``: the same with H times the fixed assist's pull toward the
      reference root pose added to its wrench (under the same cap);
    - ``"pd-batch"``: PD tracking on the batched env, no assist; ``"pd-fixed"`` or
      ``"pd-fixed=CAP"``: PD with the fixed assist (cap in body weights, default 0.5);
    - ``"legacy"`` or ``"legacy:CKPT"``: the unassisted per-fighter policy
      (tracker/checkpoints/boxing_cmu13.pt); ``"pd"``: plain PD on the per-fighter env; any other
      string: a legacy policy checkpoint path;
    - a tracker object (``reset(env)``, ``act(env, obs)``), returned as it is.
    The environment variable IGRAPH_FIGHT_TRACKER gives the default spec."""
    if spec is not None and not isinstance(spec, (str, os.PathLike)):
        return spec
    spec = spec or os.environ.get("IGRAPH_FIGHT_TRACKER") or None
    if spec is None:
        from tracker.track.assisted_policy import DEFAULT_ASSISTED_CKPT
        if DEFAULT_ASSISTED_CKPT.is_file():
            spec = "assisted"
        else:
            print(f"tracker.bouts: no assisted tracker at {DEFAULT_ASSISTED_CKPT}; using the legacy policy "
                  "(train one: igraph-fight tracker train-assisted)", file=sys.stderr)
    if isinstance(spec, str) and (spec == "legacy" or spec.startswith("legacy:")):
        spec = spec[7:] or None
        if spec is None:
            from tracker.track.policy_net import DEFAULT_CKPT
            if not DEFAULT_CKPT.is_file():
                raise ValueError(f"tracker 'legacy': no legacy policy at {DEFAULT_CKPT}")
    if isinstance(spec, str) and spec.split(":")[0].split("+")[0] in ("assisted", "assisted-off"):
        from tracker.track.assisted_policy import load_assisted
        kind, _, path = spec.partition(":")
        kind, _, extra = kind.partition("+")
        hold = 0.0
        if extra:
            name, _, val = extra.partition("=")
            try:
                hold = float(val)
            except ValueError:
                hold = -1.0
            if name != "hold" or kind != "assisted" or not 0.0 <= hold <= 2.0:
                raise ValueError(f"tracker {spec!r}: expected assisted+hold=H[:CKPT] with H in [0, 2]")
        return load_assisted(path or None, assist_off=kind == "assisted-off", hold=hold)
    if isinstance(spec, str) and (spec == "pd-batch" or spec.startswith("pd-fixed")):
        from tracker.track.pd import STANCE_GAINS, PDTracker
        if spec == "pd-batch":
            return PDTracker(class_scale=STANCE_GAINS)
        cap = spec.partition("=")[2]
        try:
            c = float(cap) if cap else 0.5
        except ValueError:
            raise ValueError(f"tracker {spec!r}: pd-fixed=CAP takes the cap in body weights") from None
        return PDTracker(class_scale=STANCE_GAINS, assist_mode="fixed", assist_cap=c, name="pd-fixed")
    if isinstance(spec, str) and (spec == "search" or spec.startswith("search:")):
        raise ValueError(f"tracker {spec!r}: the bout search trackers are an offline experiment, run by "
                         "python -m research.bout_search fight|series|rl-eval --tracker search[:...]")
    if spec == "pd":
        from tracker.track.pd import PDController
        return PDController()
    from tracker.track.policy_net import DEFAULT_CKPT, load_policy
    if spec is None and not DEFAULT_CKPT.is_file():
        from tracker.track.pd import PDController
        print(f"tracker.bouts: no learned tracker at {DEFAULT_CKPT}; tracking with PD "
              "(give a checkpoint with IGRAPH_FIGHT_TRACKER=PATH)", file=sys.stderr)
        return PDController()
    return load_policy(spec)


def make_agent(spec: str, graph, library, depth: int, first_ply: str = "table", future: str = "calibrated"):
    """An agent from a name: a style (preset name or style file) gives an IG fighter at ``depth``
    (its NPCController's ``first_ply``); ``STYLE+phys`` or ``STYLE+phys:MODEL`` the IG fighter
    whose first ply uses physically measured hit odds (tracker.bouts.hit_model; default the shipped
    model; later plies by ``future``); ``rl`` or ``rl:CKPT`` the physics RL baseline
    (tracker.bouts.rl_agent). ``+close[=R,THETA][:avoid=A,B,...]`` after a style (with or without +phys)
    wraps the fighter in a ClosingAgent (igraph_fight.closing.ClosingRule: engaged within R metres
    and THETA radians of facing, defaults 1.6 m, 1.0 rad; avoid: library ids the rule does not
    launch, e.g. from ``python -m research.fall_odds``)."""
    if spec == "rl" or spec.startswith("rl:"):
        from tracker.bouts.rl_agent import load_rl_agent
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
        from tracker.bouts.hit_model import phys_fighter
        ag = phys_fighter(graph, library, style, depth, phys or None, future)
    else:
        npc = NPCController(graph, library, style=style, depth=depth, first_ply=first_ply)
        ag = IGAgent(npc, name=f"{npc.style}({depth}{'' if first_ply == 'table' else ', ' + first_ply})", snap=False)
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


def bout_library(graph: str | None, library: str | None):
    """The action library of a library file, else the one embedded in the graph file."""
    if library:
        from motion_graph.library import load_library
        return load_library(library)
    from igraph_fight.graph import load_graph
    return load_graph(graph).load_library()
