"""The physics bouts' commands, added to `igraph-fight tracker` by tracker.cli.register:

    igraph-fight tracker bouts fight --graph G.igz --a STYLE --b STYLE ...   (one bout with artifacts)
    igraph-fight tracker bouts series --graph G.igz --a STYLE --b STYLE --bouts N ...
    igraph-fight tracker rl train --graph G.igz --tracker CKPT --minutes M --out rl.pt
    igraph-fight tracker rl eval --graph G.igz [--rl rl.pt] --styles infighter,outboxer --bouts N
    igraph-fight tracker hit-model collect|kinds|train ...

and `igraph-fight fight --physics ...` (cmd_physics_fight, the igraph_fight.physics entry point).
Only argparse here: the bouts' modules load when a command runs.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from igraph_fight.cli import (check_swap, depth, non_negative_int, positive_float, positive_int, probability, swap,
                              user_error_line)

#: the IG fighters' first-ply rules (igraph_fight.controller.FIRST_PLY) and the hit model's later plies
#: (tracker.bouts.hit_model.FUTURES), checked when a command runs
FIRST_PLY_HELP = "table (default), exact or exact2"
FUTURE_HELP = "calibrated (default), physical, kinematic or none"

TRACKER_HELP = ("tracking controller: assisted[:CKPT] (the default: the shipped learned tracker, assisted physics "
                "with its bounded wrench reported), assisted-off[:CKPT] (the same policy, plain physics), "
                "assisted+hold=H[:CKPT] (plus H times the fixed pull to the reference root, same cap), "
                "pd-fixed[=CAP], pd-batch, legacy[:CKPT] or pd")
FIGHTER_HELP = ("style, STYLE+phys[:MODEL] (physically measured hit odds, tracker.bouts.hit_model), "
                "STYLE+close[=R,THETA][:avoid=A,B,...] (closes in by a geometric rule until engaged within R m "
                "and THETA rad, never launching the avoided library actions: igraph_fight.closing), both, or "
                "rl[:CKPT] for the physics RL baseline")
ROOT_ASSIST_HELP = "diagnostic, NOT physics: hold the pelvises on the references"
FACING_HELP = ("which way a fallen fighter faces when it gets up: towards the opponent (default) or its "
               "fighting direction when the fall was detected")
RESET_HELP = ("where a fallen fighter gets up: on its reference pelvis (default; the topple undone) or where "
              "its pelvis was when the fall was detected")


def format_assist(who: str, a: dict) -> str:
    """One fighter's assist figures (tracker.track.assist.summarise_assist) as a line."""
    return (f"assist {who} (cap {a['cap_mg']:g} mg): |F| mean {a['force_mean_mg']:.3f} mg (p95 {a['force_p95_mg']:.3f}), "
            f"|tau| mean {a['torque_mean_mgm']:.3f} mg m (p95 {a['torque_p95_mgm']:.3f}), "
            f"{100 * a['at_cap_share']:.1f}% of steps at the cap, impulse {a['impulse_n_s_per_s']:.0f} N s per s")


def format_summary(s: dict) -> str:
    def pct(x):
        return "n/a" if x is None else f"{100 * x:.0f}%"
    lines = [
        f"{s['a']} (A) vs {s['b']} (B), {s['seconds']:.1f} s physics bout (seed {s['seed']}): hits A {s['hits_a']:.0f}, "
        f"hits B {s['hits_b']:.0f}, score {s['score']:+.0f}, mean distance {s['mean_distance_m']:.2f} m",
        f"  falls: A {s['falls_a']} ({s['falls_per_min_a']:.1f}/min), B {s['falls_b']} ({s['falls_per_min_b']:.1f}/min)",
        f"  planned hits {s['planned_hits']:.0f} (A {s['planned_hits_a']:.0f}, B {s['planned_hits_b']:.0f}), realised "
        f"{s['planned_realised']:.0f} ({pct(s['planned_realised_ratio'])}; while both stood: "
        f"{pct(s['planned_realised_ratio_standing'])}); unplanned hits {s['unplanned_hits']:.0f}; "
        f"touches A {s['touches_a']} B {s['touches_b']}",
        f"  clipped fist force given: A {s['damage_n_a']:.0f} N, B {s['damage_n_b']:.0f} N (sum over control steps)",
        f"  real-time factor {s['realtime_factor']:.2f}x (rendering excluded; load {s.get('machine_load')}); "
        f"tracker: {s['tracker']}",
    ]
    if s.get("physics_label"):
        lines.append(f"  {s['physics_label']}")
    for k in ("a", "b"):
        if f"assist_{k}" in s:
            lines.append("  " + format_assist(k.upper(), s[f"assist_{k}"]))
    if "hits_at_cap" in s:
        lines.append(f"  hits landed while the hitter's assist was at its cap: {s['hits_at_cap']}")
    if s.get("root_assist"):
        lines.append("  ROOT ASSIST ON: pelvises held on the references by welds; not physics, falls impossible")
    for k, v in s["artifacts"].items():
        lines.append(f"  {k}: {v}")
    return "\n".join(lines)


