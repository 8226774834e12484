"""The match evaluation of the paper's Table 1 (docs/protocols.md, Match), with the baselines.

    igraph-fight evaluate --graph G.igz --opponents human,static,gametree2,gametree3,rl \\
        --depths 1,3,5 --bouts 20 --seconds 60 --seed 0 --out out/eval --workers 2

Rows are Interaction Graph fighters IG(d) = IGAgent(NPCController(graph, style, depth=d)) (the
paper's runtime: the policy table), and with ``exact2_depths`` also IG(d)+exact2, the same
controller deciding with ``first_ply="exact2"`` (two exact plies over the graph's values);
columns the opponents. Bout i of every (row, column) pair starts from the same random initial
state (FightGame.new_initial_state with a generator seeded by (seed, i): common random
numbers), and the agents get the same random stream; the IG fighter plays slot A in even bouts
and slot B in odd ones (slot bias cancels). Score of a bout = hits landed by the IG fighter
minus hits landed by the opponent. Cells report the mean over bouts with a 95% Student-t
confidence interval.

Also measured: coverage (every decision state of the gametree-3 fighter in the IG-vs-gametree3
bouts is looked up on the graph: is there a state of its compatible group within the linking
tolerance, InteractionGraph.covers; also whether the nearest one is, InteractionGraph.locate),
the decision cost of every agent (µs per decision, wall
clock inside ``step``), the kind of every action chosen (histograms per agent), the IG
fighters' off-graph rate (with the reason: no compatible group / out of tolerance), the RL
baseline's budget, learning curve, head-to-head bouts (with its outboxer retrain) and the
planner's style-swap time. With ``human_logs``, the bouts people saved in `igraph-fight play`
give the real human column (evaluate.human_logs), reported beside the scripted proxy's.

Bouts run in ``workers`` processes (fork), or with ``backend="ray"`` on Ray actors
(evaluate.ray_runner); each task is self-contained and seeded, so results do not depend on the
worker count or the backend. Everything but timings is a function of the graph, the
checkpoints and the seed: ``results_digest`` (sha256 of the deterministic part) is identical
for identical inputs.
"""
from __future__ import annotations

import copy
import json
import sys
import time
from pathlib import Path

import numpy as np

from igraph_fight.evaluate.config import EXACT2, OPPONENTS, EvalConfig, ig_rows, row_depth
from igraph_fight.evaluate.report import aggregate, json_default, markdown, plots
from igraph_fight.state import to_sample

# ----- the per-process context -------------------------------------------------------------------
_CTX: dict | None = None


def build_context(cfg: EvalConfig, rl: dict | None = None) -> dict:
    """Graph, library, game, IG controllers (one per depth), static policy, RL checkpoints."""
    from igraph_fight.agents.static import static_policy
    from igraph_fight.controller import NPCController
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.graph import load_graph

    graph = load_graph(cfg.graph)
    lib = graph.load_library()
    controllers = {d: NPCController(graph, lib, style=cfg.style, depth=d)
                   for d in sorted(set(cfg.depths) | set(cfg.exact2_depths))}
    tables = next(iter(controllers.values())).tables if controllers else None
    game = FightGame(lib, GameConfig(max_seconds=cfg.seconds, sim=graph.sim_params()), tables=tables)
    from igraph_fight.agents.gametree import GameTreeSearch
    ctx = {"cfg": cfg, "graph": graph, "lib": lib, "game": game, "controllers": controllers,
           "static": static_policy(game.tables, cfg.style), "rl": rl or {},
           "regret": GameTreeSearch(game.tables, cfg.style, cfg.regret_depth) if cfg.regret_every else None}
    return ctx


def _init_worker(cfg: EvalConfig, rl: dict | None) -> None:
    global _CTX
    import torch
    torch.set_num_threads(1)
    if _CTX is None or _CTX["cfg"] is not cfg:  # fork inherits the parent's context
        _CTX = build_context(cfg, rl)


