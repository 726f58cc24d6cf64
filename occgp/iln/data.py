"""Training data for occgp.iln: range images ray cast in procedural outdoor scenes.

:func:`simulate_range_image` casts one ray per pixel center of a
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
``simulation``   optional 0-d str: JSON ``{"effects": ..., "vegetation":
                 ..., "beams": ...}``, written only by a non-default
                 simulation (see :func:`make_dataset`); a shard without
                 it holds exact images of scenes without vegetation
===============  ====================================================

Train scenes have seeds ``0 .. n_train - 1``, test scenes ``100000 ..
100000 + n_test - 1``: the two never share a scene (``n_test`` is at most
100000 scenes). The `seed` of :func:`make_dataset` seeds the sensor poses
drawn in each scene, and the sensor effects of each image.
"""

from __future__ import annotations

import functools
import json
import logging
import re
import zipfile
import zlib

import numpy as np

from .._atomic import atomic_open
from ..io._npz import read_npy_header
from .._validation import as_path, check_bool, check_int, check_n_jobs
from . import _effects
from ._range import LidarModel
from ._raycast import simulate_range_image
from .real import kept_beams_model

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
_RECORD_KEYS = ("effects", "vegetation", "beams")
#: The simulation record of a shard without one (exact images, no vegetation).
_PLAIN = {"effects": None, "vegetation": False}
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
# shards
# --------------------------------------------------------------------------- #
def _pose_seed(seed, scene_seed):
    return int(np.random.SeedSequence([seed, scene_seed, 7177]).generate_state(1)[0])


def _effects_seed(seed, scene_seed, image, size):
    """The seed of the sensor effects of image `image` (0-based in its scene) at `size`."""
    return np.random.SeedSequence([seed, scene_seed, image, size[0], size[1], 60013])


@functools.lru_cache(maxsize=4)
def _scene_and_poses(scene_seed, n_images, pose_seed, scene_size, vegetation=False):
    from ..datasets import outdoor_scene  # noqa: PLC0415 - datasets imports nothing of iln

    if vegetation:
        scene = outdoor_scene(scene_seed, size=scene_size, vegetation=True)
    else:
        scene = outdoor_scene(scene_seed, size=scene_size)
    return scene, scene.random_poses(n_images, seed=pose_seed)


