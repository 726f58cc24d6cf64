# Type stub of the compiled module occgp._linetrack (ext/_linetrack.pyx).
import numpy as np
from numpy.typing import NDArray

def track_lines(points: NDArray[np.float64], scan_ptr: NDArray[np.intp],
                distance_threshold: float, gap_threshold: float,
                line_of: NDArray[np.intp]) -> int: ...
