"""Range-image up-sampling models: ILN, a LIIF-style value predictor and bilinear interpolation.

Every model maps a range image and continuous queries ``(v, u)`` in the input image's pixel
coordinates (pixel centres at integer + 0.5, row 0 at the highest elevation) to ranges. A query
reads the 4 input pixels around it: vertical neighbours are clamped to the image, horizontal
neighbours wrap around for a 360° sensor (``wrap=True``) and are clamped otherwise.

Pixels without a return (range 0) are first-class: no model blends a no-return into a range.
A no-return neighbour gets weight 0, and a query whose 4 neighbours all lack a return (or whose
interpolation weight lies entirely on no-return pixels, for the bilinear and LIIF models) returns
0, i.e. no return.

Models are built from specs ``{"name": ..., "args": {...}, "sd": state_dict}`` with :func:`make`,
and new models join the registry with :func:`register` (the LIIF convention).
"""

from __future__ import annotations

import copy
import math
import numbers
from typing import Any, Callable

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

__all__ = [
    "register",
    "make",
    "available_models",
    "EDSRBaseline",
    "ILN",
    "LIIF",
    "Bilinear",
    "InverseBilinear",
    "upsample_image",
]

_MODELS: dict[str, type] = {}

#: Largest range accepted in an input image, in metres (larger values are bad input).
MAX_RANGE = 1e6

#: Queries evaluated at once by ``predict`` (bounds the memory of one forward pass).
DEFAULT_CHUNK = 65536

#: The weight priors of :class:`ILN` (``weight_prior``).
WEIGHT_PRIORS = ("inverse-range", "bilinear", "none")

#: Added to the bilinear weights before their log in ILN's weight prior: a neighbour of
#: bilinear weight 0 starts at a logit of log(1e-4) = -9.2 (reachable, never -inf).
PRIOR_EPS = 1e-4


def register(name: str) -> Callable[[type], type]:
    """Class decorator adding a model class to the registry under `name`.

    Parameters
    ----------
    name : str
        Registry name used in specs (``{"name": name, "args": {...}}``).

    Returns
    -------
    decorator : callable
        Registers the class and returns it unchanged.

    Raises
    ------
    TypeError
        If `name` is not a str.
    ValueError
        If `name` is empty or already registered to another class.
    """
    if not isinstance(name, str):
        raise TypeError(f"name must be a str, got {type(name).__name__}")
    if not name:
        raise ValueError("name must be a non-empty str")

    def decorator(cls: type) -> type:
        if name in _MODELS and _MODELS[name] is not cls:
            raise ValueError(f"model name {name!r} is already registered to {_MODELS[name].__name__}")
        _MODELS[name] = cls
        cls.registry_name = name
        return cls

    return decorator


def available_models() -> list[str]:
    """Names of the registered models, sorted.

    Returns
    -------
    names : list of str
        The names :func:`make` accepts as ``spec["name"]`` (``"bilinear"``,
        ``"edsr-baseline"``, ``"iln"``, ``"liif"`` and any added with
        :func:`register`).
    """
    return sorted(_MODELS)


def make(spec: dict, load_sd: bool = False) -> nn.Module:
    """Build a model from its spec.

    Parameters
    ----------
    spec : dict
        ``{"name": str, "args": dict}``, optionally with ``"sd"`` (a state_dict), as written by
        :meth:`RangeModel.spec` and stored in training checkpoints.
    load_sd : bool, default=False
        Load ``spec["sd"]`` into the new model.

    Returns
    -------
    model : torch.nn.Module
        The model, on the CPU, in training mode.

    Raises
    ------
    TypeError
        If `spec` is not a dict, ``spec["args"]`` is not a dict, or an argument has the wrong type.
    ValueError
        If the name is unknown, an argument is unknown or out of range, or `load_sd` is true and
        the spec has no ``"sd"`` or one that does not fit the model.

    Examples
    --------
    >>> m = make({"name": "iln", "args": {"channels": 16, "n_resblocks": 1, "depth": 1}})
    >>> m2 = make(m.spec(), load_sd=True)
    >>> sorted(m.spec())
    ['args', 'name', 'sd']
    """
    if not isinstance(spec, dict):
        raise TypeError(f"spec must be a dict with keys 'name' and 'args', got {type(spec).__name__}")
    if "name" not in spec:
        raise ValueError("spec must have a 'name' key (one of %s)" % ", ".join(available_models()))
    name = spec["name"]
    if not isinstance(name, str) or name not in _MODELS:
        raise ValueError(f"spec['name'] must be one of {available_models()}, got {name!r}")
    args = spec.get("args", {}) or {}
    if not isinstance(args, dict):
        raise TypeError(f"spec['args'] must be a dict, got {type(args).__name__}")
    cls = _MODELS[name]
    allowed = getattr(cls, "arg_names", None)
    if allowed is not None:
        unknown = sorted(set(args) - set(allowed))
        if unknown:
            raise ValueError(
                f"spec['args'] has unknown argument(s) {unknown} for model {name!r}; "
                f"expected some of {list(allowed)}"
            )
    model = cls(**copy.deepcopy(args))
    if load_sd:
        if "sd" not in spec or spec["sd"] is None:
            raise ValueError("load_sd=True needs spec['sd'] (a state_dict), but the spec has none")
        sd = spec["sd"]
        if not isinstance(sd, dict):
            raise TypeError(f"spec['sd'] must be a state_dict (dict), got {type(sd).__name__}")
        try:
            model.load_state_dict(sd)
        except RuntimeError as exc:
            raise ValueError(f"spec['sd'] does not fit model {name!r} with args {args}: {exc}") from None
    return model


