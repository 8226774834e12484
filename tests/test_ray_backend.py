"""The Ray backend on a local Ray (2 CPUs): the same graph and evaluation as the local backend."""
from __future__ import annotations

import sys

import pytest

from igraph_fight.build.backend import RAY_INSTALL_HINT, BackendUnavailable, require_ray
from igraph_fight.build.stages import shard_cuts
from igraph_fight.build.pipeline import BuildOptions, build_graph

SMALL = BuildOptions(max_samples=6_000, n_initial=32, chunk_parents=128, seed_bouts=16)


@pytest.fixture(scope="module")
def ray_2cpu():
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, logging_level="ERROR", log_to_driver=False)
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def local_build(boxing_library):
    return build_graph(boxing_library, SMALL, seed=0, workers=1)


def test_ray_build_has_the_local_content_hash_for_any_worker_count(boxing_library, local_build, ray_2cpu):
    g0, r0 = local_build
    for w in (1, 2):
        g, r = build_graph(boxing_library, SMALL, seed=0, workers=w, backend="ray")
        assert r["backend"]["backend"] == "ray" and r["backend"]["workers"] == w
        assert g.content_hash == g0.content_hash
        assert (r["n_states"], r["n_edges"]) == (r0["n_states"], r0["n_edges"])


def test_ray_build_resumes_a_local_checkpoint(boxing_library, local_build, ray_2cpu, tmp_path):
    class Stop(Exception):
        pass

    def stop_at_3(chunks: int, n: int) -> None:
        if chunks == 3:
            raise Stop

    with pytest.raises(Stop):
        build_graph(boxing_library, SMALL, seed=0, checkpoint_dir=tmp_path / "ck", on_chunk=stop_at_3)
    g, r = build_graph(boxing_library, SMALL, seed=0, workers=2, checkpoint_dir=tmp_path / "ck", backend="ray")
    assert r["resumed_from_checkpoint"] and g.content_hash == local_build[0].content_hash


def test_evaluate_on_ray_gives_the_local_results(local_build, ray_2cpu, tmp_path):
    from igraph_fight.evaluate.config import EvalConfig
    from igraph_fight.evaluate.runner import evaluate

    local_build[0].save(tmp_path / "g.igz")
    kw = dict(graph=str(tmp_path / "g.igz"), opponents=("random", "static"), depths=(1, 2), exact2_depths=(),
              bouts=2, seconds=3.0, seed=3, head_to_head=(), progress=False, regret_every=0)
    a = evaluate(EvalConfig(workers=1, **kw), tmp_path / "local")
    b = evaluate(EvalConfig(workers=2, backend="ray", **kw), tmp_path / "ray")
    assert a["results_digest"] == b["results_digest"] and a["table"] == b["table"]
    assert b["timing"]["backend"]["backend"] == "ray" and b["timing"]["backend"]["workers"] == 2


def test_shards_are_runs_of_whole_groups():
    import numpy as np
    starts = np.array([0, 5, 6, 20, 21, 40])
    for n in (1, 2, 3, 7):
        cuts = shard_cuts(starts, n)
        assert cuts[0] == 0 and cuts[-1] == 5 and all(a < b for a, b in zip(cuts, cuts[1:]))
        assert len(cuts) - 1 <= n


def test_without_ray_the_backend_says_how_to_install_it(monkeypatch, capsys, tmp_path):
    from igraph_fight.cli import main
    monkeypatch.setitem(sys.modules, "ray", None)  # import ray -> ImportError
    with pytest.raises(BackendUnavailable, match="pip install"):
        require_ray()
    rc = main(["build", "--mocap", str(tmp_path), "--out", str(tmp_path / "g.igz"), "--backend", "ray"])
    assert rc == 2 and RAY_INSTALL_HINT in capsys.readouterr().err
    with pytest.raises(ValueError, match="unknown backend"):
        from igraph_fight.build.backend import make_backend
        make_backend("spark", None)
