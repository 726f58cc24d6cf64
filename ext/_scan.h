// A scan's cell updates, shared by the compiled maps: rays, super rays and the culling
// region (declared for Cython in ext/_scan.pxd).
//
// scan_updates turns a scan into one update per cell, and each map applies them its
// own way (ext/_octree.pyx in one pass over the tree, ext/_grid.pyx to its blocks, in
// place as the rays cross the cells where the scan is walked on one thread).
// The rays of a scan may be walked on several OpenMP threads, each into its own
// counts, merged (integer sums) before the cells are collected: the modules that use
// this are built with OpenMP (OPENMP_MODULES in setup.py). Keys, ray ends and the
// sensor model come from a liboctomap OcTree of the map's resolution, so every map
// finds the cells liboctomap finds. Build without floating-point contraction
// (-ffp-contract=off), as the rest of the core. The functions are static: each module
// gets its own copy, which the compiler specialises (its FreeTest, constant arguments).
#ifndef OCCGP_SCAN_H
#define OCCGP_SCAN_H

#include <time.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <vector>

#ifdef _OPENMP
#include <omp.h>
#endif

#include <octomap/OcTree.h>

#include "_keys.h"
#include "_keytable.h"
#include "_raywalk.h"
#include "_scan_box.h"
#include "_status.h"
#include "_superrays.h"