def _size_models(model, sizes):
    """The sensor of each size, and the rows of `model`'s table each holds (None: no table).

    Without a per-beam table, each size is ``model.with_size``. With one, a size must have
    the table's rows (the full sensor) or ``table rows / k`` rows for an integer k >= 2
    (every k-th beam, :func:`~occgp.iln.kept_beams_model`)."""
    if model.beam_elevations is None:
        return [(model.with_size(*sz), None) for sz in sizes]
    out = []
    for rows, cols in sizes:
        full = model.with_size(model.rows, cols)
        if rows == model.rows:
            out.append((full, list(range(rows))))
        elif rows < model.rows and model.rows % rows == 0:
            kept_model, kept = kept_beams_model(full, model.rows // rows)
            out.append((kept_model, kept.tolist()))
        else:
            raise ValueError(f"sizes: {rows}x{cols} does not fit the model's {model.rows}-beam "
                             f"table: use {model.rows} rows (every beam) or {model.rows} / k "
                             f"rows for an integer k >= 2 (every k-th beam)")
    return out


def _chunk_images(scene_seed, start, stop, n_images, seed, sizes, models, scene_size,
                  effects=None, vegetation=False):
    """Images ``start:stop`` of the `n_images` poses of one scene: (key -> (k, rows, cols)
    float32, poses (k, 4, 4)); each size's clean image gets its own draw of `effects`."""
    scene, poses = _scene_and_poses(scene_seed, n_images, _pose_seed(seed, scene_seed),
                                    scene_size, vegetation)
    poses = poses[start:stop]
    if effects is None:
        images = {_key(sz): np.stack([simulate_range_image(scene, p, m) for p in poses])
                  for sz, m in zip(sizes, models)}
        return images, poses
    albedo = np.append(_effects.solid_reflectivity(scene.labels, scene_seed), 0.0)
    images = {}
    for sz, m in zip(sizes, models):
        out = []
        for k, p in enumerate(poses):
            clean, ids = simulate_range_image(scene, p, m, return_ids=True)
            rng = np.random.default_rng(_effects_seed(seed, scene_seed, start + k, sz))
            out.append(_effects.apply_sensor_effects(clean, m, effects, rng,
                                                     reflectivity=albedo[ids]))
        images[_key(sz)] = np.stack(out)
    return images, poses


def _write_shard(path, images, seeds, poses, model, record=None):
    """Write one shard atomically (see :mod:`occgp._atomic`)."""
    payload = dict(images)
    payload.update(lidar=np.array(model.to_json()), seeds=np.asarray(seeds, dtype=np.int64),
                   poses=np.asarray(poses, dtype=np.float64), format=np.array(FORMAT),
                   version=np.array(VERSION, dtype=np.int64))
    if record is not None:
        payload["simulation"] = np.array(json.dumps(record, sort_keys=True))
    with atomic_open(path) as fh:
        np.savez_compressed(fh, **payload)


def _check_progress(progress):
    if progress is not None and not isinstance(progress, (bool, np.bool_)):
        raise TypeError(f"progress must be a bool or None, got {type(progress).__name__}")
    return None if progress is None or progress else True  # tqdm's disable


def make_dataset(folder, n_train: int, n_test: int, sizes=("16x1024", "64x1024"), *,
                 images_per_scene: int = 4, images_per_shard: int = 32, seed: int = 0,
                 model: LidarModel | None = None, scene_size: float = 80.0,
                 overwrite: bool = False, n_jobs: int | None = None,
                 progress: bool | None = True, effects: _effects.SensorEffects | None = None,
                 vegetation: bool = False) -> dict:
    """Simulate range images in procedural outdoor scenes and write them as shards.

    For each scene (train seeds ``0 .. n_train - 1``, test seeds ``100000 +
    0 .. n_test - 1``, see :func:`occgp.datasets.outdoor_scene`),
    `images_per_scene` sensor poses are drawn on its roads
    (:meth:`~occgp.datasets.OutdoorScene.random_poses`, 1.73 m high) and each
    pose is ray cast (:func:`simulate_range_image`) at every size of `sizes`:
    the images of one pose at all sizes share the pose. Images are written
    in compressed ``.npz`` shards of up to `images_per_shard` images,
    ``FOLDER/train/shard_00000.npz``, ... and ``FOLDER/test/...``, in the
    format of the module docs. Each shard is written atomically (a temporary
    file beside it, synced and renamed into place), so an interrupted run
    leaves no half-written shard. Nothing is downloaded.

    The images are exact by default. With `effects` each size's clean
    image of each pose gets its own draw of the sensor effects
    (:func:`~occgp.iln.apply_sensor_effects`, with the reflectivity of the
    solid hit, :func:`~occgp.iln.solid_reflectivity` seeded by the scene),
    seeded by `seed`, the scene seed, the pose's index in its scene and the
    size: the shards are the same whatever `n_jobs`. With `vegetation`
    the scenes have vegetation clutter. A sensor with a per-beam table
    (e.g. ``LidarModel.hdl64e(table=True)``) gives the full table's rows
    for a size of its rows (64x1024) and every k-th beam for a size of
    ``rows / k`` rows (16x1024: every 4th beam, the real-frame protocol of
    :func:`~occgp.iln.kept_beams_model`), each at its beams' elevations.
    Such a simulation (effects, vegetation or a table) is recorded in each
    shard's ``simulation`` entry (:func:`load_shards` returns it).

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
        ignored, but for a per-beam table: see above); default
        :meth:`LidarModel.carla` (-15 to 15 degrees, 360 degrees, 80 m).
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
    effects : SensorEffects, optional
        Sensor effects (range noise, dropped returns) applied to each image;
        default None: exact images.
    vegetation : bool, default=False
        Scenes with vegetation clutter (``outdoor_scene(...,
        vegetation=True)``).

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
        a size is repeated or unknown or does not fit `model`'s per-beam
        table, or `folder` already holds shards and `overwrite` is False.
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
    if effects is not None and not isinstance(effects, _effects.SensorEffects):
        raise TypeError(f"effects must be a SensorEffects or None, got {type(effects).__name__}")
    vegetation = check_bool(vegetation, "vegetation")
    size_models = _size_models(model, sizes)
    record = None
    if effects is not None or vegetation or model.beam_elevations is not None:
        record = {"effects": None if effects is None else effects.as_dict(),
                  "vegetation": vegetation}
        if model.beam_elevations is not None:
            record["beams"] = {_key(sz)[1:]: beams
                               for sz, (_, beams) in zip(sizes, size_models)}
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
                             np.concatenate(buf_seeds), np.concatenate(buf_poses), model,
                             record)
                written[split] += len(np.concatenate(buf_seeds))
                written["shards"] += 1
                index += 1
                for v in buf_images.values():
                    v.clear()
                buf_seeds, buf_poses = [], []

            tasks = [(scene_seed, a, min(a + _CHUNK, images_per_scene))
                     for scene_seed in scene_seeds for a in range(0, images_per_scene, _CHUNK)]
            results = Parallel(n_jobs=n_jobs, return_as="generator")(
                delayed(_chunk_images)(scene_seed, a, b, images_per_scene, seed, sizes,
                                       [m for m, _ in size_models], scene_size, effects, vegetation)
                for scene_seed, a, b in tasks)
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
        record = None
        if "simulation" in members:
            record = str(_read_member(zf, "simulation", path,
                                      is_str("simulation", 1 << 16)).item())
    try:
        model = LidarModel.from_json(lidar, 1, 1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: not a valid occgp.iln shard: lidar: {exc}") from None
    try:
        record = _parse_record(record, _table_rows(lidar), sizes)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{path}: not a valid occgp.iln shard: simulation: {exc}") from None
    limit = np.float32(model.max_range)
    for size, arr in images.items():
        if not (np.isfinite(arr).all() and (arr >= 0).all() and (arr <= limit).all()):
            raise ValueError(f"{path}: not a valid occgp.iln shard: {_key(size)[1:]} images "
                             f"must be finite ranges in [0, {model.max_range}]")
    return images, seeds, poses, lidar, model, record


def _table_rows(lidar):
    """Beams of the per-beam table of the shard's ``lidar`` JSON (0: none)."""
    return len(json.loads(lidar).get("beam_elevations") or ())


def _parse_record(text, n_beams, sizes):
    """The simulation record of a shard (its JSON `text`, or None) as a dict with
    ``effects`` (SensorEffects or None), ``vegetation`` and ``beams`` (size key -> rows
    of the table, or None)."""
    if text is None:
        return {**_PLAIN, "beams": None}
    record = json.loads(text)
    if not isinstance(record, dict) or set(record) - set(_RECORD_KEYS) or \
            not {"effects", "vegetation"} <= set(record):
        raise ValueError(f"must be a JSON object with the keys effects, vegetation and "
                         f"optionally beams, got {text[:200]!r}")
    effects = record["effects"]
    effects = None if effects is None else _effects.SensorEffects.from_dict(effects)
    if not isinstance(record["vegetation"], bool):
        raise ValueError(f"vegetation must be true or false, got {record['vegetation']!r}")
    beams = record.get("beams")
    if beams is not None:
        if not n_beams or not isinstance(beams, dict):
            raise ValueError("beams must be an object of a sensor with a per-beam table")
        for key, rows in beams.items():
            if not (isinstance(rows, list) and rows and all(type(r) is int for r in rows)
                    and rows == sorted(set(rows)) and 0 <= rows[0]
                    and rows[-1] < n_beams):
                raise ValueError(f"beams[{key!r}] must list increasing rows of the "
                                 f"{n_beams}-beam table")
        for size in sizes:
            rows = beams.get(_key(size)[1:])
            if rows is None or len(rows) != size[0]:
                raise ValueError(f"beams must list the {size[0]} rows of the "
                                 f"{_key(size)[1:]} images")
    return {"effects": effects, "vegetation": record["vegetation"], "beams": beams}


def _size_model(lidar, size, beams):
    """The sensor of the images of `size` in shards of sensor JSON `lidar` and record
    ``beams``."""
    if beams is None:
        return LidarModel.from_json(lidar, *size)
    full = LidarModel.from_json(lidar, _table_rows(lidar), size[1])
    rows = beams[_key(size)[1:]]
    table = tuple(float(e) for e in full.elevations()[rows])
    return LidarModel(len(rows), size[1], full.vertical_fov, full.horizontal_fov,
                      full.max_range, table)


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
        (n, 4, 4), ``"model"`` the :class:`LidarModel` of the first size,
        ``"models"`` size -> LidarModel of each size (for a sensor with a
        per-beam table, the beams each size holds, see
        :func:`make_dataset`), ``"effects"`` the :class:`SensorEffects` of
        the images (None: exact images) and ``"vegetation"`` (bool).

    Raises
    ------
    ValueError
        Naming the file, for a file that is not an occgp.iln shard (not a
        zip, a missing or wrongly typed or shaped entry, a foreign
        ``format``, another ``version``, ranges that are NaN, negative or
        beyond the sensor's range, a malformed ``simulation`` record), a
        shard lacking a requested size, shards of different sensors or
        simulations; and for a folder without ``.npz``
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
    seeds, poses, lidar0, model0, record0 = [], [], None, None, None
    for path in files:
        images, s, p, lidar, model, record = _read_shard(path, sizes)
        if lidar0 is None:
            lidar0, model0, record0 = lidar, model, record
        elif model != model0:
            raise ValueError(f"{path}: its sensor {lidar} differs from that of {files[0]} "
                             f"({lidar0})")
        elif record != record0:
            raise ValueError(f"{path}: its simulation {record} differs from that of "
                             f"{files[0]} ({record0})")
        for size in sizes:
            parts[size].append(images[size])
        seeds.append(s)
        poses.append(p)
    out = ShardImages({size: np.concatenate(parts[size]) for size in sizes})
    if not return_meta:
        return out
    models = {size: _size_model(lidar0, size, record0["beams"]) for size in sizes}
    meta = {"seeds": np.concatenate(seeds), "poses": np.concatenate(poses),
            "model": models[sizes[0]], "models": models, "effects": record0["effects"],
            "vegetation": record0["vegetation"]}
    return out, meta
