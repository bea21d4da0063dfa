"""The body's skeleton: named joints, their parents and rest positions.

One fixed topology (a pelvis root, a three-joint spine to the head, two arms
and two legs) is enough for the garments distcloth dresses; the joint
positions are fitted to each body mesh (see ``fit_skeleton``).  Each joint
owns the bone from itself to its first child (a leaf owns the segment to the
body's extremity), so a joint's transform moves the flesh of that bone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# name -> parent name; the order is topological (a parent before its children).
JOINTS: tuple[tuple[str, str | None], ...] = (
    ("pelvis", None),
    ("spine", "pelvis"),
    ("chest", "spine"),
    ("neck", "chest"),
    ("head", "neck"),
    ("l_shoulder", "chest"),
    ("l_elbow", "l_shoulder"),
    ("l_wrist", "l_elbow"),
    ("r_shoulder", "chest"),
    ("r_elbow", "r_shoulder"),
    ("r_wrist", "r_elbow"),
    ("l_hip", "pelvis"),
    ("l_knee", "l_hip"),
    ("l_ankle", "l_knee"),
    ("r_hip", "pelvis"),
    ("r_knee", "r_hip"),
    ("r_ankle", "r_knee"),
)
JOINT_NAMES: tuple[str, ...] = tuple(name for name, _ in JOINTS)


@dataclass(frozen=True)
class Skeleton:
    """Joint names, parent indices (-1 for the root) and rest positions
    (J, 3) in the body file's frame (y up, metres; the body's left is +x)."""
    names: tuple[str, ...]
    parents: np.ndarray
    rest: np.ndarray

    def index(self, name: str) -> int:
        return self.names.index(name)

    def children(self, j: int) -> np.ndarray:
        return np.flatnonzero(self.parents == j)


def skeleton_from_positions(rest: np.ndarray) -> Skeleton:
    """The fixed topology with the given rest joint positions (J, 3)."""
    rest = np.asarray(rest, dtype=np.float64)
    if rest.shape != (len(JOINTS), 3):
        raise ValueError(f"rest joints must be ({len(JOINTS)}, 3), got {rest.shape}")
    parents = np.array([-1 if p is None else JOINT_NAMES.index(p) for _, p in JOINTS], dtype=np.int64)
    return Skeleton(JOINT_NAMES, parents, rest)
