"""Bouts of an evaluation on Ray actors (``igraph-fight evaluate --backend ray``).

Each actor builds the evaluation context once (the graph is read from ``cfg.graph``: on a
cluster of several machines that path must be readable on every node) and plays the bouts it is
given; each bout is self-contained and seeded (runner.run_task), so the results, and the
``results_digest``, are those of a local run whatever the actor and node count.
"""
from __future__ import annotations

from typing import Callable

from igraph_fight.build.stages import connect_ray
from igraph_fight.evaluate.config import EvalConfig


class BoutWorker:
    """One Ray actor's evaluation context and its bouts: ``build_context(cfg, rl)`` once, then
    ``run_task(ctx, task)`` per bout (runner.build_context and runner.run_task_in)."""

    def __init__(self, cfg: EvalConfig, rl: dict, build_context: Callable, run_task: Callable) -> None:
        import torch
        torch.set_num_threads(1)
        self.ctx = build_context(cfg, rl)
        self.run_task = run_task

    def run(self, task: dict) -> dict:
        import ray
        out = self.run_task(self.ctx, task)
        out["timing"]["node"] = ray.get_runtime_context().get_node_id()
        return out


def run_tasks_on_ray(cfg: EvalConfig, rl: dict, tasks: list[dict], on_result: Callable[[dict], None],
                     build_context: Callable, run_task: Callable, workers: int | None = None,
                     address: str | None = None) -> dict:
    """Play ``tasks`` on Ray actors (``workers``; None: one per CPU of the cluster), calling
    ``on_result`` as each bout finishes; returns {"workers", "nodes"} (nodes that played bouts)."""
    ray, started, n = connect_ray(workers, address)
    try:
        n = max(1, min(n, len(tasks)))
        cfg_ref = ray.put(cfg)
        rl_ref = ray.put(rl)
        Actor = ray.remote(num_cpus=1)(BoutWorker)
        actors = [Actor.options(scheduling_strategy="SPREAD").remote(cfg_ref, rl_ref, build_context, run_task)
                  for _ in range(n)]
        idle = list(range(n))
        queue = list(tasks)
        running: dict = {}
        nodes: set[str] = set()
        while queue or running:
            while queue and idle:
                k = idle.pop()
                running[actors[k].run.remote(queue.pop(0))] = k
            done, _ = ray.wait(list(running), num_returns=1)
            for ref in done:
                idle.append(running.pop(ref))
                r = ray.get(ref)
                nodes.add(r["timing"].pop("node"))
                on_result(r)
        for a in actors:
            ray.kill(a)
        return {"backend": "ray", "workers": n, "nodes": len(nodes)}
    finally:
        if started:
            ray.shutdown()
