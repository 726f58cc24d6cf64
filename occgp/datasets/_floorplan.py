"""A large 2D floor plan of rooms and corridors, for scaling studies.

:func:`floor_plan_2d` builds a seeded building (60 x 40 m by default) of
rooms, corridors, doorways and furniture out of the rectangles and discs of
:class:`Scene2D`, so that occupancy, signed distance and ray casting are exact,
with a robot path through every room. It is the large scene of the mixture of
GP experts' scaling study: the default laser (17 beams over 180 degrees, 8 m)
along a few hundred poses of the path gives 10,000 to 20,000 observations.
"""

import numpy as np

from .._validation import check_int, check_real
from ._scene2d import Scene2D, Circle, path_samples, Rect

__all__ = ["FloorPlan2D", "floor_plan_2d"]

#: Smallest and largest width and height of the building's interior, metres.
SIZE_RANGE = (12.0, 1000.0)
#: Room sizes between wall center lines, metres.
ROOM_SIZE = (4.0, 10.0)
_CLEARANCE = 0.5        # the path's distance to every solid, at least
_MARGIN = 1.0           # path vertices inside a room keep this far from its walls
_ENTRY = 0.6            # the path crosses a doorway straight, to this depth into the room
_DEPTH = 2.5            # and goes on to a point at most this deep (or the room's middle)
_ATTEMPTS = 30          # draws per piece of furniture before it is left out


class FloorPlan2D(Scene2D):
    """A :class:`Scene2D` building with its rooms, corridors and doorways.

    Build it with :func:`floor_plan_2d`; it scans, casts rays and answers
    occupancy queries as any :class:`Scene2D`.

    Parameters
    ----------
    solids, labels, interior_bounds, wall_thickness, path
        As for :class:`Scene2D`.
    rooms : array-like of shape (n_rooms, 2, 2)
        ``rooms[k] = [[x_min, y_min], [x_max, y_max]]``: the free interior of
        room ``k`` (inside its walls), whose walls are labelled ``room_k_...``.
    corridors : array-like of shape (n_corridors, 2, 2)
        The free rectangles of the corridors, as `rooms`.
    doorways : array-like of shape (n_doorways, 2, 2)
        The two jambs of every doorway, on the center line of its wall: a
        doorway is the open gap between them, across the whole wall.

    Attributes
    ----------
    rooms, corridors, doorways : ndarray
        As given.

    Examples
    --------
    >>> plan = floor_plan_2d()
    >>> plan.rooms.shape[1:], plan.doorways.shape[1:]
    ((2, 2), (2, 2))
    """

    def __init__(self, solids, labels, interior_bounds, wall_thickness, path, rooms,
                 corridors, doorways):
        super().__init__(solids, labels, interior_bounds, wall_thickness, path)
        self.rooms = np.asarray(rooms, dtype=np.float64).reshape(-1, 2, 2)
        self.corridors = np.asarray(corridors, dtype=np.float64).reshape(-1, 2, 2)
        self.doorways = np.asarray(doorways, dtype=np.float64).reshape(-1, 2, 2)

    def __repr__(self):
        return (f"FloorPlan2D(n_rooms={len(self.rooms)}, n_corridors={len(self.corridors)}, "
                f"n_solids={len(self.solids)})")


def _check_size(value, name):
    lo, hi = SIZE_RANGE
    try:
        return check_real(value, name, low=lo, high=hi, low_open=False, high_open=False)
    except ValueError:                  # NaN, inf or out of range (a TypeError passes)
        raise ValueError(f"{name} must lie in [{lo:g}, {hi:g}] m (room for a row of rooms "
                         f"{ROOM_SIZE[0]:g} to {ROOM_SIZE[1]:g} m deep on each side of a "
                         f"corridor, and at most 1 km), got {value!r}") from None


def _split(rng, length, lo=ROOM_SIZE[0], hi=ROOM_SIZE[1]):
    """Widths in [lo, hi] that add up to `length` (>= lo), about 6-9 m each."""
    n_min = max(int(np.ceil(length / hi - 1e-9)), 1)
    n_max = max(int(np.floor(length / lo + 1e-9)), n_min)
    n = int(np.clip(round(length / rng.uniform(6.0, 9.0)), n_min, n_max))
    return _split_fixed(rng, length, n, lo, hi, spread=0.5)


