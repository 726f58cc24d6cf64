# cython: language_level=3
# distutils: language = c++
"""Compiled core of :class:`occgp.ColorOctree`: liboctomap's ``ColorOcTree`` behind typed loops.

Nothing here validates user input: :mod:`occgp.color` coerces and checks every
array (shape, dtype, range, key range) before it reaches these methods. Every
loop and every liboctomap call that does real work runs without the GIL; a
per-tree lock serialises the operations on one tree.

Inner nodes' colours are derived state: liboctomap's ``ColorOcTree::
updateInnerOccupancy`` sets each to the average of its children's. occgp calls
it before the tree is written (when an update changed the tree since), which
gives the file liboctomap's own call sequence gives; leaves, and so every
query, never depend on it.
"""

cimport cython
from cython.operator cimport dereference as deref, preincrement as inc
from libc.stdint cimport uint8_t, uint64_t
from libc.string cimport memcpy
from libcpp cimport bool
from libcpp.algorithm cimport sort
from libcpp.pair cimport pair
from libcpp.string cimport string
from libcpp.unordered_map cimport unordered_map
from libcpp.vector cimport vector

from _keys cimport effective_end, pack_key as _pack, unpack_key as _unpack
from liboctomap cimport (
    Color, ColorOcTree, ColorOcTreeNode, KeyRay, OcTreeKey, Pointcloud, ostringstream, point3d,
)

import numpy as np


cdef enum:
    _FUSE_AVERAGE = 0
    _FUSE_MEAN = 1

#: Colour fusion rules of :meth:`_ColorOcTree._insert_colored`.
FUSE_AVERAGE = _FUSE_AVERAGE
FUSE_MEAN = _FUSE_MEAN


cdef struct ColorSum:
    uint64_t r, g, b, n


cdef int _insert_key_sets(ColorOcTree* tree, const float[:, ::1] points,
                          const float[:, ::1] free_points, const point3d& o,
                          double max_range) except -1 nogil:
    """liboctomap's ``insertPointCloud`` (its ``computeUpdate`` key sets, one
    ``updateNode`` per cell, a cell in both sets occupied) for `points`, with the rays
    to `free_points` adding their cells to the free set only (octomap_server's ground
    points): each such ray is cut at `max_range` (< 0: none) as a point's ray is, and
    its end cell gets nothing from it."""
    cdef KeyRay ray
    cdef KeyRay.iterator it
    cdef unordered_map[uint64_t, bool] cells   # packed key -> occupied
    cdef unordered_map[uint64_t, bool].iterator c
    cdef point3d p, end
    cdef OcTreeKey key
    cdef Py_ssize_t i
    cdef int part
    cdef bint truncated
    cdef float l_hit = tree.getProbHitLog(), l_miss = tree.getProbMissLog()
    cdef const float[:, ::1] rows
    for part in range(2):
        rows = points if part == 0 else free_points
        for i in range(rows.shape[0]):
            p = point3d(rows[i, 0], rows[i, 1], rows[i, 2])
            truncated = effective_end(o, p, max_range, &end)
            if tree.computeRayKeys(o, end, ray):
                it = ray.begin()
                while it != ray.end():
                    cells.insert(pair[uint64_t, bool](_pack(deref(it)), False))
                    inc(it)
            if part == 0 and not truncated and tree.coordToKeyChecked(p, key):
                cells[_pack(key)] = True
    c = cells.begin()
    while c != cells.end():
        tree.updateNode(_unpack(deref(c).first), l_hit if deref(c).second else l_miss, False)
        inc(c)
    return 0


ctypedef ColorOcTree Tree
ctypedef ColorOcTreeNode Node
cdef str _PUBLIC_CLASS = "ColorOctree"

include "_tree_core.pxi"