# ----------------------------------------------------------------------------------- validation


def _check_int(value: Any, name: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be an int, got {type(value).__name__}")
    value = int(value)
    if value < low:
        raise ValueError(f"{name} must be >= {low}, got {value}")
    return value


def _check_positive(value: Any, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a real number, got {type(value).__name__}")
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value}")
    return value


def _check_choice(value: Any, name: str, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str):
        raise TypeError(f"{name} must be one of {list(choices)}, got {type(value).__name__}")
    if value not in choices:
        raise ValueError(f"{name} must be one of {list(choices)}, got {value!r}")
    return value


def _check_bool(value: Any, name: str) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} must be a bool, got {type(value).__name__}")
    return bool(value)


def _as_tensor(x: Any, name: str) -> tuple[torch.Tensor, bool]:
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


def _check_image(images: torch.Tensor, name: str = "range_image") -> None:
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


def _check_queries(queries: torch.Tensor, rows: int, cols: int, name: str = "queries") -> None:
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


# -------------------------------------------------------------------------------------- layers


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
        channels = _check_int(channels, "channels", 1)
        n_resblocks = _check_int(n_resblocks, "n_resblocks", 0)
        res_scale = _check_positive(res_scale, "res_scale")
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


def _neighbours(queries: torch.Tensor, rows: int, cols: int, wrap: bool):
    """The 4 input pixels around each query.

    Returns flat pixel indices (B, N, 4), relative positions pixel centre − query in pixels
    (B, N, 4, 2), and the bilinear weights (B, N, 4). Token order: (top, left), (top, right),
    (bottom, left), (bottom, right).
    """
    v = queries[..., 0] - 0.5
    u = queries[..., 1] - 0.5
    i0 = torch.floor(v)
    j0 = torch.floor(u)
    a = v - i0  # fraction towards the lower row
    b = u - j0  # fraction towards the right column
    i0 = i0.long()
    j0 = j0.long()
    ii = torch.stack([i0, i0, i0 + 1, i0 + 1], dim=-1).clamp_(0, rows - 1)
    jj = torch.stack([j0, j0 + 1, j0, j0 + 1], dim=-1)
    if wrap:
        dv_j = jj.to(queries.dtype) + 0.5  # unwrapped centre: |du| <= 1 across the seam
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


