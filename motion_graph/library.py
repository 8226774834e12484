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
import os
from dataclasses import dataclass, field
from pathlib import Path

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


def load_library(path: str | os.PathLike) -> ActionLibrary:
    """Read and validate a library file (LibraryFormatError on any problem)."""
    path = str(path)
    if not os.path.exists(path):
        raise LibraryFormatError(path, "no such file")
    return _load_library(path, path)


def library_from_bytes(data: bytes, name: str = "<embedded library>") -> ActionLibrary:
    """A library from the bytes of a library file (e.g. embedded in a graph file)."""
    return _load_library(io.BytesIO(data), name)


def _load_library(src, path: str) -> ActionLibrary:
    try:
        with np.load(src, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except Exception as e:  # zipfile.BadZipFile, EOFError, ValueError, OSError ...
        raise LibraryFormatError(path, f"not a readable action-library file (truncated or corrupted?): {e}") from None
    if "header" not in data:
        raise LibraryFormatError(path, "no header: not an igraph-fight action library")
    try:
        header = json.loads(bytes(data.pop("header")).decode())
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise LibraryFormatError(path, "header is corrupted") from None
    if header.get("format") != FORMAT:
        raise LibraryFormatError(path, f"not an action library (format {header.get('format')!r})")
    if header.get("version") != VERSION:
        raise LibraryFormatError(path, f"library version {header.get('version')} is not supported (expected {VERSION}); rebuild it")
    missing = [k for k in ActionLibrary._ARRAYS + ("skel_parents", "skel_offsets", "skel_is_end_site") if k not in data]
    if missing:
        raise LibraryFormatError(path, f"missing arrays: {', '.join(missing)}")
    if _checksum(data) != header.get("checksum"):
        raise LibraryFormatError(path, "checksum mismatch: the file is corrupted")
    if list(header.get("kinds_table", [])) != list(KINDS):
        raise LibraryFormatError(path, "the label table differs from this version's; rebuild the library")
    s = header["skeleton"]
    sk = Skeleton(tuple(s["names"]), data.pop("skel_parents"), data.pop("skel_offsets"),
                  tuple(tuple(c) for c in s["channels"]), data.pop("skel_is_end_site"), float(s["metres_per_unit"]))
    lt = data.pop("local_translations", None)
    lib = ActionLibrary(skeleton=sk, fps=float(header["fps"]), parts={k: int(v) for k, v in header["parts"].items()},
                        labels=list(header["labels"]), sources=list(header["sources"]), local_translations=lt,
                        meta=header.get("meta", {}), **{k: data[k] for k in ActionLibrary._ARRAYS})
    A = lib.n_actions
    if len(lib.frame_offsets) != A + 1 or lib.frame_offsets[-1] != len(lib.rotations):
        raise LibraryFormatError(path, "inconsistent frame offsets")
    if len(lib.next_offsets) != A + 1 or (len(lib.next_ids) and lib.next_ids.max() >= A):
        raise LibraryFormatError(path, "inconsistent transition table")
    return lib


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
    m = load_motion(path, fps=fps_override)
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
