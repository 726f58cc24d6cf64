"""``occgp map``: :func:`map_scans` builds a map from scan files and ROS bags and saves it
(the command line itself is :mod:`occgp.cli`; its options and their parsing are in
``_map_options.py``)."""

from __future__ import annotations

import errno
import inspect
import re
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .._validation import check_n_jobs, check_real, check_resolution, show_number
from ..maps import OCTREE_FORMATS, available_maps, make_map, map_type
from ..octree._tree import OccupancyOctree
from ._map_options import (KNN_DEFAULTS, KNN_OPTIONS, OPTION_OF, OWN_PARAMS, POSE_FORMATS,
                           OptionError, OptionTypeError, check_knn_options, knn_error,
                           option_error, option_name, parse_fields, parse_param)

__all__ = ["map_scans", "map_methods", "OptionError", "OPTION_OF", "POSE_FORMATS",
           "KNN_OPTIONS", "KNN_DEFAULTS", "check_knn_options", "knn_error", "option_name",
           "parse_param", "parse_fields"]

#: The outputs that are 2D maps (map_server's YAML, with project_2d)
ROS_MAP_SUFFIXES = (".yaml", ".yml")
_BAG_SUFFIXES = (".bag", ".db3", ".mcap")


def map_methods() -> list[str]:
    """The map types ``occgp map --method`` builds: every registered 3D map whose
    ``insert_scan`` takes a plain scan (points and origin), plugins' included
    (:class:`~occgp.ColorOctree` then updates occupancy only: scan files carry no
    colours).

    Returns
    -------
    names : list of str
        Names of :func:`occgp.maps.available_maps`, in its order.
    """
    return [name for name in available_maps(dims=3)
            if _takes_plain_scans(map_type(name).cls)]


