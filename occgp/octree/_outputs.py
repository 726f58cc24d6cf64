"""What every log-odds map writes out and derives: PLY and PCD files, Open3D
geometries and distance fields.

The functions are methods of :class:`occgp.OccupancyOctree`,
:class:`occgp.ColorOctree` and :class:`occgp.GridMap`: :class:`~occgp.octree.LogOddsMap`
binds them in its class body (``save_ply = _outputs.save_ply``), so their first
argument is the map, named ``self``. Each calls its helper in :mod:`occgp.io._export`
or :mod:`occgp.nav._distance`, which reads the map's cells.
"""

from __future__ import annotations

from numpy.typing import ArrayLike

from ..io import _export
from ..nav import _distance

__all__ = ["save_ply", "save_pcd", "to_open3d", "distance_field"]


def save_ply(self, path, *, occupied: bool = True, binary: bool = True,
             cubes: bool = False, color: bool = True):
    """Write the occupied (or the free) cells of a map to a PLY file.

    With ``cubes=False`` the file is a point cloud: one vertex per leaf, at
    its center. With ``cubes=True`` it is a triangle mesh: each leaf is a cube
    of 8 vertices and 12 triangles (counter-clockwise seen from outside), so
    that mesh viewers (MeshLab, CloudCompare, Open3D) show the voxels. Every
    vertex carries the properties

    * ``x y z`` (float): the center (points) or a corner (cubes), in metres;
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
    """Write the centers of the occupied (or the free) leaves to a PCD v0.7 file.

    Fields ``x y z intensity`` (float32), ``intensity`` being the leaf's
    occupancy probability (PCL's ``PointXYZI``); the viewpoint is the origin.
    A colour map (:class:`occgp.ColorOctree`) adds the field ``rgb``:
    the leaf's colour packed as ``r << 16 | g << 8 | b`` in a uint32
    (``TYPE U``; PCL's ``PointXYZRGB`` holds the same bits), ``0xFFFFFF`` for
    leaves without colour.
    Pruned leaves give one point at their center (see
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
    occgp.io.read_pcd : Reads the file back.

    Examples
    --------
    >>> import os, tempfile
    >>> from occgp import OccupancyOctree
    >>> from occgp.io import read_pcd
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
        of the leaf centers (one point per leaf, pruned or not).
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
    counts as on it). Each cell takes the map's state at its center (occupied,
    free or unknown); obstacle cells are the occupied ones, plus the unknown
    ones when ``unknown="occupied"``. The distance, in metres, is from each
    cell's center to the nearest obstacle cell's center (scipy's exact
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
        distance from its center to the nearest non-obstacle cell's center.
        A boundary obstacle cell holds ``-resolution``, its free neighbour
        ``+resolution``; no cell holds 0 (``-inf`` in every cell when the
        grid holds no non-obstacle cell).
    return_closest : bool, default=False
        Also return, per cell, the center of the cell its distance is
        measured to: the nearest obstacle cell (an obstacle cell's own
        center in an unsigned field; with `signed`, for obstacle cells, the
        nearest non-obstacle cell). NaN where there is none. Ties between
        equally near cells are broken by scipy's transform.
    return_gradient : bool, default=False
        Also return the gradient of the distance as the unit vector
        ``(center - closest) / distance``: away from the nearest obstacle
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
        Only with `return_closest`: centers in metres.
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
