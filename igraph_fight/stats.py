"""The one 95% interval helper: mean and confidence interval of independent draws."""
from __future__ import annotations

import math

import numpy as np


def mean_ci(x, level: float = 0.95, normal: bool = False) -> dict:
    """Mean of ``x`` with a two-sided confidence interval at ``level``.

    Student-t by default (bouts, walks: independent draws of unknown spread); ``normal=True`` uses
    the normal approximation (z = 1.96 at 95%), as the paired walk comparison reports it.
    Returns ``mean``, ``ci_low``, ``ci_high``, ``bouts`` (the number of draws) and ``sd`` (sample
    standard deviation); with fewer than two draws the interval is the mean itself (Student-t) or
    NaN (normal form).
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), not {level!r}")
    x = np.asarray(x, dtype=np.float64)
    n = len(x)
    m = float(x.mean()) if n else float("nan")
    if n < 2:
        h = float("nan") if normal else 0.0
        return {"mean": m, "ci_low": m - h, "ci_high": m + h, "bouts": n, "sd": 0.0}
    sd = float(x.std(ddof=1))
    if normal:
        from scipy.stats import norm
        z = 1.96 if level == 0.95 else float(norm.ppf(0.5 + level / 2))
        h = z * sd / np.sqrt(n)
    else:
        from scipy import stats
        h = float(stats.t.ppf(0.5 + level / 2, n - 1)) * sd / math.sqrt(n)
    return {"mean": m, "ci_low": m - h, "ci_high": m + h, "bouts": n, "sd": sd}
