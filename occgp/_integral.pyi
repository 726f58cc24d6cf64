# Type stub of the compiled module occgp._integral (ext/_integral.pyx).
import numpy as np
from numpy.typing import NDArray

def observation_covariance(
    kind: int, cutoff2: float, A1: NDArray[np.float64], V1: NDArray[np.float64],
    len1: NDArray[np.float64], A2: NDArray[np.float64], V2: NDArray[np.float64],
    len2: NDArray[np.float64], same: bool, nodes: NDArray[np.float64],
    weights: NDArray[np.float64], offsets: NDArray[np.intp], reach: NDArray[np.float64],
    out: NDArray[np.float64], grad: NDArray[np.float64] | None, n_threads: int) -> None: ...
def tile_covariance(
    kind: int, cutoff2: float, X: NDArray[np.float64], A2: NDArray[np.float64],
    V2: NDArray[np.float64], len2: NDArray[np.float64], rows: NDArray[np.intp],
    row_ptr: NDArray[np.intp], cols: NDArray[np.intp], col_ptr: NDArray[np.intp],
    out_ptr: NDArray[np.intp], nodes: NDArray[np.float64], weights: NDArray[np.float64],
    offsets: NDArray[np.intp], reach: NDArray[np.float64], out: NDArray[np.float64],
    n_threads: int) -> None: ...
