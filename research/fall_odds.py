"""Which actions physics fighters fall in or right after, from physics bout logs.

For one fighter (player 0 = A, 1 = B) over bout directories written by ``tracker.bouts.cli fight``
(their log.jsonl and summary.json), each launched library action is counted with the falls that
came while it played or while the next action played (a fall often shows in the action after the
one that unbalanced the body). The odds per play are shrunk towards the mean over all plays
(``prior_plays`` pseudo-plays at the mean), and actions played at least ``min_plays`` times whose
shrunk odds reach ``factor`` times the mean are suggested as ``avoid`` for the closing rule
(igraph_fight.closing.ClosingRule.avoid; ``STYLE+close:avoid=A,B`` on the command lines).

    python -m research.fall_odds --player 0 DIR [DIR ...]

Named approximation: the counts credit a fall to both the action it came in and the one before,
and a handful of bouts gives a handful of falls per action; the suggestion is a screening, to be
checked on bouts it was not read from.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass
class FallOdds:
    """Per library action (index = action id): plays, falls while it played, falls while the next
    action played; ``seconds`` played (s)."""

    plays: np.ndarray
    falls_in: np.ndarray
    falls_next: np.ndarray
    seconds: np.ndarray

    def odds(self, prior_plays: float = 5.0) -> np.ndarray:
        """Falls in or right after an action per play, shrunk towards the mean over all plays."""
        mean = self.mean()
        return (self.falls_in + self.falls_next + prior_plays * mean) / (self.plays + prior_plays)

    def mean(self) -> float:
        """Falls in or right after an action per play, over all plays."""
        return float((self.falls_in + self.falls_next).sum() / max(self.plays.sum(), 1))

    def suggest_avoid(self, min_plays: int = 5, factor: float = 2.0, prior_plays: float = 5.0) -> list[int]:
        """Actions played at least ``min_plays`` times whose shrunk odds reach ``factor`` x the mean."""
        o = self.odds(prior_plays)
        return [int(a) for a in np.flatnonzero((self.plays >= min_plays) & (o >= factor * self.mean()))]


def _read(d: Path) -> tuple[list[dict], float]:
    log, summ = d / "log.jsonl", d / "summary.json"
    for p in (log, summ):
        if not p.is_file():
            raise FileNotFoundError(f"{d}: no {p.name} (a directory written by tracker.bouts.cli fight)")
    try:
        events = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
        seconds = float(json.loads(summ.read_text())["seconds"])
    except (json.JSONDecodeError, KeyError) as e:
        raise ValueError(f"{d}: unreadable bout log or summary ({e})") from None
    return events, seconds


def fall_odds(dirs: list[str | Path], player: int, n_actions: int | None = None) -> FallOdds:
    """Count plays and falls per action for ``player`` over the bout directories ``dirs``."""
    rows = []
    for d in map(Path, dirs):
        events, seconds = _read(d)
        acts = [e for e in events if e.get("type") == "action" and e.get("player") == player]
        falls = [float(e["t"]) for e in events if e.get("type") == "fall" and e.get("player") == player]
        ends = [float(e["t"]) for e in acts[1:]] + [seconds]
        for i, e in enumerate(acts):
            t0, t1 = float(e["t"]), ends[i]
            t2 = ends[i + 1] if i + 1 < len(acts) else t1
            rows.append((int(e["action"]), t1 - t0, sum(t0 <= f < t1 for f in falls), sum(t1 <= f < t2 for f in falls)))
    n = n_actions if n_actions is not None else (max((r[0] for r in rows), default=-1) + 1)
    out = FallOdds(np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n))
    for a, dt, fi, fn in rows:
        out.plays[a] += 1
        out.seconds[a] += dt
        out.falls_in[a] += fi
        out.falls_next[a] += fn
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m research.fall_odds", description=__doc__.split("\n\n")[0])
    p.add_argument("dirs", nargs="+", help="bout directories (log.jsonl, summary.json)")
    p.add_argument("--player", type=int, choices=(0, 1), default=0, help="0 = fighter A, 1 = fighter B")
    p.add_argument("--min-plays", type=int, default=5)
    p.add_argument("--factor", type=float, default=2.0)
    p.add_argument("--prior-plays", type=float, default=5.0)
    a = p.parse_args(argv)
    try:
        fo = fall_odds(a.dirs, a.player)
    except (FileNotFoundError, ValueError) as e:
        print(f"research.fall_odds: error: {e}", file=sys.stderr)
        return 2
    odds = fo.odds(a.prior_plays)
    print(f"{int(fo.plays.sum())} plays, {int(fo.falls_in.sum())} falls; falls in or after an action per play: "
          f"{fo.mean():.3f}")
    for i in np.argsort(-odds):
        if fo.plays[i]:
            print(f"action {i:3d}: plays {fo.plays[i]:4d} ({fo.seconds[i]:6.1f} s), falls in it {fo.falls_in[i]}, "
                  f"in the next {fo.falls_next[i]}, shrunk odds {odds[i]:.3f}")
    avoid = fo.suggest_avoid(a.min_plays, a.factor, a.prior_plays)
    print("suggested avoid: " + (",".join(map(str, avoid)) if avoid else "(none)"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