def _gather(flat: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """flat (B, P, C), idx (B, N, 4) -> (B, N, 4, C)."""
    b, n, k = idx.shape
    c = flat.shape[-1]
    out = torch.gather(flat, 1, idx.reshape(b, n * k, 1).expand(b, n * k, c))
    return out.reshape(b, n, k, c)


def _neighbourhood(images: torch.Tensor, queries: torch.Tensor, wrap: bool):
    """:func:`_neighbours` of `queries` in `images` (B, H, W), and the 4 neighbours' ranges.

    Returns flat pixel indices (B, N, 4), relative positions (B, N, 4, 2), bilinear weights
    (B, N, 4) and ranges (B, N, 4).
    """
    bsz, rows, cols = images.shape
    idx, rel, wb = _neighbours(queries, rows, cols, wrap)
    r = torch.gather(images.reshape(bsz, -1), 1, idx.reshape(bsz, -1)).reshape(idx.shape)
    return idx, rel, wb, r


#: The Parameters section of every model's ``query`` (filled in by :func:`_query_doc`).
_QUERY_PARAMS = """        Parameters
        ----------
        features : {features}
        images : torch.Tensor of shape (B, H, W)
            Range images divided by `max_range` (0 for no return).
        queries : torch.Tensor of shape (B, N, 2)
            ``(v, u)`` in the images' pixel units (pixel centres at integer + 0.5),
            ``0 <= v <= H``, ``0 <= u <= W``.
        wrap : bool
            Horizontal neighbours wrap around (360° sensor); clamped otherwise. Vertical
            neighbours are always clamped.
"""
_ENCODED_FEATURES = ("torch.Tensor of shape (B, C, H, W)\n"
                     "            What :meth:`encode` returned for `images`.")


def _query_doc(features: str = _ENCODED_FEATURES) -> Callable:
    """Decorator: fill the shared Parameters section into a ``query`` docstring."""
    def fill(method: Callable) -> Callable:
        text = _QUERY_PARAMS.format(features=features)
        method.__doc__ = method.__doc__.replace("{query_params}", text)
        return method
    return fill


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
        self.max_range = _check_positive(max_range, "max_range")
        self.wrap = _check_bool(wrap, "wrap")
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

    def forward(self, images: torch.Tensor, queries: torch.Tensor, wrap: bool | None = None) -> torch.Tensor:
        """Normalised ranges at `queries` of normalised images (the training path).

        No input checks; :meth:`predict` checks its input and un-normalises.

        Parameters
        ----------
        images : torch.Tensor of shape (B, H, W)
            Range images divided by `max_range` (0 for no return).
        queries : torch.Tensor of shape (B, N, 2)
            ``(v, u)`` in the input images' pixel units (pixel centres at integer + 0.5),
            ``0 <= v <= H``, ``0 <= u <= W``.
        wrap : bool, optional
            Horizontal wrap-around; default: the model's `wrap`.

        Returns
        -------
        ranges : torch.Tensor of shape (B, N)
            Normalised ranges (metres / `max_range`), 0 for no return; not clamped
            (the LIIF model may predict below 0).
        """
        wrap = self.wrap if wrap is None else bool(wrap)
        features = self.encode(images, wrap)
        return self.query(features, images, queries, wrap)[0]

    def _device(self) -> torch.device:
        return self._probe.device

    def _prepare(self, range_image, queries):
        images, was_numpy = _as_tensor(range_image, "range_image")
        out_device = images.device
        q, _ = _as_tensor(queries, "queries")
        _check_image(images)
        batched = images.ndim == 3
        if not batched:
            images = images[None]
        bsz, rows, cols = images.shape
        _check_queries(q, rows, cols)
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

    def predict(self, range_image, queries, wrap: bool | None = None, chunk: int = DEFAULT_CHUNK):
        """Ranges at continuous queries of a range image.

        Parameters
        ----------
        range_image : array-like or torch.Tensor of shape (rows, cols) or (batch, rows, cols)
            Ranges in metres, 0 where there is no return. Finite, in [0, 1e6].
        queries : array-like or torch.Tensor of shape (n_queries, 2) or (batch, n_queries, 2)
            ``(v, u)`` in the input image's pixel units (pixel centres at integer + 0.5), with
            ``0 <= v <= rows`` and ``0 <= u <= cols``. Unbatched queries with a batch of images
            are used for every image.
        wrap : bool, optional
            Horizontal neighbours (and encoder padding) wrap around (360° sensor); default: the
            model's `wrap`.
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
        chunk = _check_int(chunk, "chunk", 1)
        wrap = self.wrap if wrap is None else _check_bool(wrap, "wrap")
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

    def weights(self, range_image, queries, wrap: bool | None = None) -> np.ndarray:
        """Weights the model gives the 4 neighbours of each query.

        Interpolation weights for :class:`ILN` and :class:`Bilinear`, ensemble (area) weights
        for :class:`LIIF`. Same input rules as :meth:`predict`, evaluated in one pass (no
        chunking).

        Parameters
        ----------
        range_image : array-like or torch.Tensor of shape (rows, cols) or (batch, rows, cols)
            Ranges in metres, 0 where there is no return. Finite, in [0, 1e6].
        queries : array-like or torch.Tensor of shape (n_queries, 2) or (batch, n_queries, 2)
            ``(v, u)`` in the input image's pixel units (pixel centres at integer + 0.5), with
            ``0 <= v <= rows`` and ``0 <= u <= cols``. Unbatched queries with a batch of images
            are used for every image.
        wrap : bool, optional
            Horizontal neighbours (and encoder padding) wrap around (360° sensor); default: the
            model's `wrap`.

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
        wrap = self.wrap if wrap is None else _check_bool(wrap, "wrap")
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


class _Encoded(RangeModel):
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


@register("iln")
class ILN(_Encoded):
    """Implicit LiDAR Network: predicts interpolation weights over the 4 neighbouring pixels.

    For a query q and each of its 4 neighbouring input pixels t: the encoder feature z_t plus a
    linear embedding of the relative position Δq_t (pixel centre − query, in pixels), and with
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
        channels = _check_int(channels, "channels", 1)
        n_resblocks = _check_int(n_resblocks, "n_resblocks", 0)
        depth = _check_int(depth, "depth", 0)
        heads = _check_int(heads, "heads", 1)
        mlp_ratio = _check_positive(mlp_ratio, "mlp_ratio")
        if depth > 0 and channels % heads:
            raise ValueError(f"channels must be a multiple of heads={heads}, got {channels}")
        self._spec_args = {
            "channels": channels, "n_resblocks": n_resblocks, "depth": depth, "heads": heads,
            "mlp_ratio": mlp_ratio, "max_range": self.max_range, "wrap": self.wrap,
            "range_tokens": _check_bool(range_tokens, "range_tokens"),
            "weight_prior": _check_choice(weight_prior, "weight_prior", WEIGHT_PRIORS),
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

    @_query_doc()
    def query(self, features, images, queries, wrap):
        """Ranges and interpolation weights at queries: Σ w_t r_t over the 4 neighbours.

        No input checks (:meth:`predict` and :meth:`weights` check theirs).

{query_params}
        Returns
        -------
        ranges : torch.Tensor of shape (B, N)
            Normalised ranges (metres / `max_range`), 0 for no return.
        weights : torch.Tensor of shape (B, N, 4)
            Softmax weights of the neighbours (top, left), (top, right), (bottom, left),
            (bottom, right); 0 for no-return neighbours; all 0 when none has a return.
        """
        bsz, n = queries.shape[:2]
        idx, rel, wb, r = _neighbourhood(images, queries, wrap)
        flat = features.flatten(2).transpose(1, 2)  # (B, H*W, C)
        z = _gather(flat, idx) + self.pos_embed(rel)  # (B, N, 4, C)
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


class _MLP(nn.Sequential):
    def __init__(self, d_in: int, hidden: tuple[int, ...], d_out: int):
        layers: list[nn.Module] = []
        for h in hidden:
            layers += [nn.Linear(d_in, h), nn.ReLU()]
            d_in = h
        layers.append(nn.Linear(d_in, d_out))
        super().__init__(*layers)


@register("liif")
class LIIF(_Encoded):
    """LIIF-style value prediction (Eq. 4.2): an MLP predicts a range from each neighbour.

    For each of the 4 neighbouring pixels, an MLP maps ``[z_t, Δq_t]`` (encoder feature and
    relative position in pixels) to a normalised range; the 4 predictions are blended with the
    area weights S_t / S (the area of the rectangle between the query and the diagonally opposite
    pixel centre, i.e. bilinear weights). A prediction from a no-return pixel is dropped and the
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
        channels = _check_int(channels, "channels", 1)
        n_resblocks = _check_int(n_resblocks, "n_resblocks", 0)
        if isinstance(hidden, (str, bytes)) or not hasattr(hidden, "__iter__"):
            raise TypeError(f"hidden must be a list of ints, got {type(hidden).__name__}")
        hidden = tuple(_check_int(h, "hidden[i]", 1) for h in hidden)
        self._spec_args = {
            "channels": channels, "n_resblocks": n_resblocks, "hidden": list(hidden),
            "max_range": self.max_range, "wrap": self.wrap,
        }
        self.encoder = EDSRBaseline(channels, n_resblocks)
        self.imnet = _MLP(channels + 2, hidden, 1)

    @_query_doc()
    def query(self, features, images, queries, wrap):
        """Ranges at queries: the MLP's 4 per-neighbour predictions blended by area weights.

        No input checks (:meth:`predict` and :meth:`weights` check theirs).

{query_params}
        Returns
        -------
        ranges : torch.Tensor of shape (B, N)
            Normalised ranges (metres / `max_range`), 0 for no return.
        weights : torch.Tensor of shape (B, N, 4)
            Renormalised area (bilinear) weights of the neighbours (top, left), (top, right),
            (bottom, left), (bottom, right); 0 for no-return neighbours; all 0 when no weight
            is left (the range is then 0). The ranges are not clamped and may be below 0.
        """
        idx, rel, wb, r = _neighbourhood(images, queries, wrap)
        flat = features.flatten(2).transpose(1, 2)
        z = torch.cat([_gather(flat, idx), rel], dim=-1)  # (B, N, 4, C + 2)
        values = self.imnet(z).squeeze(-1)  # (B, N, 4)
        w = _renormalise(wb * (r > 0))
        return (w * values).sum(-1), w


def _renormalise(w: torch.Tensor) -> torch.Tensor:
    total = w.sum(-1, keepdim=True)
    ok = total > 1e-12
    return torch.where(ok, w / torch.where(ok, total, torch.ones_like(total)), torch.zeros_like(w))


@register("bilinear")
class Bilinear(RangeModel):
    """Bilinear interpolation of the 4 neighbouring pixels (no parameters).

    With 4 returns this is the textbook formula. No-return neighbours are dropped and the
    weights of the others renormalised; a query whose weight lies entirely on no-return pixels
    (all 4 lack a return, or it sits on a no-return pixel's centre line) returns 0.

    Parameters
    ----------
    max_range : float, default=80.0
        Normalising range in metres (no effect on the result).
    wrap : bool, default=True
        Horizontal wrap-around (360° sensors).
    """

    arg_names = ("max_range", "wrap")

    def __init__(self, max_range: float = 80.0, wrap: bool = True):
        super().__init__(max_range, wrap)
        self._spec_args = {"max_range": self.max_range, "wrap": self.wrap}

    @staticmethod
    def _neighbour_weights(wb: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
        return _renormalise(wb * (r > 0))

    @_query_doc(features="None\n            What :meth:`encode` returned (ignored).")
    def query(self, features, images, queries, wrap):
        """Interpolation at queries (see the class), no-return neighbours dropped.

        No input checks (:meth:`predict` and :meth:`weights` check theirs).

{query_params}
        Returns
        -------
        ranges : torch.Tensor of shape (B, N)
            Normalised ranges (metres / `max_range`), 0 for no return.
        weights : torch.Tensor of shape (B, N, 4)
            The interpolation weights of the neighbours (top, left), (top, right),
            (bottom, left), (bottom, right), renormalised over those with a return; 0 for
            no-return neighbours; all 0 when no bilinear weight lies on a return (the range
            is then 0).
        """
        _, _, wb, r = _neighbourhood(images, queries, wrap)
        w = self._neighbour_weights(wb, r)
        return (w * r).sum(-1), w


@register("inverse-bilinear")
class InverseBilinear(Bilinear):
    """Bilinear interpolation of the inverse ranges of the 4 neighbouring pixels (no parameters).

    On a plane ``n . x = d`` a beam of direction ``e`` has ``1 / r = (n . e) / d``, linear in
    ``e``: interpolating ``1 / r`` is exact to first order in the beam spacing on ground and walls,
    where interpolating ``r`` (:class:`Bilinear`) bends the plane. It is the weight prior of
    :class:`ILN` (``weight_prior="inverse-range"``, which is this model before any training) and
    a no-training baseline of its own. As a convex combination of the ranges its weights are
    ``b_t / r_t`` renormalised (``b_t`` the bilinear weights); no-return neighbours are dropped
    as in :class:`Bilinear`.

    Parameters
    ----------
    max_range : float, default=80.0
        Normalising range in metres (no effect on the result).
    wrap : bool, default=True
        Horizontal wrap-around (360° sensors).
    """

    @staticmethod
    def _neighbour_weights(wb: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
        valid = r > 0
        return _renormalise(torch.where(valid, wb / torch.where(valid, r, torch.ones_like(r)), 0.0))


# ------------------------------------------------------------------------------- full images


def _check_lidar_model(m: Any, name: str) -> None:
    for attr in ("rows", "cols", "vertical_fov", "horizontal_fov"):
        if not hasattr(m, attr):
            raise TypeError(f"{name} must be a LidarModel (occgp.iln), got {type(m).__name__}")


def _pixel_angles(m) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) elevation and azimuth grids in degrees (the occgp.iln convention)."""
    if hasattr(m, "pixel_angles"):
        elev, azim = m.pixel_angles()
        return np.asarray(elev, dtype=np.float64), np.asarray(azim, dtype=np.float64)
    low, high = (float(a) for a in m.vertical_fov)
    hfov = float(m.horizontal_fov)
    e = high - (np.arange(m.rows) + 0.5) * (high - low) / m.rows
    a = hfov / 2 - (np.arange(m.cols) + 0.5) * hfov / m.cols
    return np.broadcast_to(e[:, None], (m.rows, m.cols)), np.broadcast_to(a[None], (m.rows, m.cols))


def _angles_to_pixels(m, elev: np.ndarray, azim: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fractional (v, u) of angles in model `m` (pixel centres at integer + 0.5); u wraps at 360°."""
    if hasattr(m, "angles_to_pixels"):
        v, u = m.angles_to_pixels(elev, azim)
        return np.asarray(v, dtype=np.float64), np.asarray(u, dtype=np.float64)
    low, high = (float(a) for a in m.vertical_fov)
    hfov = float(m.horizontal_fov)
    v = (high - elev) * m.rows / (high - low)
    u = (hfov / 2 - ((azim + 180.0) % 360.0 - 180.0)) * m.cols / hfov
    if hfov >= 360.0:
        u = np.mod(u, m.cols)
    return v, u


def upsample_image(model: RangeModel, image, in_model, out_model, chunk: int = DEFAULT_CHUNK):
    """Full range image of `out_model`'s resolution from an image of `in_model`.

    Every out-resolution pixel centre is converted to its elevation and azimuth, then to
    fractional pixel coordinates of `in_model`, and queried. Pixels outside `in_model`'s field of
    view get 0 (no return).

    Parameters
    ----------
    model : RangeModel
        An ILN, LIIF or bilinear model (see :func:`make`).
    image : array-like or torch.Tensor of shape (in_model.rows, in_model.cols) or (batch, rows, cols)
        Input ranges in metres, 0 for no return.
    in_model, out_model : LidarModel
        Sensor models of the input and the output image.
    chunk : int, default=65536
        Queries evaluated at once.

    Returns
    -------
    ranges : numpy.ndarray or torch.Tensor of shape (out_model.rows, out_model.cols) or (batch, ...)
        float32 ranges, 0 for no return (numpy unless `image` is a tensor).

    Raises
    ------
    TypeError
        If `model` is not a RangeModel or `in_model` / `out_model` are not LidarModels.
    ValueError
        If `image`'s shape does not match `in_model`, or `image` is empty or holds NaN, inf or
        negative ranges.

    Examples
    --------
    >>> from types import SimpleNamespace as M
    >>> lo = M(rows=2, cols=4, vertical_fov=(-15.0, 15.0), horizontal_fov=360.0)
    >>> hi = M(rows=4, cols=4, vertical_fov=(-15.0, 15.0), horizontal_fov=360.0)
    >>> upsample_image(make({"name": "bilinear"}), np.full((2, 4), 5.0), lo, hi).shape
    (4, 4)
    """
    if not isinstance(model, RangeModel):
        raise TypeError(f"model must be an occgp.iln model (see make), got {type(model).__name__}")
    _check_lidar_model(in_model, "in_model")
    _check_lidar_model(out_model, "out_model")
    images, was_numpy = _as_tensor(image, "image")
    _check_image(images, "image")
    if tuple(images.shape[-2:]) != (in_model.rows, in_model.cols):
        raise ValueError(
            f"image must have shape ({in_model.rows}, {in_model.cols}) of in_model "
            f"(optionally with a leading batch axis), got {tuple(images.shape)}"
        )
    elev, azim = _pixel_angles(out_model)
    v, u = _angles_to_pixels(in_model, elev.ravel(), azim.ravel())
    eps = 1e-4
    inside = (v >= -eps) & (v <= in_model.rows + eps) & (u >= -eps) & (u <= in_model.cols + eps)
    q = np.stack([np.clip(v, 0, in_model.rows), np.clip(u, 0, in_model.cols)], axis=-1)[inside]
    wrap = float(in_model.horizontal_fov) >= 360.0
    pred = model.predict(images, q.astype(np.float32), wrap=wrap, chunk=chunk)
    shape = tuple(images.shape[:-2]) + (out_model.rows * out_model.cols,)
    out = torch.zeros(shape, dtype=torch.float32, device=pred.device)
    out[..., torch.from_numpy(inside).to(pred.device)] = pred
    out = out.reshape(tuple(images.shape[:-2]) + (out_model.rows, out_model.cols))
    if was_numpy:
        return out.cpu().numpy()
    return out.to(images.device)
