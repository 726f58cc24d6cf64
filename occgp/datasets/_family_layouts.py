"""Layouts of the 2D scene family: a warehouse, an open hall, a cluttered building.

Each builder takes a random generator and the size of the interior and returns a
:class:`Scene2D` (or the :class:`FloorPlan2D` it was given, refurnished) whose
solids are all rectangles and discs, with a closed or out-and-back robot path
that keeps :data:`CLEARANCE` from every solid. The path is laid out first (the
aisles, lanes and corridors it follows are free by construction); pillars,
free-standing walls and furniture are then placed clear of it.
"""

import numpy as np

from ._floorplan import FloorPlan2D, solid_outline
from ._scene2d import Circle, Rect, Scene2D, path_samples

__all__ = ["CLEARANCE", "warehouse_layout", "hall_layout", "furnish_densely",
           "outer_walls", "path_clearance"]

#: Smallest distance from the robot's path to any solid, metres.
CLEARANCE = 0.5
_PLACE = CLEARANCE + 0.05       # what a placed solid keeps from the path
_ATTEMPTS = 25                  # draws per placed object before it is left out


def outer_walls(width, height, t):
    """The four outer walls around the interior ``[-w/2, w/2] x [-h/2, h/2]``."""
    hx, hy = width / 2, height / 2
    solids = [Rect([-hx - t / 2, 0.0], [t / 2, hy + t]), Rect([hx + t / 2, 0.0], [t / 2, hy + t]),
              Rect([0.0, -hy - t / 2], [hx + t, t / 2]), Rect([0.0, hy + t / 2], [hx + t, t / 2])]
    return solids, ["outer_wall_-x", "outer_wall_+x", "outer_wall_-y", "outer_wall_+y"]


def path_clearance(solids, path):
    """Smallest distance from the polyline `path` (sampled every 0.05 m) to `solids`."""
    samples = path_samples(np.asarray(path, dtype=np.float64))
    return min(float(s.signed_distance(samples).min()) for s in solids)


def _clear_of(solid, samples, margin=_PLACE):
    return len(samples) == 0 or float(solid.signed_distance(samples).min()) >= margin


def _dedupe(path):
    path = np.asarray(path, dtype=np.float64)
    keep = np.concatenate([[True], np.any(np.abs(np.diff(path, axis=0)) > 1e-12, axis=1)])
    return path[keep]


