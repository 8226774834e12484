"""`igraph-fight evaluate` (Table 1 protocol with the baselines) and `igraph-fight train-rl`."""
from __future__ import annotations

import argparse
import json
import shlex
import sys

from igraph_fight.cli import depth_list, non_negative_int, positive_float, positive_int


def register(sub) -> None:
    p = sub.add_parser("evaluate", help="IG fighters of several depths vs the baselines: Table 1, coverage, costs")
    p.add_argument("--graph", required=True, help="Interaction Graph file (.igz, with its library embedded)")
    p.add_argument("--opponents", default="human,static,gametree2,gametree3,rl",
                   help="comma list of: human, static, gametree2, gametree3, rl, random, rl_outboxer")
    p.add_argument("--depths", type=depth_list, default="1,3,5",
                   help="IG min-max depths (1..12), one row each (default 1,3,5)")
    p.add_argument("--exact2-depths", type=depth_list, default="5",
                   help="also rows IG(d)+exact2 for these depths: two exact plies over the graph's values "
                        "(NPCController first_ply='exact2'; default 5, '' for none)")
    p.add_argument("--bouts", type=positive_int, default=20, help="bouts per cell (default 20)")
    p.add_argument("--seconds", type=positive_float, default=60.0, help="bout length (default 60 s)")
    p.add_argument("--seed", type=non_negative_int, default=0)
    p.add_argument("--out", default="out/eval", help="output folder (report.md, results.json, plots)")
    p.add_argument("--workers", type=positive_int, default=None,
                   help="bout worker processes (default 1), or Ray actors with --backend ray (default: every CPU)")
    p.add_argument("--backend", choices=("local", "ray"), default="local",
                   help="play the bouts here (default) or on Ray actors (pip install 'igraph-fight[ray]'); "
                        "the same results")
    p.add_argument("--address", default=None, metavar="auto|HOST:PORT",
                   help="with --backend ray: join this running Ray cluster (default: start Ray on this machine)")
    p.add_argument("--style", default="infighter", help="IG fighter's (and game tree's) style (default infighter)")
    p.add_argument("--rl-checkpoint", default=None, help="RL policy (default igraph_fight/checkpoints/rl_infighter.pt)")
    p.add_argument("--rl-outboxer-checkpoint", default=None,
                   help="RL policy retrained for outboxer (default igraph_fight/checkpoints/rl_outboxer.pt)")
    p.add_argument("--train-rl", action="store_true", help="retrain both RL policies first (saved into --out)")
    p.add_argument("--rl-decisions", type=positive_int, default=1_000_000,
                   help="RL budget in learner decisions (--train-rl)")
    p.add_argument("--rl-minutes", type=positive_float, default=15.0, help="RL budget cap in CPU minutes (--train-rl)")
    p.add_argument("--rl-retrain-decisions", type=positive_int, default=300_000,
                   help="outboxer fine-tuning budget in learner decisions (--train-rl)")
    p.add_argument("--head-to-head", default="random,human,static,gametree2,gametree3",
                   help="opponents of the RL policies' head-to-head bouts ('' for none)")
    p.add_argument("--h2h-bouts", type=positive_int, default=None, help="bouts per head-to-head cell (default --bouts)")
    p.add_argument("--human-logs", default=None, metavar="DIR",
                   help="bouts saved by `igraph-fight play` (e.g. out/play): the real human column, beside the proxy")
    p.add_argument("--json", action="store_true", help="print the results JSON (without per-bout detail)")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("train-rl", help="train the RL baseline (masked PPO) and save its checkpoint")
    p.add_argument("--graph", required=True, help="graph file: its embedded library and simulator options are used")
    p.add_argument("--style", default="infighter", help="Eq. 4 reward style (default infighter)")
    p.add_argument("--decisions", type=positive_int, default=1_000_000, help="budget in learner decisions")
    p.add_argument("--minutes", type=positive_float, default=15.0, help="budget cap in CPU minutes")
    p.add_argument("--seed", type=non_negative_int, default=1)
    p.add_argument("--init-from", default=None, help="warm start from a checkpoint (retraining for a new style)")
    p.add_argument("--out", required=True, help="checkpoint path (.pt)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_train_rl)


def _list(s: str) -> tuple:
    return tuple(x.strip() for x in s.split(",") if x.strip())


def _known(names: tuple, allowed: tuple, option: str) -> tuple:
    """``names`` if each is one of ``allowed``; a ValueError naming the first that is not."""
    for n in names:
        if n not in allowed:
            raise ValueError(f"{option}: unknown opponent {n!r} (one of {', '.join(allowed)})")
    return names


def cmd_evaluate(args: argparse.Namespace) -> int:
    from planner import load_style

    from igraph_fight.evaluate.config import OPPONENTS, EvalConfig
    from igraph_fight.evaluate.runner import evaluate

    load_style(args.style)          # an unknown style fails here, before any policy is computed
    if args.address is not None and args.backend != "ray":
        raise ValueError("--address needs --backend ray")
    if args.backend == "ray":
        from igraph_fight.build.backend import require_ray
        require_ray()
    depths = tuple(int(d) for d in _list(args.depths))
    if not depths:
        raise ValueError("--depths: at least one depth is needed")
    cfg = EvalConfig(graph=args.graph, opponents=_known(_list(args.opponents), OPPONENTS, "--opponents"),
                     depths=depths, exact2_depths=tuple(int(d) for d in _list(args.exact2_depths)),
                     bouts=args.bouts, seconds=args.seconds, seed=args.seed, style=args.style,
                     workers=args.workers or (0 if args.backend == "ray" else 1), backend=args.backend,
                     address=args.address,
                     rl_checkpoint=args.rl_checkpoint, rl_outboxer_checkpoint=args.rl_outboxer_checkpoint,
                     train_rl=args.train_rl, rl_decisions=args.rl_decisions, rl_cpu_minutes=args.rl_minutes,
                     rl_retrain_decisions=args.rl_retrain_decisions,
                     head_to_head=_known(_list(args.head_to_head), OPPONENTS, "--head-to-head"),
                     h2h_bouts=args.h2h_bouts, human_logs=args.human_logs, progress=True,
                     command="igraph-fight " + " ".join(shlex.quote(a) for a in sys.argv[1:]))
    rep = evaluate(cfg, args.out)
    if args.json:
        print(json.dumps({k: v for k, v in rep.items() if k != "bouts"}, default=str))
        return 0
    for r, row in rep["table"].items():
        print(f"{r:13s} " + "  ".join(f"{c} {x['mean']:+.1f} [{x['ci_low']:+.1f}, {x['ci_high']:+.1f}]"
                                     for c, x in row.items()))
    for r, x in (rep.get("human_logs") or {}).get("rows", {}).items():
        if x["bouts"]:
            print(f"{r:13s} people (play) {x['mean']:+.1f} [{x['ci_low']:+.1f}, {x['ci_high']:+.1f}], "
                  f"{x['bouts']} bouts")
    if rep["coverage"] is not None:
        print(f"coverage {100 * rep['coverage']:.1f}%")
    print(f"report: {rep['files']['report']}\njson: {rep['files']['json']}")
    return 0


def cmd_train_rl(args: argparse.Namespace) -> int:
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.graph import load_graph
    from igraph_fight.learn.train_rl import RLConfig, train
    from planner import load_style

    load_style(args.style)
    g = load_graph(args.graph)
    lib = g.load_library()
    game = FightGame(lib, GameConfig(sim=g.sim_params()))
    cfg = RLConfig(style=args.style, total_decisions=args.decisions, max_cpu_minutes=args.minutes, seed=args.seed,
                   init_from=args.init_from)
    ck = train(game, cfg, out=args.out, progress=not args.json)
    b = ck["budget"]
    if args.json:
        print(json.dumps({"out": args.out, "budget": b, "last": ck["curve"][-1] if ck["curve"] else None}))
    else:
        print(f"saved {args.out}: {b['decisions']} decisions, {b['cpu_minutes']:.1f} CPU min "
              f"({b['wall_minutes']:.1f} wall), stop: {b['stop']}")
    return 0