def _takes_plain_scans(cls) -> bool:
    try:
        sig = inspect.signature(cls.insert_scan)
    except (AttributeError, TypeError, ValueError):
        return False
    required = [p for p in list(sig.parameters.values())[1:]
                if p.default is p.empty and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
    return len(required) <= 2


def _either(names, last: str) -> str:
    """'a', 'a or b', 'a, b or c' (with `last` the word before the last name)."""
    return ", ".join(names[:-1]) + last + names[-1] if len(names) > 1 else "".join(names)


def _insert_options(cls) -> tuple[str, ...]:
    """The keyword options of a map class's insert_scan."""
    try:
        return tuple(inspect.signature(cls.insert_scan).parameters)
    except (AttributeError, TypeError, ValueError):
        return ()


def _is_bag(path) -> bool:
    """Whether `path` is read with read_rosbag: a ``.bag`` / ``.db3`` / ``.mcap`` file or
    a ROS 2 bag folder (one holding ``metadata.yaml``)."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.suffix.lower() in _BAG_SUFFIXES


def _is_carmen(path) -> bool:
    """Whether `path` is a CARMEN laser log (a text file, maybe compressed, with FLASER or
    ROBOTLASER1 lines)."""
    from ..io._carmen import is_carmen_log
    from ..io._readers import scan_kind

    path = Path(path)
    return path.is_file() and scan_kind(path) == "text" and is_carmen_log(path)


def _suffix(path: Path) -> str:
    return path.suffix.lower()


def _read_poses(path, poses_format):
    """The (n, 4, 4) poses of a KITTI or TUM file (:func:`occgp.io.read_poses`);
    a file whose format cannot be told is an error of the `poses` option."""
    from ..io import read_poses

    try:
        return read_poses(path, poses_format)
    except ValueError as exc:
        if str(exc).startswith(("cannot tell the format", "poses file")):
            raise OptionError("poses", str(exc)) from None
        raise


def _check_params(params, method) -> dict:
    """`params` as a dict, refusing a name map_scans sets from an argument of its own."""
    if params is None:
        return {}
    if not isinstance(params, Mapping):
        raise OptionTypeError("params", f"params must be a mapping of constructor "
                              f"parameters, got {type(params).__name__}")
    own = dict(OWN_PARAMS, **({name: option_name(name) for name in KNN_OPTIONS}
                              if method == "knn" else {}))
    for name, value in params.items():
        if name in own:
            arg = f"{name}=" if name in OWN_PARAMS else "knn_params"
            raise OptionError("params", f"params names {name!r} (= {show_number(value)[:60]}), which has "
                              f"its own option: give it there ({own[name]}; map_scans' "
                              f"{arg})")
    return dict(params)


def _check_map_args(paths, output, method, mode, resolution, max_range, knn_params, n_jobs,
                    poses, poses_format, bag_options, input_map,
                    project_2d=None) -> tuple[Path, float | None, float | None, int | None,
                                              Path | None]:
    """Check map_scans' arguments before anything is read; return (output, resolution,
    max_range, n_jobs, input_map) as used."""
    methods = map_methods()
    if method not in methods:
        raise OptionError("method", f"method must be one of {tuple(methods)}, got {method!r}")
    entry = map_type(method)
    output = Path(output)
    fits = entry.outputs
    if project_2d is not None:
        _check_band(project_2d)
        if _suffix(output) not in ROS_MAP_SUFFIXES:
            raise OptionError("output", f"output must end in .yaml or .yml with project_2d "
                              f"(map_server's YAML, beside its .pgm image), got "
                              f"{str(output)!r}")
    elif _suffix(output) in ROS_MAP_SUFFIXES:
        raise OptionError("output", f"a .yaml output is a 2D map: give project_2d (the "
                          f"height band, --project-2d Z_MIN Z_MAX), got {str(output)!r}")
    elif _suffix(output) not in fits:
        takers = [n for n in methods if _suffix(output) in map_type(n).formats]
        note = f" ({_suffix(output)}: {_either(takers, ' and ')} only)" \
            if _suffix(output) not in OCTREE_FORMATS and takers else ""
        raise OptionError("output", f"output must end in {', '.join(fits[:-1])} or "
                           f"{fits[-1]} for method={method!r}{note}, got {str(output)!r}")
    if not output.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, "output: no such folder for the map file",
                                str(output.parent))
    if mode is not None and "mode" not in _insert_options(entry.cls):
        takers = [repr(n) for n in methods if "mode" in _insert_options(map_type(n).cls)]
        raise OptionError("mode", f"mode applies to method={_either(takers, ' or ')} only, "
                           f"got mode={mode!r} with method={method!r}")
    if mode is not None and mode not in ("scan", "ray"):
        raise OptionError("mode", f"mode must be 'scan' or 'ray', got {mode!r}")
    if knn_params is not None and method != "knn":
        raise ValueError(f"knn_params applies to method='knn' only, got method={method!r}")
    if max_range is not None and isinstance(knn_params, Mapping) and \
            {"max_range", "sensor_range"} & set(knn_params):
        raise OptionError("max_range", "max_range is given twice: as max_range= and in "
                          "knn_params; give it once")
    own = getattr(entry.cls, "RANGE_PARAM", "max_range")
    if max_range is not None and own != "max_range":
        raise OptionError("max_range", f"max_range does not apply to method={method!r}: "
                           f"its range limit is its {own} (default "
                           f"{inspect.signature(entry.cls).parameters[own].default} m), got "
                           f"max_range={max_range!r}")
    try:
        if max_range is not None:
            max_range = check_real(max_range, "max_range", low=0.0)
    except ValueError as exc:
        raise OptionError("max_range", str(exc)) from None
    if resolution is not None:
        try:
            resolution = check_resolution(resolution)
        except ValueError as exc:
            raise OptionError("resolution", str(exc)) from None
    try:
        n_jobs = check_n_jobs(n_jobs)
    except ValueError as exc:
        raise OptionError("n_jobs", str(exc)) from None
    if poses_format is not None:
        if poses is None:
            raise OptionError("poses_format", f"poses_format applies with poses only, got "
                               f"poses_format={poses_format!r} and no poses")
        if poses_format not in POSE_FORMATS:
            raise OptionError("poses_format", f"poses_format must be one of {POSE_FORMATS} "
                               f"or None (guess from the columns), got {poses_format!r}")
    if isinstance(paths, (str, bytes)) or not len(paths):
        raise OptionError("paths", f"paths must be a non-empty sequence of scan files or "
                           f"folders, got {paths!r}")
    try:
        check_real(bag_options["tf_tolerance"], "tf_tolerance", low=0.0, high=1e9,
                   low_open=False)
    except ValueError as exc:
        raise OptionError("tf_tolerance", str(exc)) from None
    given = {k: v for k, v in bag_options.items() if v not in (None, 0.0)}
    if given and not any(_is_bag(p) for p in paths):
        name = next(iter(given))
        raise OptionError(name, f"{name} applies to ROS bag inputs only (.bag, .db3, .mcap "
                           f"files or ROS 2 bag folders), and none is among the scans")
    if input_map is not None:
        input_map = Path(input_map)
        if _suffix(input_map) not in entry.formats:
            kinds = " or ".join(entry.formats)
            raise OptionError("input_map", f"input_map must be a {kinds} file to continue a "
                               f"{method} map, got {str(input_map)!r}")
    return output, resolution, max_range, n_jobs, input_map


def _check_band(band) -> tuple[float, float]:
    """project_2d's (z_min, z_max), checked."""
    try:
        z_min, z_max = band
    except (TypeError, ValueError):
        raise OptionError("project_2d", f"project_2d must be a pair (z_min, z_max), got "
                          f"{band!r}") from None
    try:
        z_min = check_real(z_min, "project_2d's z_min", state_bounds=True)
        z_max = check_real(z_max, "project_2d's z_max", state_bounds=True)
    except ValueError as exc:
        raise OptionError("project_2d", str(exc)) from None
    if z_min > z_max:
        raise OptionError("project_2d", f"project_2d must have z_min <= z_max, got "
                          f"({z_min}, {z_max})")
    return z_min, z_max