namespace occgp {

namespace scan_detail {
constexpr uint64_t kMaxRegionCells = 1 << 28;  // larger scan key boxes are not culled
constexpr uint64_t kMaxDenseCells = 1 << 24;   // up to this, free counts live in arrays
constexpr ptrdiff_t kMinThreadRays = 64;       // fewer rays per thread: fewer threads
constexpr int kMaxThreads = 256;
constexpr ptrdiff_t kMinParallelCollect = 1 << 16;  // fewer cells: collected on one thread
constexpr int kChunksPerThread = 16;  // the rays are handed out in chunks, first come first served
// Smaller culling regions only hide rays (RayWalker::hidden): a ray's walk back costs
// some 50 ns and 10 ns a cell, against 7 ns a cell walked forward, which a region this
// small rarely repays (walking back to a region of 15 cells took 15 % longer on
// scan.dat at 0.4 m; to one of 936 cells, 9 % less on geb079 at 0.2 m)
constexpr long kMinWalkBackRegion = 128;
}  // namespace scan_detail

// Whether the map's cell at a key is known and at the lower clamping bound.
typedef bool (*FreeTest)(void* map, const octomap::OcTreeKey& key);

struct ScanCell {
  uint64_t key;  // packed key (pack_key of ext/_keys.pxd)
  float update;  // the log-odds to add, as updateNode(key, update) adds it
};

struct ScanStats {
  long region_cells;     // cells in the culling region; -1 without culling
  long rays;             // rays traversed (super rays count once)
  long traversed_cells;  // cell visits that counted a ray
  long spared_cells;     // the visits super rays spared: per walked ray, its visits x
                         // the other rays of its class
  long culled_rays;      // rays the culling region hid whole (RayWalker::hidden): not walked
  long region_spared;    // the visits the culling region spared the walked rays (walk_rays)
  long unnecessary;      // with `diagnose`: visits to cells whose update is a no-op
  timespec clock[5];     // start; end points, super rays, culling region, traversal done
};

// The statistics of a scan before (or without) its traversal, every clock now.
static inline void empty_stats(ScanStats* stats) {
  stats->region_cells = -1;
  stats->rays = 0;
  stats->traversed_cells = 0;
  stats->spared_cells = 0;
  stats->culled_rays = 0;
  stats->region_spared = 0;
  stats->unnecessary = -1;
  for (int k = 0; k < 5; ++k) clock_gettime(CLOCK_MONOTONIC, &stats->clock[k]);
}

namespace scan_detail {

// What one thread's walk of rays counts (walk_rays), added into ScanStats.
struct WalkCounts {
  long visits = 0;         // cell visits that counted a ray: traversed_cells
  long spared = 0;         // spared_cells
  long culled = 0;         // culled_rays
  long region_spared = 0;  // region_spared
};

static inline void add_walk_counts(ScanStats* stats, const WalkCounts& c) {
  stats->traversed_cells += c.visits;
  stats->spared_cells += c.spared;
  stats->culled_rays += c.culled;
  stats->region_spared += c.region_spared;
}

// One cell's update of a scan: liboctomap's insertPointCloud rule, or ray counting.
static inline float update_value(uint32_t n_free, uint32_t n_hit, bool ray_mode, float l_hit,
                          float l_miss) {
  if (ray_mode) return static_cast<float>(n_free * static_cast<double>(l_miss) +
                                          n_hit * static_cast<double>(l_hit));
  return n_hit ? l_hit : l_miss;
}

}  // namespace scan_detail

// Grow the scan's culling region (Kwon, dissertation 2.3.5, Alg. 3).
//
// Breadth first over Manhattan levels from the sensor's cell, inside the key box of
// the scan: a cell joins when each of its test cells (one step toward the origin on
// every axis where its key differs from the origin's) is already in, and a ray's visit
// cannot change its update: it is fully free (log-odds at the lower clamp) and holds no
// end point of the scan (`ends`, occgp's exactness rule), or, with `ends_in` (scan
// mode, where such a cell gets l_hit whatever crosses it), holds one. With
// `origin_in`, the sensor's cell joins whatever its state (scan mode, where the caller
// collects it: every ray that leaves it crosses it). Returns the number of cells, or -1
// when the box is too large (no culling).
static inline long build_region(FreeTest fully_free, void* map, const octomap::OcTreeKey& ko,
                         const int* lo, const int* hi, int max_level, const KeyTable& ends,
                         CellBox& region, bool ends_in = false, bool origin_in = false) {
  using namespace scan_detail;
  CellBox seen;
  std::vector<octomap::OcTreeKey> frontier, next_frontier;
  if (!region.reset(lo, hi, kMaxRegionCells) || !seen.reset(lo, hi, kMaxRegionCells)) return -1;
  // a cell joins when its update would change nothing after a ray's visit
  const auto no_op = [&](const octomap::OcTreeKey& key) {
    if (ends.contains(pack_key(key))) return ends_in;
    return fully_free(map, key);
  };
  if (!origin_in && !no_op(ko)) return 0;
  region.set(ko[0], ko[1], ko[2]);
  seen.set(ko[0], ko[1], ko[2]);
  frontier.push_back(ko);
  long count = 1;
  for (int level = 1; level < max_level + 1; ++level) {
    next_frontier.clear();
    for (size_t j = 0; j < frontier.size(); ++j) {
      const octomap::OcTreeKey c = frontier[j];
      for (int axis = 0; axis < 3; ++axis) {
        for (int d = 0; d < 2; ++d) {
          const int step = d == 0 ? 1 : -1;
          if (c[axis] != ko[axis] && (step > 0) != (c[axis] > ko[axis]))
            continue;  // only away from the origin
          octomap::OcTreeKey nb = c;
          nb[axis] = static_cast<octomap::key_type>(static_cast<int>(c[axis]) + step);
          if (!seen.inside(nb[0], nb[1], nb[2]) || seen.test(nb[0], nb[1], nb[2])) continue;
          seen.set(nb[0], nb[1], nb[2]);
          bool ok = true;
          for (int b = 0; b < 3; ++b) {  // test cells: one step back toward the origin
            if (nb[b] == ko[b]) continue;
            octomap::OcTreeKey t = nb;
            t[b] = static_cast<octomap::key_type>(static_cast<int>(nb[b]) +
                                                  (nb[b] > ko[b] ? -1 : 1));
            if (!(region.inside(t[0], t[1], t[2]) && region.test(t[0], t[1], t[2]))) {
              ok = false;
              break;
            }
          }
          if (!ok || !no_op(nb)) continue;
          region.set(nb[0], nb[1], nb[2]);
          next_frontier.push_back(nb);
          count += 1;
        }
      }
    }
    if (next_frontier.empty()) break;
    frontier.swap(next_frontier);
  }
  return count;
}

namespace scan_detail {

// What the threads of one scan's traversal share, read only.
struct Rays {
  double res;
  const octomap::point3d* origin;
  const octomap::OcTreeKey* key_origin;
  const octomap::point3d* ends;  // per ray: its end after truncation
  const octomap::OcTreeKey* end_keys;
  const uint8_t* end_ok;
  const uint32_t* ray_ids;  // super rays: the rays to walk and their weights; nullptr
  const uint32_t* ray_weights;
  const uint32_t* weights;  // per ray, or nullptr
  const CellBox* region;    // the culling region over the scan's key box
  bool cull;                // the region holds more than the sensor's cell: hide rays
  bool walk_back;           // and at least kMinWalkBackRegion cells: walk rays back
  const int* lo;            // the scan's key box
  const uint64_t* dims;
  uint64_t max_cells;  // 0: no limit
};

// Walk rays r0 <= r < r1 of a scan (of its super rays when it has them) into one
// thread's `sink` (CountSink, or a map's in-place updates: scan_updates' `direct`),
// which takes each visit with the ray's weight. Adds to `tally` the cell visits,
// those that super rays spared (each walked ray's visits times the other rays of its
// class), the rays the culling region hid whole, and the visits the region spared (a
// hidden ray's key_distance: one too many where its walk would stop short of its end
// cell); with
// `visits` (diagnose), counts every visit there too.
//
// With s.max_cells, stops (setting `stop`) once the sink's distinct cells outnumber
// it; stops when another thread set `stop`. The sink is a copy, local to the walk,
// which the stores to its counts (bytes, which may alias anything) cannot alias.
template <class Sink>
static inline void walk_rays(const Rays* s, ptrdiff_t r0, ptrdiff_t r1, Sink sink,
                             KeyTable* visits, WalkCounts* tally, StopFlag* stop) {
  uint32_t w = 1;
  long n_spared = 0, n_culled = 0, n_region_spared = 0;
  RayWalker walker;
  std::vector<uint64_t> back;
  long n_visits = 0;
  const CellBox* region = s->region;
  const double inv_res = 1.0 / s->res;
  for (ptrdiff_t r = r0; r < r1; ++r) {
    if (stop->get()) break;
    ptrdiff_t i;
    const long visits_before = n_visits;
    if (s->ray_ids != nullptr) {
      i = s->ray_ids[r];
      w = s->ray_weights[r];
    } else {
      i = r;
      if (s->weights != nullptr) w = s->weights[i];
    }
    if (!s->end_ok[i]) continue;  // computeRayKeys's out-of-range check
    // a ray whose cells all lie in the region (the most, once it has grown) is done
    // without its start()
    if (s->cull && RayWalker::hidden(*region, s->res, inv_res, *s->origin, *s->key_origin,
                                     s->ends[i], s->end_keys[i])) {
      ++n_culled;
      n_region_spared += key_distance(*s->key_origin, s->end_keys[i]);
      continue;
    }
    bool more = walker.start(s->res, *s->origin, *s->key_origin, s->ends[i], s->end_keys[i]);
    if (more && s->walk_back) {
      back.clear();
      if (walker.template walk_back<Sink::kKeys>(*region, back)) {
        // the region's box is the scan's key box
        for (size_t j = 0; j < back.size(); ++j) {
          sink.box(back[j], w);
          if (visits != nullptr)
            visits->get(Sink::kKeys ? back[j] : pack_key(box_key(back[j], s->lo, s->dims)))
                ->n_free += 1;
        }
        n_visits += back.size();
        // certified to reach the end cell: key_distance visits, `back` of them made
        n_region_spared +=
            key_distance(*s->key_origin, s->end_keys[i]) - static_cast<long>(back.size());
        more = false;
      } else {
        // the region is closed under stepping toward the origin, so a ray's cells in
        // it form a prefix of its traversal
        while (more && region->inside(walker.key(0), walker.key(1), walker.key(2)) &&
               region->test(walker.key(0), walker.key(1), walker.key(2))) {
          more = walker.next();
          ++n_region_spared;
        }
      }
    }
    if (more) {
      n_visits += walker.visit_rest([&](int kx, int ky, int kz) {
        sink.cell(kx, ky, kz, w);
        if (visits != nullptr) {
          octomap::OcTreeKey key;
          key[0] = static_cast<octomap::key_type>(kx);
          key[1] = static_cast<octomap::key_type>(ky);
          key[2] = static_cast<octomap::key_type>(kz);
          visits->get(pack_key(key))->n_free += 1;
        }
      });
    }
    if (s->ray_ids != nullptr) n_spared += (n_visits - visits_before) * (w - 1);
    if (s->max_cells && sink.distinct() > s->max_cells) {
      stop->set();
      break;
    }
  }
  tally->visits += n_visits;
  tally->spared += n_spared;
  tally->culled += n_culled;
  tally->region_spared += n_region_spared;
}

}  // namespace scan_detail

// Collect one update per cell for a scan of `n` points (rows of three floats, appended
// to `cells`, keys distinct).
//
// Every ray is traversed as liboctomap's computeRayKeys traverses it (RayWalker); the
// cells are collected with their counts (rays passing through, rays ending in) and
// each gets one update: in scan mode l_hit if any ray ends in it, else l_miss
// (liboctomap's insertPointCloud); in ray mode n_free*l_miss + n_hit*l_hit. With
// `culling`, the cells of the scan's culling region (build_region, using `fully_free`
// on `map`) are skipped: a ray's visit changes nothing there (fully free cells
// without end points; in scan mode, end cells too); rays are walked back from their
// end until they enter it, or not walked at all where RayWalker::hidden tells that
// all their cells lie in it (stats->culled_rays). With
// `weights` (ray mode; nullptr: none), ray i counts weights[i] times. With
// `superray_threshold` != 0 the rays are first grouped into super rays (super_rays, with
// the threshold's magnitude; adaptive where it is negative) and one ray per class is
// traversed. `counts` is the caller's scratch array, zero between calls unless
// `counts_dirty` (an exception left it dirty); scan mode keeps one byte of it per cell
// (a flag). With `diagnose` (slow), stats->unnecessary counts the visits of the walked
// rays to cells whose update changes nothing: fully free cells that no ray ends in (the dissertation's "unnecessary
// traversals", Table 2.3).
//
// Returns Status::out_of_range when a ray's end (after truncation) lies outside the key
// range, else Status::ray_too_short when a ray cannot be walked, collecting nothing
// (the caller finds and reports the rows). With `max_cells` > 0, a scan whose rays
// reach more than that many distinct cells collects nothing and returns
// Status::too_many_cells (a lower bound on them is checked after each ray, so memory
// stays within one ray per thread of it plus the end cells; the exact count decides).
//
// The rays are walked on up to `n_threads` OpenMP threads (fewer for small scans; one
// with `diagnose`). In scan mode they share one array of flags over the scan's key box
// (a cell is collected by the thread that flags it first); in ray mode each counts into
// a slice of `counts` of its own (no more threads than slices fit the dense limit).
// Where the box alone exceeds the limit, each thread counts in a table of its own. The
// counts are merged (integer sums) before the cells are collected, so the cells, their
// updates and the statistics are the same for every `n_threads`; only the order of
// `cells` may differ.
//
// With `free_only` (nullptr: none), a ray i with free_only[i] != 0 only clears: it is
// handled as a ray truncated at `max_range` is (octomap_server's ground points) -- its
// cells up to its (possibly truncated) end count as free, its end cell gets nothing
// from it, it is never grouped into a super ray, and its end does not keep a cell out
// of the culling region -- so every method stays exact.
//
// With `direct` (nullptr: none; scan mode, one thread, a key box within the dense
// limit, and `max_cells` out of reach of the rays), the map updates its cells in place
// instead: direct->begin_scan(lo, dims) with the scan's key box, direct->update(kx, ky,
// kz, update) for each end cell (l_hit) and then for each cell a walk visits (l_miss;
// the map ignores a cell it has updated in this scan), direct->finish() after the walk.
// `cells` then stays empty; the statistics are the same.
template <class Direct = scan_detail::NoDirect>
static inline Status scan_updates(const octomap::OcTree& keys, const float* points, ptrdiff_t n,
                           const octomap::point3d& o, double max_range, bool ray_mode,
                           bool culling, const uint32_t* weights, int superray_threshold,
                           FreeTest fully_free, void* map, std::vector<uint32_t>& counts,
                           bool& counts_dirty, std::vector<ScanCell>& cells, ScanStats* stats,
                           bool diagnose, uint64_t max_cells, int n_threads,
                           const uint8_t* free_only = nullptr, Direct* direct = nullptr) {
  using namespace scan_detail;
  using octomap::OcTreeKey;
  using octomap::point3d;
  const int collect_threads = diagnose ? 1 : std::max(1, std::min(n_threads, kMaxThreads));
  const bool weighted = weights != nullptr;
  std::vector<uint32_t> ray_ids, ray_weights;  // the rays to traverse, super rays
  ptrdiff_t n_trav = n;
  std::vector<point3d> ends;
  std::vector<uint8_t> truncated;
  KeyTable table;
  CellBox region;
  OcTreeKey ko, key;
  int lo[3], hi[3];
  int max_level = 0;
  uint64_t reach = 0;  // at least the distinct cells the rays can visit
  const float l_hit = keys.getProbHitLog(), l_miss = keys.getProbMissLog();
  std::vector<uint64_t> touched;  // box indices with a nonzero count
  uint64_t dims[3];
  uint64_t box_cells = 1;
  std::vector<OcTreeKey> end_keys;
  std::vector<uint8_t> end_ok;
  KeyTable visits;  // with diagnose: walked visits per cell
  const double res = keys.getResolution(), rf = 1.0 / res;
  Rays rays;
  StopFlag stop;
  long out_of_range = 0, too_short = 0;
  empty_stats(stats);
  keys.coordToKeyChecked(o, ko);
  for (int axis = 0; axis < 3; ++axis) lo[axis] = hi[axis] = ko[axis];
  ends.resize(n);
  end_keys.resize(n);
  end_ok.resize(n);
  truncated.resize(n);
  table.reset(static_cast<size_t>(n) / 8);
  // end cells first: they bound the region and may never join it
  uint64_t last_key = KeyTable::kEmpty;
  KeyCounts* last_entry = nullptr;  // valid until the next table.get (which may grow it)
  for (ptrdiff_t i = 0; i < n; ++i) {
    const float* p = points + 3 * i;
    truncated[i] = effective_end(o, point3d(p[0], p[1], p[2]), max_range, &ends[i]);
    if (free_only != nullptr && free_only[i]) truncated[i] = 1;  // clears only, as a cut ray
    end_ok[i] = key_checked(rf, ends[i].x(), &key[0]) && key_checked(rf, ends[i].y(), &key[1]) &&
                key_checked(rf, ends[i].z(), &key[2]);
    if (!end_ok[i]) {
      ++out_of_range;
      continue;
    }
    if (!(key == ko) && !walkable(o, ends[i])) {
      end_ok[i] = false;  // a ray too short to walk: the caller reports it
      ++too_short;
      continue;
    }
    end_keys[i] = key;
    int level = 0;
    for (int axis = 0; axis < 3; ++axis) {
      lo[axis] = std::min(lo[axis], static_cast<int>(key[axis]));
      hi[axis] = std::max(hi[axis], static_cast<int>(key[axis]));
      level += std::abs(static_cast<int>(key[axis]) - static_cast<int>(ko[axis]));
    }
    max_level = std::max(max_level, level);
    reach += level + 4;  // the cells a walk can visit: a step a key, past the end by few
    if (truncated[i]) continue;
    // consecutive points of a scan often end in one cell: its entry is kept
    const uint64_t packed = pack_key(key);
    if (packed != last_key) {
      last_entry = table.get(packed);
      last_key = packed;
    }
    last_entry->n_hit += weighted ? weights[i] : 1;
  }
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[1]);
  // nothing changed: the caller reports the bad rows
  if (out_of_range) return Status::out_of_range;
  if (too_short) return Status::ray_too_short;
  if (superray_threshold != 0) {  // < 0: adaptive
    super_rays(res, o, ko, ends, end_keys, truncated, table, std::abs(superray_threshold),
               ray_ids, ray_weights, collect_threads, superray_threshold < 0);
    n_trav = static_cast<ptrdiff_t>(ray_ids.size());
  }
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[2]);
  // scan mode: every ray that leaves the sensor's cell crosses it, so it is collected
  // below, and the region may start there whatever its state
  const bool origin_in = culling && !ray_mode && max_level > 0;
  if (culling)
    stats->region_cells = build_region(fully_free, map, ko, lo, hi, max_level, table, region,
                                       !ray_mode, origin_in);
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[3]);
  for (int axis = 0; axis < 3; ++axis) {
    dims[axis] = static_cast<uint64_t>(hi[axis] - lo[axis] + 1);
    box_cells *= dims[axis];
  }
  // threads: one with `diagnose`, and at least kMinThreadRays rays each
  if (diagnose || n_threads < 1) n_threads = 1;
  n_threads = std::min(std::min(n_threads, kMaxThreads),
                       static_cast<int>(std::max<ptrdiff_t>(n_trav / kMinThreadRays, 1)));
  // walking back to a region of the sensor's cell alone would spare one visit a ray and
  // cost more than the visits it spares
  const bool cull = stats->region_cells > 1;
  rays.res = res;
  rays.origin = &o;
  rays.key_origin = &ko;
  rays.ends = ends.data();
  rays.end_keys = end_keys.data();
  rays.end_ok = end_ok.data();
  rays.ray_ids = superray_threshold != 0 ? ray_ids.data() : nullptr;
  rays.ray_weights = superray_threshold != 0 ? ray_weights.data() : nullptr;
  rays.weights = weighted ? weights : nullptr;
  rays.region = &region;
  rays.cull = cull;
  rays.walk_back = stats->region_cells >= kMinWalkBackRegion;
  rays.lo = lo;
  rays.dims = dims;
  rays.max_cells = max_cells;
  // `direct` (scan mode, one thread): the map updates its cells in place during the
  // walk (Direct::update marks a cell for this scan and gives it its one update; the
  // end cells first, l_hit, so that no walk updates them), without flags, collected
  // cells or an update pass afterwards -- where the cells the rays can reach stay
  // within max_cells, so that the scan cannot be refused once it has begun
  if (direct != nullptr && !ray_mode && !diagnose && n_threads == 1 &&
      box_cells <= kMaxDenseCells && (max_cells == 0 || reach + table.size() <= max_cells)) {
    direct->begin_scan(lo, dims);
    for (size_t slot = 0; slot < table.capacity(); ++slot) {
      if (table.slot(slot).key == KeyTable::kEmpty) continue;
      key = unpack_key(table.slot(slot).key);
      direct->update(key[0], key[1], key[2], l_hit);
    }
    if (origin_in && cull) direct->update(ko[0], ko[1], ko[2], l_miss);  // no walk visits it
    DirectSink<Direct> sink{direct, l_miss};
    WalkCounts tally;
    walk_rays(&rays, 0, n_trav, sink, nullptr, &tally, &stop);
    add_walk_counts(stats, tally);
    clock_gettime(CLOCK_MONOTONIC, &stats->clock[4]);
    direct->finish();
    stats->rays = n_trav;
    return Status::ok;
  }
  // in scan mode a cell's update asks only whether a ray crossed it, so every thread
  // sets flags in one array (count_box); in ray mode each thread's counts get their own
  // slice of `counts`, within the dense limit: no more threads than slices fit (counting
  // in tables instead is several times slower). A box larger than the limit is counted
  // in tables by every thread.
  const bool dense = box_cells <= kMaxDenseCells;
  const bool shared = dense && !ray_mode && n_threads > 1;
  const uint64_t slices = shared ? 1 : n_threads;
  if (dense && !shared)
    n_threads = static_cast<int>(std::min<uint64_t>(n_threads, kMaxDenseCells / box_cells));
  // scan mode asks of a cell only whether a ray crossed it: a byte a cell (flags, in
  // the storage of `counts`), a quarter of the memory, which the caches hold better
  const uint64_t words = ray_mode ? box_cells * slices : (box_cells + 3) / 4;
  if (dense && (counts_dirty || counts.size() < words))
    counts.assign(std::max<uint64_t>(words, counts.size()), 0);
  counts_dirty = true;
  uint8_t* const flags = reinterpret_cast<uint8_t*>(counts.data());
  // a cell's count in the box, and clearing it, in either mode
  const auto count_at = [&](uint64_t idx) -> uint32_t {
    return ray_mode ? counts[idx] : flags[idx];
  };
  const auto clear_at = [&](uint64_t idx) {
    if (ray_mode) counts[idx] = 0;
    else flags[idx] = 0;
  };
  // scan mode: a cell an end point lies in gets l_hit whatever crosses it, so the end
  // cells in the box are flagged first (the walk then never collects them, and the
  // table's pass below does), and a collected cell's update is l_miss
  const bool ends_flagged = dense && !ray_mode;
  const auto for_end_cells = [&](auto&& f) {  // f(box index) for the table's cells in the box
    for (size_t slot = 0; slot < table.capacity(); ++slot) {
      if (table.slot(slot).key == KeyTable::kEmpty) continue;
      key = unpack_key(table.slot(slot).key);
      if (in_box(key, lo, dims)) f(box_index(key, lo, dims));
    }
  };
  if (ends_flagged) for_end_cells([&](uint64_t idx) { flags[idx] = 2; });
  if (origin_in && cull) {  // no walk visits the sensor's cell now
    if (dense) {
      const uint64_t idx = box_index(ko, lo, dims);
      if (flags[idx] == 0) {
        flags[idx] = 1;
        touched.push_back(idx);
      }
    } else {
      table.get(pack_key(ko))->n_free += 1;
    }
  }
  // walk rays r0 <= r < r1 into the counts of thread `t` (walk_rays)
  const auto walk = [&](ptrdiff_t r0, ptrdiff_t r1, int t, std::vector<uint64_t>* t_touched,
                        KeyTable* t_table, size_t base, KeyTable* t_visits,
                        WalkCounts* t_tally) {
    if (ray_mode) {
      CountSink<uint32_t> sink{
          dense ? counts.data() + static_cast<uint64_t>(t) * box_cells : nullptr,
          t_touched, t_table, base, dense, shared, {lo[0], lo[1], lo[2]},
          {dims[0], dims[1], dims[2]}};
      walk_rays(&rays, r0, r1, sink, t_visits, t_tally, &stop);
    } else {  // one array of flags for every thread
      CountSink<uint8_t> sink{dense ? flags : nullptr, t_touched, t_table, base, dense, shared,
                              {lo[0], lo[1], lo[2]}, {dims[0], dims[1], dims[2]}};
      walk_rays(&rays, r0, r1, sink, t_visits, t_tally, &stop);
    }
  };
  // thread 0 counts into the scan's own table (its first `hits` entries: the end
  // cells), the others into tables of their own
  const size_t hits = table.size();
  if (n_threads == 1) {
    WalkCounts tally;
    walk(0, n_trav, 0, &touched, &table, hits, diagnose ? &visits : nullptr, &tally);
    add_walk_counts(stats, tally);
  } else {
    std::vector<std::vector<uint64_t>> part_touched(n_threads);  // threads 1, 2, ...: new cells
    std::vector<KeyTable> part_tables(n_threads - 1);             // and their other cells
    std::vector<WalkCounts> part_tally(n_threads);
    const ptrdiff_t n_chunks =
        std::min<ptrdiff_t>(n_trav, static_cast<ptrdiff_t>(n_threads) * kChunksPerThread);
    std::exception_ptr error;
#pragma omp parallel for num_threads(n_threads) schedule(dynamic)
    for (ptrdiff_t c = 0; c < n_chunks; ++c) {
#ifdef _OPENMP
      const int t = omp_get_thread_num();
#else
      const int t = 0;
#endif
      // chunks taken one after another lie in different parts of the scan (its rays
      // split in n_threads parts): threads walking at the same time then flag cells
      // far apart, not neighbours on one cache line
      const ptrdiff_t k = n_chunks % n_threads == 0
                              ? (c % n_threads) * (n_chunks / n_threads) + c / n_threads
                              : c;
      try {
        walk(k * n_trav / n_chunks, (k + 1) * n_trav / n_chunks, t,
             t == 0 ? &touched : &part_touched[t], t == 0 ? &table : &part_tables[t - 1],
             t == 0 ? hits : 0, nullptr, &part_tally[t]);
      } catch (...) {
#pragma omp critical(occgp_scan_error)
        if (!error) error = std::current_exception();
        stop.set();
      }
    }
    if (error) std::rethrow_exception(error);
    // merge into thread 0's counts (integer sums: the order does not matter), leaving
    // the other slices zero; shared flags need only the new cells appended
    add_walk_counts(stats, part_tally[0]);
    for (int t = 1; t < n_threads; ++t) {
      if (shared) {
        touched.insert(touched.end(), part_touched[t].begin(), part_touched[t].end());
      } else if (dense) {  // ray mode
        uint32_t* part = counts.data() + static_cast<uint64_t>(t) * box_cells;
        for (const uint64_t idx : part_touched[t]) {
          if (counts[idx] == 0) touched.push_back(idx);
          counts[idx] += part[idx];
          part[idx] = 0;
        }
      }
      if (!stop.get()) {
        const KeyTable& part_table = part_tables[t - 1];
        for (size_t slot = 0; slot < part_table.capacity(); ++slot) {
          if (part_table.slot(slot).key != KeyTable::kEmpty)
            table.get(part_table.slot(slot).key)->n_free += part_table.slot(slot).n_free;
        }
      }
      add_walk_counts(stats, part_tally[t]);
    }
  }
  clock_gettime(CLOCK_MONOTONIC, &stats->clock[4]);
  bool too_many = false;
  if (stop.get()) {
    too_many = true;
  } else if (max_cells) {
    // the distinct cells: those counted in the box, and the table's others
    uint64_t distinct = touched.size() + table.size();
    if (dense && !ends_flagged) {
      for (size_t slot = 0; slot < table.capacity(); ++slot) {
        if (table.slot(slot).key == KeyTable::kEmpty) continue;
        key = unpack_key(table.slot(slot).key);
        if (in_box(key, lo, dims) && count_at(box_index(key, lo, dims))) distinct -= 1;
      }
    }
    too_many = distinct > max_cells;
  }
  if (too_many) {
    for (const uint64_t idx : touched) clear_at(idx);
    if (ends_flagged) for_end_cells(clear_at);
    counts_dirty = false;
    return Status::too_many_cells;  // nothing changed: the caller reports it
  }
  // one update per cell: the traversed cells (on the threads), then the table's: end cells
  // (in scan mode all of them; else those no ray crossed) and cells outside the box
  const ptrdiff_t n_touched = static_cast<ptrdiff_t>(touched.size());
  cells.reserve(touched.size() + table.size());
  cells.resize(touched.size());
  const int ct = n_touched >= kMinParallelCollect ? collect_threads : 1;  // not the walk's
