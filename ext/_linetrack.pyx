# cython: language_level=3
"""Line tracking of planar laser scans (compiled core of occgp.gp.LineTracking).

Kim & Kim's Algorithm 1: within each scan, hits are visited in bearing order
and grown into lines. A line's total-least-squares fit comes from running sums
of its points (relative to its first point, so that far-off coordinates do not
cancel): the next hit joins when it lies within `distance_threshold` of the
fitted line and within `gap_threshold` of the previous hit; otherwise it
starts a new line, which the hit after it joins when within `gap_threshold`.
Each hit costs O(1).
"""

from libc.math cimport atan2, cos, sin, sqrt, fabs


def track_lines(const double[:, ::1] points, const Py_ssize_t[::1] scan_ptr,
                double distance_threshold, double gap_threshold, Py_ssize_t[::1] line_of):
    """Label each hit of `points` (n, 2), ordered by bearing within each scan, with its line.

    Scan ``s`` holds rows ``scan_ptr[s]:scan_ptr[s + 1]``. Lines never span two
    scans. Writes ``line_of`` (n,) and returns the number of lines; lines are
    numbered in the order they start.
    """
    cdef Py_ssize_t n_scans = scan_ptr.shape[0] - 1
    cdef Py_ssize_t s, i, n_lines = 0
    cdef double rx = 0.0, ry = 0.0      # the line's first point
    cdef double px = 0.0, py = 0.0      # the previous hit
    cdef double sx, sy, sxx, sxy, syy, cnt
    cdef double qx, qy, mx, my, cxx, cxy, cyy, theta, perp, gap2
    cdef double gap_thr2 = gap_threshold * gap_threshold
    cdef bint accept
    with nogil:
        for s in range(n_scans):
            cnt = 0.0
            sx = sy = sxx = sxy = syy = 0.0
            for i in range(scan_ptr[s], scan_ptr[s + 1]):
                qx = points[i, 0] - rx
                qy = points[i, 1] - ry
                accept = False
                if cnt > 0.0:
                    gap2 = (points[i, 0] - px) ** 2 + (points[i, 1] - py) ** 2
                    if gap2 <= gap_thr2:
                        mx = sx / cnt
                        my = sy / cnt
                        cxx = sxx / cnt - mx * mx
                        cxy = sxy / cnt - mx * my
                        cyy = syy / cnt - my * my
                        if cxx + cyy <= 0.0:
                            accept = True        # one point (or coincident ones) so far
                        else:
                            theta = 0.5 * atan2(2.0 * cxy, cxx - cyy)
                            perp = fabs(-(qx - mx) * sin(theta) + (qy - my) * cos(theta))
                            accept = perp <= distance_threshold
                if not accept:
                    rx = points[i, 0]
                    ry = points[i, 1]
                    qx = 0.0
                    qy = 0.0
                    cnt = 0.0
                    sx = sy = sxx = sxy = syy = 0.0
                    n_lines += 1
                cnt += 1.0
                sx += qx
                sy += qy
                sxx += qx * qx
                sxy += qx * qy
                syy += qy * qy
                line_of[i] = n_lines - 1
                px = points[i, 0]
                py = points[i, 1]
    return n_lines
