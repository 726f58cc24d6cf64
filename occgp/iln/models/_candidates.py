"""Analytic interpolation candidates of a query, shared by the edge-aware rule and the selector.

A query ``(v, u)`` between input rows ``i`` (above) and ``i + 1`` (below), at vertical
fraction ``t`` from row ``i``, and between columns ``j`` (left) and ``j + 1`` (right), at
horizontal fraction ``b`` from column ``j``, has these candidates, all formed in inverse range
``1 / r`` (linear along the beams of a plane, to first order):

====  ==============  ==========================================================================
k     name            value of ``1 / r``
====  ==============  ==========================================================================
0     ``prior``       inverse bilinear (the 4 neighbours, no-returns dropped)
1     ``up``          row ``i`` at the query's column (copy of the upper row)
2     ``down``        row ``i + 1`` (copy of the lower row)
3     ``left``        column ``j`` at the query's row (copy of the left column)
4     ``right``       column ``j + 1``
5     ``ext-up``      ``s[i] + t (s[i] - s[i-1])``: rows ``i - 1``, ``i`` extended to the query
6     ``ext-down``    ``s[i+1] + (1 - t) (s[i+1] - s[i+2])``
7     ``ext-left``    ``c[j] + b (c[j] - c[j-1])``
8     ``ext-right``   ``c[j+1] + (1 - b) (c[j+1] - c[j+2])``
9     ``no-return``   no return (range 0)
====  ==============  ==========================================================================

``s[k]`` is row ``k``'s inverse range at the query's column (interpolated between columns ``j``
and ``j + 1`` with weights ``1 - b`` and ``b``, renormalised over the pixels with a return),
``c[k]`` column ``k``'s at the query's row (between rows ``i`` and ``i + 1``, ``1 - t`` and
``t``). Columns wrap around for a 360° sensor and are clamped otherwise; rows outside the image
do not exist. A candidate exists where every pixel value it reads exists, and an extension
only where it stays a range in ``(0, 1]`` of the normalised image (``1 / r >= 1``).
The candidates 0-4 are convex combinations of the 4 neighbours (:func:`candidate_weights`);
the extensions read one pixel row or column further out.
"""

from __future__ import annotations

import torch

from ._base import neighbourhood, query_frame, renormalise

__all__ = ["CANDIDATES", "N_CANDIDATES", "PRIOR", "NO_RETURN", "FIRST_EXTENSION", "inverse", "line_inverse",
           "lines", "candidates", "inverse_weights"]

#: Names of the candidates, in their order along the last axis of :func:`candidates`.
CANDIDATES = ("prior", "up", "down", "left", "right", "ext-up", "ext-down", "ext-left",
              "ext-right", "no-return")
N_CANDIDATES = len(CANDIDATES)
PRIOR = 0
NO_RETURN = N_CANDIDATES - 1
FIRST_EXTENSION = CANDIDATES.index("ext-up")


def inverse(r: torch.Tensor) -> torch.Tensor:
    """``1 / r`` where ``r > 0``, else 0."""
    valid = r > 0
    return torch.where(valid, 1.0 / torch.where(valid, r, torch.ones_like(r)), 0.0)


def line_inverse(r_a: torch.Tensor, r_b: torch.Tensor, f: torch.Tensor):
    """Inverse range between two pixels at fraction `f` from `r_a`, and whether it exists.

    The value is ``((1 - f) / r_a + f / r_b)`` renormalised over the pixels with a return; it
    does not exist where the weight lies entirely on pixels without a return.
    """
    w_a = (1 - f) * (r_a > 0)
    w_b = f * (r_b > 0)
    total = w_a + w_b
    ok = total > 1e-12
    value = (w_a * inverse(r_a) + w_b * inverse(r_b)) / torch.where(ok, total, torch.ones_like(total))
    return torch.where(ok, value, torch.zeros_like(value)), ok


def _column(j: torch.Tensor, width: int, wrap: bool) -> torch.Tensor:
    return j.remainder(width) if wrap else j.clamp(0, width - 1)


