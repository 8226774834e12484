"""Sampler, clustering, edges, graph file and the build command on the real boxing library."""
from __future__ import annotations

import dataclasses
import inspect
import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from igraph_fight.build import cluster, explore
from igraph_fight import sim, state
from igraph_fight.build.pipeline import BuildOptions, build_graph
from igraph_fight.graph import GraphFormatError, InteractionGraph
from igraph_fight.sim import SimTables
from motion_graph.atomic import KILL_ENV
from motion_graph.errors import LibraryFormatError

ROOT = Path(__file__).resolve().parent.parent
SMALL = BuildOptions(max_samples=12_000, n_initial=32, chunk_parents=128, seed_bouts=0)


@pytest.fixture(scope="module")
def lib(boxing_library):
    return boxing_library


@pytest.fixture(scope="module")
def tables(lib) -> SimTables:
    return SimTables.from_library(lib)


@pytest.fixture(scope="module")
def built(lib):
    return build_graph(lib, SMALL, seed=0, workers=1)


# ---- sampler ------------------------------------------------------------------------------------
def test_sampler_is_deterministic_by_seed(tables):
    o = SMALL.explore_options()
    o = dataclasses.replace(o, max_samples=4000)
    a = explore.explore(tables, o, seed=5)
    b = explore.explore(tables, o, seed=5)
    c = explore.explore(tables, o, seed=6)
    for k in ("si", "sf", "parent", "action", "score_c", "score_j"):
        assert np.array_equal(getattr(a, k), getattr(b, k))
    assert len(a) == 4000 and a.stop_reason == "max_samples"
    assert not np.array_equal(a.sf, c.sf)
    # children really are the simulated results of their parents' actions
    kids = np.nonzero(a.parent >= 0)[0][:50]
    ci, cf, _, _ = sim.expand_samples(tables.kernel_tuple(), a.si, a.sf, a.parent[kids], a.action[kids])
    assert np.array_equal(ci, a.si[kids]) and np.array_equal(cf, a.sf[kids])


def test_initial_states_face_each_other_in_the_requested_share(tables):
    o = dataclasses.replace(SMALL, n_initial=200, initial_facing_share=0.75, initial_facing_deg=30.0).explore_options()
    si, sf = explore.initial_samples(tables, o, seed=3)
    ang = np.abs(sf[:, 1:])
    facing = np.all(ang <= math.radians(30.0) + 1e-12, axis=1)
    assert facing[:150].all()
    # the rest take any angle: most of them are not facing
    assert facing[150:].mean() < 0.3 and ang[150:].max() > math.radians(120.0)
    o0 = dataclasses.replace(SMALL, n_initial=200, initial_facing_share=0.0).explore_options()
    assert np.all(np.abs(explore.initial_samples(tables, o0, seed=3)[1][:, 1:]) <= math.pi)
    with pytest.raises(ValueError, match="initial_facing_share"):
        dataclasses.replace(SMALL, initial_facing_share=1.5).validate()


def test_bout_seed_states_are_reward_free_deterministic_canonical_samples(lib, tables):
    from igraph_fight.build.seeding import bout_seed_states
    si, sf = bout_seed_states(lib, tables, 2, 10.0, seed=5)
    si2, sf2 = bout_seed_states(lib, tables, 2, 10.0, seed=5)
    assert len(si) > 10 and np.array_equal(si, si2) and np.array_equal(sf, sf2)
    assert si.shape[1] == sim.N_SI and sf.shape[1] == sim.N_SF
    assert np.all((si[:, sim.SI_MSELF] >= 0) & (si[:, sim.SI_MSELF] < lib.n_actions))
    assert np.all(sf[:, sim.SF_R] >= 0) and np.all(np.abs(sf[:, 1:]) <= np.pi + 1e-9)
    # they become roots of the sampler: a tiny build with them archives more distinct groups
    o = dataclasses.replace(SMALL, max_samples=3000)
    a0 = explore.explore(tables, o.explore_options(), 0)
    a1 = explore.explore(tables, o.explore_options(), 0, extra_initial=(si, sf))
    assert int(np.sum(a1.parent < 0)) > int(np.sum(a0.parent < 0))
    # the pairing chooses the second fighter (a second human proxy by default, or a random one)
    sr, fr = bout_seed_states(lib, tables, 2, 10.0, seed=5, pairing="random")
    assert len(sr) > 10 and not (len(sr) == len(si) and np.array_equal(sr, si))
    with pytest.raises(ValueError, match="pairing"):
        bout_seed_states(lib, tables, 1, 1.0, seed=0, pairing="robot")
    with pytest.raises(ValueError, match="seed_pairing"):
        dataclasses.replace(BuildOptions(), seed_pairing="robot").validate()


