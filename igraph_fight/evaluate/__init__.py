"""The match evaluation of the paper's Table 1 with the baselines: ``runner`` plays the bouts,
``report`` aggregates them into tables, plots and markdown.

    from igraph_fight.evaluate import EvalConfig, evaluate
    report = evaluate(EvalConfig(bouts=20, seconds=60.0), "out/eval")
"""
from igraph_fight.evaluate.config import EvalConfig
from igraph_fight.evaluate.runner import evaluate

__all__ = ["EvalConfig", "evaluate"]
