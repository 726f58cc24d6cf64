"""The colour occupancy octree: liboctomap's ``ColorOcTree`` under a numpy API.

:class:`ColorOctree` is :class:`~occgp.octree.LogOddsMap` in front of the compiled
``ColorOcTree`` (``occgp._color._ColorOcTree``); the parts it shares with
:class:`occgp.OccupancyOctree` (leaf and node counts, its repr) are functions of
``_queries.py`` bound in its class body.
"""

from __future__ import annotations

import os
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._atomic import write_bytes
from .._docfill import fill_doc
from ..io import _octomap_format as fmt
from .._color import FUSE_AVERAGE, FUSE_MEAN, _ColorOcTree
from . import _queries
from ._logodds import OCTREE_ATTRIBUTES, SENSOR_MODEL, LogOddsMap
from ._options import InsertOptions, resolve_options
from ..maps import register
from .._octree import KEYRAY_CELLS, _check_full_data
from .._reading import read_regular
from .._scan_input import prefilter
from .._validation import as_path, check_bool, check_choice, check_resolution

__all__ = ["ColorOctree", "ColorLeaves", "FUSIONS"]

#: The colour fusion rules of :meth:`ColorOctree.insert_scan`.
if TYPE_CHECKING:
    from ._tree import OccupancyOctree

FUSIONS = ("average", "mean")
#: The tree type a ColorOcTree file names in its header (liboctomap's getTreeType()).
TREE_TYPE = "ColorOcTree"
#: liboctomap's "no colour": a node's colour is unset while it is pure white.
UNSET = (255, 255, 255)


class ColorLeaves(NamedTuple):
    """The leaves (cells) of a :class:`ColorOctree`, as arrays (one row per leaf)."""

    #: Cell centers, shape (n_leaves, 3), in metres.
    centers: NDArray[np.float64]
    #: Cell edge lengths, shape (n_leaves,): the resolution times a power of two.
    sizes: NDArray[np.float64]
    #: Log-odds of occupancy, shape (n_leaves,), float32 as liboctomap stores them.
    log_odds: NDArray[np.float32]
    #: Colours, uint8, shape (n_leaves, 3) (red, green, blue); (255, 255, 255) where
    #: the cell has no colour (liboctomap's unset colour).
    colors: NDArray[np.uint8]


@register("color-octree", formats=(".ot",),
          description="OctoMap's octree with a colour per cell", resolution=0.1)
