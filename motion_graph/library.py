"""ActionLibrary: segmented, labelled actions of one skeleton as flat arrays, with Next(a).

Every action is stored in its own start frame: the pelvis starts above the origin, the fighting
direction (head facing plus the clip's stance offset, see motion_graph.strikes) along +Z, +X to the left, Y up, the floor
at y = 0. Actions are concatenated along the frame axis; ``frame_offsets`` slices them. Frames
are at the library rate (``fps``, 30 by default); an action's last frame is the next source
action's first frame, so consecutive actions of a take chain exactly.
"""
from __future__ import annotations

import hashlib
import io
import json
import math
import os
import struct
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Collection

import numpy as np

from motion_graph.atomic import atomic_write_bytes
from motion_graph.classify import (
    ATTACK_KINDS, DEFENCE_KINDS, KINDS, Annotation, ClassifyParams, annotate, load_label_file)
from motion_graph.errors import LibraryFormatError, MocapFormatError
from motion_graph.features import clip_features
from motion_graph.io import find_mocap_files, load_motion
from motion_graph.motion import Motion, forward_kinematics
from motion_graph.rotations import matrix_to_quat, quat_to_matrix, slerp_quats, wrap_angle, yaw_matrix
from motion_graph.segment import SegmentParams, segment_clip
from motion_graph.semantics import resolve_parts
from motion_graph.skeleton import Skeleton
from motion_graph.strikes import StrikeParams, detect_strikes, stance_offset

FORMAT = "igraph-fight/action-library"
VERSION = 1


@dataclass(frozen=True)
class LibraryParams:
    """Options of a library build (stored in the file)."""

    fps: float = 30.0
    next_method: str = "hubs"        # "hubs": pose clusters; "threshold": every pair under the threshold
    next_threshold_m: float = 0.20   # hubs: max mean joint distance within a pose cluster (m);
                                     # threshold: max end/start pose distance for a -> b (m)
    next_velocity_s: float = 0.05    # threshold method: joint velocity difference weighted by this (s)
    segment: SegmentParams = SegmentParams()
    strikes: StrikeParams = StrikeParams()
    classify: ClassifyParams = ClassifyParams()
    part_overrides: dict | None = None

    def to_json(self) -> dict:
        import dataclasses
        return json.loads(json.dumps(dataclasses.asdict(self), default=float))


