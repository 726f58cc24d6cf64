"""LIIF-style value prediction: an MLP predicts a range from each of the 4 neighbours."""

from __future__ import annotations

import torch
from torch import nn

from ..._validation import check_int
from ._base import gather, neighbourhood, query_doc, renormalise
from ._encoder import EDSRBaseline, EncodedModel
from ._registry import register

__all__ = ["LIIF"]

class _MLP(nn.Sequential):
    def __init__(self, d_in: int, hidden: tuple[int, ...], d_out: int):
        layers: list[nn.Module] = []
        for h in hidden:
            layers += [nn.Linear(d_in, h), nn.ReLU()]
            d_in = h
        layers.append(nn.Linear(d_in, d_out))
        super().__init__(*layers)


@register("liif")
class LIIF(EncodedModel):
    """LIIF-style value prediction (Eq. 4.2): an MLP predicts a range from each neighbour.

    For each of the 4 neighbouring pixels, an MLP maps ``[z_t, Δq_t]`` (encoder feature and
    relative position in pixels) to a normalised range; the 4 predictions are blended with the
    area weights S_t / S (the area of the rectangle between the query and the diagonally opposite
    pixel center, i.e. bilinear weights). A prediction from a no-return pixel is dropped and the
    remaining weights renormalised; with no weight left the query returns 0 (no return).

    Parameters
    ----------
    channels : int, default=64
        Encoder feature channels.
    n_resblocks : int, default=16
        Residual blocks of the EDSR-baseline encoder.
    hidden : list of int, default=(256, 256, 256, 256)
        Hidden widths of the value MLP.
    max_range : float, default=80.0
        Normalising range in metres.
    wrap : bool, default=True
        Horizontal wrap-around (360° sensors).

    References
    ----------
    Chen, Y., Liu, S., Wang, X. "Learning Continuous Image Representation with Local Implicit
    Image Function", CVPR 2021.
    """

    arg_names = ("channels", "n_resblocks", "hidden", "max_range", "wrap")

    def __init__(
        self,
        channels: int = 64,
        n_resblocks: int = 16,
        hidden=(256, 256, 256, 256),
        max_range: float = 80.0,
        wrap: bool = True,
    ):
        super().__init__(max_range, wrap)
        channels = check_int(channels, "channels", low=1, state_bounds=True)
        n_resblocks = check_int(n_resblocks, "n_resblocks", low=0, state_bounds=True)
        if isinstance(hidden, (str, bytes)) or not hasattr(hidden, "__iter__"):
            raise TypeError(f"hidden must be a list of ints, got {type(hidden).__name__}")
        hidden = tuple(check_int(h, "hidden[i]", low=1, state_bounds=True) for h in hidden)
        self._spec_args = {
            "channels": channels, "n_resblocks": n_resblocks, "hidden": list(hidden),
            "max_range": self.max_range, "wrap": self.wrap,
        }
        self.encoder = EDSRBaseline(channels, n_resblocks)
        self.imnet = _MLP(channels + 2, hidden, 1)

    @query_doc()
    def query(self, features, images, queries, wrap):
        """Ranges at queries: the MLP's 4 per-neighbour predictions blended by area weights.

        {query_sections}
            Renormalised area (bilinear) weights of the neighbours (top, left), (top, right),
            (bottom, left), (bottom, right); 0 for no-return neighbours; all 0 when no weight
            is left (the range is then 0). The ranges are not clamped and may be below 0.
        """
        idx, rel, wb, r = neighbourhood(images, queries, wrap)
        flat = features.flatten(2).transpose(1, 2)
        z = torch.cat([gather(flat, idx), rel], dim=-1)  # (B, N, 4, C + 2)
        values = self.imnet(z).squeeze(-1)  # (B, N, 4)
        w = renormalise(wb * (r > 0))
        return (w * values).sum(-1), w