def make_agent(ctx: dict, name: str):
    """An agent by its table name: IG(d), human, static, gametree2/3, rl, rl_outboxer, random."""
    from igraph_fight.agents import IGAgent, RandomAgent
    from igraph_fight.agents.gametree import GameTreeAgent
    from igraph_fight.agents.human import HumanProxyAgent
    from igraph_fight.agents.rl import RLAgent
    from igraph_fight.agents.static import StaticAgent

    cfg = ctx["cfg"]
    if name.startswith("IG("):
        c = ctx["controllers"][row_depth(name)]
        if name.endswith(EXACT2):
            c = copy.copy(c)  # the same graph, index and policy table; only the decision rule differs
            c.first_ply = "exact2"
        return IGAgent(c, name=name)
    if name == "human":
        return HumanProxyAgent()
    if name == "static":
        return StaticAgent(cfg.style, policy=ctx["static"])
    if name.startswith("gametree"):
        return GameTreeAgent(int(name[len("gametree"):]), cfg.style)
    if name == "random":
        return RandomAgent()
    if name in ("rl", "rl_outboxer"):
        ck = ctx["rl"].get(name)
        if ck is None:
            raise ValueError(f"no RL checkpoint loaded for {name!r}")
        return RLAgent(ck, name=name)
    raise ValueError(f"unknown agent {name!r} (known: IG(d), {', '.join(OPPONENTS)})")


class _Watch:
    """Wraps an agent: times ``step``; with ``probe`` also looks every decision state up on the
    graph before the agent acts (coverage for the gametree-3 fighter; for IG fighters, why a
    decision is off the graph: no compatible group, or a group but out of tolerance)."""

    def __init__(self, agent, graph=None, probe: bool = False, regret=None, regret_every: int = 0) -> None:
        self.agent = agent
        self.name = agent.name
        self.graph = graph
        self.coverage = probe
        self.regret = regret            # a GameTreeSearch: exact depth-3 values of the agent's choices
        self.regret_every = regret_every
        self.regrets: list[tuple[float, int, int]] = []  # (regret, agrees with the search, off graph)
        self.fidelity: list[tuple] = []  # per sampled on-graph decision, see _fidelity
        self.us = 0.0
        self.n = 0
        self.cov_n = 0
        self.cov_in = 0        # the nearest state within tolerance
        self.cov_any = 0       # some state within tolerance (coverage)
        self.cov_nogroup = 0

    def reset(self, game, player, rng) -> None:
        self.agent.reset(game, player, rng)

    def step(self, state, player) -> int:
        if self.coverage:
            tables = state.game.tables
            si, sf = to_sample(tables, state.world, player)
            live = (int(tables.nextset[si[0]]), int(si[1]), int(si[2]), int(si[3]), float(sf[0]), float(sf[1]),
                    float(sf[2]))
            s, _, within = self.graph.nearest_state(*live)
            self.cov_n += 1
            self.cov_in += int(within)
            self.cov_any += int(within or self.graph.covers(*live))
            self.cov_nogroup += int(s < 0)
        q = None
        if self.regret is not None and self.regret_every and self.n % self.regret_every == 0:
            acts, q = self.regret.root_q(*to_sample(state.game.tables, state.world, player))
            off0 = self.agent.off_graph
            self._fidelity(state, player, int(acts[int(np.argmax(q))]), len(acts))
        t = time.perf_counter()
        a = self.agent.step(state, player)
        self.us += (time.perf_counter() - t) * 1e6
        self.n += 1
        if q is not None:
            qa = float(q[acts == a][0])
            self.regrets.append((float(q.max()) - qa, int(qa >= q.max() - 1e-9), int(self.agent.off_graph > off0)))
        return a


    def _fidelity(self, state, player, best_action: int, n_menu: int) -> None:
        """For an on-graph decision: the matched state's edges (stored features, as the planner sees
        them) against the same actions simulated exactly from the live state. Records (mean
        |W_stored - W_exact|, edges, stored hit & exact hit, stored hit & exact miss, stored miss &
        exact hit, chosen edge predicted a hit, it really hits, distinct actions with an edge, menu
        size, the exact search's best action has an edge)."""
        from motion_graph.classify import KINDS
        from planner import edge_rewards

        from igraph_fight import sim
        from igraph_fight.controller import observe
        from igraph_fight.build.edge_features import edge_features
        c = self.agent.controller
        d = c.act(observe(state, player))
        if d.off_graph or d.state < 0:
            return
        g = self.graph.arrays
        lo, hi = int(g["state_offsets"][d.state]), int(g["state_offsets"][d.state + 1])
        if hi <= lo:
            return
        acts = g["edge_action"][lo:hi].astype(np.int64)
        stored = {k: np.asarray(g[k][lo:hi]) for k in g.keys() if k.startswith("feat_")}
        w_st, _ = edge_rewards(stored, c._table.style_obj, list(KINDS))
        si, sf = to_sample(state.game.tables, state.world, player)
        _, _, ft, _ = sim.expand_samples(state.game.tables.kernel_tuple(), si[None], sf[None],
                                         np.zeros(len(acts), dtype=np.int64), acts)
        ex = edge_features(state.game.tables, np.full(len(acts), si[sim.SI_MOTHER]), acts, ft)
        w_ex, _ = edge_rewards(ex, c._table.style_obj, list(KINDS))
        hs = stored["feat_dmg_given"] > 0
        he = ex["feat_dmg_given"] > 0
        k = d.edge - lo if lo <= d.edge < hi else -1
        self.fidelity.append((float(np.mean(np.abs(w_st - w_ex))), int(hi - lo), int(np.sum(hs & he)),
                              int(np.sum(hs & ~he)), int(np.sum(~hs & he)),
                              int(hs[k]) if k >= 0 else -1, int(he[k]) if k >= 0 else -1, len(set(acts.tolist())),
                              n_menu, int(best_action in set(acts.tolist()))))


