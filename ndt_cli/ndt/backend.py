"""The compiled pieces of the method, swappable as one: Numba kernels or their numpy twins.

Every Numba kernel has a plain-numpy twin that computes the same thing (the tests compare them
at 1e-9). :data:`NUMPY` runs a whole registration on the twins: slow, but independent of the
compiler, and what a test holds the Numba path against end to end.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ndt_cli.core import merge
from ndt_cli.core.geometry import SURFACES, SURFACES_NUMPY, Merge, Surfaces
from ndt_cli.ndt import bnb_kernels, kernels, passes
from ndt_cli.ndt.bnb_kernels import SearchKernels
from ndt_cli.ndt.grid import NDTMap
from ndt_cli.ndt.kernels import SourcePoints


@dataclass(frozen=True)
class Kernels:
    """One implementation of every kernel the registration calls."""

    name: str
    accumulate: Callable[[NDTMap, SourcePoints, np.ndarray, bool], np.ndarray]
    point_scores: Callable[[NDTMap, SourcePoints, np.ndarray], tuple[np.ndarray, np.ndarray]]
    slice_pass: Callable[..., tuple]
    search: SearchKernels  # the branch and bound of the global search
    surfaces: Surfaces  # neighbours, normals and planarity in 3D (levelling, ICP)
    merge_groups: Merge  # a scan's ICP voxels merged chunk by chunk

    def __repr__(self) -> str:
        return f"Kernels({self.name})"


NUMBA = Kernels(
    "numba",
    kernels.accumulate,
    kernels.point_scores,
    passes.slice_pass,
    bnb_kernels.NUMBA,
    SURFACES,
    merge.merge_groups,
)
NUMPY = Kernels(
    "numpy",
    kernels.accumulate_numpy,
    kernels.point_scores_numpy,
    passes.slice_pass_numpy,
    bnb_kernels.NUMPY,
    SURFACES_NUMPY,
    merge.merge_groups_numpy,
)