def _new_map(method, resolution, max_range, params, n_jobs, input_map, knn=None):
    """The map to insert into: loaded from `input_map` or new (through the registry).
    A value of `params` the map refuses raises the option error of ``params``."""
    entry = map_type(method)
    names = entry.parameters()
    given = {**(knn or {}), **params}
    if "n_jobs" in names:
        given["n_jobs"] = n_jobs
    if max_range is not None and "max_range" in names:
        given["max_range"] = max_range
    if input_map is None:
        if "resolution" in names:
            # None: the type's registered default (a plugin's may differ), else 0.1
            given["resolution"] = (entry.defaults.get("resolution", 0.1)
                                   if resolution is None else resolution)
        try:
            mapper = make_map(method, **given)
            if params:
                _probe(mapper, params)
        except (ValueError, TypeError) as exc:
            if params and not isinstance(exc, (OptionError, OptionTypeError)):
                raise option_error("params", exc) from None
            raise
        return mapper
    try:
        mapper = entry.cls.load(input_map)
    except ValueError as exc:
        raise ValueError(f"input_map: cannot continue it as a {method} map: {exc}") from None
    try:
        if given:
            mapper.set_params(**given)
    except (ValueError, TypeError) as exc:
        if params and _names_any(exc, params):
            raise option_error("params", exc) from None
        raise ValueError(f"input_map: cannot continue it as a {method} map: {exc}") from None
    if resolution is not None and resolution != mapper.resolution:
        raise OptionError("resolution", f"resolution {resolution:g} differs from that of "
                           f"input_map {str(input_map)!r} ({mapper.resolution:g}); leave it "
                           f"out to continue the map at its own")
    return mapper


def _names_any(exc: Exception, params) -> bool:
    """Whether the message of `exc` names one of the parameters `params`."""
    return any(re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", str(exc))
               for name in params)


