"""The compact graph file container (graph file versions 3 and 4): an index, then 64-byte aligned blobs.

Layout (all integers little-endian)::

    bytes 0-7     MAGIC  b"IGFGRAPH"
    bytes 8-15    uint64 n: length of the index
    bytes 16..    the index: n bytes of UTF-8 JSON, an object (the graph header, see
                  igraph_fight.graph), whose ``members`` maps every array name to its member spec
    then          the blobs, each at an offset that is a multiple of ALIGN, zero padding between

A blob is a byte range of the file: ``{"offset", "nbytes", "crc32", "compression": "none" |
"deflate", "dtype", "count"}``: ``count`` values of ``dtype`` (numpy's little-endian string,
e.g. ``"<f8"``, ``"|u1"``), stored as they are (``"none"``: ``nbytes == count * itemsize``) or
as one zlib stream (``"deflate"``) that inflates to exactly ``count * itemsize`` bytes. ``crc32``
(zlib.crc32) covers the ``nbytes`` stored bytes.

A member spec: ``{"encoding", "dtype", "shape": [n], ...}`` with ``dtype`` the array's canonical
dtype (what the graph's arrays hold in memory) and one of these encodings:

- ``"raw"``: ``data`` is a blob of the canonical dtype, stored: memory-mapped read-only, no copy
  (``copy`` true: read into memory instead; for the index arrays the numba kernels follow).
- ``"narrow"``: ``data`` holds the same integers in a narrower integer dtype; widened on use.
- ``"table"``: ``data`` holds codes (uint8 or uint16) into ``values`` (a JSON list of numbers):
  array = values[codes], for float arrays with few distinct values (exact: a JSON number is
  the shortest repr of a float64 and parses back to the same float64).
- ``"offsets"``: ``data`` holds the n - 1 differences of a non-decreasing array that starts at 0
  (CSR offsets): array = [0, cumsum(data)].
- ``"derived"``: the array is ``formula(arrays)`` (a function the reader is given by name, see
  igraph_fight.graph.FORMULAS; each formula yields one array), except at the positions whose bit
  is set in ``mask`` (a blob of ceil(n / 8) uint8, numpy.packbits order), which take the ``data``
  values in order. An optional ``crc32`` (version 4 writes it) is zlib.crc32 of the decoded
  array's bytes: a reader whose formula gives other bits refuses the array instead of using it.

Reading is bounded before anything is inflated or allocated: the index at most ``max_index``
bytes of strict JSON, every blob inside the file, raw blobs aligned, the dtypes plain numbers,
and the arrays decoded from the file at most MAX_INFLATION times the file's size (+1 MiB) all
together. Every blob's CRC-32 is checked on load, a derived array's ``crc32`` once it is decoded. Arrays other than raw ones are decoded on first
access (GraphArrays); what validation needs (the stored integers, the tables' values, the
exceptions of derived arrays) is read on load.

The mapping keeps the file memory-mapped: replace a graph file (write a new one and rename it, as
motion_graph.atomic does), never rewrite one in place while a process uses it.
"""
from __future__ import annotations

import json
import mmap
import struct
import threading
import zlib
from collections.abc import Callable, Iterator, MutableMapping
from dataclasses import dataclass

import numpy as np

MAGIC = b"IGFGRAPH"
ALIGN = 64
#: decoded arrays (and inflated blobs) of a file at most this many times its size, plus 1 MiB
MAX_INFLATION = 32
INFLATION_SLACK = 1 << 20
#: dtypes a blob may hold (little-endian plain numbers)
BLOB_DTYPES = ("|u1", "<u2", "<u4", "<u8", "|i1", "<i2", "<i4", "<i8", "<f4", "<f8")
ENCODINGS = ("raw", "narrow", "table", "offsets", "derived")
#: the largest count or length a spec may declare
MAX_COUNT = 1 << 40


def is_compact(prefix: bytes) -> bool:
    """Whether a file starting with ``prefix`` is a compact container."""
    return prefix[:len(MAGIC)] == MAGIC


