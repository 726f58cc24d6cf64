// The outcome codes of occgp's compiled core (declared for Cython in ext/_status.pxd).
//
// Every routine of the core that can fail reports one of these instead of a string,
// a None or an exception of its own; occgp/_status.py holds the same codes as the
// IntEnum `Status` and turns each failure into its exception (`check_status`). The
// codes of the rays (ok, out_of_range, ray_too_short) are also the per-ray codes of
// the maps' `_check_rays`. Keep the values in step with occgp/_status.py.
#ifndef OCCGP_STATUS_H
#define OCCGP_STATUS_H

#include <cstdint>

namespace occgp {

enum class Status : uint8_t {
  ok = 0,
  out_of_range = 1,            // a ray end (after truncation) has no valid key
  ray_too_short = 2,           // a ray crosses a cell border but is too short to walk
  too_many_cells = 3,          // a scan reaches more cells than its limit
  truncated_data = 4,          // a tree's data block ends before its last node
  corrupt_depth = 5,           // a node of a data block lies deeper than 16 levels
  corrupt_value = 6,           // a node of a data block holds a non-finite log-odds
  unreadable_data = 7,         // liboctomap could not read a data block
  weights_length = 8,          // ray weights do not match the scan's rays
  weights_with_superrays = 9,  // ray weights were given with super rays
};

}  // namespace occgp

#endif  // OCCGP_STATUS_H
