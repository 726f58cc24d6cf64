"""The EDSR-baseline encoder of the learned models, and their base over its features."""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from ..._validation import check_int, check_real
from ._base import RangeModel
from ._registry import register

__all__ = ["EDSRBaseline", "EncodedModel"]


def _pad(x: torch.Tensor, wrap: bool) -> torch.Tensor:
    """Pad (B, C, H, W) by one pixel: replicate vertically, circular (or replicate) horizontally."""
    x = F.pad(x, (1, 1, 0, 0), mode="circular" if wrap else "replicate")
    return F.pad(x, (0, 0, 1, 1), mode="replicate")


class _Conv(nn.Conv2d):
    """3x3 convolution with the range-image padding (no zero padding)."""

    def __init__(self, c_in: int, c_out: int):
        super().__init__(c_in, c_out, 3, padding=0)

    def forward(self, x: torch.Tensor, wrap: bool = True) -> torch.Tensor:  # type: ignore[override]
        return super().forward(_pad(x, wrap))


class _ResBlock(nn.Module):
    def __init__(self, channels: int, res_scale: float):
        super().__init__()
        self.conv1 = _Conv(channels, channels)
        self.conv2 = _Conv(channels, channels)
        self.res_scale = res_scale

    def forward(self, x: torch.Tensor, wrap: bool = True) -> torch.Tensor:
        y = self.conv2(F.relu(self.conv1(x, wrap)), wrap)
        return x + self.res_scale * y


@register("edsr-baseline")
class EDSRBaseline(nn.Module):
    """EDSR-baseline feature encoder for range images (no up-sampling tail).

    A 3x3 convolution from 1 to `channels`, `n_resblocks` residual blocks (conv, ReLU, conv), a
    3x3 convolution and a global skip connection. Every convolution pads its input explicitly:
    replicate vertically, circular horizontally (``wrap=True``, a 360° sensor) or replicate.

    Parameters
    ----------
    channels : int, default=64
        Feature channels C.
    n_resblocks : int, default=16
        Residual blocks (0 allowed).
    res_scale : float, default=1.0
        Scale of each residual branch.
    """

    arg_names = ("channels", "n_resblocks", "res_scale")

    def __init__(self, channels: int = 64, n_resblocks: int = 16, res_scale: float = 1.0):
        super().__init__()
        channels = check_int(channels, "channels", low=1, state_bounds=True)
        n_resblocks = check_int(n_resblocks, "n_resblocks", low=0, state_bounds=True)
        res_scale = check_real(res_scale, "res_scale", low=0.0, state_bounds=True)
        self._spec_args = {"channels": channels, "n_resblocks": n_resblocks, "res_scale": res_scale}
        self.out_dim = channels
        self.head = _Conv(1, channels)
        self.body = nn.ModuleList(_ResBlock(channels, res_scale) for _ in range(n_resblocks))
        self.body_tail = _Conv(channels, channels)

    def forward(self, x: torch.Tensor, wrap: bool = True) -> torch.Tensor:
        """Features of normalised range images.

        No input checks (the models call it on checked input).

        Parameters
        ----------
        x : torch.Tensor of shape (B, 1, H, W)
            Range images divided by the model's normalising range (0 for no return).
        wrap : bool, default=True
            Circular horizontal padding (a 360° sensor); replicate padding when false.
            Vertical padding always replicates.

        Returns
        -------
        features : torch.Tensor of shape (B, C, H, W)
            ``C`` = `channels`, on `x`'s device.
        """
        x = self.head(x, wrap)
        y = x
        for block in self.body:
            y = block(y, wrap)
        return x + self.body_tail(y, wrap)

    def spec(self, with_sd: bool = True) -> dict:
        """Spec ``{"name", "args"[, "sd"]}`` that :func:`make` rebuilds this encoder from.

        Parameters
        ----------
        with_sd : bool, default=True
            Include the state_dict (``self.state_dict()``: detached tensors on the
            encoder's device, sharing its parameters' storage).

        Returns
        -------
        spec : dict
            ``"name"``: ``"edsr-baseline"``; ``"args"``: a new dict of `channels`,
            `n_resblocks` and `res_scale`; ``"sd"`` if `with_sd`.
        """
        spec = {"name": self.registry_name, "args": dict(self._spec_args)}
        if with_sd:
            spec["sd"] = self.state_dict()
        return spec


class EncodedModel(RangeModel):
    """A range model over the features of an EDSR-baseline encoder (``self.encoder``)."""

    def encode(self, images, wrap):
        """EDSR-baseline features of normalised range images (no input checks).

        Parameters
        ----------
        images : torch.Tensor of shape (B, H, W)
            Range images divided by `max_range` (0 for no return).
        wrap : bool
            Circular horizontal padding of the encoder (360° sensor); replicate otherwise.

        Returns
        -------
        features : torch.Tensor of shape (B, C, H, W)
            ``C`` = `channels`.
        """
        return self.encoder(images[:, None], wrap)
