"""Training data for occgp.iln: range images ray cast in procedural outdoor scenes.

:func:`simulate_range_image` casts one ray per pixel centre of a
:class:`~occgp.iln._range.LidarModel` into a scene made of analytic solids
(e.g. :func:`occgp.datasets.outdoor_scene`), exactly. :func:`make_dataset`
writes shards of such images, the same poses at several resolutions, and
:func:`load_shards` reads them back with strict checks.

Shard format (one compressed ``.npz`` per shard, in ``train/`` and
``test/`` subfolders):

===============  ====================================================
key              value
===============  ====================================================
``r16x1024`` ..  float32 ``(n, rows, cols)``: the images of each size
``lidar``        0-d str: JSON of the LidarModel fields but rows, cols
``seeds``        int64 ``(n,)``: the scene seed of each image
``poses``        float64 ``(n, 4, 4)``: sensor-to-world poses
``format``       0-d str ``"occgp.iln.shard"``
``version``      0-d int64, 1
===============  ====================================================

Train scenes have seeds ``0 .. n_train - 1``, test scenes ``100000 ..
100000 + n_test - 1``: the two never share a scene (``n_test`` is at most
100000 scenes). The `seed` of :func:`make_dataset` seeds the sensor poses
drawn in each scene.
"""

from __future__ import annotations

import functools
import logging
import os
import re
import zipfile
import zlib

import numpy as np
from numpy.typing import NDArray

from .._npz_io import read_npy_header
from .._validation import as_path, check_bool, check_int, check_n_jobs
from ..datasets._geometry import Box, Ellipsoid, Frustum, first_hit
from ._common import as_pose
from ._range import LidarModel

__all__ = ["simulate_range_image", "make_dataset", "load_shards", "parse_size", "ShardImages",
           "SIZES", "FORMAT", "VERSION", "TEST_SEED_OFFSET"]

logger = logging.getLogger("occgp")
logger.addHandler(logging.NullHandler())

FORMAT = "occgp.iln.shard"
VERSION = 1
#: Sizes (rows, cols) a shard may hold, as in the dissertation's CARLA data set.
SIZES = ((16, 1024), (64, 1024), (128, 2048), (256, 4096))
#: Test scenes' seeds start here (train scenes: 0 .. n_train - 1).
TEST_SEED_OFFSET = 100_000
_MAX_IMAGES = 1_000_000  # per shard
_MAX_SCENES = TEST_SEED_OFFSET
_SHARD_KEYS = ("lidar", "seeds", "poses", "format", "version")
_CHUNK = 8  # poses simulated per task of make_dataset
#: Most bytes of images one shard of make_dataset holds (uncompressed).
MAX_SHARD_BYTES = 2**31


def _key(size):
    return f"r{size[0]}x{size[1]}"


def parse_size(size) -> tuple:
    """``(rows, cols)`` of a size given as ``"16x1024"`` or a pair, checked against ``SIZES``.

    Parameters
    ----------
    size : str or pair of int
        ``"ROWSxCOLS"`` (``x`` or ``X``, surrounding spaces allowed), or ``(rows, cols)``.

    Returns
    -------
    size : tuple of two int
        ``(rows, cols)``, one of ``SIZES``.

    Raises
    ------
    ValueError
        If `size` is a str not of the form ``"ROWSxCOLS"``, a pair holds an int below 1, or
        the size is not one of ``SIZES`` (16x1024, 64x1024, 128x2048, 256x4096).
    TypeError
        If `size` is neither a str nor a pair, or a pair does not hold ints.
    """
    if isinstance(size, str):
        m = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", size)
        if not m:
            raise ValueError(f"size must look like '64x1024' (rows x cols), got {size!r}")
        pair = (int(m.group(1)), int(m.group(2)))
    else:
        try:
            rows, cols = size
        except (TypeError, ValueError):
            raise TypeError(f"size must be a str like '64x1024' or a (rows, cols) pair, got "
                            f"{type(size).__name__}") from None
        pair = (check_int(rows, "size rows", low=1), check_int(cols, "size cols", low=1))
    if pair not in SIZES:
        raise ValueError(f"size must be one of {', '.join('x'.join(map(str, s)) for s in SIZES)}, "
                         f"got {pair[0]}x{pair[1]}")
    return pair