def _dt(s: str) -> np.dtype:
    return np.dtype(s)


def dtype_name(dt) -> str:
    """numpy's explicit little-endian name of an integer or float dtype (``"<f8"``, ``"|u1"``)."""
    d = np.dtype(dt).newbyteorder("<") if np.dtype(dt).itemsize > 1 else np.dtype(dt)
    return d.str


# ----- writing -----------------------------------------------------------------------------------
def narrow_dtype(a: np.ndarray) -> np.dtype:
    """The smallest integer dtype that holds every value of integer array ``a``."""
    if len(a) == 0:
        return np.dtype(np.uint8)
    lo, hi = int(a.min()), int(a.max())
    for dt in (np.uint8, np.int8, np.uint16, np.int16, np.uint32, np.int32, np.uint64, np.int64):
        info = np.iinfo(dt)
        if info.min <= lo and hi <= info.max:
            return np.dtype(dt)
    return a.dtype


#: values per piece when an array is encoded, compared or compressed piece by piece
CHUNK = 1 << 21
#: edges per shard when a file's edges are replayed shard by shard (graph_replay.iter_replay)
SHARD_EDGES = 1 << 18


def chunks(n: int, size: int = CHUNK) -> Iterator[tuple[int, int]]:
    """[lo, hi) ranges of at most ``size`` covering [0, n)."""
    for lo in range(0, n, size):
        yield lo, min(n, lo + size)


def table_values(a: np.ndarray, max_values: int = 65535) -> list[float] | None:
    """The sorted distinct values of float array ``a`` when there are at most ``max_values`` of
    them and ``values[searchsorted(values, a)] == a`` bit for bit (-0.0 kept apart from 0.0) with
    values JSON can hold, else None. Read piece by piece: memory is bounded by the values."""
    if len(a) == 0:
        return None
    values = np.zeros(0, dtype=a.dtype)
    for lo, hi in chunks(len(a)):
        c = np.asarray(a[lo:hi])
        if not np.isfinite(c).all():
            return None
        values = np.union1d(values, np.unique(c))
        if len(values) > max_values:
            return None
    values_l = [float(v) for v in values]
    if not np.array_equal(np.asarray(values_l, dtype=a.dtype).view(np.uint8), values.view(np.uint8)):
        return None
    for lo, hi in chunks(len(a)):
        c = np.asarray(a[lo:hi])
        if not np.array_equal(values[np.searchsorted(values, c)].view(np.uint8), c.view(np.uint8)):
            return None  # -0.0 and 0.0 merged by unique: keep the bits
    return values_l


def table_codes(a: np.ndarray, max_values: int = 65535) -> tuple[list[float], np.ndarray] | None:
    """(values, codes) with a == values[codes] bit for bit, or None (table_values)."""
    values = table_values(a, max_values)
    if values is None:
        return None
    v = np.asarray(values, dtype=a.dtype)
    return values, np.searchsorted(v, a).astype(np.uint8 if len(values) <= 256 else np.uint16)


