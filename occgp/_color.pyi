# Type stub of the compiled module occgp._color (ext/_color.pyx).
import numpy as np
from numpy.typing import NDArray
from typing_extensions import disjoint_base

# _TreeCore is compiled from ext/_tree_core.pxi into both modules: one stub, checked in _octree
from ._octree import _TreeCore as _TreeCore

FUSE_AVERAGE: int
FUSE_MEAN: int

@disjoint_base
class _ColorOcTree(_TreeCore):
    def _insert_colored(self, points: NDArray[np.float32], origin: NDArray[np.float32],
                        max_range: float, colors: NDArray[np.uint8] | None, fusion: int,
                        free_points: NDArray[np.float32] | None = None) -> int: ...
    def _fuse_colors(self, points: NDArray[np.float32], colors: NDArray[np.uint8],
                     replace: bool) -> NDArray[np.bool_]: ...
    def _colors(self, points: NDArray[np.float32],
                ) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]: ...
    def _leaves(self, occupied_only: bool,
                ) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float32],
                           NDArray[np.uint8]]: ...
    def _write_data(self) -> bytes: ...
    def _read_data(self, payload: bytes, resolution: float) -> None: ...