def _parse_sizes(sizes, name="sizes"):
    if isinstance(sizes, str) or not hasattr(sizes, "__iter__"):
        raise TypeError(f"{name} must be a sequence of sizes like ['16x1024', '64x1024'], "
                        f"got {type(sizes).__name__}")
    out = [parse_size(s) for s in sizes]
    if not out:
        raise ValueError(f"{name} must name at least one size")
    if len(set(out)) != len(out):
        raise ValueError(f"{name} must not repeat a size, got {[_key(s)[1:] for s in out]}")
    return out


# --------------------------------------------------------------------------- #
# ray casting
# --------------------------------------------------------------------------- #
def _interval(lo, hi, n, start, step):
    """Indices k in [0, n) with ``start + (k + 0.5) * step`` in [lo, hi] (step may be < 0)."""
    a = (lo - start) / step - 0.5
    b = (hi - start) / step - 0.5
    a, b = min(a, b), max(a, b)
    return int(np.ceil(a - 1e-9)), int(np.floor(b + 1e-9))


def _angular_box(lo, hi):
    """Conservative elevation range and azimuth arc (degrees) of a sensor-frame AABB.

    Returns (elev_lo, elev_hi, az_lo, az_hi) with az_hi - az_lo <= 360, or
    None for the azimuth arc when the box surrounds the z axis.
    """
    dx = np.array([lo[0], hi[0]])
    dy = np.array([lo[1], hi[1]])
    near = np.hypot(np.clip(0.0, lo[0], hi[0]), np.clip(0.0, lo[1], hi[1]))
    far = np.hypot(np.abs(dx).max(), np.abs(dy).max())
    e_hi = np.degrees(np.arctan2(hi[2], near if hi[2] > 0 else far))
    e_lo = np.degrees(np.arctan2(lo[2], far if lo[2] > 0 else near))
    if lo[0] <= 0.0 <= hi[0] and lo[1] <= 0.0 <= hi[1]:
        return e_lo, e_hi, None
    cx, cy = (lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2
    centre = np.degrees(np.arctan2(cy, cx))
    corners = np.degrees(np.arctan2(np.repeat(dy, 2), np.tile(dx, 2)))
    delta = (corners - centre + 180.0) % 360.0 - 180.0
    return e_lo, e_hi, (centre + delta.min(), centre + delta.max())


def _intersect(solid, origin, directions):
    """``solid.intersect(origin, directions)`` for one origin; the occgp primitives take a
    faster path (np.dot into their frame, none for an unrotated solid)."""
    if not isinstance(solid, (Box, Ellipsoid, Frustum)):
        return solid.intersect(origin[None], directions)
    rot = solid.rotation
    o = ((origin - solid.center) @ rot)[None]
    d = directions if np.array_equal(rot, np.eye(3)) else np.dot(directions, rot)
    t0, t1 = solid._interval(o, d)
    return first_hit(t0, t1)


def _cropped_columns(arc, model):
    """Columns (j0, j1) of a cropped model whose centres may lie in the azimuth arc."""
    a, b = arc
    pieces = [(a, b)]
    if a < -180.0:
        pieces = [(a + 360.0, 180.0), (-180.0, b)]
    elif b > 180.0:
        pieces = [(a, 180.0), (-180.0, b - 360.0)]
    h = model.horizontal_fov
    j0, j1 = model.cols, -1
    for lo, hi in pieces:
        k0, k1 = _interval(lo, hi, model.cols, h / 2, -h / model.cols)
        k0, k1 = max(k0, 0), min(k1, model.cols - 1)
        if k0 <= k1:
            j0, j1 = min(j0, k0), max(j1, k1)
    return j0, j1


def simulate_range_image(scene, pose, model: LidarModel) -> NDArray[np.float32]:
    """Ray cast a range image of `scene` from `pose`, one ray per pixel centre, exactly.

    Each solid is first culled to the block of pixels its (conservative)
    angular extent covers as seen from the sensor, and only those rays are
    intersected with it; the result equals ``scene.ray_cast`` over every
    pixel-centre direction (first hit, up to ``model.max_range``).

    Parameters
    ----------
    scene : Scene
        A scene of analytic solids (``scene.solids``, each with ``aabb`` and
        ``intersect``), e.g. :func:`occgp.datasets.outdoor_scene` or a room;
        any other object with ``ray_cast(origins, directions, max_range)``
        is ray cast without culling.
    pose : array-like of shape (4, 4) or tuple (origin, heading)
        Sensor-to-world transform (rigid), or a level sensor at `origin`
        (3,) turned by `heading` radians about +z.
    model : LidarModel

    Returns
    -------
    image : ndarray of shape (model.rows, model.cols), dtype float32
        Ranges in metres, 0.0 where the ray hits nothing within
        ``model.max_range`` (a sensor inside a solid sees range 0 too).

    Raises
    ------
    TypeError
        If `model` is not a LidarModel, `scene` can neither list solids nor
        cast rays, or `pose` does not hold real numbers.
    ValueError
        If `pose` is not (4, 4) nor an (origin, heading) pair, not finite,
        not rigid, or translated by more than 1e7 m.

    Examples
    --------
    >>> from occgp.datasets import outdoor_scene
    >>> from occgp.iln._range import LidarModel
    >>> scene = outdoor_scene(0, size=40)
    >>> image = simulate_range_image(scene, scene.trajectory(1)[0], LidarModel.carla(16, 64))
    >>> image.shape, image.dtype, bool((image[-1] > 0).all())   # the ground all around
    ((16, 64), dtype('float32'), True)
    """
    if not isinstance(model, LidarModel):
        raise TypeError(f"model must be a LidarModel, got {type(model).__name__}")
    pose = as_pose(pose)
    rot, origin = pose[:3, :3], pose[:3, 3]
    # np.dot: numpy's matmul is several times slower for (n, 3) x (3, 3)
    dirs = np.dot(model.directions(), rot.T)  # (rows, cols, 3) in the world frame
    solids = getattr(scene, "solids", None)
    if solids is None or not all(hasattr(s, "aabb") and hasattr(s, "intersect") for s in solids):
        if not callable(getattr(scene, "ray_cast", None)):
            raise TypeError(f"scene must list analytic solids or have a ray_cast method, got "
                            f"{type(scene).__name__}")
        dist, hit = scene.ray_cast(origin, dirs.reshape(-1, 3), model.max_range)
        image = np.where(hit, dist, 0.0).reshape(model.shape)
        return image.astype(np.float32)
    t = np.full(model.shape, np.inf)
    low, high = model.vertical_fov
    h = model.horizontal_fov
    for solid in solids:
        lo_w, hi_w = solid.aabb
        corners = np.array(np.meshgrid(*zip(lo_w, hi_w), indexing="ij")).reshape(3, -1).T
        local = (corners - origin) @ rot  # sensor frame
        lo, hi = local.min(axis=0), local.max(axis=0)
        if np.linalg.norm(np.clip(0.0, lo, hi)) > model.max_range:
            continue
        e_lo, e_hi, arc = _angular_box(lo, hi)
        i0, i1 = _interval(e_lo, e_hi, model.rows, high, -(high - low) / model.rows)
        if model.beam_elevations is not None:  # rows not uniform: test them all
            i0, i1 = 0, model.rows - 1
        i0, i1 = max(i0, 0), min(i1, model.rows - 1)
        if i0 > i1:
            continue
        if arc is None:
            cols = slice(0, model.cols)
        else:
            j0, j1 = _interval(arc[0], arc[1], model.cols, h / 2, -h / model.cols)
            if model.full_circle:
                if j1 - j0 + 1 >= model.cols:
                    cols = slice(0, model.cols)
                else:
                    cols = np.arange(j0, j1 + 1) % model.cols
            else:
                j0, j1 = _cropped_columns(arc, model)
                if j0 > j1:
                    continue
                cols = slice(j0, j1 + 1)
        rows = slice(i0, i1 + 1)
        block = dirs[rows, cols] if isinstance(cols, slice) else dirs[rows][:, cols]
        hit = _intersect(solid, origin, block.reshape(-1, 3)).reshape(block.shape[:2])
        if isinstance(cols, slice):
            np.minimum(t[rows, cols], hit, out=t[rows, cols])
        else:
            t[rows, cols] = np.minimum(t[rows, cols], hit)
    image = np.where(t <= model.max_range, t, 0.0)
    return image.astype(np.float32)


# --------------------------------------------------------------------------- #
# shards
# --------------------------------------------------------------------------- #
def _pose_seed(seed, scene_seed):
    return int(np.random.SeedSequence([seed, scene_seed, 7177]).generate_state(1)[0])


@functools.lru_cache(maxsize=4)
def _scene_and_poses(scene_seed, n_images, pose_seed, scene_size):
    from ..datasets import outdoor_scene  # noqa: PLC0415 - datasets imports nothing of iln

    scene = outdoor_scene(scene_seed, size=scene_size)
    return scene, scene.random_poses(n_images, seed=pose_seed)


def _chunk_images(scene_seed, start, stop, n_images, seed, sizes, model, scene_size):
    """Images ``start:stop`` of the `n_images` poses of one scene: (key -> (k, rows, cols)
    float32, poses (k, 4, 4))."""
    scene, poses = _scene_and_poses(scene_seed, n_images, _pose_seed(seed, scene_seed),
                                    scene_size)
    poses = poses[start:stop]
    images = {_key(sz): np.stack([simulate_range_image(scene, p, model.with_size(*sz))
                                  for p in poses]) for sz in sizes}
    return images, poses


def _write_shard(path, images, seeds, poses, model):
    """Write one shard atomically (a temporary file renamed into place)."""
    tmp = path.with_name(path.name + ".tmp")
    payload = dict(images)
    payload.update(lidar=np.array(model.to_json()), seeds=np.asarray(seeds, dtype=np.int64),
                   poses=np.asarray(poses, dtype=np.float64), format=np.array(FORMAT),
                   version=np.array(VERSION, dtype=np.int64))
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **payload)
    os.replace(tmp, path)