def cmd_physics_fight(args: argparse.Namespace) -> int:
    """`igraph-fight fight --physics` and `igraph-fight tracker bouts fight`: args of
    igraph_fight.cli.fight (graph, library, a, b, depth_a, depth_b, swap_a, seconds, seed, out, json);
    optional attributes tracker (a spec for tracker.bouts.loaders.load_tracker, or a tracker object),
    video, video_fps, root_assist, reset_place, reset_facing, max_wall_s (`tracker bouts fight` sets
    them; IGRAPH_FIGHT_TRACKER and IGRAPH_FIGHT_VIDEO=0 are the environment defaults)."""
    from tracker.bouts.run import run_physics_fight
    from tracker.bouts.setup import BoutConfig
    video = getattr(args, "video", None)
    if video is None:
        video = os.environ.get("IGRAPH_FIGHT_VIDEO", "1") not in ("0", "false", "no")
    try:
        if not args.seconds > 0:
            raise ValueError(f"--seconds must be > 0, got {args.seconds}")
        swap_a = check_swap(getattr(args, "swap_a", None), args.seconds)
        summary = run_physics_fight(args.graph, args.a, args.b, args.depth_a, args.depth_b, args.seconds, args.seed,
                                    args.out, library=args.library, swap_a=swap_a,
                                    tracker=getattr(args, "tracker", None), video=video,
                                    video_fps=float(getattr(args, "video_fps", 15.0) or 15.0),
                                    root_assist=bool(getattr(args, "root_assist", False)),
                                    progress=not args.json, max_wall_s=getattr(args, "max_wall_s", None),
                                    config=BoutConfig(seconds=args.seconds,
                                                      reset_place=getattr(args, "reset_place", "reference"),
                                                      reset_facing=getattr(args, "reset_facing", "opponent")))
    except (FileNotFoundError, ValueError) as e:
        print(user_error_line(e), file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(summary))
    else:
        print(format_summary(summary))
    return 0


def add_fight_arguments(f: argparse.ArgumentParser, tracker_help: str = TRACKER_HELP) -> None:
    """Options of `tracker bouts fight` (one physics bout with artifacts)."""
    f.add_argument("--graph", required=True)
    f.add_argument("--library", default=None)
    f.add_argument("--a", default="infighter", help=FIGHTER_HELP)
    f.add_argument("--b", default="outboxer")
    f.add_argument("--depth-a", type=depth, default=5)
    f.add_argument("--depth-b", type=depth, default=5)
    f.add_argument("--swap-a", type=swap, default=None, help="T:STYLE: fighter A switches to STYLE at T seconds")
    f.add_argument("--seconds", type=positive_float, default=60.0)
    f.add_argument("--seed", type=non_negative_int, default=1)
    f.add_argument("--out", default="out/fight")
    f.add_argument("--tracker", default=None, help=tracker_help)
    f.add_argument("--no-video", dest="video", action="store_false", default=True)
    f.add_argument("--video-fps", type=positive_float, default=15.0)
    f.add_argument("--root-assist", action="store_true", help=ROOT_ASSIST_HELP)
    f.add_argument("--reset-place", choices=("reference", "fall"), default="reference", help=RESET_HELP)
    f.add_argument("--reset-facing", choices=("fall", "opponent"), default="opponent", help=FACING_HELP)
    f.add_argument("--max-wall-s", type=positive_float, default=None,
                   help="stop after this many wall-clock seconds (slow trackers); the summary covers the seconds "
                   "simulated by then (its 'seconds'), per-minute figures divide by them")
    f.add_argument("--json", action="store_true")