def test_sampler_does_not_depend_on_any_reward(built):
    for fn in (explore.explore, build_graph):
        names = " ".join(inspect.signature(fn).parameters)
        assert "reward" not in names and "style" not in names
    assert not any("reward" in f.name or "style" in f.name for f in dataclasses.fields(BuildOptions))
    # one archive serves every style: two Eq. 4 rewards differ on the very same edges
    g, _ = built
    f = g.edge_features()
    infighter = -0.5 * f["theta_self"] ** 2 - 2.0 * (f["r"] - 0.7) ** 2 + f["dmg_given"] - f["dmg_received"]
    outboxer = -0.5 * f["theta_self"] ** 2 - 2.0 * (f["r"] - 1.6) ** 2 + f["dmg_given"] - f["dmg_received"]
    assert len(infighter) == g.n_edges and not np.allclose(infighter, outboxer)


# ---- clustering ---------------------------------------------------------------------------------
def test_clusters_never_merge_across_groups_and_respect_the_tolerance(tables):
    o = dataclasses.replace(SMALL.explore_options(), max_samples=8000)
    arc = explore.explore(tables, o, seed=0)
    G = explore.group_rows(tables.nextset, arc.si, o.f0)
    copt = cluster.ClusterOptions(tol_r_m=0.05, tol_theta_rad=math.radians(10))
    cl = cluster.cluster_samples(G, arc.si, arc.sf, copt)
    order = np.argsort(cl.labels, kind="stable")
    lab = cl.labels[order]
    same = lab[1:] == lab[:-1]
    assert np.all(G[order][1:][same] == G[order][:-1][same])
    assert cl.snap_r.max() <= copt.tol_r_m + 1e-12
    assert cl.snap_theta.max() <= copt.tol_theta_rad + 1e-12
    assert cl.snap_frames.max() < o.f0
    assert len(cl.si) < len(arc.si)  # some samples were merged
    # a coarser tolerance gives fewer states
    cl2 = cluster.cluster_samples(G, arc.si, arc.sf, cluster.ClusterOptions(tol_r_m=0.2, tol_theta_rad=math.radians(30)))
    assert len(cl2.si) < len(cl.si)
    rep = cl.report()
    assert 0 < rep["snap_mean_cm"] <= rep["snap_max_cm"] <= 5.0 + 1e-9


# ---- edges --------------------------------------------------------------------------------------
def test_every_edge_lands_within_tolerance(built, tables):
    g, rep = built
    o = SMALL
    assert g.n_edges > 0 and rep["n_edges"] == g.n_edges
    assert g.edge_snap_r.max() <= o.link_tol_r_m + 1e-12
    assert g.edge_snap_theta.max() <= o.link_tol_theta_rad + 1e-12
    # independent check through the state API: re-simulate edges from their source states
    rng = np.random.default_rng(0)
    src_of = np.repeat(np.arange(g.n_states), g.out_degree())
    for e in rng.choice(g.n_edges, 40, replace=False):
        s, t = src_of[e], g.edge_target[e]
        si = np.array([g.state_m_self[s], g.state_m_other[s], g.state_f_other[s], g.state_mask_other[s]])
        sf = np.array([g.state_r[s], g.state_theta_self[s], g.state_theta_other[s]])
        w = state.from_sample(tables, si, sf)
        w = state.start_action(tables, w, 0, int(g.edge_action[e]))
        w2, ev = state.advance(tables, w)
        decider = 1 if 1 in ev.deciders else 0
        assert decider == g.edge_swap[e]
        lsi, lsf = state.to_sample(tables, w2, decider)
        assert tables.nextset[lsi[0]] == g.state_nextset[t] and lsi[1] == g.state_m_other[t]
        assert abs(lsi[2] - g.state_f_other[t]) < o.f0 and lsi[3] == g.state_mask_other[t]
        assert abs(lsf[0] - g.state_r[t]) <= o.link_tol_r_m + 1e-9
        for k, name in ((1, "state_theta_self"), (2, "state_theta_other")):
            d = (lsf[k] - g.arrays[name][t] + np.pi) % (2 * np.pi) - np.pi
            assert abs(d) <= o.link_tol_theta_rad + 1e-9
        assert g.feat_duration[e] == pytest.approx(ev.frames / tables.fps)
        assert g.feat_dmg_given[e] == ev.damage[1] and g.feat_dmg_received[e] == ev.damage[0]
        assert g.feat_r[e] == pytest.approx(state.relative(w2, 0)[0])


