"""The Table 1 evaluation's report: aggregate the bouts into tables (mean score with a 95%
interval per cell, coverage, decision costs, kind histograms, IG diagnostics), plots and markdown."""
from __future__ import annotations

import hashlib
import json
import math
import os
import platform
import subprocess
from dataclasses import asdict
from pathlib import Path

import numpy as np

from igraph_fight.evaluate.config import (
    EXACT2, OPPONENT_DOC, OPPONENTS, PAPER, PAPER_COVERAGE, EvalConfig, ig_rows, row_depth)
from igraph_fight.stats import mean_ci

def json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


def _kind_hist(rows: list[dict], who: str) -> dict:
    h: dict[str, int] = {}
    for r in rows:
        for k, v in r[f"kinds_{who}"].items():
            h[k] = h.get(k, 0) + v
    return dict(sorted(h.items()))


def aggregate(cfg: EvalConfig, ctx: dict, rl: dict, results: list[dict], notes: list[str]) -> dict:
    graph = ctx["graph"]
    rows = ig_rows(cfg)
    table: dict = {}
    off: dict = {}
    for r in rows:
        table[r], off[r] = {}, {}
        for c in cfg.opponents:
            sub = [x for x in results if x["row"] == r and x["col"] == c]
            cell = mean_ci([x["score"] for x in sub])
            cell["hits_ig"] = float(np.mean([x["hits_row"] for x in sub]))
            cell["hits_opponent"] = float(np.mean([x["hits_col"] for x in sub]))
            cell["mean_distance_m"] = float(np.mean([x["mean_distance_m"] for x in sub]))
            cell["paper"] = PAPER.get(c, {}).get(row_depth(r)) if not r.endswith(EXACT2) else None
            table[r][c] = cell
            n = sum(x["ig"]["decisions"] for x in sub)
            off[r][c] = sum(x["ig"]["off_graph"] for x in sub) / max(n, 1)
    h2h: dict = {}
    for r in ("rl", "rl_outboxer"):
        for c in cfg.head_to_head:
            sub = [x for x in results if x["row"] == r and x["col"] == c]
            if sub:
                cell = mean_ci([x["score"] for x in sub])
                cell["mean_distance_m"] = float(np.mean([x["mean_distance_m"] for x in sub]))
                h2h.setdefault(r, {})[c] = cell
    cov = [x["coverage"] for x in results if "coverage" in x]
    cov_n = sum(c["n"] for c in cov)
    coverage = sum(c["covered"] for c in cov) / cov_n if cov_n else None
    # decision cost and kinds per agent name
    agents: dict[str, dict] = {}
    for x in results:
        for who, name in (("row", x["row"]), ("col", x["col"])):
            a = agents.setdefault(name, {"us": 0.0, "n": 0, "kinds": {}})
            a["us"] += x["timing"][f"us_{who}"]
            a["n"] += x[f"decisions_{who}"]
            for k, v in x[f"kinds_{who}"].items():
                a["kinds"][k] = a["kinds"].get(k, 0) + v
    decision_us = {k: (v["us"] / v["n"] if v["n"] else None) for k, v in sorted(agents.items())}
    events = {}
    for x in results:
        for who, name in (("row", x["row"]), ("col", x["col"])):
            if f"events_{who}" in x:
                e = events.setdefault(name, [0, 0])
                e[0] += x[f"events_{who}"]
                e[1] += x[f"decisions_{who}"]
    baselines = {"gametree_events_per_decision": {k: v[0] / max(v[1], 1) for k, v in sorted(events.items())},
                 "static_training": {k: getattr(ctx["static"], k) for k in ("states", "events", "iterations", "gamma")}}
    kinds = {k: dict(sorted(v["kinds"].items())) for k, v in sorted(agents.items())}
    collapse = {}
    for k, h in kinds.items():
        tot = sum(h.values())
        if tot:
            p = np.array(list(h.values()), dtype=np.float64) / tot
            collapse[k] = {"top_kind": max(h, key=h.get), "top_share": float(p.max()),
                           "entropy_bits": float(-(p * np.log2(p)).sum()), "decisions": tot}
    ig_diag = {}
    for r in rows:
        sub = [x for x in results if x["row"] == r]
        snaps = sum(x["ig"]["snaps"] for x in sub)
        pn = sum(x["ig"]["probe_n"] for x in sub)
        rg = [t for x in sub for t in x["ig"]["regret"]]
        def _rg(sel):
            z = [t for t in rg if sel(t)]
            return {"n": len(z), "mean_regret": float(np.mean([t[0] for t in z])) if z else None,
                    "agreement": float(np.mean([t[1] for t in z])) if z else None}
        ig_diag[r] = {"off_graph_rate": sum(x["ig"]["off_graph"] for x in sub) / max(sum(x["ig"]["decisions"] for x in sub), 1),
                      "live_states_within_tolerance": sum(x["ig"]["probe_within"] for x in sub) / max(pn, 1),
                      "live_states_without_compatible_group": sum(x["ig"]["probe_no_group"] for x in sub) / max(pn, 1),
                      "off_graph_by_opponent": off[r],
                      "snap_mean_cm": 100 * sum(x["ig"]["snap_m"] for x in sub) / max(snaps, 1),
                      "snap_mean_deg": math.degrees(sum(x["ig"]["snap_rad"] for x in sub) / max(snaps, 1)),
                      "snap_mean_frames_other": sum(x["ig"]["snap_frames"] for x in sub) / max(snaps, 1),
                      "edge_fidelity": _fid([t for x in sub for t in x["ig"]["fidelity"]]),
                      "regret_vs_exact_search": {"all": _rg(lambda t: True), "on_graph": _rg(lambda t: t[2] == 0),
                                                 "off_graph": _rg(lambda t: t[2] == 1),
                                                 "depth": cfg.regret_depth, "every": cfg.regret_every}}
    rl_info = {}
    if rl.get("rl") is not None:
        b = rl["rl"]["budget"]
        rb = rl.get("rl_outboxer", {}).get("budget", {}) if rl.get("rl_outboxer") is not None else {}
        rl_info = {
            "checkpoint": rl.get("rl_path"), "style": rl["rl"]["style"],
            "train_minutes": b["cpu_minutes"], "train_wall_minutes": b["wall_minutes"], "decisions": b["decisions"],
            "updates": b["updates"], "config": rl["rl"]["config"],
            "retrain_minutes_new_style": rb.get("cpu_minutes"), "retrain_wall_minutes_new_style": rb.get("wall_minutes"),
            "retrain_decisions_new_style": rb.get("decisions"), "retrain_checkpoint": rl.get("rl_outboxer_path"),
            "retrain_from": "rl (infighter) weights, fine-tuned with the outboxer reward",
            "head_to_head": h2h,
            "curve_last": rl["rl"]["curve"][-1] if rl["rl"]["curve"] else None,
        }
    targets = _targets(cfg, table, coverage)
    det = {"table": table, "coverage": coverage, "coverage_detail": {
               "decisions": cov_n, "covered": sum(c["covered"] for c in cov),
               "nearest_within": sum(c["within"] for c in cov),
               "no_compatible_group": sum(c["no_group"] for c in cov)},
           "kinds": kinds, "mode_collapse": collapse, "baselines": baselines, "ig_diagnostics": ig_diag, "head_to_head": h2h,
           "targets": targets, "bouts_detail": [{k: v for k, v in x.items() if k != "timing"} for x in results]}
    digest = hashlib.sha256(json.dumps(det, sort_keys=True, default=json_default).encode()).hexdigest()
    from igraph_fight.graph import package_version
    return {
        "config": {k: v for k, v in asdict(cfg).items() if k not in ("progress",)},
        "graph": {"path": str(cfg.graph), "n_states": graph.n_states, "n_edges": graph.n_edges,
                  "content_hash": graph.content_hash, "f0": graph.header.get("options", {}).get("f0"),
                  "link_tol_r_m": graph.header.get("options", {}).get("link_tol_r_m"),
                  "link_tol_theta_rad": graph.header.get("options", {}).get("link_tol_theta_rad")},
        "ig_fighter": {"style": cfg.style, "agent": "IGAgent(NPCController(graph, style, depth=d)) with the defaults"
                       + ("; rows IG(d)+exact2: the same controller with first_ply='exact2' (two exact plies, the "
                          "graph's values at the leaves)" if cfg.exact2_depths else "")},
        "paper": {"table": {c: {f"IG({d})": v for d, v in PAPER[c].items()} for c in PAPER}, "coverage": PAPER_COVERAGE},
        **{k: v for k, v in det.items() if k != "bouts_detail"},
        "decision_us": decision_us,
        "rl": rl_info,
        "machine": machine_info(),
        "package_version": package_version(),
        "command": cfg.command,
        "notes": notes,
        "results_digest": digest,
        "timing": {},
        "bouts": det["bouts_detail"],
    }