class Writer:
    """Collects blobs and writes the container (``finish``). Blobs are encoded piece by piece
    (CHUNK values at a time: narrowed, coded, deflated as one zlib stream, CRC-32 updated) into a
    spool file (an anonymous temporary file in ``spool_dir``, default the system's), which
    ``finish`` copies behind the index: the writer's memory does not grow with the arrays, which
    may be memory-mapped files. ``chunk``: values per piece (the file does not depend on it)."""

    def __init__(self, spool_dir: str | None = None, chunk: int = CHUNK) -> None:
        import tempfile
        if chunk < 1:
            raise ValueError(f"chunk must be at least 1 value, not {chunk}")
        self.spool = tempfile.TemporaryFile(dir=spool_dir)
        self.pos = 0
        self.chunk = int(chunk)

    def close(self) -> None:
        self.spool.close()

    def __enter__(self) -> "Writer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def blob(self, a: np.ndarray, compress: bool, dtype=None,
             transform: Callable[[np.ndarray], np.ndarray] | None = None) -> dict:
        """Add the values of 1-d ``a`` (after ``transform``, piece by piece) as ``dtype`` (default
        a's); returns the blob spec (offset relative to the blobs' start)."""
        a = np.asarray(a).reshape(-1)
        dt = dtype_name(dtype if dtype is not None else a.dtype)
        pad = -self.pos % ALIGN              # the padding before a blob (none after the last)
        self.spool.write(bytes(pad))
        self.pos += pad
        z = zlib.compressobj(6) if compress else None
        crc, nbytes = 0, 0
        for lo, hi in chunks(len(a), self.chunk):
            c = np.asarray(a[lo:hi])
            if transform is not None:
                c = transform(c)
            raw = memoryview(np.ascontiguousarray(c.astype(dt, copy=False))).cast("B")
            data = z.compress(raw) if z is not None else raw
            crc = zlib.crc32(data, crc)
            self.spool.write(data)
            nbytes += len(data)
        if z is not None:
            data = z.flush()
            crc = zlib.crc32(data, crc)
            self.spool.write(data)
            nbytes += len(data)
        spec = {"offset": self.pos, "nbytes": nbytes, "crc32": crc,
                "compression": "deflate" if compress else "none", "dtype": dt, "count": int(a.size)}
        self.pos += nbytes
        return spec

    def finish(self, fh, header: dict, seal: Callable[[dict], str], magic: bytes = MAGIC) -> dict:
        """Write ``magic`` (8 bytes), the index and the blobs; returns the index written: ``header``
        with its members' blob offsets made absolute and ``checksum`` = seal(that index) (a string
        of fixed length: the index is laid out with a placeholder of its length first)."""
        import shutil
        placeholder = seal(header)
        start = 0
        for _ in range(16):  # the index's length depends on the offsets it holds
            index = {**header, "members": _shift(header["members"], start), "checksum": placeholder}
            need = 16 + len(json.dumps(index, allow_nan=False).encode())
            if need + (-need % ALIGN) <= start:
                break
            start = need + (-need % ALIGN)
        index["checksum"] = seal(index)
        text = json.dumps(index, allow_nan=False).encode()
        if 16 + len(text) > start:
            raise ValueError("the checksum changed the index's length")
        fh.write(magic + struct.pack("<Q", start - 16) + text + b" " * (start - 16 - len(text)))
        self.spool.flush()
        self.spool.seek(0)
        shutil.copyfileobj(self.spool, fh, 1 << 22)
        return index


def _shift(members: dict, start: int) -> dict:
    def blob(b: dict) -> dict:
        return {**b, "offset": b["offset"] + start}
    out = {}
    for k, m in members.items():
        m = dict(m)
        for part in ("data", "mask"):
            if part in m:
                m[part] = blob(m[part])
        out[k] = m
    return out


def encode_raw(w: Writer, a: np.ndarray, copy: bool = False) -> dict:
    spec = {"encoding": "raw", "dtype": dtype_name(a.dtype), "shape": list(a.shape), "data": w.blob(a, False)}
    if copy:
        spec["copy"] = True
    return spec


def encode_ints(w: Writer, a: np.ndarray) -> dict:
    """An integer array, narrowed and deflated."""
    return {"encoding": "narrow", "dtype": dtype_name(a.dtype), "shape": list(a.shape),
            "data": w.blob(a, True, dtype=narrow_dtype(a))}


def encode_floats(w: Writer, a: np.ndarray, deflate: bool) -> dict:
    """A float array as a table of its distinct values when it has few, else its values (deflated
    or memory-mapped)."""
    values = table_values(a, 4096)
    if values is not None:
        v = np.asarray(values, dtype=a.dtype)
        return {"encoding": "table", "dtype": dtype_name(a.dtype), "shape": list(a.shape), "values": values,
                "data": w.blob(a, True, dtype=np.uint8 if len(values) <= 256 else np.uint16,
                               transform=lambda c: np.searchsorted(v, c))}
    if deflate:
        return {"encoding": "raw", "dtype": dtype_name(a.dtype), "shape": list(a.shape), "data": w.blob(a, True)}
    return encode_raw(w, a)