def add_series_arguments(r: argparse.ArgumentParser, tracker_help: str = TRACKER_HELP) -> None:
    """Options of `tracker bouts series` (N physics bouts between two agents, aggregated)."""
    r.add_argument("--graph", required=True, help="interaction graph file (.igz) the planner fighters use")
    r.add_argument("--a", default="infighter", help="fighter A (default infighter): " + FIGHTER_HELP)
    r.add_argument("--b", default="outboxer", help="fighter B (default outboxer), as --a")
    r.add_argument("--depth-a", type=depth, default=5, help="A's min-max search depth (default 5)")
    r.add_argument("--depth-b", type=depth, default=5, help="B's min-max search depth (default 5)")
    r.add_argument("--bouts", type=positive_int, default=10, help="number of bouts (default 10)")
    r.add_argument("--seconds", type=positive_float, default=60.0, help="seconds per bout (default 60)")
    r.add_argument("--seed0", type=non_negative_int, default=0,
                   help="first bout's seed (bouts use seed0, seed0+1, ...; default 0)")
    r.add_argument("--tracker", default=None, help=tracker_help)
    r.add_argument("--root-assist", action="store_true", help=ROOT_ASSIST_HELP)
    r.add_argument("--reset-place", choices=("reference", "fall"), default="reference", help=RESET_HELP)
    r.add_argument("--reset-facing", choices=("fall", "opponent"), default="opponent", help=FACING_HELP)
    r.add_argument("--out", default=None, help="write the result (with every bout's summary) as JSON")


def cmd_series(a: argparse.Namespace) -> int:
    """`tracker bouts series`; ``a.tracker``: a spec (load_tracker) or a tracker object."""
    from tracker.bouts.run import run_series
    from tracker.bouts.setup import BoutConfig
    res = run_series(a.graph, a.a, a.b, a.bouts, a.seconds, a.depth_a, a.depth_b, a.seed0, a.tracker,
                     a.root_assist, log=lambda x: print(x, flush=True),
                     config=BoutConfig(reset_place=a.reset_place, reset_facing=a.reset_facing))
    if a.out:
        from motion_graph.atomic import atomic_write_text
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(Path(a.out), json.dumps(res, indent=1))
    print(json.dumps({k: v for k, v in res.items() if k != "bouts"}, indent=1))
    return 0


def add_bout_commands(sub) -> None:
    """`bouts fight|series` under a subparsers object."""
    b = sub.add_parser("bouts", help="physics bouts between two agents (one with artifacts, or a series)",
                       description="Physics bouts: two tracked humanoids, each driven by an action-choosing agent.")
    bs = b.add_subparsers(dest="bouts_command", metavar="BOUTS_COMMAND")
    bs.required = True
    f = bs.add_parser("fight", help="one physics bout with artifacts (igraph-fight fight --physics, more options)")
    add_fight_arguments(f)
    f.set_defaults(func=cmd_physics_fight)
    r = bs.add_parser("series", help="N physics bouts between two agents, aggregated (no artifacts)")
    add_series_arguments(r)
    r.set_defaults(func=cmd_series)


# ----------------------------------------------------------------------------------------------
# the physics RL baseline


def cmd_rl_train(a: argparse.Namespace) -> int:
    from dataclasses import asdict

    from tracker.bouts.rl_agent import RLConfig
    from tracker.learn.train_physics_rl import parse_overrides, train
    try:
        kw = parse_overrides(a.set)
    except ValueError as exc:
        print(f"igraph-fight: error: tracker rl train: {exc}", file=sys.stderr)
        return 2
    if not (a.graph or a.library):
        print("igraph-fight: error: tracker rl train: --graph or --library is needed (where the actions come from)",
              file=sys.stderr)
        return 2
    cfg = RLConfig(**{**asdict(RLConfig()), **kw})
    res = train(a.graph, a.tracker, a.out, a.minutes, cfg, library=a.library, resume=a.resume,
                log=lambda s: print(s, flush=True), progress=not a.no_progress)
    print(json.dumps(res["budget"]))
    return 0


