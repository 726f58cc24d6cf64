"""Queries of the occupancy octree: values at points and depths, ray casts, key
conversions and cell listings.

The functions are methods of :class:`occgp.OccupancyOctree`, which binds them in its
class body (``leaves = _queries.leaves``), so their first argument is the map, named
``self``; they call its compiled core (``_query_depth``, ``_nodes``, ``_cast_rays``,
...)."""

from __future__ import annotations

import numbers
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docfill import fill_doc
from .._params import renamed_keywords
from ._logodds import Leaves
from ._options import check_bbox
from .._octree import TREE_DEPTH, TREE_MAX_VAL
from .._validation import as_numeric, as_points, check_bool, check_int, check_real

__all__ = ["Nodes", "num_leaves", "num_nodes", "tree_repr", "as_float32_directions", "pack_keys", "unpack_keys", "coord_to_key",
           "key_to_coord", "extract_points", "occupancy", "log_odds", "is_occupied",
           "cast_rays", "leaves", "nodes", "is_at_threshold", "ray_intersections"]


class Nodes(NamedTuple):
    """The nodes of an octree, inner ones included (see :meth:`OccupancyOctree.nodes`)."""

    #: Node centers, metres, shape (n_nodes, 3).
    centers: NDArray[np.float64]
    #: Edge lengths, shape (n_nodes,): ``resolution * 2**(16 - depths)``.
    sizes: NDArray[np.float64]
    #: Tree depth of each node, uint8: 0 is the root, 16 the finest cells.
    depths: NDArray[np.uint8]
    #: Log-odds, float32 as liboctomap stores them; an inner node holds the largest
    #: log-odds of its children.
    log_odds: NDArray[np.float32]
    #: True where the node is listed as a leaf: it has no children, or lies at the
    #: listing's ``max_depth``.
    is_leaf: NDArray[np.bool_]


def tree_repr(self) -> str:
    """``OccupancyOctree(resolution=0.1, num_leaves=12)``: the octrees' repr."""
    return f"{type(self).__name__}(resolution={self.resolution!r}, num_leaves={self.num_leaves})"


def _num_leaves(self) -> int:
    """Number of leaves (known cells, after pruning)."""
    return self._num_leaves()


def _num_nodes(self) -> int:
    """Number of nodes in the tree, inner nodes included."""
    return self._num_nodes()


#: The octrees' (:class:`occgp.OccupancyOctree`, :class:`occgp.ColorOctree`) leaf and
#: node counts, as properties over their compiled cores.
num_leaves = property(_num_leaves)
num_nodes = property(_num_nodes)


def _check_bbox(self, bbox: ArrayLike) -> np.ndarray:
    """`bbox` as a float32 (2, 3) array: finite, min <= max, corners in key range."""
    box32 = check_bbox(bbox)
    ok = self._in_range(box32)
    if not ok.all():
        self._raise_out_of_range("bbox corners", ok, "")
    return box32


