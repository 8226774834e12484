"""Mocap loaders against malformed input: mutations of the real shared files fed to load_motion.

Usage:
    python benchmarks/bench_mocap_fuzz.py                       # 5000 mutations, seed 0
    python benchmarks/bench_mocap_fuzz.py --mutations 20000 --seed 3 --json
    python benchmarks/bench_mocap_fuzz.py --save-failures out/fuzz   # keep the files of bad outcomes

Each case starts from a real file under the mocap root (a BVH, or an AMC with its ASF; whole, or cut
to its first frames, which is still a valid file) and applies one to three mutations: truncation,
byte flips, deleted / duplicated / swapped lines, numbers replaced by special ones (nan, inf,
1e-320, huge integers, superscript and full-width digits, '1_0', ...), huge frame and channel
counts, deep or cyclic hierarchies, a BOM, CRLF or CR line ends, missing values, bad axis orders.
Every load runs in a forked child process limited to 2 GiB of address space (RLIMIT_AS) and killed
after 10 s. Outcomes:

- ``valid``: a Motion with at least one frame, finite fps > 0, finite rotations, root positions,
  local translations, offsets and forward-kinematics positions;
- ``mocap_format_error``: MocapFormatError (its message is also checked: one line, names the file);
- ``other_exception``: any other exception (the loaders' contract is broken);
- ``invalid_load``: a Motion that fails the checks of ``valid``;
- ``limit``: killed at 10 s, or out of memory under the 2 GiB limit.

Prints the counts, the largest peak RSS (VmHWM of the load's process, which starts with about
90 MB of imported libraries) and the slowest load. Asserts nothing.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import re
import resource
import select
import shutil
import signal
import tempfile
import time
from collections import Counter
from pathlib import Path

#: Address-space limit of each load's process, bytes.
MEMORY_LIMIT = 2 * 1024**3
#: Wall-clock limit of each load, seconds.
TIME_LIMIT_S = 10.0
#: Longest MocapFormatError problem text accepted as short (quotes of file text are cut at 80 characters).
MAX_PROBLEM_CHARS = 400

#: Replacements for a number: non-finite, tiny, huge, non-ASCII digits, and other non-numbers.
SPECIAL_NUMBERS = (
    "nan", "NaN", "-nan", "inf", "-inf", "Infinity", "infinity", "1e-320", "-1e-320", "5e-324", "0", "-0", "0.0",
    "1e308", "1e309", "-1e999", "1.7976931348623157e308", "1e6", "1e7", "1e8", "1e100", "-1", "300000000",
    "99999999999999999999", "9" * 4301, "1" + "0" * 5000, "0" * 5000 + "1", "\u00b2", "1\u00b2", "\u00b3\u2074",
    "\uff11\uff12", "\u0663", "\u0b67", "1_0", "0x1A", "1e", ".", "+", "-", "", "1.2.3", "1e5e5", "--1", "\x00",
)
#: Replacements for an ASF axis order.
BAD_AXIS_ORDERS = ("XXZ", "XY", "XYZW", "ABC", "xyz", "ZYX", "YZX", "", "X Y Z", "XYZXYZ")
_NUMBER = re.compile(rb"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")
_BOM = b"\xef\xbb\xbf"


# ----------------------------------------------------------------------------- sources


def source_cases(root: Path) -> list[dict[str, Path]]:
    """Every real BVH ({"x.bvh": path}) and every AMC with its ASF ({"x.amc": .., "y.asf": ..})."""
    out: list[dict[str, Path]] = []
    for f in sorted(root.rglob("*")):
        if f.suffix.lower() == ".bvh":
            out.append({f.name: f})
        elif f.suffix.lower() == ".amc":
            asf = f.with_name(f.stem.split("_")[0] + ".asf")
            if asf.exists():
                out.append({f.name: f, asf.name: asf})
    return out


def _cut_bvh(data: bytes, frames: int) -> bytes:
    """The hierarchy and the first `frames` frames of a BVH, its Frames: line rewritten."""
    lines = data.splitlines(keepends=True)
    m = next(i for i, l in enumerate(lines) if l.strip() == b"MOTION")
    f = next(i for i in range(m + 1, len(lines)) if lines[i].strip().startswith(b"Frames:"))
    eol = b"\r\n" if lines[f].endswith(b"\r\n") else b"\n"
    t = next(i for i in range(m + 1, len(lines)) if lines[i].strip().startswith(b"Frame Time:"))
    return b"".join(lines[:f] + [b"Frames: %d" % frames + eol] + lines[f + 1:t + 1] + lines[t + 1:t + 1 + frames])


def _cut_amc(data: bytes, frames: int) -> bytes:
    """The header and the first `frames` frames of an AMC."""
    lines = data.splitlines(keepends=True)
    stop = next((i for i, l in enumerate(lines) if l.strip() == str(frames + 1).encode()), len(lines))
    return b"".join(lines[:stop])


def base_case(source: dict[str, Path], rng: random.Random) -> dict[str, bytes]:
    """The files of a valid case: the source whole (one time in ten) or cut to 1-300 frames."""
    files = {name: p.read_bytes() for name, p in source.items()}
    if rng.randrange(10) == 9:  # (not 0: Hypothesis's randoms favour 0, and whole files load slowly)
        return files
    frames = rng.choice((1, 2, 3, rng.randint(4, 60), rng.randint(4, 300)))
    for name in files:
        if name.endswith(".bvh"):
            files[name] = _cut_bvh(files[name], frames)
        elif name.endswith(".amc"):
            files[name] = _cut_amc(files[name], frames)
    return files


# ----------------------------------------------------------------------------- mutations
# Each takes the bytes of one file and a Random, and returns the mutated bytes.


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True)


#: Lines that declare structure, counts or units (BVH, ASF, AMC frame numbers).
_KEY_LINE = re.compile(rb"[ \t]*(?:ROOT|JOINT|End|OFFSET|CHANNELS|MOTION|Frames:|Frame Time:|begin|end|name|length|"
                       rb"direction|axis|dof|limits|order|position|orientation|mass|angle|:|root|[0-9]+[ \t]*\r?$)")


def structure_lines(lines: list[bytes]) -> list[int]:
    """Indices of the lines (among the first 5000) that declare structure, counts or units."""
    return [i for i, line in enumerate(lines[:5000]) if _KEY_LINE.match(line)]


def _pick_line(lines: list[bytes], rng: random.Random) -> int:
    """A line index: a structure line (keyword, count, unit) two times in five, one of the first
    200 lines one time in five, else any line."""
    if not lines:
        return 0
    u = rng.random()
    if u < 0.4:
        keyed = structure_lines(lines)
        if keyed:
            return rng.choice(keyed)
    return rng.randrange(min(len(lines), 200)) if u < 0.6 else rng.randrange(len(lines))


def replace_number(line: bytes, k: int, new: str) -> bytes:
    """The line with its k-th number (counted modulo how many it has) replaced by new; unchanged
    when it has none."""
    nums = list(_NUMBER.finditer(line))
    if not nums:
        return line
    m = nums[k % len(nums)]
    return line[:m.start()] + new.encode() + line[m.end():]


def truncate(data: bytes, rng: random.Random) -> bytes:
    return data[:rng.randrange(len(data) + 1)]


def flip_bytes(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    for _ in range(rng.randint(1, 8)):
        if b:
            i = rng.randrange(min(len(b), 8000)) if rng.random() < 0.6 else rng.randrange(len(b))
            b[i] = rng.choice((rng.randrange(256), *b"\n\r\t {}-.e0:\x00\xff"))
    return bytes(b)


def delete_line(data: bytes, rng: random.Random) -> bytes:
    lines = _lines(data)
    if lines:
        del lines[_pick_line(lines, rng)]
    return b"".join(lines)


def duplicate_line(data: bytes, rng: random.Random) -> bytes:
    lines = _lines(data)
    if lines:
        i = _pick_line(lines, rng)
        lines[i:i] = [lines[i]] * rng.choice((1, 1, 2, 1000))
    return b"".join(lines)


def swap_lines(data: bytes, rng: random.Random) -> bytes:
    lines = _lines(data)
    if len(lines) > 1:
        i, j = _pick_line(lines, rng), _pick_line(lines, rng)
        lines[i], lines[j] = lines[j], lines[i]
    return b"".join(lines)


def special_number(data: bytes, rng: random.Random) -> bytes:
    """One number of a line replaced by a special one (on a header line more often than not)."""
    lines = _lines(data)
    for _ in range(20):
        i = _pick_line(lines, rng)
        if lines and _NUMBER.search(lines[i]):
            lines[i] = replace_number(lines[i], rng.randrange(64), rng.choice(SPECIAL_NUMBERS))
            break
    return b"".join(lines)


def huge_count(data: bytes, rng: random.Random) -> bytes:
    """The BVH Frames: or a CHANNELS count, or an AMC frame number, made huge, zero or off by one."""
    value = rng.choice((b"300000000", b"1000001", b"10000000000000000000000", b"0", b"-5", b"7", b"1" + b"0" * 4400))
    pats = [rb"(Frames:[ \t]*)[0-9]+", rb"(CHANNELS[ \t]+)[0-9]+", rb"(\n)[0-9]+(?=\r?\n)"]
    pat = re.compile(rng.choice(pats))
    hits = list(pat.finditer(data))
    if not hits:
        return data
    m = rng.choice(hits[:50])
    return data[:m.start()] + m.group(1) + value + data[m.end():]


def deep_hierarchy(data: bytes, rng: random.Random) -> bytes:
    """A chain of nested joints (BVH) or bones (ASF): 10 to 20,000 deep, with or without channels."""
    n = rng.choice((10, 500, 1500, 2000, 4000, 6000, 20000))
    if b":bonedata" in data:  # ASF: bones b0..b{n-1} hung under lowerback
        dof = b"  dof rx\n" if rng.random() < 0.3 else b""
        bones = b"".join(b"  begin\n  id %d\n  name b%d\n  direction 0 1 0\n  length 0.5\n  axis 0 0 0 XYZ\n%s  end\n"
                         % (100 + k, k, dof) for k in range(n))
        links = b"lowerback b0\n" + b"".join(b"b%d b%d\n" % (k, k + 1) for k in range(n - 1))
        data = data.replace(b":hierarchy", bones + b":hierarchy", 1)
        return _insert_after_last(data, b"\n  end", b"\n" + links)
    m = re.search(rb"CHANNELS[^\n]*\n", data)
    if not m:
        return data
    ch = b"CHANNELS 3 Zrotation Xrotation Yrotation\n" if rng.random() < 0.2 else b""
    chain = b"".join(b"JOINT j%d\n{\nOFFSET 0 1 0\n%s" % (k, ch) for k in range(n))
    chain += b"End Site\n{\nOFFSET 0 0 0\n}\n" + b"}\n" * n
    return data[:m.end()] + chain + data[m.end():]


def _insert_after_last(data: bytes, marker: bytes, insert: bytes) -> bytes:
    """insert placed at the last marker (the end of the :hierarchy section) when it follows ':hierarchy'."""
    h = data.find(b":hierarchy")
    k = data.rfind(marker)
    if h < 0 or k < h:
        return data
    return data[:k] + insert.rstrip(b"\n") + data[k:]


def cyclic_hierarchy(data: bytes, rng: random.Random) -> bytes:
    """ASF: a hierarchy line that closes a cycle, repeats a child or names root as a child;
    BVH: an extra or missing brace."""
    if b":hierarchy" in data:
        line = rng.choice((b"ltibia lfemur", b"lfemur lfemur", b"lfoot lhipjoint", b"root lhipjoint",
                           b"head thorax", b"ltoes root", b"rtoes ghost"))
        return _insert_after_last(data, b"\n  end", b"\n" + line + b"\n")
    lines = _lines(data)
    i = _pick_line(lines, rng)
    lines.insert(i, rng.choice((b"{\n", b"}\n", b"}\n}\n", b"ROOT again\n{\n")))
    return b"".join(lines)


def missing_value(data: bytes, rng: random.Random) -> bytes:
    """Drop what follows a keyword (name, length, axis, direction, dof, order, OFFSET, CHANNELS,
    ROOT, JOINT, Frames:, Frame Time:) on one line."""
    keys = rb"(?m)^([ \t]*(?:name|length|axis|direction|dof|order|position|orientation|OFFSET|CHANNELS|ROOT|JOINT|Frames:|Frame Time:))[^\r\n]*"
    hits = list(re.finditer(keys, data))
    if not hits:
        return data
    m = rng.choice(hits)
    keep = m.group(0).split()[:rng.choice((0, 1, 2))]
    return data[:m.start()] + m.group(1) + (b" " + b" ".join(keep) if keep else b"") + data[m.end():]


def bad_axis(data: bytes, rng: random.Random) -> bytes:
    """An ASF axis order, or a BVH channel name, replaced."""
    hits = list(re.finditer(rb"\b(XYZ|[XYZ](?:rotation|position))\b", data))
    if not hits:
        return data
    m = rng.choice(hits)
    new = rng.choice(BAD_AXIS_ORDERS) if len(m.group(0)) == 3 else rng.choice(
        ("Wrotation", "Xrotation", "Zposition", "xrotation", "Xscale", ""))
    return data[:m.start()] + new.encode() + data[m.end():]


def add_bom(data: bytes, rng: random.Random) -> bytes:
    return _BOM + data if rng.random() < 0.8 else data[:len(data) // 2] + _BOM + data[len(data) // 2:]


def line_ends(data: bytes, rng: random.Random) -> bytes:
    """LF -> CRLF, CRLF -> LF, or all line ends -> CR."""
    lf = data.replace(b"\r\n", b"\n")
    return rng.choice((lf.replace(b"\n", b"\r\n"), lf, lf.replace(b"\n", b"\r")))


def junk_line(data: bytes, rng: random.Random) -> bytes:
    lines = _lines(data)
    junk = bytes(rng.randrange(256) for _ in range(rng.randint(1, 40))) + b"\n"
    lines.insert(_pick_line(lines, rng), rng.choice((junk, "\u00b2 \uff11 \u0663\n".encode(), b"\xff\xfe\x00\n")))
    return b"".join(lines)


def reencode(data: bytes, rng: random.Random) -> bytes:
    """The text as UTF-16 (with its BOM), or Latin-1 bytes in a name."""
    if rng.random() < 0.5:
        return data.decode("utf-8", "replace").encode("utf-16")
    return data.replace(b"Hips", b"H\xe9ps\xff", 1).replace(b"lfemur", b"lf\xe9mur", 2)


def long_line(data: bytes, rng: random.Random) -> bytes:
    """One line made 200,000 characters long (many tokens, or one huge token)."""
    lines = _lines(data)
    if not lines:
        return data
    i = _pick_line(lines, rng)
    extra = b" 0" * 100_000 if rng.random() < 0.5 else b"7" * 200_000
    lines[i] = lines[i].rstrip(b"\r\n") + extra + b"\n"
    return b"".join(lines)


MUTATIONS = {f.__name__: f for f in (
    truncate, flip_bytes, delete_line, duplicate_line, swap_lines, special_number, huge_count, deep_hierarchy,
    cyclic_hierarchy, missing_value, bad_axis, add_bom, line_ends, junk_line, reencode, long_line)}
#: Relative frequency of each mutation.
WEIGHTS = {"truncate": 2, "flip_bytes": 3, "delete_line": 2, "duplicate_line": 2, "swap_lines": 2, "special_number": 6,
           "huge_count": 2, "deep_hierarchy": 1, "cyclic_hierarchy": 1, "missing_value": 2, "bad_axis": 2,
           "add_bom": 1, "line_ends": 1, "junk_line": 1, "reencode": 1, "long_line": 1}


def mutate_case(files: dict[str, bytes], rng: random.Random) -> tuple[dict[str, bytes], list[str]]:
    """One to three mutations of one file of a case (an AMC case: the AMC or the ASF); returns
    the files and the names of the mutations ('file:mutation')."""
    files = dict(files)
    names = list(MUTATIONS)
    done = []
    for _ in range(rng.choice((1, 1, 2, 3))):
        target = rng.choice(sorted(files))
        op = rng.choices(names, weights=[WEIGHTS[n] for n in names])[0]
        files[target] = MUTATIONS[op](files[target], rng)
        done.append(f"{target}:{op}")
    return files, done


def main_file(files: dict[str, bytes]) -> str:
    """The file of a case that load_motion is given (the BVH or the AMC)."""
    return next(n for n in sorted(files) if not n.endswith(".asf"))


# ----------------------------------------------------------------------------- one load


def check_motion(m) -> str | None:
    """Why a loaded Motion is unusable (None when it is fine)."""
    import numpy as np

    if m.n_frames < 1:
        return "no frames"
    if not (np.isfinite(m.fps) and m.fps > 0):
        return f"fps {m.fps!r}"
    T, J = m.n_frames, m.skeleton.n_joints
    if m.rotations.shape != (T, J, 4) or m.root_positions.shape != (T, 3) or m.skeleton.offsets.shape != (J, 3):
        return "array shapes disagree"
    arrays = {"rotations": m.rotations, "root_positions": m.root_positions, "offsets": m.skeleton.offsets}
    if m.local_translations is not None:
        arrays["local_translations"] = m.local_translations
    for name, a in arrays.items():
        if not np.all(np.isfinite(a)):
            return f"non-finite {name}"
    if not np.isfinite(m.skeleton.metres_per_unit) or m.skeleton.metres_per_unit <= 0:
        return "metres_per_unit"
    for start in range(0, T, 256):  # forward kinematics in slices of frames: bounded memory
        if not np.all(np.isfinite(m.slice(start, start + 256).positions())):
            return "non-finite positions"
    return None


def _vm_hwm_kb() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss


def _child_load(path: str) -> dict:
    """Runs in the forked child: one load_motion, classified."""
    from motion_graph.errors import MocapFormatError
    from motion_graph.io import load_motion

    t = time.perf_counter()
    peak_kb = 0
    try:
        m = load_motion(path)
        seconds = time.perf_counter() - t
        peak_kb = _vm_hwm_kb()
        problem = check_motion(m)
        out = {"outcome": "valid" if problem is None else "invalid_load", "detail": problem or "",
               "frames": m.n_frames, "joints": m.skeleton.n_joints}
    except MocapFormatError as e:
        seconds = time.perf_counter() - t
        s = str(e)  # names the file at fault: the one loaded, or the ASF beside an AMC
        bad_message = ("\n" in s or "\r" in s or not s.startswith(e.path + (f":{e.line}: " if e.line else ": "))
                       or Path(e.path).parent != Path(path).parent or len(e.problem) > MAX_PROBLEM_CHARS)
        out = {"outcome": "mocap_format_error", "detail": f"{Path(e.path).name}{s[len(e.path):]}"[:300],
               "bad_message": bad_message, "problem_chars": len(e.problem)}
    except MemoryError:
        seconds = time.perf_counter() - t
        out = {"outcome": "limit", "detail": "MemoryError under the 2 GiB limit"}
    except Exception as e:  # the contract is broken: report it
        seconds = time.perf_counter() - t
        out = {"outcome": "other_exception", "detail": f"{type(e).__name__}: {str(e)[:200]}"}
    out["seconds"] = seconds
    out["peak_rss_mb"] = (peak_kb if out["outcome"] in ("valid", "invalid_load") else _vm_hwm_kb()) / 1024
    return out


def _start(path: str) -> tuple[int, int]:
    """Fork a child that loads path under the limits; returns (pid, read end of its pipe)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        os.close(r)
        code = 0
        try:
            resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
            out = _child_load(path)
            os.write(w, json.dumps(out).encode())
        except BaseException:  # noqa: BLE001 - nothing may escape a forked child
            code = 1
        finally:
            os._exit(code)
    os.close(w)
    return pid, r