def encode_offsets(w: Writer, a: np.ndarray) -> dict | None:
    """CSR offsets as their differences (None unless ``a`` starts at 0 and never decreases)."""
    if len(a) == 0 or a[0] != 0:
        return None
    d = np.diff(a)
    if len(d) and d.min() < 0:
        return None
    return {"encoding": "offsets", "dtype": dtype_name(a.dtype), "shape": list(a.shape),
            "data": w.blob(d, True, dtype=narrow_dtype(d))}


class DerivedEncoder:
    """An array stored as a formula of the others, fed piece by piece: ``update(lo, hi, derived)``
    with the formula's values at [lo, hi) (the pieces in order, covering the array), then
    ``finish(w)``: the member spec (the positions where the two differ bit for bit as a mask and
    their values), or None when they differ at more than half the positions. Memory: the mask's
    bits and the exceptions, never the whole array. ``crc``: record the CRC-32 of ``a``'s bytes,
    which the reader checks after decoding."""

    def __init__(self, a: np.ndarray, formula: str, crc: bool = False) -> None:
        self.a, self.formula, self.crc = a, formula, crc
        self.dt = np.dtype(dtype_name(a.dtype))
        self.value_crc = 0
        self.bits: list[np.ndarray] = []    # packed mask bytes
        self.carry = np.zeros(0, dtype=bool)
        self.exceptions: list[np.ndarray] = []
        self.n_exc = 0
        self.done = 0

    def update(self, lo: int, hi: int, derived: np.ndarray) -> None:
        if lo != self.done or hi < lo or hi > len(self.a):
            raise ValueError(f"{self.formula}: pieces must cover the array in order (got [{lo}, {hi}) after {self.done})")
        a = np.ascontiguousarray(self.a[lo:hi], dtype=self.dt)
        d = np.ascontiguousarray(np.asarray(derived).astype(self.dt, copy=False))
        if d.shape != a.shape:
            raise ValueError(f"{self.formula}: {len(d)} derived values for [{lo}, {hi})")
        n = hi - lo
        diff = (a.view(np.uint8).reshape(n, -1) != d.view(np.uint8).reshape(n, -1)).any(axis=1) if n else \
            np.zeros(0, dtype=bool)
        if self.crc and n:
            self.value_crc = zlib.crc32(memoryview(a).cast("B"), self.value_crc)
        if diff.any():
            self.exceptions.append(a[diff])
            self.n_exc += int(diff.sum())
        diff = np.concatenate([self.carry, diff])
        whole = len(diff) - len(diff) % 8
        self.bits.append(np.packbits(diff[:whole]))
        self.carry = diff[whole:]
        self.done = hi

    def finish(self, w: Writer) -> dict | None:
        n = len(self.a)
        if self.done != n:
            raise ValueError(f"{self.formula}: pieces cover [0, {self.done}) of {n} values")
        if self.n_exc > n // 2:
            return None
        spec = {"encoding": "derived", "formula": self.formula, "dtype": dtype_name(self.dt), "shape": [n]}
        if self.crc:
            spec["crc32"] = self.value_crc
        if self.n_exc:
            mask = np.concatenate(self.bits + [np.packbits(self.carry)])
            spec["mask"] = w.blob(mask, True)
            spec["data"] = w.blob(np.concatenate(self.exceptions), False)
        return spec


def encode_derived(w: Writer, a: np.ndarray, formula: str, derived: np.ndarray, crc: bool = False) -> dict | None:
    """``a`` as ``formula`` of the other arrays (``derived``: its value) and the values where the
    two differ bit for bit; None when they differ at more than half the positions (DerivedEncoder
    in one piece)."""
    e = DerivedEncoder(a, formula, crc)
    e.update(0, len(a), derived)
    return e.finish(w)


