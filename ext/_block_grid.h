// The cells of occgp.GridMap (ext/_grid.pyx): a hashed root of dense 8 x 8 x 8 blocks.
//
// A cell is liboctomap's 16-bit key (packed by pack_key, ext/_keys.h) and a float32
// log-odds. The root (the project's open-addressing KeyMap, ext/_keytable.h: a power
// of two of slots, so a lookup takes a multiply and a mask, no division) maps a
// block's key (the cell keys shifted right by 3 on each axis) to a block that holds
// the 512 log-odds of its cells and a bit mask of the known ones. A lookup hashes once
// per block, not once per cell; an Accessor keeps the last block it found, so the
// cells of one ray or one scan, which are mostly in the same block as the cell before
// them, are found without hashing at all.
//
// Memory: a block is 2,184 bytes (512 floats, a mask of the known cells, a mask of the
// cells updated in the current scan and the scan it belongs to) plus its root slots
// (16 bytes each, at most half of them used) and its owning pointer; memory_usage()
// counts them all.
#ifndef OCCGP_BLOCK_GRID_H
#define OCCGP_BLOCK_GRID_H

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <utility>
#include <vector>

#include "_keytable.h"

namespace occgp {

constexpr int kBlockBits = 3;                           // 8 cells a side
constexpr uint64_t kBlockMask = (1u << kBlockBits) - 1;
constexpr int kBlockCells = 1 << (3 * kBlockBits);      // 512

struct GridBlock {
  uint64_t known[kBlockCells / 64];
  uint64_t marked[kBlockCells / 64];  // cells updated in scan `epoch` (begin_scan)
  uint32_t epoch;
  float value[kBlockCells];
};

// The block holding a packed key (its three keys shifted right by kBlockBits).
inline uint64_t block_of(uint64_t packed) {
  constexpr uint64_t field = 0xFFFFull >> kBlockBits;
  return ((packed >> kBlockBits) & field) | ((packed >> (16 + kBlockBits)) & field) << 16 |
         ((packed >> (32 + kBlockBits)) & field) << 32;
}

// The cell's index inside its block (x fastest).
inline int cell_of(uint64_t packed) {
  return static_cast<int>((packed & kBlockMask) | ((packed >> 16) & kBlockMask) << kBlockBits |
                          ((packed >> 32) & kBlockMask) << (2 * kBlockBits));
}

// The packed key of cell `index` of block `block`.
inline uint64_t key_of(uint64_t block, int index) {
  const uint64_t i = static_cast<uint64_t>(index);
  return ((block & 0xFFFF) << kBlockBits | (i & kBlockMask)) |
         (((block >> 16) & 0xFFFF) << kBlockBits | ((i >> kBlockBits) & kBlockMask)) << 16 |
         (((block >> 32) & 0xFFFF) << kBlockBits | ((i >> (2 * kBlockBits)) & kBlockMask)) << 32;
}

// A root slot: a block's key and the block.
struct BlockRef {
  uint64_t key;
  GridBlock* block;
};

class BlockGrid {
 public:
  BlockGrid() { root_.reset(8); }

  // The block of `block_key`, or nullptr.
  GridBlock* find_block(uint64_t block_key) const {
    const BlockRef* ref = root_.find(block_key);
    return ref == nullptr ? nullptr : ref->block;
  }

  // The block of `block_key`, created (no cell known) if missing. When memory runs out
  // it throws and the grid is unchanged.
  GridBlock* get_block(uint64_t block_key) {
    if (const BlockRef* found = root_.find(block_key)) return found->block;
    return add_block(block_key);
  }

  // A new block for `block_key` (off the lookups' hot path).
  __attribute__((noinline)) GridBlock* add_block(uint64_t block_key) {
    root_.reserve(root_.size() + 1);  // the allocations first, each undone if it throws
    std::unique_ptr<GridBlock> block(new GridBlock);
    std::memset(block->known, 0, sizeof(block->known));
    std::memset(block->marked, 0, sizeof(block->marked));
    block->epoch = 0;  // no scan's marks
    blocks_.push_back(std::move(block));
    BlockRef* ref = root_.get(block_key);  // room reserved: no allocation
    ref->block = blocks_.back().get();
    return ref->block;
  }

  // The log-odds of a known cell, or nullptr.
  float* find(uint64_t packed) const {
    GridBlock* block = find_block(block_of(packed));
    return block ? find_in(block, packed) : nullptr;
  }

  static float* find_in(GridBlock* block, uint64_t packed) {
    const int i = cell_of(packed);
    return (block->known[i >> 6] >> (i & 63)) & 1 ? &block->value[i] : nullptr;
  }

  // The log-odds of a cell, made known at 0 if it was not; second: whether it was new.
  std::pair<float*, bool> emplace_in(GridBlock* block, uint64_t packed) {
    const int i = cell_of(packed);
    uint64_t& word = block->known[i >> 6];
    const uint64_t bit = 1ull << (i & 63);
    if (word & bit) return std::make_pair(&block->value[i], false);
    word |= bit;
    block->value[i] = 0.0f;
    ++n_cells_;
    return std::make_pair(&block->value[i], true);
  }

  std::pair<float*, bool> emplace(uint64_t packed) {
    return emplace_in(get_block(block_of(packed)), packed);
  }

