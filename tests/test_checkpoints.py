"""Checkpoint files (igraph_fight.checkpoint): read weights-only, versioned, written atomically; no
loader runs code from a file."""
from __future__ import annotations

import pathlib
from pathlib import Path

import numpy as np
import pytest
import torch

from igraph_fight.checkpoint import CheckpointError, convert, load_checkpoint, plain, save_checkpoint

ROOT = Path(__file__).resolve().parent.parent


class Marker:
    """Unpickling this writes ``path``: what a crafted checkpoint does to run code on load."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)

    def __reduce__(self):
        return pathlib.Path.write_text, (self.path, "code ran")


def _evil(tmp_path: Path, name: str, fields: dict) -> tuple[Path, Path]:
    """A checkpoint with the right format entries whose unpickling would write a marker file."""
    marker = tmp_path / f"{name}.marker"
    path = tmp_path / f"{name}.pt"
    torch.save({**fields, "payload": Marker(marker)}, path)
    assert not marker.exists()
    return path, marker


def _loaders(tiny_graph_file, boxing_library):
    """Every product and research route that reads a checkpoint file: (name, format fields,
    function of the path)."""
    from igraph_fight.agents.rl import RL_FORMAT, RL_VERSION, RLAgent
    from igraph_fight.agents.rl import load_checkpoint as load_rl
    from igraph_fight.game import FightGame, GameConfig
    from igraph_fight.graph import load_graph
    from igraph_fight.learn.train_rl import RLConfig
    from igraph_fight.learn.train_rl import train as train_rl
    from tracker.bouts.hit_model import HIT_MODEL_FORMAT, HIT_MODEL_VERSION, load_hit_model
    from tracker.bouts.loaders import load_tracker
    from tracker.bouts.rl_agent import RL_CKPT_FORMAT, RL_CKPT_VERSION, load_rl_agent, load_rl_checkpoint
    from tracker.learn.train_physics_rl import train as train_physics_rl
    from tracker.learn.train_tracker import TrainConfig
    from tracker.learn.train_tracker import train as train_tracker
    from tracker.track.policy_net import POLICY_FORMAT, POLICY_VERSION, load_policy
    from tracker.track.policy_net import load_checkpoint as load_policy_ck
    from tracker.learn.train_assisted import AssistedTrainConfig
    from tracker.learn.train_assisted import train as train_assisted
    from tracker.track.assisted_policy import FORMAT as ASSISTED_FORMAT
    from tracker.track.assisted_policy import VERSION as ASSISTED_VERSION
    from tracker.track.assisted_policy import load_assisted

    g = load_graph(tiny_graph_file)
    game = FightGame(g.load_library(), GameConfig(sim=g.sim_params()))
    rl = {"format": RL_FORMAT, "version": RL_VERSION}
    pol = {"format": POLICY_FORMAT, "version": POLICY_VERSION}
    prl = {"format": RL_CKPT_FORMAT, "version": RL_CKPT_VERSION}
    hm = {"format": HIT_MODEL_FORMAT, "version": HIT_MODEL_VERSION}
    asd = {"format": ASSISTED_FORMAT, "version": ASSISTED_VERSION}
    return [
        ("load_assisted (--tracker assisted:CKPT)", asd, load_assisted),
        ("tracker train-assisted --resume", asd, lambda p: train_assisted(
            str(p.with_suffix(".out.pt")), 0.01, AssistedTrainConfig(n_envs=1, pool_walks=1, walk_actions=2),
            resume=str(p), progress=False, log=None, max_iterations=0)),
        ("kinematic rl load_checkpoint", rl, load_rl),
        ("RLAgent", rl, lambda p: RLAgent(p)),
        ("train-rl --init-from", rl, lambda p: train_rl(game, RLConfig(total_decisions=1, init_from=str(p)),
                                                        progress=False)),
        ("tracking policy load_checkpoint", pol, load_policy_ck),
        ("load_policy", pol, load_policy),
        ("load_tracker (--tracker CKPT)", pol, load_tracker),
        ("tracker train --resume", pol, lambda p: train_tracker(TrainConfig(n_workers=1, envs_per_worker=1), None, 0.01,
                                                                str(p.with_suffix(".out.pt")), resume=str(p),
                                                                progress=False, log=lambda *a: None)),
        ("research layer head", pol, _research_head_loader()),
        ("physics rl load_rl_checkpoint", prl, load_rl_checkpoint),
        ("load_rl_agent (rl:CKPT)", prl, lambda p: load_rl_agent(p, boxing_library)),
        ("tracker rl train --resume", prl, lambda p: train_physics_rl(str(tiny_graph_file), "pd",
                                                                      str(p.with_suffix(".out.pt")), 0.01,
                                                                      resume=str(p), log=lambda s: None)),
        ("load_hit_model (--hit-model, +phys:MODEL)", hm, load_hit_model),
        ("generic load_checkpoint", rl, lambda p: load_checkpoint(p, RL_FORMAT, (RL_VERSION,))),
        ("convert (legacy reader)", rl, lambda p: convert(p, p.with_suffix(".converted.pt"))),
    ]


def _research_head_loader():
    from research.layer_head import load_head_policy
    return load_head_policy


@pytest.mark.realdata
def test_a_checkpoint_that_would_run_code_is_refused_by_every_loader(tmp_path, tiny_graph_file, boxing_library):
    """A .pt whose unpickling writes a marker file (a __reduce__ payload, the right format
    entries): every loader raises CheckpointError naming the file, and the marker never appears."""
    loaders = _loaders(tiny_graph_file, boxing_library)
    for i, (name, fields, load) in enumerate(loaders):
        path, marker = _evil(tmp_path, f"evil{i}", fields)
        with pytest.raises(CheckpointError) as e:
            load(path)
        msg = str(e.value)
        assert str(path) in msg and "\n" not in msg and "refused unread" in msg, (name, msg)
        assert not marker.exists(), f"{name}: the checkpoint ran code"
    # the command line answers one line, exit code 2
    from igraph_fight.cli import main
    path, marker = _evil(tmp_path, "cli", {"format": "igraph-fight/tracker-policy", "version": 2})
    assert main(["tracker", "eval", "--controller", "learned", "--ckpt", str(path), "--walks", "1"]) == 2
    assert not marker.exists()


def test_format_and_version_are_checked_with_one_line_errors(tmp_path):
    p = tmp_path / "a.pt"
    save_checkpoint(p, {"w": torch.ones(2)}, "igraph-fight/example", 3)
    ck = load_checkpoint(p, "igraph-fight/example", (3,))
    assert ck["format"] == "igraph-fight/example" and ck["version"] == 3 and torch.equal(ck["w"], torch.ones(2))
    cases = [(lambda: load_checkpoint(p, "igraph-fight/other", (3,), what="other thing"),
              "not a other thing checkpoint (format 'igraph-fight/example')"),
             (lambda: load_checkpoint(p, "igraph-fight/example", (1, 2)), "version 3, this version reads 1, 2"),
             (lambda: load_checkpoint(tmp_path / "missing.pt", "x", (1,)), "no such file")]
    torch.save({"w": torch.ones(2)}, tmp_path / "noformat.pt")
    cases.append((lambda: load_checkpoint(tmp_path / "noformat.pt", "x", (1,)), "no format entry"))
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    cases.append((lambda: load_checkpoint(tmp_path / "junk.pt", "x", (1,)), "not a loadable checkpoint"))
    torch.save([1, 2], tmp_path / "list.pt")
    cases.append((lambda: load_checkpoint(tmp_path / "list.pt", "x", (1,)), "not a dict"))
    for fn, text in cases:
        with pytest.raises(CheckpointError) as e:
            fn()
        assert text in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_numpy_content_is_stored_as_tensors_and_objects_are_refused(tmp_path):
    """save_checkpoint keeps values exactly (numpy arrays as tensors of their dtype, numpy scalars
    as numbers, tuples and state-dict order kept), refuses what weights-only loading cannot build,
    and replaces the file atomically (no temporary file left)."""
    from collections import OrderedDict
    sd = torch.nn.Linear(3, 2).state_dict()
    payload = {"mean": np.linspace(0, 1, 5), "std": np.arange(3, dtype=np.float32), "n": np.int64(7),
               "x": np.float64(0.1), "cfg": {"hidden": (64, 32), "gains": [1.5, np.float32(2.0)]}, "sd": sd,
               "version_str": torch.__version__}
    p = tmp_path / "c.pt"
    save_checkpoint(p, payload, "f", 1)
    save_checkpoint(p, payload, "f", 1)          # over an existing file
    assert sorted(x.name for x in tmp_path.iterdir()) == ["c.pt"]
    ck = load_checkpoint(p, "f", (1,))
    assert ck["mean"].dtype == torch.float64 and np.array_equal(np.asarray(ck["mean"]), payload["mean"])
    assert ck["std"].dtype == torch.float32 and type(ck["n"]) is int and ck["n"] == 7 and ck["x"] == 0.1
    assert ck["cfg"]["hidden"] == (64, 32) and ck["cfg"]["gains"] == [1.5, 2.0]
    assert isinstance(ck["sd"], OrderedDict) and list(ck["sd"]) == list(sd)
    assert type(ck["version_str"]) is str
    for bad in (object(), np.array(["a"]), np.array([None], dtype=object), {1j: 2}, lambda: 0):
        with pytest.raises(TypeError):
            plain({"k": bad})
    assert plain(payload["cfg"]["hidden"]) is payload["cfg"]["hidden"]   # nothing to convert: the same object


def test_convert_rewrites_a_legacy_file_without_running_code(tmp_path):
    """A pre-format pickle (numpy arrays, a torch version object) is refused by the loader with a
    pointer to ``convert``; convert keeps its values and records the format; a legacy file that
    would run code is refused by convert too."""
    old = tmp_path / "old.pt"
    torch.save({"obs_mean": np.arange(4.0), "torch_version": torch.__version__, "w": torch.ones(3)}, old)
    with pytest.raises(CheckpointError, match="numpy"):
        load_checkpoint(old, "igraph-fight/tracker-policy", (2,))
    new = tmp_path / "new.pt"
    from igraph_fight.checkpoint import main
    assert main(["convert", str(old), str(new), "--format", "igraph-fight/tracker-policy", "--version", "2"]) == 0
    ck = load_checkpoint(new, "igraph-fight/tracker-policy", (2,))
    assert np.array_equal(np.asarray(ck["obs_mean"]), np.arange(4.0)) and ck["torch_version"] == str(torch.__version__)
    assert main(["convert", str(old), str(tmp_path / "x.pt")]) == 2            # no format given, none in the file
    path, marker = _evil(tmp_path, "legacy_evil", {"obs_mean": np.arange(2.0)})
    with pytest.raises(CheckpointError):
        convert(path, tmp_path / "y.pt", "f", 1)
    assert not marker.exists()


def test_shipped_checkpoints_load_weights_only_with_their_formats():
    from igraph_fight.agents.rl import RL_FORMAT, RL_VERSION
    expected = {"igraph_fight/checkpoints/rl_infighter.pt": (RL_FORMAT, RL_VERSION),
                "igraph_fight/checkpoints/rl_outboxer.pt": (RL_FORMAT, RL_VERSION),
                "tracker/checkpoints/boxing_cmu13.pt": ("igraph-fight/tracker-policy", 2),
                "tracker/checkpoints/physics_rl_cmu13.pt": ("igraph-fight/physics-rl", 1),
                "tracker/checkpoints/hit_model_cmu13.pt": ("igraph-fight/hit-model", 1),
                "tracker/checkpoints/assisted_cmu13.pt": ("igraph-fight/assisted-tracker", 1)}
    found = sorted(str(p.relative_to(ROOT)) for d in ("igraph_fight/checkpoints", "tracker/checkpoints")
                   for p in (ROOT / d).glob("*.pt"))
    assert found == sorted(expected)
    for rel, (fmt, ver) in expected.items():
        ck = torch.load(ROOT / rel, map_location="cpu", weights_only=True)
        assert (ck["format"], ck["version"]) == (fmt, ver), rel


def test_no_source_file_loads_pickles_with_code():
    """No file of the repository (product, research, tests, benchmarks) calls torch.load with
    weights_only off."""
    needle = "weights_only=" + "False"
    bad = [str(p.relative_to(ROOT)) for d in ("igraph_fight", "tracker", "planner", "motion_graph", "research", "tests",
                                             "benchmarks", "examples") if (ROOT / d).is_dir()
           for p in (ROOT / d).rglob("*.py") if needle in p.read_text(encoding="utf-8", errors="replace")]
    assert not bad, f"{needle} in: {', '.join(bad)}"