def _fid(f: list) -> dict:
    """Aggregate of _Watch._fidelity records."""
    if not f:
        return {"decisions": 0}
    a = np.array(f, dtype=np.float64)
    tp, fp, fn = a[:, 2].sum(), a[:, 3].sum(), a[:, 4].sum()
    ch = a[a[:, 5] >= 0]
    pred = ch[ch[:, 5] == 1]
    return {"decisions": len(f), "edges": int(a[:, 1].sum()), "mean_abs_reward_error": float(a[:, 0].mean()),
            "stored_hits_that_hit": float(tp / max(tp + fp, 1)), "exact_hits_stored": float(tp / max(tp + fn, 1)),
            "chosen_edge_predicts_hit": int(len(pred)), "chosen_predicted_hits_that_hit": float(pred[:, 6].mean()) if len(pred) else None,
            "menu_share_with_edge": float(np.mean(a[:, 7] / a[:, 8])), "exact_best_action_has_edge": float(a[:, 9].mean())}


def _targets(cfg: EvalConfig, table: dict, coverage) -> dict:
    rows = [f"IG({d})" for d in sorted(cfg.depths)]
    t: dict = {}
    if len(rows) >= 2:
        t["strength_grows_with_depth"] = {
            c: bool(all(table[a][c]["mean"] <= table[b][c]["mean"] for a, b in zip(rows, rows[1:]))
                    and table[rows[0]][c]["mean"] < table[rows[-1]][c]["mean"]) for c in cfg.opponents}
    top = rows[-1] if rows else None
    if top == "IG(5)":
        t["IG(5)_positive_ci_excludes_0"] = {c: bool(table[top][c]["ci_low"] > 0) for c in cfg.opponents
                                             if c in ("human", "static", "gametree2", "rl")}
        if "gametree3" in cfg.opponents:
            t["IG(5)_vs_gametree3_at_least_0"] = bool(table[top]["gametree3"]["mean"] >= 0)
    x2 = f"IG(5){EXACT2}"
    if x2 in table:
        t[f"{x2}_positive_ci_excludes_0"] = {c: bool(table[x2][c]["ci_low"] > 0) for c in cfg.opponents
                                              if c in ("human", "static", "gametree2", "rl")}
        if "gametree3" in cfg.opponents:
            t[f"{x2}_vs_gametree3_at_least_0"] = bool(table[x2]["gametree3"]["mean"] >= 0)
    if coverage is not None:
        t["coverage_at_least_93"] = bool(coverage >= 0.93)
        t["coverage_goal_97"] = bool(coverage >= 0.97)
    return t