def coord_to_key(self, points: ArrayLike, depth: int = TREE_DEPTH) -> NDArray[np.uint16]:
    """The 16-bit keys of the cells holding `points` (liboctomap's ``coordToKey``).

    ``floor(coordinate / resolution) + 32768`` per axis, from the
    single-precision coordinate as liboctomap computes it. With `depth`
    below 16, the key of the depth-`depth` node holding the point, as
    liboctomap's ``coordToKey(coord, depth)`` and ``adjustKeyAtDepth``
    give it: the key at the node's center, ``(key >> s << s) + (1 << (s -
    1))`` per axis with ``s = 16 - depth``; ``key_to_coord(keys, depth)``
    gives the node's center.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
    depth : int, default=16
        Tree depth of the cells, in [1, 16] (16: the finest cells). Depth
        0, the root, has no key of its own (liboctomap's formula wraps
        around there).

    Returns
    -------
    keys : ndarray of uint16, shape (n_points, 3)

    Raises
    ------
    TypeError
        If `points` does not hold numbers or `depth` is not an int.
    ValueError
        If `points` is malformed, not finite, or outside the key range, or
        `depth` lies outside [1, 16].

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> OccupancyOctree(0.1).coord_to_key([[0.05, -0.05, 1.0]]).tolist()
    [[32768, 32767, 32778]]
    >>> OccupancyOctree(0.1).coord_to_key([[0.05, -0.05, 1.0]], depth=14).tolist()
    [[32770, 32766, 32778]]
    """
    depth = check_int(depth, "depth", low=1, high=TREE_DEPTH)
    pts = self._as_float32_points(points, "points")
    ok = self._in_range(pts)
    if not ok.all():
        self._raise_out_of_range("points", ok, "")
    keys = np.floor(pts.astype(np.float64) * (1.0 / self.resolution)) + TREE_MAX_VAL
    shift = TREE_DEPTH - depth
    if shift:
        keys = np.floor(keys / (1 << shift)) * (1 << shift) + (1 << (shift - 1))
    return np.ascontiguousarray(keys, dtype=np.uint16)


def key_to_coord(self, keys: ArrayLike, depth: int = TREE_DEPTH) -> NDArray[np.float64]:
    """Centers of the cells of `keys` at `depth` (liboctomap's ``keyToCoord``).

    Parameters
    ----------
    keys : array-like of int, shape (n_keys, 3)
        Keys in [0, 65535].
    depth : int, default=16
        Tree depth of the cells: 16 is the finest (edge ``resolution``),
        ``d`` gives the node of edge ``resolution * 2**(16 - d)`` holding
        the key.

    Returns
    -------
    centers : ndarray of shape (n_keys, 3)

    Raises
    ------
    TypeError
        If `keys` does not hold integers.
    ValueError
        If `keys` is not of shape (n_keys, 3), a key lies outside
        [0, 65535], or `depth` outside [0, 16].

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1)
    >>> m.key_to_coord(m.coord_to_key([[0.05, -0.05, 1.0]])).round(3).tolist()
    [[0.05, -0.05, 1.05]]
    """
    depth = check_int(depth, "depth", low=0, high=TREE_DEPTH)
    arr = as_numeric(keys, "keys", kinds="iu")
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"keys must have shape (n_keys, 3), got {arr.shape}")
    if arr.size and (arr.min() < 0 or arr.max() > 2 * TREE_MAX_VAL - 1):
        raise ValueError(f"keys must lie in [0, {2 * TREE_MAX_VAL - 1}], got "
                         f"[{arr.min()}, {arr.max()}]")
    return self._key_to_coord(np.ascontiguousarray(arr, dtype=np.uint16), depth)


def extract_points(self, occupied: bool = True) -> tuple[NDArray[np.float64],
                                                        NDArray[np.float64]]:
    """Centers and sizes of the occupied (or the free) leaves.

    Parameters
    ----------
    occupied : bool, default=True
        True: the leaves at or above the occupancy threshold; False: the
        known leaves below it.

    Returns
    -------
    centers : ndarray of shape (n_leaves, 3)
    sizes : ndarray of shape (n_leaves,)
        Edge of each leaf (pruned leaves are larger than the resolution).

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> centers, sizes = m.extract_points()
    >>> centers.round(2).tolist(), len(m.extract_points(occupied=False)[0])
    ([[0.55, 0.05, 0.05]], 5)
    """
    occupied = check_bool(occupied, "occupied")
    centers, sizes, values = self._leaves(False)
    keep = (values >= np.float32(self._log_odds_thresholds()[2])) == occupied
    return centers[keep], sizes[keep]