def _finish(pid: int, r: int, started: float) -> dict:
    chunks = []
    while True:
        b = os.read(r, 65536)
        if not b:
            break
        chunks.append(b)
    os.close(r)
    _, status = os.waitpid(pid, 0)
    if chunks:
        return json.loads(b"".join(chunks))
    sig = os.WTERMSIG(status) if os.WIFSIGNALED(status) else None
    return {"outcome": "limit", "detail": f"child died (signal {sig}, status {status})",
            "seconds": time.perf_counter() - started, "peak_rss_mb": float("nan")}


# ----------------------------------------------------------------------------- the run


def run(n: int, seed: int, workers: int, root: Path, save_failures: Path | None, progress: bool) -> dict:
    from motion_graph.io import load_motion  # noqa: F401 - imported before forking: children start warm

    sources = source_cases(root)
    if not sources:
        raise SystemExit(f"no .bvh / .amc files under {root}")
    rng = random.Random(seed)
    tmp = Path(tempfile.mkdtemp(prefix="mocap_fuzz_"))
    counts: Counter = Counter()
    by_mutation: dict[str, Counter] = {}
    bad: list[dict] = []
    bad_messages = []
    peak = {"peak_rss_mb": 0.0}
    slowest = {"seconds": 0.0}
    longest = {"chars": 0}
    running: dict[int, tuple[int, int, float, int, dict, list[str], Path]] = {}  # fd -> job
    t0 = time.perf_counter()
    next_case = 0

    def record(job_result: dict, case: int, mutations: list[str], folder: Path, files: dict[str, bytes]) -> None:
        o = job_result["outcome"]
        counts[o] += 1
        for mname in {m.split(":")[1] for m in mutations}:
            by_mutation.setdefault(mname, Counter())[o] += 1
        row = {"case": case, "source": main_file(files), "mutations": mutations, **job_result}
        if job_result.get("peak_rss_mb", 0) > peak["peak_rss_mb"]:
            peak.update(row)
        if job_result["seconds"] > slowest["seconds"]:
            slowest.update(row)
        if o in ("other_exception", "invalid_load", "limit"):
            bad.append(row)
            if save_failures is not None:
                dest = save_failures / f"case_{case:06d}"
                dest.mkdir(parents=True, exist_ok=True)
                for name, data in files.items():
                    (dest / name).write_bytes(data)
        if job_result.get("bad_message"):
            bad_messages.append(row)
        longest["chars"] = max(longest["chars"], job_result.get("problem_chars", 0))
        shutil.rmtree(folder, ignore_errors=True)

    while next_case < n or running:
        while next_case < n and len(running) < workers:
            files, mutations = mutate_case(base_case(rng.choice(sources), rng), rng)
            folder = tmp / f"c{next_case}"
            folder.mkdir()
            for name, data in files.items():
                (folder / name).write_bytes(data)
            started = time.perf_counter()
            pid, r = _start(str(folder / main_file(files)))
            running[r] = (pid, r, started, next_case, files, mutations, folder)
            next_case += 1
        ready, _, _ = select.select(list(running), [], [], 0.2)
        now = time.perf_counter()
        for r in list(running):
            pid, _, started, case, files, mutations, folder = running[r]
            if r in ready:
                del running[r]
                record(_finish(pid, r, started), case, mutations, folder, files)
            elif now - started > TIME_LIMIT_S:
                os.kill(pid, signal.SIGKILL)
                del running[r]
                res = _finish(pid, r, started)
                res.update(outcome="limit", detail=f"killed after {TIME_LIMIT_S:g} s", seconds=now - started)
                record(res, case, mutations, folder, files)
        done = sum(counts.values())
        if progress and done and done % 500 == 0 and not running:
            print(f"  {done}/{n} {dict(counts)} {time.perf_counter() - t0:.0f} s", flush=True)
    shutil.rmtree(tmp, ignore_errors=True)
    return {
        "mutations": n, "seed": seed, "workers": workers, "sources": len(sources), "wall_s": round(time.perf_counter() - t0, 1),
        "counts": {k: counts.get(k, 0) for k in ("valid", "mocap_format_error", "other_exception", "invalid_load", "limit")},
        "bad_messages": len(bad_messages), "longest_problem_chars": longest["chars"],
        "peak_rss_mb": round(peak["peak_rss_mb"], 1), "peak_case": {k: peak.get(k) for k in ("case", "source", "mutations", "outcome", "detail")},
        "slowest_s": round(slowest["seconds"], 3), "slowest_case": {k: slowest.get(k) for k in ("case", "source", "mutations", "outcome", "detail")},
        "by_mutation": {k: dict(v) for k, v in sorted(by_mutation.items())},
        "failures": bad[:50], "bad_message_examples": bad_messages[:10],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mutations", type=int, default=5000, help="number of mutated cases (default 5000)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--workers", type=int, default=1, help="loads running at once (default 1)")
    ap.add_argument("--mocap", default=None, help="mocap folder (default: $IGRAPH_FIGHT_MOCAP or ../shared/mocap)")
    ap.add_argument("--save-failures", default=None, help="folder to keep the files of bad outcomes in")
    ap.add_argument("--json", action="store_true", help="print one JSON object")
    args = ap.parse_args()
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from motion_graph import paths

    root = Path(args.mocap) if args.mocap else paths.find_mocap_root()
    if root is None or not root.is_dir():
        raise SystemExit("mocap folder not found (give --mocap)")
    rep = run(args.mutations, args.seed, max(1, args.workers), root,
              Path(args.save_failures) if args.save_failures else None, progress=not args.json)
    if args.json:
        print(json.dumps(rep, indent=1))
        return
    c = rep["counts"]
    print(f"{rep['mutations']} mutations of {rep['sources']} real cases (seed {rep['seed']}, {rep['workers']} worker, "
          f"{rep['wall_s']} s)")
    print(f"  loaded valid {c['valid']}, MocapFormatError {c['mocap_format_error']}, other exception {c['other_exception']}, "
          f"non-finite / fps <= 0 loads {c['invalid_load']}, over 10 s or 2 GiB {c['limit']}; "
          f"MocapFormatError messages not one line naming the file or over {MAX_PROBLEM_CHARS} characters: "
          f"{rep['bad_messages']} (longest {rep['longest_problem_chars']})")
    print(f"  peak RSS {rep['peak_rss_mb']} MB: {rep['peak_case']}")
    print(f"  slowest load {rep['slowest_s']} s: {rep['slowest_case']}")
    for f in rep["failures"][:20]:
        print(f"  BAD case {f['case']} {f['source']} {f['mutations']}: {f['outcome']} {f['detail']}")
    print("  by mutation: " + "; ".join(f"{k} {v}" for k, v in rep["by_mutation"].items()))


if __name__ == "__main__":
    main()
