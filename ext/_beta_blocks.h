// BetaBlocks: the Beta evidence of a kernel map's cells (used from ext/_kernel.pyx).
//
// Cells are grouped in blocks of 4 x 4 x 4 keys (keys as liboctomap's, 16 bits per
// axis). A block holds float32 alpha and beta for its 64 cells and a bit mask of the
// cells any kernel reached (520 bytes); a hash table maps the packed block key to
// the block's index. Blocks live in chunks of 32 (stable addresses, at most 31 unused
// blocks). Reached cells fill 40-85% of their blocks in the la3dm and synthetic
// scenes at 5 cm: 12-30 bytes per reached cell in all.
#ifndef OCCGP_BETA_BLOCKS_H
#define OCCGP_BETA_BLOCKS_H

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "_keytable.h"

namespace occgp {

struct BetaBlock {
  uint64_t mask;      // bit c: cell c was reached by a kernel
  float alpha[64];    // occupied evidence, cell c = x | y << 2 | z << 4 (low two key bits)
  float beta[64];     // free evidence
};

struct BlockSlot {
  uint64_t key;       // packed block key: (kx >> 2) | (ky >> 2) << 16 | (kz >> 2) << 32
  uint64_t index;     // 1 + the block's index in BetaBlocks (0: none yet)
};

class BetaBlocks {
 public:
  static uint64_t block_key(long kx, long ky, long kz) {
    return uint64_t(kx >> 2) | (uint64_t(ky >> 2) << 16) | (uint64_t(kz >> 2) << 32);
  }
  static int cell_index(long kx, long ky, long kz) {
    return int(kx & 3) | (int(ky & 3) << 2) | (int(kz & 3) << 4);
  }

  void clear() {
    index_.reset(16);
    chunks_.clear();
    chunks_.shrink_to_fit();
    size_ = 0;
    cells_ = 0;
  }

  // Index of the block of `bkey`, created empty when absent.
  size_t get_index(uint64_t bkey) {
    BlockSlot* s = index_.get(bkey);
    if (s->index == 0) {
      if (size_ == chunks_.size() * kChunk) {
        chunks_.emplace_back(new BetaBlock[kChunk]());
      }
      s->index = ++size_;
    }
    return s->index - 1;
  }
  BetaBlock* get(uint64_t bkey) { return block(get_index(bkey)); }
  BetaBlock* block(size_t i) { return &chunks_[i / kChunk][i % kChunk]; }

  // Start fetching the index slot of `bkey` (a hint before get_index / find).
  void prefetch_index(uint64_t bkey) const { index_.prefetch(bkey); }

  const BetaBlock* find(uint64_t bkey) {
    const BlockSlot* s = index_.find(bkey);
    return s == nullptr ? nullptr : block(s->index - 1);
  }

  // Add evidence to one cell (marking it reached).
  void add(long kx, long ky, long kz, float alpha, float beta) {
    BetaBlock* b = get(block_key(kx, ky, kz));
    int c = cell_index(kx, ky, kz);
    if (!(b->mask >> c & 1)) {
      b->mask |= uint64_t(1) << c;
      ++cells_;
    }
    b->alpha[c] += alpha;
    b->beta[c] += beta;
  }

  size_t num_cells() const { return cells_; }
  void add_cells(size_t n) { cells_ += n; }
  size_t num_blocks() const { return size_; }
  // The index's slots (the export walks them to find each block's key).
  size_t index_capacity() const { return index_.capacity(); }
  const BlockSlot& index_slot(size_t i) const { return index_.slot(i); }

  size_t memory_bytes() const {
    return chunks_.size() * kChunk * sizeof(BetaBlock) + chunks_.capacity() * sizeof(void*) +
           index_.capacity() * sizeof(BlockSlot);
  }

 private:
  static constexpr size_t kChunk = 32;
  KeyMap<BlockSlot> index_;
  std::vector<std::unique_ptr<BetaBlock[]>> chunks_;
  size_t size_ = 0;   // blocks in use
  size_t cells_ = 0;
};

}  // namespace occgp

#endif  // OCCGP_BETA_BLOCKS_H