def value_crc32(a: np.ndarray) -> int:
    """zlib.crc32 of an array's little-endian bytes in its own dtype."""
    a = np.ascontiguousarray(a)
    return zlib.crc32(memoryview(a.astype(dtype_name(a.dtype), copy=False)).cast("B")) if a.nbytes else 0


# ----- reading -----------------------------------------------------------------------------------
class FormatProblem(ValueError):
    """A problem of a compact file (the caller turns it into its format error)."""


@dataclass
class Member:
    """A member of a compact file not decoded yet: its spec and what load read of it."""

    name: str
    spec: dict
    stored: np.ndarray | None = None  # data: narrow ints, table codes, offset differences, exception values
    mask: np.ndarray | None = None    # derived: positions of the exceptions (bool, n)

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(self.spec["shape"])

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(self.spec["dtype"])

    @property
    def encoding(self) -> str:
        return self.spec["encoding"]

    def __len__(self) -> int:
        return self.shape[0]

    def values(self) -> np.ndarray:
        """An array holding exactly the values the decoded array holds (no more, perhaps fewer
        or in another order and dtype): what range checks need without decoding. Derived arrays:
        only their exceptions (the rest follows from arrays that are checked themselves)."""
        if self.encoding == "table":
            return np.asarray(self.spec["values"], dtype=self.dtype)
        if self.encoding == "derived":
            return self.stored if self.stored is not None else np.zeros(0, dtype=self.dtype)
        if self.encoding == "offsets":
            return self.decode(GraphArrays({}), {})
        return self.stored

    def value_index(self, i: int) -> int:
        """The position in the decoded array of ``values()[i]`` (derived arrays: of the i-th
        exception); -1 when it has none (tables)."""
        if self.encoding == "derived":
            return int(np.flatnonzero(self.mask)[i])
        if self.encoding == "table":
            return -1
        return i

    def decode(self, arrays: "GraphArrays", formulas: dict[str, Callable]) -> np.ndarray:
        enc, dt = self.encoding, self.dtype
        if enc == "narrow":
            return self.stored.astype(dt)
        if enc == "table":
            return np.asarray(self.spec["values"], dtype=dt)[self.stored]
        if enc == "offsets":
            out = np.empty(self.shape[0], dtype=dt)
            out[0] = 0
            np.cumsum(self.stored, out=out[1:], dtype=dt)
            return out
        out = np.ascontiguousarray(formulas[self.spec["formula"]](arrays), dtype=dt)
        if out.shape != self.shape:
            raise FormatProblem(f"{self.name}: its formula gives {out.shape[0] if out.ndim else 0} values, not "
                                f"{self.shape[0]}")
        if self.mask is not None and self.stored is not None and len(self.stored):
            out = out.copy() if not out.flags.writeable else out
            out[self.mask] = self.stored
        if "crc32" in self.spec and value_crc32(out) != self.spec["crc32"]:
            raise FormatProblem(f"{self.name}: {self.spec['formula']} gives other values on this machine than "
                                f"where the file was written (CRC-32 mismatch)")
        return out


