"""What occgp's log-odds maps share: parameters, scan validation and queries.

:class:`occgp.OccupancyOctree` and :class:`occgp.GridMap` put this class in
front of their compiled cores, which provide ``_setup``, ``_in_range``,
``_check_rays`` and ``_query`` with the same meaning.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..nav import _distance
from ..io import _export
from .._docfill import fill_doc
from .._octree import TREE_MAX_VAL
from ..nav._planning import PlanningMixin
from .._status import Status, check_status
from ._superray_policy import learn_superrays
from .._validation import (
    as_point, as_points, check_bool, check_choice, check_int, check_probability, check_real,
    check_resolution,
)

__all__ = ["LogOddsMap", "OctreeFace", "Leaves", "MODES", "METHODS"]

MODES = ("scan", "ray")
#: Rays between two cells whose float squared length is below FLT_MIN cannot be walked.
_SHORTEST_RAY = float(np.sqrt(np.finfo(np.float32).tiny))
#: Longest ray whose float squared length is finite.
_LONGEST_RAY = float(np.sqrt(np.finfo(np.float32).max))
METHODS = ("auto", "plain", "culling", "superray", "superray+culling")
#: The settable sensor-model parameters (:meth:`LogOddsMap.set_params`).
_SENSOR_PARAMS = ("prob_hit", "prob_miss", "clamping_min", "clamping_max",
                  "occupancy_threshold")


#: The sensor model of the log-odds maps (liboctomap's), as numpydoc parameters.
SENSOR_MODEL = """\
prob_hit : float, default=0.7
    Probability that a cell is occupied given a ray ends in it; in (0.5, 1).
prob_miss : float, default=0.4
    Probability that a cell is occupied given a ray crosses it; in (0, 0.5).
clamping_min : float, default=0.1192
    Lower clamping bound (probability); in (0, 0.5).
clamping_max : float, default=0.971
    Upper clamping bound (probability); in (0.5, 1).
occupancy_threshold : float, default=0.5
    Cells at or above this probability count as occupied; in (0, 1)."""

#: The attributes every octree shows.
OCTREE_ATTRIBUTES = """\
resolution : float
    Edge length of the smallest cells.
num_leaves : int
    Number of leaves (known cells after pruning).
num_nodes : int
    Number of nodes, inner ones included.
