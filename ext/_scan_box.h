// The key box of a scan and where its walk counts the visits (used by ext/_scan.h).
//
// A scan's rays end in a box of keys (the end points' and the sensor's cells). The
// flags or counts of the cells its rays cross live in arrays over that box (count_box,
// CountSink), or, where it is too large, in a hash table (count_free); a map may
// instead update its cells in place as the rays cross them (DirectSink, scan_updates'
// `direct`).
#ifndef OCCGP_SCAN_BOX_H
#define OCCGP_SCAN_BOX_H

#include <cstdint>
#include <cstdlib>
#include <vector>

#include <octomap/OcTreeKey.h>

#include "_keys.h"
#include "_keytable.h"

namespace occgp {
namespace scan_detail {

// |a - b|_1 over the three keys: the cells a ray from the cell `a` visits before it
// reaches the cell `b` (one a step; a walk that stops short of `b` visits fewer).
static inline long key_distance(const octomap::OcTreeKey& a, const octomap::OcTreeKey& b) {
  long d = 0;
  for (int axis = 0; axis < 3; ++axis)
    d += std::abs(static_cast<long>(a[axis]) - static_cast<long>(b[axis]));
  return d;
}

static inline bool in_box(const octomap::OcTreeKey& key, const int* lo, const uint64_t* dims) {
  return static_cast<uint64_t>(static_cast<int>(key[0]) - lo[0]) < dims[0] &&
         static_cast<uint64_t>(static_cast<int>(key[1]) - lo[1]) < dims[1] &&
         static_cast<uint64_t>(static_cast<int>(key[2]) - lo[2]) < dims[2];
}

static inline uint64_t box_index(const octomap::OcTreeKey& key, const int* lo, const uint64_t* dims) {
  return (static_cast<uint64_t>(key[2] - lo[2]) * dims[1] +
          static_cast<uint64_t>(key[1] - lo[1])) * dims[0] +
         static_cast<uint64_t>(key[0] - lo[0]);
}

static inline octomap::OcTreeKey box_key(uint64_t idx, const int* lo, const uint64_t* dims) {
  octomap::OcTreeKey key;
  key[0] = static_cast<octomap::key_type>(lo[0] + idx % dims[0]);
  idx /= dims[0];
  key[1] = static_cast<octomap::key_type>(lo[1] + idx % dims[1]);
  key[2] = static_cast<octomap::key_type>(lo[2] + idx / dims[1]);
  return key;
}

// Count `w` rays through the cell (kx, ky, kz) in `table`: cells outside the scan's
// dense box, off the hot path of count_free.
__attribute__((noinline, cold)) static void count_free_table(int kx, int ky, int kz, uint32_t w,
                                                             KeyTable* table) {
  octomap::OcTreeKey key;
  key[0] = static_cast<octomap::key_type>(kx);
  key[1] = static_cast<octomap::key_type>(ky);
  key[2] = static_cast<octomap::key_type>(kz);
  table->get(pack_key(key))->n_free += w;
}

// Count `w` rays through the box cell `idx` of `counts`, appending it to `touched`
// when it is new. Counts of one byte (scan mode) are flags: 1 once a ray crossed the
// cell. With `shared` (scan mode, every thread flagging cells in one array), the
// thread that sets a flag first, atomically, appends the cell, so each cell is
// appended once over all threads.
template <class Count>
static inline void count_box(Count* counts, uint64_t idx, uint32_t w, bool shared,
                             std::vector<uint64_t>* touched) {
  if (shared) {
    if (__atomic_load_n(counts + idx, __ATOMIC_RELAXED) == 0 &&
        __atomic_exchange_n(counts + idx, Count(1), __ATOMIC_RELAXED) == 0)
      touched->push_back(idx);
  } else {
    if (counts[idx] == 0) touched->push_back(idx);
    counts[idx] = sizeof(Count) == 1 ? Count(1) : static_cast<Count>(counts[idx] + w);
  }
}

// Count `w` rays through the cell (kx, ky, kz): in the scan's dense box (`free_counts`,
// see count_box), or the table.
template <class Count>
static inline void count_free(int kx, int ky, int kz, uint32_t w, bool dense, bool shared,
                              const int* lo, const uint64_t* dims, Count* free_counts,
                              std::vector<uint64_t>* touched, KeyTable* table) {
  const uint64_t x = static_cast<uint64_t>(kx - lo[0]);
  const uint64_t y = static_cast<uint64_t>(ky - lo[1]);
  const uint64_t z = static_cast<uint64_t>(kz - lo[2]);
  // liboctomap's traversal may step past the end cell before its length test stops
  // it: such cells lie outside the box and go to the table
  if (dense && x < dims[0] && y < dims[1] && z < dims[2]) {
    count_box(free_counts, (z * dims[1] + y) * dims[0] + x, w, shared, touched);
  } else {
    count_free_table(kx, ky, kz, w, table);
  }
}

// Where walk_rays counts one thread's visits: cells of the scan's key box in `counts`
// (dense; new ones appended to `touched`, count_box), other cells in `table`'s n_free
// (count_free); `table_base`: the entries of `table` that are not this thread's cells.
// The members are copies, which the counts' stores cannot alias.
template <class Count>
struct CountSink {
  Count* counts;
  std::vector<uint64_t>* touched;
  KeyTable* table;
  size_t table_base;
  bool dense, shared;
  int lo[3];
  uint64_t dims[3];

  static constexpr bool kKeys = false;  // box() takes box indices

  // `w` rays through the box cell `idx`, or through the cell (kx, ky, kz)
  void box(uint64_t idx, uint32_t w) {
    if (dense) count_box(counts, idx, w, shared, touched);
    else table->get(pack_key(box_key(idx, lo, dims)))->n_free += w;
  }
  void cell(int kx, int ky, int kz, uint32_t w) {
    count_free(kx, ky, kz, w, dense, shared, lo, dims, counts, touched, table);
  }
  // the distinct cells counted so far
  uint64_t distinct() const { return touched->size() + (table->size() - table_base); }
};

// scan_updates without a map's in-place updates (its default `direct`).
struct NoDirect {
  void begin_scan(const int*, const uint64_t*) {}
  void update(int, int, int, float) {}
  void finish() {}
};

// A map's in-place updates as walk_rays' sink (scan_updates' `direct`): each visit
// gives its cell `l_miss` unless this scan updated the cell already.
template <class Direct>
struct DirectSink {
  Direct* direct;
  float l_miss;
  static constexpr bool kKeys = true;  // box() takes packed keys

  void box(uint64_t key, uint32_t) {
    const octomap::OcTreeKey k = unpack_key(key);
    direct->update(k[0], k[1], k[2], l_miss);
  }
  void cell(int kx, int ky, int kz, uint32_t) { direct->update(kx, ky, kz, l_miss); }
  uint64_t distinct() const { return 0; }  // the caller bounds the cells beforehand
};

}  // namespace scan_detail
}  // namespace occgp

#endif  // OCCGP_SCAN_BOX_H
