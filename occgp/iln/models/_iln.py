"""ILN: interpolation weights over the 4 neighbouring pixels, from a small transformer."""

from __future__ import annotations

import torch
from torch import nn

from ..._validation import check_bool, check_choice, check_int, check_real
from ._base import gather, neighbourhood, query_doc
from ._encoder import EDSRBaseline, EncodedModel
from ._registry import register

__all__ = ["ILN", "WEIGHT_PRIORS", "PRIOR_EPS"]

#: The weight priors of :class:`ILN` (``weight_prior``).
WEIGHT_PRIORS = ("inverse-range", "bilinear", "none")

#: Added to the bilinear weights before their log in ILN's weight prior: a neighbour of
#: bilinear weight 0 starts at a logit of log(1e-4) = -9.2 (reachable, never -inf).
PRIOR_EPS = 1e-4


class _SelfAttention(nn.Module):
    """Multi-head self-attention over the 4 tokens of each query."""

    def __init__(self, dim: int, heads: int):
        super().__init__()
        self.heads = heads
        self.qkv = nn.Linear(dim, 3 * dim)
        self.proj = nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        n, t, c = x.shape
        d = c // self.heads
        q, k, v = self.qkv(x).reshape(n, t, 3, self.heads, d).permute(2, 0, 3, 1, 4)
        # explicit matmuls: faster than scaled_dot_product_attention for 4 tokens (fwd + bwd)
        att = torch.softmax((q @ k.transpose(-1, -2)) * d**-0.5, dim=-1)  # (n, heads, t, t)
        return self.proj((att @ v).transpose(1, 2).reshape(n, t, c))