bounds : tuple of ndarray of shape (3,)
    Minimum and maximum corner of the known space (NaN when empty)."""


class Leaves(NamedTuple):
    """The leaves (cells) of a map, as arrays (one row per leaf)."""

    #: Cell centres, shape (n_leaves, 3), in metres.
    centers: NDArray[np.float64]
    #: Cell edge lengths, shape (n_leaves,): the resolution times a power of two.
    sizes: NDArray[np.float64]
    #: Log-odds of occupancy, shape (n_leaves,), float32 as liboctomap stores them.
    log_odds: NDArray[np.float32]


class LogOddsMap(PlanningMixin):
    """Base of the log-odds maps: see :class:`occgp.OccupancyOctree` for the parameters."""

    #: What the map is called in error messages.
    _kind = "map"
    #: After a scan where grouping its rays into super rays took longer than the
    #: traversal it saved, ``method="superray+culling"`` inserts this many scans with
    #: the culling region alone, then tries super rays again; each further such scan
    #: in a row doubles the pause, up to 8 times this.
    SUPERRAY_BACKOFF = 8
    #: The most distinct cells one scan may reach (its rays' cells and end cells): a
    #: scan past it raises ValueError and changes nothing, instead of collecting
    #: tens of gigabytes of cells (e.g. a resolution a thousand times too fine for
    #: its rays). About 48 bytes a cell while the scan is collected, plus the map's
    #: own nodes; raise it on the class or the map for larger scans.
    MAX_SCAN_CELLS = 2**27
    _superray_skip = 0
    _superray_pause = SUPERRAY_BACKOFF

    if TYPE_CHECKING:  # provided by the compiled core the subclass also derives from
        def _setup(self, resolution: float, prob_hit: float, prob_miss: float,
                   clamping_min: float, clamping_max: float,
                   occupancy_threshold: float) -> None: ...
        def _in_range(self, points: NDArray[np.float32]) -> NDArray[np.bool_]: ...
        def _check_rays(self, points: NDArray[np.float32], origin: NDArray[np.float32],
                        max_range: float) -> tuple[NDArray[np.uint8], NDArray[np.int64]]: ...
        def _query(self, points: NDArray[np.float32], what: int) -> Any: ...
        def _num_cells(self) -> int: ...
        def _bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]: ...
        def _memory_usage(self) -> int: ...
        def _clear(self) -> None: ...

    def __init__(
        self,
        resolution: float,
        *,
        prob_hit: float = 0.7,
        prob_miss: float = 0.4,
        clamping_min: float = 0.1192,
        clamping_max: float = 0.971,
        occupancy_threshold: float = 0.5,
    ) -> None:
        params = dict(
            resolution=resolution, prob_hit=prob_hit, prob_miss=prob_miss,
            clamping_min=clamping_min, clamping_max=clamping_max,
            occupancy_threshold=occupancy_threshold,
        )
        checked = check_params(params)
        self._build(checked, *(checked[k] for k in _SENSOR_PARAMS))

    def _build(self, params: dict, prob_hit: float, prob_miss: float, clamping_min: float,
               clamping_max: float, occupancy_threshold: float) -> None:
        """Build the empty map: its checked constructor `params` and the compiled core's
        sensor model. The map's cells live in the compiled core, so a log-odds map is
        built (and its parameters checked) at construction."""
        self._params = params
        self._setup(params["resolution"], prob_hit, prob_miss, clamping_min, clamping_max,
                    occupancy_threshold)
        self._superray_skip = 0
        self._superray_pause = self.SUPERRAY_BACKOFF

    # ------------------------------------------------------------------ parameters
    def get_params(self, deep: bool = True) -> dict:
        """The constructor's parameters (scikit-learn's ``get_params``).

        Parameters
        ----------
        deep : bool, default=True
            Accepted for scikit-learn's API; a map holds no nested estimators.

        Returns
        -------
        params : dict
            Parameter name to value (``type(m)(**m.get_params())`` and
            :func:`sklearn.base.clone` build an empty map with the same
            parameters).
        """
        return dict(self._params)

    @property
    def resolution(self) -> float:
        """Edge length of the smallest cells, in metres."""
        return self._params["resolution"]

    @property
    def prob_hit(self) -> float:
        return self._params["prob_hit"]

    @property
    def prob_miss(self) -> float:
        return self._params["prob_miss"]

    @property
    def clamping_min(self) -> float:
        return self._params["clamping_min"]

    @property
    def clamping_max(self) -> float:
        return self._params["clamping_max"]

    @property
    def occupancy_threshold(self) -> float:
        return self._params["occupancy_threshold"]

    @property
    def key_range(self) -> tuple[float, float]:
        """The interval ``[low, high)`` of coordinates (metres, every axis) the map can hold."""
        r = self.resolution
        return -TREE_MAX_VAL * r, TREE_MAX_VAL * r

    # ------------------------------------------------------------------ structure
    @property
    def num_cells(self) -> int:
        """Number of cells holding evidence (an octree's pruned leaf counts once)."""
        return self._num_cells()

    @property
    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min corner, max corner) of the known space, in metres; NaN when empty."""
        if self.num_cells == 0:
            return np.full(3, np.nan), np.full(3, np.nan)
        return self._bounds()

    def memory_usage(self) -> int:
        """Bytes used by the map's cells: the octree's nodes (liboctomap's
        ``memoryUsage``), the grid's hash map (an estimate of its nodes and buckets).

        Returns
        -------
        nbytes : int
        """
        return self._memory_usage()

    def clear(self):
        """Remove every cell (the parameters stay).

        Returns
        -------
        self
            The map.
        """
        self._clear()
        return self

    # ------------------------------------------------------------------ queries
    def occupancy(self, points: ArrayLike) -> NDArray[np.float64]:
        """Probability of occupancy at each point, NaN where the map knows nothing.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
            Query points, in metres. Points outside the key range are unknown.

        Returns
        -------
        p : ndarray of shape (n_points,)
            Occupancy probability of the cell holding each point, or NaN.
        """
        return self._query(self._as_float32_points(points, "points"), 0)

    def log_odds(self, points: ArrayLike) -> NDArray[np.float64]:
        """Log-odds of occupancy at each point, NaN where the map knows nothing.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)

        Returns
        -------
        l : ndarray of shape (n_points,)
            The cell's stored log-odds (float32 values), or NaN.
        """
        return self._query(self._as_float32_points(points, "points"), 1)

    @fill_doc()
    def is_occupied(self, points: ArrayLike, *, return_unknown: bool = False):
        """Whether each point lies in an occupied cell.

        A cell is occupied when its probability is at least
        ``occupancy_threshold``. Unknown cells are reported as not occupied;
        ask for `return_unknown` to tell them apart from free ones.

        Parameters
        ----------
        points : array-like of shape (n_points, 3)
        return_unknown : bool, default=False
            Also return the mask of points in unknown cells.

        {occupied_returns}

        Examples
        --------
        >>> from occgp import OccupancyOctree
        >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0, 0]], [0, 0, 0])
        >>> occ, unk = m.is_occupied([[1.0, 0, 0], [0.5, 0, 0], [9, 9, 9]], return_unknown=True)
        >>> occ.tolist(), unk.tolist()
        ([True, False, False], [False, False, True])
        """
        return_unknown = check_bool(return_unknown, "return_unknown")
        state = self._query(self._as_float32_points(points, "points"), 2)
        occupied = state == 1
        return (occupied, state < 0) if return_unknown else occupied

    def set_params(self, **params):
        """Change the sensor model (liboctomap's ``setProbHit``, ``setClampingThresMin``, ...).

        Sets any of ``prob_hit``, ``prob_miss``, ``clamping_min``,
        ``clamping_max`` and ``occupancy_threshold``, checked as the
        constructor checks them (scikit-learn's ``set_params``;
        :meth:`get_params` reads them back). As with liboctomap's setters, the
        stored log-odds do not change: the new values apply to later updates
        (and clamps) and to the queries that compare with a threshold
        (:meth:`is_occupied`, and the octree's ``is_at_threshold`` and
        ``extract_points``, ...). The resolution is fixed: ``resolution`` is accepted only with
        the map's own value (so that ``set_params(**other.get_params())``
        works between maps of one resolution). Pickles keep the new values;
        ``.bt`` / ``.ot`` files store only the resolution, so pass the values
        to :meth:`load` again.

        Parameters
        ----------
        **params
            The parameters to change, by name.

        Returns
        -------
        self
            The map.

        Raises
        ------
        TypeError
            If a value is not a real number.
        ValueError
            If a name is not a settable parameter of this map (subclasses such
            as :class:`occgp.KNNMap`, whose sensor model has other parameters,
            have none), `resolution` differs from the map's, or a value lies
            outside the constructor's range. The map is then unchanged.

        Examples
        --------
        >>> from occgp import OccupancyOctree
        >>> m = OccupancyOctree(0.1).set_params(prob_hit=0.9, clamping_max=0.99)
        >>> m.prob_hit, m.get_params()["clamping_max"]
        (0.9, 0.99)
        """
        settable = [k for k in _SENSOR_PARAMS if k in self._params]
        for name, value in params.items():
            if name == "resolution" and "resolution" in self._params:
                if value != self.resolution:
                    raise ValueError(f"resolution is fixed at construction ({self.resolution!r}), "
                                     f"got {value!r}; build a new map instead")
            elif name not in settable:
                raise ValueError(f"{name!r} is not a parameter set_params can change on "
                                 f"{type(self).__name__} (settable: "
                                 f"{', '.join(settable) or 'none'})")
        if not settable:
            return self
        new = check_params({**self._params, **{k: v for k, v in params.items()
                                               if k != "resolution"}})
        self._set_sensor_model(*(new[k] for k in _SENSOR_PARAMS))
        self._params = new
        return self

    # ------------------------------------------------------------------ maps out
    def save_ply(self, path, *, occupied: bool = True, binary: bool = True,
                 cubes: bool = False, color: bool = True):
        """Write the occupied (or the free) cells of a map to a PLY file.

        With ``cubes=False`` the file is a point cloud: one vertex per leaf, at
        its centre. With ``cubes=True`` it is a triangle mesh: each leaf is a cube
        of 8 vertices and 12 triangles (counter-clockwise seen from outside), so
        that mesh viewers (MeshLab, CloudCompare, Open3D) show the voxels. Every
        vertex carries the properties

        * ``x y z`` (float): the centre (points) or a corner (cubes), in metres;
        * ``size`` (float): the leaf's edge (pruned leaves are larger than the
          resolution);
        * ``probability`` (float): the leaf's occupancy probability;
        * ``red green blue`` (uchar, with `color`): the leaf's own colour for
          a colour map (:class:`occgp.ColorOctree`; ``255 255 255`` where a
          leaf has none), otherwise a viridis colour of the leaf's height, spread
          from the lowest to the highest cell.

        A ``comment`` line records the map's resolution. Faces are
        ``property list uchar int vertex_indices``.

        The file is written atomically: a temporary file beside `path` replaces
        it once complete, so the previous file stays intact if the write fails.

        Parameters
        ----------
        path : str or os.PathLike
            Destination (overwritten).
        occupied : bool, default=True
            True: the leaves at or above the occupancy threshold; False: the
            known leaves below it.
        binary : bool, default=True
            ``binary_little_endian`` (True) or ``ascii`` (False) encoding.
        cubes : bool, default=False
            Write each leaf as a cube mesh instead of a point.
        color : bool, default=True
            Add the colours (the cells' own for a colour map, else by height).

        Returns
        -------
        self
            The map.

        Raises
        ------
        TypeError
            If `path` is not a str or os.PathLike, or a flag
            is not a bool.
        ValueError
            If ``cubes=True`` and the leaves are more than 268,435,455 (their
            vertex indices would overflow int32).
        OSError
            If the file cannot be written (missing folder, no permission); the
            message names the path.

        Notes
        -----
        Coordinates are stored in single precision, as liboctomap stores them:
        across the key range (``2**15`` cells each side) that resolves a cell to
        about 1/256 of its edge.

        Examples
        --------
        >>> import os, tempfile
        >>> from occgp import OccupancyOctree
        >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
        >>> path = os.path.join(tempfile.mkdtemp(), "map.ply")
        >>> _ = m.save_ply(path, binary=False)
        >>> print(open(path).read().splitlines()[-1])
        1.04999995 0.0500000007 0.0500000007 0.100000001 0.699999988 33 145 140
        """
        _export.save_ply(self, path, occupied=occupied, binary=binary, cubes=cubes,
                         color=color)
        return self

    def save_pcd(self, path, *, occupied: bool = True, binary: bool = True):
        """Write the centres of the occupied (or the free) leaves to a PCD v0.7 file.

        Fields ``x y z intensity`` (float32), ``intensity`` being the leaf's
        occupancy probability (PCL's ``PointXYZI``); the viewpoint is the origin.
        A colour map (:class:`occgp.ColorOctree`) adds the field ``rgb``:
        the leaf's colour packed as ``r << 16 | g << 8 | b`` in a uint32
        (``TYPE U``; PCL's ``PointXYZRGB`` holds the same bits), ``0xFFFFFF`` for
        leaves without colour.
        Pruned leaves give one point at their centre (see
        :meth:`~occgp.OccupancyOctree.expand` for finest cells).

        The file is written atomically: a temporary file beside `path` replaces
        it once complete, so the previous file stays intact if the write fails.

        Parameters
        ----------
        path : str or os.PathLike
            Destination (overwritten).
        occupied : bool, default=True
            True: the leaves at or above the occupancy threshold; False: the
            known leaves below it.
        binary : bool, default=True
            ``DATA binary`` (True) or ``DATA ascii`` (False).

        Returns
        -------
        self
            The map.

        Raises
        ------
        TypeError
            If `path` is not a str or os.PathLike, or a flag
            is not a bool.
        OSError
            If the file cannot be written; the message names the path.

        See Also
        --------
        occgp.datasets.read_pcd : Reads the file back.

        Examples
        --------
        >>> import os, tempfile
        >>> from occgp import OccupancyOctree
        >>> from occgp.datasets import read_pcd
        >>> m = OccupancyOctree(0.1).insert_scan([[1.0, 0.0, 0.0]], [0.0, 0.0, 0.0])
        >>> path = os.path.join(tempfile.mkdtemp(), "map.pcd")
        >>> _ = m.save_pcd(path)
        >>> scan, fields = read_pcd(path, return_fields=True)
        >>> scan.points.round(2).tolist(), fields["intensity"].round(2).tolist()
        ([[1.05, 0.05, 0.05]], [0.7])
        """
        _export.save_pcd(self, path, occupied=occupied, binary=binary)
        return self

    def to_open3d(self, *, kind: str = "voxels", occupied: bool = True,
                  max_voxels: int | None = None):
        """The occupied (or the free) cells of a map as an Open3D geometry.

        Parameters
        ----------
        tree : OccupancyOctree or GridMap
        kind : {"voxels", "points"}, default="voxels"
            ``"voxels"``: an ``open3d.geometry.VoxelGrid`` of voxel size
            ``resolution``, aligned to the map's cells; pruned leaves are expanded
            to their finest cells. ``"points"``: an ``open3d.geometry.PointCloud``
            of the leaf centres (one point per leaf, pruned or not).
        occupied : bool, default=True
            True: the leaves at or above the occupancy threshold; False: the
            known leaves below it.
        max_voxels : int, default=None
            The most voxels (None: ``occgp.io._export.MAX_VOXELS``, 4194304) ``kind="voxels"`` builds (about 56 bytes each); past
            it a ValueError is raised before any allocation (free space, which
            prunes into large leaves, reaches it first).

        Returns
        -------
        geometry : open3d.geometry.VoxelGrid or open3d.geometry.PointCloud
            Coloured by height (viridis, from the lowest to the highest cell), or
            with the cells' own colours for a colour map
            (:class:`occgp.ColorOctree`).

        Raises
        ------
        ImportError
            If Open3D is not installed (the extra ``occgp[open3d]``).
        TypeError
            If `occupied` not a bool or `max_voxels` not an int.
        ValueError
            If `kind` is unknown, or the voxels would be more than `max_voxels`.
        """
        return _export.to_open3d(self, kind=kind, occupied=occupied,
                                 max_voxels=_export.MAX_VOXELS if max_voxels is None
                                 else max_voxels)

    def distance_field(self, bbox: ArrayLike, resolution: float | None = None, *,
                       unknown: str = "occupied", max_cells: int | None = None,
                       signed: bool = False, return_closest: bool = False,
                       return_gradient: bool = False):
        """Euclidean distance from each cell of a regular grid to the nearest obstacle.

        The grid covers the box `bbox` with cubic cells of edge `resolution`,
        aligned to its multiples: its minimum corner is
        ``floor(bbox[0] / resolution) * resolution`` and it reaches at least
        ``bbox[1]`` (a corner within 1e-9 cell of a multiple of `resolution`
        counts as on it). Each cell takes the map's state at its centre (occupied,
        free or unknown); obstacle cells are the occupied ones, plus the unknown
        ones when ``unknown="occupied"``. The distance, in metres, is from each
        cell's centre to the nearest obstacle cell's centre (scipy's exact
        feature transform, ``scipy.ndimage.distance_transform_edt``; the
        distance is ``sqrt(i² + j² + k²) * resolution`` for the integer offset
        ``(i, j, k)`` to that cell), so obstacle cells hold 0 and a cell next to
        one holds `resolution`. Obstacles outside the box are not seen. For a
        field stored in blocks, truncated, and updated from the map's changes,
        see :class:`occgp.DistanceMap`.

        Parameters
        ----------
        bbox : array-like of shape (2, 3)
            ``[min_corner, max_corner]`` in metres, finite, min < max on every axis.
        resolution : float, default=None
            Cell edge in metres; default: the map's resolution (then the grid's
            cells are the map's finest cells).
        unknown : {"occupied", "free"}, default="occupied"
            How cells the map knows nothing about count: as obstacles (the safe
            choice for planning) or as free space. Points outside the map's key
            range are unknown.
        max_cells : int, default=None
            The most cells (None: ``occgp.nav._distance.MAX_DISTANCE_CELLS``, 8388608)
            the grid may have (about 30 bytes each at peak, up to 90 with
            `signed` and both extras); past it a ValueError is raised before any
            allocation.
        signed : bool, default=False
            Signed distances, as voxblox's and nvblox's ESDF: positive outside
            obstacles (the distance above), and in each obstacle cell minus the
            distance from its centre to the nearest non-obstacle cell's centre.
            A boundary obstacle cell holds ``-resolution``, its free neighbour
            ``+resolution``; no cell holds 0 (``-inf`` in every cell when the
            grid holds no non-obstacle cell).
        return_closest : bool, default=False
            Also return, per cell, the centre of the cell its distance is
            measured to: the nearest obstacle cell (an obstacle cell's own
            centre in an unsigned field; with `signed`, for obstacle cells, the
            nearest non-obstacle cell). NaN where there is none. Ties between
            equally near cells are broken by scipy's transform.
        return_gradient : bool, default=False
            Also return the gradient of the distance as the unit vector
            ``(centre - closest) / distance``: away from the nearest obstacle
            outside obstacles, towards free space inside them (signed), so that
            it points where the distance grows; 0 in the obstacle cells of an
            unsigned field, NaN where `closest` is NaN.

        Returns
        -------
        field : DistanceField
            Named tuple ``(distances, origin, resolution)``: `distances` of shape
            (nx, ny, nz) indexed along x, y, z (inf everywhere when the grid holds
            no obstacle), `origin` the grid's minimum corner, `resolution` its
            cell edge.
        closest : ndarray of shape (nx, ny, nz, 3)
            Only with `return_closest`: centres in metres.
        gradient : ndarray of shape (nx, ny, nz, 3)
            Only with `return_gradient`.

        Raises
        ------
        TypeError
            If `bbox` does not hold numbers, `resolution` is not a real number,
            `max_cells` not an int, or a flag not a bool.
        ValueError
            If `bbox` is not of shape (2, 3), not finite or not min < max;
            `resolution` not positive and finite; `unknown` not one of the
            choices; or the grid would have more than `max_cells` cells.

        Examples
        --------
        >>> from occgp import OccupancyOctree
        >>> m = OccupancyOctree(1.0).set_cells([[0.5, 0.5, 0.5]], [2.0])
        >>> field = m.distance_field([[0, 0, 0], [3, 1, 1]], unknown="free")
        >>> field.distances[:, 0, 0].tolist(), field.origin.tolist()
        ([0.0, 1.0, 2.0], [0.0, 0.0, 0.0])
        >>> m = m.set_cells([[1.5, 0.5, 0.5], [2.5, 0.5, 0.5]], [2.0, -2.0])
        >>> field, closest, gradient = m.distance_field(
        ...     [[0, 0, 0], [3, 1, 1]], unknown="free", signed=True,
        ...     return_closest=True, return_gradient=True)
        >>> field.distances[:, 0, 0].tolist()
        [-2.0, -1.0, 1.0]
        >>> closest[:, 0, 0, 0].tolist(), gradient[:, 0, 0, 0].tolist()
        ([2.5, 2.5, 1.5], [1.0, 1.0, 1.0])
        """
        return _distance.distance_field(
            self, bbox, resolution, unknown=unknown,
            max_cells=_distance.MAX_DISTANCE_CELLS if max_cells is None else max_cells,
            signed=signed, return_closest=return_closest, return_gradient=return_gradient)

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _check_method(method: str, superray_threshold: int) -> tuple[str, int]:
        """Validate `method` and `superray_threshold`; return the method ("auto" becomes
        "superray+culling", which backs off super rays on scans where grouping does not
        pay) and the threshold the core takes (0: no super rays)."""
        method = check_choice(method, "method", METHODS)
        superray_threshold = check_int(superray_threshold, "superray_threshold", low=1,
                                       high=2**31 - 1)
        if method == "auto":
            method = "superray+culling"
        return method, int(superray_threshold) if method.startswith("superray") else 0

    def _max_scan_cells(self) -> int:
        """MAX_SCAN_CELLS, checked (it may be set on the class or the map)."""
        return check_int(self.MAX_SCAN_CELLS, "MAX_SCAN_CELLS", low=1, high=2**62)

    @staticmethod
    def _insert_statistics(stats: tuple) -> dict[str, float]:
        """``last_insert_`` from what a core's scan insertion returns."""
        region, cells, rays, traversed, seconds, unnecessary, spared, culled, region_spared = stats
        out = {"rays": rays, "updated_cells": cells, "traversed_cells": traversed,
               "spared_cells": spared, "culled_rays": culled,
               "region_spared_cells": region_spared,
               "region_cells": region, "endpoint_seconds": seconds[0],
               "superray_seconds": seconds[1], "region_seconds": seconds[2],
               "preprocessing_seconds": seconds[1] + seconds[2],
               "traversal_seconds": seconds[3], "update_seconds": seconds[4]}
        if unnecessary >= 0:
            out["unnecessary_traversals"] = unnecessary
        return out

    def _validated_scan(self, points: ArrayLike, origin: ArrayLike, max_range, mode: str,
                        check_ends: bool = True, name: str = "points"):
        """Check a scan for insertion; return (points, origin, max_range, cells) as the
        core wants them (float32, -1 for no limit; cells: see :meth:`_raise_bad_ends`), or
        None for an empty scan. Without `check_ends` the caller's core checks the ray ends
        itself (and calls :meth:`_raise_bad_ends` when one is out of range or cannot be
        walked), and cells is None. `name`: the points' name in errors."""
        mode = check_choice(mode, "mode", MODES)
        rng = -1.0 if max_range is None else check_real(max_range, "max_range", low=0.0)
        pts64 = as_points(points, name)
        org = self._as_float32_origin(origin)
        with np.errstate(over="ignore"):
            pts = pts64.astype(np.float32)
        if len(pts) == 0:
            return None
        if rng >= 0:
            pts = _cut_far_rays(pts64, pts, org, rng)
        cells = self._raise_bad_ends(pts, org, rng, name) if check_ends else None
        return pts, org, rng, cells

    def _raise_bad_ends(self, pts: np.ndarray, org: np.ndarray, rng: float,
                        name: str = "points") -> np.ndarray:
        """Raise ValueError if a ray end (after truncation at `rng`) is out of key range,
        or a ray is too short for the single-precision traversal to walk it; otherwise
        return each ray's key distance (a bound on the cells it crosses)."""
        codes, cells = self._check_rays(pts, org, rng)
        if (codes == Status.OUT_OF_RANGE).any():
            self._raise_out_of_range(name, codes != Status.OUT_OF_RANGE,
                                     " (after truncation at max_range)" if rng >= 0 else "")
        if (codes == Status.RAY_TOO_SHORT).any():
            bad = np.flatnonzero(codes == Status.RAY_TOO_SHORT)
            check_status(Status.RAY_TOO_SHORT, n_bad=len(bad), n_total=len(codes),
                         shortest=_SHORTEST_RAY, first=int(bad[0]))
        return cells

    def _record_insert(self, stats, pts: np.ndarray, org: np.ndarray, rng: float,
                       method: str, threshold: int) -> None:
        """Set ``last_insert_`` from a core's scan insertion, or raise for its Status
        (the core changed nothing)."""
        if isinstance(stats, Status):
            if stats != Status.TOO_MANY_CELLS:
                self._raise_bad_ends(pts, org, rng)     # the rays at fault, by row
            check_status(stats, n_rays=len(pts), max_scan_cells=self.MAX_SCAN_CELLS,
                         resolution=self.resolution)
        self.last_insert_ = self._insert_statistics(stats)
        self.last_insert_["superrays"] = threshold != 0
        learn_superrays(self, method, len(pts))

    def _as_float32_points(self, x: ArrayLike, name: str) -> np.ndarray:
        # beyond float range is beyond every key range: inf, which no key holds
        with np.errstate(over="ignore"):
            return np.ascontiguousarray(as_points(x, name), dtype=np.float32)

    def _as_float32_origin(self, x: ArrayLike, name: str = "origin") -> np.ndarray:
        with np.errstate(over="ignore"):
            org = np.ascontiguousarray(as_point(x, name), dtype=np.float32)
        if not self._in_range(org[None]).all():
            lo, hi = self.key_range
            raise ValueError(f"{name} {org.tolist()} lies outside the {self._kind}'s key range "
                             f"[{lo:g}, {hi:g}) m at resolution {self.resolution:g}")
        return org

    def _raise_out_of_range(self, name: str, ok: np.ndarray, what: str) -> None:
        lo, hi = self.key_range
        check_status(Status.OUT_OF_RANGE, n_bad=int(np.count_nonzero(~ok)), n_total=len(ok),
                     name=name, what=what, kind=self._kind, lo=lo, hi=hi,
                     resolution=self.resolution, first=int(np.flatnonzero(~ok)[0]))


class OctreeFace(LogOddsMap):
    """What the octrees (:class:`occgp.OccupancyOctree`, :class:`occgp.ColorOctree`) add to
    the log-odds face: the tree's leaves and nodes, from their compiled cores'
    ``_num_leaves`` and ``_num_nodes``."""

    if TYPE_CHECKING:  # provided by the compiled core the subclass also derives from
        def _num_leaves(self) -> int: ...
        def _num_nodes(self) -> int: ...

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(resolution={self.resolution!r}, "
                f"num_leaves={self.num_leaves})")

    @property
    def num_leaves(self) -> int:
        """Number of leaves (known cells, after pruning)."""
        return self._num_leaves()

    @property
    def num_nodes(self) -> int:
        """Number of nodes in the tree, inner nodes included."""
        return self._num_nodes()

    def _num_cells(self) -> int:
        return self._num_leaves()


def check_params(params: dict) -> dict:
    """Validate a log-odds map's parameters; return them as floats."""
    out = dict(params)
    out["resolution"] = check_resolution(params["resolution"])
    out["prob_hit"] = check_real(params["prob_hit"], "prob_hit", low=0.5, high=1.0)
    out["prob_miss"] = check_real(params["prob_miss"], "prob_miss", low=0.0, high=0.5)
    out["clamping_min"] = check_real(params["clamping_min"], "clamping_min", low=0.0, high=0.5)
    out["clamping_max"] = check_real(params["clamping_max"], "clamping_max", low=0.5, high=1.0)
    out["occupancy_threshold"] = check_probability(params["occupancy_threshold"],
                                                   "occupancy_threshold")
    return out


def _cut_far_rays(pts64: np.ndarray, pts: np.ndarray, org: np.ndarray, rng: float) -> np.ndarray:
    """Make rays to far points cut at `rng` as they should be.

    liboctomap truncates a ray at ``max_range`` along ``(p - origin).normalized()``, in
    single precision: a point so far (over ~1.8e19 m, or beyond float range) that its
    squared distance overflows gives a zero direction, and the ray would vanish. Those
    points (only those: every other ray keeps liboctomap's arithmetic) are moved, in
    double precision, onto their ray at twice `rng`, where the truncation gives the cut
    the ray should have. When twice `rng` is itself that far, the cut end lies beyond
    every key range, and the point is left to be reported out of range.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        d = pts - org
        nsq = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
    far = ~np.isfinite(nsq)
    if not far.any():
        return pts
    delta = pts64[far] - org.astype(np.float64)
    scale = np.abs(delta).max(axis=1, keepdims=True)
    unit = delta / scale
    dist = scale[:, 0] * np.linalg.norm(unit, axis=1)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    cut = dist > rng
    if 2 * rng >= 0.5 * _LONGEST_RAY:
        return pts
    pts = pts.copy()
    rows = np.flatnonzero(far)[cut]
    pts[rows] = (org.astype(np.float64) + unit[cut] * (2 * rng)).astype(np.float32)
    return pts