def run_task(task: dict) -> dict:
    """One bout: task = {id, row, col, i}, in this process's context. Returns the deterministic
    outcome and the timings."""
    return run_task_in(_CTX, task)


def run_task_in(ctx: dict, task: dict) -> dict:
    """One bout in the evaluation context ``ctx`` (build_context)."""
    from igraph_fight.match import run_bout

    cfg: EvalConfig = ctx["cfg"]
    game = ctx["game"]
    i = int(task["i"])
    is_ig = task["row"].startswith("IG(")
    row = _Watch(make_agent(ctx, task["row"]), ctx["graph"], probe=is_ig, regret=ctx.get("regret") if is_ig else None,
                 regret_every=cfg.regret_every)
    col = _Watch(make_agent(ctx, task["col"]), ctx["graph"], probe=task["col"] == "gametree3" and task["row"].startswith("IG("))
    initial = game.new_initial_state(np.random.default_rng([cfg.seed, i]))
    slot = i % 2  # the row agent's slot
    agents = [row, col] if slot == 0 else [col, row]
    res = run_bout(game, agents, cfg.seconds, np.random.default_rng([cfg.seed, i, 1]), initial=initial)
    hits_row, hits_col = float(res.hits[slot]), float(res.hits[1 - slot])
    kinds = [{}, {}]
    for d in res.decisions:
        who = 0 if d["player"] == slot else 1
        k = d["kind"]
        kinds[who][k] = kinds[who].get(k, 0) + 1
    out = {
        "id": task["id"], "row": task["row"], "col": task["col"], "i": i, "slot": slot,
        "score": hits_row - hits_col, "hits_row": hits_row, "hits_col": hits_col,
        "decisions_row": row.n, "decisions_col": col.n, "kinds_row": kinds[0], "kinds_col": kinds[1],
        "mean_distance_m": round(float(res.mean_distance_m), 6), "seconds": float(res.seconds),
        "timing": {"us_row": row.us, "us_col": col.us, "wall_s": res.wall_s},
    }
    for who, w in (("row", row), ("col", col)):
        if hasattr(w.agent, "events"):
            out[f"events_{who}"] = int(w.agent.events)
    if col.coverage:
        out["coverage"] = {"n": col.cov_n, "within": col.cov_in, "covered": col.cov_any, "no_group": col.cov_nogroup}
    ag = row.agent
    if hasattr(ag, "off_graph"):
        out["ig"] = {"off_graph": int(ag.off_graph), "decisions": int(ag.decisions),
                     "snap_m": float(np.sum(ag.snap_m)) if ag.snap_m else 0.0, "snaps": len(ag.snap_m),
                     "snap_rad": float(np.sum(ag.snap_rad)) if ag.snap_rad else 0.0,
                     "snap_frames": float(np.sum(np.abs(getattr(ag, "snap_frames", []) or [0]))),
                     "probe_n": row.cov_n, "probe_within": row.cov_in, "probe_no_group": row.cov_nogroup,
                     "regret": row.regrets, "fidelity": row.fidelity}
    return out