  size_t size() const { return n_cells_; }
  size_t num_blocks() const { return blocks_.size(); }

  void clear() {
    root_.reset(8);  // frees the slots too
    std::vector<std::unique_ptr<GridBlock>>().swap(blocks_);
    n_cells_ = 0;
  }

  void reserve_blocks(size_t n) {
    root_.reserve(n);
    blocks_.reserve(n);
  }

  // Bytes of the blocks, their owning pointers and the root's slots.
  size_t memory_usage() const {
    return blocks_.size() * sizeof(GridBlock) + blocks_.capacity() * sizeof(void*) +
           root_.capacity() * sizeof(BlockRef);
  }

  // Calls f(packed key, log-odds) for every known cell, block by block.
  template <class F>
  void for_each(F f) const {
    for (size_t slot = 0; slot < root_.capacity(); ++slot) {
      const BlockRef& ref = root_.slot(slot);
      if (ref.key == BlockRoot::kEmpty) continue;
      const GridBlock* block = ref.block;
      for (int w = 0; w < kBlockCells / 64; ++w) {
        uint64_t bits = block->known[w];
        while (bits) {
          const int i = w * 64 + __builtin_ctzll(bits);
          bits &= bits - 1;
          f(key_of(ref.key, i), block->value[i]);
        }
      }
    }
  }

  // Every known cell as (packed key, log-odds), those below `threshold` left out when
  // `occupied_only`.
  void collect(std::vector<std::pair<uint64_t, float>>& out, bool occupied_only,
               float threshold) const {
    out.reserve(out.size() + n_cells_);
    for_each([&](uint64_t key, float value) {
      if (!occupied_only || value >= threshold) out.push_back(std::make_pair(key, value));
    });
  }

  // The smallest and largest key of the known cells on each axis (unchanged if none).
  void key_bounds(uint16_t lo[3], uint16_t hi[3]) const {
    for_each([&](uint64_t key, float) {
      for (int axis = 0; axis < 3; ++axis) {
        const uint16_t k = static_cast<uint16_t>((key >> (16 * axis)) & 0xFFFF);
        if (k < lo[axis]) lo[axis] = k;
        if (k > hi[axis]) hi[axis] = k;
      }
    });
  }

  void set(uint64_t packed, float value) { *emplace(packed).first = value; }

  // Start a scan: every cell unmarked. The marks live in the blocks and are cleared
  // lazily, when a block is first touched in the new scan (its epoch is behind).
  void begin_scan() {
    if (++epoch_ == 0) {  // wrapped after 2^32 scans: reset every block once
      for (const std::unique_ptr<GridBlock>& block : blocks_) block->epoch = 0;
      epoch_ = 1;
    }
  }

  // Make the marks of `block` this scan's (none, if it was last marked in another).
  void mark_scan(GridBlock* block) const {
    if (block->epoch != epoch_) {
      std::memset(block->marked, 0, sizeof(block->marked));
      block->epoch = epoch_;
    }
  }

  // Mark cell `packed` of `block` as updated in this scan; false if it already was.
  bool mark(GridBlock* block, uint64_t packed) const {
    mark_scan(block);
    const int i = cell_of(packed);
    uint64_t& word = block->marked[i >> 6];
    const uint64_t bit = 1ull << (i & 63);
    if (word & bit) return false;
    word |= bit;
    return true;
  }

 private:
  typedef KeyMap<BlockRef> BlockRoot;

  BlockRoot root_;
  std::vector<std::unique_ptr<GridBlock>> blocks_;  // owns the blocks, in creation order
  size_t n_cells_ = 0;
  uint32_t epoch_ = 0;
};

// Finds cells of one BlockGrid, remembering the last block it looked in: the cells of
// a scan come in runs that share a block, so most lookups never hash. It may remember
// that a block is missing: use one for lookups (find) or for inserts, not for lookups
// across inserts.
class BlockAccessor {
 public:
  BlockAccessor() : grid_(nullptr) {}
  explicit BlockAccessor(BlockGrid* grid) : grid_(grid) {}

  // Look in `grid` from now on, remembering nothing.
  void reset(BlockGrid* grid) {
    grid_ = grid;
    last_key_ = ~0ull;
    last_ = nullptr;
  }

  float* find(uint64_t packed) {
    GridBlock* block = block_for(block_of(packed), false);
    return block ? BlockGrid::find_in(block, packed) : nullptr;
  }

  std::pair<float*, bool> emplace(uint64_t packed) {
    return grid_->emplace_in(block_for(block_of(packed), true), packed);
  }

  // The block of a cell, created if missing.
  GridBlock* block(uint64_t packed) { return block_for(block_of(packed), true); }

 private:
  GridBlock* block_for(uint64_t block_key, bool create) {
    if (block_key != last_key_ || (create && last_ == nullptr)) {
      last_ = create ? grid_->get_block(block_key) : grid_->find_block(block_key);
      last_key_ = block_key;
    }
    return last_;
  }

  BlockGrid* grid_;
  uint64_t last_key_ = ~0ull;
  GridBlock* last_ = nullptr;
};

}  // namespace occgp

#endif  // OCCGP_BLOCK_GRID_H