@dataclass
class ActionLibrary:
    """Actions of one skeleton. Frame arrays are indexed by global frame; see ``frames(a)``.

    Attributes (A actions, F frames in total, J joints, S strikes, E transitions):
        skeleton, fps (frames/s), parts (semantic part -> joint).
        labels (A,) str; kinds (A,) int index into ``classify.KINDS``.
        sources (A,) str file path; src_start, src_end (A,) source frames; src_fps (A,);
        src_placement (A, 3): where the action starts in its take (pelvis x, z in metres above the
        take's floor, fighting direction in radians), so take = placement o action frame.
        frame_offsets (A+1,) int.
        rotations (F, J, 4) local joint quaternions (x, y, z, w); root_positions (F, 3) metres;
        local_translations (F, J, 3) or None.
        positions (F, J, 3): forward kinematics of the above (metres, action frame).
        path (F, 3): pelvis ground x, z (m) and fighting direction (rad) per frame, action frame.
        dx, dz, dheading (A,): end of ``path`` (m, m, rad); duration (A,) seconds.
        strike_offsets (A+1,), strike_joint, strike_kind, strike_w0, strike_w1, strike_peak (S,) int
            (frames relative to the action start, window [w0, w1)), strike_reach (S,) metres.
        defence_w0, defence_w1 (A,) int frames, -1 when the action is no defence.
        next_offsets (A+1,), next_ids (E,), next_cost (E,) metres: Next(a) as CSR.
        meta: provenance and build options.
    """

    skeleton: Skeleton
    fps: float
    parts: dict[str, int]
    labels: list[str]
    kinds: np.ndarray
    sources: list[str]
    src_start: np.ndarray
    src_end: np.ndarray
    src_fps: np.ndarray
    src_placement: np.ndarray
    frame_offsets: np.ndarray
    rotations: np.ndarray
    root_positions: np.ndarray
    local_translations: np.ndarray | None
    path: np.ndarray
    dx: np.ndarray
    dz: np.ndarray
    dheading: np.ndarray
    strike_offsets: np.ndarray
    strike_joint: np.ndarray
    strike_kind: np.ndarray
    strike_w0: np.ndarray
    strike_w1: np.ndarray
    strike_peak: np.ndarray
    strike_reach: np.ndarray
    defence_w0: np.ndarray
    defence_w1: np.ndarray
    next_offsets: np.ndarray
    next_ids: np.ndarray
    next_cost: np.ndarray
    meta: dict = field(default_factory=dict)
    positions: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.positions is None:
            self.positions = self._fk()

    # ----- basic views -------------------------------------------------------------------
    @property
    def n_actions(self) -> int:
        return len(self.labels)

    @property
    def n_frames(self) -> np.ndarray:
        """(A,) frames per action (including both boundary frames)."""
        return np.diff(self.frame_offsets)

    @property
    def duration(self) -> np.ndarray:
        """(A,) seconds per action."""
        return (self.n_frames - 1) / self.fps

    def frames(self, a: int) -> slice:
        return slice(int(self.frame_offsets[a]), int(self.frame_offsets[a + 1]))

    def next(self, a: int) -> np.ndarray:
        """Next(a): the actions that may follow a."""
        return self.next_ids[self.next_offsets[a]:self.next_offsets[a + 1]]

    def strikes(self, a: int) -> range:
        return range(int(self.strike_offsets[a]), int(self.strike_offsets[a + 1]))

    def is_attack(self, a: int) -> bool:
        return self.strike_offsets[a + 1] > self.strike_offsets[a]

    def is_defence(self, a: int) -> bool:
        return self.defence_w0[a] >= 0

    def label_counts(self) -> dict[str, int]:
        out: dict[str, int] = {}
        for l in self.labels:
            out[l] = out.get(l, 0) + 1
        return dict(sorted(out.items(), key=lambda kv: -kv[1]))

    def action_motion(self, a: int) -> Motion:
        """One action as a Motion in its start frame."""
        sl = self.frames(a)
        lt = None if self.local_translations is None else self.local_translations[sl].copy()
        return Motion(self.skeleton, self.rotations[sl].copy(), self.root_positions[sl].copy(), self.fps, lt,
                      f"{self.sources[a]}#{a}")

    def _fk(self) -> np.ndarray:
        t = (self.local_translations.copy() if self.local_translations is not None
             else np.broadcast_to(self.skeleton.offsets, (len(self.rotations),) + self.skeleton.offsets.shape).copy())
        t[:, 0] = self.root_positions
        return forward_kinematics(self.skeleton.parents, quat_to_matrix(self.rotations), t)[1]

    # ----- graph -------------------------------------------------------------------------
    def to_networkx(self):
        """The action graph as a networkx.DiGraph (nodes carry label and duration)."""
        import networkx as nx
        g = nx.DiGraph()
        for a in range(self.n_actions):
            g.add_node(a, label=self.labels[a], duration=float(self.duration[a]), source=Path(self.sources[a]).name)
        for a in range(self.n_actions):
            for e in range(self.next_offsets[a], self.next_offsets[a + 1]):
                g.add_edge(a, int(self.next_ids[e]), residual_m=float(self.next_cost[e]))
        return g

    def largest_scc(self) -> list[int]:
        import networkx as nx
        comps = list(nx.strongly_connected_components(self.to_networkx()))
        return sorted(max(comps, key=len)) if comps else []

    def graph_report(self) -> dict:
        scc = self.largest_scc()
        deg = np.diff(self.next_offsets)
        return {
            "n_actions": self.n_actions,
            "n_transitions": int(len(self.next_ids)),
            "mean_out_degree": float(deg.mean()) if len(deg) else 0.0,
            "dead_ends": int((deg == 0).sum()),
            "largest_scc_size": len(scc),
            "largest_scc_fraction": len(scc) / max(self.n_actions, 1),
            "worst_transition_residual_m": float(self.next_cost.max()) if len(self.next_cost) else 0.0,
        }

    def random_walk(self, n_actions: int, rng: np.random.Generator, start: int | None = None) -> list[int]:
        """A random walk through Next(a), restricted to the largest strongly connected component."""
        scc = set(self.largest_scc())
        a = int(rng.choice(sorted(scc))) if start is None else int(start)
        out = [a]
        while len(out) < n_actions:
            nxt = [int(b) for b in self.next(a) if int(b) in scc] or [int(b) for b in self.next(a)]
            if not nxt:
                raise ValueError(f"action {a} has no successor")
            a = int(rng.choice(nxt))
            out.append(a)
        return out

    # ----- playback ----------------------------------------------------------------------
    def sequence_motion(self, action_ids: list[int], blend_frames: int = 4,
                        start_xz: tuple[float, float] = (0.0, 0.0), start_heading: float = 0.0) -> Motion:
        """Play actions one after another in world coordinates (library fps).

        Each action's root placement continues from the previous one's end (its dx, dz, dheading);
        the boundary frame is shared, and the pose difference at each transition is blended
        away over the first ``blend_frames`` frames of the next action.
        """
        if not action_ids:
            raise ValueError("empty action sequence")
        rots, roots, lts = [], [], []
        x, z, h = float(start_xz[0]), float(start_xz[1]), float(start_heading)
        prev_last_rot = None
        prev_last_lt = None
        for k, a in enumerate(action_ids):
            sl = self.frames(a)
            rot = self.rotations[sl].copy()
            root = self.root_positions[sl].copy()
            lt = None if self.local_translations is None else self.local_translations[sl].copy()
            Ry = yaw_matrix(h)
            R = quat_to_matrix(rot[:, 0])
            rot[:, 0] = matrix_to_quat(Ry @ R)
            root = root @ Ry.T + np.array([x, 0.0, z])
            if prev_last_rot is not None and blend_frames > 0:
                nb = min(blend_frames, len(rot) - 1)
                w = (1.0 - (np.arange(nb) + 1) / (nb + 1))  # weight of the previous end pose
                for i in range(nb):
                    rot[i] = _slerp_pair(rot[i], prev_last_rot, w[i] if i > 0 else 1.0)
                if lt is not None and prev_last_lt is not None:
                    for i in range(nb):
                        wi = w[i] if i > 0 else 1.0
                        lt[i] = (1 - wi) * lt[i] + wi * prev_last_lt
            start = 0 if k == 0 else 1  # the boundary frame is shared
            rots.append(rot[start:])
            roots.append(root[start:])
            if lt is not None:
                lts.append(lt[start:])
            prev_last_rot = rot[-1]
            prev_last_lt = None if lt is None else lt[-1]
            c, s = np.cos(h), np.sin(h)
            x += c * self.dx[a] + s * self.dz[a]
            z += -s * self.dx[a] + c * self.dz[a]
            h = float(wrap_angle(h + self.dheading[a]))
        lt_all = np.concatenate(lts) if lts else None
        return Motion(self.skeleton, np.concatenate(rots), np.concatenate(roots), self.fps, lt_all,
                      f"sequence{list(action_ids)}")

    # ----- persistence -------------------------------------------------------------------
    _ARRAYS = ("kinds", "src_start", "src_end", "src_fps", "src_placement", "frame_offsets", "rotations", "root_positions", "path",
               "dx", "dz", "dheading", "strike_offsets", "strike_joint", "strike_kind", "strike_w0", "strike_w1",
               "strike_peak", "strike_reach", "defence_w0", "defence_w1", "next_offsets", "next_ids", "next_cost")

    def save(self, path: str | os.PathLike) -> None:
        """Write the library (.npz with a JSON header), atomically, with a content checksum."""
        atomic_write_bytes(path, self.to_bytes())

    def to_bytes(self) -> bytes:
        """The library file's bytes (what ``save`` writes)."""
        arrays = {k: np.asarray(getattr(self, k)) for k in self._ARRAYS}
        if self.local_translations is not None:
            arrays["local_translations"] = self.local_translations
        sk = self.skeleton
        arrays.update(skel_parents=sk.parents, skel_offsets=sk.offsets, skel_is_end_site=sk.is_end_site)
        header = {
            "format": FORMAT, "version": VERSION, "fps": self.fps, "labels": self.labels, "sources": self.sources,
            "parts": self.parts, "kinds_table": list(KINDS),
            "skeleton": {"names": list(sk.names), "channels": [list(c) for c in sk.channels],
                         "metres_per_unit": sk.metres_per_unit},
            "meta": self.meta, "checksum": _checksum(arrays),
        }
        buf = io.BytesIO()
        np.savez_compressed(buf, header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8), **arrays)
        return buf.getvalue()


