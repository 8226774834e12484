"""Decision cost of the baseline agents and of the IG fighter (µs per decision, one core).

Usage: python benchmarks/bench_agents.py [--graph G.igz] [--states N] [--depths 1,2,3] [--json]

Decision states are reached by random play from random initial states (FightGame) on the
graph's library (or the CMU boxing library when no graph is given). Each agent decides once in
every state after a warm-up; the game tree is timed with and without alpha-beta pruning (same
decisions, asserted) with the events it simulated per decision. Prints the figures.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--graph", default=None, help="graph file (also times IG(d) at --ig-depths)")
    ap.add_argument("--states", type=int, default=200)
    ap.add_argument("--depths", default="1,2,3", help="game-tree depths")
    ap.add_argument("--ig-depths", default="1,3,5")
    ap.add_argument("--rl", default=None, help="RL checkpoint (default: the shipped one, if it fits)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()

    import torch
    torch.set_num_threads(1)
    from igraph_fight.agents import IGAgent, RandomAgent
    from igraph_fight.agents.gametree import GameTreeSearch
    from igraph_fight.agents.human import HumanProxyAgent
    from igraph_fight.agents.static import StaticAgent, static_policy
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.state import to_sample

    graph = None
    if args.graph:
        from igraph_fight.graph import load_graph
        graph = load_graph(args.graph)
        lib = graph.load_library()
        game = FightGame(lib, GameConfig(sim=graph.sim_params()))
    else:
        from motion_graph.library import build_library
        from motion_graph.paths import find_mocap_root
        lib = build_library([str(find_mocap_root() / "cmu" / "boxing")])
        game = FightGame(lib, GameConfig())
    rng = np.random.default_rng(0)
    states = []
    while len(states) < args.states:
        st = game.new_initial_state(rng)
        for _ in range(int(rng.integers(1, 12))):
            p = st.current_player()
            st.apply_action(int(rng.choice(st.legal_actions(p))))
        states.append((st, st.current_player()))
    out: dict = {"states": len(states), "n_actions": lib.n_actions,
                 "mean_menu": float(np.mean([len(s.legal_actions(p)) for s, p in states]))}

    def time_agent(agent) -> float:
        s0, p0 = states[0]
        agent.reset(game, p0, np.random.default_rng(0))
        agent.step(s0.clone(), p0)  # warm-up / compile
        t = time.perf_counter()
        for s, p in states:
            agent.step(s.clone(), p)
        return (time.perf_counter() - t) / len(states) * 1e6

    for d in (int(x) for x in args.depths.split(",")):
        res = {}
        for prune in (True, False):
            gs = GameTreeSearch(game.tables, "infighter", d, prune=prune)
            samples = [to_sample(game.tables, s.world, p) for s, p in states]
            gs.search(*samples[0])
            gs.count[:] = 0
            t = time.perf_counter()
            acts = [gs.search(*x)[0] for x in samples]
            res[prune] = ((time.perf_counter() - t) / len(samples) * 1e6, gs.count[0] / len(samples), acts)
        assert res[True][2] == res[False][2], "alpha-beta changed a decision"
        out[f"gametree{d}"] = {"us": res[True][0], "events": res[True][1], "us_unpruned": res[False][0],
                               "events_unpruned": res[False][1]}
    static_policy(game.tables)
    out["static_us"] = time_agent(StaticAgent())
    out["human_us"] = time_agent(HumanProxyAgent())
    out["random_us"] = time_agent(RandomAgent())
    try:
        from igraph_fight.agents.rl import RLAgent, default_checkpoint
        out["rl_us"] = time_agent(RLAgent(args.rl or default_checkpoint()))
    except (FileNotFoundError, ValueError) as e:
        out["rl_us"] = f"skipped: {e}"
    if graph is not None:
        from igraph_fight.controller import NPCController
        for d in (int(x) for x in args.ig_depths.split(",")):
            c = NPCController(graph, lib, style="infighter", depth=d)
            ag = IGAgent(c, snap=False)
            out[f"IG({d})_us"] = time_agent(ag)
            out[f"IG({d})_off_graph"] = ag.off_graph / max(ag.decisions, 1)
            c.close()
    if args.json:
        print(json.dumps(out))
        return
    for k, v in out.items():
        print(f"{k:22s} {v}")


if __name__ == "__main__":
    main()