@fill_doc(sensor_model=SENSOR_MODEL, octree_attributes=OCTREE_ATTRIBUTES)
class ColorOctree(LogOddsMap, _ColorOcTree):
    """Probabilistic 3D occupancy map whose cells also hold a colour (OctoMap's ColorOcTree).

    Occupancy works as in :class:`occgp.OccupancyOctree` (scan mode): each
    :meth:`insert_scan` is liboctomap's ``insertPointCloud``, so the occupancy
    leaves are identical, leaf for leaf, to an :class:`~occgp.OccupancyOctree`
    fed the same scans. In addition each scan's end points carry colours,
    fused into their end cells by averaging (see `fusion` in
    :meth:`insert_scan`). The tree is liboctomap's own ``ColorOcTree``: maps
    are written as ``.ot`` files that octovis shows in colour and every
    OctoMap tool reads as a ``ColorOcTree``.

    A colour is 8 bits per channel (red, green, blue). As in liboctomap, a
    cell whose colour is pure white ``(255, 255, 255)`` counts as having no
    colour (``ColorOcTreeNode::isColorSet``): white is also the colour of
    cells nothing coloured. When eight sibling cells share their log-odds they
    are pruned into their parent whatever their colours, which then holds the
    children's average colour (liboctomap's ``ColorOcTree::pruneNode``).

    Parameters
    ----------
    resolution : float
        Edge length of the smallest cells, in metres; in ``[1e-15, 1e14]``.
    {sensor_model}

    Attributes
    ----------
    {octree_attributes}

    See Also
    --------
    occgp.OccupancyOctree : The same map without colours, and its other updates.

    Examples
    --------
    >>> from occgp.octree import ColorOctree
    >>> m = ColorOctree(0.1).insert_scan([[1.02, 0.05, 0.05]], [0.05, 0.05, 0.05],
    ...                                  colors=[[200, 40, 10]])
    >>> m = m.insert_scan([[1.02, 0.05, 0.05]], [0.05, 0.05, 0.05], colors=[[100, 0, 30]])
    >>> rgb, has_color = m.colors([[1.02, 0.05, 0.05], [0.5, 0.05, 0.05]])
    >>> rgb.tolist(), has_color.tolist()     # (200 + 100) // 2, ...; a free cell: none
    ([[150, 20, 20], [255, 255, 255]], [True, False])
    >>> m.is_occupied([[1.02, 0.05, 0.05]]).tolist()
    [True]
    """

    _kind = "octree"

    def __repr__(self) -> str:
        return _queries.tree_repr(self)

    num_leaves = _queries.num_leaves
    num_nodes = _queries.num_nodes
    _num_cells = _queries._num_leaves

    # ------------------------------------------------------------------ updates
    def insert_scan(
        self,
        points: ArrayLike,
        origin: ArrayLike,
        colors: ArrayLike | None = None,
        *,
        max_range: float | None = None,
        fusion: str = "average",
        free_points: ArrayLike | None = None,
        options: InsertOptions | None = None,
        **kwargs: Any,
    ) -> "ColorOctree":
        """Integrate one coloured range scan into the map.

        The occupancy update is liboctomap's ``insertPointCloud`` (as
        :meth:`occgp.OccupancyOctree.insert_scan` with ``mode="scan"``): the
        cells the rays cross are marked free, the cells they end in occupied,
        each cell updated once. Then the colour of every point whose ray is not
        truncated at `max_range` is fused into its end cell.

        Without `colors` (a plain scan, as every map of :mod:`occgp.maps`
        takes) only the occupancy is updated and no colour is fused: coloured
        cells keep their colour (unless eight siblings are pruned into their
        parent, which then takes their average, see the class notes) and
        cells without one stay unset (:meth:`colors` reports them white and
        not set).

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Ray end points in the world frame, in metres. Must be finite and in
            the key range (after truncation at `max_range`). An empty scan
            changes nothing.
        origin : array-like of shape (3,)
            Sensor position in the world frame, in metres.
        colors : array-like of shape (n_points, 3), default=None
            The points' colours (red, green, blue): integers in [0, 255] (any
            integer dtype, e.g. uint8), or floats in [0, 1] (as Open3D holds
            them; scaled by 255 and rounded to the nearest integer). Pure white
            is liboctomap's "no colour" (see the class notes). None: occupancy
            only, the cells' colours are left as they are (`fusion` then has
            no effect).
        max_range : float, default=None
            Rays longer than this are truncated: the cells up to `max_range`
            are marked free, the end cell is neither marked occupied nor
            coloured. None means no limit.
        fusion : {"average", "mean"}, default="average"
            How colours are fused. ``"average"`` is liboctomap's
            ``averageNodeColor`` applied point by point, in the order of
            `points`: a cell without colour takes the point's colour, a
            coloured cell becomes ``(previous + colour) // 2`` per channel (a
            running pairwise average that weighs the latest points most; the
            map is the one liboctomap's ``insertPointCloud`` followed by
            ``averageNodeColor`` per point gives). ``"mean"`` first takes, per
            end cell, the mean of the colours of this scan's points ending in
            it (rounded half up), then fuses it into the cell with one
            ``averageNodeColor`` (cells in key order): within a scan every
            point weighs the same; across scans, each scan's mean is averaged
            pairwise with the cell's colour (a file stores no point counts).
        free_points : array-like of shape (n_free, 3), default=None
            End points of rays that only clear (octomap_server's ground
            points): their cells join the scan's free set, their end cells get
            nothing and no colour. The update is then liboctomap's
            ``insertPointCloud`` key sets built by occgp (liboctomap's
            ``computeRayKeys``, one ``updateNode`` per cell, occupied over
            free), the map :meth:`occgp.OccupancyOctree.insert_scan` gives with
            the same `free_points`.
        options : InsertOptions, default=None
            Of :class:`~occgp.octree.InsertOptions`, the colour tree takes
            `min_range`: points (with their colours) and free points nearer to
            `origin` than this are dropped first, as for
            :meth:`occgp.OccupancyOctree.insert_scan` (double-precision
            distances; None: no filter); finite, >= 0 and less than
            `max_range`. The other fields must keep their defaults (the
            occupancy update is always liboctomap's ``insertPointCloud``).
        **kwargs
            `min_range` by name, as in earlier releases.

        Returns
        -------
        self : ColorOctree
            The updated map, to allow chaining.

        Raises
        ------
        TypeError
            If `points`, `origin` or `colors` does not hold real numbers
            (booleans are refused for `colors`).
        ValueError
            If `points` is not of shape (n_points, 3), `origin` not of shape
            (3,), either holds NaN or inf or lies outside the key range (after
            truncation at `max_range`); a ray is too short for the
            single-precision traversal, crosses more than 99,990 cells
            (liboctomap's ray buffer) or the scan reaches more than
            :attr:`MAX_SCAN_CELLS` cells; `colors` is not of shape
            (n_points, 3), holds integers outside [0, 255] or floats outside
            [0, 1] (or NaN); `max_range` or `fusion` is invalid; `min_range`
            is negative, not finite or not less than `max_range`;
            `free_points` is not of shape (n_free, 3), holds NaN or inf, or
            has a ray as bad as the points' above. The map is then unchanged.

        Examples
        --------
        >>> m = ColorOctree(0.1)
        >>> pts = [[1.01, 0.05, 0.05], [1.02, 0.05, 0.05], [1.03, 0.05, 0.05]]
        >>> rgb = [[0, 0, 0], [90, 90, 90], [30, 30, 30]]
        >>> m.insert_scan(pts, [0.05, 0.05, 0.05], rgb).colors(pts[:1])[0].tolist()
        [[37, 37, 37]]
        >>> m2 = ColorOctree(0.1).insert_scan(pts, [0.05, 0.05, 0.05], rgb, fusion="mean")
        >>> m2.colors(pts[:1])[0].tolist()
        [[40, 40, 40]]
        >>> m2.insert_scan(pts, [0.05, 0.05, 0.05]).colors(pts[:1])[0].tolist()  # no colours
        [[40, 40, 40]]
        """
        opts, _ = resolve_options(options, kwargs, f"{type(self).__name__}.insert_scan",
                                  ("min_range",), threaded=False)
        fusion = check_choice(fusion, "fusion", FUSIONS)
        points, free64, keep = prefilter(points, origin, opts.min_range, max_range, free_points)
        scan = self._validated_scan(points, origin, max_range, "scan")
        free = None if free64 is None else self._validated_scan(
            free64, origin, max_range, "scan", name="free_points")
        n_given = len(keep) if keep is not None else (0 if scan is None else len(scan[0]))
        rgb = None if colors is None else _as_colors(colors, n_given)
        if keep is not None and rgb is not None:
            rgb = np.ascontiguousarray(rgb[keep])
        if scan is None:
            if free is None:
                return self
            scan = (np.empty((0, 3), np.float32), free[1], free[2], np.zeros(0, np.int64))
        pts, org, rng, cells = scan
        rays = [(cells, "points")] + ([] if free is None else [(free[3], "free_points")])
        self._check_ray_cells(rays, len(pts) + (0 if free is None else len(free[0])))
        self._insert_colored(pts, org, rng, rgb,
                             FUSE_AVERAGE if fusion == "average" else FUSE_MEAN,
                             None if free is None else free[0])
        return self

    def _check_ray_cells(self, rays: list, n_rays: int) -> None:
        """Raise ValueError when a ray crosses more cells than liboctomap's ray buffer
        holds, or the scan's rays may reach more than MAX_SCAN_CELLS; `rays`: (cells,
        name) of each set of rays (see ``_raise_bad_ends``)."""
        for cells, name in rays:
            if len(cells) and cells.max() > KEYRAY_CELLS:
                bad = np.flatnonzero(cells > KEYRAY_CELLS)
                to = "" if name == "points" else f" to {name}"
                raise ValueError(
                    f"{len(bad)} of {len(cells)} rays{to} cross more than {KEYRAY_CELLS} "
                    f"cells (first: row {int(bad[0])}), more than liboctomap's ray buffer "
                    "holds; use a coarser resolution or max_range; the map is unchanged")
        if sum(int(c.sum()) + len(c) for c, _ in rays) > self._max_scan_cells():
            raise ValueError(
                f"the scan's {n_rays} rays may reach more than MAX_SCAN_CELLS="
                f"{self.MAX_SCAN_CELLS} cells at resolution {self.resolution:g} m; use a "
                "coarser resolution, max_range or fewer points, or raise MAX_SCAN_CELLS; "
                "the map is unchanged")

    def update_colors(self, points: ArrayLike, colors: ArrayLike) -> "ColorOctree":
        """Fuse colours into the cells holding `points` (liboctomap's ``averageNodeColor``).

        Point by point, in order: a cell without colour takes the colour, a
        coloured one becomes ``(previous + colour) // 2`` per channel.
        Occupancy is unchanged. Points in cells the map does not know are
        skipped (liboctomap finds no node there); a point in a pruned leaf
        colours the whole leaf.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Finite, in the key range.
        colors : array-like of shape (n_points, 3)
            Integers in [0, 255] or floats in [0, 1], as for :meth:`insert_scan`.

        Returns
        -------
        self : ColorOctree

        Raises
        ------
        TypeError
            If `points` or `colors` does not hold real numbers.
        ValueError
            If `points` is not of shape (n_points, 3), holds NaN or inf or
            lies outside the key range, or `colors` is invalid (see
            :meth:`insert_scan`). The map is then unchanged.
        """
        pts, rgb = self._checked_cells(points, colors)
        self._fuse_colors(pts, rgb, False)
        return self

    def set_colors(self, points: ArrayLike, colors: ArrayLike) -> "ColorOctree":
        """Set the colour of the cells holding `points` (liboctomap's ``setNodeColor``).

        As :meth:`update_colors`, but each colour replaces the cell's (the last
        point in a cell wins). Setting ``(255, 255, 255)`` removes a cell's
        colour.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Finite, in the key range.
        colors : array-like of shape (n_points, 3)
            Integers in [0, 255] or floats in [0, 1], as for :meth:`insert_scan`.

        Returns
        -------
        self : ColorOctree

        Raises
        ------
        TypeError, ValueError
            As :meth:`update_colors`; the map is then unchanged.
        """
        pts, rgb = self._checked_cells(points, colors)
        self._fuse_colors(pts, rgb, True)
        return self

    def _checked_cells(self, points: ArrayLike,
                       colors: ArrayLike) -> tuple[NDArray[np.float32], NDArray[np.uint8]]:
        pts = self._as_float32_points(points, "points")
        ok = self._in_range(pts)
        if not ok.all():
            self._raise_out_of_range("points", ok, "")
        return pts, _as_colors(colors, len(pts))

    # ------------------------------------------------------------------ queries
    def colors(self, points: ArrayLike) -> tuple[NDArray[np.uint8], NDArray[np.bool_]]:
        """Colour of the cell holding each point.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres. Points outside the key range are unknown.

        Returns
        -------
        colors : ndarray of uint8, shape (n_points, 3)
            Red, green, blue; ``(255, 255, 255)`` where `has_color` is False.
        has_color : ndarray of bool, shape (n_points,)
            False where the cell is unknown or holds no colour (liboctomap's
            unset white).

        Raises
        ------
        TypeError, ValueError
            If `points` is not a finite real array of shape (n_points, 3).
        """
        return self._colors(self._as_float32_points(points, "points"))

    def leaves(self, *, occupied_only: bool = False) -> ColorLeaves:
        """Return every leaf of the tree as arrays.

        Parameters
        ----------
        occupied_only : bool, default=False
            Keep only the occupied leaves.

        Returns
        -------
        leaves : ColorLeaves
            Named tuple ``(centers, sizes, log_odds, colors)``, in liboctomap's
            leaf order (that of :meth:`occgp.OccupancyOctree.leaves`).

        Examples
        --------
        >>> m = ColorOctree(0.1).insert_scan([[0.55, 0.05, 0.05]], [0.05, 0.05, 0.05],
        ...                                  colors=[[1.0, 0.5, 0.0]])
        >>> leaves = m.leaves(occupied_only=True)
        >>> leaves.centers.round(2).tolist(), leaves.colors.tolist()
        ([[0.55, 0.05, 0.05]], [[255, 128, 0]])
        """
        occupied_only = check_bool(occupied_only, "occupied_only")
        return ColorLeaves(*self._leaves(occupied_only))

    def extract_points(self, occupied: bool = True):
        """Centers, edges and colours of the occupied (or the free) leaves.

        Parameters
        ----------
        occupied : bool, default=True
            True: the leaves at or above the occupancy threshold; False: the
            known leaves below it.

        Returns
        -------
        centers : ndarray of shape (n, 3)
        sizes : ndarray of shape (n,)
        colors : ndarray of uint8, shape (n, 3)
            ``(255, 255, 255)`` for leaves without colour.
        """
        occupied = check_bool(occupied, "occupied")
        centers, sizes, values, rgb = self._leaves(False)
        keep = (values >= np.float32(self._log_odds_thresholds()[2])) == occupied
        return centers[keep], sizes[keep], rgb[keep]

    # ------------------------------------------------------------------ structure
    # ------------------------------------------------------------------ I/O
    def to_bytes(self) -> bytes:
        """Serialise the map as a ColorOcTree ``.ot`` file (every log-odds and colour).

        Returns
        -------
        data : bytes
            The contents of a file with ``id ColorOcTree``, which liboctomap's
            ``AbstractOcTree::read`` and octovis read as a ColorOcTree.
            Inner nodes hold their children's average colour (liboctomap's
            ``ColorOcTree::updateInnerOccupancy``, run first when the map
            changed since).
        """
        body = self._write_data()
        header = (f"{fmt.FULL_HEADER}\n# (feel free to add / change comments, but leave the "
                  f"first line as it is!)\n#\nid {TREE_TYPE}\nsize {self.num_nodes}\n"
                  f"res {self.resolution!r}\ndata\n").encode("ascii")
        return header + body

    @classmethod
    def from_bytes(cls, data: bytes, **params) -> "ColorOctree":
        """Build a map from the contents of a ColorOcTree ``.ot`` file.

        Parameters
        ----------
        data : bytes
            File contents.
        **params
            Sensor-model parameters (``prob_hit``, ``clamping_min``, ...); the
            file stores only the resolution.

        Returns
        -------
        tree : ColorOctree

        Raises
        ------
        TypeError
            If `data` is not bytes.
        ValueError
            If the data is not an OctoMap file, is a ``.bt`` file (which holds
            no colours), holds another tree type than ``ColorOcTree`` (e.g. an
            ``OcTree``: read it with :meth:`occgp.OccupancyOctree.from_bytes`),
            or is truncated or corrupt.
        """
        if not isinstance(data, (bytes, bytearray, memoryview)):
            raise TypeError(f"data must be bytes, got {type(data).__name__}")
        return cls._from_data(bytes(data), "data", params)

    def save(self, path: str | os.PathLike) -> "ColorOctree":
        """Write the map to a ColorOcTree ``.ot`` file (see :meth:`to_bytes`).

        The file is written atomically: a temporary file beside `path` replaces
        it once complete, so the previous file stays intact if the write fails.

        Parameters
        ----------
        path : str or path-like
            Destination, ending in ``.ot`` (a ``.bt`` file cannot hold colours).

        Returns
        -------
        self : ColorOctree

        Raises
        ------
        TypeError
            If `path` is not a str or os.PathLike.
        ValueError
            If `path` does not end in ``.ot``.
        OSError
            If the file cannot be written.
        """
        path = os.fspath(as_path(path))
        if os.path.splitext(path)[1].lower() != ".ot":
            raise ValueError(f"path must end in .ot (a ColorOcTree file; .bt files hold no "
                             f"colours), got {path!r}")
        write_bytes(path, self.to_bytes())
        return self

    @classmethod
    def load(cls, path: str | os.PathLike, **params) -> "ColorOctree":
        """Read a map from a ColorOcTree ``.ot`` file.

        Parameters
        ----------
        path : str or path-like
        **params
            Sensor-model parameters, as for :meth:`from_bytes`.

        Returns
        -------
        tree : ColorOctree

        Raises
        ------
        OSError
            If the file cannot be read, or is not a regular file (a named pipe,
            a device such as ``/dev/zero``: refused before it is opened).
        ValueError
            As :meth:`from_bytes`, naming the file.
        """
        path = os.fspath(as_path(path))
        data = read_regular(path, what="an OctoMap file")
        return cls._from_data(data, path, params)

    @classmethod
    def _from_data(cls, data: bytes, source: str, params: dict) -> "ColorOctree":
        header = fmt.parse_header(data, source)
        if header.binary:
            raise ValueError(f"{source} is a binary (.bt) OctoMap file, which holds no "
                             f"colours; ColorOctree reads {TREE_TYPE!r} .ot files")
        if header.tree_type != TREE_TYPE:
            raise ValueError(f"{source} holds a {header.tree_type!r} tree; ColorOctree reads "
                             f"only {TREE_TYPE!r} files (OccupancyOctree.load reads 'OcTree' "
                             "files)")
        try:
            check_resolution(header.resolution)
        except ValueError as exc:
            raise ValueError(f"{source}: the header's {exc}") from None
        tree = cls(header.resolution, **params)
        if header.size == 0:
            return tree
        buf = np.frombuffer(data, dtype=np.uint8)
        try:
            nodes, end = _check_full_data(buf, header.data_offset, 8)  # + r, g, b
        except ValueError as exc:
            raise ValueError(f"{source}: {exc}") from None
        if nodes != header.size:
            raise ValueError(f"{source}: corrupt data: the header announces {header.size} "
                             f"nodes, the data holds {nodes}")
        tree._read_data(data[header.data_offset:end], header.resolution)
        return tree

    def to_octree(self) -> "OccupancyOctree":
        """The map without its colours: an :class:`~occgp.OccupancyOctree` with the same
        nodes, log-odds and parameters (leaf for leaf).

        The ``.ot`` data of both trees list the nodes depth first, each as its
        float32 log-odds, the colour's three bytes (ColorOcTree only) and the
        child mask; dropping the colour bytes gives the OcTree's data.

        Returns
        -------
        tree : OccupancyOctree

        Examples
        --------
        >>> from occgp import ColorOctree
        >>> m = ColorOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0], colors=[[255, 0, 0]])
        >>> t = m.to_octree()
        >>> type(t).__name__, t.num_leaves == m.num_leaves
        ('OccupancyOctree', True)
        """
        from ._tree import OccupancyOctree

        tree = OccupancyOctree(**self.get_params())
        if self.num_nodes:
            body = np.frombuffer(self._write_data(), dtype=np.uint8).reshape(-1, 8)
            data = np.ascontiguousarray(body[:, [0, 1, 2, 3, 7]]).tobytes()
            tree._read_data(data, False, self.resolution)
        return tree

    def __reduce__(self):
        return (_rebuild, (type(self), self.get_params(), self.to_bytes()))

    def _sensor_params(self) -> dict:
        return {k: v for k, v in self._params.items() if k != "resolution"}