def test_no_dead_ends_and_contract_arrays(built):
    g, rep = built
    assert rep["dead_end_fraction"] == 0.0 and rep["pruned_states"] > 0
    assert np.all(g.out_degree() > 0)
    a = g.arrays
    assert a["state_offsets"].dtype == np.int64 and a["edge_target"].dtype == np.int32
    assert a["edge_swap"].dtype == np.uint8 and a["edge_action"].dtype == np.int32
    assert a["feat_kind"].dtype == np.int32 and a["feat_other_kind"].dtype == np.int32
    for k in ("feat_duration", "feat_r", "feat_r_mean", "feat_theta_self", "feat_theta_other", "feat_dmg_given",
              "feat_dmg_received", "feat_def_self", "feat_def_other"):
        assert a[k].dtype == np.float64 and len(a[k]) == g.n_edges
    assert np.all((a["feat_theta_self"] >= -np.pi) & (a["feat_theta_self"] < np.pi))
    assert np.all(a["feat_duration"] >= 0) and a["edge_swap"].any()
    for key in ("n_states", "n_edges", "build_seconds", "peak_rss_mb", "dead_end_fraction", "snap_mean_cm",
                "snap_max_cm"):
        assert key in rep


# ---- graph file ---------------------------------------------------------------------------------
def test_file_round_trip_info_and_export(built, tmp_path):
    g, _ = built
    path = tmp_path / "g.igz"
    g.save(path)
    h = InteractionGraph.load(path)
    assert h.content_hash == g.content_hash
    for k, v in g.arrays.items():
        assert np.array_equal(v, h.arrays[k]), k
    info = h.info()
    assert info["n_states"] == g.n_states and info["n_edges"] == g.n_edges
    assert info["dead_end_fraction"] == 0.0 and sum(info["degree_histogram"].values()) == g.n_states
    assert info["library_fingerprint"] and info["seed"] == 0 and info["package_version"]
    assert info["options"]["max_samples"] == SMALL.max_samples
    # saving again (new timestamp) keeps the content hash
    g.header.pop("created", None)
    g.save(tmp_path / "g2.igz")
    assert InteractionGraph.load(tmp_path / "g2.igz").content_hash == g.content_hash
    from motion_graph.classify import KINDS
    d = h.as_dict()
    assert d["kinds_table"] == list(KINDS) and h["state_offsets"] is h.arrays["state_offsets"]
    nxg = h.to_networkx()
    assert nxg.number_of_nodes() == g.n_states and nxg.number_of_edges() == g.n_edges


