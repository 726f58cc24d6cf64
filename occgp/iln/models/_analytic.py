"""Edge-aware interpolation: inverse bilinear, or a copy of the nearer row across depth edges."""

from __future__ import annotations

import torch

from ..._validation import check_bool, check_real
from ._base import RangeModel, neighbourhood, query_doc
from ._candidates import inverse, inverse_weights, lines
from ._registry import register

__all__ = ["EdgeAwareInterpolation", "DEFAULT_TOLERANCE"]

#: Relative agreement of a planar extension with inverse bilinear that keeps the latter.
DEFAULT_TOLERANCE = 0.05


@register("edge-aware")
class EdgeAwareInterpolation(RangeModel):
    """Inverse bilinear interpolation that copies the nearer row across depth edges.

    A no-training rule between :class:`InverseBilinear` and nearest-row copying. A query
    between input rows ``i`` (above) and ``i + 1`` (below), at vertical fraction ``t`` from
    row ``i``, has these candidates, all in inverse range ``1 / r``:

    * ``P``, the inverse bilinear value (the prior);
    * the planar extension from above, ``s[i] + t (s[i] - s[i-1])`` (``1 / r`` extended
      linearly from rows ``i - 1`` and ``i`` to the query's fractional row);
    * the planar extension from below, ``s[i+1] + (1 - t) (s[i+1] - s[i+2])``;

    where ``s[k]`` is row ``k``'s inverse range at the query's column (see below). An extension
    *agrees* when it lies within ``tolerance * P`` of ``P``. Where at least one extension
    exists and none agrees, the query lies on a depth edge and gets a copy of the nearer row
    (row ``i`` for ``t <= 0.5``, ties to the upper row, else row ``i + 1``); everywhere else it
    keeps ``P``. On a plane both extensions equal ``P`` (``1 / r`` is linear in the beam
    direction there), so the rule is inverse bilinear on ground and walls; across a step both
    extensions continue their own surface and miss ``P``, which blends the two, so the query
    takes the surface of the nearer row instead of a point floating between them.

    **Columns.** The rule acts along the columns only: every row value ``s[k]``, and the
    copied row, is interpolated in ``1 / r`` between the query's two neighbouring columns (the
    horizontal half of :class:`InverseBilinear`; wrapped for a 360° sensor, clamped otherwise),
    and there is no edge test across columns. The output is always a convex combination of
    the 4 neighbouring pixels: the inverse bilinear weights, or the nearer row's horizontal
    ones.

    **Borders and no-returns.** An extension exists only where both of its rows lie in the
    image and have a return at the query's column (horizontal weight on a pixel with a
    return). At the top (queries between rows 0 and 1) only the lower extension exists, at the
    bottom only the upper one; where neither exists (an image of 2 rows, or no-returns on both
    sides) the query keeps ``P``. Queries outside the outermost row centers read that row
    alone, as :class:`InverseBilinear` does. No-return neighbours are dropped as in
    :class:`InverseBilinear`, and a query whose ``P`` is no return stays no return. Where the
    nearer row has no return at the query's column (the edge of a no-return region, e.g. the
    sky above a roof), the query keeps ``P`` by default, so the rule never turns a return into
    a no-return; with ``copy_no_returns=True`` it copies that no-return (range 0) instead.

    Parameters
    ----------
    max_range : float, default=80.0
        Normalising range in metres (no effect on the result).
    wrap : bool, default=True
        Horizontal wrap-around (360° sensors).
    tolerance : float, default=0.05
        Relative agreement, in ``1 / r``, of an extension with the inverse bilinear value that
        keeps the latter; > 0. ``inf`` is not allowed; a large value (e.g. 1e9) gives
        :class:`InverseBilinear`.
    copy_no_returns : bool, default=False
        On a depth edge whose nearer row has no return at the query's column, copy the
        no-return (True) or keep the inverse bilinear value (False).

    Raises
    ------
    TypeError
        If `max_range` or `tolerance` is not a real number, or `wrap` or `copy_no_returns` is
        not a bool.
    ValueError
        If `max_range` or `tolerance` is not finite and positive.

    Examples
    --------
    >>> import numpy as np
    >>> step = np.array([[10.0] * 4] * 2 + [[20.0] * 4] * 2)   # a step between rows 1 and 2
    >>> m = EdgeAwareInterpolation()
    >>> m.predict(step, [[2.25, 2.0], [1.75, 2.0]]).tolist()  # nearer rows: 2 (below), 1 (above)
    [20.0, 10.0]
    """

    arg_names = ("max_range", "wrap", "tolerance", "copy_no_returns")

    def __init__(self, max_range: float = 80.0, wrap: bool = True,
                 tolerance: float = DEFAULT_TOLERANCE, copy_no_returns: bool = False):
        super().__init__(max_range, wrap)
        self.tolerance = check_real(tolerance, "tolerance", low=0.0, state_bounds=True)
        self.copy_no_returns = check_bool(copy_no_returns, "copy_no_returns")
        self._spec_args = {"max_range": self.max_range, "wrap": self.wrap,
                           "tolerance": self.tolerance, "copy_no_returns": self.copy_no_returns}

    @query_doc(features="None\n    What :meth:`encode` returned (ignored).")
    def query(self, features, images, queries, wrap):
        """Edge-aware interpolation at queries (see the class).

        {query_sections}
            The weights of the neighbours (top, left), (top, right), (bottom, left),
            (bottom, right): the inverse bilinear ones, or on a depth edge the nearer row's
            horizontal inverse-range weights (0 on the other row); 0 for no-return
            neighbours; all 0 when the range is 0.
        """
        _, _, wb, r = neighbourhood(images, queries, wrap)
        w_prior = inverse_weights(wb, r)
        prior = (w_prior * r).sum(-1)

        s, _, t, b, _ = lines(images, queries, wrap)
        (s_up2, ok_up2), (s_up, ok_up), (s_dn, ok_dn), (s_dn2, ok_dn2) = s

        has_prior = prior > 0
        inv_prior = inverse(prior)
        limit = self.tolerance * inv_prior
        ext_up = s_up + t * (s_up - s_up2)
        ext_dn = s_dn + (1 - t) * (s_dn - s_dn2)
        formed_up = ok_up2 & ok_up
        formed_dn = ok_dn & ok_dn2
        agree = (formed_up & ((ext_up - inv_prior).abs() <= limit)) | \
                (formed_dn & ((ext_dn - inv_prior).abs() <= limit))
        edge = has_prior & (formed_up | formed_dn) & ~agree

        upper = (t <= 0.5).unsqueeze(-1)
        zero = torch.zeros_like(b)
        w_rows = torch.stack([1 - b, b, zero, zero], dim=-1)
        w_rows = torch.where(upper, w_rows, w_rows.roll(2, dims=-1))
        w_copy = inverse_weights(w_rows, r)
        if not self.copy_no_returns:
            edge = edge & (w_copy.sum(-1) > 0)
        w = torch.where(edge.unsqueeze(-1), w_copy, w_prior)
        return (w * r).sum(-1), w
