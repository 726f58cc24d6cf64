// Small containers for occgp's compiled maps (used from ext/_scan.h, ext/_kernel.pyx).
//
// KeyMap<Slot>: open-addressing hash table from a packed key (3 x 16 bits) to the
//   rest of a Slot (a struct whose first member is `uint64_t key`), 16-24 bytes a
//   slot, linear probing, at most half full.
//   KeyTable = KeyMap<KeyCounts>: the rays that pass through a cell and end in it
//   during one scan (replaces liboctomap's std::tr1 unordered sets).
//   KeyMap<BlockSlot> indexes the kernel maps' blocks of cells (_beta_blocks.h),
//   KeyMap<BlockRef> the grid's (_block_grid.h).
// CellBox: a bitset over a box of keys (the culling region of one scan).
// StopFlag: a flag that the threads of one scan's traversal set and poll.
#ifndef OCCGP_KEYTABLE_H
#define OCCGP_KEYTABLE_H

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace occgp {

struct KeyCounts {
  uint64_t key;
  uint32_t n_free;  // rays passing through the cell
  uint32_t n_hit;   // rays ending in the cell
  uint32_t group;   // super rays: 1 + the index of the cell's group of end points, or 0
};

constexpr uint64_t kEmptyKey = ~uint64_t(0);

template <class Slot>
class KeyMap {
 public:
  static constexpr uint64_t kEmpty = kEmptyKey;

  KeyMap() { reset(1024); }

  // Drop every entry; keep room for about `expected` keys.
  void reset(size_t expected) {
    size_t cap = 16;
    while (cap < 2 * expected) cap <<= 1;
    slots_.assign(cap, empty_slot());
    mask_ = cap - 1;
    size_ = 0;
  }

  // The entry of `key`, inserted with a zero payload when absent.
  Slot* get(uint64_t key) {
    if (2 * (size_ + 1) > slots_.size()) grow();
    size_t i = hash(key) & mask_;
    while (true) {
      Slot& s = slots_[i];
      if (s.key == key) return &s;
      if (s.key == kEmpty) {
        s.key = key;
        ++size_;
        return &s;
      }
      i = (i + 1) & mask_;
    }
  }

  // Room for `expected` keys in all without growing; the entries stay.
  void reserve(size_t expected) {
    while (slots_.size() < 2 * expected) grow();
  }

  // The entry of `key`, or nullptr when absent.
  Slot* find(uint64_t key) {
    return const_cast<Slot*>(static_cast<const KeyMap*>(this)->find(key));
  }

  const Slot* find(uint64_t key) const {
    size_t i = hash(key) & mask_;
    while (true) {
      const Slot& s = slots_[i];
      if (s.key == key) return &s;
      if (s.key == kEmpty) return nullptr;
      i = (i + 1) & mask_;
    }
  }

  // Start fetching the slot where the search for `key` begins (a hint: nothing changes).
  void prefetch(uint64_t key) const {
    __builtin_prefetch(&slots_[hash(key) & mask_], 0, 3);
  }

  bool contains(uint64_t key) const {
    size_t i = hash(key) & mask_;
    while (true) {
      const Slot& s = slots_[i];
      if (s.key == key) return true;
      if (s.key == kEmpty) return false;
      i = (i + 1) & mask_;
    }
  }

  size_t size() const { return size_; }
  size_t capacity() const { return slots_.size(); }
  const Slot& slot(size_t i) const { return slots_[i]; }

 private:
  static size_t hash(uint64_t k) {  // murmur3 finaliser
    k ^= k >> 33;
    k *= 0xff51afd7ed558ccdULL;
    k ^= k >> 33;
    return static_cast<size_t>(k);
  }

  static Slot empty_slot() {
    Slot s{};
    s.key = kEmpty;
    return s;
  }

  // Twice the slots; when the allocation throws, the table is unchanged.
  void grow() {
    std::vector<Slot> bigger(slots_.size() * 2, empty_slot());
    const size_t mask = bigger.size() - 1;
    for (const Slot& s : slots_) {
      if (s.key == kEmpty) continue;
      size_t i = hash(s.key) & mask;
      while (bigger[i].key != kEmpty) i = (i + 1) & mask;
      bigger[i] = s;
    }
    slots_.swap(bigger);
    mask_ = mask;
  }

  std::vector<Slot> slots_;
  size_t mask_ = 0;
  size_t size_ = 0;
};

using KeyTable = KeyMap<KeyCounts>;

// A bitset over the keys lo[a] <= k[a] <= hi[a].
class CellBox {
 public:
  // Returns false (and holds nothing) when the box has more than `max_cells` cells.
  bool reset(const int lo[3], const int hi[3], uint64_t max_cells) {
    uint64_t n = 1;
    for (int a = 0; a < 3; ++a) {
      lo_[a] = lo[a];
      dim_[a] = static_cast<uint64_t>(hi[a] - lo[a] + 1);
      n *= dim_[a];
    }
    if (n > max_cells) {
      bits_.clear();
      return false;
    }
    bits_.assign((n + 63) / 64, 0);
    return true;
  }

  bool inside(int x, int y, int z) const {
    return x >= lo_[0] && y >= lo_[1] && z >= lo_[2] &&
           static_cast<uint64_t>(x - lo_[0]) < dim_[0] &&
           static_cast<uint64_t>(y - lo_[1]) < dim_[1] &&
           static_cast<uint64_t>(z - lo_[2]) < dim_[2];
  }

  // The caller checks inside() first.
  bool test(int x, int y, int z) const { return test_index(index(x, y, z)); }

  // By the index of a cell inside the box; stride(axis) steps it by one key on `axis`.
  bool test_index(uint64_t i) const { return (bits_[i >> 6] >> (i & 63)) & 1; }
  uint64_t stride(int axis) const { return axis == 0 ? 1 : axis == 1 ? dim_[0] : dim_[0] * dim_[1]; }

  void set(int x, int y, int z) {
    uint64_t i = index(x, y, z);
    bits_[i >> 6] |= uint64_t(1) << (i & 63);
  }

 public:
  uint64_t index(int x, int y, int z) const {
    return (static_cast<uint64_t>(z - lo_[2]) * dim_[1] + static_cast<uint64_t>(y - lo_[1])) *
               dim_[0] +
           static_cast<uint64_t>(x - lo_[0]);
  }

 private:

  int lo_[3] = {0, 0, 0};
  uint64_t dim_[3] = {0, 0, 0};
  std::vector<uint64_t> bits_;
};

// Set by any thread of a traversal, polled by all (relaxed: it only stops work early).
class StopFlag {
 public:
  bool get() const { return flag_.load(std::memory_order_relaxed); }
  void set() { flag_.store(true, std::memory_order_relaxed); }

 private:
  std::atomic<bool> flag_{false};
};

}  // namespace occgp

#endif  // OCCGP_KEYTABLE_H
