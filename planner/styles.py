"""Fighting styles: the weights of the Eq. 4 reward family, presets and user style files.

A style file is TOML or JSON with the fields of :class:`Style` at the top level (``kind_pref`` a
table/object ``attack kind -> multiplier``) and an optional ``base`` naming a preset (or another
style file, relative to this one) whose values it starts from::

    name = "southpaw_counter"
    base = "outboxer"            # optional: start from a preset
    d_p = 1.2                    # metres
    w_dmg_received = 20.0
    [kind_pref]
    straight = 2.0

Every error in a style file raises :class:`StyleError`, which names the file and the field.
"""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

#: Attack kind names, mirroring ``motion_graph.classify.ATTACK_KINDS`` (hard-coded here so that
#: planner stays a leaf package; keep the two in step).
ATTACK_KINDS: tuple[str, ...] = ("jab", "straight", "hook", "uppercut", "kick")

#: Which edge feature gives the distance r of Eq. 4.
DISTANCE_FEATURES: dict[str, str] = {"end": "feat_r", "mean": "feat_r_mean"}

_PRESET_PACKAGE = "planner.presets"


class StyleError(ValueError):
    """A style (file) is invalid. ``path`` is the file (or ``<Style>``), ``field`` the offending field."""

    def __init__(self, path: str, field: str | None, problem: str) -> None:
        self.path = str(path)
        self.field = field
        self.problem = problem
        where = f"{self.path}: field {field!r}" if field else self.path
        super().__init__(f"{where}: {problem}")


@dataclass(frozen=True)
class Style:
    """Weights of the fighting reward (Eq. 4 family, see :mod:`planner.rewards`).

    r = -w_theta*theta_self^2 - w_d*(r - d_p)^2 + w_dmg_given*D+*kind_pref[kind]
        - w_dmg_received*D- + w_def*def_self        (angles rad, distances m)

    Attributes:
        name: style name.
        d_p: preferred distance to the opponent, metres (> 0).
        w_theta: weight per rad^2 of the fighter's own facing error (>= 0).
        w_d: weight per m^2 of distance error (>= 0).
        w_dmg_given: weight per unit of damage dealt (>= 0), multiplied by ``kind_pref`` of the
            attack that dealt it.
        w_dmg_received: weight per unit of damage taken (>= 0).
        w_def: bonus per opponent attack avoided by the fighter's own defence (>= 0).
        kind_pref: attack kind (one of :data:`ATTACK_KINDS`) -> multiplier (>= 0) on D+; kinds not
            listed count 1.0.
        per_second: when True the facing and distance terms are multiplied by the edge duration
            (s), i.e. they become penalties per second instead of per decision.
        distance: ``"end"`` uses the distance at the next decision (feat_r, the paper), ``"mean"``
            the mean over the edge (feat_r_mean).
        description: free text.
    """

    name: str
    d_p: float
    w_theta: float = 0.5
    w_d: float = 3.0
    w_dmg_given: float = 10.0
    w_dmg_received: float = 10.0
    w_def: float = 0.0
    kind_pref: Mapping[str, float] = field(default_factory=dict)
    per_second: bool = False
    distance: str = "end"
    description: str = ""

    def __post_init__(self) -> None:
        clean = _validate({f.name: getattr(self, f.name) for f in fields(self)}, "<Style>")
        for k, v in clean.items():
            object.__setattr__(self, k, v)
        object.__setattr__(self, "kind_pref", MappingProxyType(dict(clean["kind_pref"])))

    def __hash__(self) -> int:
        d = self.to_dict()
        d["kind_pref"] = tuple(sorted(d["kind_pref"].items()))
        return hash(tuple(d.items()))

    def pref(self, kind: str) -> float:
        """Multiplier on damage dealt by an attack of this kind (1.0 when not listed)."""
        return float(self.kind_pref.get(kind, 1.0))

    def to_dict(self) -> dict[str, Any]:
        """Plain dict with the fields of a style file."""
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["kind_pref"] = dict(self.kind_pref)
        return d


_FLOAT_FIELDS = ("d_p", "w_theta", "w_d", "w_dmg_given", "w_dmg_received", "w_def")
_KNOWN = {f.name for f in fields(Style)}


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _validate(d: Mapping[str, Any], path: str, partial: bool = False) -> dict[str, Any]:
    """Check a style's fields; return a cleaned copy. Raises StyleError naming the field.

    ``partial``: a file with a ``base`` may leave out required fields.
    """
    for k in d:
        if k not in _KNOWN:
            raise StyleError(path, str(k), f"unknown field; known: {', '.join(sorted(_KNOWN))}")
    if not partial and "name" not in d:
        raise StyleError(path, "name", "missing")
    if not partial and "d_p" not in d:
        raise StyleError(path, "d_p", "missing (preferred distance in metres)")
    out = dict(d)
    if "name" in d and (not isinstance(d["name"], str) or not d["name"].strip()):
        raise StyleError(path, "name", f"must be a non-empty string, got {d['name']!r}")
    for k in _FLOAT_FIELDS:
        if k not in d:
            continue
        v = d[k]
        if not _is_number(v):
            raise StyleError(path, k, f"must be a number, got {type(v).__name__} {v!r}")
        if not math.isfinite(v):
            raise StyleError(path, k, f"must be finite, got {v!r}")
        if k == "d_p" and v <= 0:
            raise StyleError(path, k, f"preferred distance must be > 0 metres, got {v!r}")
        if v < 0:
            raise StyleError(path, k, f"weights must be >= 0 (the sign is in the formula), got {v!r}")
        out[k] = float(v)
    if "kind_pref" in d:
        kp = d["kind_pref"]
        if not isinstance(kp, Mapping):
            raise StyleError(path, "kind_pref", f"must be a table attack kind -> number, got {type(kp).__name__}")
        clean: dict[str, float] = {}
        for kind, v in kp.items():
            fname = f"kind_pref.{kind}"
            if kind not in ATTACK_KINDS:
                raise StyleError(path, fname, f"unknown attack kind; known: {', '.join(ATTACK_KINDS)}")
            if not _is_number(v) or not math.isfinite(v) or v < 0:
                raise StyleError(path, fname, f"must be a finite number >= 0, got {v!r}")
            clean[kind] = float(v)
        out["kind_pref"] = clean
    elif not partial:
        out["kind_pref"] = {}
    if "per_second" in d and not isinstance(d["per_second"], bool):
        raise StyleError(path, "per_second", f"must be true or false, got {d['per_second']!r}")
    if "distance" in d and d["distance"] not in DISTANCE_FEATURES:
        raise StyleError(path, "distance", f"must be one of {', '.join(DISTANCE_FEATURES)}, got {d['distance']!r}")
    if "description" in d and not isinstance(d["description"], str):
        raise StyleError(path, "description", f"must be a string, got {type(d['description']).__name__}")
    return out