def machine_info() -> dict:
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    vers = {}
    for m in ("numpy", "numba", "torch", "scipy"):
        try:
            vers[m] = __import__(m).__version__
        except Exception:  # noqa: BLE001
            vers[m] = None
    commit = None
    try:
        root = Path(__file__).resolve().parent.parent
        commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, timeout=5).stdout.strip() or None
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
        if commit and dirty:
            commit += "+dirty"
    except Exception:  # noqa: BLE001
        pass
    return {"cpu": cpu, "cores": cores, "platform": platform.platform(), "python": platform.python_version(),
            "versions": vers, "git": commit}


# ----- artefacts -----------------------------------------------------------------------------------
def plots(report: dict, rl: dict, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(12, 4))
    for name, lab in (("rl", "infighter"), ("rl_outboxer", "outboxer retrain")):
        ck = rl.get(name)
        if ck is None or not ck.get("curve"):
            continue
        cv = ck["curve"]
        off = 0 if name == "rl" else rl["rl"]["budget"]["decisions"]
        x = np.array([c["decisions"] for c in cv]) + off
        ax[0].plot(x, [c["mean_reward"] for c in cv], label=f"{lab}: mean reward per decision")
        opps = sorted({k[6:] for c in cv for k in c if k.startswith("score_")})
        for o in opps:
            y = np.array([c.get(f"score_{o}", np.nan) for c in cv], dtype=float)
            k = max(1, len(y) // 25)
            ys = np.convolve(np.nan_to_num(y), np.ones(k) / k, mode="same") if k > 1 else y
            ax[1].plot(x, ys, label=f"{lab} vs {o}", ls="-" if name == "rl" else "--")
    ax[0].set_xlabel("learner decisions")
    ax[0].set_ylabel("Eq. 4 reward per decision")
    ax[1].set_xlabel("learner decisions")
    ax[1].set_ylabel("training bout score (hits - hits received), smoothed")
    if ax[0].lines:
        ax[0].legend(fontsize=7)
        ax[1].legend(fontsize=6, ncol=2)
    fig.suptitle("RL baseline learning curve (masked PPO)")
    fig.tight_layout()
    fig.savefig(out / "rl_curve.png", dpi=80)
    plt.close(fig)
    kinds = report["kinds"]
    names = list(kinds)
    allk = sorted({k for h in kinds.values() for k in h})
    fig, ax = plt.subplots(figsize=(max(8, 0.9 * len(names)), 4))
    bottom = np.zeros(len(names))
    cmap = plt.get_cmap("tab20")
    for j, k in enumerate(allk):
        v = np.array([kinds[n].get(k, 0) / max(sum(kinds[n].values()), 1) for n in names])
        ax.bar(names, v, bottom=bottom, label=k, color=cmap(j % 20))
        bottom += v
    ax.set_ylabel("share of decisions")
    ax.set_title("action kinds chosen per agent")
    ax.legend(fontsize=7, bbox_to_anchor=(1.01, 1), loc="upper left")
    plt.setp(ax.get_xticklabels(), rotation=30, ha="right")
    fig.tight_layout()
    fig.savefig(out / "kinds.png", dpi=80)
    plt.close(fig)


def _f(x, nd: int = 1) -> str:
    if x is None:
        return "-"
    if isinstance(x, float) and not math.isfinite(x):
        return "-"
    return f"{x:+.{nd}f}" if isinstance(x, float) else str(x)


def markdown(rep: dict) -> str:
    """The Markdown report (deterministic sections first, timings last)."""
    cfg = rep["config"]
    L: list[str] = []
    L.append("# Interaction Graph fighters vs baselines (Table 1 protocol)\n")
    L.append(f"- command: `{rep['command'] or '(library call)'}`")
    L.append(f"- package version {rep['package_version']}, git {rep['machine']['git']}")
    m = rep["machine"]
    L.append(f"- machine: {m['cpu']}, {m['cores']} cores available, {m['platform']}, Python {m['python']}, "
             + ", ".join(f"{k} {v}" for k, v in m["versions"].items()))
    g = rep["graph"]
    L.append(f"- graph: `{g['path']}` ({g['n_states']} states, {g['n_edges']} edges, f0 {g['f0']}, link tolerance "
             f"{g['link_tol_r_m']} m / {math.degrees(g['link_tol_theta_rad'] or 0):.0f} deg, content {g['content_hash'][:12]})")
    L.append(f"- IG fighter: {rep['ig_fighter']['agent']}, style **{cfg['style']}** (also the game-tree reward)")
    L.append(f"- {cfg['bouts']} bouts of {cfg['seconds']:.0f} s per cell, seed {cfg['seed']}; bout i of every cell starts "
             "from the same random initial state; the IG fighter plays slot A in even bouts, B in odd ones")
    L.append(f"- results digest (everything but timings): `{rep['results_digest'][:16]}`")
    for n in rep["notes"]:
        L.append(f"- note: {n}")
    L.append("\n## Table 1: mean score per bout (IG hits - opponent hits), 95% CI; paper in brackets\n")
    cols = list(next(iter(rep["table"].values())).keys()) if rep["table"] else []
    L.append("| | " + " | ".join(cols) + " |")
    L.append("|---|" + "---|" * len(cols))
    for r, row in rep["table"].items():
        cells = []
        for c in cols:
            x = row[c]
            p = f" [{x['paper']:+d}]" if x.get("paper") is not None else ""
            cells.append(f"{x['mean']:+.1f} ({x['ci_low']:+.1f}, {x['ci_high']:+.1f}){p}")
        L.append(f"| {r} | " + " | ".join(cells) + " |")
    L.append("\nOpponents: " + "; ".join(f"**{c}** {OPPONENT_DOC[c]}" for c in cols if c in OPPONENT_DOC) + ".")
    L.append("\nHits per bout (IG / opponent) and mean distance (m):\n")
    L.append("| | " + " | ".join(cols) + " |")
    L.append("|---|" + "---|" * len(cols))
    for r, row in rep["table"].items():
        L.append(f"| {r} | " + " | ".join(f"{row[c]['hits_ig']:.1f} / {row[c]['hits_opponent']:.1f}, "
                                          f"{row[c]['mean_distance_m']:.2f}" for c in cols) + " |")
    if rep.get("human_logs"):
        from igraph_fight.evaluate.human_logs import markdown_section
        L.extend(markdown_section(rep["human_logs"], rep["table"]))
    L.append("\n## Targets\n")
    for k, v in rep["targets"].items():
        if isinstance(v, dict):
            L.append(f"- {k}: " + ", ".join(f"{c} {'yes' if ok else '**no**'}" for c, ok in v.items()))
        else:
            L.append(f"- {k}: {'yes' if v else '**no**'}")
    L.append("\n## Coverage\n")
    cd = rep["coverage_detail"]
    if rep["coverage"] is not None:
        L.append(f"{100 * rep['coverage']:.1f}% of the {cd['decisions']} decision states of the gametree-3 fighter lie within "
                 f"the linking tolerance of an IG state of their compatible group (paper: 93%); "
                 f"{cd['no_compatible_group']} had no compatible group at all. For "
                 f"{100 * cd['nearest_within'] / max(cd['decisions'], 1):.1f}% the *nearest* state (normalised "
                 "distance, what the controller maps a live state to) is itself within the tolerance: the "
                 "controller's on-graph rate for these states.")
    L.append("\n## IG fighter diagnostics (off-graph decisions, runtime snapping)\n")
    L.append("Off-graph rate: decisions the controller flagged off the graph (overall and per opponent); "
             "'no group': live states whose compatible group (Next-set, M_other, open strikes, F_other within f0) "
             "holds no IG state at all; snapping: mean correction per snapped decision.\n")
    L.append("| | off-graph | " + " | ".join(f"vs {c}" for c in cols) + " | no group | snap cm | snap deg | other's frame shift |")
    L.append("|---|---|" + "---|" * len(cols) + "---|---|---|---|")
    for r, d in rep["ig_diagnostics"].items():
        L.append(f"| {r} | {100 * d['off_graph_rate']:.0f}% | " + " | ".join(
            f"{100 * d['off_graph_by_opponent'][c]:.0f}%" for c in cols) +
            f" | {100 * d['live_states_without_compatible_group']:.0f}% | {d['snap_mean_cm']:.1f} | "
            f"{d['snap_mean_deg']:.1f} | {d['snap_mean_frames_other']:.1f} |")
    L.append("\nDecision quality: on a sample of IG decisions (every "
             f"{cfg.get('regret_every')}th), the exact depth-{cfg.get('regret_depth')} min-max over the simulator (the "
             "gametree reward) values every legal action; regret = best value - value of the IG's action (Eq. 4 reward "
             "units), agreement = the IG picked a best action.\n")
    L.append("| | sampled | agreement | mean regret | on graph: n, agreement, regret | off graph: n, agreement, regret |")
    L.append("|---|---|---|---|---|---|")
    for r, d in rep["ig_diagnostics"].items():
        g = d.get("regret_vs_exact_search")
        if not g:
            continue

        def cell(z):
            if not z["n"]:
                return "0"
            return f"{z['n']}, {100 * z['agreement']:.0f}%, {z['mean_regret']:.2f}"
        a = g["all"]
        L.append(f"| {r} | {a['n']} | {100 * (a['agreement'] or 0):.0f}% | {a['mean_regret'] or 0:.2f} | "
                 f"{cell(g['on_graph'])} | {cell(g['off_graph'])} |")
    L.append("\nEdge fidelity: on the same sampled decisions when on the graph, every edge of the matched state "
             "(its stored features, what the planner optimises) against the same action simulated exactly from the "
             "live state.\n")
    L.append("| | decisions | edges | mean abs reward error | stored hits that hit | exact hits the graph knew | "
             "chosen edges predicting a hit: n, share that hit | menu actions with an edge | exact best action has an edge |")
    L.append("|---|---|---|---|---|---|---|---|---|")
    for r, d in rep["ig_diagnostics"].items():
        f = d.get("edge_fidelity") or {}
        if not f.get("decisions"):
            continue
        ph = f["chosen_predicted_hits_that_hit"]
        L.append(f"| {r} | {f['decisions']} | {f['edges']} | {f['mean_abs_reward_error']:.2f} | "
                 f"{100 * f['stored_hits_that_hit']:.0f}% | {100 * f['exact_hits_stored']:.0f}% | "
                 f"{f['chosen_edge_predicts_hit']}, {'-' if ph is None else f'{100 * ph:.0f}%'} | "
                 f"{100 * f['menu_share_with_edge']:.0f}% | {100 * f['exact_best_action_has_edge']:.0f}% |")
    L.append("\n## Decision cost (µs per decision, wall clock inside step; varies with the machine)\n")
    L.append("| agent | µs |\n|---|---|")
    for k, v in rep["decision_us"].items():
        L.append(f"| {k} | {v:.0f} |" if v is not None else f"| {k} | - |")
    b = rep.get("baselines", {})
    if b.get("gametree_events_per_decision"):
        L.append("\nGame tree: " + ", ".join(f"{k} simulates {v:.0f} events per decision (alpha-beta, exact)"
                                            for k, v in b["gametree_events_per_decision"].items()) + ".")
    if b.get("static_training"):
        st = b["static_training"]
        L.append(f"Static: value iteration over {st['states']} grid states, {st['events']} simulated events, "
                 f"{st['iterations']} sweeps (gamma {st['gamma']}), trained at start-up (seconds).")
    rl = rep.get("rl") or {}
    if rl:
        L.append("\n## RL baseline (masked PPO)\n")
        L.append(f"- checkpoint `{rl['checkpoint']}` ({rl['style']} reward): {rl['train_minutes']:.1f} CPU minutes "
                 f"({rl['train_wall_minutes']:.1f} wall), {rl['decisions']} learner decisions, {rl['updates']} updates; "
                 "training command: `igraph-fight train-rl --graph G --style infighter --out igraph_fight/checkpoints/rl_infighter.pt`")
        if rl.get("retrain_minutes_new_style") is not None:
            L.append(f"- new style (outboxer): {rl['retrain_minutes_new_style']:.1f} CPU minutes, "
                     f"{rl['retrain_decisions_new_style']} decisions ({rl['retrain_from']}) vs the planner's style swap "
                     f"{rep['style_swap_ms']:.0f} ms (NPCController.set_style at depth {rep['timing']['style_swap'].get('depth')})"
                     if rep.get("style_swap_ms") is not None else "")
        L.append("- learning curve: `rl_curve.png`")
        if rl.get("head_to_head"):
            h = rl["head_to_head"]
            hc = sorted({c for v in h.values() for c in v}, key=lambda c: OPPONENTS.index(c))
            L.append("\nHead-to-head (RL score: its hits - opponent hits; mean, 95% CI; mean distance m):\n")
            L.append("| | " + " | ".join(hc) + " |")
            L.append("|---|" + "---|" * len(hc))
            for r, row in h.items():
                L.append(f"| {r} | " + " | ".join(
                    f"{row[c]['mean']:+.1f} ({row[c]['ci_low']:+.1f}, {row[c]['ci_high']:+.1f}), {row[c]['mean_distance_m']:.2f} m"
                    if c in row else "-" for c in hc) + " |")
    L.append("\n## Action kinds per agent (share of decisions; `kinds.png`)\n")
    allk = sorted({k for h in rep["kinds"].values() for k in h})
    L.append("| agent | " + " | ".join(allk) + " | top share | entropy (bits) |")
    L.append("|---|" + "---|" * len(allk) + "---|---|")
    for n, h in rep["kinds"].items():
        tot = max(sum(h.values()), 1)
        mc = rep["mode_collapse"].get(n, {})
        L.append(f"| {n} | " + " | ".join(f"{100 * h.get(k, 0) / tot:.0f}%" for k in allk) +
                 f" | {100 * mc.get('top_share', 0):.0f}% | {mc.get('entropy_bits', 0):.2f} |")
    t = rep["timing"]
    L.append("\n## Timings (vary from run to run)\n")
    L.append(f"- wall time {t.get('wall_s', 0) / 60:.1f} min: setup {t.get('setup_s', 0):.0f} s, RL {t.get('rl_s', 0):.0f} s, "
             f"bouts {t.get('bouts_s', 0):.0f} s with {cfg['workers']} workers")
    if t.get("style_swap"):
        L.append(f"- style swap: {t['style_swap']}")
    return "\n".join(L) + "\n"
