"""The README's commands, pasted as written, work.

Every command line of the README's ```bash blocks (after the two install commands) is parsed by
the real igraph-fight parser (an unknown option or a stray ``[--flag]`` fails); the quick ones run
for real in a folder laid out like a checkout (``../shared/mocap`` beside it, ``graph.igz`` a
small real Interaction Graph), and so does the README's Python API block.
"""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: commands that run for real (the others are long: parsed only)
RUN = ("mocap inspect", "mocap segment", "graph info", "fight --graph", "policy")


def _blocks(lang: str) -> list[str]:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return re.findall(rf"```{lang}\n(.*?)```", text, flags=re.S)


def _commands() -> list[str]:
    out = []
    for block in _blocks("bash")[1:]:                 # the first block is the install (CI runs it)
        joined = re.sub(r"\\\n\s*", " ", block)
        for line in joined.splitlines():
            line = line.split(" #")[0].strip()
            if line and not line.startswith("#"):
                out.append(line)
    return out


def test_readme_has_commands():
    cmds = _commands()
    assert any(c.startswith("igraph-fight fight") for c in cmds) and len(cmds) >= 10, cmds


@pytest.mark.parametrize("cmd", [c for c in _commands() if c.startswith("igraph-fight ")])
def test_readme_command_parses(cmd):
    from igraph_fight.cli import build_parser
    argv = shlex.split(cmd)[1:]
    try:
        build_parser().parse_args(argv)
    except SystemExit as e:
        pytest.fail(f"`{cmd}` does not parse (exit {e.code})")


@pytest.fixture(scope="module")
def checkout(tmp_path_factory, small_graph, mocap_root):
    """A folder laid out like a checkout: repo/ (planner, examples, graph.igz) beside shared/mocap."""
    base = tmp_path_factory.mktemp("readme")
    (base / "shared").mkdir()
    os.symlink(mocap_root, base / "shared" / "mocap")
    repo = base / "repo"
    repo.mkdir()
    for d in ("planner", "examples"):
        os.symlink(ROOT / d, repo / d)
    graph, _ = small_graph
    graph.save(repo / "graph.igz")
    return repo


def _run(cmd: str, cwd: Path, timeout: float = 240.0) -> subprocess.CompletedProcess:
    argv = shlex.split(cmd)
    if argv[0] == "igraph-fight":
        argv = [sys.executable, "-m", "igraph_fight", *argv[1:]]
    elif argv[0] == "python":
        argv = [sys.executable, *argv[1:]]
    env = dict(os.environ, IGRAPH_FIGHT_VIDEO="0", MPLBACKEND="Agg")
    return subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)


@pytest.mark.realdata
@pytest.mark.slow
def test_readme_quick_commands_run(checkout):
    ran = []
    for cmd in _commands():
        if cmd.startswith("igraph-fight ") and cmd[len("igraph-fight "):].startswith(RUN):
            r = _run(cmd, checkout)
            assert r.returncode == 0, f"`{cmd}` failed (rc {r.returncode}):\n{r.stderr[-2000:]}"
            ran.append(cmd)
    assert len(ran) >= 5, ran


@pytest.mark.realdata
def test_readme_examples_answer_help(checkout):
    for cmd in _commands():
        if cmd.startswith("python "):
            script = shlex.split(cmd)[1]
            r = _run(f"python {script} --help", checkout, timeout=60)
            assert r.returncode == 0, f"`{script} --help` failed:\n{r.stderr[-2000:]}"


@pytest.mark.realdata
def test_readme_python_api_runs(checkout):
    blocks = _blocks("python")
    assert blocks, "the README has no Python block"
    for code in blocks:
        r = subprocess.run([sys.executable, "-c", code], cwd=checkout, capture_output=True, text=True, timeout=240)
        assert r.returncode == 0, f"the README's Python block failed:\n{r.stderr[-2000:]}"