def style_from_dict(d: Mapping[str, Any], source: str = "<dict>") -> Style:
    """Build a :class:`Style` from a dict of style-file fields (no ``base``); errors name ``source``."""
    clean = _validate(d, source)
    return Style(**clean)


def list_presets() -> list[str]:
    """Names of the shipped preset styles."""
    root = resources.files(_PRESET_PACKAGE)
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def _read_raw(path: Path, source: str) -> dict[str, Any]:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise StyleError(source, None, f"cannot read: {exc}") from exc
    suffix = path.suffix.lower()
    try:
        if suffix == ".toml":
            raw = tomllib.loads(data.decode("utf-8"))
        elif suffix == ".json":
            raw = json.loads(data.decode("utf-8"))
        else:
            raise StyleError(source, None, "style files must end in .toml or .json")
    except (tomllib.TOMLDecodeError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise StyleError(source, None, f"not valid {suffix[1:].upper()}: {exc}") from exc
    if not isinstance(raw, dict):
        raise StyleError(source, None, "top level must be a table/object")
    return raw


def _load_raw(path: Path, source: str, seen: tuple[str, ...]) -> dict[str, Any]:
    """Read a style file and merge it over its ``base`` (recursively)."""
    raw = _read_raw(path, source)
    base = raw.pop("base", None)
    _validate(raw, source, partial=True)  # errors name the file that holds the bad field
    if base is None:
        return raw
    if not isinstance(base, str) or not base:
        raise StyleError(source, "base", f"must be a preset name or a style file path, got {base!r}")
    if base in list_presets():
        bpath, bsource = None, f"preset {base!r}"
    else:
        bpath = (path.parent / base).resolve()
        bsource = str(bpath)
        if not bpath.is_file():
            raise StyleError(source, "base", f"neither a preset ({', '.join(list_presets())}) nor a file: {base!r}")
    if bsource in seen:
        raise StyleError(source, "base", f"circular base chain: {' -> '.join(seen + (bsource,))}")
    if bpath is None:
        with resources.as_file(resources.files(_PRESET_PACKAGE) / f"{base}.toml") as p:
            merged = _load_raw(Path(p), bsource, seen + (bsource,))
    else:
        merged = _load_raw(bpath, bsource, seen + (bsource,))
    kp = dict(merged.get("kind_pref", {}))
    if isinstance(raw.get("kind_pref"), Mapping):
        kp.update(raw["kind_pref"])
        raw["kind_pref"] = kp
    merged.update(raw)
    return merged


def load_style(path_or_name: str | Path) -> Style:
    """Load a style: a preset name (``infighter``, ``outboxer``, ``balanced``) or a .toml/.json file.

    Raises:
        StyleError: the file is missing, unreadable, malformed, or a field is unknown, of the wrong
            type, out of range (negative weight, d_p <= 0) or names an unknown attack kind. The
            message names the file and the field.
    """
    s = str(path_or_name)
    presets = ", ".join(list_presets())
    if not s.strip():
        raise StyleError("<style>", None, f"empty style name: give a preset ({presets}) or a .toml/.json style file")
    p = Path(s)
    path_like = "/" in s or p.suffix.lower() in (".toml", ".json")
    if not path_like and not p.suffix and not p.exists():
        if s not in list_presets():
            raise StyleError(s, None, f"unknown style: not a preset ({presets}) nor a .toml/.json style file")
        with resources.as_file(resources.files(_PRESET_PACKAGE) / f"{s}.toml") as pp:
            return style_from_dict(_load_raw(Path(pp), f"preset {s!r}", ()), f"preset {s!r}")
    if not p.is_file():
        if path_like:
            raise StyleError(s, None, f"no such file (a style file path was given; presets: {presets})")
        raise StyleError(s, None, f"unknown style: not a preset ({presets}) nor a .toml/.json style file")
    return style_from_dict(_load_raw(p, s, (str(p.resolve()),)), s)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(float(v))
    return json.dumps(str(v))  # a JSON string is a valid TOML basic string


def save_style(style: Style, path: str | Path) -> None:
    """Write a style to a .toml or .json file that :func:`load_style` reads back unchanged."""
    p = Path(path)
    d = style.to_dict()
    if p.suffix.lower() == ".json":
        p.write_text(json.dumps(d, indent=2) + "\n", encoding="utf-8")
        return
    if p.suffix.lower() != ".toml":
        raise StyleError(str(p), None, "style files must end in .toml or .json")
    kp = d.pop("kind_pref")
    lines = [f"{k} = {_toml_value(v)}" for k, v in d.items()]
    lines += ["", "[kind_pref]"] + [f"{k} = {_toml_value(v)}" for k, v in kp.items()]
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