#pragma omp parallel for num_threads(ct) schedule(static) if (ct > 1)
  for (ptrdiff_t t = 0; t < n_touched; ++t) {
    cells[t].key = pack_key(box_key(touched[t], lo, dims));
    if (ends_flagged) {
      cells[t].update = l_miss;
    } else {
      const KeyCounts* entry = table.find(cells[t].key);
      cells[t].update = update_value(count_at(touched[t]), entry ? entry->n_hit : 0, ray_mode,
                                     l_hit, l_miss);
    }
  }
  ScanCell cell;
  for (size_t slot = 0; slot < table.capacity(); ++slot) {
    if (table.slot(slot).key == KeyTable::kEmpty) continue;
    key = unpack_key(table.slot(slot).key);
    uint32_t n_free = table.slot(slot).n_free;
    if (dense && in_box(key, lo, dims)) {
      const uint64_t idx = box_index(key, lo, dims);
      if (ends_flagged) {
        clear_at(idx);  // an end cell: l_hit
      } else if (count_at(idx)) {
        continue;  // collected above
      }
      n_free = 0;
    }
    cell.key = pack_key(key);
    cell.update = update_value(n_free, table.slot(slot).n_hit, ray_mode, l_hit, l_miss);
    cells.push_back(cell);
  }
#pragma omp parallel for num_threads(ct) schedule(static) if (ct > 1)
  for (ptrdiff_t t = 0; t < n_touched; ++t) clear_at(touched[t]);
  counts_dirty = false;
  stats->rays = n_trav;
  if (diagnose) {
    stats->unnecessary = 0;
    for (size_t slot = 0; slot < visits.capacity(); ++slot) {
      if (visits.slot(slot).key == KeyTable::kEmpty) continue;
      const KeyCounts* entry = table.find(visits.slot(slot).key);
      if ((entry == nullptr || entry->n_hit == 0) &&
          fully_free(map, unpack_key(visits.slot(slot).key)))
        stats->unnecessary += visits.slot(slot).n_free;
    }
  }
  return Status::ok;
}

}  // namespace occgp

#endif  // OCCGP_SCAN_H
