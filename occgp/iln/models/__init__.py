"""Range-image up-sampling models: ILN, a LIIF-style value predictor, bilinear and edge-aware rules.

Every model maps a range image and continuous queries ``(v, u)`` in the input image's pixel
coordinates (pixel centers at integer + 0.5, row 0 at the highest elevation) to ranges. A query
reads the 4 input pixels around it: vertical neighbours are clamped to the image, horizontal
neighbours wrap around for a 360° sensor (``wrap=True``) and are clamped otherwise.

Pixels without a return (range 0) are first-class: no model blends a no-return into a range.
A no-return neighbour gets weight 0, and a query whose 4 neighbours all lack a return (or whose
interpolation weight lies entirely on no-return pixels, for the bilinear and LIIF models) returns
0, i.e. no return.

Models are built from specs ``{"name": ..., "args": {...}, "sd": state_dict}`` with :func:`make`,
and new models join the registry with :func:`register` (the LIIF convention).

The registry and the spec round trip live in ``_registry``, the input checks, the
neighbourhood lookup and :class:`RangeModel` in ``_base``, the shared EDSR-baseline encoder
in ``_encoder``, one model per module (``_iln``, ``_liif``, ``_bilinear``, ``_analytic``: the edge-aware rule), and the
full-image up-sampling in ``_image``.
"""

from ._analytic import EdgeAwareInterpolation
from ._base import DEFAULT_CHUNK, MAX_RANGE, RangeModel
from ._bilinear import Bilinear, InverseBilinear
from ._encoder import EDSRBaseline
from ._iln import ILN, PRIOR_EPS, WEIGHT_PRIORS
from ._image import image_queries, upsample_image
from ._liif import LIIF
from ._candidates import CANDIDATES
from ._selector import CandidateSelector, choose_candidates, hard_queries, selector_labels
from ._registry import available_models, make, register

__all__ = [
    "register",
    "make",
    "available_models",
    "EDSRBaseline",
    "ILN",
    "LIIF",
    "Bilinear",
    "InverseBilinear",
    "EdgeAwareInterpolation",
    "CandidateSelector",
    "CANDIDATES",
    "hard_queries",
    "choose_candidates",
    "selector_labels",
    "upsample_image",
    "image_queries",
]
