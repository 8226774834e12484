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


def guess_metres_per_unit(positions_units: np.ndarray) -> tuple[str, float]:
    """Pick the candidate unit that makes the performer's vertical extent closest to 1.65 m.

    Args:
        positions_units: (T, J, 3) global joint positions in file units, Y up.
    Returns:
        (unit name, metres per unit).
    """
    step = max(1, positions_units.shape[0] // 50)
    p = positions_units[::step]
    extent = float(np.median(p[..., 1].max(axis=1) - p[..., 1].min(axis=1)))
    if not np.isfinite(extent) or extent <= 0:
        return "m", 1.0
    best = min(CANDIDATE_UNITS.items(), key=lambda kv: abs(np.log(extent * kv[1] / TYPICAL_HEIGHT_M)))
    return best