def _slerp_pair(q_to: np.ndarray, q_from: np.ndarray, w_from: float) -> np.ndarray:
    """Per-joint slerp: weight w_from on q_from, the rest on q_to. (J, 4) arrays."""
    q = np.stack([q_from, q_to])  # (2, J, 4)
    return slerp_quats(q, np.array([0.0, 1.0]), np.array([1.0 - w_from]))[0]


def _checksum(arrays: dict[str, np.ndarray]) -> str:
    h = hashlib.sha256()
    for k in sorted(arrays):
        a = np.ascontiguousarray(arrays[k])
        h.update(k.encode())
        h.update(str(a.dtype).encode())
        h.update(str(a.shape).encode())
        h.update(a.tobytes())
    return h.hexdigest()


# ----- reading and validating library files (and other .npz files) without trusting them ----------
#: the most members an .npz file may hold
NPZ_MAX_MEMBERS = 256
#: the largest .npy header (the dict after the magic) of a member, bytes (numpy's own limit)
NPY_MAX_HEADER = 10_000
#: the largest JSON header of a library file, bytes
LIBRARY_HEADER_MAX_BYTES = 16 << 20
#: a library's members may declare at most this many times the file's size in all (plus
#: NPZ_INFLATION_SLACK); the CMU boxing library inflates 1.6 times
LIBRARY_MAX_INFLATION = 32.0
NPZ_INFLATION_SLACK = 1 << 20
_NPZ_MAX_DIRECTORY = NPZ_MAX_MEMBERS * 512   # bytes of zip central directory


@dataclass(frozen=True)
class NpyMember:
    """One array of an .npz file as its zip entry and .npy header declare it (nothing inflated)."""

    name: str
    shape: tuple[int, ...]
    dtype: np.dtype
    size: int  # declared uncompressed bytes of the member (the .npy header included)


def quote(value: object, limit: int = 80) -> str:
    """repr(value) cut to ``limit`` characters: how error messages quote what a file holds."""
    r = repr(value)
    return r if len(r) <= limit else r[:limit - 3] + "..."


def _why(e: BaseException) -> str:
    return quote(f"{type(e).__name__}: {e}")[1:-1]


def _zip_directory_size(fh, size: int) -> int | None:
    """Bytes of the zip central directory as the end record declares them (None: no end record)."""
    n = min(size, 22 + 65535)
    fh.seek(size - n)
    tail = fh.read(n)
    i = tail.rfind(b"PK\x05\x06")
    if i < 0 or len(tail) - i < 22:
        return None
    cd = struct.unpack("<I", tail[i + 12:i + 16])[0]
    j = tail.rfind(b"PK\x06\x06", 0, i)  # zip64 end record
    if j >= 0 and i - j >= 56:
        cd = max(cd, struct.unpack("<Q", tail[j + 40:j + 48])[0])
    return cd


def _npy_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, key: str, name: str, error) -> NpyMember:
    try:
        with zf.open(info) as f:
            pre = f.read(10)
            if len(pre) < 10 or pre[:6] != b"\x93NUMPY":
                raise error(name, f"{key}: not a .npy array")
            if pre[6] == 1:
                start, hlen = 10, struct.unpack("<H", pre[8:10])[0]
            elif pre[6] == 2:
                pre += f.read(2)
                start, hlen = 12, struct.unpack("<I", pre[8:12])[0]
            else:
                raise error(name, f"{key}: .npy format version {pre[6]} is not supported")
            if hlen > NPY_MAX_HEADER:
                raise error(name, f"{key}: .npy header of {hlen} bytes (at most {NPY_MAX_HEADER})")
            text = f.read(hlen)
    except LibraryFormatError:
        raise
    except Exception as e:  # BadZipFile, zlib.error, EOFError, OSError ...
        raise error(name, f"{key}: truncated or corrupted ({_why(e)})") from None
    if len(text) < hlen:
        raise error(name, f"{key}: truncated .npy header")
    read_header = np.lib.format.read_array_header_1_0 if pre[6] == 1 else np.lib.format.read_array_header_2_0
    try:
        shape, _, dtype = read_header(io.BytesIO(pre[8:start] + text), max_header_size=NPY_MAX_HEADER)
    except Exception as e:
        raise error(name, f"{key}: bad .npy header ({_why(e)})") from None
    if (dtype.hasobject or dtype.fields is not None or dtype.subdtype is not None or dtype.kind not in "biuf"
            or not dtype.isnative):
        raise error(name, f"{key}: dtype {quote(dtype.str)} is not a plain native number or boolean")
    if any(d < 0 for d in shape):
        raise error(name, f"{key}: negative shape {quote(shape)}")
    need = start + hlen + math.prod(shape) * dtype.itemsize
    if info.file_size != need:
        raise error(name, f"{key}: its zip entry declares {info.file_size} bytes, its .npy header "
                          f"{quote(shape)} {dtype} needs {need}")
    return NpyMember(key, tuple(int(d) for d in shape), dtype, int(info.file_size))


