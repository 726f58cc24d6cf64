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

Train scenes have seeds ``0 .. n_train - 1`` (plus `seed` times
``SEED_STRIDE``), test scenes ``100000 + ...``: the two never share a scene.
"""

from __future__ import annotations

import json
import logging
import os
import re
import zipfile
import zlib

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_numeric, as_path, check_bool, check_int
from ._range import LidarModel

__all__ = ["simulate_range_image", "make_dataset", "load_shards", "parse_size", "SIZES",
           "FORMAT", "VERSION", "TEST_SEED_OFFSET"]

logger = logging.getLogger("occgp")
logger.addHandler(logging.NullHandler())

FORMAT = "occgp.iln.shard"
VERSION = 1
#: Sizes (rows, cols) a shard may hold, as in the dissertation's CARLA data set.
SIZES = ((16, 1024), (64, 1024), (128, 2048), (256, 4096))
#: Test scenes' seeds start here (train scenes: 0 .. n_train - 1).
TEST_SEED_OFFSET = 100_000
#: make_dataset(seed=s) shifts every scene seed by s * SEED_STRIDE.
SEED_STRIDE = 1_000_000
_MAX_IMAGES = 1_000_000
_ORTHO_TOL = 1e-6


def _key(size):
    return f"r{size[0]}x{size[1]}"


def parse_size(size) -> tuple:
    """``(rows, cols)`` of a size given as ``"16x1024"`` or a pair, checked against ``SIZES``.

    Raises
    ------
    ValueError
        If `size` is not one of ``SIZES`` (16x1024, 64x1024, 128x2048, 256x4096).
    TypeError
        If `size` is neither a str nor a pair of ints.
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
def _as_pose(pose):
    """A checked (4, 4) sensor-to-world pose from a 4x4 array or (origin, heading)."""
    if isinstance(pose, tuple) and len(pose) == 2:
        origin = as_numeric(pose[0], "pose origin")
        if origin.shape != (3,):
            raise ValueError(f"pose origin must have shape (3,), got {origin.shape}")
        heading = pose[1]
        if isinstance(heading, (bool, np.bool_)) or not np.isscalar(heading) or \
                not isinstance(heading, (int, float, np.integer, np.floating)):
            raise TypeError(f"pose heading must be a real number (radians), got "
                            f"{type(heading).__name__}")
        origin = origin.astype(np.float64)
        heading = float(heading)
        if not (np.isfinite(origin).all() and np.isfinite(heading)):
            raise ValueError("pose origin and heading must be finite")
        c, s = np.cos(heading), np.sin(heading)
        out = np.eye(4)
        out[:2, :2] = [[c, -s], [s, c]]
        out[:3, 3] = origin
    else:
        out = as_numeric(pose, "pose")
        if out.shape != (4, 4):
            raise ValueError(f"pose must be a (4, 4) sensor-to-world matrix or an "
                             f"(origin, heading) pair, got shape {out.shape}")
        out = out.astype(np.float64)
        if not np.isfinite(out).all():
            raise ValueError("pose must be finite (no NaN or inf)")
        rot = out[:3, :3]
        if not (np.allclose(out[3], [0, 0, 0, 1], atol=0, rtol=0)
                and np.abs(rot @ rot.T - np.eye(3)).max() <= _ORTHO_TOL
                and np.linalg.det(rot) > 0):
            raise ValueError("pose must be a rigid transform: an orthonormal rotation with "
                             "determinant 1 (to 1e-6) and last row [0, 0, 0, 1]")
    if np.abs(out[:3, 3]).max() > 1e7:
        raise ValueError(f"pose translation must have coordinates of magnitude at most 1e7 m, "
                         f"got {out[:3, 3].tolist()}")
    return out


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
    pose = _as_pose(pose)
    rot, origin = pose[:3, :3], pose[:3, 3]
    dirs = model.directions() @ rot.T  # (rows, cols, 3) in the world frame
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
        if isinstance(cols, slice):
            block = dirs[rows, cols]
            shape = block.shape[:2]
            hit = solid.intersect(origin[None], block.reshape(-1, 3)).reshape(shape)
            np.minimum(t[rows, cols], hit, out=t[rows, cols])
        else:
            block = dirs[rows][:, cols]
            shape = block.shape[:2]
            hit = solid.intersect(origin[None], block.reshape(-1, 3)).reshape(shape)
            t[rows, cols] = np.minimum(t[rows, cols], hit)
    image = np.where(t <= model.max_range, t, 0.0)
    return image.astype(np.float32)