def occupancy(self, points: ArrayLike, *, depth: int = 0) -> NDArray[np.float64]:
    """Probability of occupancy at each point, NaN where the map knows nothing.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Query points, in metres. Points outside the key range are unknown.
    depth : int, default=0
        Tree depth of the answering node, in [0, 16]; 0 means 16 (the leaf
        holding the point). ``d`` answers with the depth-``d`` node holding
        the point, as liboctomap's ``search(key, depth)``: an inner node's
        value is the largest log-odds of its children, so a coarse query
        is conservative (occupied if anything below is); a pruned leaf
        coarser than ``d`` answers for itself.

    Returns
    -------
    p : ndarray of shape (n_points,)
        Occupancy probability of the node holding each point, or NaN.

    Raises
    ------
    TypeError
        If `points` does not hold numbers or `depth` is not an int.
    ValueError
        If `points` is not of shape (n_points, 3) or holds NaN or inf, or
        `depth` lies outside [0, 16].

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> m.occupancy([[0.45, 0.05, 0.05]]).round(2).tolist()      # a free leaf
    [0.4]
    >>> m.occupancy([[0.45, 0.05, 0.05]], depth=13).round(2).tolist()  # its 0.8 m node
    [0.7]
    """
    return self._depth_query(points, depth, 0)


def log_odds(self, points: ArrayLike, *, depth: int = 0) -> NDArray[np.float64]:
    """Log-odds of occupancy at each point, NaN where the map knows nothing.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Query points, in metres. Points outside the key range are unknown.
    depth : int, default=0
        Tree depth of the answering node, as for :meth:`occupancy`.

    Returns
    -------
    l : ndarray of shape (n_points,)
        The node's stored log-odds (float32 values), or NaN.

    Raises
    ------
    TypeError, ValueError
        As :meth:`occupancy`.
    """
    return self._depth_query(points, depth, 1)


@fill_doc()
def is_occupied(self, points: ArrayLike, *, return_unknown: bool = False,
                depth: int = 0):
    """Whether each point lies in an occupied cell.

    A cell is occupied when its probability is at least
    ``occupancy_threshold``. Unknown cells are reported as not occupied;
    ask for `return_unknown` to tell them apart from free ones.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
    return_unknown : bool, default=False
        Also return the mask of points in unknown cells.
    depth : int, default=0
        Tree depth of the answering node, as for :meth:`occupancy`: an
        inner node is occupied when one of its children is.

    {occupied_returns}

    Raises
    ------
    TypeError, ValueError
        As :meth:`occupancy`, and TypeError if `return_unknown` is not a
        bool.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
    >>> occ, unk = m.is_occupied([[1.0, 0, 0], [0.5, 0, 0], [9, 9, 9]], return_unknown=True)
    >>> occ.tolist(), unk.tolist()
    ([True, False, False], [False, False, True])
    """
    return_unknown = check_bool(return_unknown, "return_unknown")
    state = self._depth_query(points, depth, 2)
    occupied = state == 1
    return (occupied, state < 0) if return_unknown else occupied


def _depth_query(self, points: ArrayLike, depth: int, what: int):
    """The core's query `what` (see ``_query_depth``) at a checked depth."""
    d = self._check_depth(depth)
    pts = self._as_float32_points(points, "points")
    return self._query(pts, what) if d == TREE_DEPTH else self._query_depth(pts, what, d)


