"""The real human column of Table 1: bouts people played against the NPC in `igraph-fight play`,
read from their saved logs (log.jsonl with a meta line: igraph_fight.play.bouts).

A bout counts for row IG(d) when it ran to its full length (meta ``complete``) and the NPC
played the whole bout at depth d (one depth in ``npc_depths``); its score is the paper's: hits
landed by the NPC minus hits landed by the person, counted from the log's hit lines. Bouts cut
short, with a depth change, or unreadable are listed with the reason and left out. Cells report
the mean with a 95% Student-t interval (igraph_fight.stats.mean_ci), the bouts' NPC styles and
the graphs they were played on (content hashes), since people may play on another graph than
the one the table's other columns use.
"""
from __future__ import annotations

import os
from pathlib import Path

from igraph_fight.stats import mean_ci

#: log files read at most under a folder; folder depth searched
MAX_LOGS = 10_000
MAX_DEPTH = 3


def find_logs(folder: str | os.PathLike) -> list[Path]:
    """log.jsonl files under ``folder`` (at most MAX_DEPTH levels down, MAX_LOGS files), sorted."""
    root = Path(folder)
    out: list[Path] = []
    level = [root]
    for _ in range(MAX_DEPTH + 1):
        nxt = []
        for d in level:
            try:
                entries = sorted(d.iterdir())
            except OSError:
                continue
            for p in entries:
                if p.name.startswith("."):
                    continue
                if p.name == "log.jsonl" and p.is_file():
                    out.append(p)
                elif p.is_dir() and not p.is_symlink():
                    nxt.append(p)
                if len(out) >= MAX_LOGS:
                    return sorted(out)
        level = nxt
    return sorted(out)


def read_human_bout(path: str | os.PathLike) -> dict:
    """One saved bout: {log, depth (None if it changed), styles, graph, complete, seconds, score,
    hits_npc, hits_human}; raises ValueError for a log that is not a human bout."""
    from igraph_fight.match import read_bout_log

    log = read_bout_log(path)
    metas = log.get("meta") or []
    if not metas:
        raise ValueError("no meta line: not a bout saved by igraph-fight play")
    m = metas[0]
    human, npc = m.get("human"), m.get("npc")
    if human not in (0, 1) or npc not in (0, 1) or human == npc:
        raise ValueError("meta does not say which fighter was the person and which the NPC")
    hits = [0, 0]
    for h in log.get("hit", []):
        if h.get("attacker") in (0, 1):
            hits[h["attacker"]] += 1
    depths = m.get("npc_depths")
    depths = [d for d in depths if isinstance(d, int) and not isinstance(d, bool)] if isinstance(depths, list) else []
    played = m.get("played_s")
    return {"log": str(path), "depth": depths[0] if len(depths) == 1 else None, "depths": depths,
            "styles": [str(s) for s in m.get("npc_styles", [])][:8] if isinstance(m.get("npc_styles"), list) else [],
            "graph": str(m.get("graph", ""))[:64], "complete": m.get("complete") is True,
            "seconds": float(played) if isinstance(played, (int, float)) and not isinstance(played, bool) else None,
            "hits_npc": hits[npc], "hits_human": hits[human], "score": float(hits[npc] - hits[human])}


def human_table(folder: str | os.PathLike, depths=(1, 3, 5), graph_hash: str | None = None) -> dict:
    """The real human column: {"rows": {"IG(d)": mean_ci cell + styles, graphs, mean seconds},
    "bouts": every bout read, "skipped": [(log, reason)], "folder", "other_graph": bouts played on
    another graph than ``graph_hash``}."""
    rows: dict[str, dict] = {}
    bouts, skipped = [], []
    for p in find_logs(folder):
        try:
            b = read_human_bout(p)
        except ValueError as e:
            skipped.append({"log": str(p), "reason": str(e)[:200]})
            continue
        if not b["complete"]:
            skipped.append({"log": str(p), "reason": "bout cut short (saved before its end)"})
            continue
        if b["depth"] is None:
            skipped.append({"log": str(p), "reason": f"the NPC's depth changed during the bout ({b['depths']})"})
            continue
        bouts.append(b)
    for d in depths:
        sub = [b for b in bouts if b["depth"] == d]
        cell = mean_ci([b["score"] for b in sub])
        cell["styles"] = sorted({s for b in sub for s in b["styles"]})
        cell["graphs"] = sorted({b["graph"] for b in sub})
        cell["mean_seconds"] = (sum(b["seconds"] or 0.0 for b in sub) / len(sub)) if sub else None
        rows[f"IG({d})"] = cell
    other = sum(1 for b in bouts if graph_hash and b["graph"] != graph_hash)
    return {"folder": str(folder), "rows": rows, "bouts": bouts, "skipped": skipped, "other_graph": other,
            "other_depths": sorted({b["depth"] for b in bouts} - set(depths))}


def markdown_section(human: dict, table: dict) -> list[str]:
    """Report lines: the real human column beside the scripted proxy's (when evaluated) and the paper's."""
    from igraph_fight.evaluate.config import PAPER

    L = ["\n## Table 1, human column: people in `igraph-fight play` beside the scripted proxy\n",
         f"Saved bouts under `{human['folder']}` (IG score = NPC hits - person's hits a bout; mean, 95% interval, "
         "bouts). Only complete bouts at one NPC depth count; the proxy column is the scripted stand-in "
         "(agents/human.py).\n",
         "| | people (play) | bouts | NPC styles | mean length s | proxy (scripted) | paper |", "|---|---|---|---|---|---|---|"]
    for r, c in human["rows"].items():
        d = int(r[3:-1])
        proxy = table.get(r, {}).get("human")
        ptxt = f"{proxy['mean']:+.1f} [{proxy['ci_low']:+.1f}, {proxy['ci_high']:+.1f}]" if proxy else "-"
        if c["bouts"]:
            real = f"{c['mean']:+.1f} [{c['ci_low']:+.1f}, {c['ci_high']:+.1f}]"
            secs = f"{c['mean_seconds']:.0f}"
        else:
            real, secs = "-", "-"
        L.append(f"| {r} | {real} | {c['bouts']} | {', '.join(c['styles']) or '-'} | {secs} | {ptxt} | "
                 f"{PAPER['human'].get(d, '-')} |")
    if human["other_graph"]:
        L.append(f"\n{human['other_graph']} of these bouts were played on another graph than the one evaluated here.")
    if human["skipped"]:
        L.append(f"\nLeft out: {len(human['skipped'])} logs (" + "; ".join(
            f"{Path(s['log']).parent.name}: {s['reason']}" for s in human["skipped"][:5])
            + ("; ..." if len(human["skipped"]) > 5 else "") + ").")
    return L