# ----- RL checkpoints ----------------------------------------------------------------------------
def _rl_checkpoints(cfg: EvalConfig, ctx: dict, out: Path, notes: list[str]) -> dict:
    """Load (or train) the infighter RL policy and its outboxer retrain."""
    from igraph_fight.agents.rl import default_checkpoint, load_checkpoint
    from igraph_fight.graph import library_fingerprint
    from igraph_fight.learn.train_rl import RLConfig, train

    if not ({"rl", "rl_outboxer"} & set(cfg.opponents) or cfg.head_to_head):
        return {}
    fp = library_fingerprint(ctx["lib"])
    game = ctx["game"]
    paths = {"rl": Path(cfg.rl_checkpoint) if cfg.rl_checkpoint else default_checkpoint("infighter"),
             "rl_outboxer": Path(cfg.rl_outboxer_checkpoint) if cfg.rl_outboxer_checkpoint
             else default_checkpoint("outboxer")}
    cks: dict = {}
    for name in ("rl", "rl_outboxer"):
        p = paths[name]
        ok = False
        if not cfg.train_rl and p.is_file():
            ck = load_checkpoint(p)
            ok = ck.get("library_fingerprint") == fp and ck.get("n_actions") == game.tables.n_actions
            if ok:
                cks[name] = ck
                cks[name + "_path"] = str(p)
            else:
                notes.append(f"{p} was trained on another action library: retrained here")
        if not ok:
            if not cfg.train_rl and not p.is_file():
                notes.append(f"{p} missing: trained here")
            dest = out / p.name
            if name == "rl":
                rc = RLConfig(style="infighter", total_decisions=cfg.rl_decisions, max_cpu_minutes=cfg.rl_cpu_minutes,
                              seed=cfg.seed + 1)
            else:
                rc = RLConfig(style="outboxer", total_decisions=cfg.rl_retrain_decisions,
                              max_cpu_minutes=cfg.rl_cpu_minutes, seed=cfg.seed + 2, init_from=cks["rl_path"])
            cks[name] = train(game, rc, out=dest, progress=cfg.progress)
            cks[name + "_path"] = str(dest)
    return cks


def _style_swap_ms(ctx: dict, repeat: int = 3) -> dict:
    """Time from set_style('outboxer') to the new table being live on the deepest controller."""
    from igraph_fight.controller import NPCController
    d = max(ctx["cfg"].depths) if ctx["cfg"].depths else 5
    c = NPCController(ctx["graph"], ctx["lib"], style=ctx["cfg"].style, depth=d)
    times = []
    try:
        for k in range(repeat):
            c.set_style("outboxer" if k % 2 == 0 else ctx["cfg"].style).result()
            times.append(float(c.last_swap_ms))
    finally:
        c.close()
    return {"median_ms": float(np.median(times)), "runs_ms": [round(t, 1) for t in times], "depth": d}


# ----- the evaluation ------------------------------------------------------------------------------
def tasks_for(cfg: EvalConfig, with_rl: bool = True) -> list[dict]:
    """Every bout: the table's (row, column, i), then the RL policies' head-to-head bouts."""
    rows = ig_rows(cfg)
    tasks = []
    for r in rows:
        for c in cfg.opponents:
            for i in range(cfg.bouts):
                tasks.append({"row": r, "col": c, "i": i, "kind": "table"})
    if cfg.head_to_head and with_rl:
        nb = cfg.h2h_bouts if cfg.h2h_bouts is not None else cfg.bouts
        for r in ("rl", "rl_outboxer"):
            for c in cfg.head_to_head:
                for i in range(nb):
                    tasks.append({"row": r, "col": c, "i": i, "kind": "h2h"})
    for k, t in enumerate(tasks):
        t["id"] = k
    return tasks


