"""The base of the range-image models: input checks, the neighbourhood lookup, RangeModel.

A query ``(v, u)`` reads the 4 input pixels around it (:func:`neighbourhood`): vertical
neighbours are clamped to the image, horizontal neighbours wrap around for a 360° sensor
(``wrap=True``) and are clamped otherwise. :class:`RangeModel` checks the input of every
model and evaluates its ``query`` in chunks.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np
import torch
from torch import nn

from ..._docfill import fill_doc
from ..._validation import check_bool, check_int, check_real

__all__ = ["MAX_RANGE", "DEFAULT_CHUNK", "as_tensor", "check_image", "check_queries",
           "query_frame", "neighbourhood", "gather", "renormalise", "masked_l1", "LOSS_PARAMS", "query_doc", "RangeModel"]

#: Largest range accepted in an input image, in metres (larger values are bad input).
MAX_RANGE = 1e6

#: Queries evaluated at once by ``predict`` (bounds the memory of one forward pass).
DEFAULT_CHUNK = 65536


def as_tensor(x: Any, name: str) -> tuple[torch.Tensor, bool]:
    """Float32 tensor from numpy / torch / array-like; the flag tells whether it was numpy."""
    if isinstance(x, torch.Tensor):
        if x.dtype.is_complex or x.dtype == torch.bool:
            raise TypeError(f"{name} must hold real numbers, got dtype {x.dtype}")
        return x.detach().to(torch.float32), False
    if isinstance(x, (str, bytes, dict)) or x is None:
        raise TypeError(f"{name} must be a numpy array or a torch tensor, got {type(x).__name__}")
    try:
        arr = np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a numpy array or a torch tensor: {exc}") from None
    if arr.dtype.kind not in "iuf":
        raise TypeError(f"{name} must hold real numbers, got dtype {arr.dtype}")
    return torch.from_numpy(np.ascontiguousarray(arr, dtype=np.float32)), True


def check_image(images: torch.Tensor, name: str = "range_image") -> None:
    """Raise unless `images` is (rows, cols) or (batch, rows, cols), non-empty, in [0, 1e6]."""
    if images.ndim not in (2, 3):
        raise ValueError(
            f"{name} must have shape (rows, cols) or (batch, rows, cols), got {tuple(images.shape)}"
        )
    if images.numel() == 0:
        raise ValueError(f"{name} must not be empty, got shape {tuple(images.shape)}")
    if not bool(torch.isfinite(images).all()):
        raise ValueError(f"{name} must be finite (0 marks no return), got NaN or inf")
    if bool((images < 0).any()):
        raise ValueError(f"{name} must be non-negative (0 marks no return), got a negative range")
    if bool((images > MAX_RANGE).any()):
        raise ValueError(
            f"{name} must hold ranges <= {MAX_RANGE:g} m, got {float(images.max()):g}"
        )


def check_queries(queries: torch.Tensor, rows: int, cols: int, name: str = "queries") -> None:
    """Raise unless `queries` is (n, 2) or (batch, n, 2), finite, within a (rows, cols) image."""
    if queries.ndim not in (2, 3) or queries.shape[-1] != 2:
        raise ValueError(
            f"{name} must have shape (n_queries, 2) or (batch, n_queries, 2) of (v, u) pixel "
            f"coordinates, got {tuple(queries.shape)}"
        )
    if queries.numel() == 0:
        return
    if not bool(torch.isfinite(queries).all()):
        raise ValueError(f"{name} must be finite, got NaN or inf")
    v, u = queries[..., 0], queries[..., 1]
    if bool((v < 0).any() or (v > rows).any() or (u < 0).any() or (u > cols).any()):
        raise ValueError(
            f"{name} must lie within the input image, 0 <= v <= {rows} and 0 <= u <= {cols} "
            f"(pixel units), got v in [{float(v.min()):g}, {float(v.max()):g}] and "
            f"u in [{float(u.min()):g}, {float(u.max()):g}]"
        )


def query_frame(queries: torch.Tensor):
    """Upper row ``i0``, left column ``j0`` (long, unclamped, unwrapped) and the fractions
    ``t`` (towards the lower row) and ``b`` (towards the right column) of queries (..., 2)."""
    v = queries[..., 0] - 0.5
    u = queries[..., 1] - 0.5
    i0 = torch.floor(v)
    j0 = torch.floor(u)
    return i0.long(), j0.long(), v - i0, u - j0


def _neighbours(queries: torch.Tensor, rows: int, cols: int, wrap: bool):
    """The 4 input pixels around each query.

    Returns flat pixel indices (B, N, 4), relative positions pixel center − query in pixels
    (B, N, 4, 2), and the bilinear weights (B, N, 4). Token order: (top, left), (top, right),
    (bottom, left), (bottom, right).
    """
    i0, j0, a, b = query_frame(queries)
    ii = torch.stack([i0, i0, i0 + 1, i0 + 1], dim=-1).clamp_(0, rows - 1)
    jj = torch.stack([j0, j0 + 1, j0, j0 + 1], dim=-1)
    if wrap:
        dv_j = jj.to(queries.dtype) + 0.5  # unwrapped center: |du| <= 1 across the seam
        jj = jj.remainder(cols)
    else:
        jj = jj.clamp_(0, cols - 1)
        dv_j = jj.to(queries.dtype) + 0.5
    dv = ii.to(queries.dtype) + 0.5 - queries[..., 0:1]
    du = dv_j - queries[..., 1:2]
    rel = torch.stack([dv, du], dim=-1)
    wa = torch.stack([1 - a, 1 - a, a, a], dim=-1)
    wb = torch.stack([1 - b, b, 1 - b, b], dim=-1)
    return ii * cols + jj, rel, wa * wb


def gather(flat: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """flat (B, P, C), idx (B, N, 4) -> (B, N, 4, C)."""
    b, n, k = idx.shape
    c = flat.shape[-1]
    out = torch.gather(flat, 1, idx.reshape(b, n * k, 1).expand(b, n * k, c))
    return out.reshape(b, n, k, c)


def neighbourhood(images: torch.Tensor, queries: torch.Tensor, wrap: bool):
    """:func:`_neighbours` of `queries` in `images` (B, H, W), and the 4 neighbours' ranges.

    Returns flat pixel indices (B, N, 4), relative positions (B, N, 4, 2), bilinear weights
    (B, N, 4) and ranges (B, N, 4).
    """
    bsz, rows, cols = images.shape
    idx, rel, wb = _neighbours(queries, rows, cols, wrap)
    r = torch.gather(images.reshape(bsz, -1), 1, idx.reshape(bsz, -1)).reshape(idx.shape)
    return idx, rel, wb, r


#: The input note, Parameters and first Returns lines of every model's ``query`` (filled in
#: by :func:`query_doc`).
_QUERY_SECTIONS = """No input checks (:meth:`predict` and :meth:`weights` check theirs).