def _probe(mapper, params) -> None:
    """Check the values of `params` on a map type that checks its parameters only at its
    first update: one zero-length ray into an empty copy (:func:`sklearn.base.clone`).
    An error naming one of `params` is raised; any other is the real run's to report."""
    from sklearn.base import clone

    try:
        probe = clone(mapper)
    except Exception:                # noqa: BLE001 -- a map clone cannot copy: no probe
        return
    try:
        probe.insert_scan(np.zeros((1, 3)), np.zeros(3))
    except (ValueError, TypeError) as exc:
        if _names_any(exc, params):
            raise


def map_scans(paths, output: str | Path, *, resolution: float | None = None,
              method: str = "octree", mode: str | None = None,
              max_range: float | None = None, knn_params: Mapping[str, Any] | None = None,
              poses: str | Path | None = None, poses_format: str | None = None,
              topic: str | None = None, fixed_frame: str | None = None,
              sensor_frame: str | None = None, tf_tolerance: float = 0.0, fields=None,
              input_map: str | Path | None = None, n_jobs: int | None = -1,
              params: Mapping[str, Any] | None = None,
              project_2d: tuple[float, float] | None = None, scan_filter=None,
              progress: bool | None = None, out=None):
    """Build a map from scan files and ROS bags and save it.

    Every step (loading `input_map`, reading each scan file, inserting each
    scan, converting a kernel map to an octree, saving) advances one progress
    bar. At the end one line gives the scans, points, cells, the insertion
    time and the wall time of the whole call; lines before it say how many
    points were dropped (non-finite points of bags) or cut at the range
    limit.

    Parameters
    ----------
    paths : sequence of str or path-like
        Scan files or folders, read lazily, scan by scan, as one
        :class:`occgp.io.ScanSequence` (posed by `poses`; the suffixes
        of :func:`occgp.io.read_scans`); CARMEN 2D laser logs (text
        files, maybe compressed, with ``FLASER`` or ``ROBOTLASER1`` lines),
        read with :func:`occgp.io.read_carmen` and inserted as planar
        scans at z = 0 placed by their own poses (no-return readings
        dropped); and ROS bags (a ``.bag``, ``.db3`` or ``.mcap`` file, or a
        ROS 2 bag folder holding ``metadata.yaml``), read with
        :func:`occgp.io.read_rosbag`. Scans go in in this order.
    output : str or path-like
        The map file; its suffix gives the format: one of the map type's own
        formats (:attr:`occgp.maps.MapType.formats`: ``.bt`` / ``.ot`` for
        the octrees, ``.npz`` with the evidence for the kernel maps and the
        grid, see their ``save``), or ``.bt`` / ``.ot`` (OctoMap) and
        ``.ply`` / ``.pcd`` (the occupied cells, see
        :meth:`~occgp.OccupancyOctree.save_ply` /
        :meth:`~occgp.OccupancyOctree.save_pcd`) through the map's
        ``to_octree()``: a kernel map's cells then hold their posterior mean
        as log-odds (a ``.bt`` file keeps only whether it is above 0.5);
        cells no kernel reached stay unknown.
    resolution : float, default=None
        Cell size in metres; None means the resolution the map type
        registered (:func:`occgp.maps.register`'s defaults), else 0.1, or the
        resolution of `input_map` (which a value given must equal).
    method : str, default="octree"
        A map type of :func:`map_methods` (the registered 3D maps, see
        :func:`occgp.maps.available_maps`), built with
        :func:`occgp.maps.make_map`: e.g. ``"octree"``
        (:class:`~occgp.OccupancyOctree`), ``"grid"``, ``"bgk"``,
        ``"akimap"`` (``random_state=0``) or ``"knn"`` (an octree, written as
        it is). The map gets `resolution` and `n_jobs` (and `max_range`) when
        its constructor takes them.
    mode : {"scan", "ray"}, default=None
        The update mode (None: ``"scan"``); only for maps whose
        ``insert_scan`` takes it (the octree and the grid).
    max_range : float, default=None
        Range limit in metres; None means none (a loaded kernel map keeps
        its own). A map whose
        ``insert_scan`` takes ``max_range`` (the octree, the grid) inserts
        longer beams up to it as free space only; one with a ``max_range``
        parameter (BGK, AKIMap) gets it and cuts them there too (or drops
        them whole, la3dm's rule, when its ``far_beams`` is ``"drop"``, set
        with `params` or kept from `input_map`); any other map gets only the
        end points within `max_range` of the sensor; the k-NN
        map (``method="knn"``) gets it as its own ``max_range`` parameter (it
        cuts the rays; also settable in `knn_params`, not in both). The points beyond
        the limit are counted and reported (raw points: BGK applies its
        limit to the centroids of its down-sampling cubes).
    knn_params : mapping, default=None
        For ``method="knn"`` only: :class:`~occgp.KNNMap`'s ``k``, ``p_u``,
        ``p_l``, ``p_m``, ``p_m_out``, ``p_min``, ``p_max``,
        ``occupancy_threshold``, ``max_range`` and ``cdf`` (``p_t`` and
        ``sensor_range``, the old names, are deprecated); those left out take
        KNNMap's defaults (``max_range`` 4 m: points farther from the sensor are not
        inserted, their rays are cut there). Checked as KNNMap checks them
        (Miao et al.'s Eq. 12) before any scan is read.
    poses : str or path-like, default=None
        A trajectory file: KITTI odometry poses (12 numbers a line, a 3 x 4
        row-major sensor-to-world pose) or TUM (``t x y z qx qy qz qw``).
        Pose ``i`` moves scan ``i`` (in input order, over all `paths`) with
        :func:`occgp.io.apply_poses`; the file must hold one pose per
        scan. TUM timestamps are not matched to scans, only the order counts.
    poses_format : {"kitti", "tum"}, default=None
        The format of `poses`; None guesses it from the first line's columns
        (12: kitti, 8: tum).
    topic, fixed_frame, sensor_frame, tf_tolerance
        For ROS bags only, passed to :func:`occgp.io.read_rosbag`
        (defaults: the only PointCloud2 topic, the root of the TF tree, the
        cloud's frame, 0 s).
    fields : int, str or numpy.dtype, default=None
        Record layout of ``.bin`` scan files, passed to
        :func:`occgp.io.read_scans` (None: by file name).
    input_map : str or path-like, default=None
        A saved map to continue, in one of the map type's own formats
        (``.bt`` / ``.ot`` for ``method="octree"`` and ``"knn"``, ``.npz``
        written by ``save`` for ``"bgk"``, ``"akimap"`` and ``"grid"``),
        read with the class's ``load``; `n_jobs`, `max_range`, `knn_params`
        and `params` are then set with its ``set_params``. The scans are
        inserted into it.
    n_jobs : int, default=-1
        Threads of the map (the constructor's ``n_jobs``, of every map type
        that has threads): -1 every core, None or 1 one. The map does not
        depend on it.
    params : mapping, default=None
        Further constructor parameters of the map type (e.g.
        ``{"prob_hit": 0.8}``), checked by the class before any scan is read
        (a map type that checks its parameters at its first update gets one
        zero-length ray into an empty copy). A parameter set by an argument of
        its own (`resolution`, `n_jobs`, `max_range`, and with
        ``method="knn"`` those of `knn_params`) is refused: each value has one
        place.
    project_2d : (float, float), default=None
        ``(z_min, z_max)``: write a 2D map of that height band instead of
        the 3D map (:meth:`~occgp.OccupancyOctree.project_2d` at the map's
        resolution, over its bounds; a map without it, such as a kernel
        map, goes through its ``to_octree()``), as map_server / Nav2's
        YAML + PGM pair (:meth:`~occgp.OccupancyGrid2D.save_ros_map`);
        `output` must then end in ``.yaml`` or ``.yml``, and the image is
        written beside it with the suffix ``.pgm``.
    scan_filter : occgp.filters.ScanFilter, default=None
        octomap_server's filters (minimum range, height band, self box,
        ground plane), applied to every scan in the world frame before it is
        inserted (:meth:`~occgp.filters.ScanFilter.apply`); with
        ``ground="free"`` the ground points go in as ``free_points`` (maps
        whose ``insert_scan`` takes them: the octree and the grid). Checked
        before any scan is read; the points it drops are counted and
        reported.
    progress : bool, default=None
        Show a progress bar (None: only on a terminal).
    out : file-like, default=None
        Where the summary lines go (None: standard output).

    Returns
    -------
    map : OccupancyMap
        The map built.

    Raises
    ------
    ValueError
        If `output` has a suffix other than those above or one that does not
        fit `method`; `method` or `mode` is not one of the choices (or `mode`
        is given with another method than the octree); `max_range` or
        `resolution` is not positive, or `max_range` is given both as itself
        and in `knn_params`; `n_jobs` is 0; `knn_params` is given with
        another method, names a parameter KNNMap does not take or holds a
        value KNNMap rejects; `poses_format` is given without `poses` or is not a
        choice; the format of `poses` cannot be guessed, or it does not hold
        one pose per scan; a bag option is given and no bag is among `paths`;
        `input_map` does not fit `method`, holds another class of map, or its
        resolution differs from `resolution`; `params` names a parameter
        given by an argument of its own, one the map type does not take, or
        a value it refuses; a file is malformed; or no scan
        is found. The arguments are checked before any file is read; the pose
        count and `input_map` before any scan is inserted. Nothing is written
        when an error is raised.
    TypeError
        If `max_range`, `resolution` or `tf_tolerance` is not a real number,
        `knn_params` or `params` is not a mapping or holds a value of the
        wrong type.
    OSError
        If a scan, pose or map file cannot be read, the folder of `output`
        does not exist (checked first) or the output cannot be written.
    ImportError
        If a bag is given and the ``rosbags`` package is not installed.
    """
    from tqdm.auto import tqdm

    from ..io import Scan, ScanSequence, apply_poses, read_carmen, read_rosbag

    t_start = time.perf_counter()
    out = sys.stdout if out is None else out
    bag_options = {"topic": topic, "fixed_frame": fixed_frame, "sensor_frame": sensor_frame,
                   "tf_tolerance": tf_tolerance}
    output_path, resolution, max_range, n_jobs, input_path = _check_map_args(
        paths, output, method, mode, resolution, max_range, knn_params, n_jobs, poses,
        poses_format, bag_options, input_map, project_2d)
    params = _check_params(params, method)
    _check_scan_filter(scan_filter, method)
    knn = check_knn_options({} if knn_params is None else knn_params) \
        if method == "knn" else {}
    entry = map_type(method)
    pose_array = None if poses is None else _read_poses(poses, poses_format)
    if project_2d is not None:
        convert = not callable(getattr(entry.cls, "project_2d", None))
    else:
        convert = _suffix(output_path) not in entry.formats and not (
            isinstance(entry.cls, type) and issubclass(entry.cls, OccupancyOctree))
    bar = tqdm(total=(input_path is not None) + len(paths) + convert + 1, unit="step",
               disable=None if progress is None else not progress)
    try:
        if input_path is not None:
            bar.set_description(f"loading {input_path.name}")
        mapper: Any = _new_map(method, resolution, max_range, params, n_jobs, input_path,
                               knn)
        if input_path is not None:
            bar.update()
        sources = []          # (input, scans)
        if not any(_is_bag(p) or _is_carmen(p) for p in paths):
            # scan files only: one sequence, posed by the pose file: the Python API's reader
            bar.set_description("listing scan files")
            files = ScanSequence(paths, fields=fields, progress=False)
            if pose_array is not None and len(pose_array) != len(files):
                raise OptionError("poses", f"poses file {str(poses)!r} holds "
                                  f"{len(pose_array)} poses for {len(files)} scans; expected "
                                  f"one pose per scan, in input order")
            if pose_array is not None:
                files = files.with_poses(pose_array)
                pose_array = None      # the sequence carries them
            sources.append((", ".join(map(str, paths)), files))
            bar.total += len(files)
            bar.update(len(paths))
        else:
            for path in paths:
                bar.set_description(f"reading {Path(path).name}")
                if _is_bag(path):
                    source = read_rosbag(path, topic, fixed_frame=fixed_frame,
                                         sensor_frame=sensor_frame, tf_tolerance=tf_tolerance)
                elif _is_carmen(path):
                    source = read_carmen(path).scans_3d()
                else:
                    source = ScanSequence(path, fields=fields, progress=False)
                sources.append((path, source))
                bar.total += len(source)
                bar.update()
        n_scans = sum(len(s) for _, s in sources)
        if not n_scans:
            raise ValueError("no scans found in " + ", ".join(map(str, paths)))
        if pose_array is not None and len(pose_array) != n_scans:
            raise OptionError("poses", f"poses file {str(poses)!r} holds {len(pose_array)} "
                               f"poses for {n_scans} scans; expected one pose per scan, in "
                               f"input order")
        insert, limit, how = _inserter(mapper, mode, max_range)
        n_points = n_beyond = n_done = n_filtered = n_free = 0
        beams = np.zeros(2, dtype=np.int64)     # BGK's (kept, dropped) beams
        dropped = []
        t0 = time.perf_counter()
        bar.set_description("inserting scans")
        for path, source in sources:
            for scan in source:
                scan, free = scan if len(scan) == 2 and isinstance(scan[0], Scan) \
                    else (scan, None)          # a CARMEN scan: (returns, free beam ends)
                if pose_array is not None:
                    scan = apply_poses([scan], pose_array[n_done:n_done + 1])[0]
                points = scan.points
                n_points += len(points)
                if scan_filter is not None:
                    points, free = scan_filter.apply(points, scan.origin)
                    n_filtered += len(scan.points) - len(points)
                    n_free += 0 if free is None else len(free)
                if limit is not None and len(points):
                    far = np.linalg.norm(np.asarray(points, dtype=np.float64)
                                         - np.asarray(scan.origin, dtype=np.float64),
                                         axis=1) > limit
                    n_beyond += int(np.count_nonzero(far))
                    if how == "drop":
                        points = points[~far]
                insert(points, scan.origin, free)
                if how == "param" and hasattr(mapper, "last_beams_"):
                    beams += mapper.last_beams_
                n_done += 1
                bar.update()
            if getattr(source, "n_dropped", 0):
                dropped.append((path, source.n_dropped, source.n_points))
        seconds = time.perf_counter() - t0
        tree = mapper
        if convert:
            bar.set_description("converting to an octree")
            tree = mapper.to_octree()
            bar.update()
        bar.set_description(f"writing {output_path.name}")
        if project_2d is not None:
            written = " and ".join(map(str, tree.project_2d(
                *_check_band(project_2d)).save_ros_map(output_path)))
        else:
            written = str(output_path)
            _save(mapper, tree, output_path, entry.formats)
        bar.update()
    finally:
        bar.close()
    wall = time.perf_counter() - t_start
    for path, n, total in dropped:
        print(f"dropped {n:,} of {total:,} points of {path} with a NaN or inf coordinate",
              file=out)
    if n_filtered:
        ground = f" ({n_free:,} ground points inserted as free)" if n_free else ""
        print(f"the scan filter took {n_filtered:,} of {n_points:,} points{ground}", file=out)
    if limit is not None and n_beyond:
        print(_beyond_message(mapper, how, n_beyond, n_points, limit, beams), file=out)
    if isinstance(mapper, OccupancyOctree):
        built = f"{mapper.num_leaves:,} leaves"
    elif convert:
        built = f"{mapper.num_cells:,} cells ({tree.num_leaves:,} octree leaves)"
    else:
        built = f"{mapper.num_cells:,} cells"
    start = f"{input_path} + " if input_path is not None else ""
    print(f"{start}{n_scans} scans, {n_points:,} points → {built}; inserted in "
          f"{seconds:.2f} s, wall time {wall:.2f} s; wrote {written}", file=out)
    return mapper


