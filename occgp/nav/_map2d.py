"""A 2D occupancy grid for navigation: the projection of a 3D map's height band.

:class:`OccupancyGrid2D` is what ``project_2d`` of the log-odds maps returns;
it writes and reads the PGM + YAML pair of ROS's map_server / Nav2
(:mod:`occgp.nav._ros_map`) and finds its frontiers (:mod:`occgp.nav._frontiers`).
"""

from __future__ import annotations

import os

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _frontiers
from . import _ros_map
from .._validation import as_numeric, as_path, as_point, as_points, check_int, check_real

__all__ = ["OccupancyGrid2D"]


class OccupancyGrid2D:
    """A 2D grid of cell states: occupied, free or unknown.

    Cell ``[i, j]`` covers ``origin + [i, j] * resolution`` to
    ``origin + [i + 1, j + 1] * resolution`` (metres); `states` is indexed
    along x, then y. Built by ``project_2d`` of the log-odds maps
    (:meth:`occgp.OccupancyOctree.project_2d`), or read from map_server files
    (:meth:`load_ros_map`).

    Parameters
    ----------
    states : array-like of int of shape (nx, ny)
        1 occupied, 0 free, -1 unknown (ROS's ``nav_msgs/OccupancyGrid`` uses
        100, 0 and -1: see :meth:`to_ros_array`). Copied as int8.
    origin : array-like of shape (2,)
        x, y of the grid's minimum corner, metres.
    resolution : float
        Edge of the square cells, metres.

    Attributes
    ----------
    states : ndarray of int8 of shape (nx, ny)
    origin : ndarray of shape (2,)
    resolution : float

    Raises
    ------
    TypeError
        If `states` does not hold integers or `resolution` is not a real number.
    ValueError
        If `states` is not 2D or holds values other than -1, 0 and 1, `origin`
        is not 2 finite numbers or `resolution` not positive and finite.

    Examples
    --------
    >>> from occgp import OccupancyGrid2D
    >>> grid = OccupancyGrid2D([[1, 0], [-1, 0]], origin=[-1.0, 0.0], resolution=0.5)
    >>> grid.shape, grid.cell_centers()[1, 0].tolist()
    ((2, 2), [-0.25, 0.25])
    """

    def __init__(self, states: ArrayLike, origin: ArrayLike, resolution: float) -> None:
        arr = as_numeric(states, "states", kinds="iufb")
        if arr.dtype.kind not in "iu":
            raise TypeError(f"states must hold integers (-1, 0 or 1), got dtype {arr.dtype}")
        if arr.ndim != 2:
            raise ValueError(f"states must have shape (nx, ny), got {arr.shape}")
        if arr.size and not np.isin(arr, (-1, 0, 1)).all():
            bad = arr[~np.isin(arr, (-1, 0, 1))]
            raise ValueError(f"states must hold -1 (unknown), 0 (free) and 1 (occupied) only, "
                             f"got {int(bad.flat[0])}")
        self.states = np.array(arr, dtype=np.int8, order="C")
        self.origin = as_point(origin, "origin", dim=2).copy()
        self.resolution = check_real(resolution, "resolution", low=0.0)

    def __repr__(self) -> str:
        return (f"OccupancyGrid2D(shape={self.shape}, origin={self.origin.tolist()}, "
                f"resolution={self.resolution!r})")

    @property
    def shape(self) -> tuple[int, int]:
        """(nx, ny), the number of cells along x and y."""
        return self.states.shape  # type: ignore[return-value]

    # ------------------------------------------------------------------ cells
    def cell_centers(self) -> NDArray[np.float64]:
        """Centers of every cell.

        Returns
        -------
        centers : ndarray of shape (nx, ny, 2)
            x, y in metres, indexed as `states`.

        Examples
        --------
        >>> from occgp import OccupancyGrid2D
        >>> OccupancyGrid2D([[0, 1]], [0, 0], 0.5).cell_centers().tolist()
        [[[0.25, 0.25], [0.25, 0.75]]]
        """
        axes = [self.origin[a] + (np.arange(n) + 0.5) * self.resolution
                for a, n in enumerate(self.shape)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)

    def world_to_cell(self, points: ArrayLike) -> NDArray[np.int64]:
        """The cell index of each point: ``floor((point - origin) / resolution)``.

        Parameters
        ----------
        points : array-like of shape (n_points, 2)
            x, y in metres, finite.

        Returns
        -------
        index : ndarray of int64 of shape (n_points, 2)
            ``[i, j]`` per point; points outside the grid get indices outside
            ``[0, nx) x [0, ny)`` (test with ``(index >= 0) & (index < shape)``).

        Raises
        ------
        TypeError
            If `points` does not hold real numbers.
        ValueError
            If `points` is not of shape (n_points, 2), holds NaN or inf, or lies
            so far away that its index overflows int64.

        Examples
        --------
        >>> from occgp import OccupancyGrid2D
        >>> grid = OccupancyGrid2D([[0, 1], [1, 0]], [0, 0], 0.5)
        >>> grid.world_to_cell([[0.7, 0.2], [-0.1, 0.0]]).tolist()
        [[1, 0], [-1, 0]]
        """
        pts = as_points(points, "points", dim=2)
        index = np.floor((pts - self.origin) / self.resolution)
        if len(index) and np.abs(index).max() >= 2.0**62:
            raise ValueError("points lie too far from the grid: their cell index overflows int64")
        return index.astype(np.int64)

    # ------------------------------------------------------------------ ROS
    def to_ros_array(self) -> NDArray[np.int8]:
        """The cells as ``nav_msgs/OccupancyGrid`` holds them.

        Returns
        -------
        data : ndarray of int8 of shape (ny, nx)
            100 occupied, 0 free, -1 unknown; row ``j`` is ``y = origin[1] +
            (j + 0.5) * resolution`` (rows from the smallest y, as the message's
            row-major ``data``: ``data.ravel()``).

        Examples
        --------
        >>> from occgp import OccupancyGrid2D
        >>> OccupancyGrid2D([[1, 0, -1]], [0, 0], 0.5).to_ros_array().tolist()
        [[100], [0], [-1]]
        """
        lut = np.array([0, 100, -1], dtype=np.int8)  # indexed by state: 0, 1, -1
        return np.ascontiguousarray(lut[self.states.T])

    def occupancy_image(self) -> NDArray[np.uint8]:
        """The cells as map_saver's trinary image: 0 occupied, 254 free, 205 unknown.

        Returns
        -------
        image : ndarray of uint8 of shape (ny, nx)
            Row 0 is the largest y (the top of the image, as map_server reads
            it), column 0 the smallest x.

        Examples
        --------
        >>> from occgp import OccupancyGrid2D
        >>> OccupancyGrid2D([[1, 0, -1]], [0, 0], 0.5).occupancy_image().ravel().tolist()
        [205, 254, 0]
        """
        lut = np.array([_ros_map.FREE, _ros_map.OCCUPIED, _ros_map.UNKNOWN], dtype=np.uint8)
        return np.ascontiguousarray(lut[self.states.T[::-1]])

    def save_ros_map(self, path: str | os.PathLike) -> tuple:
        """Write the grid as map_server / Nav2 files: a PGM image and its YAML file.

        The YAML file `path` (``image``, ``mode: trinary``, ``resolution``,
        ``origin: [x, y, 0.0]``, ``negate: 0``, ``occupied_thresh: 0.65``,
        ``free_thresh: 0.196``) names the image ``<stem>.pgm`` written beside
        it: a binary PGM (P5) of :meth:`occupancy_image` (0 occupied, 254 free,
        205 unknown, the top row the largest y), as ``map_saver`` writes
        trinary maps. The thresholds are map_saver's fixed trinary ones:
        map_server (ROS 1 and Nav2) reads the three grey levels back as
        occupied, free and unknown. Numbers are written in full precision.

        The files are written atomically: both go to temporary files beside
        `path` first, then the image replaces ``<stem>.pgm`` and only after it
        the YAML file replaces `path`, so that a reader never sees a YAML file
        naming a missing or half-written image; the previous files stay intact
        if the write fails (when replacing the YAML file fails, the old image
        is put back). A process killed between the two replacements can leave
        the new image beside the old YAML file.

        Parameters
        ----------
        path : str or os.PathLike
            The YAML file, ending in ``.yaml`` or ``.yml``; without a suffix,
            ``.yaml`` is added. Its folder must exist.

        Returns
        -------
        yaml_path, image_path : pathlib.Path
            The two files written.

        Raises
        ------
        TypeError
            If `path` is not a str or os.PathLike.
        ValueError
            If `path` has another suffix, or the grid has no cell.
        OSError
            If a file cannot be written.

        Examples
        --------
        >>> import tempfile, pathlib
        >>> from occgp import OccupancyGrid2D
        >>> grid = OccupancyGrid2D([[1, 0], [-1, 0]], [-1.0, 2.0], 0.5)
        >>> with tempfile.TemporaryDirectory() as tmp:
        ...     yaml_path, pgm = grid.save_ros_map(pathlib.Path(tmp) / "map")
        ...     back = OccupancyGrid2D.load_ros_map(yaml_path)
        ...     print(pgm.name, back.states.tolist(), back.origin.tolist())
        map.pgm [[1, 0], [-1, 0]] [-1.0, 2.0]
        """
        path = as_path(path)
        if path.suffix == "":
            path = path.with_name(path.name + ".yaml")
        elif path.suffix not in (".yaml", ".yml"):
            raise ValueError(f"path must end in .yaml or .yml (the map's YAML file; the "
                             f"image is written beside it), got {str(path)!r}")
        if self.states.size == 0:
            raise ValueError(f"cannot write an empty grid (shape {self.shape}) as a map image")
        return _ros_map.write_ros_map(path, self.occupancy_image(), self.resolution,
                                      self.origin)

    @classmethod
    def load_ros_map(cls, path: str | os.PathLike) -> "OccupancyGrid2D":
        """Read map_server / Nav2 files: a YAML file and the PGM image it names.

        The YAML file must give ``image`` (a path relative to the YAML file's
        folder, or absolute), ``resolution``, ``origin`` (``[x, y, yaw]`` with
        yaw 0), ``negate``, ``occupied_thresh`` and ``free_thresh``; ``mode`` is
        optional and must be ``trinary``. Each pixel is classified as
        map_server's trinary mode does: with ``p = (255 - v) / 255`` (or
        ``v / 255`` with ``negate: 1``; ``maxval`` in place of 255),
        occupied where ``p > occupied_thresh``, free where ``p < free_thresh``,
        unknown otherwise. The image must be a PGM (binary P5 or plain P2).

        Parameters
        ----------
        path : str or os.PathLike
            The YAML file.

        Returns
        -------
        grid : OccupancyGrid2D

        Raises
        ------
        TypeError
            If `path` is not a str or os.PathLike.
        OSError
            If a file cannot be read (FileNotFoundError when missing).
        ValueError
            If the YAML file is not valid YAML, lacks a key, holds a value of the
            wrong type or range (a non-zero yaw, a mode other than trinary,
            thresholds out of order), or the image is not a well-formed PGM
            (truncated data, extra bytes, a malformed header, values above
            maxval). The message names the file.

        Examples
        --------
        >>> import tempfile, pathlib
        >>> from occgp import OccupancyGrid2D
        >>> with tempfile.TemporaryDirectory() as tmp:
        ...     _ = OccupancyGrid2D([[0, 1, -1]], [0, 0], 0.1).save_ros_map(pathlib.Path(tmp) / "m.yaml")
        ...     OccupancyGrid2D.load_ros_map(pathlib.Path(tmp) / "m.yaml").states.tolist()
        [[0, 1, -1]]
        """
        states, origin, resolution = _ros_map.read_ros_map(as_path(path))
        return cls(states, origin, resolution)

    # ------------------------------------------------------------------ frontiers
    def frontiers(self, *, min_size: int = 1) -> _frontiers.Frontiers:
        """Frontier cells: free cells with an unknown neighbour, in clusters.

        A frontier cell is a free cell with at least one unknown cell among its
        4 edge neighbours; the cells beyond the grid count as unknown. Frontier
        cells are clustered by 8-connectivity (``scipy.ndimage.label``).

        Parameters
        ----------
        min_size : int, default=1
            Clusters of fewer cells are dropped.

        Returns
        -------
        frontiers : Frontiers
            Cell centers of shape (n_cells, 2), their clusters, and each
            cluster's centroid and size (largest first).

        Raises
        ------
        TypeError
            If `min_size` is not an int.
        ValueError
            If `min_size` is below 1.

        Examples
        --------
        >>> from occgp import OccupancyGrid2D
        >>> grid = OccupancyGrid2D([[1, 1, 1, 1], [1, 0, 0, -1], [1, 0, 0, -1], [1, 1, 1, 1]],
        ...                        origin=[0, 0], resolution=1.0)
        >>> f = grid.frontiers()
        >>> f.cells.tolist(), f.sizes.tolist(), f.centroids.tolist()
        ([[1.5, 2.5], [2.5, 2.5]], [2], [[2.0, 2.5]])
        """
        min_size = check_int(min_size, "min_size", low=1)
        return _frontiers.find_frontiers(self.states, self.origin, self.resolution, min_size)
