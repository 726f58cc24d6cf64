"""Bilinear interpolation of the ranges or of the inverse ranges (no parameters)."""

from __future__ import annotations

import torch

from ..._docfill import fill_doc
from ._base import RangeModel, neighbourhood, query_doc, renormalise
from ._candidates import inverse_weights
from ._registry import register

__all__ = ["Bilinear", "InverseBilinear"]

#: The Parameters section of both models.
_PARAMS = """Parameters
----------
max_range : float, default=80.0
    Normalising range in metres (no effect on the result).
wrap : bool, default=True
    Horizontal wrap-around (360° sensors)."""


@register("bilinear")
@fill_doc(params=_PARAMS)
class Bilinear(RangeModel):
    """Bilinear interpolation of the 4 neighbouring pixels (no parameters).

    With 4 returns this is the textbook formula. No-return neighbours are dropped and the
    weights of the others renormalised; a query whose weight lies entirely on no-return pixels
    (all 4 lack a return, or it sits on a no-return pixel's center line) returns 0.

    {params}
    """

    arg_names = ("max_range", "wrap")

    def __init__(self, max_range: float = 80.0, wrap: bool = True):
        super().__init__(max_range, wrap)
        self._spec_args = {"max_range": self.max_range, "wrap": self.wrap}

    @staticmethod
    def _neighbour_weights(wb: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
        return renormalise(wb * (r > 0))

    @query_doc(features="None\n    What :meth:`encode` returned (ignored).")
    def query(self, features, images, queries, wrap):
        """Interpolation at queries (see the class), no-return neighbours dropped.

        {query_sections}
            The interpolation weights of the neighbours (top, left), (top, right),
            (bottom, left), (bottom, right), renormalised over those with a return; 0 for
            no-return neighbours; all 0 when no bilinear weight lies on a return (the range
            is then 0).
        """
        _, _, wb, r = neighbourhood(images, queries, wrap)
        w = self._neighbour_weights(wb, r)
        return (w * r).sum(-1), w


@register("inverse-bilinear")
@fill_doc(params=_PARAMS)
class InverseBilinear(Bilinear):
    """Bilinear interpolation of the inverse ranges of the 4 neighbouring pixels (no parameters).

    On a plane ``n . x = d`` a beam of direction ``e`` has ``1 / r = (n . e) / d``, linear in
    ``e``: interpolating ``1 / r`` is exact to first order in the beam spacing on ground and walls,
    where interpolating ``r`` (:class:`Bilinear`) bends the plane. It is the weight prior of
    :class:`ILN` (``weight_prior="inverse-range"``, which is this model before any training) and
    a no-training baseline of its own. As a convex combination of the ranges its weights are
    ``b_t / r_t`` renormalised (``b_t`` the bilinear weights); no-return neighbours are dropped
    as in :class:`Bilinear`.

    {params}
    """

    @staticmethod
    def _neighbour_weights(wb: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
        return inverse_weights(wb, r)
