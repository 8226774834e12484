"""Strategy swap: an Interaction Graph fighter switches style mid-bout (paper section 7.1).

    python examples/strategy_swap.py --graph G.igz [--seconds 60] [--seed 1] [--out DIR]

Fighter A starts as an outboxer and switches to infighter at half time (``NPCController.
set_style``: the new policy is computed in the background and swapped in atomically) against the
same opponent B (an infighter by default: a pressing opponent is what an outboxer has to keep
away). For each of ``--bouts`` seeds it plays the swap bout and a control bout with the same
seed in which A keeps its first style; both are identical up to the swap, so the difference of
their second halves is the effect of the swap alone (the first half also carries the approach
from the random start, so a plain before/after comparison mixes in the time effect).

Printed and written to DIR (summary.json, strategy_swap.png): per phase the mean pelvis distance,
A's punches by kind, the share of hooks/uppercuts vs straights (jab + straight) among A's punches,
punches per decision and hits, and the punch kinds the library holds (the CMU boxing takes hold
jabs and straights only, as far as the classifier finds, so the hook/uppercut share is 0 there).
``--artifacts`` also writes the first swap bout's viewer artifacts (HTML animation, BVH, log).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

PUNCH_KINDS = ("jab", "straight", "hook", "uppercut")
STRAIGHTS = ("jab", "straight")
HOOKS = ("hook", "uppercut")


@dataclass
class Phase:
    """What fighter A did in [t0, t1) of a bout (seconds, metres)."""

    t0: float
    t1: float
    mean_distance_m: float
    decisions: int
    punches: dict = field(default_factory=dict)      # kind -> count (A's launched punches)
    hook_uppercut_share: float = float("nan")        # of A's punches
    straight_share: float = float("nan")             # jab + straight, of A's punches
    punches_per_decision: float = 0.0
    hits_landed: int = 0
    hits_received: int = 0


def library_punch_kinds(lib) -> dict[str, int]:
    """Number of library actions per punch kind (the classifier's labels)."""
    labels = list(lib.labels)
    return {k: labels.count(k) for k in PUNCH_KINDS}


def phase_stats(res, t0: float, t1: float, player: int = 0) -> Phase:
    """Phase statistics of ``player`` from a traced BoutResult (igraph_fight.match)."""
    tr = res.trace
    sel = (tr["t"] >= t0) & (tr["t"] < t1)
    dist = float(tr["distance"][sel].mean()) if sel.any() else float("nan")
    dec = [d for d in res.decisions if d["player"] == player and t0 <= d["t"] < t1]
    punches = {k: sum(1 for d in dec if d["kind"] == k) for k in PUNCH_KINDS}
    n = sum(punches.values())
    hits = [h for h in res.hit_events if t0 <= h["t"] < t1]
    return Phase(t0, t1, dist, len(dec), punches,
                 sum(punches[k] for k in HOOKS) / n if n else float("nan"),
                 sum(punches[k] for k in STRAIGHTS) / n if n else float("nan"),
                 n / max(len(dec), 1),
                 sum(1 for h in hits if h["attacker"] == player), sum(1 for h in hits if h["victim"] == player))


class SwapSetup:
    """Controllers and game for swap bouts on one graph (controllers are reused across bouts)."""

    def __init__(self, graph, lib, opponent: str = "infighter", depth: int = 5, seconds: float = 60.0) -> None:
        from igraph_fight.controller import NPCController
        from igraph_fight.game import FightGame, GameConfig

        self.graph, self.lib = graph, lib
        self.a = NPCController(graph, lib, style="balanced", depth=depth)
        self.b = NPCController(graph, lib, style=opponent, depth=depth)
        self.game = FightGame(lib, GameConfig(max_seconds=seconds, sim=graph.sim_params()), tables=self.a.tables)
        self.seconds = seconds
        self.swap_ms: list[float] = []

    def bout(self, first, second, seed: int, t_swap: float):
        """One traced bout: A plays ``first``, then ``second`` from the first decision at or
        after ``t_swap`` (None: no swap); styles are preset names, style files or planner.Style.
        Returns the BoutResult and A's IGAgent."""
        from igraph_fight.agents import IGAgent
        from igraph_fight.match import run_bout

        self.a.set_style(first, wait=True)
        n1, n2 = getattr(first, "name", first), getattr(second, "name", second)
        # snap=True: the fighter snaps itself only (distance and angle) onto its graph state
        a, b = IGAgent(self.a, f"A:{n1}", snap=True), IGAgent(self.b, f"B:{self.b.style}", snap=True)
        schedule = []
        if second is not None and second != first:
            def do_swap() -> None:
                self.a.set_style(second, wait=True)
                self.swap_ms.append(float(self.a.last_swap_ms))
                a.name = f"A:{n1}->{n2}"
            schedule.append((t_swap, do_swap, f"A switches to {second}"))
        res = run_bout(self.game, [a, b], self.seconds, np.random.default_rng(seed), trace=True, schedule=schedule)
        return res, a

    def close(self) -> None:
        self.a.close()
        self.b.close()


def swap_experiment(setup: SwapSetup, first: str, second: str, seeds, t_swap: float, skip: float = 2.0) -> dict:
    """Swap bouts and same-seed control bouts (A keeps ``first``). Phases: before = [skip,
    t_swap), after = [t_swap + skip, end). Returns per-bout rows and the means."""
    rows = []
    for seed in seeds:
        row = {"seed": int(seed)}
        for name, sec in (("swap", second), ("control", None)):
            res, agent = setup.bout(first, sec, int(seed), t_swap)
            row[name] = {"before": asdict(phase_stats(res, skip, t_swap)),
                         "after": asdict(phase_stats(res, t_swap + skip, res.seconds + 1e-9)),
                         "off_graph": agent.off_graph / max(agent.decisions, 1), "result": res}
        rows.append(row)
    out = {"rows": rows}
    for name in ("swap", "control"):
        for ph in ("before", "after"):
            vals = [r[name][ph] for r in rows]
            punches = {k: sum(v["punches"][k] for v in vals) for k in PUNCH_KINDS}
            n = sum(punches.values())
            dec = sum(v["decisions"] for v in vals)
            out[f"{name}_{ph}"] = {
                "mean_distance_m": float(np.mean([v["mean_distance_m"] for v in vals])),
                "decisions": dec, "punches": punches,
                "hook_uppercut_share": sum(punches[k] for k in HOOKS) / n if n else float("nan"),
                "straight_share": sum(punches[k] for k in STRAIGHTS) / n if n else float("nan"),
                "punches_per_decision": n / max(dec, 1),
                "hits_landed": sum(v["hits_landed"] for v in vals),
                "hits_received": sum(v["hits_received"] for v in vals)}
    diff = [r["control"]["after"]["mean_distance_m"] - r["swap"]["after"]["mean_distance_m"] for r in rows]
    out["after_distance_control_minus_swap_m"] = float(np.mean(diff))
    out["after_distance_diffs_m"] = [float(x) for x in diff]
    return out


def _plot(exp: dict, t_swap: float, first: str, second: str, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), gridspec_kw={"width_ratios": [2.2, 1, 1]})
    ax = axes[0]
    for k, r in enumerate(exp["rows"]):
        for name, col in (("swap", "#e4572e"), ("control", "#888")):
            tr = r[name]["result"].trace
            ax.plot(tr["t"], tr["distance"], color=col, lw=1.2 if name == "swap" else 0.8, alpha=0.8,
                    label=(f"{first} -> {second}" if name == "swap" else f"control: {first} throughout")
                    if k == 0 else None)
    ax.axvline(t_swap, color="k", ls="--", lw=1)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("pelvis distance (m)")
    ax.set_title("distance, every seed")
    ax.legend(loc="upper right", fontsize=8)
    labels = ["before\n(swap)", "after\n(swap)", "before\n(control)", "after\n(control)"]
    keys = ["swap_before", "swap_after", "control_before", "control_after"]
    axes[1].bar(labels, [exp[k]["mean_distance_m"] for k in keys], color=["#3fa7d6", "#e4572e", "#bbb", "#888"])
    axes[1].set_ylabel("mean distance (m)")
    axes[1].set_title("mean distance by phase")
    share_s = [exp[k]["straight_share"] for k in keys]
    share_h = [exp[k]["hook_uppercut_share"] for k in keys]
    x = np.arange(len(keys))
    axes[2].bar(x - 0.2, np.nan_to_num(share_s), 0.4, label="jab + straight", color="#3fa7d6")
    axes[2].bar(x + 0.2, np.nan_to_num(share_h), 0.4, label="hook + uppercut", color="#e4572e")
    axes[2].set_xticks(x, labels)
    axes[2].set_ylabel("share of A's punches")
    axes[2].set_ylim(0, 1.05)
    axes[2].legend(fontsize=8)
    axes[2].set_title("punch kinds")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def _fmt_phase(name: str, p: dict) -> str:
    hs = "n/a" if np.isnan(p["hook_uppercut_share"]) else f"{p['hook_uppercut_share']:.2f}"
    ss = "n/a" if np.isnan(p["straight_share"]) else f"{p['straight_share']:.2f}"
    pk = " ".join(f"{k}={v}" for k, v in p["punches"].items())
    return (f"  {name:<16} {p['mean_distance_m']:6.2f} m  {p['decisions']:4d} decisions  punches [{pk}]  "
            f"hook+uppercut {hs}  jab+straight {ss}  punches/decision {p['punches_per_decision']:.2f}  "
            f"hits {p['hits_landed']}:{p['hits_received']}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", required=True, help="Interaction Graph file (.igz, library embedded)")
    ap.add_argument("--seconds", type=float, default=60.0, help="bout length (default 60)")
    ap.add_argument("--t-swap", type=float, default=None, help="swap time (default half time)")
    ap.add_argument("--seed", type=int, default=1, help="first seed (default 1)")
    ap.add_argument("--bouts", type=int, default=4, help="swap bouts (seeds seed .. seed+bouts-1), each with a control")
    ap.add_argument("--first", default="outboxer")
    ap.add_argument("--second", default="infighter")
    ap.add_argument("--opponent", default="infighter", help="style of B (default infighter)")
    ap.add_argument("--depth", type=int, default=5)
    ap.add_argument("--skip", type=float, default=2.0, help="seconds left out after the start and the swap")
    ap.add_argument("--out", default="out/strategy_swap")
    ap.add_argument("--artifacts", action="store_true", help="also write the first swap bout's viewer artifacts")
    args = ap.parse_args(argv)

    from igraph_fight.graph import load_graph
    t0 = time.perf_counter()
    graph = load_graph(args.graph)
    lib = graph.load_library()
    t_swap = args.t_swap if args.t_swap is not None else args.seconds / 2
    setup = SwapSetup(graph, lib, args.opponent, args.depth, args.seconds)
    kinds = library_punch_kinds(lib)
    print(f"graph {args.graph}: {graph.n_states} states, {graph.n_edges} edges; library punch kinds (actions): "
          + ", ".join(f"{k} {n}" for k, n in kinds.items()))
    seeds = list(range(args.seed, args.seed + args.bouts))
    exp = swap_experiment(setup, args.first, args.second, seeds, t_swap, args.skip)
    out = Path(args.out)
    _plot(exp, t_swap, args.first, args.second, out / "strategy_swap.png")
    print(f"A: {args.first} -> {args.second} at {t_swap:.0f} s vs B: {args.opponent}; {len(seeds)} bouts of "
          f"{args.seconds:.0f} s (seeds {seeds[0]}..{seeds[-1]}), phases skip {args.skip:.0f} s after start/swap")
    for k in ("swap_before", "swap_after", "control_before", "control_after"):
        print(_fmt_phase(k, exp[k]))
    print(f"  after the swap the distance is {exp['after_distance_control_minus_swap_m']:+.2f} m shorter than in the "
          f"control (per seed: {', '.join(f'{d:+.2f}' for d in exp['after_distance_diffs_m'])})")
    if setup.swap_ms:
        print(f"  style swap (set_style request -> live): {np.median(setup.swap_ms):.0f} ms median")
    if kinds["hook"] + kinds["uppercut"] == 0:
        print("  note: the library holds no hooks or uppercuts, so the hook/uppercut share is 0 in every phase")
    summary = {k: v for k, v in exp.items() if k != "rows"}
    summary["per_bout"] = [{"seed": r["seed"], **{n: {"before": r[n]["before"], "after": r[n]["after"],
                                                      "off_graph": r[n]["off_graph"]} for n in ("swap", "control")}}
                           for r in exp["rows"]]
    summary.update(graph=str(args.graph), library_punch_kinds=kinds, first=args.first, second=args.second,
                   opponent=args.opponent, t_swap=t_swap, seconds=args.seconds, swap_ms=setup.swap_ms,
                   wall_s=time.perf_counter() - t0)
    if args.artifacts:
        from igraph_fight.match import write_bout_artifacts
        arts = write_bout_artifacts(setup.game, exp["rows"][0]["swap"]["result"], out / "bout",
                                    title=f"{args.first} -> {args.second} vs {args.opponent}")
        summary["artifacts"] = arts
        print(f"  bout artifacts: {out / 'bout'}")
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, default=float))
    print(f"  wrote {out / 'strategy_swap.png'} and {out / 'summary.json'} ({summary['wall_s']:.0f} s)")
    setup.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