cdef class _ColorOcTree(_TreeCore):
    """A liboctomap ``ColorOcTree`` owned by Python. Use :class:`occgp.ColorOctree`."""

    # an update changed the tree since the inner nodes' colours were last computed
    cdef bint _inner_dirty

    cdef void _reset(self) noexcept:
        self._inner_dirty = False

    # ------------------------------------------------------------------ updates
    def _insert_colored(self, const float[:, ::1] points, const float[::1] origin,
                        double max_range, const uint8_t[:, ::1] colors, int fusion,
                        const float[:, ::1] free_points=None):
        """liboctomap's ``insertPointCloud`` (every ray valid: checked by the caller;
        with `free_points`, whose rays only clear, its key sets built here, see
        :func:`_insert_key_sets`), then the colour of each point whose ray is not
        truncated at `max_range` fused into its end cell. FUSE_AVERAGE: ``averageNodeColor`` point by point, in
        order. FUSE_MEAN: per end cell, the rounded mean of its points' colours, fused
        by one ``averageNodeColor`` per cell, in key order (x fastest). `colors` None:
        occupancy only, no colour changes (`fusion` ignored). Returns the number of
        points whose colour was fused."""
        cdef ColorOcTree* tree = self._get()
        cdef Pointcloud cloud
        cdef Py_ssize_t i, n = points.shape[0]
        cdef point3d o = point3d(origin[0], origin[1], origin[2])
        cdef point3d p, end
        cdef OcTreeKey key
        cdef unordered_map[uint64_t, ColorSum] sums
        cdef unordered_map[uint64_t, ColorSum].iterator it
        cdef vector[uint64_t] order
        cdef ColorSum* s
        cdef size_t j
        cdef Py_ssize_t fused = 0
        cdef bint sets = free_points is not None
        cdef bint paint = colors is not None
        with self._lock:
            with nogil:
                self._inner_dirty = True
                if sets:
                    _insert_key_sets(tree, points, free_points, o, max_range)
                else:
                    cloud.reserve(n)
                    for i in range(n):
                        cloud.push_back(points[i, 0], points[i, 1], points[i, 2])
                    tree.insertPointCloud(cloud, o, max_range, False, False)
                for i in range(n if paint else 0):
                    p = point3d(points[i, 0], points[i, 1], points[i, 2])
                    if effective_end(o, p, max_range, &end):
                        continue
                    if not tree.coordToKeyChecked(p, key):
                        continue
                    fused += 1
                    if fusion == _FUSE_AVERAGE:
                        tree.averageNodeColor(key, colors[i, 0], colors[i, 1], colors[i, 2])
                    else:
                        s = &sums[_pack(key)]
                        s.r += colors[i, 0]
                        s.g += colors[i, 1]
                        s.b += colors[i, 2]
                        s.n += 1
                if paint and fusion == _FUSE_MEAN:
                    order.reserve(sums.size())
                    it = sums.begin()
                    while it != sums.end():
                        order.push_back(deref(it).first)
                        inc(it)
                    # key order, z slowest: packed keys hold x in the low bits
                    sort(order.begin(), order.end())
                    for j in range(order.size()):
                        s = &sums[order[j]]
                        tree.averageNodeColor(
                            _unpack(order[j]), <uint8_t>((2 * s.r + s.n) // (2 * s.n)),
                            <uint8_t>((2 * s.g + s.n) // (2 * s.n)),
                            <uint8_t>((2 * s.b + s.n) // (2 * s.n)))
        return fused

    def _fuse_colors(self, const float[:, ::1] points, const uint8_t[:, ::1] colors,
                     bint replace):
        """For each point in a known cell (in order): ``averageNodeColor`` of its colour,
        or ``setNodeColor`` with `replace`. Points in unknown cells are skipped. Returns
        a bool mask of the points whose cell was known."""
        cdef ColorOcTree* tree = self._get()
        cdef Py_ssize_t i, n = points.shape[0]
        cdef OcTreeKey key
        cdef ColorOcTreeNode* node
        known = np.zeros(n, dtype=np.bool_)
        cdef uint8_t[::1] k = known.view(np.uint8)
        with self._lock:
            with nogil:
                self._inner_dirty = True
                for i in range(n):
                    if not tree.coordToKeyChecked(
                            point3d(points[i, 0], points[i, 1], points[i, 2]), key):
                        continue
                    if replace:
                        node = tree.setNodeColor(key, colors[i, 0], colors[i, 1], colors[i, 2])
                    else:
                        node = tree.averageNodeColor(key, colors[i, 0], colors[i, 1],
                                                     colors[i, 2])
                    k[i] = node != NULL
        return known

    def _colors(self, const float[:, ::1] points):
        """(colours uint8 (n, 3), set bool (n,)) of the cells holding `points`: the
        cell's colour, or liboctomap's unset white (255, 255, 255) where the cell is
        unknown or its colour is unset (then False)."""
        cdef ColorOcTree* tree = self._get()
        cdef Py_ssize_t i, n = points.shape[0]
        cdef OcTreeKey key
        cdef ColorOcTreeNode* node
        cdef Color c
        rgb = np.full((n, 3), 255, dtype=np.uint8)
        has = np.zeros(n, dtype=np.bool_)
        cdef uint8_t[:, ::1] out = rgb
        cdef uint8_t[::1] h = has.view(np.uint8)
        with self._lock:
            with nogil:
                for i in range(n):
                    if not tree.coordToKeyChecked(
                            point3d(points[i, 0], points[i, 1], points[i, 2]), key):
                        continue
                    node = tree.search(key, 0)
                    if node == NULL:
                        continue
                    c = node.getColor()
                    out[i, 0] = c.r
                    out[i, 1] = c.g
                    out[i, 2] = c.b
                    h[i] = node.isColorSet()
        return rgb, has

    def _leaves(self, bint occupied_only):
        """Centres (n, 3), sizes (n,), log-odds (n,) and colours (n, 3) uint8 of the
        leaves, in liboctomap's leaf order."""
        cdef ColorOcTree* tree = self._get()
        cdef vector[double] centers, sizes
        cdef vector[float] values
        cdef vector[uint8_t] rgb
        cdef ColorOcTree.leaf_iterator it, end
        cdef Color c
        cdef unsigned depth
        with self._lock:
            with nogil:
                if tree.size() > 0:
                    it = tree.begin_leafs(0)
                    end = tree.end_leafs()
                    while it != end:
                        if not occupied_only or tree.isNodeOccupied(&deref(it)):
                            depth = it.getDepth()
                            centers.push_back(tree.keyToCoord(it.getKey()[0], depth))
                            centers.push_back(tree.keyToCoord(it.getKey()[1], depth))
                            centers.push_back(tree.keyToCoord(it.getKey()[2], depth))
                            sizes.push_back(it.getSize())
                            values.push_back(deref(it).getLogOdds())
                            c = deref(it).getColor()
                            rgb.push_back(c.r)
                            rgb.push_back(c.g)
                            rgb.push_back(c.b)
                        inc(it)
        cdef Py_ssize_t n = sizes.size()
        out_c = np.empty((n, 3))
        out_s = np.empty(n)
        out_v = np.empty(n, dtype=np.float32)
        out_rgb = np.empty((n, 3), dtype=np.uint8)
        cdef double[:, ::1] oc = out_c
        cdef double[::1] os_ = out_s
        cdef float[::1] ov = out_v
        cdef uint8_t[:, ::1] orgb = out_rgb
        if n:
            memcpy(&oc[0, 0], centers.data(), 3 * n * sizeof(double))
            memcpy(&os_[0], sizes.data(), n * sizeof(double))
            memcpy(&ov[0], values.data(), n * sizeof(float))
            memcpy(&orgb[0, 0], rgb.data(), 3 * n * sizeof(uint8_t))
        return out_c, out_s, out_v, out_rgb

    # ------------------------------------------------------------------ structure
    # ------------------------------------------------------------------ serialisation
    def _write_data(self):
        """The tree's .ot data block (no header), after liboctomap's
        ``updateInnerOccupancy`` when an update changed the tree since the last one."""
        cdef ColorOcTree* tree = self._get()
        cdef ostringstream stream
        cdef string data
        with self._lock:
            with nogil:
                # ColorOcTree::updateInnerOccupancy dereferences the root unchecked
                if self._inner_dirty and tree.size() > 0:
                    tree.updateInnerOccupancy()
                self._inner_dirty = False
                tree.writeData(stream)
                data = stream.str()
        return <bytes>data

    def _read_data(self, bytes payload, double resolution):
        """Replace the tree by the .ot data block `payload` (validated by the caller)."""
        self._read(payload, False, resolution)
