"""Skeleton tree: joint names, parents, rest offsets (metres)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Skeleton:
    """A joint tree in parent-before-child order.

    Attributes:
        names: joint names; BVH end sites get the name ``<parent>_End``.
        parents: (J,) parent index per joint, -1 for the root.
        offsets: (J, 3) rest translation of each joint from its parent, metres (root: usually 0).
        channels: per joint, the channel names declared in the file (e.g. ``("Zrotation", ...)``);
            empty for end sites and joints without degrees of freedom.
        is_end_site: (J,) True for BVH End Site / ASF bone tips (no rotation of their own).
        metres_per_unit: the scale applied to the file's lengths to get metres.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    is_end_site: np.ndarray
    metres_per_unit: float = 1.0
    limits_deg: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        p = np.asarray(self.parents)
        if p.ndim != 1 or len(p) != len(self.names) or p[0] != -1:
            raise ValueError("skeleton: parents must be (J,) with the root first")
        if np.any(p[1:] >= np.arange(1, len(p))):
            raise ValueError("skeleton: joints must be ordered parents before children")

    @property
    def n_joints(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of a joint by exact name (KeyError naming the joint if absent)."""
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no joint named {name!r} in skeleton ({', '.join(self.names)})") from None

    def children(self, j: int) -> list[int]:
        return [int(c) for c in np.nonzero(self.parents == j)[0]]

    def chain(self, j: int) -> list[int]:
        """Joints from the root down to j (inclusive)."""
        out = []
        while j >= 0:
            out.append(j)
            j = int(self.parents[j])
        return out[::-1]

    def chain_length(self, a: int, b: int) -> float:
        """Rest-pose length (metres) of the path from ancestor a down to b."""
        length = 0.0
        j = b
        while j != a:
            if j < 0:
                raise ValueError(f"{self.names[a]} is not an ancestor of {self.names[b]}")
            length += float(np.linalg.norm(self.offsets[j]))
            j = int(self.parents[j])
        return length

    def scaled(self, factor: float) -> "Skeleton":
        """The same skeleton with lengths multiplied by factor."""
        return Skeleton(self.names, self.parents, self.offsets * factor, self.channels,
                        self.is_end_site, self.metres_per_unit * factor, self.limits_deg)