def _wall(lo, hi, axis, line, t, gaps):
    """Rectangles of a wall along `axis` (0: x) over [lo, hi] on `line`, minus `gaps`."""
    pieces, a = [], lo
    for g0, g1 in sorted(gaps) + [(hi, hi)]:
        if g0 - a > 1e-9:
            c, h = (a + g0) / 2, (g0 - a) / 2
            pieces.append(Rect([c, line] if axis == 0 else [line, c],
                                [h, t / 2] if axis == 0 else [t / 2, h]))
        a = g1
    return pieces


def solid_outline(solid, step=0.1):
    """Points on the boundary of a furniture solid, at most `step` apart."""
    if isinstance(solid, Circle):
        n = max(int(np.ceil(2 * np.pi * solid.radius / step)), 8)
        a = np.linspace(0, 2 * np.pi, n, endpoint=False)
        return solid.center + solid.radius * np.column_stack([np.cos(a), np.sin(a)])
    hx, hy = solid.half
    nx, ny = (max(int(np.ceil(2 * h / step)), 1) for h in (hx, hy))
    sx, sy = np.linspace(-hx, hx, nx + 1), np.linspace(-hy, hy, ny + 1)
    local = np.vstack([np.column_stack([sx, np.full_like(sx, -hy)]),
                       np.column_stack([sx, np.full_like(sx, hy)]),
                       np.column_stack([np.full_like(sy, -hx), sy]),
                       np.column_stack([np.full_like(sy, hx), sy])])
    return solid.center + local @ solid.rotation.T


def _furnish(rng, room, path_points, doors, count, first_box, first_disc):
    """Up to `count` boxes and discs inside `room` ((2, 2) free box), clear of the path
    (by more than the clearance), of the walls, the doorways and of one another."""
    (rx0, ry0), (rx1, ry1) = room
    placed, labels = [], []
    n_box, n_disc = first_box, first_disc
    for _ in range(count):
        is_box = rng.random() < 0.6
        if is_box:
            half = np.array([rng.uniform(0.3, 1.0), rng.uniform(0.25, 0.7)])
            angle = rng.uniform(-np.pi / 3, np.pi / 3) if rng.random() < 0.4 else 0.0
            reach = np.abs(np.array([[np.cos(angle), np.sin(angle)],
                                     [np.sin(angle), np.cos(angle)]])) @ half
        else:
            radius = rng.uniform(0.2, 0.6)
            reach = np.array([radius, radius])
        lo, hi = np.array([rx0, ry0]) + reach + 0.1, np.array([rx1, ry1]) - reach - 0.1
        if np.any(hi <= lo):
            continue
        for _ in range(_ATTEMPTS):
            center = rng.uniform(lo, hi)
            cand = Rect(center, half, angle) if is_box else Circle(center, radius)
            if cand.signed_distance(path_points).min() < _CLEARANCE + 0.05:
                continue
            if len(doors) and np.any(cand.signed_distance(doors[:, :2]) < doors[:, 2] + 0.6):
                continue
            edge = solid_outline(cand)
            if any(s.signed_distance(edge).min() < 0.3
                   or cand.signed_distance(solid_outline(s)).min() < 0.3 for s in placed):
                continue
            placed.append(cand)
            if is_box:
                n_box += 1
                labels.append(f"box_{n_box}")
            else:
                n_disc += 1
                labels.append(f"disc_{n_disc}")
            break
    return placed, labels, n_box, n_disc


