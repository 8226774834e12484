"""What a physics bout produced (tracker.bouts.physics_bout): the result record and its summary (the kinematic
bouts' summary keys plus falls, planned hits and the physics reward terms)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def zero_reward() -> dict:
    """The physics reward terms of one fighter, all zero (tracker.bouts.physics_bout accumulates them)."""
    return {"match": 0.0, "close": 0.0, "facing": 0.0, "energy": 0.0, "fall": 0.0, "given_n": 0.0,
            "received_n": 0.0}


@dataclass
class PhysicsBoutResult:
    """Everything a physics bout produced (times s, distances m, forces N)."""

    names: tuple[str, str]
    seconds: float
    seed: int
    hits: np.ndarray                  # realised hits by A, by B
    planned: np.ndarray               # planned hits by A, by B
    planned_realised: np.ndarray      # planned hits that landed, by A, by B
    planned_standing: np.ndarray      # planned hits due while both fighters stood
    planned_standing_realised: np.ndarray
    falls: np.ndarray
    damage_n: np.ndarray              # clipped fist force given (sum over control steps), by A, by B
    touches: np.ndarray
    decisions: list[dict]
    hit_events: list[dict]
    planned_events: list[dict]
    fall_events: list[dict]
    touch_events: list[dict]
    notes: list[dict]
    trace: dict
    reward: list[dict]
    wall_s: float
    sim_s: float
    tracker: str
    agents_info: list[dict] = field(default_factory=list)
    assist: list[dict] | None = None   # per fighter: tracker.track.assist.summarise_assist (batched trackers)
    physics: str = "physics (no assist)"   # how the physics is labelled (AssistConfig.label)

    @property
    def score(self) -> float:
        return float(self.hits[0] - self.hits[1])

    @property
    def realtime_factor(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else float("nan")

    def summary(self) -> dict:
        minutes = max(self.seconds / 60.0, 1e-9)
        p = float(self.planned.sum())
        ps = float(self.planned_standing.sum())
        dist = self.trace["distance"]
        down = np.asarray(self.trace["down"], dtype=bool).reshape(-1, 2)
        kinds = [{}, {}]
        for d in self.decisions:
            kinds[d["player"]][d["kind"]] = kinds[d["player"]].get(d["kind"], 0) + 1
        share = [{k: v / max(sum(c.values()), 1) for k, v in sorted(c.items())} for c in kinds]
        foreseen = [d["foreseen"] for d in self.decisions if "foreseen" in d]   # foresight's guesses, right or not
        return {
            "a": self.names[0], "b": self.names[1], "seconds": self.seconds, "seed": self.seed, "physics": True,
            "hits_a": float(self.hits[0]), "hits_b": float(self.hits[1]), "score": self.score,
            "defended_a": 0.0, "defended_b": 0.0,
            "mean_distance_m": float(np.mean(dist)) if len(dist) else float("nan"),
            "decisions_a": sum(1 for d in self.decisions if d["player"] == 0),
            "decisions_b": sum(1 for d in self.decisions if d["player"] == 1),
            "kind_share_a": share[0], "kind_share_b": share[1],
            "falls_a": int(self.falls[0]), "falls_b": int(self.falls[1]),
            "falls_per_min_a": float(self.falls[0]) / minutes, "falls_per_min_b": float(self.falls[1]) / minutes,
            "fall_reasons": {r: sum(1 for e in self.fall_events if e["reason"] == r)
                             for r in sorted({e["reason"] for e in self.fall_events})},
            "standing_s_a": float((~down[:, 0]).sum()) / 30.0 if len(down) else 0.0,
            "standing_s_b": float((~down[:, 1]).sum()) / 30.0 if len(down) else 0.0,
            "planned_hits": p, "planned_hits_a": float(self.planned[0]), "planned_hits_b": float(self.planned[1]),
            "realised_hits": float(self.hits.sum()),
            "planned_realised": float(self.planned_realised.sum()),
            "planned_realised_ratio": float(self.planned_realised.sum()) / p if p else None,
            **({"foreseen_share": float(np.mean(foreseen))} if foreseen else {}),
            "planned_hits_standing": ps,
            "planned_realised_ratio_standing": float(self.planned_standing_realised.sum()) / ps if ps else None,
            "unplanned_hits": float(self.hits.sum() - self.planned_realised.sum()),
            # per planned hit: 0 when it landed, else how near the strike's fist came to the opponent's
            # head/chest/belly while its window was open and both stood (m; None: it never was)
            "planned_closest_m": [0.0 if e.get("realised") else e.get("closest_m") for e in self.planned_events],
            # per planned hit, at its predicted instant (tracker.bouts.physics_bout's miss anatomy; None: a fighter was down):
            # how far the striker's pelvis was behind its reference along the line to the opponent (m)
            "planned_lag_attacker_m": [e.get("lag_attacker_m") for e in self.planned_events],
            "touches_a": int(self.touches[0]), "touches_b": int(self.touches[1]),
            "damage_n_a": float(self.damage_n[0]), "damage_n_b": float(self.damage_n[1]),
            "reward_a": self.reward[0], "reward_b": self.reward[1],
            "realtime_factor": self.realtime_factor, "wall_s": self.wall_s, "sim_s": self.sim_s,
            "tracker": self.tracker, "agents": self.agents_info, "physics_label": self.physics,
            **({"assist_a": self.assist[0], "assist_b": self.assist[1],
                "hits_at_cap": int(sum(1 for h in self.hit_events if h.get("assist_at_cap")))}
               if self.assist is not None else {}),
            **{f"off_graph_{'ab'[k]}": (a["off_graph"] / max(a["decisions"], 1)) for k, a in enumerate(self.agents_info)
               if "off_graph" in a},
        }