class GraphArrays(MutableMapping):
    """A graph's arrays by name, in their canonical dtypes. Arrays of a compact file other than the
    memory-mapped ones are Members, decoded on first access (thread-safe) and then kept; ``peek``
    gives either without decoding. Pickles as a plain dict of decoded arrays. A problem found
    while decoding (a FormatProblem) is raised as ``error(problem)`` when ``error`` is given;
    ``context`` is for the formulas (what they share, e.g. a parsed library)."""

    def __init__(self, arrays: dict[str, np.ndarray], members: dict[str, Member] | None = None,
                 formulas: dict[str, Callable] | None = None, order: list[str] | None = None,
                 error: Callable[[str], Exception] | None = None) -> None:
        self._arrays = dict(arrays)
        self._members = dict(members or {})
        self._formulas = dict(formulas or {})
        self._order = list(order) if order is not None else [*self._arrays, *self._members]
        self._lock = threading.RLock()
        self._error = error
        self.context: dict = {}

    def peek(self, name: str) -> np.ndarray | Member:
        """The decoded array, or the Member when it is not decoded yet (KeyError if neither)."""
        a = self._arrays.get(name)
        return a if a is not None else self._members[name]

    def __getitem__(self, name: str) -> np.ndarray:
        a = self._arrays.get(name)
        if a is not None:
            return a
        with self._lock:
            a = self._arrays.get(name)
            if a is None:
                m = self._members[name]
                try:
                    a = m.decode(self, self._formulas)
                except FormatProblem as e:
                    if self._error is None:
                        raise
                    raise self._error(str(e)) from None
                self._arrays[name] = a
                del self._members[name]
        return a

    def __setitem__(self, name: str, value: np.ndarray) -> None:
        with self._lock:
            self._members.pop(name, None)
            if name not in self._arrays and name not in self._order:
                self._order.append(name)
            self._arrays[name] = value

    def __delitem__(self, name: str) -> None:
        with self._lock:
            if name in self._members:
                del self._members[name]
            else:
                del self._arrays[name]
            self._order.remove(name)

    def __contains__(self, name: object) -> bool:
        return name in self._arrays or name in self._members

    def __iter__(self) -> Iterator[str]:
        return iter([k for k in self._order if k in self])

    def __len__(self) -> int:
        return len(self._arrays) + len(self._members)

    def __reduce__(self):
        return dict, ({k: np.array(self[k]) for k in self},)


def _int(v, lo: int = 0, hi: int = MAX_COUNT) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi


def _check_blob(b, what: str, size: int, data_start: int) -> None:
    if not isinstance(b, dict) or set(b) != {"offset", "nbytes", "crc32", "compression", "dtype", "count"}:
        raise FormatProblem(f"{what}: not a blob spec")
    if b["dtype"] not in BLOB_DTYPES:
        raise FormatProblem(f"{what}: dtype {_q(b['dtype'])} is not a plain little-endian number")
    if b["compression"] not in ("none", "deflate"):
        raise FormatProblem(f"{what}: compression {_q(b['compression'])} is not supported")
    if not (_int(b["offset"]) and _int(b["nbytes"]) and _int(b["count"]) and _int(b["crc32"], 0, 0xFFFFFFFF)):
        raise FormatProblem(f"{what}: offset, nbytes, count and crc32 must be non-negative integers")
    if b["offset"] < data_start:
        raise FormatProblem(f"{what}: offset {b['offset']} lies inside the index (it ends at byte {data_start})")
    if b["offset"] + b["nbytes"] > size:
        raise FormatProblem(f"truncated or corrupted ({what} ends at byte {b['offset'] + b['nbytes']}, the file "
                            f"has {size})")
    if b["compression"] == "none":
        if b["nbytes"] != b["count"] * _dt(b["dtype"]).itemsize:
            raise FormatProblem(f"{what}: {b['nbytes']} bytes for {b['count']} values of {b['dtype']}")
        if b["offset"] % ALIGN:
            raise FormatProblem(f"{what}: offset {b['offset']} is not a multiple of {ALIGN}")


def _q(v) -> str:
    s = repr(v)
    return s if len(s) <= 60 else s[:57] + "..."