def _inserter(mapper, mode, max_range):
    """(insert(points, origin), the range limit whose points are counted or None, how the
    map meets it): "cut" (the map's own range parameter cuts rays), "param" (its
    ``max_range`` parameter), "option" (insert_scan's ``max_range`` cuts rays) or "drop"
    (the points beyond are not passed)."""
    options = _insert_options(type(mapper))
    params = mapper.get_params()
    kwargs: dict[str, Any] = {}
    if mode is not None:
        kwargs["mode"] = mode
    elif "mode" in options:
        kwargs["mode"] = "scan"
    if getattr(type(mapper), "RANGE_PARAM", None) in params:    # KNNMap: it cuts rays
        limit, how = params[type(mapper).RANGE_PARAM], "cut"
    elif "max_range" in params:
        limit, how = params["max_range"], "param"
    elif max_range is not None and "max_range" in options:
        kwargs["max_range"] = max_range
        limit, how = max_range, "option"
    else:
        limit, how = max_range, "drop"

    def insert(points, origin, free_points=None):
        if free_points is None:
            mapper.insert_scan(points, origin, **kwargs)
        else:
            mapper.insert_scan(points, origin, free_points=free_points, **kwargs)
    return insert, limit, how


def _check_scan_filter(scan_filter, method: str) -> None:
    """map_scans' `scan_filter`, checked (on an empty scan) before any file is read."""
    if scan_filter is None:
        return
    from ..filters import ScanFilter
    if not isinstance(scan_filter, ScanFilter):
        raise TypeError(f"scan_filter must be an occgp.filters.ScanFilter, got "
                        f"{type(scan_filter).__name__}")
    try:
        scan_filter.masks(np.empty((0, 3)), np.zeros(3))
    except ValueError as exc:
        raise OptionError("scan_filter", str(exc)) from None
    if scan_filter.ground == "free" and "free_points" not in _insert_options(
            map_type(method).cls):
        takers = [repr(n) for n in map_methods()
                  if "free_points" in _insert_options(map_type(n).cls)]
        raise OptionError("scan_filter", f"ground='free' needs a map whose insert_scan takes "
                          f"free_points ({_either(takers, ' or ')}), got method={method!r}; "
                          f"use ground='drop'")