def lines(images: torch.Tensor, queries: torch.Tensor, wrap: bool):
    """The rows' and columns' inverse ranges around queries (see the module docs).

    Returns
    -------
    rows : list of 4 (value, exists) pairs
        ``s[i - 1]``, ``s[i]``, ``s[i + 1]``, ``s[i + 2]``, each (B, N).
    columns : list of 4 (value, exists) pairs
        ``c[j - 1]``, ``c[j]``, ``c[j + 1]``, ``c[j + 2]``.
    t, b : torch.Tensor of shape (B, N)
        The vertical and horizontal fractions.
    pixels : torch.Tensor of shape (B, N, 4, 4)
        Normalised ranges of rows ``i - 1 .. i + 2`` and columns ``j - 1 .. j + 2`` (0 for no
        return and outside the image).
    """
    bsz, height, width = images.shape
    i0, j0, t, b = query_frame(queries)
    offsets = torch.arange(-1, 3, device=queries.device)
    rows = i0[..., None] + offsets  # (B, N, 4)
    cols = _column(j0[..., None] + offsets, width, wrap)
    inside = (rows >= 0) & (rows < height)
    flat = (rows.clamp(0, height - 1) * width)[..., :, None] + cols[..., None, :]  # (B, N, 4, 4)
    px = torch.gather(images.reshape(bsz, -1), 1, flat.reshape(bsz, -1)).reshape(flat.shape)
    px = px * inside[..., None]  # rows outside the image: no return
    rows = [line_inverse(px[..., k, 1], px[..., k, 2], b) for k in range(4)]
    columns = [line_inverse(px[..., 1, k], px[..., 2, k], t) for k in range(4)]
    return rows, columns, t, b, px


def candidates(images: torch.Tensor, queries: torch.Tensor, wrap: bool):
    """The candidates' ranges at queries (see the module docs), and which exist.

    Parameters
    ----------
    images : torch.Tensor of shape (B, H, W)
        Normalised range images (0 for no return).
    queries : torch.Tensor of shape (B, N, 2)
        ``(v, u)`` in the images' pixel units.
    wrap : bool
        Columns wrap around (360° sensor).

    Returns
    -------
    ranges : torch.Tensor of shape (B, N, 10)
        Normalised ranges of the candidates of :data:`CANDIDATES` (0 for no return and where a
        candidate does not exist).
    exists : torch.Tensor of bool, shape (B, N, 10)
        Where a candidate exists; ``prior`` (no return where the 4 neighbours have none) and
        ``no-return`` always exist.
    pixels : torch.Tensor of shape (B, N, 4, 4)
        The normalised ranges of the 4 x 4 input pixels around each query, rows ``i - 1`` to
        ``i + 2`` and columns ``j - 1`` to ``j + 2`` (0 for no return and outside the image).
    """
    rows, columns, t, b, px = lines(images, queries, wrap)
    (s_up2, ok_up2), (s_up, ok_up), (s_dn, ok_dn), (s_dn2, ok_dn2) = rows
    (c_l2, ok_l2), (c_l, ok_l), (c_r, ok_r), (c_r2, ok_r2) = columns

    _, _, wb, r = neighbourhood(images, queries, wrap)
    w_prior = inverse_weights(wb, r)
    prior = inverse((w_prior * r).sum(-1))
    ext = [
        (s_up + t * (s_up - s_up2), ok_up2 & ok_up),
        (s_dn + (1 - t) * (s_dn - s_dn2), ok_dn & ok_dn2),
        (c_l + b * (c_l - c_l2), ok_l2 & ok_l),
        (c_r + (1 - b) * (c_r - c_r2), ok_r & ok_r2),
    ]
    inv = torch.stack([prior, s_up, s_dn, c_l, c_r] + [e for e, _ in ext], dim=-1)
    ok = torch.stack([torch.ones_like(ok_up), ok_up, ok_dn, ok_l, ok_r] + [o & (e >= 1.0) for e, o in ext],
                     dim=-1)
    ranges = inverse(torch.where(ok, inv, torch.zeros_like(inv)))
    ranges = torch.cat([ranges, torch.zeros_like(ranges[..., :1])], dim=-1)
    ok = torch.cat([ok, torch.ones_like(ok[..., :1])], dim=-1)
    return ranges, ok, px


def inverse_weights(wb: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
    """Inverse-range interpolation weights ``wb / r`` renormalised over the returns."""
    valid = r > 0
    return renormalise(torch.where(valid, wb / torch.where(valid, r, torch.ones_like(r)), 0.0))
