"""Cut a clip into actions at quiet double-support moments, never inside a strike.

Measured on the CMU boxing takes: strict double-support instants come
about 2.5 times a second for this bouncing boxer, so cutting at each over-segments and halves
punches. A cut is allowed only where both feet are planted, no strike is under way, both fists
are back near guard, and the body is quiet (a local minimum of fist + pelvis + foot speed over a
window). Pieces holding two strikes far apart are then split between them, long pieces are
split at their quietest allowed frame, and pieces shorter than the minimum are merged.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from motion_graph.contacts import ContactParams, foot_contacts, runs
from motion_graph.features import ClipFeatures
from motion_graph.strikes import Strike


@dataclass(frozen=True)
class SegmentParams:
    """Knobs in seconds, m/s and fractions of arm length. quiet_window_s sets the action rate."""

    quiet_window_s: float = 0.30   # a cut is a local minimum of quietness within +-this
    min_action_s: float = 0.30     # shorter pieces are merged into a neighbour
    max_action_s: float = 2.0      # longer pieces are split at their quietest allowed frame
    guard_reach: float = 0.72      # both fists closer to their shoulders than this (fraction of arm)
    split_strikes_s: float = 0.45  # a piece with two strike peaks this far apart is split between them
    contacts: ContactParams = ContactParams()


@dataclass(frozen=True)
class Segmentation:
    """Cut frames of one clip: actions are [cuts[i], cuts[i+1]] (sharing the boundary frame)."""

    cuts: np.ndarray          # (K+1,) increasing frame indices, first 0, last T-1
    contacts: np.ndarray      # (T, 2) foot contacts
    quietness: np.ndarray     # (T,) summed speeds, m/s
    allowed: np.ndarray       # (T,) where a cut may go

    @property
    def n_actions(self) -> int:
        return len(self.cuts) - 1


def quietness(feat: ClipFeatures) -> np.ndarray:
    """Sum of fist, pelvis (horizontal) and foot (horizontal) speeds, m/s."""
    return feat.hand_speed.sum(axis=1) + feat.pelvis_speed + feat.foot_speed.sum(axis=1)


def segment_clip(feat: ClipFeatures, strikes: list[Strike], params: SegmentParams = SegmentParams()) -> Segmentation:
    """Choose cut frames for one clip."""
    fps, T = feat.fps, feat.n_frames
    contacts = foot_contacts(feat, params.contacts)
    q = quietness(feat)
    in_strike = np.zeros(T, bool)
    for s in strikes:
        in_strike[s.start:s.stop] = True
    guard = (feat.reach < params.guard_reach).all(axis=1)
    allowed = contacts.all(axis=1) & ~in_strike & guard
    allowed_relaxed = ~in_strike  # used only to split between strikes / over-long pieces
    w = max(1, int(round(params.quiet_window_s * fps)))
    cand = []
    for t in np.nonzero(allowed)[0]:
        lo, hi = max(0, t - w), min(T, t + w + 1)
        if q[t] <= q[lo:hi].min() + 1e-12:
            cand.append(int(t))
    min_len = max(1, int(round(params.min_action_s * fps)))
    cuts = _enforce_gap([0] + cand + [T - 1], q, min_len, T)
    # Split pieces holding two strikes far apart, then over-long pieces.
    peaks = np.array(sorted(s.peak for s in strikes), dtype=int)
    changed = True
    while changed:
        changed = False
        for a, b in zip(cuts[:-1], cuts[1:]):
            inside = peaks[(peaks > a) & (peaks < b)]
            target = None
            if len(inside) >= 2:
                gaps = np.diff(inside)
                k = int(np.argmax(gaps))
                if gaps[k] >= params.split_strikes_s * fps:
                    target = _quietest(q, allowed, allowed_relaxed, inside[k] + 1, inside[k + 1], a + min_len, b - min_len)
            if target is None and (b - a) > params.max_action_s * fps:
                target = _quietest(q, allowed, allowed_relaxed, a + min_len, b - min_len, a + min_len, b - min_len)
            if target is not None:
                cuts = sorted(set(cuts) | {target})
                changed = True
                break
    return Segmentation(np.array(cuts, dtype=int), contacts, q, allowed)


def _quietest(q, allowed, relaxed, lo, hi, bound_lo, bound_hi) -> int | None:
    lo, hi = max(lo, bound_lo), min(hi, bound_hi)
    if hi <= lo:
        return None
    for mask in (allowed, relaxed):
        idx = np.arange(lo, hi)
        idx = idx[mask[lo:hi]]
        if len(idx):
            return int(idx[np.argmin(q[idx])])
    return None


def _enforce_gap(cuts: list[int], q: np.ndarray, min_len: int, T: int) -> list[int]:
    """Drop interior cuts until every piece is at least min_len frames, removing the noisier cut first."""
    cuts = sorted(set(cuts))
    while len(cuts) > 2:
        lens = np.diff(cuts)
        k = int(np.argmin(lens))
        if lens[k] >= min_len:
            break
        # piece k = [cuts[k], cuts[k+1]]: remove one of its interior ends
        options = [i for i in (k, k + 1) if 0 < i < len(cuts) - 1]
        drop = max(options, key=lambda i: q[cuts[i]])
        cuts.pop(drop)
    return cuts


def double_support_cut_count(feat: ClipFeatures, params: SegmentParams = SegmentParams()) -> int:
    """How many pieces cutting at every double-support interval would give (for comparison)."""
    return len(runs(foot_contacts(feat, params.contacts).all(axis=1))) + 1