def _reject_constant(token: str):
    raise ValueError(f"{token} is not a number")


def _finite_float(token: str) -> float:
    x = float(token)
    if not math.isfinite(x):
        raise ValueError(f"{quote(token)} is not a finite number")
    return x


def _unique_keys(pairs: list) -> dict:
    d = {}
    for k, v in pairs:
        if k in d:
            raise ValueError(f"duplicate key {quote(k)}")
        d[k] = v
    return d


def parse_json_header(raw: bytes, name: str, error: type[LibraryFormatError] = LibraryFormatError) -> dict:
    """A file's JSON header (an object; no NaN, infinities or overflowing numbers, no duplicate
    keys) or ``error``."""
    try:
        header = json.loads(raw.decode("utf-8"), parse_constant=_reject_constant, parse_float=_finite_float,
                            object_pairs_hook=_unique_keys)
    except (UnicodeDecodeError, ValueError, RecursionError) as e:
        raise error(name, f"header: not valid JSON ({_why(e)})") from None
    if not isinstance(header, dict):
        raise error(name, "header: not a JSON object")
    return header


def read_npz(src: str | os.PathLike | bytes, name: str, what: str, *, max_header_bytes: int, max_inflation: float,
             check: Callable[[dict, dict[str, NpyMember]], None] | None = None,
             error: type[LibraryFormatError] = LibraryFormatError,
             only: Collection[str] | None = None) -> tuple[dict, dict[str, np.ndarray]]:
    """The JSON header and the arrays of an .npz file (np.savez), read without trusting it.

    Before anything is inflated: the file must be a zip archive (else "not an <what>") of at most
    NPZ_MAX_MEMBERS unencrypted ``.npy`` members, stored or deflated, one of them ``header``
    (uint8 JSON of at most ``max_header_bytes``); each member's declared size must be exactly what
    its .npy header's shape and dtype need (plain numbers or booleans: nothing to unpickle), and
    all together at most ``max_inflation`` times the file's size (+ NPZ_INFLATION_SLACK). Then
    ``check(header, members)`` vets the header and the declared shapes (raising ``error``); only
    then are the arrays read (``only``: just these), each stopped at its declared size and
    CRC-checked by zipfile. Any problem: ``error(name, problem)``, a one-line problem.
    """
    if isinstance(src, (bytes, bytearray, memoryview)):
        fh = io.BytesIO(bytes(src))
    else:
        try:
            fh = open(src, "rb")
        except OSError as e:
            raise error(name, f"cannot be read ({e.strerror or type(e).__name__})") from None
    with fh:
        size = fh.seek(0, 2)
        fh.seek(0)
        if fh.read(4) != b"PK\x03\x04":
            raise error(name, f"not an {what} ({'an empty file' if size == 0 else 'not a zip archive'})")
        directory = _zip_directory_size(fh, size)
        if directory is not None and directory > _NPZ_MAX_DIRECTORY:
            raise error(name, f"zip directory of {directory} bytes (at most {_NPZ_MAX_DIRECTORY})")
        fh.seek(0)
        try:
            zf = zipfile.ZipFile(fh)
        except Exception as e:  # BadZipFile, EOFError, OSError, ValueError, struct.error ...
            raise error(name, f"truncated or corrupted ({_why(e)})") from None
        with zf:
            infos = zf.infolist()
            if len(infos) > NPZ_MAX_MEMBERS:
                raise error(name, f"{len(infos)} zip members (at most {NPZ_MAX_MEMBERS})")
            keys: dict[str, zipfile.ZipInfo] = {}
            for info in infos:
                if not info.filename.endswith(".npy") or info.filename in ("/", ".npy"):
                    raise error(name, f"unexpected zip member {quote(info.filename)}")
                key = info.filename[:-4]
                if key in keys:
                    raise error(name, f"{quote(key)}: two zip members")
                if info.flag_bits & 0x1:
                    raise error(name, f"{quote(key)}: encrypted")
                if info.compress_type not in (zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED):
                    raise error(name, f"{quote(key)}: compression method {info.compress_type} is not supported")
                if info.compress_type == zipfile.ZIP_STORED and info.compress_size != info.file_size:
                    raise error(name, f"{quote(key)}: truncated or corrupted (stored sizes differ)")
                keys[key] = info
            if "header" not in keys:
                raise error(name, f"not an {what} (no header)")
            total = sum(i.file_size for i in infos)
            budget = int(max_inflation * size) + NPZ_INFLATION_SLACK
            if total > budget:
                raise error(name, f"members declare {total} bytes, more than the {budget} allowed for "
                                  f"a file of {size}")
            members = {k: _npy_member(zf, info, k, name, error) for k, info in keys.items()}
            h = members["header"]
            if h.dtype != np.uint8 or len(h.shape) != 1:
                raise error(name, f"header: dtype {h.dtype} with {len(h.shape)} dims (expected 1-d uint8)")
            if h.shape[0] > max_header_bytes:
                raise error(name, f"header: {h.shape[0]} bytes of JSON (at most {max_header_bytes})")

            def read(key: str) -> np.ndarray:
                try:
                    with zf.open(keys[key]) as f:
                        return np.lib.format.read_array(f, allow_pickle=False, max_header_size=NPY_MAX_HEADER)
                except Exception as e:  # BadZipFile (CRC), ValueError (EOF), zlib.error, OSError ...
                    raise error(name, f"{key}: truncated or corrupted ({_why(e)})") from None

            header = parse_json_header(read("header").tobytes(), name, error)
            if check is not None:
                check(header, members)
            arrays = {k: read(k) for k in keys if k != "header" and (only is None or k in only)}
    return header, arrays