def check_spec(name: str, m, canonical: np.dtype, size: int, data_start: int, formulas: dict[str, str]) -> int:
    """Vet a member spec (nothing read); returns the bytes its decoding allocates. ``formulas``:
    the formula names a derived member may use, each mapped to the array it yields."""
    if not isinstance(m, dict) or m.get("encoding") not in ENCODINGS:
        raise FormatProblem(f"{name}: encoding {_q(m.get('encoding') if isinstance(m, dict) else m)} is not one of "
                            f"{', '.join(ENCODINGS)}")
    enc = m["encoding"]
    allowed = {"encoding", "dtype", "shape", "data", "copy", "values", "formula", "mask", "crc32"}
    if set(m) - allowed:
        raise FormatProblem(f"{name}: unexpected key {_q(sorted(set(m) - allowed)[0])}")
    if m.get("dtype") != dtype_name(canonical):
        raise FormatProblem(f"{name}: dtype {_q(m.get('dtype'))} (expected 1-d {canonical})")
    shape = m.get("shape")
    if not (isinstance(shape, list) and len(shape) == 1 and _int(shape[0])):
        raise FormatProblem(f"{name}: shape {_q(shape)} (expected 1-d {canonical})")
    n = shape[0]
    need = 0
    for part in ("data", "mask"):
        if part in m:
            _check_blob(m[part], f"{name}.{part}", size, data_start)
            b = m[part]
            if b["compression"] == "deflate":
                need += b["count"] * _dt(b["dtype"]).itemsize
    data = m.get("data")
    if "crc32" in m and enc != "derived":
        raise FormatProblem(f"{name}: unexpected key 'crc32'")
    if enc != "derived" and data is None:
        raise FormatProblem(f"{name}: no data")
    if enc == "raw":
        if data["dtype"] != m["dtype"] or data["count"] != n:
            raise FormatProblem(f"{name}: raw data of {data['count']} {data['dtype']} for {n} {m['dtype']}")
        if data["compression"] == "none" and not m.get("copy", False):
            return need
    elif enc == "narrow":
        if canonical.kind not in "iu" or _dt(data["dtype"]).kind not in "iu" or data["count"] != n:
            raise FormatProblem(f"{name}: narrow data of {data['count']} {data['dtype']} for {n} {m['dtype']}")
    elif enc == "table":
        vals = m.get("values")
        if (canonical.kind != "f" or not isinstance(vals, list) or not 1 <= len(vals) <= 65535
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals)):
            raise FormatProblem(f"{name}: table values must be a list of 1 to 65535 numbers")
        if data["dtype"] not in ("|u1", "<u2") or data["count"] != n:
            raise FormatProblem(f"{name}: table codes of {data['count']} {data['dtype']} for {n} values")
    elif enc == "offsets":
        if canonical.kind not in "iu" or _dt(data["dtype"]).kind not in "iu" or data["count"] != max(n - 1, 0) or n < 1:
            raise FormatProblem(f"{name}: offset differences of {data['count']} {data['dtype']} for {n} offsets")
    else:  # derived
        f = m.get("formula")
        if not isinstance(f, str) or formulas.get(f) != name:
            raise FormatProblem(f"{name}: formula {_q(f)} is not known")
        if "crc32" in m and not _int(m["crc32"], 0, 0xFFFFFFFF):
            raise FormatProblem(f"{name}: crc32 {_q(m['crc32'])} is not a CRC-32")
        if ("mask" in m) != ("data" in m):
            raise FormatProblem(f"{name}: a mask needs its data and data its mask")
        if "mask" in m and (m["mask"]["dtype"] != "|u1" or m["mask"]["count"] != (n + 7) // 8
                            or data["dtype"] != m["dtype"] or data["count"] > n):
            raise FormatProblem(f"{name}: mask of {m['mask']['count']} bytes, {data['count']} exceptions for {n} values")
    return need + n * canonical.itemsize


def read_index(fh, size: int, max_index: int) -> tuple[bytes, int]:
    """(the index's raw JSON bytes, where the blobs may start): checks the magic and the index
    length (nothing parsed)."""
    fh.seek(0)
    head = fh.read(16)
    if len(head) < 16 or not is_compact(head):
        raise FormatProblem("truncated or corrupted (no index)")
    (n,) = struct.unpack("<Q", head[8:16])
    if n > max_index:
        raise FormatProblem(f"header: {n} bytes of JSON (at most {max_index})")
    if 16 + n > size:
        raise FormatProblem(f"truncated or corrupted (an index of {n} bytes in a file of {size})")
    return fh.read(n), 16 + n


def open_map(path: str, size: int) -> mmap.mmap | None:
    """The file memory-mapped read-only (None for an empty file)."""
    if size == 0:
        return None
    with open(path, "rb") as fh:
        return mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)


