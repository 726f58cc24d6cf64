"""The adaptive super-ray method of the log-odds maps (``method="superray+culling"``):
the threshold the compiled core takes for a scan, and the back-off after a scan whose
grouping did not pay (the state lives on the map: ``_superray_skip``, the scans left
to insert without super rays, and ``_superray_pause``, the next pause)."""

from .._octree import RAY_VISITS  # a ray's start, in cell visits (ext/_superrays.h)


def adaptive_threshold(m, method: str, threshold: int) -> int:
    """The super-ray threshold the core takes for `m`'s next scan: "superray+culling"
    groups adaptively (negated: only the cells where grouping can pay), and not at all
    (0) while it backs off."""
    if method != "superray+culling":
        return threshold
    if m._superray_skip > 0:
        m._superray_skip -= 1
        return 0
    return -threshold


def learn_superrays(m, method: str, n_points: int) -> None:
    """After a "superray+culling" scan of `n_points` that grouped rays: back `m` off when
    the grouping (``superray_seconds``) cost more than the traversal it saved, estimated
    from the scan's traversal time, a ray's start costing RAY_VISITS cell visits: the
    work it spared (rays, and their cell visits) over the work it did. Rays into cells
    near the sensor, which hold the most end points, are short: a ray spared is not an
    average ray."""
    stats = m.last_insert_
    if method != "superray+culling" or not stats["superrays"]:
        return
    spared = (n_points - stats["rays"]) * RAY_VISITS + stats["spared_cells"]
    done = stats["rays"] * RAY_VISITS + stats["traversed_cells"]
    saved = spared * stats["traversal_seconds"] / max(done, 1)
    if saved < stats["superray_seconds"]:
        m._superray_skip = m._superray_pause
        m._superray_pause = min(2 * m._superray_pause, 8 * m.SUPERRAY_BACKOFF)
    else:
        m._superray_pause = m.SUPERRAY_BACKOFF