def _check_library_members(header: dict, members: dict[str, NpyMember], name: str) -> None:
    """Format, version and the declared shapes and dtypes of a library file's members."""
    if header.get("format") != FORMAT:
        raise LibraryFormatError(name, f"not an igraph-fight action library (format {quote(header.get('format'))})")
    if header.get("version") != VERSION:
        raise LibraryFormatError(name, f"library version {quote(header.get('version'))} is not supported "
                                       f"(expected {VERSION}); rebuild it")
    need = set(ActionLibrary._ARRAYS) | {"skel_parents", "skel_offsets", "skel_is_end_site"}
    missing = sorted(need - set(members))
    if missing:
        raise LibraryFormatError(name, f"missing arrays: {', '.join(missing)}")
    extra = sorted(set(members) - need - {"header", "local_translations"})
    if extra:
        raise LibraryFormatError(name, f"unexpected array {quote(extra[0])}")
    A = members["kinds"].shape[0] if len(members["kinds"].shape) == 1 else -1
    F = members["rotations"].shape[0] if members["rotations"].shape else -1
    J = members["skel_parents"].shape[0] if len(members["skel_parents"].shape) == 1 else -1
    S = members["strike_joint"].shape[0] if len(members["strike_joint"].shape) == 1 else -1
    E = members["next_ids"].shape[0] if len(members["next_ids"].shape) == 1 else -1
    shapes = {
        "kinds": (A,), "src_start": (A,), "src_end": (A,), "src_fps": (A,), "src_placement": (A, 3),
        "frame_offsets": (A + 1,), "rotations": (F, J, 4), "root_positions": (F, 3), "path": (F, 3),
        "local_translations": (F, J, 3), "dx": (A,), "dz": (A,), "dheading": (A,), "strike_offsets": (A + 1,),
        "strike_joint": (S,), "strike_kind": (S,), "strike_w0": (S,), "strike_w1": (S,), "strike_peak": (S,),
        "strike_reach": (S,), "defence_w0": (A,), "defence_w1": (A,), "next_offsets": (A + 1,),
        "next_ids": (E,), "next_cost": (E,), "skel_parents": (J,), "skel_offsets": (J, 3), "skel_is_end_site": (J,),
    }
    floats = {"src_fps", "src_placement", "rotations", "root_positions", "path", "local_translations", "dx", "dz",
              "dheading", "strike_reach", "next_cost", "skel_offsets"}
    for k, m in members.items():
        if k == "header":
            continue
        kinds = "b" if k == "skel_is_end_site" else "f" if k in floats else "iu"
        if m.dtype.kind not in kinds or m.shape != shapes[k]:
            raise LibraryFormatError(name, f"{k}: shape {m.shape} {m.dtype} (expected {shapes[k]} of "
                                           f"{'bool' if kinds == 'b' else 'floats' if kinds == 'f' else 'ints'})")
    if A < 1 or J < 1:
        raise LibraryFormatError(name, "kinds, skel_parents: no actions or no joints")


def _library_fields(header: dict, name: str, A: int, J: int) -> None:
    """Types and ranges of a library header's fields."""
    def bad(what: str, problem: str):
        raise LibraryFormatError(name, f"{what}: {problem}")

    fps = header.get("fps")
    if isinstance(fps, bool) or not isinstance(fps, (int, float)) or not 0 < fps <= 10_000:
        bad("fps", f"{quote(fps)} is not a frame rate in (0, 10000]")
    for key in ("labels", "sources"):
        v = header.get(key)
        if not isinstance(v, list) or len(v) != A or not all(isinstance(s, str) for s in v):
            bad(key, f"not a list of {A} strings")
    bad_labels = [s for s in header["labels"] if s not in KINDS]
    if bad_labels:
        bad("labels", f"unknown label {quote(bad_labels[0])}")
    if list(header.get("kinds_table") or []) != list(KINDS):
        bad("kinds_table", "the label table differs from this version's; rebuild the library")
    parts = header.get("parts")
    if not isinstance(parts, dict) or not all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v < J
                                              for v in parts.values()):
        bad("parts", f"not a map of part names to joints in [0, {J})")
    sk = header.get("skeleton")
    if not isinstance(sk, dict):
        bad("skeleton", "not an object")
    names, channels, mpu = sk.get("names"), sk.get("channels"), sk.get("metres_per_unit")
    if not isinstance(names, list) or len(names) != J or not all(isinstance(s, str) for s in names):
        bad("skeleton.names", f"not a list of {J} strings")
    if (not isinstance(channels, list) or len(channels) != J
            or not all(isinstance(c, list) and all(isinstance(s, str) for s in c) for c in channels)):
        bad("skeleton.channels", f"not a list of {J} lists of strings")
    if isinstance(mpu, bool) or not isinstance(mpu, (int, float)) or not 0 < mpu < 1e6:
        bad("skeleton.metres_per_unit", f"{quote(mpu)} is not a positive scale")
    if not isinstance(header.get("meta", {}), dict):
        bad("meta", "not an object")