def _check_progress(progress):
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be a bool or None, got {type(progress).__name__}")
    return None if progress is None or progress else True  # tqdm's disable


def make_dataset(folder, n_train: int, n_test: int, sizes=("16x1024", "64x1024"), *,
                 images_per_scene: int = 4, images_per_shard: int = 32, seed: int = 0,
                 model: LidarModel | None = None, scene_size: float = 80.0,
                 overwrite: bool = False, n_jobs: int | None = None,
                 progress: bool | None = True) -> dict:
    """Simulate range images in procedural outdoor scenes and write them as shards.

    For each scene (train seeds ``0 .. n_train - 1``, test seeds ``100000 +
    0 .. n_test - 1``, see :func:`occgp.datasets.outdoor_scene`),
    `images_per_scene` sensor poses are drawn on its roads
    (:meth:`~occgp.datasets.OutdoorScene.random_poses`, 1.73 m high) and each
    pose is ray cast (:func:`simulate_range_image`) at every size of `sizes`:
    the images of one pose at all sizes share the pose. Images are written
    in compressed ``.npz`` shards of up to `images_per_shard` images,
    ``FOLDER/train/shard_00000.npz``, ... and ``FOLDER/test/...``, in the
    format of the module docs. Each shard is written to a temporary file
    and renamed into place, so an interrupted run leaves no half-written
    shard. Nothing is downloaded.

    Parameters
    ----------
    folder : str or os.PathLike
        The dataset folder (created if missing).
    n_train, n_test : int
        Numbers of train and test scenes, 0 to 100,000 each (not both 0).
    sizes : sequence of str or (rows, cols), default=("16x1024", "64x1024")
        Any of 16x1024, 64x1024, 128x2048 and 256x4096 (the dissertation's
        CARLA resolutions), each once.
    images_per_scene : int, default=4
        Sensor poses per scene, 1 to 10,000.
    images_per_shard : int, default=32
        Most images (poses) in one shard, 1 to 1,000,000, and at most 2 GiB
        of images (uncompressed, all sizes; e.g. 405 poses at all four
        sizes). Memory use is about two shards' worth.
    seed : int, default=0
        Seeds the poses; the scenes are fixed by their seeds.
    model : LidarModel, optional
        The sensor's fields of view and range (its rows and cols are
        ignored); default :meth:`LidarModel.carla` (-15 to 15 degrees,
        360 degrees, 80 m).
    scene_size : float, default=80.0
        Side of each scene, metres (see :func:`occgp.datasets.outdoor_scene`).
    overwrite : bool, default=False
        Replace the shards of an earlier run in `folder` (they are deleted
        first); without it such shards raise ValueError.
    n_jobs : int, optional
        Scenes simulated in parallel through joblib (None: one at a time,
        unless a ``joblib.parallel_config`` says otherwise; -1: every
        core). The shards are the same whatever `n_jobs`.
    progress : bool or None, default=True
        Show a progress bar (tqdm; None: only on a terminal).

    Returns
    -------
    counts : dict
        ``{"train": images, "test": images, "shards": files written}``.

    Raises
    ------
    TypeError
        If an argument has a wrong type.
    ValueError
        If a count or size is out of range (a shard above 2 GiB included),
        a size is repeated or unknown, or `folder` already holds shards and
        `overwrite` is False.
    OSError
        If `folder` cannot be created or written.

    Examples
    --------
    >>> import tempfile
    >>> folder = tempfile.mkdtemp()
    >>> make_dataset(folder, 1, 1, sizes=["16x1024"], images_per_scene=1, progress=False)
    {'train': 1, 'test': 1, 'shards': 2}
    >>> load_shards(f"{folder}/train", ["16x1024"])["16x1024"].shape
    (1, 16, 1024)
    """
    from joblib import Parallel, delayed  # noqa: PLC0415
    from tqdm.auto import tqdm  # noqa: PLC0415

    from .._validation import check_real  # noqa: PLC0415

    folder = as_path(folder, "folder")
    n_train = check_int(n_train, "n_train", low=0, high=_MAX_SCENES)
    n_test = check_int(n_test, "n_test", low=0, high=_MAX_SCENES)
    if n_train + n_test == 0:
        raise ValueError("n_train and n_test must not both be 0")
    sizes = _parse_sizes(sizes)
    images_per_scene = check_int(images_per_scene, "images_per_scene", low=1, high=10_000)
    images_per_shard = check_int(images_per_shard, "images_per_shard", low=1, high=_MAX_IMAGES)
    seed = check_int(seed, "seed", low=0)
    model = LidarModel.carla() if model is None else model
    if not isinstance(model, LidarModel):
        raise TypeError(f"model must be a LidarModel or None, got {type(model).__name__}")
    scene_size = check_real(scene_size, "scene_size", low=30.0, high=400.0, low_open=False,
                            high_open=False)
    per_image = 4 * sum(r * c for r, c in sizes)
    if images_per_shard * per_image > MAX_SHARD_BYTES:
        raise ValueError(f"images_per_shard={images_per_shard} images of {per_image} bytes "
                         f"(all sizes) exceed {MAX_SHARD_BYTES} bytes per shard; use at most "
                         f"{MAX_SHARD_BYTES // per_image}")
    overwrite = check_bool(overwrite, "overwrite")
    n_jobs = check_n_jobs(n_jobs)
    disable = _check_progress(progress)
    splits = {"train": range(n_train), "test": range(TEST_SEED_OFFSET, TEST_SEED_OFFSET + n_test)}
    for split in splits:
        old = sorted((folder / split).glob("shard_*.npz")) if (folder / split).is_dir() else []
        if old and not overwrite:
            raise ValueError(f"{folder / split}: already holds {len(old)} shards; pass "
                             f"overwrite=True (--overwrite) to replace them")
    total = (n_train + n_test) * images_per_scene
    written = {"train": 0, "test": 0, "shards": 0}
    with tqdm(total=total, desc="range images", unit="img", disable=disable) as bar:
        for split, scene_seeds in splits.items():
            out = folder / split
            out.mkdir(parents=True, exist_ok=True)
            for old in out.glob("shard_*.npz"):
                old.unlink()
            buf_images = {_key(sz): [] for sz in sizes}
            buf_seeds, buf_poses = [], []
            index = 0

            def flush(out=out, split=split):
                nonlocal index, buf_seeds, buf_poses
                if not buf_seeds:
                    return
                images = {k: np.concatenate(v) for k, v in buf_images.items()}
                _write_shard(out / f"shard_{index:05d}.npz", images,
                             np.concatenate(buf_seeds), np.concatenate(buf_poses), model)
                written[split] += len(np.concatenate(buf_seeds))
                written["shards"] += 1
                index += 1
                for v in buf_images.values():
                    v.clear()
                buf_seeds, buf_poses = [], []

            tasks = [(scene_seed, a, min(a + _CHUNK, images_per_scene))
                     for scene_seed in scene_seeds for a in range(0, images_per_scene, _CHUNK)]
            results = Parallel(n_jobs=n_jobs, return_as="generator")(
                delayed(_chunk_images)(scene_seed, a, b, images_per_scene, seed, sizes, model,
                                       scene_size) for scene_seed, a, b in tasks)
            for (images, poses), (scene_seed, _, _) in zip(results, tasks):  # results first
                left, start = len(poses), 0
                while left:
                    room = images_per_shard - sum(len(s) for s in buf_seeds)
                    take = min(room, left)
                    for k in buf_images:
                        buf_images[k].append(images[k][start:start + take])
                    buf_seeds.append(np.full(take, scene_seed, dtype=np.int64))
                    buf_poses.append(poses[start:start + take])
                    start += take
                    left -= take
                    if sum(len(s) for s in buf_seeds) == images_per_shard:
                        flush()
                bar.update(len(poses))
            flush()
    logger.info("make_dataset: wrote %d train and %d test images in %d shards to %s",
                written["train"], written["test"], written["shards"], folder)
    return written


