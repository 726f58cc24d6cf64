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

// The block grid's in-place updates during a scan's walk (scan_updates' `direct`,
// ext/_scan.h), instead of flags over the scan's key box, a list of its cells and an
// update pass: update() marks a cell in its block (BlockGrid's per-scan marks) and
// gives it its one update of the scan, and does nothing to a cell this scan marked
// already. The blocks of the scan's key box are found through a dense index of them,
// filled as the walk reaches them, so that a visit takes no hash lookup. A new cell is
// written at once; a known cell's log-odds, far from the walk in memory, are updated
// by finish() after the walk, in a loop whose loads the processor overlaps (about 5%
// less time on scan.dat and on the geb079 trajectory than during the walk). A scan
// that runs out of memory while it walks is then partly applied.
class GridDirect {
 public:
  void reset(BlockGrid* grid, float lo, float hi) {
    grid_ = grid;
    cache_.reset(grid);
    lo_ = lo;
    hi_ = hi;
    updated = 0;
  }

  // A new scan over the key box lo .. lo + dims - 1.
  void begin_scan(const int* lo, const uint64_t* dims) {
    grid_->begin_scan();
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a) {
      blo_[a] = lo[a] >> kBlockBits;
      bdims_[a] = static_cast<uint64_t>(((lo[a] + static_cast<int>(dims[a]) - 1) >> kBlockBits) -
                                        blo_[a] + 1);
      n *= bdims_[a];
    }
    index_.assign(n, nullptr);
  }

  __attribute__((always_inline)) void update(int kx, int ky, int kz, float value) {
    const uint64_t bx = static_cast<uint64_t>((kx >> kBlockBits) - blo_[0]);
    const uint64_t by = static_cast<uint64_t>((ky >> kBlockBits) - blo_[1]);
    const uint64_t bz = static_cast<uint64_t>((kz >> kBlockBits) - blo_[2]);
    const uint64_t packed = pack_keys(kx, ky, kz);
    GridBlock* block;
    if (bx < bdims_[0] && by < bdims_[1] && bz < bdims_[2]) {
      GridBlock*& slot = index_[(bz * bdims_[1] + by) * bdims_[0] + bx];
      if (slot == nullptr) slot = reach(packed);
      block = slot;
    } else {  // past the box (liboctomap's walk may step beyond its end cell)
      block = reach(packed);
    }
    const int c = cell_of(packed);
    uint64_t& word = block->marked[c >> 6];
    const uint64_t bit = 1ull << (c & 63);
    if (word & bit) return;
    word |= bit;
    ++updated;
    if ((block->known[c >> 6] >> (c & 63)) & 1) {
      // a known cell: its log-odds, far from the walk's cells in memory, are updated
      // after the walk (finish), where the loads overlap
      pending_.push_back(Pending{&block->value[c], value});
      return;
    }
    const std::pair<float*, bool> cell = grid_->emplace_in(block, packed);
    apply_update(cell.first, cell.second, value, lo_, hi_);
  }

  // The block of cell `packed`, created if missing, with this scan's marks.
  __attribute__((noinline)) GridBlock* reach(uint64_t packed) {
    GridBlock* block = cache_.block(packed);
    grid_->mark_scan(block);
    return block;
  }

  // Update the known cells the walk marked.
  void finish() {
    const size_t n = pending_.size();
    for (size_t j = 0; j < n; ++j) {
      if (j + 8 < n) __builtin_prefetch(pending_[j + 8].value, 1, 3);
      apply_update(pending_[j].value, false, pending_[j].update, lo_, hi_);
    }
    pending_.clear();
  }

  uint64_t updated = 0;  // cells updated in place

 private:
  BlockGrid* grid_ = nullptr;
  BlockAccessor cache_;
  float lo_ = 0, hi_ = 0;
  int blo_[3] = {0, 0, 0};
  uint64_t bdims_[3] = {0, 0, 0};
  std::vector<GridBlock*> index_;  // the blocks of the scan's box, nullptr until reached
  struct Pending {
    float* value;
    float update;
  };
  std::vector<Pending> pending_;  // the known cells marked in this scan, and their updates
};

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
