"""The layout's rules, checked on the source: no import cycles, no private name imported across
files, the kinematic package free of the tracker, product code free of research/, benchmarks
without sys.path edits, and a README a newcomer reads in two minutes."""
from __future__ import annotations

import ast
import os
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("motion_graph", "planner", "igraph_fight", "tracker")
#: folders whose files must not import private names from other files
ALL_CODE = PACKAGES + ("research", "tests", "benchmarks", "examples")


def _files(folders) -> list[Path]:
    out = []
    for top in folders:
        base = ROOT / top
        if base.is_dir():
            out += sorted(p for p in base.rglob("*.py") if "__pycache__" not in p.parts)
    return out


def _module(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path, known: set[str]):
    """(target module, imported name or None) for every import in ``path`` (any nesting level)."""
    mod = _module(path)
    is_pkg = path.name == "__init__.py"
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name, None
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                parts = (mod if is_pkg else mod.rpartition(".")[0]).split(".")
                if node.level > 1:
                    parts = parts[: len(parts) - node.level + 1]
                base = ".".join(parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for a in node.names:
                sub = f"{base}.{a.name}"
                yield (sub, None) if sub in known else (base, a.name)


def _owner(target: str, known: set[str]) -> str | None:
    while target and target not in known:
        target = target.rpartition(".")[0]
    return target or None


def test_no_import_cycles():
    files = _files(PACKAGES)
    known = {_module(p) for p in files}
    graph = defaultdict(set)
    for p in files:
        src = _module(p)
        for tgt, _ in _imports(p, known):
            dst = _owner(tgt, known)
            if dst and dst != src:
                graph[src].add(dst)
    # Tarjan's strongly connected components, iteratively
    index, low, on, stack, sccs = {}, {}, set(), [], []
    counter = [0]
    for root in sorted(known):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    x = stack.pop()
                    on.discard(x)
                    comp.append(x)
                    if x == v:
                        break
                if len(comp) > 1:
                    sccs.append(sorted(comp))
    assert not sccs, "import cycles (module-level and function-level imports): " + "; ".join(
        " <-> ".join(c) for c in sccs)


def test_no_private_name_imported_across_files():
    files = _files(ALL_CODE)
    known = {_module(p) for p in files}
    bad = []
    for p in files:
        for tgt, name in _imports(p, known):
            if name and name.startswith("_") and not name.startswith("__"):
                bad.append(f"{p.relative_to(ROOT)}: {name} from {tgt}")
    assert not bad, "private names imported from another file:\n" + "\n".join(bad)


def test_product_packages_do_not_import_research():
    bad = []
    for p in _files(PACKAGES):
        for tgt, _ in _imports(p, set()):
            if tgt == "research" or tgt.startswith("research."):
                bad.append(str(p.relative_to(ROOT)))
    assert not bad, "product code imports research/: " + ", ".join(sorted(set(bad)))


def test_kinematic_packages_do_not_import_the_tracker():
    bad = []
    for p in _files(("motion_graph", "planner", "igraph_fight")):
        for tgt, _ in _imports(p, set()):
            if tgt == "tracker" or tgt.startswith("tracker."):
                bad.append(str(p.relative_to(ROOT)))
    assert not bad, "kinematic code imports tracker: " + ", ".join(sorted(set(bad)))
    code = ("import sys, igraph_fight, igraph_fight.cli; "
            "bad = sorted(m for m in sys.modules if m == 'tracker' or m.startswith('tracker.')); "
            "print(','.join(bad)); sys.exit(1 if bad else 0)")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, f"importing igraph_fight.cli loaded {r.stdout.strip()} {r.stderr[-500:]}"


def test_benchmarks_do_not_edit_sys_path():
    bad = [str(p.relative_to(ROOT)) for p in _files(("benchmarks",)) if "sys.path" in p.read_text(encoding="utf-8")]
    assert not bad, "benchmarks edit sys.path (run them from an install): " + ", ".join(bad)


def test_file_names_say_what_they_are():
    """A file name that two packages share must not mean two things (e.g. graph.py: the action graph
    in motion_graph, the Interaction Graph in igraph_fight)."""
    names = defaultdict(set)
    for p in _files(PACKAGES):
        if p.name not in ("__init__.py", "__main__.py", "cli.py"):
            names[p.name].add(p.relative_to(ROOT).parts[0])
    shared = {n: sorted(pk) for n, pk in names.items() if len(pk) > 1}
    assert not shared, f"file names used by several packages: {shared}"


def test_readme_is_short():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    lines = text.splitlines()
    assert len(lines) <= 220, f"README.md has {len(lines)} lines (at most 220)"
    longest = max(len(line) for line in lines)
    assert longest <= 200, f"README.md has a line of {longest} characters (at most 200)"
    import re
    hist = [line for line in lines if re.search(r"\b(session [0-9]+|[a-z]+(th|st|nd|rd) session)\b", line, re.I)]
    assert not hist, "README.md speaks of sessions (history lives in git): " + hist[0][:100]


def test_no_code_speaks_of_sessions():
    import re
    pat = re.compile(r"\b(session [0-9]+|[a-z]+(th|st|nd|rd) session)\b", re.I)
    bad = [f"{p.relative_to(ROOT)}:{i + 1}" for p in _files(PACKAGES + ("tests", "benchmarks", "examples"))
           for i, line in enumerate(p.read_text(encoding="utf-8").splitlines()) if pat.search(line)]
    assert not bad, "code speaks of sessions (history lives in git): " + ", ".join(bad[:10])


if __name__ == "__main__":  # pragma: no cover - a quick report while restructuring
    os.chdir(ROOT)
    for name, fn in sorted(globals().items()):
        if name.startswith("test_"):
            try:
                fn()
                print("ok  ", name)
            except AssertionError as e:
                print("FAIL", name, "\n   ", str(e)[:3000])


def test_architecture_drawing_names_real_modules():
    """docs/architecture.md's drawing is kept true: every module it names exists (a bare name
    after a path lives in that path's folder)."""
    import re
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    drawing = re.findall(r"```\n(.*?)```", text, flags=re.S)
    assert drawing, "docs/architecture.md has no drawing"
    missing, named = [], 0
    for line in drawing[0].splitlines():
        folder = None
        for tok in re.findall(r"[\w/]+\.py|[\w]+/(?:[\w]+/)*", line):
            if "/" in tok.rstrip("/"):
                path = ROOT / tok
                folder = path.parent if tok.endswith(".py") else path
            elif tok.endswith("/"):
                path = ROOT / tok
                folder = path
            elif folder is not None:
                path = folder / tok
            else:
                continue
            named += 1
            if not path.exists():
                missing.append(str(path.relative_to(ROOT)))
    assert named >= 40, f"the drawing names only {named} modules"
    assert not missing, "docs/architecture.md names modules that do not exist: " + ", ".join(missing)