class ShardImages(dict):
    """The images of :func:`load_shards`: ``(rows, cols) -> array``, also indexed by ``"64x1024"``."""

    def __getitem__(self, size):
        return super().__getitem__(size if isinstance(size, tuple) and size in self
                                   else parse_size(size))

    def __contains__(self, size):
        try:
            return super().__contains__(size if isinstance(size, tuple) else parse_size(size))
        except (TypeError, ValueError):
            return False

    def get(self, size, default=None):
        """The images of `size`, or `default` when that size was not loaded (or is no size).

        Parameters
        ----------
        size : str or pair of int
            ``"64x1024"`` or ``(64, 1024)``, as :func:`parse_size` reads it.
        default : object, default=None
            Returned when `size` is not a key (a malformed or unknown size included).

        Returns
        -------
        images : ndarray of float32, shape (n_images, rows, cols), or `default`
        """
        return self[size] if size in self else default


def _read_member(zf, name, path, check):
    """Read one ``.npy`` member of a shard, checking its header with `check` first."""
    try:
        with zf.open(name + ".npy") as fh:
            shape, fortran, dtype = read_npy_header(fh)
            check(shape, dtype)
            count = int(np.prod(shape, dtype=np.int64))
            if count * dtype.itemsize > zf.getinfo(name + ".npy").file_size:
                raise ValueError(f"{name} is truncated: its header declares {shape} {dtype}")
            data = fh.read(count * dtype.itemsize)
            if len(data) != count * dtype.itemsize:
                raise ValueError(f"{name} is truncated")
            arr = np.frombuffer(data, dtype=dtype)
            return arr.reshape(shape, order="F" if fortran else "C")
    except ValueError as exc:
        raise ValueError(f"{path}: not a valid occgp.iln shard: {exc}") from None
    except (zipfile.BadZipFile, zlib.error, EOFError, KeyError, OSError) as exc:
        raise ValueError(f"{path}: not a valid occgp.iln shard: cannot read {name!r} "
                         f"({type(exc).__name__}: {exc})") from None