def floor_plan_2d(seed: int = 0, *, width: float = 60.0, height: float = 40.0,
                  wall_thickness: float = 0.2, furniture: int = 3) -> FloorPlan2D:
    """A large 2D building of rooms, corridors and furniture, with a robot path.

    The interior ``[-width/2, width/2] x [-height/2, height/2]`` lies inside
    outer walls `wall_thickness` thick. Horizontal corridors (along x) run the
    whole width between rows of rooms (rows alternate with corridors, so
    every row opens onto one corridor or two); the middle one is the main
    corridor, 2.5-3 m wide, the others are 2-2.5 m wide. Vertical side
    corridors, 2-3 m wide, cross the rows between corridors near both ends
    of the building (and every ~25 m in wider ones). Rooms measure 4-10 m
    between wall center lines. Every room has a doorway 1.1-1.5 m wide onto
    a corridor; some rooms have a second one onto their other corridor or a
    side corridor, and some neighbouring rooms are interconnected by a
    doorway 0.9-1.5 m wide. Rooms hold up to `furniture` boxes (some rotated)
    and discs. Every solid is a rectangle or a disc, so
    :meth:`~Scene2D.occupancy`, :meth:`~Scene2D.signed_distance` and
    :meth:`~Scene2D.ray_cast` are exact.

    The robot's path (:attr:`Scene2D.path`) runs along the middle of every
    corridor, crossing between them by the side corridors (and into the
    middle of those it does not cross by, and back) and, from the corridor,
    straight through the main doorway of every room and on to a point up to
    2.5 m inside it, then back out; it keeps at least 0.5 m from every solid
    everywhere along it (the narrowest passages are the doorways, 1.1 m or
    wider). With the default seed and size it has 176 vertices and is 508 m
    long, so that ``scan(n_poses=N)`` takes scans ``508 / (N - 1)`` m apart:
    0.6 m at N=848, 0.3 m at N=1694.

    With the default laser (:meth:`~Scene2D.scan`: 17 beams over 180
    degrees, 8 m range) a pose gives about 32 GP observations (a beam with a
    return counts 2: its hit and its free segment; one without counts 1, see
    :func:`occgp.gp.observations_from_scans`), so ``n_poses = round(n / 32)``
    gives about ``n`` observations. For seed 0 at the default size:

    ========  ==============  ============
    n_poses   observations    pose spacing
    ========  ==============  ============
    31        998             16.9 m
    62        1,987           8.3 m
    154       4,985           3.3 m
    310       10,000          1.6 m
    619       19,989          0.82 m
    ========  ==============  ============

    Seeds 1 to 5 give within 2% of these counts at the same `n_poses`.

    A building has about one room per 75 to 95 m^2 and 7 to 8 solids per
    room. It takes 0.02 s to build at the default size and 14 s at the
    largest (1 km x 1 km: 10,600 rooms, 84,000 solids), where every
    :class:`Scene2D` query, which loops over the solids, is slow too.

    Parameters
    ----------
    seed : int, default=0
        Seed of the layout (``np.random.default_rng(seed)``): the same seed
        gives the same building; 0 is the fixed default.
    width, height : float, default=60.0, 40.0
        Size of the interior, metres, in [12, 1000].
    wall_thickness : float, default=0.2
        Thickness of every wall, metres, in [0.05, 0.5].
    furniture : int, default=3
        Pieces of furniture tried per room, in [0, 10]; a piece that does not
        fit clear of the path (by 0.55 m), the walls and doorways and the
        other pieces is left out.

    Returns
    -------
    scene : FloorPlan2D
        A :class:`Scene2D` with the rooms, corridors and doorways as
        attributes. Solids are labelled ``outer_wall_-x`` (``+x``, ``-y``,
        ``+y``), ``room_<k>_wall_<side>`` (pieces numbered ``_<i>`` where a
        doorway splits them), ``side_corridor_<j>_wall_<side>_row_<r>``,
        ``box_<i>`` and ``disc_<i>``.

    Raises
    ------
    TypeError
        If `seed` or `furniture` is not an int, or `width`, `height` or
        `wall_thickness` is not a real number.
    ValueError
        If an argument lies outside its range.

    See Also
    --------
    room_2d : the 22 x 18 m room of the GP occupancy-map papers.

    Examples
    --------
    >>> plan = floor_plan_2d()
    >>> [b.tolist() for b in plan.interior_bounds]
    [[-30.0, -20.0], [30.0, 20.0]]
    >>> len(plan.rooms), len(plan.solids)
    (32, 221)
    >>> plan.occupancy([[0.0, 0.0], [30.1, 0.0]]).tolist()   # main corridor, outer wall
    [False, True]
    >>> from occgp.gp import observations_from_scans
    >>> hits, starts, ends = observations_from_scans(plan.scan(n_poses=31))
    >>> len(hits) + len(starts)
    998
    """
    seed = check_int(seed, "seed", low=0)
    width = _check_size(width, "width")
    height = _check_size(height, "height")
    t = check_real(wall_thickness, "wall_thickness", low=0.05, high=0.5, low_open=False,
                   high_open=False)
    furniture = check_int(furniture, "furniture", low=0, high=10)
    rng = np.random.default_rng(seed)
    x0, x1, y0, y1 = -width / 2, width / 2, -height / 2, height / 2
    # every wall, the outer ones included, is centered on a line: a cell between two lines
    # is free inside them by t / 2
    X_lo, X_hi, Y_lo, Y_hi = x0 - t / 2, x1 + t / 2, y0 - t / 2, y1 + t / 2

    # ---- bands along y: room rows alternating with corridors ------------------------
    span_y = Y_hi - Y_lo
    n_corr = 1
    while (span_y - n_corr * (2.5 + t)) / (n_corr + 1) > 9.0:   # rows about 4.5-9.5 m deep
        n_corr += 1
    main = n_corr // 2
    corr_w = np.array([rng.uniform(2.5, 3.0) if c == main else rng.uniform(2.0, 2.5)
                       for c in range(n_corr)])
    depths = _split_fixed(rng, span_y - np.sum(corr_w + t), n_corr + 1)
    lines = [Y_lo]                      # band boundaries: row 0, corridor 0, row 1, ...
    for r in range(n_corr + 1):
        lines.append(lines[-1] + depths[r])
        if r < n_corr:
            lines.append(lines[-1] + corr_w[r] + t)
    lines[-1] = Y_hi
    row_y = [(lines[2 * r], lines[2 * r + 1]) for r in range(n_corr + 1)]
    corr_y = [(lines[2 * c + 1], lines[2 * c + 2]) for c in range(n_corr)]

    # ---- side corridors across the inner rows (between two corridors) -----------------
    span_x = X_hi - X_lo
    side = []                           # (x_a, x_b) wall center lines of each side corridor
    if n_corr >= 2:
        n_side = 1 if width < 30 else max(2, round(width / 25))
        side_w = rng.uniform(2.0, 3.0, n_side)
        if n_side == 1:
            band = side_w[0] + t
            slack = (span_x - band) / 2 - ROOM_SIZE[0]
            c = (X_lo + X_hi) / 2 + rng.uniform(-1, 1) * min(slack, 0.2 * span_x)
            centers = [c]
        else:
            first = X_lo + rng.uniform(4.5, 8.0) + (side_w[0] + t) / 2
            last = X_hi - rng.uniform(4.5, 8.0) - (side_w[-1] + t) / 2
            gap = (last - first) / (n_side - 1)
            centers = [first] + [first + i * gap + rng.uniform(-0.2, 0.2) * gap
                                 for i in range(1, n_side - 1)] + [last]
        side = [(c - (w + t) / 2, c + (w + t) / 2) for c, w in zip(centers, side_w)]

    # ---- rooms ----------------------------------------------------------------------
    rooms = []                          # dicts: x (a, b), y (a, b) center lines, row, ...
    for r, (ya, yb) in enumerate(row_y):
        inner = 0 < r < n_corr
        cuts = [X_lo] + [v for s in (side if inner else []) for v in s] + [X_hi]
        for seg, (sa, sb) in enumerate(zip(cuts[::2], cuts[1::2])):
            edges = sa + np.concatenate([[0.0], np.cumsum(_split(rng, sb - sa))])
            edges[-1] = sb
            for i, (xa, xb) in enumerate(zip(edges[:-1], edges[1:])):
                rooms.append({"x": (xa, xb), "y": (ya, yb), "row": r, "seg": seg,
                              "first": i == 0, "last": i == len(edges) - 2,
                              "h_doors": {}, "v_doors": {}})
    n_rooms = len(rooms)

    def free(room):
        (xa, xb), (ya, yb) = room["x"], room["y"]
        return np.array([[xa + t / 2, ya + t / 2], [xb - t / 2, yb - t / 2]])

    def door_x(room, w):
        (fx0, _), (fx1, _) = free(room)
        m = max(_MARGIN, w / 2 + 0.3)
        return rng.uniform(fx0 + m, fx1 - m)

    def door_y(room, w):
        (_, fy0), (_, fy1) = free(room)
        m = w / 2 + 0.3
        return rng.uniform(fy0 + m, fy1 - m)

    # doorways: a main one (on the path) onto a corridor, maybe a second one
    for room in rooms:
        r = room["row"]
        options = [c for c in (r - 1, r) if 0 <= c < n_corr]  # corridor below / above
        pick = options[int(rng.integers(len(options)))]
        room["main"] = pick
        w = rng.uniform(1.1, 1.5)
        room["h_doors"][pick] = (door_x(room, w), w)
        if len(options) == 2 and rng.random() < 0.25:
            other = options[0] if pick == options[1] else options[1]
            w = rng.uniform(0.9, 1.5)
            room["h_doors"][other] = (door_x(room, w), w)
    # interconnections between neighbours in a row segment; doorways onto side corridors
    for k in range(n_rooms - 1):
        a, b = rooms[k], rooms[k + 1]
        if a["row"] == b["row"] and a["seg"] == b["seg"] and rng.random() < 0.3:
            w = rng.uniform(0.9, 1.5)
            a["v_doors"]["+x"] = (door_y(a, w), w)
    for room in rooms:
        inner = 0 < room["row"] < n_corr
        for side_name, at_side in (("-x", room["first"] and room["seg"] > 0),
                                   ("+x", room["last"] and room["seg"] < len(side))):
            if inner and at_side and rng.random() < 0.4:
                w = rng.uniform(0.9, 1.5)
                room["v_doors"][side_name] = (door_y(room, w), w)

    # ---- walls ----------------------------------------------------------------------
    solids = [Rect([x0 - t / 2, 0.0], [t / 2, height / 2 + t]),
              Rect([x1 + t / 2, 0.0], [t / 2, height / 2 + t]),
              Rect([0.0, y0 - t / 2], [width / 2 + t, t / 2]),
              Rect([0.0, y1 + t / 2], [width / 2 + t, t / 2])]
    labels = ["outer_wall_-x", "outer_wall_+x", "outer_wall_-y", "outer_wall_+y"]
    doorways = []

    def add(pieces, label):
        solids.extend(pieces)
        labels.extend([label] if len(pieces) == 1 else
                      [f"{label}_{i}" for i in range(len(pieces))])

    for k, room in enumerate(rooms):
        (xa, xb), (ya, yb), r = room["x"], room["y"], room["row"]
        for side_name, line, c in (("-y", ya, r - 1), ("+y", yb, r)):
            if not 0 <= c < n_corr:
                continue                # the outer wall
            gaps = []
            if c in room["h_doors"]:
                dx, w = room["h_doors"][c]
                gaps.append((dx - w / 2, dx + w / 2))
                doorways.append([[dx - w / 2, line], [dx + w / 2, line]])
            add(_wall(xa, xb, 0, line, t, gaps), f"room_{k}_wall_{side_name}")
        if not room["last"]:            # the wall to the next room of the segment
            gaps = []
            if "+x" in room["v_doors"]:
                dy, w = room["v_doors"]["+x"]
                gaps.append((dy - w / 2, dy + w / 2))
                doorways.append([[xb, dy - w / 2], [xb, dy + w / 2]])
            add(_wall(ya, yb, 1, xb, t, gaps), f"room_{k}_wall_+x")
    beside = {}                         # (side corridor, row, its wall side): the room there
    for room in rooms:
        if 0 < room["row"] < n_corr:
            if room["first"] and room["seg"] > 0:
                beside[room["seg"] - 1, room["row"], "+x"] = room
            if room["last"] and room["seg"] < len(side):
                beside[room["seg"], room["row"], "-x"] = room
    for j, (va, vb) in enumerate(side):
        for r in range(1, n_corr):
            ya, yb = row_y[r]
            for side_name, line, key in (("-x", va, "+x"), ("+x", vb, "-x")):
                owner = beside[j, r, side_name]
                gaps = []
                if key in owner["v_doors"]:
                    dy, w = owner["v_doors"][key]
                    gaps.append((dy - w / 2, dy + w / 2))
                    doorways.append([[line, dy - w / 2], [line, dy + w / 2]])
                add(_wall(ya - t / 2, yb + t / 2, 1, line, t, gaps),
                    f"side_corridor_{j}_wall_{side_name}_row_{r}")

    # ---- the path: a sweep of every corridor, into every room and back -----------------
    corr_c = [(a + b) / 2 for a, b in corr_y]
    side_c = [(a + b) / 2 for a, b in side]
    ends = (x0 + _MARGIN, x1 - _MARGIN)
    path, excursions = [], {}

    def excursion(k):
        room, c = rooms[k], rooms[k]["main"]
        dx, _ = room["h_doors"][c]
        (fx0, fy0), (fx1, fy1) = free(room)
        into = 1.0 if room["row"] > c else -1.0     # the room lies above its corridor
        door_face = fy0 if into > 0 else fy1
        e = [dx, door_face + into * _ENTRY]
        # a point at most _DEPTH into the room, between the doorway and the room's center
        depth = min((fy1 - fy0) / 2, _DEPTH) + rng.uniform(-0.3, 0.3)
        x_mid = dx + rng.uniform(0.3, 0.7) * ((fx0 + fx1) / 2 - dx)
        mid = np.clip([x_mid, door_face + into * depth],
                      [fx0 + _MARGIN, fy0 + _MARGIN], [fx1 - _MARGIN, fy1 - _MARGIN])
        leg = [[dx, corr_c[c]], e, mid.tolist(), e, [dx, corr_c[c]]]
        excursions[k] = np.array(leg)
        return leg

    # corridor c is swept from where the path enters it to its nearer end, then to the
    # other end, where the side corridor nearest that end leads on to corridor c + 1
    entry, link = [ends[0]], []
    for c in range(n_corr - 1):
        near = min(ends, key=lambda e: abs(e - entry[c]))
        far = ends[1] if near == ends[0] else ends[0]
        link.append(int(np.argmin([abs(v - far) for v in side_c])))
        entry.append(side_c[link[c]])

    def stub(j, c):
        """Into side corridor j from corridor c, to the middle of the row above, and back."""
        ya, yb = row_y[c + 1]
        return [[side_c[j], corr_c[c]], [side_c[j], (ya + yb) / 2], [side_c[j], corr_c[c]]]

    def sweep(c, x_in):
        near = min(ends, key=lambda e: abs(e - x_in))
        far = ends[1] if near == ends[0] else ends[0]
        # stops along the corridor: room doorways, and the side corridors across the row
        # above that the path does not take
        stops = [(rooms[k]["h_doors"][c][0], "room", k) for k in by_corridor[c]]
        if c + 1 < n_corr:
            stops += [(side_c[j], "side", j) for j in range(len(side)) if j != link[c]]
        out_leg = sorted((s for s in stops if (s[0] - x_in) * (near - x_in) > 0),
                         key=lambda s: abs(s[0] - x_in))
        back_leg = sorted((s for s in stops if (s[0] - x_in) * (near - x_in) <= 0),
                          key=lambda s: abs(s[0] - near))
        pts = [[x_in, corr_c[c]]]
        for leg in (out_leg, back_leg):
            for _, kind, i in leg:
                pts += excursion(i) if kind == "room" else stub(i, c)
            pts.append([near if leg is out_leg else far, corr_c[c]])
        return pts

    by_corridor = [[] for _ in range(n_corr)]
    for k, room in enumerate(rooms):
        by_corridor[room["main"]].append(k)
    for c in range(n_corr):
        path += sweep(c, entry[c])
        if c + 1 < n_corr:
            path += [[entry[c + 1], corr_c[c]], [entry[c + 1], corr_c[c + 1]]]
    path = np.array(path)
    keep = np.concatenate([[True], np.any(np.diff(path, axis=0) != 0, axis=1)])
    path = path[keep]

    # ---- furniture, clear of the path, the walls, the doorways and one another ----------
    n_box = n_disc = 0
    door_arr = np.array(doorways).reshape(-1, 2, 2)
    door_center = door_arr.mean(axis=1)
    door_half = np.linalg.norm(door_arr[:, 1] - door_arr[:, 0], axis=1) / 2
    for k, room in enumerate(rooms):
        box = free(room)
        near = np.all((door_center >= box[0] - t) & (door_center <= box[1] + t), axis=1)
        doors = np.column_stack([door_center[near], door_half[near]])
        pieces, names, n_box, n_disc = _furnish(
            rng, box, path_samples(excursions[k]), doors, furniture, n_box, n_disc)
        solids += pieces
        labels += names

    room_boxes = [free(room) for room in rooms]
    corridors = [[[x0, a + t / 2], [x1, b - t / 2]] for a, b in corr_y]
    for va, vb in side:
        for r in range(1, n_corr):
            corridors.append([[va + t / 2, row_y[r][0] - t / 2],
                              [vb - t / 2, row_y[r][1] + t / 2]])
    return FloorPlan2D(solids, labels, ([x0, y0], [x1, y1]), t, path, room_boxes,
                       corridors, door_arr)


def _split_fixed(rng, length, n, lo=ROOM_SIZE[0], hi=ROOM_SIZE[1], spread=0.3):
    """`n` widths in [lo, hi] adding up to `length` (lo * n <= length <= hi * n), drawn
    around equal shares by factors in [1 - spread, 1 + spread]."""
    for _ in range(20):
        u = rng.uniform(1.0 - spread, 1.0 + spread, n)
        widths = lo + (length - lo * n) * u / u.sum()
        if widths.max() <= hi:
            return widths
    return np.full(n, length / n)