Parameters
----------
features : {features}
images : torch.Tensor of shape (B, H, W)
    Range images divided by `max_range` (0 for no return).
queries : torch.Tensor of shape (B, N, 2)
    ``(v, u)`` in the images' pixel units (pixel centers at integer + 0.5),
    ``0 <= v <= H``, ``0 <= u <= W``.
wrap : bool
    Horizontal neighbours wrap around (360° sensor); clamped otherwise. Vertical
    neighbours are always clamped.

Returns
-------
ranges : torch.Tensor of shape (B, N)
    Normalised ranges (metres / `max_range`), 0 for no return.
weights : torch.Tensor of shape (B, N, 4)"""
_ENCODED_FEATURES = ("torch.Tensor of shape (B, C, H, W)\n"
                     "    What :meth:`encode` returned for `images`.")

#: The image and query parameters of :meth:`RangeModel.predict` and :meth:`RangeModel.weights`.
_IMAGE_PARAMS = """Parameters
----------
range_image : array-like or torch.Tensor of shape (rows, cols) or (batch, rows, cols)
    Ranges in metres, 0 where there is no return. Finite, in [0, 1e6].
queries : array-like or torch.Tensor of shape (n_queries, 2) or (batch, n_queries, 2)
    ``(v, u)`` in the input image's pixel units (pixel centers at integer + 0.5), with
    ``0 <= v <= rows`` and ``0 <= u <= cols``. Unbatched queries with a batch of images
    are used for every image.
wrap : bool, optional
    Horizontal neighbours (and encoder padding) wrap around (360° sensor); default: the
    model's `wrap`."""


#: The Parameters section of the training losses (``RangeModel.loss`` and its overrides).
LOSS_PARAMS = """Parameters
----------
images : torch.Tensor of shape (B, H, W)
    Normalised range images.
queries : torch.Tensor of shape (B, N, 2)
    ``(v, u)`` in the images' pixel units.
target : torch.Tensor of shape (B, N)
    True normalised ranges at the queries (0 for no return).
wrap : bool
    Horizontal wrap-around."""


def query_doc(features: str = _ENCODED_FEATURES) -> Callable:
    """Decorator: fill the shared sections into a ``query`` docstring (``{query_sections}``)."""
    return fill_doc(query_sections=_QUERY_SECTIONS.format(features=features))


