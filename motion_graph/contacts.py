"""Foot contacts from sole height and horizontal speed, with hysteresis."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion_graph.features import ClipFeatures


@dataclass(frozen=True)
class ContactParams:
    """Thresholds in metres and metres per second (independent of the frame rate)."""

    height_on: float = 0.04    # planted when the sole is below this ...
    speed_on: float = 0.30     # ... and slower than this
    height_off: float = 0.06   # released when above this ...
    speed_off: float = 0.50    # ... or faster than this
    min_run_s: float = 0.03    # contact/flight runs shorter than this are absorbed


def _hysteresis(on: np.ndarray, off: np.ndarray) -> np.ndarray:
    state = bool(on[0])
    out = np.empty(len(on), bool)
    for t in range(len(on)):
        if state and off[t]:
            state = False
        elif not state and on[t]:
            state = True
        out[t] = state
    return out


def _absorb_short(x: np.ndarray, min_len: int) -> np.ndarray:
    x = x.copy()
    if min_len <= 1:
        return x
    t = 0
    n = len(x)
    while t < n:
        u = t
        while u < n and x[u] == x[t]:
            u += 1
        if u - t < min_len and t > 0 and u < n:
            x[t:u] = x[t - 1]
        t = u
    return x


def foot_contacts(feat: ClipFeatures, params: ContactParams = ContactParams()) -> np.ndarray:
    """(T, 2) bool: left/right foot planted."""
    out = np.empty((feat.n_frames, 2), bool)
    min_len = max(1, int(round(params.min_run_s * feat.fps)))
    for k in range(2):
        h, v = feat.foot_height[:, k], feat.foot_speed[:, k]
        on = (h < params.height_on) & (v < params.speed_on)
        off = (h > params.height_off) | (v > params.speed_off)
        out[:, k] = _absorb_short(_hysteresis(on, off), min_len)
    return out


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) intervals where mask is True."""
    m = np.concatenate([[False], mask.astype(bool), [False]])
    d = np.diff(m.astype(np.int8))
    starts = np.nonzero(d == 1)[0]
    stops = np.nonzero(d == -1)[0]
    return list(zip(starts.tolist(), stops.tolist()))


def contact_summary(contacts: np.ndarray, fps: float) -> dict:
    """Shares of frames with double support, single support and flight, and double-support interval stats."""
    both = contacts.all(axis=1)
    none = ~contacts.any(axis=1)
    ds = runs(both)
    lens = np.array([b - a for a, b in ds], float) / fps
    return {
        "double_support_share": float(both.mean()),
        "single_support_share": float((~both & ~none).mean()),
        "flight_share": float(none.mean()),
        "double_support_intervals": len(ds),
        "double_support_median_s": float(np.median(lens)) if len(lens) else 0.0,
        "double_support_per_s": len(ds) / max((len(contacts) - 1) / fps, 1e-9),
    }