class _PreNormBlock(nn.Module):
    """Pre-norm transformer block: x + MHA(LN(x)), then x + MLP(LN(x))."""

    def __init__(self, dim: int, heads: int, mlp_dim: int):
        super().__init__()
        self.norm1 = nn.LayerNorm(dim)
        self.attn = _SelfAttention(dim, heads)
        self.norm2 = nn.LayerNorm(dim)
        self.mlp = nn.Sequential(nn.Linear(dim, mlp_dim), nn.GELU(), nn.Linear(mlp_dim, dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x + self.attn(self.norm1(x))
        return x + self.mlp(self.norm2(x))


@register("iln")
class ILN(EncodedModel):
    """Implicit LiDAR Network: predicts interpolation weights over the 4 neighbouring pixels.

    For a query q and each of its 4 neighbouring input pixels t: the encoder feature z_t plus a
    linear embedding of the relative position Δq_t (pixel center − query, in pixels), and with
    `range_tokens` one of its relative log range, gives the token z'_t; a pre-norm transformer of
    depth `depth` (`heads` heads) mixes the 4 tokens; a shared linear head, plus the fixed
    `weight_prior`, and a softmax give w_t, and the output is Σ w_t r_t (Eq. 4.3) with r_t the
    neighbours' input ranges. No-return neighbours are masked out before the softmax; a query whose
    neighbours all lack a return returns 0 (no return). The output is therefore a convex
    combination of the neighbours with returns. Inputs are normalised by `max_range`.
    ``range_tokens=False, weight_prior="none"`` is the dissertation's ILN.

    Parameters
    ----------
    channels : int, default=64
        Encoder feature channels (a multiple of `heads` when `depth` > 0).
    n_resblocks : int, default=16
        Residual blocks of the EDSR-baseline encoder.
    depth : int, default=1
        Transformer blocks; 0 drops the attention (Fig. 4.8's ablation).
    heads : int, default=8
        Attention heads.
    mlp_ratio : float, default=2.0
        Hidden width of each block's MLP as a multiple of `channels`.
    max_range : float, default=80.0
        Normalising range in metres (the sensor's maximum range).
    wrap : bool, default=True
        Horizontal wrap-around (360° sensors).
    range_tokens : bool, default=True
        Also add to each token a linear embedding of its neighbour's log range relative to the
        mean log range of the query's neighbours with returns. Interpolation weights of the form
        ``softmax(log b_t - log r_t)`` (``b_t`` bilinear weights) interpolate the inverse range,
        which is exact on flat ground; with this embedding they lie one linear map away from the
        tokens, where from the encoder's features alone they have to be learnt over the whole
        dynamic range of the sensor. False gives the token of the dissertation (feature plus
        position embedding only).
    weight_prior : {"inverse-range", "bilinear", "none"}, default="inverse-range"
        A fixed term added to the logits, so that the network learns a correction to a known
        interpolation rather than the interpolation itself; its head starts at zero, so an
        untrained model *is* the prior. ``"bilinear"`` adds ``log(b_t + 1e-4)`` (``b_t`` the
        bilinear weights): bilinear interpolation of the ranges. ``"inverse-range"`` also
        subtracts ``log r_t``: bilinear interpolation of the inverse ranges, exact to first
        order on any plane (``1 / r`` is linear in the beam direction there), so on ground and
        walls. ``"none"`` is the dissertation's ILN (weights learnt from scratch, default
        initialisation of the head). Outputs stay convex combinations of the neighbours with
        returns.

    References
    ----------
    Kwon, Y., Sung, M., Yoon, S.-E. "Implicit LiDAR Network: LiDAR Super-Resolution via
    Interpolation Weight Prediction", ICRA 2022.
    """

    arg_names = ("channels", "n_resblocks", "depth", "heads", "mlp_ratio", "max_range", "wrap",
                 "range_tokens", "weight_prior")

    def __init__(
        self,
        channels: int = 64,
        n_resblocks: int = 16,
        depth: int = 1,
        heads: int = 8,
        mlp_ratio: float = 2.0,
        max_range: float = 80.0,
        wrap: bool = True,
        range_tokens: bool = True,
        weight_prior: str = "inverse-range",
    ):
        super().__init__(max_range, wrap)
        channels = check_int(channels, "channels", low=1, state_bounds=True)
        n_resblocks = check_int(n_resblocks, "n_resblocks", low=0, state_bounds=True)
        depth = check_int(depth, "depth", low=0, state_bounds=True)
        heads = check_int(heads, "heads", low=1, state_bounds=True)
        mlp_ratio = check_real(mlp_ratio, "mlp_ratio", low=0.0, state_bounds=True)
        if depth > 0 and channels % heads:
            raise ValueError(f"channels must be a multiple of heads={heads}, got {channels}")
        self._spec_args = {
            "channels": channels, "n_resblocks": n_resblocks, "depth": depth, "heads": heads,
            "mlp_ratio": mlp_ratio, "max_range": self.max_range, "wrap": self.wrap,
            "range_tokens": check_bool(range_tokens, "range_tokens"),
            "weight_prior": check_choice(weight_prior, "weight_prior", list(WEIGHT_PRIORS),
                                         strict_type=True),
        }
        self.encoder = EDSRBaseline(channels, n_resblocks)
        self.pos_embed = nn.Linear(2, channels)
        self.range_embed = nn.Linear(1, channels) if self._spec_args["range_tokens"] else None
        mlp_dim = max(1, int(round(mlp_ratio * channels)))
        self.blocks = nn.ModuleList(_PreNormBlock(channels, heads, mlp_dim) for _ in range(depth))
        self.norm = nn.LayerNorm(channels) if depth > 0 else nn.Identity()
        self.head = nn.Linear(channels, 1)
        if self._spec_args["weight_prior"] != "none":
            nn.init.zeros_(self.head.weight)
            nn.init.zeros_(self.head.bias)

    @query_doc()
    def query(self, features, images, queries, wrap):
        """Ranges and interpolation weights at queries: Σ w_t r_t over the 4 neighbours.

        {query_sections}
            Softmax weights of the neighbours (top, left), (top, right), (bottom, left),
            (bottom, right); 0 for no-return neighbours; all 0 when none has a return.
        """
        bsz, n = queries.shape[:2]
        idx, rel, wb, r = neighbourhood(images, queries, wrap)
        flat = features.flatten(2).transpose(1, 2)  # (B, H*W, C)
        z = gather(flat, idx) + self.pos_embed(rel)  # (B, N, 4, C)
        valid = r > 0
        log_r = torch.log(torch.where(valid, r, torch.ones_like(r)))  # 0 where no return
        if self.range_embed is not None:
            count = valid.sum(-1, keepdim=True).clamp_min(1)
            mean = log_r.sum(-1, keepdim=True) / count  # no-return tokens hold log 1 = 0
            z = z + self.range_embed(torch.where(valid, log_r - mean, 0.0)[..., None])
        x = z.reshape(bsz * n, 4, -1)
        for block in self.blocks:
            x = block(x)
        logits = self.head(self.norm(x)).reshape(bsz, n, 4)
        prior = self._spec_args["weight_prior"]
        if prior != "none":
            logits = logits + torch.log(wb + PRIOR_EPS)
            if prior == "inverse-range":
                logits = logits - log_r
        logits = logits.masked_fill(~valid, torch.finfo(logits.dtype).min)
        w = torch.softmax(logits, dim=-1) * valid.any(dim=-1, keepdim=True)
        return (w * r).sum(-1), w
