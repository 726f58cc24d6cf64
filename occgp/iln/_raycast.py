"""Exact range images of scenes of analytic solids, ray cast one ray per pixel center.

:func:`simulate_range_image` (re-exported by :mod:`occgp.iln.data` and
:mod:`occgp.iln`) culls each solid to the block of pixels its angular extent
covers and intersects only those rays with it.
"""

from __future__ import annotations

import numpy as np

from .._validation import check_bool
from ..datasets._geometry import Box, Ellipsoid, Frustum, first_hit
from ._common import as_pose
from ._range import LidarModel

__all__ = ["simulate_range_image"]


# --------------------------------------------------------------------------- #
# ray casting
# --------------------------------------------------------------------------- #
def _interval(lo, hi, n, start, step):
    """Indices k in [0, n) with ``start + (k + 0.5) * step`` in [lo, hi] (step may be < 0)."""
    a = (lo - start) / step - 0.5
    b = (hi - start) / step - 0.5
    a, b = min(a, b), max(a, b)
    return int(np.ceil(a - 1e-9)), int(np.floor(b + 1e-9))


def _angular_boxes(lo, hi):
    """Conservative elevation ranges and azimuth arcs (degrees) of sensor-frame AABBs.

    `lo`, `hi`: (n, 3). Returns elev_lo, elev_hi, az_lo, az_hi (each (n,), az_hi - az_lo
    <= 360) and `around` (n,), True where the box surrounds the z axis (no arc).
    """
    x, y = np.stack([lo[:, 0], hi[:, 0]], 1), np.stack([lo[:, 1], hi[:, 1]], 1)
    near = np.hypot(np.clip(0.0, lo[:, 0], hi[:, 0]), np.clip(0.0, lo[:, 1], hi[:, 1]))
    far = np.hypot(np.abs(x).max(axis=1), np.abs(y).max(axis=1))
    e_hi = np.degrees(np.arctan2(hi[:, 2], np.where(hi[:, 2] > 0, near, far)))
    e_lo = np.degrees(np.arctan2(lo[:, 2], np.where(lo[:, 2] > 0, far, near)))
    around = (lo[:, 0] <= 0.0) & (hi[:, 0] >= 0.0) & (lo[:, 1] <= 0.0) & (hi[:, 1] >= 0.0)
    center = np.degrees(np.arctan2((lo[:, 1] + hi[:, 1]) / 2, (lo[:, 0] + hi[:, 0]) / 2))
    corners = np.degrees(np.arctan2(np.repeat(y, 2, axis=1), np.tile(x, 2)))
    delta = (corners - center[:, None] + 180.0) % 360.0 - 180.0
    return e_lo, e_hi, center + delta.min(axis=1), center + delta.max(axis=1), around


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


#: Corner selectors of a box: corner k takes the high bound where ``_HIGH[k]`` is True.
_HIGH = np.array(np.meshgrid([False, True], [False, True], [False, True],
                             indexing="ij")).reshape(3, -1).T
_SIGNS = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T


def _world_boxes(solids):
    """World AABBs ``(lo (n, 3), hi (n, 3))`` of `solids`, the occgp primitives' computed
    together (as their ``aabb``: local box corners rotated into the world frame)."""
    lo, hi = np.empty((len(solids), 3)), np.empty((len(solids), 3))
    prim = [k for k, s in enumerate(solids) if type(s) in (Box, Ellipsoid, Frustum)]
    for k, s in enumerate(solids):
        if type(s) not in (Box, Ellipsoid, Frustum):
            lo[k], hi[k] = s.aabb
    if prim:
        half, offset = np.empty((len(prim), 3)), np.zeros((len(prim), 3))
        for row, k in enumerate(prim):
            s = solids[k]
            if type(s) is Box:
                half[row] = s.half_extents
            elif type(s) is Ellipsoid:
                half[row] = s.radii
            else:
                r = max(s.radius_bottom, s.radius_top)
                half[row] = (r, r, s.height / 2)
                offset[row, 2] = s.height / 2
        rot = np.stack([solids[k].rotation for k in prim])
        center = np.stack([solids[k].center for k in prim])
        local = _SIGNS[None] * half[:, None] + offset[:, None]
        world = np.einsum("nkj,nij->nki", local, rot) + center[:, None]
        lo[prim], hi[prim] = world.min(axis=1), world.max(axis=1)
    return lo, hi


def _cropped_columns(arc, model):
    """Columns (j0, j1) of a cropped model whose centers may lie in the azimuth arc."""
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