def read_blob(mm: mmap.mmap, b: dict, what: str, copy: bool = False) -> np.ndarray:
    """A blob's values (CRC-checked; ``none``: a read-only view of the map unless ``copy``)."""
    off, nb = b["offset"], b["nbytes"]
    view = memoryview(mm)[off:off + nb]
    try:
        if zlib.crc32(view) != b["crc32"]:
            raise FormatProblem(f"{what}: truncated or corrupted (CRC-32 mismatch)")
        dt = _dt(b["dtype"])
        if b["compression"] == "none":
            a = np.frombuffer(mm, dtype=dt, count=b["count"], offset=off)
            return a.copy() if copy else a
        want = b["count"] * dt.itemsize
        d = zlib.decompressobj()
        try:
            out = d.decompress(view, want)
            extra = d.decompress(d.unconsumed_tail, 1) if len(out) == want and not d.eof else b""
        except zlib.error as e:
            raise FormatProblem(f"{what}: truncated or corrupted ({e})") from None
        if len(out) != want or not d.eof or extra or d.unused_data:
            raise FormatProblem(f"{what}: truncated or corrupted (the stream does not inflate to {want} bytes)")
        return np.frombuffer(out, dtype=dt).copy() if dt.itemsize > 1 else np.frombuffer(bytearray(out), dtype=dt)
    finally:
        view.release()


def load_member(mm: mmap.mmap, name: str, spec: dict) -> np.ndarray | Member:
    """A raw member as its array (mapped, or copied with ``copy``); any other as a Member with
    what validation needs read (the stored integers, codes, differences, exceptions and mask)."""
    enc = spec["encoding"]
    if enc == "raw":
        a = read_blob(mm, spec["data"], f"{name}.data", copy=bool(spec.get("copy", False)))
        return a
    m = Member(name, spec)
    if "data" in spec:
        m.stored = read_blob(mm, spec["data"], f"{name}.data")
    if enc == "table" and m.stored is not None and len(m.stored) and int(m.stored.max()) >= len(spec["values"]):
        i = int(np.argmax(m.stored >= len(spec["values"])))
        raise FormatProblem(f"{name}: code {int(m.stored[i])} at [{i}] is outside its table of "
                            f"{len(spec['values'])} values")
    if enc == "offsets" and m.stored is not None and m.stored.dtype.kind == "i" and len(m.stored) and m.stored.min() < 0:
        raise FormatProblem(f"{name}: not {spec['shape'][0]} non-decreasing offsets")
    if "mask" in spec:
        bits = read_blob(mm, spec["mask"], f"{name}.mask")
        n = spec["shape"][0]
        if len(bits) and n % 8 and int(bits[-1]) & ((1 << (8 - n % 8)) - 1):
            raise FormatProblem(f"{name}: mask bits past the end")
        m.mask = np.unpackbits(bits, count=n).astype(bool)
        if int(m.mask.sum()) != len(m.stored):
            raise FormatProblem(f"{name}: {int(m.mask.sum())} exceptions in the mask, {len(m.stored)} values")
    return m


def load_members(mm: mmap.mmap, specs: dict[str, dict], threads: int = 2) -> dict[str, np.ndarray | Member]:
    """load_member of every spec, the largest first, on ``threads`` threads (zlib checks and
    inflates without the GIL); the first problem in spec order is raised."""
    from concurrent.futures import ThreadPoolExecutor

    def size(spec: dict) -> int:
        return sum(spec[p]["nbytes"] for p in ("data", "mask") if p in spec)

    order = sorted(specs, key=lambda k: -size(specs[k]))
    with ThreadPoolExecutor(max(1, threads)) as ex:
        futs = {k: ex.submit(load_member, mm, k, specs[k]) for k in order}
    problems = [k for k in specs if futs[k].exception() is not None]
    if problems:
        raise futs[problems[0]].exception()
    return {k: futs[k].result() for k in specs}
