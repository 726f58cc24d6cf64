# cython: language_level=3
"""The outcome codes of the compiled core (``ext/_status.h``): declarations only.

``occgp/_status.py`` holds the same codes as the IntEnum ``Status`` and turns a
failure into its exception (``check_status``).
"""

from libc.stdint cimport uint8_t


cdef extern from "_status.h" namespace "occgp" nogil:
    cdef enum class Status(uint8_t):
        ok
        out_of_range
        ray_too_short
        too_many_cells
        truncated_data
        corrupt_depth
        corrupt_value
        unreadable_data
        weights_length
        weights_with_superrays
