// A scan's cell updates applied to the block grid (ext/_block_grid.h, ext/_grid.pyx), on
// several OpenMP threads where the cells are many: the cells the grid holds are found
// and updated on the threads (lookups only, each cell by one thread: a scan's keys are
// distinct), the new ones inserted afterwards on one thread, in the scan's order. Each
// cell gets the one update liboctomap's updateNode would give it, so the grid is the
// same for every number of threads.
#ifndef OCCGP_GRID_APPLY_H
#define OCCGP_GRID_APPLY_H

#include <cstddef>
#include <cstdint>
#include <vector>

#include "_block_grid.h"
#include "_scan.h"

namespace occgp {

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
static inline void apply_grid_updates(BlockGrid& cells, const std::vector<ScanCell>& found,
                                      float lo, float hi, int n_threads) {
  const ptrdiff_t n = static_cast<ptrdiff_t>(found.size());
  if (n_threads > 1 && n >= kMinParallelApply && cells.size() > 0) {
    std::vector<uint8_t> missing(n, 0);
#pragma omp parallel num_threads(n_threads)
    {
      BlockAccessor cache(&cells);
#pragma omp for schedule(static)
      for (ptrdiff_t j = 0; j < n; ++j) {
        float* value = cache.find(found[j].key);
        if (value == nullptr) missing[j] = 1;
        else apply_update(value, false, found[j].update, lo, hi);
      }
    }
    BlockAccessor cache(&cells);
    for (ptrdiff_t j = 0; j < n; ++j) {
      if (!missing[j]) continue;
      const std::pair<float*, bool> cell = cache.emplace(found[j].key);
      apply_update(cell.first, cell.second, found[j].update, lo, hi);
    }
    return;
  }
  BlockAccessor cache(&cells);
  for (ptrdiff_t j = 0; j < n; ++j) {
    const std::pair<float*, bool> cell = cache.emplace(found[j].key);
    apply_update(cell.first, cell.second, found[j].update, lo, hi);
  }
}

}  // namespace occgp

#endif  // OCCGP_GRID_APPLY_H