def _check_library_arrays(d: dict[str, np.ndarray], labels: list[str], name: str) -> None:
    """Ranges of a library's arrays: CSR offsets, indices, frame windows, finite values."""
    def bad(what: str, problem: str):
        raise LibraryFormatError(name, f"{what}: {problem}")

    def within(what: str, x: np.ndarray, lo, hi) -> None:  # every x in [lo, hi) (bounds may be arrays)
        x = np.asarray(x).reshape(-1)
        out = (x < lo) | (x >= hi)
        if out.any():
            i = int(np.argmax(out))
            lo_i, hi_i = np.broadcast_to(lo, x.shape)[i], np.broadcast_to(hi, x.shape)[i]
            bad(what, f"{x[i]} at [{i}] is outside [{lo_i}, {hi_i})")

    def offsets(what: str, off: np.ndarray, total: int, min_step: int = 0) -> None:
        off = off.astype(np.int64)
        if off[0] != 0 or off[-1] != total or np.any(np.diff(off) < min_step):
            bad(what, f"not offsets from 0 to {total} in steps of at least {min_step}")

    for k, v in d.items():
        if v.dtype.kind == "f" and not np.isfinite(v).all():
            i = int(np.argmax(~np.isfinite(v).reshape(-1)))
            bad(k, f"{v.reshape(-1)[i]} at [{i}] is not finite")
    A, F, J = len(d["kinds"]), len(d["rotations"]), len(d["skel_parents"])
    if len(labels) != A:
        bad("labels", f"{len(labels)} labels for {A} actions")
    norm = np.linalg.norm(d["rotations"], axis=-1).reshape(-1)
    off_unit = np.abs(norm - 1.0) > 0.01
    if off_unit.any():
        i = int(np.argmax(off_unit))
        bad("rotations", f"quaternion {i} has norm {norm[i]:.6g}, not 1")
    offsets("frame_offsets", d["frame_offsets"], F, 2)
    offsets("strike_offsets", d["strike_offsets"], len(d["strike_joint"]))
    offsets("next_offsets", d["next_offsets"], len(d["next_ids"]))
    within("next_ids", d["next_ids"], 0, A)
    within("kinds", d["kinds"], 0, len(KINDS))
    wrong = np.nonzero(d["kinds"] != np.array([KINDS.index(s) if s in KINDS else -1 for s in labels]))[0]
    if len(wrong):
        bad("kinds", f"{d['kinds'][wrong[0]]} at [{wrong[0]}] is not the kind of its label {quote(labels[wrong[0]])}")
    within("strike_joint", d["strike_joint"], 0, J)
    within("strike_kind", d["strike_kind"], 0, len(KINDS))
    n = np.diff(d["frame_offsets"].astype(np.int64))
    n_of = np.repeat(n, np.diff(d["strike_offsets"].astype(np.int64)))
    w0, w1 = d["strike_w0"].astype(np.int64), d["strike_w1"].astype(np.int64)
    within("strike_w0", w0, 0, n_of)
    within("strike_w1", w1, w0 + 1, n_of + 1)  # w0 < w1 <= frames of the action
    within("strike_peak", d["strike_peak"], 0, n_of)
    d0, d1 = d["defence_w0"].astype(np.int64), d["defence_w1"].astype(np.int64)
    none = d0 < 0
    if np.any(d0 < -1) or np.any(none & (d1 != -1)) or np.any(~none & (d1 <= d0)):
        bad("defence_w0", "defence windows must be -1, -1 or 0 <= w0 < w1")
    within("strike_reach", d["strike_reach"], 0, np.inf)
    within("next_cost", d["next_cost"], 0, np.inf)
    within("src_fps", d["src_fps"], 1e-9, np.inf)
    p = d["skel_parents"].astype(np.int64)
    if p[0] != -1 or np.any(p[1:] < -1) or np.any(p[1:] >= np.arange(1, J)):
        bad("skel_parents", "not parent indices with the root first and parents before children")


def load_library(path: str | os.PathLike) -> ActionLibrary:
    """Read and validate a library file (LibraryFormatError on any problem): bounded reading
    (``read_npz``), checksum, and every header field and array range-checked."""
    path = str(path)
    if not os.path.exists(path):
        raise LibraryFormatError(path, "no such file")
    return _load_library(path, path)


def library_from_bytes(data: bytes, name: str = "<embedded library>") -> ActionLibrary:
    """A library from the bytes of a library file (e.g. embedded in a graph file), validated as
    ``load_library`` does."""
    return _load_library(bytes(data), name)


