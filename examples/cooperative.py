"""Cooperative control by dynamic programming (paper sections 6.3 and 7.2; igraph_fight.coop).

    python examples/cooperative.py --graph G.igz [--seconds 20] [--bouts 3] [--out DIR]

The paper's carrying task on the boxing data: two sparring partners keep a target distance,
face each other, avoid hitting each other and move their midpoint in one of 8 directions of the
pair frame (0 = towards B, 2 = A's left, 4 = away from B, 6 = A's right; planner.
cooperative_rewards). The graph's missing midpoint features are simulated once per edge
(coop.midpoint_features; the same simulation must reproduce the graph's feat_r and
feat_duration, which is checked and printed); then value iteration (planner.
value_iteration_pair) gives one policy per direction, both fighters maximising the common reward.
For each direction the pair plays ``--bouts`` bouts with the DP policy and the same number with
uniformly random legal actions (same start states); printed per direction: the midpoint's travel
along the commanded direction (frame by frame in the current pair frame, and start-to-end in
the initial pair frame), the reward earned per decision, the distance error and hits.
Writes DIR/cooperative.png (midpoint paths in the initial pair frame) and DIR/summary.json.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

NAMES = ["towards B", "front-left", "left", "back-left", "away", "back-right", "right", "front-right"]


def _mid_path(res) -> np.ndarray:
    """Midpoint path in the initial pair frame (x = A's left, z = towards B), metres."""
    p = res.trace["pose"]
    mid = 0.5 * (p[:, 0, :2] + p[:, 1, :2])
    d = p[0, 1, :2] - p[0, 0, :2]
    b = np.arctan2(d[0], d[1])
    u = np.array([np.sin(b), np.cos(b)])
    left = np.array([np.cos(b), -np.sin(b)])
    rel = mid - mid[0]
    return np.stack([rel @ left, rel @ u], axis=1)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", required=True, help="Interaction Graph file (.igz, library embedded)")
    ap.add_argument("--seconds", type=float, default=20.0, help="bout length (default 20)")
    ap.add_argument("--bouts", type=int, default=3, help="bouts per direction and policy (default 3)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--target", type=float, default=1.2, help="target distance between the partners (m)")
    ap.add_argument("--speed", type=float, default=0.3, help="wanted midpoint speed (m/s)")
    ap.add_argument("--gamma", type=float, default=0.9)
    ap.add_argument("--threads", type=int, default=1, help="numba threads for value iteration (default 1)")
    ap.add_argument("--directions", type=int, nargs="+", default=list(range(8)))
    ap.add_argument("--out", default="out/cooperative")
    args = ap.parse_args(argv)

    from igraph_fight import coop
    from igraph_fight.agents import RandomAgent
    from igraph_fight.controller import NPCController
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.graph import load_graph

    t_all = time.perf_counter()
    graph = load_graph(args.graph)
    lib = graph.load_library()
    ctrl = NPCController(graph, lib, style="balanced", depth=1)  # its index maps live states to graph states
    t = time.perf_counter()
    mf = coop.midpoint_features(graph, ctrl.tables, workers=None)
    feats = dict(graph.arrays)
    feats.update(mf)
    chk = mf["check"]
    print(f"graph {args.graph}: {graph.n_states} states, {graph.n_edges} edges; midpoint features simulated in "
          f"{time.perf_counter() - t:.1f} s (re-simulated vs stored: max |feat_r diff| "
          f"{chk['max_abs_r_diff_m']:.2g} m, max |duration diff| {chk['max_abs_duration_diff_s']:.2g} s)")
    game = FightGame(lib, GameConfig(max_seconds=args.seconds, sim=graph.sim_params()),
                     tables=ctrl.tables)
    seeds = list(range(args.seed, args.seed + args.bouts))
    # random pairs: one set of bouts from the same start states, measured against every direction
    rand_res = [coop.play(game, [RandomAgent(), RandomAgent()], args.seconds, s, args.target) for s in seeds]
    rows, paths = [], {}
    print(f"target distance {args.target} m, speed {args.speed} m/s, gamma {args.gamma}; {len(seeds)} bouts of "
          f"{args.seconds:.0f} s per direction and policy")
    print(f"{'dir':>3} {'':<12} {'VI':>12} | {'travel m (DP / random)':>22} | {'start-to-end m':>15} | "
          f"{'reward/decision':>16} | {'dist. err m':>11} | {'hits':>9}")
    for k in args.directions:
        pol = coop.cooperative_policy(graph, feats, k, args.target, args.speed, gamma=args.gamma,
                                      n_threads=args.threads)
        dp, rn = [], []
        for i, s in enumerate(seeds):
            m, res = coop.run_pair(game, [coop.CoopAgent(ctrl, pol, 0), coop.CoopAgent(ctrl, pol, 1)], args.seconds,
                                   s, pol)
            dp.append(m)
            paths.setdefault(k, {"dp": [], "random": []})["dp"].append(_mid_path(res))
            rr = rand_res[i]
            rn.append(coop.measure(rr, pol))
            paths[k]["random"].append(_mid_path(rr))

        def mean(lst, key):
            return float(np.mean([x[key] for x in lst]))

        row = {"direction": k, "name": NAMES[k % 8], "vi_sweeps": pol.sweeps, "vi_ms": round(pol.compute_ms, 1)}
        for key in ("travel_m", "world_m", "reward_per_decision", "distance_err_m", "facing_err_rad", "hits"):
            row[f"dp_{key}"] = mean(dp, key)
            row[f"random_{key}"] = mean(rn, key)
        rows.append(row)
        print(f"{k:>3} {NAMES[k % 8]:<12} {pol.sweeps:>4} {pol.compute_ms:>5.0f} ms | {row['dp_travel_m']:>+9.2f} / "
              f"{row['random_travel_m']:>+9.2f} | {row['dp_world_m']:>+6.2f} / {row['random_world_m']:>+6.2f} | "
              f"{row['dp_reward_per_decision']:>7.2f} / {row['random_reward_per_decision']:>6.2f} | "
              f"{row['dp_distance_err_m']:.2f} / {row['random_distance_err_m']:.2f} | "
              f"{row['dp_hits']:.1f} / {row['random_hits']:.1f}")
    agg = {key: (float(np.mean([r[f"dp_{key}"] for r in rows])), float(np.mean([r[f"random_{key}"] for r in rows])))
           for key in ("travel_m", "world_m", "reward_per_decision", "distance_err_m")}
    print(f"mean over directions (DP / random): travel {agg['travel_m'][0]:+.2f} / {agg['travel_m'][1]:+.2f} m, "
          f"start-to-end {agg['world_m'][0]:+.2f} / {agg['world_m'][1]:+.2f} m, reward per decision "
          f"{agg['reward_per_decision'][0]:.2f} / {agg['reward_per_decision'][1]:.2f}, distance error "
          f"{agg['distance_err_m'][0]:.2f} / {agg['distance_err_m'][1]:.2f} m")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    _plot(paths, out / "cooperative.png", args.seconds)
    (out / "summary.json").write_text(json.dumps({
        "graph": str(args.graph), "check": mf["check"], "target_distance_m": args.target, "speed_mps": args.speed,
        "gamma": args.gamma, "seconds": args.seconds, "seeds": seeds, "directions": rows, "mean": agg,
        "wall_s": time.perf_counter() - t_all}, indent=1))
    print(f"wrote {out / 'cooperative.png'} and {out / 'summary.json'} ({time.perf_counter() - t_all:.0f} s)")
    ctrl.close()
    return 0


def _plot(paths: dict, path: Path, seconds: float) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from planner import direction_vector

    fig, ax = plt.subplots(figsize=(7, 7))
    cmap = plt.get_cmap("tab10")
    for k, pp in sorted(paths.items()):
        col = cmap(k % 10)
        for j, xy in enumerate(pp["dp"]):
            ax.plot(xy[:, 0], xy[:, 1], color=col, lw=1.3, label=f"{k}: {NAMES[k % 8]}" if j == 0 else None)
            ax.plot(*xy[-1], "o", color=col, ms=4)
        vx, vz = direction_vector(k)
        ax.annotate("", xy=(1.2 * vx, 1.2 * vz), xytext=(0, 0), arrowprops=dict(arrowstyle="->", color=col, lw=1))
    first = next(iter(paths.values()))
    for j, xy in enumerate(first["random"]):
        ax.plot(xy[:, 0], xy[:, 1], color="#999", lw=0.8, ls="--", label="random" if j == 0 else None)
    ax.plot(0, 0, "k+", ms=10)
    ax.set_aspect("equal")
    ax.set_xlabel("x: A's left (m)")
    ax.set_ylabel("z: towards B (m)")
    ax.set_title(f"pair midpoint over {seconds:.0f} s per commanded direction (arrows), initial pair frame")
    ax.legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)


if __name__ == "__main__":
    sys.exit(main())