def evaluate(cfg: EvalConfig, out: str | Path) -> dict:
    """Run the evaluation, write report.md, results.json and plots into ``out``; return the JSON."""
    global _CTX
    import torch
    torch.set_num_threads(1)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    c0 = time.process_time()
    notes: list[str] = []
    for o in list(cfg.opponents) + list(cfg.head_to_head):
        if o not in OPPONENTS:
            raise ValueError(f"unknown opponent {o!r} (known: {', '.join(OPPONENTS)})")
    ctx = build_context(cfg)
    t_setup = time.perf_counter() - t0
    rl = _rl_checkpoints(cfg, ctx, out, notes)
    ctx["rl"] = {k: v for k, v in rl.items() if not k.endswith("_path")}
    t_rl = time.perf_counter() - t0 - t_setup
    _CTX = ctx
    tasks = tasks_for(cfg, with_rl="rl" in ctx["rl"] and "rl_outboxer" in ctx["rl"])
    _warm_up(ctx, sorted({t["row"] for t in tasks} | {t["col"] for t in tasks}))
    results: list[dict] = [None] * len(tasks)  # type: ignore[list-item]
    bar = None
    if cfg.progress:
        from tqdm import tqdm
        bar = tqdm(total=len(tasks), desc="bouts", unit="bout", file=sys.stderr)
    t_b = time.perf_counter()
    backend = {"backend": "local", "workers": cfg.workers}
    if cfg.backend == "ray":
        from igraph_fight.evaluate.ray_runner import run_tasks_on_ray

        def got(r: dict) -> None:
            results[r["id"]] = r
            if bar is not None:
                bar.update(1)
        order = sorted(tasks, key=lambda t: -_cost_hint(t))
        backend = run_tasks_on_ray(cfg, ctx["rl"], order, got, build_context, run_task_in, cfg.workers or None,
                                   cfg.address)
    elif cfg.workers <= 1:
        for t in tasks:
            results[t["id"]] = run_task(t)
            if bar is not None:
                bar.update(1)
    else:
        import multiprocessing as mp
        method = "fork" if "fork" in mp.get_all_start_methods() else "spawn"
        mpc = mp.get_context(method)
        order = sorted(tasks, key=lambda t: -_cost_hint(t))  # long bouts first: better packing
        with mpc.Pool(cfg.workers, initializer=_init_worker, initargs=(cfg, ctx["rl"])) as pool:
            for r in pool.imap_unordered(run_task, order, chunksize=1):
                results[r["id"]] = r
                if bar is not None:
                    bar.update(1)
    if bar is not None:
        bar.close()
    t_bouts = time.perf_counter() - t_b
    swap = _style_swap_ms(ctx) if cfg.depths else {}
    report = aggregate(cfg, ctx, rl, results, notes)
    if cfg.human_logs:
        from igraph_fight.evaluate.human_logs import human_table
        report["human_logs"] = human_table(cfg.human_logs, cfg.depths, ctx["graph"].content_hash)
    report["style_swap_ms"] = swap.get("median_ms")
    report["timing"]["style_swap"] = swap
    report["timing"]["backend"] = backend
    report["timing"].update({"setup_s": t_setup, "rl_s": t_rl, "bouts_s": t_bouts,
                             "wall_s": time.perf_counter() - t0, "parent_cpu_s": time.process_time() - c0})
    plots(report, rl, out)
    report["files"] = {"report": str(out / "report.md"), "json": str(out / "results.json"),
                       "rl_curve": str(out / "rl_curve.png"), "kinds": str(out / "kinds.png")}
    (out / "results.json").write_text(json.dumps(report, indent=1, default=json_default))
    (out / "report.md").write_text(markdown(report))
    return report


def _warm_up(ctx: dict, names) -> None:
    """One decision of every agent on a throwaway state, so that compilation (numba, torch) is
    neither in the decision times nor repeated in every worker (fork inherits it)."""
    game = ctx["game"]
    for n in names:
        a = make_agent(ctx, n)
        st = game.new_initial_state(np.random.default_rng(12345))
        p = st.current_player()
        a.reset(game, p, np.random.default_rng(0))
        a.step(st, p)


def _cost_hint(t: dict) -> float:
    c = t["col"]
    return 10.0 if c == "gametree3" else 3.0 if c == "gametree2" else 1.0
