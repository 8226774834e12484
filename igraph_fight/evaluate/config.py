"""The Table 1 evaluation's settings: the paper's figures, the opponents, the IG rows, EvalConfig."""
from __future__ import annotations

from dataclasses import dataclass, field

PAPER = {  # Table 1 of Shum, Komura & Yamazaki 2008, rows IG(1), IG(3), IG(5) (docs/protocols.md, Match)
    "human": {1: -15, 3: 23, 5: 28},
    "static": {1: 34, 3: 54, 5: 55},
    "gametree2": {1: -37, 3: 14, 5: 28},
    "gametree3": {1: -53, 3: -19, 5: -4},
}


PAPER_COVERAGE = 0.93


OPPONENT_DOC = {
    "human": "a scripted reactive PROXY for a person issuing high-level commands (0.25 s reaction delay, noisy "
             "rules; agents/human.py), not a person",
    "static": "trained by value iteration to approach and hit a target frozen in guard, no defence (after Lee & Lee "
              "2004; agents/static.py)",
    "gametree2": "min-max to depth 2 on the exact simulator, same reward as the IG fighter (agents/gametree.py)",
    "gametree3": "the same to depth 3",
    "rl": "masked PPO policy on continuous features, infighter reward (agents/rl.py, rl_train.py)",
    "rl_outboxer": "the RL policy fine-tuned for the outboxer reward",
    "random": "uniform legal actions",
}


OPPONENTS = ("human", "static", "gametree2", "gametree3", "rl", "random", "rl_outboxer")


EXACT2 = "+exact2"  # row suffix: the IG fighter searches two exact plies over the graph's values


def ig_rows(cfg: "EvalConfig") -> list[str]:
    """The table's rows: IG(d) per depth, then IG(d)+exact2 per exact2 depth."""
    return [f"IG({d})" for d in cfg.depths] + [f"IG({d}){EXACT2}" for d in cfg.exact2_depths]


def row_depth(row: str) -> int:
    """d of a row name IG(d) or IG(d)+exact2."""
    return int(row[3:row.index(")")])


@dataclass
class EvalConfig:
    """What to evaluate (see the module docstring); paths as strings."""

    graph: str
    opponents: tuple = ("human", "static", "gametree2", "gametree3", "rl")
    depths: tuple = (1, 3, 5)
    exact2_depths: tuple = (5,)                 # extra rows IG(d)+exact2: NPCController(first_ply="exact2")
    bouts: int = 20
    seconds: float = 60.0
    seed: int = 0
    workers: int = 1                            # bout processes (local), Ray actors (ray; 0: every CPU)
    backend: str = "local"                      # "local" or "ray" (evaluate.ray_runner)
    address: str | None = None                  # ray: a running cluster's address (default: start Ray here)
    style: str = "infighter"
    rl_checkpoint: str | None = None            # default: igraph_fight/checkpoints/rl_infighter.pt
    rl_outboxer_checkpoint: str | None = None   # default: igraph_fight/checkpoints/rl_outboxer.pt
    train_rl: bool = False                      # retrain both RL policies before the bouts
    rl_decisions: int = 1_000_000
    rl_cpu_minutes: float = 15.0
    rl_retrain_decisions: int = 300_000
    head_to_head: tuple = ("random", "human", "static", "gametree2", "gametree3")
    h2h_bouts: int | None = None                # default: bouts
    regret_every: int = 8                       # every k-th IG decision: exact depth-3 regret (0: off)
    regret_depth: int = 3
    human_logs: str | None = None               # folder of bouts saved by `igraph-fight play` (the real human column)
    progress: bool = True
    command: str = ""
    extra: dict = field(default_factory=dict)