def _rebuild(cls, params: dict, data: bytes) -> ColorOctree:
    """Unpickle: the header stores the resolution with full precision (repr)."""
    return cls.from_bytes(data, **{k: v for k, v in params.items() if k != "resolution"})


def _as_colors(colors: ArrayLike, n: int, name: str = "colors") -> NDArray[np.uint8]:
    """`colors` as a C-contiguous uint8 array of shape (n, 3), or raise naming `name`.

    Integers must lie in [0, 255]; floats in [0, 1] are scaled by 255 and rounded
    to the nearest integer (halves to even).
    """
    try:
        arr = np.asarray(colors)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{name} must be a numeric array, could not convert it: {exc}") from None
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold integers in [0, 255] or floats in [0, 1], got "
                        f"dtype {arr.dtype}")
    if arr.shape != (n, 3):
        raise ValueError(f"{name} must have shape ({n}, 3) (one red, green, blue row per "
                         f"point), got {arr.shape}")
    if arr.dtype.kind == "f":
        bad = ~((arr >= 0) & (arr <= 1)).all(axis=1)   # NaN fails both
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"{name} of a float dtype must lie in [0, 1] (pass integers for 0-255 "
                f"values): {int(bad.sum())} rows lie outside or hold NaN (first: row {row}, "
                f"{arr[row].tolist()})")
        return np.ascontiguousarray(np.rint(arr.astype(np.float64) * 255.0), dtype=np.uint8)
    bad = ~((arr >= 0) & (arr <= 255)).all(axis=1)
    if bad.any():
        row = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name} of an integer dtype must lie in [0, 255]: {int(bad.sum())} "
                         f"rows lie outside (first: row {row}, {arr[row].tolist()})")
    return np.ascontiguousarray(arr, dtype=np.uint8)