def _load_library(src: str | bytes, path: str) -> ActionLibrary:
    header, data = read_npz(src, path, "igraph-fight action library", max_header_bytes=LIBRARY_HEADER_MAX_BYTES,
                            max_inflation=LIBRARY_MAX_INFLATION,
                            check=lambda h, m: _check_library_members(h, m, path))
    if _checksum(data) != header.get("checksum"):
        raise LibraryFormatError(path, "checksum mismatch: the file is corrupted")
    A, J = len(data["kinds"]), len(data["skel_parents"])
    _library_fields(header, path, A, J)
    _check_library_arrays(data, header["labels"], path)
    s = header["skeleton"]
    try:  # everything was checked above; a ValueError here would still be the file's
        sk = Skeleton(tuple(s["names"]), data.pop("skel_parents"), data.pop("skel_offsets"),
                      tuple(tuple(c) for c in s["channels"]), data.pop("skel_is_end_site"), float(s["metres_per_unit"]))
        lt = data.pop("local_translations", None)
        return ActionLibrary(skeleton=sk, fps=float(header["fps"]), parts={k: int(v) for k, v in header["parts"].items()},
                             labels=list(header["labels"]), sources=list(header["sources"]), local_translations=lt,
                             meta=header.get("meta", {}), **{k: data[k] for k in ActionLibrary._ARRAYS})
    except ValueError as e:
        raise LibraryFormatError(path, f"arrays: {_why(e)}") from None


def validate_library(lib: ActionLibrary, name: str = "<library>") -> None:
    """Raise LibraryFormatError unless an ActionLibrary's arrays are in range (what load_library checks)."""
    d = {k: np.asarray(getattr(lib, k)) for k in ActionLibrary._ARRAYS}
    d.update(skel_parents=np.asarray(lib.skeleton.parents), skel_offsets=np.asarray(lib.skeleton.offsets))
    if lib.local_translations is not None:
        d["local_translations"] = np.asarray(lib.local_translations)
    _check_library_arrays(d, list(lib.labels), name)


# ----- building ----------------------------------------------------------------------------

def _resample_exact(m: Motion, a: int, b: int, n: int) -> Motion:
    """Frames a..b (inclusive, source rate) resampled to exactly n frames spanning the same interval."""
    t_src = np.arange(m.n_frames) / m.fps
    t_dst = np.linspace(a / m.fps, b / m.fps, n)
    rot = slerp_quats(m.rotations, t_src, t_dst)
    root = np.stack([np.interp(t_dst, t_src, m.root_positions[:, k]) for k in range(3)], axis=-1)
    lt = None
    if m.local_translations is not None:
        flat = m.local_translations.reshape(m.n_frames, -1)
        lt = np.stack([np.interp(t_dst, t_src, flat[:, k]) for k in range(flat.shape[1])], axis=-1).reshape(n, -1, 3)
    return Motion(m.skeleton, rot, root, n and (n - 1) / max((b - a) / m.fps, 1e-9), lt, m.source)


@dataclass
class ClipResult:
    """Everything the segmentation of one file produced (for plots and reports)."""

    path: str
    motion: Motion
    features: object
    strikes: list
    offset: float
    segmentation: object
    annotations: list[Annotation]


def segment_file(path: str | os.PathLike, params: LibraryParams = LibraryParams(),
                 fps_override: float | None = None) -> ClipResult:
    """Load one file, find its strikes, cut it into actions and annotate them."""
    return segment_motion(load_motion(path, fps=fps_override), path, params)


def segment_motion(m: Motion, path: str | os.PathLike, params: LibraryParams = LibraryParams()) -> ClipResult:
    """Find a loaded motion's strikes, cut it into actions and annotate them (``path``: its source)."""
    feat = clip_features(m, params.part_overrides)
    strikes = detect_strikes(feat, params.strikes)
    seg = segment_clip(feat, strikes, params.segment)
    offset = stance_offset(strikes, feat, seg.cuts)
    anns = [annotate(feat, strikes, a, b, offset, params.classify)
            for a, b in zip(seg.cuts[:-1].tolist(), seg.cuts[1:].tolist())]
    return ClipResult(str(path), m, feat, strikes, offset, seg, anns)


def segment_files(files: list[str | os.PathLike], params: LibraryParams = LibraryParams(),
                  progress: bool = False, fps_override: float | None = None) -> list[ClipResult]:
    """segment_file for every mocap file in files/folders (one skeleton required)."""
    paths = find_mocap_files(list(files))
    if not paths:
        raise MocapFormatError(", ".join(str(f) for f in files), "no .bvh or .amc files found")
    it = paths
    if progress:
        from tqdm import tqdm
        it = tqdm(paths, desc="segment", unit="file")
    out: list[ClipResult] = []
    for f in it:
        r = segment_file(f, params, fps_override)
        if out and r.motion.skeleton.names != out[0].motion.skeleton.names:
            raise MocapFormatError(str(f), f"skeleton differs from {out[0].path}; build one library per skeleton")
        out.append(r)
    return out


def build_library(files: list[str | os.PathLike], params: LibraryParams = LibraryParams(),
                  labels_file: str | os.PathLike | None = None, progress: bool = False,
                  fps_override: float | None = None) -> ActionLibrary:
    """Segment, classify and annotate mocap files of one skeleton into an ActionLibrary.

    Args:
        files: BVH / AMC files or folders (folders are searched recursively).
        params: build options.
        labels_file: user labels that override the automatic ones (see classify.load_label_file).
        progress: show a progress bar.
        fps_override: override the source files' frame rate.
    """
    clips = segment_files(files, params, progress, fps_override)
    return library_from_clips(clips, params, labels_file)


def library_from_clips(clips: list[ClipResult], params: LibraryParams = LibraryParams(),
                       labels_file: str | os.PathLike | None = None) -> ActionLibrary:
    """Assemble segmented clips into a library, applying user labels."""
    user = load_label_file(labels_file) if labels_file else {}
    rows = []
    fps = params.fps
    for c in clips:
        m = c.motion
        for (a, b), ann in zip(zip(c.segmentation.cuts[:-1].tolist(), c.segmentation.cuts[1:].tolist()),
                               c.annotations):
            key = (Path(c.path).name, a)
            n = max(2, int(round((b - a) / m.fps * fps)) + 1)
            rows.append(dict(src=c.path, a=a, b=b, src_fps=m.fps, n=n, ann=ann, label=user.get(key, ann.label),
                             motion=m, feat=c.features, offset=c.offset, user=key in user))
    skel = clips[0].motion.skeleton
    parts = resolve_parts(skel, params.part_overrides)
    lib = _assemble(skel, parts, rows, params)
    lib.meta["sources"] = {c.path: _file_sha256(c.path) for c in clips}
    return lib


