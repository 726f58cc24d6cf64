// A scan's cell updates applied to the hashed grid (ext/_grid.pyx), on several
// OpenMP threads where the cells are many: the cells the grid holds are found and
// updated on the threads (lookups only, each cell by one thread: a scan's keys are
// distinct), the new ones inserted afterwards on one thread, in the scan's order. Each
// cell gets the one update liboctomap's updateNode would give it, so the grid is the
// same for every number of threads.
#ifndef OCCGP_GRID_APPLY_H
#define OCCGP_GRID_APPLY_H

#include <cstddef>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include "_scan.h"

namespace occgp {

typedef std::unordered_map<uint64_t, float> GridCells;  // packed key -> log-odds

constexpr ptrdiff_t kMinParallelApply = 1 << 15;  // fewer cells: applied on one thread

// liboctomap's updateNode(key, update) on one cell's log-odds (0 when `created`),
// clamped to [lo, hi].
static inline void apply_update(float* value, bool created, float update, float lo, float hi) {
  if (!created && ((update >= 0 && *value >= hi) || (update <= 0 && *value <= lo)))
    return;  // already at the bound: no change
  *value += update;
  if (*value < lo) *value = lo;
  else if (*value > hi) *value = hi;
}

// Apply `found` (distinct keys) to `cells` on up to `n_threads` threads.
static inline void apply_grid_updates(GridCells& cells, const std::vector<ScanCell>& found,
                                      float lo, float hi, int n_threads) {
  const ptrdiff_t n = static_cast<ptrdiff_t>(found.size());
  if (cells.empty()) cells.reserve(found.size());
  if (n_threads > 1 && n >= kMinParallelApply && !cells.empty()) {
    std::vector<uint8_t> missing(n, 0);
#pragma omp parallel for num_threads(n_threads) schedule(static)
    for (ptrdiff_t j = 0; j < n; ++j) {
      const GridCells::iterator it = cells.find(found[j].key);
      if (it == cells.end()) missing[j] = 1;
      else apply_update(&it->second, false, found[j].update, lo, hi);
    }
    for (ptrdiff_t j = 0; j < n; ++j) {
      if (!missing[j]) continue;
      float* value = &cells.emplace(found[j].key, 0.0f).first->second;
      apply_update(value, true, found[j].update, lo, hi);
    }
    return;
  }
  for (ptrdiff_t j = 0; j < n; ++j) {
    const std::pair<GridCells::iterator, bool> cell = cells.emplace(found[j].key, 0.0f);
    apply_update(&cell.first->second, cell.second, found[j].update, lo, hi);
  }
}

}  // namespace occgp

#endif  // OCCGP_GRID_APPLY_H
