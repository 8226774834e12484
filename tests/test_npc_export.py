"""igraph-fight export: the reference reader (examples/npc_export_reader.py, numpy only) answers
what NPCController(offgraph="nearest", first_ply="table") answers, action and graph state, on
live states recorded in kinematic bouts on the small graph, for every exported style and depth."""
from __future__ import annotations

import importlib.util
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

from igraph_fight import FightGame, NPCController, Observation, observe
from igraph_fight.agents import IGAgent
from igraph_fight.agents.human import HumanProxyAgent
from igraph_fight.export import export_npc
from igraph_fight.game import GameConfig
from igraph_fight.match import run_bout

ROOT = Path(__file__).resolve().parent.parent
READER = ROOT / "examples" / "npc_export_reader.py"
STYLES = ("infighter", "outboxer", "balanced")
DEPTHS = (1, 3, 5)
#: live states the agreement test compares on (at least)
N_LIVE = 10_000


def _reader_module():
    spec = importlib.util.spec_from_file_location("npc_export_reader", READER)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


class Recorder:
    """An agent that records the observation of every decision it makes, then lets ``inner`` choose."""

    def __init__(self, inner, out: list) -> None:
        self.inner, self.out, self.name = inner, out, getattr(inner, "name", "agent")

    def reset(self, game, player, rng) -> None:
        self.inner.reset(game, player, rng)

    def step(self, state, player) -> int:
        self.out.append(observe(state, player))
        return self.inner.step(state, player)


@pytest.fixture(scope="module")
def export_file(small_graph, tmp_path_factory) -> Path:
    g, lib = small_graph
    path = tmp_path_factory.mktemp("export") / "npc.bin"
    export_npc(g, list(STYLES), list(DEPTHS), path, library=lib)
    return path


@pytest.fixture(scope="module")
def live_states(small_graph) -> list:
    """Decision states of kinematic bouts: IG fighters (snapping and not) against each other and
    against the human proxy, several seeds, until N_LIVE are recorded."""
    g, lib = small_graph
    ca = NPCController(g, lib, style="infighter", depth=3)
    cb = NPCController(g, lib, style="outboxer", depth=5)
    game = FightGame(lib, GameConfig(max_seconds=60.0, sim=g.sim_params()), tables=ca.tables)
    obs: list = []
    seed = 0
    try:
        while len(obs) < N_LIVE:
            snap = (False, "self")[seed % 2]
            pair = [IGAgent(ca, snap=snap), IGAgent(cb, snap=snap) if seed % 3 else HumanProxyAgent()]
            run_bout(game, [Recorder(p, obs) for p in pair], 60.0, np.random.default_rng(seed))
            seed += 1
    finally:
        ca.close()
        cb.close()
    return obs


def test_the_reader_imports_neither_numba_nor_igraph_fight():
    code = (f"import sys; sys.path.insert(0, {str(READER.parent)!r}); import npc_export_reader; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('numba', 'igraph_fight', 'planner', 'motion_graph')]; "
            "print(bad); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stdout + r.stderr


def test_reader_matches_the_controller_on_live_states(small_graph, export_file, live_states):
    g, lib = small_graph
    npc = _reader_module().NPCExport.load(str(export_file))
    assert len(live_states) >= N_LIVE
    ctrl = NPCController(g, lib, style=STYLES[0], depth=DEPTHS[0], offgraph="nearest", first_ply="table")
    levels: Counter = Counter()
    off = 0
    try:
        for st in STYLES:
            ctrl.set_style(st, wait=True)
            for d in DEPTHS:
                ctrl.set_depth(d, wait=True)
                for o in live_states:
                    want = ctrl.act(o)
                    got = npc.decide(st, d, *o)
                    assert got == (want.action, want.state, want.off_graph), (st, d, o, got, want)
                    if st == STYLES[0] and d == DEPTHS[0]:
                        levels[npc.locate(*o)[1]] += 1
                        off += bool(want.off_graph)
    finally:
        ctrl.close()
    print(f"{len(live_states)} live states x {len(STYLES) * len(DEPTHS)} tables agree; search levels {dict(levels)}, "
          f"{off} off the graph")
    # the bouts reach the graph's off-graph levels too (another frame, another opponent action or mask)
    assert levels[0] > 0 and levels[1] + levels[2] > 0 and off > 0, (levels, off)


def test_reader_matches_the_controller_at_every_search_level(small_graph, export_file):
    """Crafted observations for the levels bouts rarely reach: an unknown opponent action or mask
    (level 2), a Next-set no state has (level 3, with the fallback tables), any frame (level 1)."""
    g, lib = small_graph
    npc = _reader_module().NPCExport.load(str(export_file))
    rng = np.random.default_rng(5)
    A = lib.n_actions
    nf = np.diff(lib.frame_offsets)
    bits = np.diff(lib.strike_offsets)
    obs = []
    for _ in range(1500):
        m_self, m_other = int(rng.integers(A)), int(rng.integers(A))
        obs.append((float(rng.uniform(0.0, 5.0)), float(rng.uniform(-4, 4)), float(rng.uniform(-4, 4)), m_self,
                    m_other, int(rng.integers(nf[m_other])), int(rng.integers(1 << int(bits[m_other])))))
    absent = set(npc.index["nextsets_absent"])
    ns_of = npc.s["nextset_of"]
    ctrl = NPCController(g, lib, style="outboxer", depth=5, offgraph="nearest")
    try:
        for st in STYLES:
            ctrl.set_style(st, wait=True)
            levels = Counter()
            for o in obs:
                want = ctrl.act(Observation(*o))
                assert npc.decide(st, 5, *o) == (want.action, want.state, want.off_graph), (st, o)
                levels[npc.locate(*o)[1]] += 1
            print(f"{st}: {len(obs)} crafted states agree; search levels {dict(levels)}")
            assert levels[1] > 0 and levels[2] > 0, levels
            if absent and any(int(ns_of[o[3]]) in absent for o in obs):
                assert levels[3] > 0, levels
    finally:
        ctrl.close()


def test_a_corrupted_export_is_refused(export_file, tmp_path):
    mod = _reader_module()
    data = bytearray(export_file.read_bytes())
    data[-10] ^= 0xFF
    (tmp_path / "bad.bin").write_bytes(bytes(data))
    with pytest.raises(ValueError, match="corrupted"):
        mod.NPCExport.load(str(tmp_path / "bad.bin"))
    (tmp_path / "graph.bin").write_bytes(b"IGFGRAPH" + bytes(40))
    with pytest.raises(ValueError, match="not an igraph-fight NPC export"):
        mod.NPCExport.load(str(tmp_path / "graph.bin"))


def test_export_cli_writes_a_small_file(small_graph, tmp_path, capsys):
    from igraph_fight.cli import main

    g, _ = small_graph
    gpath = tmp_path / "g.igz"
    g.save(gpath)
    assert main(["export", "--graph", str(gpath), "--styles", "infighter,outboxer", "--depths", "1,3",
                 "--out", str(tmp_path / "npc.bin"), "--json"]) == 0
    import json
    info = json.loads(capsys.readouterr().out)
    assert info["tables"] == 4 and info["bytes"] == (tmp_path / "npc.bin").stat().st_size
    npc = _reader_module().NPCExport.load(str(tmp_path / "npc.bin"))
    assert sorted(npc.tables) == [("infighter", 1), ("infighter", 3), ("outboxer", 1), ("outboxer", 3)]
    assert main(["export", "--graph", str(gpath), "--styles", "nosuchstyle", "--out", str(tmp_path / "x.bin")]) == 2