def test_corrupted_or_foreign_files_give_clear_errors(built, tmp_path, lib):
    g, _ = built
    path = tmp_path / "g.igz"
    g.save(path)
    data = path.read_bytes()
    (tmp_path / "trunc.igz").write_bytes(data[: len(data) // 2])
    with pytest.raises(GraphFormatError, match="truncated or corrupted"):
        InteractionGraph.load(tmp_path / "trunc.igz")
    flipped = bytearray(data)
    i = len(flipped) // 2
    flipped[i] ^= 0xFF
    (tmp_path / "flip.igz").write_bytes(bytes(flipped))
    with pytest.raises(GraphFormatError, match="corrupted"):
        InteractionGraph.load(tmp_path / "flip.igz")
    lib.save(tmp_path / "lib.npz")
    with pytest.raises(GraphFormatError, match="not an igraph-fight graph file"):
        InteractionGraph.load(tmp_path / "lib.npz")
    with pytest.raises(LibraryFormatError, match="no such file"):
        InteractionGraph.load(tmp_path / "missing.igz")
    g.check_library(lib)


# ---- checkpoints and determinism ----------------------------------------------------------------
class _Stop(KeyboardInterrupt):
    pass


def test_resume_after_interruption_gives_the_same_graph(lib, built, tmp_path):
    ckpt = tmp_path / "ckpt"

    def stop(chunks: int, n: int) -> None:
        if chunks == 3:
            raise _Stop()

    with pytest.raises(_Stop):
        build_graph(lib, SMALL, seed=0, checkpoint_dir=ckpt, on_chunk=stop)
    header = explore.read_checkpoint_header(ckpt / "archive.npz")
    assert header["chunks"] == 3 and 0 < header["n"] < SMALL.max_samples
    # other options refuse the checkpoint
    with pytest.raises(ValueError, match="other inputs or options"):
        build_graph(lib, dataclasses.replace(SMALL, max_samples=16_000), seed=0, checkpoint_dir=ckpt)
    g, rep = build_graph(lib, SMALL, seed=0, checkpoint_dir=ckpt)
    assert rep["resumed_from_checkpoint"]
    assert g.content_hash == built[0].content_hash
    assert not ckpt.exists()


#: a small build for the kill tests (about 2 s a run) and, per IGRAPH_FIGHT_TEST_KILL_AT stage,
#: what the killed run leaves: the checkpoint's archive, the graph file, a temporary file
KILL_ARGS = ["--max-samples", "2000", "--n-initial", "16", "--seed-bouts", "0", "--quiet", "--json"]
KILL_STAGES = (("sample@2", True, False, False), ("cluster", True, False, False), ("link", True, False, False),
               ("write", True, False, True), ("written", True, True, False))


def test_a_kill_at_any_stage_then_the_same_command_gives_the_same_graph(lib, tmp_path):
    """`igraph-fight build` SIGKILLed (by the test hook) while sampling, clustering, linking,
    writing the file and after writing it: the same command then resumes from the checkpoint,
    gives the uninterrupted build's graph and leaves only the graph file."""
    lib_path = tmp_path / "lib.npz"
    lib.save(lib_path)
    want = build_graph(lib, dataclasses.replace(BuildOptions(), max_samples=2000, n_initial=16, seed_bouts=0),
                       seed=0)[0].content_hash
    env = {k: v for k, v in os.environ.items() if k != KILL_ENV}
    for stage, ckpt_left, out_left, tmp_left in KILL_STAGES:
        folder = tmp_path / stage.replace("@", "_")
        folder.mkdir()
        out = folder / "g.igz"
        cmd = [sys.executable, "-m", "igraph_fight", "build", "--library", str(lib_path), "--out", str(out), *KILL_ARGS]
        r = subprocess.run(cmd, env={**env, KILL_ENV: stage}, capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert r.returncode == -signal.SIGKILL, (stage, r.returncode, r.stderr[-2000:])
        temps = [p.name for p in folder.iterdir() if ".tmp-" in p.name]
        assert (folder / "g.igz.ckpt" / "archive.npz").exists() == ckpt_left, stage
        assert out.exists() == out_left and bool(temps) == tmp_left, (stage, temps)
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert r.returncode == 0, (stage, r.stderr[-2000:])
        rep = json.loads(r.stdout)
        assert rep["content_hash"] == want and rep["resumed_from_checkpoint"], stage
        assert [p.name for p in folder.iterdir()] == ["g.igz"], stage  # no checkpoint, no temporary file
        assert InteractionGraph.load(out).content_hash == want


def test_atomic_write_removes_only_stale_temp_files_of_dead_writers(tmp_path):
    from motion_graph.atomic import atomic_write, atomic_write_bytes, stale_temp_files

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    target = tmp_path / "f.bin"
    keep = {f".f.bin.tmp-{dead.pid}-0123abcd": False, f".f.bin.tmp-{os.getpid()}-0123abcd": True,
            f".g.bin.tmp-{dead.pid}-0123abcd": True, f".f.bin.tmp-{dead.pid}": True, "f.bin.tmp": True}
    for name in keep:
        (tmp_path / name).write_bytes(b"x")
    assert stale_temp_files(target) == [tmp_path / f".f.bin.tmp-{dead.pid}-0123abcd"]
    atomic_write_bytes(target, b"new")
    assert target.read_bytes() == b"new"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([n for n, k in keep.items() if k] + ["f.bin"])

    def fail(fh) -> None:
        fh.write(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(target, fail)
    assert target.read_bytes() == b"new"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([n for n, k in keep.items() if k] + ["f.bin"])


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one core")
def test_workers_do_not_change_the_graph(lib, built):
    g, _ = build_graph(lib, SMALL, seed=0, workers=2)
    assert g.content_hash == built[0].content_hash
    # seed bouts: one process, or shared by two forked ones
    seeded = dataclasses.replace(SMALL, max_samples=4000, seed_bouts=8, seed_bout_seconds=5.0)
    g1, r1 = build_graph(lib, seeded, seed=0, workers=1)
    g2, r2 = build_graph(lib, seeded, seed=0, workers=2)
    assert g1.content_hash == g2.content_hash and r1["n_samples"] == r2["n_samples"]


def test_cli_build_info_export(lib, tmp_path, capsys):
    from igraph_fight.cli import main

    lib.save(tmp_path / "lib.npz")
    out = tmp_path / "g.igz"
    args = ["build", "--library", str(tmp_path / "lib.npz"), "--out", str(out), "--max-samples", "3000",
            "--n-initial", "16", "--seed-bouts", "4", "--seed", "3", "--json"]
    assert main(args) == 0
    rep = json.loads(capsys.readouterr().out)
    for key in ("n_states", "n_edges", "build_seconds", "peak_rss_mb", "dead_end_fraction", "snap_mean_cm",
                "snap_max_cm", "content_hash"):
        assert key in rep
    assert not (tmp_path / "g.igz.ckpt").exists()
    assert main(["graph", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["content_hash"] == rep["content_hash"] and info["n_edges"] == rep["n_edges"]
    assert main(["graph", "export", str(out), "--out", str(tmp_path / "g.graphml")]) == 0
    assert (tmp_path / "g.graphml").stat().st_size > 0
    (tmp_path / "bad.igz").write_bytes(b"garbage")
    assert main(["graph", "info", str(tmp_path / "bad.igz")]) == 2
    assert "not an igraph-fight graph file" in capsys.readouterr().err
    (tmp_path / "cut.igz").write_bytes(out.read_bytes()[:5000])
    assert main(["graph", "info", str(tmp_path / "cut.igz")]) == 2
    assert "truncated or corrupted" in capsys.readouterr().err
    # a leftover checkpoint of another build is refused with a clear message, --restart discards it
    ck = tmp_path / "g.igz.ckpt"
    other = dataclasses.replace(BuildOptions(), max_samples=3000, n_initial=16, chunk_parents=64, seed_bouts=4)

    def interrupt(chunks: int, n: int) -> None:
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        build_graph(lib, other, seed=3, checkpoint_dir=ck, on_chunk=interrupt)
    build_graph_args = args[:-1] + ["--max-samples", "2000"]
    assert main(build_graph_args) == 2
    assert "--restart" in capsys.readouterr().err
    assert main(build_graph_args + ["--restart"]) == 0
    assert not ck.exists()


def test_cli_build_with_a_guard_records_it_for_every_user_of_the_graph(lib, tmp_path, capsys):
    from igraph_fight.cli import main
    from igraph_fight.controller import NPCController
    from igraph_fight.graph import load_graph

    lib.save(tmp_path / "lib.npz")
    base = ["build", "--library", str(tmp_path / "lib.npz"), "--max-samples", "2000", "--n-initial", "16",
            "--seed-bouts", "0", "--quiet"]
    assert main(base + ["--out", str(tmp_path / "g.igz"), "--guard", "0.05"]) == 0
    g = load_graph(tmp_path / "g.igz")
    assert g.sim_params().guard_radius_m == 0.05
    T = NPCController(g, lib, style="infighter", depth=1).tables.kernel_tuple()
    assert T[17] == pytest.approx((0.05 + 0.05) ** 2) and T[18] == 6      # 0.2 s lead at 30 fps
    assert main(base + ["--out", str(tmp_path / "h.igz"), "--guard", "-0.1"]) == 2
    assert "guard_radius_m" in capsys.readouterr().err


def test_cli_build_with_smaller_targets_records_them(lib, tmp_path, capsys):
    from igraph_fight.cli import main
    from igraph_fight.graph import load_graph

    lib.save(tmp_path / "lib.npz")
    base = ["build", "--library", str(tmp_path / "lib.npz"), "--max-samples", "2000", "--n-initial", "16",
            "--seed-bouts", "0", "--quiet"]
    assert main(base + ["--out", str(tmp_path / "g.igz"), "--target-radius", "0.05,0.1,0.1"]) == 0
    assert load_graph(tmp_path / "g.igz").sim_params().target_radius_m == {"head": 0.05, "chest": 0.1, "belly": 0.1}
    for bad in ("0.05,0.1", "0,0.1,0.1", "a,b,c"):
        assert main(base + ["--out", str(tmp_path / "h.igz"), "--target-radius", bad]) == 2
        assert "HEAD,CHEST,BELLY" in capsys.readouterr().err


@pytest.mark.parametrize("tr, tt", [(0.1, math.radians(20)), (0.025, math.radians(5))])
def test_spatial_index_agrees_with_brute_force(tr, tt):
    """Any grid answers exactly (the sampler's duplicate index is a finer grid than the linking one)."""
    from igraph_fight.build import spatial

    rng = np.random.default_rng(0)
    N, f0 = 4000, 3
    r1, a = (1.5, np.pi) if tr > 0.05 else (0.6, 0.4)  # the fine grid: points packed closer
    K = np.stack([rng.integers(0, 3, N), rng.integers(0, 3, N), rng.integers(0, 12, N), rng.integers(0, 2, N)], 1)
    F = np.stack([rng.uniform(0.3, r1, N), rng.uniform(-a, a, N), rng.uniform(-a, a, N)], 1)
    ix = spatial.new_index(N, tr, tt, f0)
    assert spatial.index_insert_many(ix, K, F) == N
    wrap = lambda a: (a + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    found = 0
    for q in range(300):
        k = np.array([rng.integers(0, 3), rng.integers(0, 3), rng.integers(0, 12), rng.integers(0, 2)])
        x = np.array([rng.uniform(0.3, r1), rng.uniform(-a, a), rng.uniform(-a, a)])
        ok = ((K[:, 0] == k[0]) & (K[:, 1] == k[1]) & (K[:, 3] == k[3]) & (np.abs(K[:, 2] - k[2]) < f0)
              & (np.abs(F[:, 0] - x[0]) <= tr) & (np.abs(wrap(F[:, 1] - x[1])) <= tt)
              & (np.abs(wrap(F[:, 2] - x[2])) <= tt))
        ids = np.empty(64, dtype=np.int64)
        d = np.empty(64)
        n = spatial.index_search(ix, k, x[0], x[1], x[2], tr, tt, True, ids, d)
        assert set(ids[:n].tolist()) == set(np.nonzero(ok)[0].tolist())
        assert np.all(np.diff(d[:n]) >= 0)
        first = spatial.index_search(ix, k, x[0], x[1], x[2], tr, tt, False, ids[:0], d[:0])
        assert (first >= 0) == ok.any() and (first < 0 or ok[first])
        found += n
    assert found > 20


def test_locate_maps_a_live_state_to_its_graph_state(built, tables):
    g, _ = built
    for s in (0, g.n_states // 2, g.n_states - 1):
        si = np.array([g.state_m_self[s], g.state_m_other[s], g.state_f_other[s], g.state_mask_other[s]])
        sf = np.array([g.state_r[s], g.state_theta_self[s], g.state_theta_other[s]])
        w = state.from_sample(tables, si, sf)
        t, d, within = g.locate(tables, w, 0)
        assert t == s and d < 1e-6 and within
        # moved by 3 cm: still that state, within tolerance
        w2 = dataclasses.replace(w, x=w.x + np.array([0.0, 0.03 * np.sin(sf[1])]),
                                 z=w.z + np.array([0.0, 0.03 * np.cos(sf[1])]))
        t2, d2, within2 = g.locate(tables, w2, 0)
        assert within2 and d2 > 0


def test_covers_is_the_existence_of_a_state_within_tolerance(built):
    """covers(): some compatible state within the linking tolerance (brute force over all states);
    nearest_state's flag tests only the nearest one, so it never says yes where covers says no."""
    g, _ = built
    a = g.arrays
    opts = g.header["options"]
    tr, tt, f0 = opts["link_tol_r_m"], opts["link_tol_theta_rad"], opts["f0"]
    wrap = lambda x: (x + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    rng = np.random.default_rng(4)
    agree = 0
    for _ in range(300):
        s = int(rng.integers(g.n_states))
        q = (int(a["state_nextset"][s]), int(a["state_m_other"][s]), int(a["state_f_other"][s]) + int(rng.integers(-3, 4)),
             int(a["state_mask_other"][s]), float(a["state_r"][s] + rng.normal(0, 0.15)),
             float(a["state_theta_self"][s] + rng.normal(0, 0.5)), float(a["state_theta_other"][s] + rng.normal(0, 0.5)))
        ok = ((a["state_nextset"] == q[0]) & (a["state_m_other"] == q[1]) & (np.abs(a["state_f_other"] - q[2]) < f0)
              & (a["state_mask_other"] == q[3]) & (np.abs(a["state_r"] - q[4]) <= tr)
              & (np.abs(wrap(a["state_theta_self"] - q[5])) <= tt) & (np.abs(wrap(a["state_theta_other"] - q[6])) <= tt))
        cov = g.covers(*q)
        assert cov == bool(ok.any())
        _, _, within = g.nearest_state(*q)
        assert not within or cov
        agree += int(within == cov)
    assert 0 < agree <= 300


def test_edge_columns_on_disk_give_the_same_graph(lib, built, tmp_path):
    """With a checkpoint folder the edges' columns are memory-mapped files under edges/ (filled
    block by block); the graph is the in-memory build's, array for array."""
    ckpt = tmp_path / "ckpt"
    g, _ = build_graph(lib, SMALL, seed=0, checkpoint_dir=ckpt, keep_checkpoint=True)
    files = sorted(p.name for p in (ckpt / "edges").iterdir())
    assert "feat_r" not in files and "r.f8" in files and "target.i8" in files and "swap.i1" in files
    E = g.n_edges
    assert (ckpt / "edges" / "r.f8").stat().st_size >= 8 * E > 0
    want = built[0].arrays
    for k in ("edge_target", "edge_action", "edge_swap", "feat_r", "feat_theta_self", "feat_dmg_given",
              "edge_snap_r", "state_offsets"):
        np.testing.assert_array_equal(g.arrays[k], want[k])
    assert g.content_hash == built[0].content_hash


def test_column_store_fills_in_place_and_hands_back_read_only(tmp_path):
    from igraph_fight.build.columns import ColumnStore
    for folder in (None, tmp_path / "cols"):
        st = ColumnStore(folder)
        a = st.new("x", 5, np.float64)
        b = st.new("n", 0, np.int64)
        a[:2], a[2:] = [1.0, 2.0], [3.0, 4.0, 5.0]
        with pytest.raises(ValueError, match="allocated twice"):
            st.new("x", 1, np.float64)
        out = st.finish()
        np.testing.assert_array_equal(out["x"], [1, 2, 3, 4, 5])
        assert len(out["n"]) == 0 and not out["x"].flags.writeable
        if folder is not None:
            assert isinstance(out["x"], np.memmap) and (folder / "x.f8").stat().st_size == 40
