"""The Ray backend on a simulated 3-node cluster (ray.cluster_utils.Cluster on this machine):
work lands on more than one node and the graph is the local build's."""
from __future__ import annotations

import pytest

from igraph_fight.build.pipeline import BuildOptions, build_graph

SMALL = BuildOptions(max_samples=6_000, n_initial=32, chunk_parents=128, seed_bouts=0)


@pytest.fixture(scope="module")
def cluster():
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster
    c = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    for _ in range(2):
        c.add_node(num_cpus=1)
    ray.init(address=c.address, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    c.wait_for_nodes()
    yield c
    ray.shutdown()
    c.shutdown()


def test_three_node_build_runs_on_several_nodes_with_the_local_hash(boxing_library, cluster):
    import ray
    assert len([n for n in ray.nodes() if n["Alive"]]) == 3
    g0, _ = build_graph(boxing_library, SMALL, seed=0, workers=1)
    g, r = build_graph(boxing_library, SMALL, seed=0, workers=3, backend="ray")
    assert r["backend"]["nodes_with_tasks"] >= 2, r["backend"]
    assert g.content_hash == g0.content_hash