def _file_sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _assemble(skel: Skeleton, parts: dict[str, int], rows: list[dict], params: LibraryParams) -> ActionLibrary:
    fps = params.fps
    rots, roots, lts, paths, placements = [], [], [], [], []
    offsets = [0]
    st_off, st_joint, st_kind, st_w0, st_w1, st_peak, st_reach = [0], [], [], [], [], [], []
    d_w0, d_w1 = [], []
    dxs, dzs, dhs = [], [], []
    for r in rows:
        m, feat, a, b, n = r["motion"], r["feat"], r["a"], r["b"], r["n"]
        clip = _resample_exact(m, a, b, n)
        t_src = np.arange(feat.n_frames) / feat.fps
        t_dst = np.linspace(a / m.fps, b / m.fps, n)
        pel = clip.positions()[:, parts["pelvis"]]  # exact (unsmoothed) pelvis at library frames
        px, pz = pel[:, 0], pel[:, 2]
        ph = np.interp(t_dst, t_src, feat.facing) + r["offset"]
        h0 = ph[0]
        Ryi = yaw_matrix(-h0)
        origin = np.array([px[0], feat.floor_y, pz[0]])
        root = (clip.root_positions - origin) @ Ryi.T
        R = quat_to_matrix(clip.rotations[:, 0])
        rot = clip.rotations.copy()
        rot[:, 0] = matrix_to_quat(Ryi @ R)
        c, s = np.cos(h0), np.sin(h0)
        gx, gz = px - px[0], pz - pz[0]
        path = np.stack([c * gx - s * gz, s * gx + c * gz, ph - h0], axis=1)
        placements.append((px[0], pz[0], h0))
        rots.append(rot)
        roots.append(root)
        if clip.local_translations is not None:
            lts.append(clip.local_translations)
        paths.append(path)
        offsets.append(offsets[-1] + n)
        dxs.append(path[-1, 0])
        dzs.append(path[-1, 1])
        dhs.append(float(wrap_angle(path[-1, 2])))
        scale = (n - 1) / max(b - a, 1)  # source frames -> library frames
        ann: Annotation = r["ann"]
        label = r["label"]
        strikes = ann.strikes if label in ATTACK_KINDS or not r["user"] else []
        for limb, kind, w0, w1, pk, reach in strikes:
            st_joint.append(parts[limb])
            st_kind.append(KINDS.index(label if r["user"] and label in ATTACK_KINDS else kind))
            lw0 = int(np.floor(w0 * scale))
            lw1 = max(lw0 + 1, int(np.ceil(w1 * scale)))
            st_w0.append(min(lw0, n - 1))
            st_w1.append(min(lw1, n))
            st_peak.append(min(int(round(pk * scale)), n - 1))
            st_reach.append(reach)
        st_off.append(len(st_joint))
        if ann.defence is not None and label in DEFENCE_KINDS:
            d_w0.append(int(np.floor(ann.defence[0] * scale)))
            d_w1.append(max(int(np.floor(ann.defence[0] * scale)) + 1, int(np.ceil(ann.defence[1] * scale))))
        else:
            d_w0.append(-1)
            d_w1.append(-1)
    lib = ActionLibrary(
        skeleton=skel, fps=fps, parts=parts, labels=[r["label"] for r in rows],
        kinds=np.array([KINDS.index(r["label"]) for r in rows], dtype=np.int32),
        sources=[r["src"] for r in rows], src_start=np.array([r["a"] for r in rows], dtype=np.int64),
        src_end=np.array([r["b"] for r in rows], dtype=np.int64),
        src_fps=np.array([r["src_fps"] for r in rows], dtype=np.float64),
        src_placement=np.array(placements, dtype=np.float64),
        frame_offsets=np.array(offsets, dtype=np.int64), rotations=np.concatenate(rots),
        root_positions=np.concatenate(roots), local_translations=np.concatenate(lts) if lts else None,
        path=np.concatenate(paths), dx=np.array(dxs), dz=np.array(dzs), dheading=np.array(dhs),
        strike_offsets=np.array(st_off, dtype=np.int64), strike_joint=np.array(st_joint, dtype=np.int32),
        strike_kind=np.array(st_kind, dtype=np.int32), strike_w0=np.array(st_w0, dtype=np.int32),
        strike_w1=np.array(st_w1, dtype=np.int32), strike_peak=np.array(st_peak, dtype=np.int32),
        strike_reach=np.array(st_reach, dtype=np.float64),
        defence_w0=np.array(d_w0, dtype=np.int32), defence_w1=np.array(d_w1, dtype=np.int32),
        next_offsets=np.zeros(len(rows) + 1, dtype=np.int64), next_ids=np.zeros(0, dtype=np.int32),
        next_cost=np.zeros(0), meta={"params": params.to_json()},
    )
    from motion_graph.action_graph import compute_next, compute_next_hubs
    if params.next_method == "hubs":
        compute_next_hubs(lib, params.next_threshold_m)
    elif params.next_method == "threshold":
        compute_next(lib, params.next_threshold_m, params.next_velocity_s)
    else:
        raise ValueError(f"unknown next_method {params.next_method!r} (hubs or threshold)")
    return lib
