"""Edge features (docs/contracts.md) from the simulator's per-event feature rows (sim.FT_*)."""
from __future__ import annotations

import numpy as np

from igraph_fight import sim
from igraph_fight.sim import SimTables


def edge_features(tables: SimTables, m_other: np.ndarray, action: np.ndarray, ft: np.ndarray) -> dict[str, np.ndarray]:
    """The contract's ``feat_*`` arrays for events in which the decider launched ``action`` while the
    other played ``m_other``; ``ft`` (K, sim.N_FEAT) are the kernel's feature rows."""
    return {
        "feat_duration": ft[:, sim.FT_FRAMES] / tables.fps, "feat_r": ft[:, sim.FT_R],
        "feat_r_mean": ft[:, sim.FT_R_MEAN], "feat_theta_self": ft[:, sim.FT_TH_SELF],
        "feat_theta_other": ft[:, sim.FT_TH_OTHER], "feat_dmg_given": ft[:, sim.FT_DMG_GIVEN],
        "feat_dmg_received": ft[:, sim.FT_DMG_RECEIVED], "feat_kind": tables.kinds[np.asarray(action)],
        "feat_other_kind": tables.kinds[np.asarray(m_other)], "feat_def_self": ft[:, sim.FT_DEF_SELF],
        "feat_def_other": ft[:, sim.FT_DEF_OTHER],
    }
