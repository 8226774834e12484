"""Length-unit detection for mocap files that do not declare their unit (BVH)."""
from __future__ import annotations

import numpy as np

#: Candidate file units, metres per unit. The CMU ASF unit is 1/0.45 inch ("length 0.45").
CANDIDATE_UNITS: dict[str, float] = {
    "m": 1.0,
    "cm": 0.01,
    "mm": 0.001,
    "inch": 0.0254,
    "cmu_asf": 0.0254 / 0.45,
}

#: Typical standing height of an adult performer, metres; the scale is chosen to land near it.
TYPICAL_HEIGHT_M = 1.65


def sample_step(n_frames: int) -> int:
    """Frame step of the sample (about 50 frames) that guess_metres_per_unit looks at."""
    return max(1, n_frames // 50)


def guess_metres_per_unit(positions_units: np.ndarray, step: int | None = None) -> tuple[str, float]:
    """Pick the candidate unit that makes the performer's vertical extent closest to 1.65 m.

    Args:
        positions_units: (T, J, 3) global joint positions in file units, Y up.
        step: look at every step-th frame; default sample_step(T). Give 1 for positions that
            are already such a sample.
    Returns:
        (unit name, metres per unit); ("m", 1.0) when the extent is not a positive finite number.
    """
    if step is None:
        step = sample_step(positions_units.shape[0])
    p = positions_units[::step]
    extent = float(np.median(p[..., 1].max(axis=1) - p[..., 1].min(axis=1)))
    if not np.isfinite(extent) or extent <= 0:
        return "m", 1.0
    with np.errstate(divide="ignore", over="ignore"):  # a subnormal extent: log(0) ranks last
        best = min(CANDIDATE_UNITS.items(), key=lambda kv: abs(np.log(extent * kv[1] / TYPICAL_HEIGHT_M)))
    return best