# ------------------------------------------------------------------------ warehouse
def warehouse_layout(rng, width, height, t):
    """Rack rows along the longer side, aisles 1.5-3 m, cross aisles, pillars.

    Parameters
    ----------
    rng : numpy.random.Generator
    width, height : float
        Interior size, metres (at least 12 x 10).
    t : float
        Thickness of the outer walls.

    Returns
    -------
    scene : Scene2D
        Racks ``rack_<row>_<segment>``, pillars ``pillar_<i>``; the path sweeps every
        aisle in turn (a serpentine through the end bands) and returns to its start
        through a cross aisle (or along an end band) and the first aisle.
    """
    swap = height > width                   # racks run along the longer side (local u)
    U, V = (height, width) if swap else (width, height)
    b_lo, b_hi = rng.uniform(2.5, 3.0), rng.uniform(3.0, 4.5)   # end bands; b_hi: loading
    if rng.random() < 0.5:
        b_lo, b_hi = b_hi, b_lo
    u0, u1 = -U / 2 + b_lo, U / 2 - b_hi      # extent of the racks along u
    # rows across v: [wall rack], aisle, rack, aisle, rack, ..., aisle
    racks_v, aisles = [], []                  # (v_lo, v_hi) of racks; (center, width) of aisles
    v = -V / 2
    if rng.random() < 0.5:                    # a single-sided rack against the wall
        d = rng.uniform(0.5, 0.8)
        racks_v.append((v, v + d))
        v += d
    while True:
        a, d = rng.uniform(1.5, 3.0), rng.uniform(0.8, 1.3)
        if V / 2 - (v + a + d) < 1.5:
            break
        aisles.append((v + a / 2, a))
        racks_v.append((v + a, v + a + d))
        v += a + d
    rest = V / 2 - v                          # the last aisle, 1.5 m or more
    if rest >= 3.0 + 0.5 and rng.random() < 0.5:
        d = min(rng.uniform(0.5, 0.8), rest - 3.0)
        racks_v.append((V / 2 - d, V / 2))
        rest -= d
    aisles.append((v + rest / 2, rest))
    # cross aisles split every rack row into segments
    length = u1 - u0
    n_cross = int(length // rng.uniform(12.0, 18.0))
    cross = []                                # (center, width)
    if n_cross:
        widths = rng.uniform(2.0, 3.0, n_cross)
        seg = (length - widths.sum()) / (n_cross + 1)
        edge = u0
        for w in widths:
            lo = edge + seg * rng.uniform(0.85, 1.15)
            cross.append((lo + w / 2, w))
            edge = lo + w
    cuts = [u0] + [x for c, w in cross for x in (c - w / 2, c + w / 2)] + [u1]
    segments = list(zip(cuts[::2], cuts[1::2]))

    def world(p):                             # local (u, v) -> (x, y)
        p = np.asarray(p, dtype=np.float64)
        return p[..., ::-1] if swap else p

    def rect(cu, cv, hu, hv):
        return Rect(world([cu, cv]), world([hu, hv]))

    solids, labels = outer_walls(width, height, t)
    for r, (va, vb) in enumerate(racks_v):
        for s, (ua, ub) in enumerate(segments):
            solids.append(rect((ua + ub) / 2, (va + vb) / 2, (ub - ua) / 2, (vb - va) / 2))
            labels.append(f"rack_{r}_{s}")

    # the path: a serpentine through every aisle, back to the start
    ua, ub = -U / 2 + b_lo / 2, U / 2 - b_hi / 2
    path, at = [], ua
    for vc, _ in aisles:
        other = ub if at == ua else ua
        path += [[at, vc], [other, vc]]
        at = other
    v_first, v_last = aisles[0][0], aisles[-1][0]
    if cross:
        uc = cross[int(rng.integers(len(cross)))][0]
        path += [[uc, v_last], [uc, v_first], [ua, v_first]]
    else:
        path += [[at, v_first], [ua, v_first]]
    path = world(_dedupe(path))

    # pillars: at rack-row ends (in a cross aisle or an end band) or in the loading band
    samples = path_samples(path)
    n_pillars = int(rng.integers(2, 7))
    placed = 0
    for _ in range(_ATTEMPTS * n_pillars):
        if placed == n_pillars or not racks_v:
            break
        r = rng.uniform(0.2, 0.35)
        if rng.random() < 0.7:
            va, vb = racks_v[int(rng.integers(len(racks_v)))]
            end = cuts[int(rng.integers(len(cuts)))]
            side = 1.0 if end in cuts[1::2] else -1.0
            center = [end + side * r, (va + vb) / 2]
        else:
            lo_band = b_lo > b_hi
            band = (-U / 2 + r + 0.3, u0 - r - 0.3) if lo_band else (u1 + r + 0.3,
                                                                      U / 2 - r - 0.3)
            if band[1] <= band[0]:
                continue
            center = [rng.uniform(*band), rng.uniform(-V / 2 + r + 0.3, V / 2 - r - 0.3)]
        pillar = (Circle(world(center), r) if rng.random() < 0.5
                  else Rect(world(center), [r, r]))
        if _clear_of(pillar, samples):
            solids.append(pillar)
            labels.append(f"pillar_{placed}")
            placed += 1
    return Scene2D(solids, labels, ([-width / 2, -height / 2], [width / 2, height / 2]), t,
                   path)


# ----------------------------------------------------------------------------- hall
def hall_layout(rng, width, height, t):
    """An open hall: a jittered grid of round and square pillars, free-standing walls.

    Parameters
    ----------
    rng : numpy.random.Generator
    width, height : float
        Interior size, metres (at least 12 x 10).
    t : float
        Thickness of the outer and free-standing walls.

    Returns
    -------
    scene : Scene2D
        Pillars ``pillar_<i>``, walls ``wall_<i>``; the path sweeps the lanes between
        the pillar rows (a serpentine) and returns to its start along an end lane and
        the first lane.
    """
    margin = 3.0                              # pillar centers keep this far from the walls
    sx, sy = rng.uniform(4.0, 7.0, 2)
    nx = max(int((width - 2 * margin) // sx) + 1, 1)
    ny = max(int((height - 2 * margin) // sy) + 1, 1)
    xs = (np.arange(nx) - (nx - 1) / 2) * sx
    ys = (np.arange(ny) - (ny - 1) / 2) * sy
    solids, labels = outer_walls(width, height, t)
    pillars, reach = [], []
    for x in xs:
        for y in ys:
            if rng.random() < 0.1:
                continue                      # a missing pillar
            c = np.array([x, y]) + rng.uniform(-0.3, 0.3, 2)
            r = rng.uniform(0.15, 0.35)
            if rng.random() < 0.5:
                pillars.append(Circle(c, r))
                reach.append(r)
            else:
                angle = np.pi / 4 if rng.random() < 0.3 else 0.0
                pillars.append(Rect(c, [r, r], angle))
                reach.append(r * np.sqrt(2))
    solids += pillars
    labels += [f"pillar_{i}" for i in range(len(pillars))]

    # lanes midway between the pillar rows and between the walls and the outer rows
    bounds = np.concatenate([[-height / 2], ys, [height / 2]])
    lanes = (bounds[:-1] + bounds[1:]) / 2
    xa, xb = -width / 2 + 1.2, width / 2 - 1.2
    path, at = [], xa
    for y in lanes:
        other = xb if at == xa else xa
        path += [[at, y], [other, y]]
        at = other
    path += [[at, lanes[0]], [xa, lanes[0]]]
    path = _dedupe(path)

    # free-standing walls, clear of the path and of the pillars
    samples = path_samples(path)
    centers = np.array([p.center for p in pillars]).reshape(-1, 2)
    reach = np.asarray(reach)
    n_walls = int(rng.integers(2, 6))
    placed = 0
    for _ in range(_ATTEMPTS * n_walls):
        if placed == n_walls:
            break
        length = rng.uniform(2.0, 6.0)
        u = rng.random()
        angle = 0.0 if u < 0.4 else np.pi / 2 if u < 0.7 else rng.uniform(0, np.pi)
        c = rng.uniform([-width / 2 + 1.0, -height / 2 + 1.0],
                        [width / 2 - 1.0, height / 2 - 1.0])
        wall = Rect(c, [length / 2, t / 2], angle)
        lo, hi = wall.bounding_box()
        if np.any(lo < [-width / 2 + 0.3, -height / 2 + 0.3]) or \
                np.any(hi > [width / 2 - 0.3, height / 2 - 0.3]):
            continue
        if len(centers) and np.any(wall.signed_distance(centers) < reach + 0.3):
            continue
        if not _clear_of(wall, samples):
            continue
        solids.append(wall)
        labels.append(f"wall_{placed}")
        placed += 1
    return Scene2D(solids, labels, ([-width / 2, -height / 2], [width / 2, height / 2]), t,
                   path)


# ------------------------------------------------------------------------ cluttered
def _piece(rng):
    """One piece of furniture in its own frame: (kind, [(center, half or radius, angle)])."""
    u = rng.random()
    if u < 0.25:
        return "disc", [((0.0, 0.0), rng.uniform(0.2, 0.6), None)]
    if u < 0.5:
        return "box", [((0.0, 0.0), (rng.uniform(0.25, 0.9), rng.uniform(0.2, 0.6)), 0.0)]
    w = rng.uniform(0.2, 0.35)                # arm half-width
    if u < 0.7:                               # L: two arms sharing a corner
        a, b = rng.uniform(0.6, 1.1, 2)
        return "L", [((a - w, 0.0), (a, w), 0.0), ((0.0, b - w), (w, b), 0.0)]
    if u < 0.85:                              # T: a bar and a stem
        a, b = rng.uniform(0.6, 1.1), rng.uniform(0.4, 0.9)
        return "T", [((0.0, 0.0), (a, w), 0.0), ((0.0, -(b + w)), (w, b), 0.0)]
    k = int(rng.integers(2, 4))               # a cross or a six-pointed star
    a = rng.uniform(0.5, 0.9)
    return "star", [((0.0, 0.0), (a, w), np.pi * i / k) for i in range(k)]


def _place(parts, center, angle):
    c, s = np.cos(angle), np.sin(angle)
    rot = np.array([[c, -s], [s, c]])
    out = []
    for offset, size, a in parts:
        p = np.asarray(center) + rot @ np.asarray(offset)
        out.append(Circle(p, size) if a is None else Rect(p, size, a + angle))
    return out


def furnish_densely(rng, plan: FloorPlan2D) -> FloorPlan2D:
    """Fill every room of `plan` with many discs, boxes and L, T and star shapes.

    The pieces (unions of rotated rectangles, or discs) are placed clear of the path
    (by 0.55 m), of the doorways (by 0.6 m past their half-width), inside the room,
    and 0.25 m from one another.

    Parameters
    ----------
    rng : numpy.random.Generator
    plan : FloorPlan2D
        The building; its path and rooms are kept.

    Returns
    -------
    plan : FloorPlan2D
        A new building with the pieces added, labelled ``piece_<i>_<kind>_<part>``.
    """
    solids, labels = list(plan.solids), list(plan.labels)
    samples = path_samples(plan.path)
    door_center = plan.doorways.mean(axis=1)
    door_half = np.linalg.norm(plan.doorways[:, 1] - plan.doorways[:, 0], axis=1) / 2
    n_piece = 0
    for lo, hi in plan.rooms:
        near = np.all((samples >= lo - 1.0) & (samples <= hi + 1.0), axis=1)
        room_samples = samples[near]
        at_door = np.all((door_center >= lo - 1.0) & (door_center <= hi + 1.0), axis=1)
        doors, halves = door_center[at_door], door_half[at_door]
        area = float(np.prod(hi - lo))
        placed_parts, outlines = [], []
        for _ in range(min(int(area / rng.uniform(3.0, 5.0)), 25)):
            kind, parts = _piece(rng)
            for _ in range(_ATTEMPTS):
                cand = _place(parts, rng.uniform(lo, hi), rng.uniform(-np.pi, np.pi))
                boxes = np.array([s.bounding_box() for s in cand])
                if np.any(boxes[:, 0] < lo + 0.05) or np.any(boxes[:, 1] > hi - 0.05):
                    continue
                if not all(_clear_of(s, room_samples) for s in cand):
                    continue
                if len(doors) and any(np.any(s.signed_distance(doors) < halves + 0.6)
                                      for s in cand):
                    continue
                edge = np.vstack([solid_outline(s) for s in cand])
                if any(p.signed_distance(edge).min() < 0.25 for p in placed_parts) or \
                        any(s.signed_distance(o).min() < 0.25 for s in cand for o in outlines):
                    continue
                for i, s in enumerate(cand):
                    solids.append(s)
                    labels.append(f"piece_{n_piece}_{kind}_{i}")
                    placed_parts.append(s)
                    outlines.append(solid_outline(s))
                n_piece += 1
                break
    return FloorPlan2D(solids, labels, plan.interior_bounds, plan.wall_thickness, plan.path,
                       plan.rooms, plan.corridors, plan.doorways)