def cmd_rl_eval(a: argparse.Namespace) -> int:
    from igraph_fight.controller import FIRST_PLY

    from tracker.bouts.hit_model import FUTURES
    from tracker.bouts.rl_eval import evaluate_vs_rl, split_styles
    for name, val, allowed in (("--first-ply", a.first_ply, FIRST_PLY), ("--future", a.future, FUTURES)):
        if val not in allowed:
            print(f"igraph-fight: error: tracker rl eval: {name} {val!r}: one of {', '.join(allowed)}", file=sys.stderr)
            return 2
    res = evaluate_vs_rl(a.graph, a.rl, split_styles(a.styles), a.bouts, a.seconds, a.depth, a.tracker, a.library,
                         seed0=a.seed0, root_assist=a.root_assist, log=lambda s: print(s, flush=True),
                         first_ply=a.first_ply, hit_model=a.hit_model, future=a.future, workers=a.workers)
    summary = {k: v for k, v in res.items() if k != "styles"}
    summary["styles"] = {s: {k: v for k, v in d.items() if k != "bouts"} for s, d in res["styles"].items()}
    print(json.dumps(summary, indent=1))
    if a.out:
        from motion_graph.atomic import atomic_write_text
        Path(a.out).parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(a.out, json.dumps(res, indent=1))
    return 0


def add_rl_eval_arguments(e: argparse.ArgumentParser, tracker_help: str = TRACKER_HELP) -> None:
    """Options of `tracker rl eval` (planner+tracker fighters against the RL baseline)."""
    e.add_argument("--graph", required=True)
    e.add_argument("--library", default=None)
    e.add_argument("--rl", default=None, help="RL checkpoint (default: the shipped tracker/checkpoints/physics_rl_cmu13.pt)")
    e.add_argument("--tracker", default=None, help=tracker_help)
    e.add_argument("--styles", default="infighter,outboxer",
                   help="comma-separated IG styles; STYLE+close[=R,THETA][:avoid=A,B,...]: closes in by a geometric "
                   "rule until engaged (igraph_fight.closing)")
    e.add_argument("--bouts", type=positive_int, default=10)
    e.add_argument("--seconds", type=positive_float, default=60.0)
    e.add_argument("--depth", type=depth, default=5)
    e.add_argument("--seed0", type=non_negative_int, default=0, help="first bout's seed (bouts use seed0, seed0+1, ...)")
    e.add_argument("--first-ply", default="table",
                   help=f"the IG fighters' first plies (igraph_fight.controller.NPCController): {FIRST_PLY_HELP}")
    e.add_argument("--hit-model", nargs="?", const="default", default=None, metavar="MODEL",
                   help="IG fighters score their first ply with physically measured hit odds (tracker.bouts.hit_model; "
                        "no value: the shipped tracker/checkpoints/hit_model_cmu13.pt)")
    e.add_argument("--future", default="calibrated",
                   help=f"with --hit-model: the later plies' values (tracker.bouts.hit_model.phys_fighter): {FUTURE_HELP}")
    e.add_argument("--workers", type=positive_int, default=1, help="processes playing the bouts (same results)")
    e.add_argument("--root-assist", action="store_true", help=ROOT_ASSIST_HELP)
    e.add_argument("--out", default=None, help="write the result as JSON")


def add_rl_commands(sub) -> None:
    """`rl train|eval` under a subparsers object."""
    g = sub.add_parser("rl", help="the physics RL baseline: self-play training, evaluation against planner fighters",
                       description="The physics RL baseline (tracker.bouts.rl_agent): a policy over the action "
                                   "menus trained by self-play PPO in physics bouts.")
    gs = g.add_subparsers(dest="rl_command", metavar="RL_COMMAND")
    gs.required = True
    t = gs.add_parser("train", help="self-play PPO for a fixed wall-clock budget")
    t.add_argument("--graph", default=None, help="graph file whose embedded library gives the actions")
    t.add_argument("--library", default=None)
    t.add_argument("--tracker", required=True, help="tracking policy checkpoint (or 'pd')")
    t.add_argument("--minutes", type=positive_float, default=75.0)
    t.add_argument("--out", required=True)
    t.add_argument("--resume", default=None)
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override an RLConfig field")
    t.add_argument("--no-progress", action="store_true", help="no progress bar (the per-iteration lines stay)")
    t.set_defaults(func=cmd_rl_train)
    e = gs.add_parser("eval", help="planner+tracker fighters vs the RL baseline")
    add_rl_eval_arguments(e)
    e.set_defaults(func=cmd_rl_eval)


# ----------------------------------------------------------------------------------------------
# the hit model