def _expect(name, shape_of, dtype_of):
    def check(shape, dtype):
        if dtype.hasobject or dtype != np.dtype(dtype_of):
            raise ValueError(f"{name} must have dtype {np.dtype(dtype_of)}, got {dtype}")
        if not shape_of(shape):
            raise ValueError(f"{name} has a wrong shape {shape}")
    return check


def _read_shard(path, sizes):
    try:
        zf = zipfile.ZipFile(path)
    except zipfile.BadZipFile:
        raise ValueError(f"{path}: not a valid occgp.iln shard (not a .npz / zip file)") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: not a valid occgp.iln shard (a directory)") from None
    with zf:
        members = {n[:-4] for n in zf.namelist() if n.endswith(".npy")}
        missing = [k for k in _SHARD_KEYS if k not in members]
        if missing:
            raise ValueError(f"{path}: not a valid occgp.iln shard: missing {missing}")

        def is_str(what, longest):
            def check(shape, dtype):
                if dtype.kind != "U" or shape != () or dtype.itemsize > 4 * longest:
                    raise ValueError(f"{what} must be a 0-d str, got {dtype} of shape {shape}")
            return check
        fmt = _read_member(zf, "format", path, is_str("format", 64))
        if fmt.item() != FORMAT:
            raise ValueError(f"{path}: not a valid occgp.iln shard: format is {fmt.item()!r}, "
                             f"expected {FORMAT!r}")
        version = _read_member(zf, "version", path, _expect("version", lambda s: s == (), "<i8"))
        if int(version.item()) != VERSION:
            raise ValueError(f"{path}: occgp.iln shard version {int(version.item())} is not "
                             f"supported (this occgp reads version {VERSION})")
        lidar = str(_read_member(zf, "lidar", path, is_str("lidar", 4096)).item())
        n_holder = []

        def n_of(shape, dtype):
            if dtype != np.dtype("<i8") or len(shape) != 1 or not 1 <= shape[0] <= _MAX_IMAGES:
                raise ValueError(f"seeds must be int64 of shape (n,), 1 <= n <= {_MAX_IMAGES}, "
                                 f"got {dtype} of shape {shape}")
            n_holder.append(shape[0])
        seeds = _read_member(zf, "seeds", path, n_of)
        n = n_holder[0]
        poses = _read_member(zf, "poses", path,
                             _expect("poses", lambda s: s == (n, 4, 4), "<f8"))
        if not np.isfinite(poses).all():
            raise ValueError(f"{path}: not a valid occgp.iln shard: poses hold NaN or inf")
        have = sorted(m for m in members if re.fullmatch(r"r\d+x\d+", m))
        images = {}
        for size in sizes:
            key = _key(size)
            if key not in members:
                raise ValueError(f"{path}: the shard has no {key[1:]} images (it has "
                                 f"{', '.join(h[1:] for h in have) or 'none'})")
            arr = _read_member(zf, key, path,
                               _expect(key, lambda s, size=size: s == (n, *size), "<f4"))
            images[size] = arr
    try:
        model = LidarModel.from_json(lidar, 1, 1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: not a valid occgp.iln shard: lidar: {exc}") from None
    limit = np.float32(model.max_range)
    for size, arr in images.items():
        if not (np.isfinite(arr).all() and (arr >= 0).all() and (arr <= limit).all()):
            raise ValueError(f"{path}: not a valid occgp.iln shard: {_key(size)[1:]} images "
                             f"must be finite ranges in [0, {model.max_range}]")
    return images, seeds, poses, lidar, model


def load_shards(folder, sizes, *, return_meta: bool = False):
    """Read the shards of a :func:`make_dataset` split folder, checking every entry.

    Parameters
    ----------
    folder : str or os.PathLike
        A folder of ``shard_*.npz`` files: ``FOLDER/train`` or
        ``FOLDER/test`` of :func:`make_dataset` (every ``*.npz`` in it is
        read, in name order).
    sizes : sequence of str or (rows, cols)
        The sizes to read, e.g. ``["16x1024", "64x1024"]``.
    return_meta : bool, default=False
        Also return the scene seeds, poses and sensor model.

    Returns
    -------
    images : ShardImages
        ``(rows, cols) -> float32 array (n, rows, cols)`` for each size, in
        shard order; also indexed by ``"16x1024"``-style strings.
    meta : dict
        Only if `return_meta`: ``"seeds"`` int64 (n,), ``"poses"`` float64
        (n, 4, 4), ``"model"`` the :class:`LidarModel` (rows and cols those
        of the first size).

    Raises
    ------
    ValueError
        Naming the file, for a file that is not an occgp.iln shard (not a
        zip, a missing or wrongly typed or shaped entry, a foreign
        ``format``, another ``version``, ranges that are NaN, negative or
        beyond the sensor's range), a shard lacking a requested size,
        shards of different sensors; and for a folder without ``.npz``
        files (naming its ``train`` / ``test`` subfolders if it has them),
        or bad `sizes`.
    OSError
        If `folder` does not exist or is not a directory.
    TypeError
        If an argument has a wrong type.

    Examples
    --------
    >>> import tempfile
    >>> folder = tempfile.mkdtemp()
    >>> _ = make_dataset(folder, 1, 0, sizes=["16x1024"], images_per_scene=2, progress=False)
    >>> images, meta = load_shards(f"{folder}/train", ["16x1024"], return_meta=True)
    >>> images[(16, 1024)].shape, meta["seeds"].tolist(), meta["model"].max_range
    ((2, 16, 1024), [0, 0], 80.0)
    """
    folder = as_path(folder, "folder")
    sizes = _parse_sizes(sizes)
    return_meta = check_bool(return_meta, "return_meta")
    if not folder.exists():
        raise FileNotFoundError(2, "no such directory", str(folder))
    if not folder.is_dir():
        raise NotADirectoryError(20, "expected a directory of shards", str(folder))
    files = sorted(p for p in folder.glob("*.npz"))
    if not files:
        subs = [s for s in ("train", "test") if (folder / s).is_dir()]
        hint = f"; read {' or '.join(str(folder / s) for s in subs)}" if subs else ""
        raise ValueError(f"{folder}: no .npz shards in the folder{hint}")
    parts = {size: [] for size in sizes}
    seeds, poses, lidar0, model0 = [], [], None, None
    for path in files:
        images, s, p, lidar, model = _read_shard(path, sizes)
        if lidar0 is None:
            lidar0, model0 = lidar, model
        elif model != model0:
            raise ValueError(f"{path}: its sensor {lidar} differs from that of {files[0]} "
                             f"({lidar0})")
        for size in sizes:
            parts[size].append(images[size])
        seeds.append(s)
        poses.append(p)
    out = ShardImages({size: np.concatenate(parts[size]) for size in sizes})
    if not return_meta:
        return out
    meta = {"seeds": np.concatenate(seeds), "poses": np.concatenate(poses),
            "model": model0.with_size(*sizes[0])}
    return out, meta