def _beyond_message(mapper, how, n, total, limit, beams) -> str:
    where = f"{n:,} of {total:,} points lie beyond"
    if how == "option":
        return f"{where} max_range {limit:g} m: their rays were cut there (free space only)"
    if how == "cut":
        return (f"{where} {type(mapper).RANGE_PARAM} {limit:g} m: not inserted, their rays "
                f"were cut there")
    name = type(mapper).__name__
    cut = getattr(mapper, "far_beams", None) == "cut"
    if how == "param" and hasattr(mapper, "last_beams_"):
        kept, beyond = (int(b) for b in beams)
        return (f"{where} max_range {limit:g} m: {name.removesuffix('Map')} "
                f"{'cut' if cut else 'dropped'} {beyond:,} of its {kept + beyond:,} beams "
                f"(to the end points' centroids per cube of ds_resolution) "
                + ("there (free space only)" if cut else "beyond it"))
    if how == "param" and cut:
        return f"{where} max_range {limit:g} m: {name} cut their beams there (free space only)"
    if how == "param":
        return f"{where} max_range {limit:g} m: {name} dropped them"
    return f"{where} max_range {limit:g} m: dropped ({name} got only the nearer ones)"


def _save(mapper, tree, output: Path, formats) -> None:
    suffix = _suffix(output)
    if suffix in formats:
        mapper.save(output)
    elif suffix == ".ply":
        tree.save_ply(output)
    elif suffix == ".pcd":
        tree.save_pcd(output)
    else:
        tree.save(output, format=suffix[1:])