def masked_l1(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean ``|pred - target|`` over the entries whose target has a return (target > 0).

    Parameters
    ----------
    pred : torch.Tensor
        Predicted (normalised) ranges.
    target : torch.Tensor
        True ranges, same shape as `pred` (or broadcastable to it); 0 marks no return.

    Returns
    -------
    loss : torch.Tensor
        0-d tensor of `pred`'s dtype; 0 when no target has a return.
    """
    mask = (target > 0).to(pred.dtype)
    return (torch.abs(pred - target) * mask).sum() / mask.sum().clamp_min(1.0)


def renormalise(w: torch.Tensor) -> torch.Tensor:
    """`w` (..., 4) divided by its sum over the last axis; all 0 where that sum is ~0."""
    total = w.sum(-1, keepdim=True)
    ok = total > 1e-12
    return torch.where(ok, w / torch.where(ok, total, torch.ones_like(total)), torch.zeros_like(w))


class RangeModel(nn.Module):
    """Base of the range-image models: spec, input checks, chunked ``predict``.

    Subclasses implement ``encode(images, wrap)`` (features or None) and
    ``query(features, images, queries, wrap)`` on normalised ranges, returning ``(pred, weights)``
    with `pred` of shape (B, N) and `weights` (B, N, 4) the final weight of each neighbour
    (interpolation weights for ILN and bilinear, ensemble weights for LIIF).
    """

    registry_name = "?"

    def __init__(self, max_range: float, wrap: bool):
        super().__init__()
        self.max_range = check_real(max_range, "max_range", low=0.0, state_bounds=True)
        self.wrap = check_bool(wrap, "wrap")
        # empty, non-persistent: follows .to(device) so parameter-free models know their device
        self.register_buffer("_probe", torch.zeros(0), persistent=False)

    # -- spec
    def spec(self, with_sd: bool = True) -> dict:
        """Spec ``{"name", "args"[, "sd"]}`` that :func:`make` rebuilds this model from.

        Parameters
        ----------
        with_sd : bool, default=True
            Include the state_dict (tensors detached and moved to the CPU).

        Returns
        -------
        spec : dict
        """
        spec = {"name": self.registry_name, "args": dict(self._spec_args)}
        if with_sd:
            spec["sd"] = {k: v.detach().cpu().clone() for k, v in self.state_dict().items()}
        return spec

    # -- subclass interface
    def encode(self, images: torch.Tensor, wrap: bool) -> torch.Tensor | None:
        """Features of normalised range images; this base (the bilinear model) has none.

        Parameters
        ----------
        images : torch.Tensor of shape (B, H, W)
            Range images divided by `max_range` (0 for no return). Not used here.
        wrap : bool
            Horizontal wrap-around (360° sensor). Not used here.

        Returns
        -------
        None
            Subclasses with an encoder (:class:`ILN`, :class:`LIIF`) return a tensor
            of shape (B, C, H, W).
        """
        return None

    def query(self, features, images, queries, wrap):  # pragma: no cover - abstract
        raise NotImplementedError

    def forward(self, images: torch.Tensor, queries: torch.Tensor, wrap: bool | None = None,
                target: torch.Tensor | None = None) -> torch.Tensor:
        """Normalised ranges at `queries` of normalised images, or the training loss.

        No input checks; :meth:`predict` checks its input and un-normalises. With `target`,
        the training loss of :meth:`loss` (through ``forward``, so that
        ``DistributedDataParallel`` synchronises its gradients).

        Parameters
        ----------
        images : torch.Tensor of shape (B, H, W)
            Range images divided by `max_range` (0 for no return).
        queries : torch.Tensor of shape (B, N, 2)
            ``(v, u)`` in the input images' pixel units (pixel centers at integer + 0.5),
            ``0 <= v <= H``, ``0 <= u <= W``.
        wrap : bool, optional
            Horizontal wrap-around; default: the model's `wrap`.
        target : torch.Tensor of shape (B, N), optional
            True normalised ranges at the queries (0 for no return).

        Returns
        -------
        ranges : torch.Tensor of shape (B, N)
            Normalised ranges (metres / `max_range`), 0 for no return; not clamped
            (the LIIF model may predict below 0). The 0-d loss instead where `target` is given.
        """
        wrap = self.wrap if wrap is None else bool(wrap)
        if target is not None:
            return self.loss(images, queries, target, wrap)
        features = self.encode(images, wrap)
        return self.query(features, images, queries, wrap)[0]

    @fill_doc(loss_params=LOSS_PARAMS)
    def loss(self, images: torch.Tensor, queries: torch.Tensor, target: torch.Tensor,
             wrap: bool) -> torch.Tensor:
        """The training loss: :func:`masked_l1` of the predicted and true normalised ranges.

        {loss_params}

        Returns
        -------
        loss : torch.Tensor
            0-d.
        """
        return masked_l1(self.query(self.encode(images, wrap), images, queries, wrap)[0], target)

    def _device(self) -> torch.device:
        return self._probe.device

    def _prepare(self, range_image, queries):
        images, was_numpy = as_tensor(range_image, "range_image")
        out_device = images.device
        q, _ = as_tensor(queries, "queries")
        check_image(images)
        batched = images.ndim == 3
        if not batched:
            images = images[None]
        bsz, rows, cols = images.shape
        check_queries(q, rows, cols)
        if q.ndim == 3:
            if not batched:
                raise ValueError(
                    f"queries of shape (batch, n_queries, 2) need range_image of shape "
                    f"(batch, rows, cols), got range_image {tuple(images.shape[1:])}"
                )
            if q.shape[0] != bsz:
                raise ValueError(
                    f"queries batch size {q.shape[0]} does not match range_image batch size {bsz}"
                )
        else:
            q = q[None].expand(bsz, -1, -1)
        return images, q, batched, was_numpy, out_device

    @fill_doc(image_params=_IMAGE_PARAMS)
    def predict(self, range_image, queries, wrap: bool | None = None, chunk: int = DEFAULT_CHUNK):
        """Ranges at continuous queries of a range image.

        {image_params}
        chunk : int, default=65536
            Queries evaluated at once per image (memory bound; the result does not depend on it).

        Returns
        -------
        ranges : numpy.ndarray or torch.Tensor of shape (n_queries,) or (batch, n_queries)
            float32 ranges in metres (>= 0), 0 for no return; numpy if `range_image` was not a tensor,
            else a tensor on `range_image`'s device.

        Raises
        ------
        TypeError
            If `range_image` or `queries` is not numeric array data, `wrap` is not a bool (or
            None), or `chunk` is not an int.
        ValueError
            If a shape is wrong (batched queries with an unbatched image, or batch sizes that
            differ), `range_image` is empty, holds NaN, inf, negative ranges or ranges above
            1e6 m, a query is not finite or lies outside the image, or `chunk` < 1.
        """
        chunk = check_int(chunk, "chunk", low=1, state_bounds=True)
        wrap = self.wrap if wrap is None else check_bool(wrap, "wrap")
        images, q, batched, was_numpy, out_device = self._prepare(range_image, queries)
        device = self._device()
        images = images.to(device) / self.max_range
        q = q.to(device)
        n = q.shape[1]
        was_training = self.training
        self.eval()
        try:
            with torch.no_grad():
                features = self.encode(images, wrap)
                parts = [
                    self.query(features, images, q[:, s : s + chunk], wrap)[0]
                    for s in range(0, n, chunk)
                ]
        finally:
            self.train(was_training)
        pred = torch.cat(parts, dim=1) if parts else images.new_zeros((images.shape[0], 0))
        pred = (pred * self.max_range).clamp_min_(0.0)  # LIIF may predict below 0
        if not batched:
            pred = pred[0]
        if was_numpy:
            return pred.cpu().numpy().astype(np.float32, copy=False)
        return pred.to(out_device)

    @fill_doc(image_params=_IMAGE_PARAMS)
    def weights(self, range_image, queries, wrap: bool | None = None) -> np.ndarray:
        """Weights the model gives the 4 neighbours of each query.

        Interpolation weights for :class:`ILN` and :class:`Bilinear`, ensemble (area) weights
        for :class:`LIIF`. Same input rules as :meth:`predict`, evaluated in one pass (no
        chunking).

        {image_params}

        Returns
        -------
        weights : numpy.ndarray of float32, shape (n_queries, 4) or (batch, n_queries, 4)
            Neighbour order (top, left), (top, right), (bottom, left), (bottom, right); 0 for
            no-return neighbours; each row sums to 1, or is all 0 for a query that returns no
            return. Always numpy, whatever the input type.

        Raises
        ------
        TypeError
            If `range_image` or `queries` is not numeric array data, or `wrap` is not a bool
            (or None).
        ValueError
            If a shape is wrong (batched queries with an unbatched image, or batch sizes that
            differ), `range_image` is empty, holds NaN, inf, negative ranges or ranges above
            1e6 m, or a query is not finite or lies outside the image.
        """
        wrap = self.wrap if wrap is None else check_bool(wrap, "wrap")
        images, q, batched, _, _ = self._prepare(range_image, queries)
        device = self._device()
        images = images.to(device) / self.max_range
        was_training = self.training
        self.eval()
        try:
            with torch.no_grad():
                w = self.query(self.encode(images, wrap), images, q.to(device), wrap)[1]
        finally:
            self.train(was_training)
        w = w.cpu().numpy()
        return w if batched else w[0]