def simulate_range_image(scene, pose, model: LidarModel, *, return_ids: bool = False):
    """Ray cast a range image of `scene` from `pose`, one ray per pixel center, exactly.

    Each solid is first culled to the block of pixels its (conservative)
    angular extent covers as seen from the sensor, and only those rays are
    intersected with it; the result equals ``scene.ray_cast`` over every
    pixel-center direction (first hit, up to ``model.max_range``).

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
    return_ids : bool, default=False
        Also return the index of the solid each pixel's ray hits (in
        ``scene.solids``), e.g. for its reflectivity
        (:func:`~occgp.iln.solid_reflectivity`); needs a scene of solids.

    Returns
    -------
    image : ndarray of shape (model.rows, model.cols), dtype float32
        Ranges in metres, 0.0 where the ray hits nothing within
        ``model.max_range`` (a sensor inside a solid sees range 0 too).
    ids : ndarray of shape (model.rows, model.cols), dtype int64
        Only with `return_ids`: the index of the solid hit first (of the
        lowest index where several solids meet at that range), -1 where
        `image` is 0.

    Raises
    ------
    TypeError
        If `model` is not a LidarModel, `scene` can neither list solids nor
        cast rays, `pose` does not hold real numbers, or `return_ids` is
        not a bool.
    ValueError
        If `pose` is not (4, 4) nor an (origin, heading) pair, not finite,
        not rigid, or translated by more than 1e7 m; or `return_ids` is
        True for a scene that does not list analytic solids.

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
    return_ids = check_bool(return_ids, "return_ids")
    pose = as_pose(pose)
    rot, origin = pose[:3, :3], pose[:3, 3]
    # np.dot: numpy's matmul is several times slower for (n, 3) x (3, 3)
    dirs = np.dot(model.directions(), rot.T)  # (rows, cols, 3) in the world frame
    solids = getattr(scene, "solids", None)
    if solids is None or not all(hasattr(s, "aabb") and hasattr(s, "intersect") for s in solids):
        if not callable(getattr(scene, "ray_cast", None)):
            raise TypeError(f"scene must list analytic solids or have a ray_cast method, got "
                            f"{type(scene).__name__}")
        if return_ids:
            raise ValueError(f"return_ids=True needs a scene that lists analytic solids, got "
                             f"{type(scene).__name__}")
        dist, hit = scene.ray_cast(origin, dirs.reshape(-1, 3), model.max_range)
        image = np.where(hit, dist, 0.0).reshape(model.shape)
        return image.astype(np.float32)
    t = np.full(model.shape, np.inf)
    ids = np.full(model.shape, -1, dtype=np.int64) if return_ids else None
    low, high = model.vertical_fov
    h = model.horizontal_fov
    boxes_lo, boxes_hi = _world_boxes(solids)
    # a per-beam table, negated to increase with the row
    table = None if model.beam_elevations is None else -np.asarray(model.beam_elevations)
    corners = np.where(_HIGH[None], boxes_hi[:, None], boxes_lo[:, None])  # (n, 8, 3)
    local = np.dot(corners - origin, rot)  # sensor frame
    lo, hi = local.min(axis=1), local.max(axis=1)
    in_range = np.linalg.norm(np.clip(0.0, lo, hi), axis=1) <= model.max_range
    elev_lo, elev_hi, az_lo, az_hi, around = _angular_boxes(lo, hi)
    for index, solid in enumerate(solids):
        if not in_range[index]:
            continue
        e_lo, e_hi = elev_lo[index], elev_hi[index]
        arc = None if around[index] else (az_lo[index], az_hi[index])
        if table is None:
            i0, i1 = _interval(e_lo, e_hi, model.rows, high, -(high - low) / model.rows)
        else:  # the rows whose beams' elevations lie in [e_lo, e_hi] (1e-9 degree margin)
            i0 = int(np.searchsorted(table, -(e_hi + 1e-9), side="left"))
            i1 = int(np.searchsorted(table, -(e_lo - 1e-9), side="right")) - 1
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
        if ids is not None:
            _record_ids(ids, t, rows, cols, hit, index)
        if isinstance(cols, slice):
            np.minimum(t[rows, cols], hit, out=t[rows, cols])
        else:
            t[rows, cols] = np.minimum(t[rows, cols], hit)
    image = np.where(t <= model.max_range, t, 0.0)
    if ids is None:
        return image.astype(np.float32)
    ids[image == 0.0] = -1
    return image.astype(np.float32), ids


def _record_ids(ids, t, rows, cols, hit, index):
    """Set `ids` to `index` in the block where `hit` is nearer than the ranges `t` so far."""
    if isinstance(cols, slice):
        closer = hit < t[rows, cols]
        ids[rows, cols][closer] = index
    else:
        closer = hit < t[rows][:, cols]
        sub = ids[rows][:, cols]
        sub[closer] = index
        ids[rows, cols] = sub