def cmd_hit_model(args: argparse.Namespace) -> int:
    """`tracker hit-model collect|kinds|train`."""
    import numpy as np

    from tracker.bouts.hit_model import FUTURES
    from tracker.learn.train_hit_model import HitModelConfig, collect, kind_table, load_data, plot_report, train
    if args.cmd == "collect":
        if args.future not in FUTURES:
            print(f"igraph-fight: error: tracker hit-model collect: --future {args.future!r}: one of "
                  f"{', '.join(FUTURES)}", file=sys.stderr)
            return 2
        r = collect(args.graph, args.bouts, args.out, args.seconds, args.seed0, args.explore, args.workers,
                    args.tracker, args.rl, args.hit_model, args.future)
        print(json.dumps(r, indent=1))
        return 0
    try:
        parts = [load_data(p) for p in args.data]
    except ValueError as e:
        print(f"igraph-fight: error: tracker hit-model {args.cmd}: {e}", file=sys.stderr)
        return 2
    if args.cmd == "kinds":
        from igraph_fight.graph import load_graph
        lib = load_graph(args.graph).load_library()
        ny = min(d["y"].shape[1] for d in parts)
        data = {"action": np.concatenate([d["action"] for d in parts]),
                "y": np.concatenate([d["y"][:, :ny] for d in parts])}
        for r in kind_table(data, lib):
            print(f"{r['kind']:>13}: {r['n']:6d} decisions, {r['mean_s']:.2f} s, landed {r['given']:.3f}, hit while "
                  f"playing {r['received']:.3f}" + (f", fall in span {r['fell']:.2f}, {r['falls_per_min']:.1f} falls per "
                                                      "minute of it" if "fell" in r else ""))
        return 0
    ny = min(d["y"].shape[1] for d in parts)          # early files have no fall column
    for d in parts:
        d["y"] = d["y"][:, :ny]
    data = {k: np.concatenate([d[k] for d in parts]) for k in ("X", "y", "action", "seed", "rl")}
    data["meta"] = [d["meta"] for d in parts]
    from tracker.learn.overrides import parse_config_overrides
    try:
        cfg = HitModelConfig(**parse_config_overrides(args.set, HitModelConfig))
    except ValueError as exc:
        print(f"igraph-fight: error: tracker hit-model train: {exc}", file=sys.stderr)
        return 2
    model, report = train(data, cfg)
    model.save(args.out)
    if report:
        plot_report(report, f"{args.out}.png")
    print(json.dumps(report, indent=1))
    return 0


def add_hit_model_commands(sub) -> None:
    """`hit-model collect|kinds|train` under a subparsers object."""
    h = sub.add_parser("hit-model", help="the physically measured hit odds: collect bout samples, fit, tabulate",
                       description="The hit model (tracker.bouts.hit_model): the odds that an action lands a "
                                   "physical hit and that the fighter is hit while playing it.")
    hs = h.add_subparsers(dest="cmd", metavar="HIT_MODEL_COMMAND")
    hs.required = True
    c = hs.add_parser("collect", help="play exploring physics bouts and write hit samples")
    c.add_argument("--graph", required=True)
    c.add_argument("--bouts", type=positive_int, default=200)
    c.add_argument("--seconds", type=positive_float, default=60.0)
    c.add_argument("--seed0", type=non_negative_int, default=1000)
    c.add_argument("--explore", type=probability, default=0.4)
    c.add_argument("--workers", type=positive_int, default=2)
    c.add_argument("--tracker", default=None, help=TRACKER_HELP)
    c.add_argument("--rl", default=None)
    c.add_argument("--hit-model", default=None, help="IG fighters use this hit model (a further data round)")
    c.add_argument("--future", default="calibrated", help=FUTURE_HELP)
    c.add_argument("--out", required=True)
    k = hs.add_parser("kinds", help="per action kind: landed, hit while playing, falls (collected samples)")
    k.add_argument("--data", required=True, nargs="+")
    k.add_argument("--graph", required=True, help="the graph whose library the samples were collected on")
    t = hs.add_parser("train", help="fit the hit model on collected samples")
    t.add_argument("--data", required=True, nargs="+")
    t.add_argument("--out", required=True)
    t.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="HitModelConfig field")
    h.set_defaults(func=cmd_hit_model)


def main(argv: list[str] | None = None) -> int:
    """``python -m tracker.bouts.cli bouts|rl|hit-model ...``: the same commands without the igraph-fight prefix."""
    p = argparse.ArgumentParser(prog="python -m tracker.bouts.cli", description="physics bouts, the RL baseline, the hit model")
    sub = p.add_subparsers(dest="command", required=True)
    add_bout_commands(sub)
    add_rl_commands(sub)
    add_hit_model_commands(sub)
    a = p.parse_args(argv)
    return a.func(a)


if __name__ == "__main__":
    sys.exit(main())