def cast_rays(
    self,
    origins: ArrayLike,
    directions: ArrayLike,
    *,
    max_range: float | ArrayLike | None = None,
    ignore_unknown: bool = False,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Cast rays through the map and return where they stop (liboctomap's ``castRay``).

    A ray stops at the first occupied cell (a hit), at an unknown cell unless
    `ignore_unknown`, or after `max_range` metres.

    Parameters
    ----------
    origins : array-like of shape (n_rays, 3) or (3,)
        Ray origins; a single origin is shared by all rays.
    directions : array-like of shape (n_rays, 3)
        Ray directions; need not be unit length, must not be zero.
    max_range : float or array-like of shape (n_rays,), default=None
        Longest distance to travel. None: no limit (with `ignore_unknown`,
        rays then stop once they leave the map's bounding box).
    ignore_unknown : bool, default=False
        Treat unknown cells as free instead of stopping there.

    Returns
    -------
    ends : ndarray of shape (n_rays, 3)
        Center of the cell where each ray stopped.
    hits : ndarray of bool, shape (n_rays,)
        True where the ray stopped at an occupied cell.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[1.02, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> ends, hits = m.cast_rays([0.05, 0.05, 0.05], [[1.0, 0, 0]])
    >>> hits.tolist(), ends.round(2).tolist()
    ([True], [[1.05, 0.05, 0.05]])
    """
    dirs = as_float32_directions(directions)
    n = len(dirs)
    ignore_unknown = check_bool(ignore_unknown, "ignore_unknown")
    org_arr = as_numeric(origins, "origins")
    if org_arr.ndim == 1:
        orgs = np.repeat(self._as_float32_origin(org_arr, "origins")[None], n, axis=0)
    else:
        orgs = self._as_float32_points(org_arr, "origins")
        if len(orgs) != n:
            raise ValueError(f"origins must have shape (3,) or ({n}, 3) to match "
                             f"directions, got {orgs.shape}")
    ok = self._in_range(orgs)
    if not ok.all():
        self._raise_out_of_range("origins", ok, "")
    if max_range is None:
        ranges = np.full(n, -1.0)
        if ignore_unknown:
            ranges = self._distance_past_bounds(orgs)
    elif isinstance(max_range, (numbers.Real, np.floating, np.integer)):
        ranges = np.full(n, check_real(max_range, "max_range", low=0.0))
    else:
        try:
            ranges = np.asarray(max_range)
        except ValueError:  # ragged
            ranges = np.array(None)
        if ranges.dtype.kind not in "iuf" or ranges.ndim == 0:
            raise TypeError(f"max_range must be a real number or an array of them, "
                            f"got {type(max_range).__name__} of dtype {ranges.dtype}")
        if ranges.shape != (n,):
            raise ValueError(f"max_range must be a scalar or of shape ({n},), "
                             f"got {ranges.shape}")
        ranges = ranges.astype(np.float64)
        if not (np.isfinite(ranges) & (ranges > 0)).all():
            raise ValueError("max_range must be positive and finite")
    # no ray travels farther than the key range's diagonal (castRay stops there)
    ranges = np.minimum(ranges, 2 * np.sqrt(3) * (self.key_range[1] - self.key_range[0]))
    return self._cast_rays(orgs, dirs, bool(ignore_unknown), np.ascontiguousarray(ranges))


def _distance_past_bounds(self, origins: np.ndarray) -> np.ndarray:
    """Per origin, a range past which no known cell lies (for unlimited casts)."""
    lo, hi = self.bounds
    if not np.isfinite(lo).all():
        return np.full(len(origins), self.resolution)
    corners = np.array(np.meshgrid(*zip(lo, hi), indexing="ij")).reshape(3, -1).T
    far = np.linalg.norm(origins[:, None, :] - corners[None], axis=2).max(axis=1)
    return far + 2 * self.resolution


def leaves(self, *, occupied_only: bool = False, bbox: ArrayLike | None = None,
           max_depth: int = 0) -> Leaves:
    """Return every leaf of the tree as arrays (liboctomap's ``begin_leafs``).

    The leaves come in liboctomap's iterator order (depth first, children
    in liboctomap's child order).

    Parameters
    ----------
    occupied_only : bool, default=False
        Keep only the occupied leaves.
    bbox : array-like of shape (2, 3), default=None
        ``[min_corner, max_corner]``: keep only the leaves overlapping this
        axis-aligned box (``begin_leafs_bbx``). A box larger than the key
        range means all of it.
    max_depth : int, default=0
        Deepest level listed, in [0, 16]; 0 means 16 (the leaves
        themselves). As ``begin_leafs(max_depth)``: inner nodes at
        `max_depth` are listed as leaves, with their own size and value
        (the largest log-odds below them), and `occupied_only` tests
        that value.

    Returns
    -------
    leaves : Leaves
        Named tuple ``(centers, sizes, log_odds)``.

    Raises
    ------
    TypeError
        If `occupied_only` is not a bool, `max_depth` not an int, or `bbox`
        does not hold numbers.
    ValueError
        If `max_depth` lies outside [0, 16], or `bbox` is not of shape
        (2, 3), holds NaN or has min > max on an axis.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> centers, sizes, log_odds = m.leaves(occupied_only=True)
    >>> centers.round(2).tolist(), sizes.round(2).tolist()
    ([[0.55, 0.05, 0.05]], [0.1])
    >>> leaves = m.leaves(max_depth=13)     # one 0.8 m cube holds the scan's cells
    >>> leaves.sizes.round(2).tolist(), leaves.log_odds.round(3).tolist()
    ([0.8], [0.847])
    """
    occupied_only = check_bool(occupied_only, "occupied_only")
    depth = self._check_depth(max_depth, "max_depth")
    if depth < TREE_DEPTH:
        key_box = None if bbox is None else self._leaves_key_box(bbox)
        centers, sizes, _, values, _ = self._nodes(depth, True, occupied_only, key_box)
        return Leaves(centers, sizes, values)
    if bbox is not None:
        box = as_numeric(bbox, "bbox")
        if box.shape != (2, 3):
            raise ValueError(f"bbox must have shape (2, 3) (min and max corner), "
                             f"got {box.shape}")
        box = np.ascontiguousarray(box, dtype=np.float64)
        if np.isnan(box).any() or (box[0] > box[1]).any():
            raise ValueError(f"bbox must have min <= max on every axis, got {box.tolist()}")
        box = np.clip(box, *(np.array(self.key_range) * [1, 1 - 1e-12]))
        return Leaves(*self._leaves(occupied_only, box))
    return Leaves(*self._leaves(occupied_only))


def nodes(self, *, max_depth: int = 0, bbox: ArrayLike | None = None) -> "Nodes":
    """Return every node of the tree, inner nodes included (liboctomap's ``begin_tree``).

    The nodes come in the order of liboctomap's tree iterator: depth first,
    each node before its children, children in liboctomap's child order
    (``x`` in bit 0, ``y`` in bit 1, ``z`` in bit 2 of the child index).
    The root (depth 0, center at the origin, edge ``resolution * 2**16``)
    comes first when the map is not empty. An inner node's log-odds is the
    largest of its children's (liboctomap's ``updateInnerOccupancy``,
    which occgp keeps current after every update and deletion).

    Parameters
    ----------
    max_depth : int, default=0
        Deepest level listed, in [0, 16]; 0 means 16 (every node). Nodes
        at `max_depth` are listed as leaves (``is_leaf`` True) and their
        children are not listed, as ``begin_tree(max_depth)`` does.
    bbox : array-like of shape (2, 3), default=None
        ``[min_corner, max_corner]``: list only the nodes whose cube
        overlaps this box (and so, with each node, its ancestors). A box
        larger than the key range means all of it.

    Returns
    -------
    nodes : Nodes
        Named tuple ``(centers, sizes, depths, log_odds, is_leaf)``.

    Raises
    ------
    TypeError
        If `max_depth` is not an int or `bbox` does not hold numbers.
    ValueError
        If `max_depth` lies outside [0, 16], or `bbox` is not of shape
        (2, 3), holds NaN or has min > max on an axis.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[0.15, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> nodes = m.nodes()
    >>> len(nodes.depths), int(nodes.depths[0]), int(nodes.is_leaf.sum())   # root first
    (18, 0, 2)
    """
    depth = self._check_depth(max_depth, "max_depth")
    key_box = None if bbox is None else self._leaves_key_box(bbox)
    return Nodes(*self._nodes(depth, False, False, key_box))


def is_at_threshold(self, points: ArrayLike, *, depth: int = 0) -> NDArray[np.bool_]:
    """Whether each point's cell is at a clamping bound (liboctomap's ``isNodeAtThreshold``).

    True where the stored log-odds is at or beyond ``logit(clamping_max)``
    or ``logit(clamping_min)`` (as float32, liboctomap's comparison): such
    a cell does not change under further updates in the same direction.
    Unknown cells (and points outside the key range) give False.

    Parameters
    ----------
    points : array-like of shape (n_points, 3)
        Query points, in metres.
    depth : int, default=0
        Answer for the node at this depth, as :meth:`log_odds` does.

    Returns
    -------
    at_threshold : ndarray of bool, shape (n_points,)

    Raises
    ------
    TypeError, ValueError
        As :meth:`log_odds`.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05])
    >>> pts = [[0.55, 0.05, 0.05], [5.0, 5.0, 5.0]]
    >>> m.is_at_threshold(pts).tolist(), m.to_max_likelihood().is_at_threshold(pts).tolist()
    ([False, False], [True, False])
    """
    depth = self._check_depth(depth)
    return self._query_depth(self._as_float32_points(points, "points"), 3, depth) == 1


@renamed_keywords(centres="centers")
def ray_intersections(
    self,
    origins: ArrayLike,
    directions: ArrayLike,
    centers: ArrayLike,
    *,
    delta: float = 0.0,
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Where each ray enters a cell (liboctomap's ``getRayIntersection``).

    For row ``i``, the line through ``origins[i]`` along ``directions[i]``
    is intersected with the six faces of the cube of edge ``resolution``
    centered at ``centers[i]`` (liboctomap's computation, in its mixed
    single and double precision, faces widened by 1e-6); of the faces it
    meets, the one nearest along the direction is kept (the smallest
    signed distance: behind the origin when the origin lies inside the
    cube), and the point ``origin + unit_direction * (distance + delta)``
    is returned. Typical use: the `ends` of :meth:`cast_rays` as
    `centers`, to get the surface point where each ray hit.

    Parameters
    ----------
    origins : array-like of shape (n_rays, 3) or (3,)
        Ray origins (one shared origin, or one per ray), in the key range.
    directions : array-like of shape (n_rays, 3)
        Ray directions; normalised (in single precision, as ``castRay``
        normalises them), must not be zero.
    centers : array-like of shape (n_rays, 3) or (3,)
        Centers of the cells, in the key range (used as given, not snapped
        to the cell grid).
    delta : float, default=0.0
        Metres to move the point along the ray (liboctomap's ``delta``):
        a small positive value puts it inside the cell; ``|delta|`` at
        most the key range's diagonal.

    Returns
    -------
    points : ndarray of shape (n_rays, 3)
        The entry points; NaN where the line misses the cube.
    found : ndarray of bool, shape (n_rays,)
        Whether the line meets the cube.

    Raises
    ------
    TypeError
        If an array does not hold real numbers or `delta` is not a real number.
    ValueError
        If a shape is wrong (or the rows of `origins` or `centers` do not
        match `directions`), an array holds NaN or inf, `origins` or
        `centers` lie outside the key range, a direction is zero, or
        `delta` is out of range.

    Examples
    --------
    >>> from occgp import OccupancyOctree
    >>> m = OccupancyOctree(0.1)
    >>> pts, found = m.ray_intersections([0.05, 0.05, 0.05], [[1.0, 0, 0]],
    ...                                  [[1.05, 0.05, 0.05]])
    >>> found.tolist(), pts.round(3).tolist()
    ([True], [[1.0, 0.05, 0.05]])
    """
    dirs = as_float32_directions(directions)
    n = len(dirs)
    orgs = self._rows_in_range(origins, "origins", n)
    cens = self._rows_in_range(centers, "centers", n)
    reach = 2 * np.sqrt(3) * (self.key_range[1] - self.key_range[0])
    delta = check_real(delta, "delta", low=-reach, high=reach, low_open=False,
                       high_open=False)
    return self._ray_intersections(orgs, dirs, cens, delta)


def _rows_in_range(self, x: ArrayLike, name: str, n: int) -> np.ndarray:
    """`x` as float32 rows, one per ray ((3,) is shared), all in the key range."""
    arr = as_numeric(x, name)
    if arr.ndim == 1:
        rows = np.repeat(self._as_float32_origin(arr, name)[None], n, axis=0)
    else:
        rows = self._as_float32_points(arr, name)
        if len(rows) != n:
            raise ValueError(f"{name} must have shape (3,) or ({n}, 3) to match "
                             f"directions, got {rows.shape}")
        ok = self._in_range(rows)
        if not ok.all():
            self._raise_out_of_range(name, ok, "")
    return np.ascontiguousarray(rows)


def _check_depth(self, depth: int, name: str = "depth") -> int:
    """A node depth in [0, 16] as liboctomap's search takes it: 0 becomes 16."""
    d = check_int(depth, name, low=0, high=TREE_DEPTH)
    return d if d else TREE_DEPTH


def _leaves_key_box(self, bbox: ArrayLike) -> np.ndarray:
    """The lowest and highest key of `bbox` (rows), clipped to the key range."""
    box = as_numeric(bbox, "bbox")
    if box.shape != (2, 3):
        raise ValueError(f"bbox must have shape (2, 3) (min and max corner), "
                         f"got {box.shape}")
    box = np.ascontiguousarray(box, dtype=np.float64)
    if np.isnan(box).any() or (box[0] > box[1]).any():
        raise ValueError(f"bbox must have min <= max on every axis, got {box.tolist()}")
    box = np.clip(box, *(np.array(self.key_range) * [1, 1 - 1e-12]))
    # as the compiled _leaves computes them
    keys = np.floor((1.0 / self.resolution) * box) + TREE_MAX_VAL
    return np.ascontiguousarray(np.clip(keys, 0, 2 * TREE_MAX_VAL - 1), dtype=np.uint16)


def as_float32_directions(directions: ArrayLike) -> np.ndarray:
    """Ray directions for liboctomap's ``castRay``, which normalises them in single
    precision: rows whose float squared length would overflow or underflow (e.g. 1e39,
    or 1e-30) are normalised in double precision first; the others are passed as given."""
    d64 = as_points(directions, "directions")
    zero = ~(d64 != 0).any(axis=1)
    if zero.any():
        raise ValueError(f"directions must be non-zero, got {int(zero.sum())} zero vectors "
                         f"(first: row {int(np.flatnonzero(zero)[0])})")
    with np.errstate(over="ignore", under="ignore"):
        d = d64.astype(np.float32)
        nsq = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    bad = ~((nsq >= np.finfo(np.float32).tiny) & np.isfinite(nsq))
    if bad.any():
        u = d64[bad] / np.abs(d64[bad]).max(axis=1, keepdims=True)
        d[bad] = u / np.linalg.norm(u, axis=1, keepdims=True)
    return np.ascontiguousarray(d)


def pack_keys(keys: np.ndarray) -> np.ndarray:
    """Packed keys (x in the low 16 bits), as the compiled core hashes them."""
    k = keys.astype(np.uint64)
    return k[:, 0] | (k[:, 1] << np.uint64(16)) | (k[:, 2] << np.uint64(32))


def unpack_keys(packed: np.ndarray) -> NDArray[np.uint16]:
    """The (n, 3) uint16 keys of packed keys (the inverse of :func:`pack_keys`)."""
    return np.column_stack([(packed >> np.uint64(16 * a)) & np.uint64(0xFFFF)
                            for a in range(3)]).astype(np.uint16).reshape(-1, 3)
