"""A learnt selector over analytic interpolation candidates: inverse bilinear unless it is sure."""

from __future__ import annotations

import torch
from torch import nn

from ..._validation import check_bool, check_int, check_real
from ..._docfill import fill_doc
from ._base import LOSS_PARAMS, RangeModel, neighbourhood, query_doc, query_frame
from ._candidates import (
    CANDIDATES, FIRST_EXTENSION, N_CANDIDATES, NO_RETURN, PRIOR, candidates, inverse,
    inverse_weights,
)
from ._registry import register

__all__ = ["CandidateSelector", "N_FEATURES", "DEFAULT_THRESHOLD", "selector_labels",
           "hard_queries", "choose_candidates", "PLANAR_TOLERANCE", "DEFAULT_TIE",
           "DEFAULT_NO_RETURN_THRESHOLD"]

#: Clip of the log ratios of the features (a factor e**4 = 55 in range).
_CLIP = 4.0
#: Features of a query: 16 pixel log ratios and 16 return flags of the 4 x 4 pixels, 8 candidate
#: log ratios (up .. ext-right), 10 existence flags, t - 1/2, b - 1/2 and the prior's log range
#: (nothing tied to a sensor's geometry, such as the row's height in the image).
N_FEATURES = 16 + 16 + 8 + 10 + 3
#: Default confidence a non-prior candidate needs to replace the prior.
DEFAULT_THRESHOLD = 0.5
#: Default confidence the no-return candidate needs (a wrong no-return costs the whole range).
DEFAULT_NO_RETURN_THRESHOLD = 0.9
#: Default tie margin of the training labels, metres (:func:`selector_labels`).
DEFAULT_TIE = 0.02
#: Relative agreement, in 1 / r, of a planar extension with the prior that makes a query planar
#: (:func:`hard_queries`).
PLANAR_TOLERANCE = 0.05


def _log_ratio(x: torch.Tensor, ref: torch.Tensor) -> torch.Tensor:
    """``log(x / ref)`` clipped to [-4, 4], 0 where ``x`` is 0."""
    ok = x > 0
    ratio = torch.where(ok, x, ref) / ref
    return torch.where(ok, torch.log(ratio).clamp(-_CLIP, _CLIP), torch.zeros_like(x))


def _features(ranges, exists, px, queries):
    """(B, N, N_FEATURES) features of queries from their candidates and 4 x 4 pixels."""
    prior = ranges[..., PRIOR]
    ref = torch.where(prior > 0, prior, torch.ones_like(prior))  # max range without a prior
    inv_ref = inverse(ref)[..., None]
    pix = px.flatten(-2)
    # ratios of inverse ranges, i.e. ref / r: 0 for no return
    f_pix = _log_ratio(inverse(pix), inv_ref)
    f_cand = _log_ratio(inverse(ranges[..., 1:NO_RETURN]), inv_ref)
    _, _, t, b = query_frame(queries)
    extra = torch.stack([t - 0.5, b - 0.5, torch.log(ref).clamp_min(-8.0) / 4.0], dim=-1)
    return torch.cat([f_pix, (pix > 0).to(pix.dtype), f_cand, exists.to(pix.dtype), extra], -1)


def hard_queries(ranges: torch.Tensor, exists: torch.Tensor, px: torch.Tensor,
                 tolerance: float = PLANAR_TOLERANCE) -> torch.Tensor:
    """Queries where the planar test fails or a neighbour has no return.

    The planar test passes where the prior has a return and a vertical extension (``ext-up``
    or ``ext-down``) lies within `tolerance` of it, relatively in ``1 / r`` (the edge test of
    :class:`EdgeAwareInterpolation`).

    Parameters
    ----------
    ranges : torch.Tensor of shape (B, N, 10)
        The candidates' normalised ranges (:func:`candidates`).
    exists : torch.Tensor of bool, shape (B, N, 10)
        Which candidates exist.
    px : torch.Tensor of shape (B, N, 4, 4)
        The 4 x 4 input pixels around each query (the inner 2 x 2 are its neighbours).
    tolerance : float, default=0.05
        Relative agreement in ``1 / r``.

    Returns
    -------
    hard : torch.Tensor of bool, shape (B, N)
    """
    inv_prior = inverse(ranges[..., PRIOR])
    vertical = slice(FIRST_EXTENSION, FIRST_EXTENSION + 2)  # ext-up, ext-down
    inv_ext = inverse(ranges[..., vertical])
    agree = exists[..., vertical] & ((inv_ext - inv_prior[..., None]).abs()
                                <= tolerance * inv_prior[..., None])
    planar = (inv_prior > 0) & agree.any(-1)
    missing = (px[..., 1:3, 1:3] <= 0).flatten(-2).any(-1)
    return ~planar | missing


def selector_labels(ranges: torch.Tensor, exists: torch.Tensor, target: torch.Tensor,
                    tie: float) -> torch.Tensor:
    """The best candidate of each query, near-ties going to the earlier candidate.

    The error of a candidate is its absolute range error; a candidate with a return where the
    truth has none, and a no-return where the truth has one, err by 1 (the normalised maximum
    range). The label is the first candidate, in the order of :data:`CANDIDATES`, whose error
    is within `tie` of the best: the prior whenever it is that close, else a copy before an
    extension (a copy is a convex combination of input pixels, an extension amplifies their
    noise).

    Parameters
    ----------
    ranges : torch.Tensor of shape (B, N, 10)
        The candidates' normalised ranges (:func:`candidates`).
    exists : torch.Tensor of bool, shape (B, N, 10)
        Which candidates exist (a missing one is never the label).
    target : torch.Tensor of shape (B, N)
        True normalised ranges (0 for no return).
    tie : float
        Margin in normalised range (metres / ``max_range``).

    Returns
    -------
    labels : torch.Tensor of int64, shape (B, N)
        Indices into :data:`CANDIDATES`.
    """
    truth = target[..., None]
    hit = truth > 0
    has = ranges > 0
    err = torch.where(hit & has, (ranges - truth).abs(), torch.ones_like(ranges))
    err = torch.where(~hit & ~has, torch.zeros_like(err), err)
    err = torch.where(exists, err, torch.full_like(err, float("inf")))
    near = err <= err.min(-1, keepdim=True).values + tie
    return near.to(torch.int8).argmax(-1)  # the first candidate within `tie` of the best


@register("selector")
class CandidateSelector(RangeModel):
    """Inverse bilinear interpolation, replaced where a small classifier is confident.

    Each query gets the ten analytic candidates of :mod:`occgp.iln.models._candidates`:
    inverse bilinear (the prior), copies of the upper or lower row and of the left or right
    column, the planar extensions of ``1 / r`` from the two rows above, the two below, the two
    columns to the left or to the right, and no return. A multi-layer perceptron reads the
    query's 4 x 4 input pixels (log ratios of their ranges to the prior's, and which have a
    return), the candidates' log ratios and existence, the query's fractional position between
    its neighbours and the prior's range, and gives a probability to each candidate
    (missing ones get 0). The query takes the most probable candidate other than the prior
    when its probability is at least `threshold` (`no_return_threshold` for no return) and
    above the prior's; else the prior.

    The last layer starts at zero, so an untrained model gives every candidate the same
    probability and *is* inverse bilinear interpolation; training
    (:func:`occgp.iln.training.train` with ``loss: select``) minimises the cross-entropy
    towards each query's best candidate, ties going to the prior (:func:`selector_labels`).
    On a plane the extensions agree with the prior, and a model sure of nothing keeps it;
    the candidates the network may choose never blend two surfaces, so across a depth edge
    the query takes one of them.

    Parameters
    ----------
    hidden : int, default=64
        Width of the two hidden layers.
    threshold : float, default=0.5
        Confidence a candidate other than the prior needs, in [0, 1] (1 keeps the prior
        everywhere). The shipped model's value was chosen on held-out training scenes.
    no_return_threshold : float, default=0.9
        Confidence the no-return candidate needs, in [0, 1], on top of `threshold` (a
        no-return where the truth has a return errs by the whole range; a return where the
        truth has none only costs precision). Below it the query takes the best of the other
        candidates, or the prior.
    max_range : float, default=80.0
        Normalising range in metres.
    wrap : bool, default=True
        Horizontal wrap-around (360° sensors).
    max_farther : float, optional
        Never choose a candidate whose range exceeds the prior's by more than this fraction
        (None: no limit). An occupancy map suffers most from ranges that are too long: the
        ray then frees the cells of the surface it should have ended on. With 0.02 the
        selector only ever shortens the prior's range (by a copy or an extension of the
        nearer surface) or keeps it, which raises a map's AUC and lowers the range-image
        scores (see the user guide). Prediction only; the training ignores it.
    tie : float, default=0.02
        Training only: the prior is the label of a query whose prior errs by at most `tie`
        metres more than the best candidate; >= 0.

    Notes
    -----
    The weights (:meth:`weights`) of a query are those of its candidate over the 4
    neighbours: the inverse bilinear weights, one row's or one column's inverse-range
    weights for a copy, all 0 for no return. An extension reads a row or column beyond the 4
    neighbours and is not a convex combination of them; its weights are those of the copy of
    the row or column it extends (where its value comes from).
    """

    arg_names = ("hidden", "threshold", "no_return_threshold", "max_farther", "max_range", "wrap",
                 "tie")

    def __init__(self, hidden: int = 64, threshold: float = DEFAULT_THRESHOLD,
                 no_return_threshold: float = DEFAULT_NO_RETURN_THRESHOLD,
                 max_farther: float | None = None, max_range: float = 80.0, wrap: bool = True,
                 tie: float = DEFAULT_TIE):
        super().__init__(max_range, wrap)
        hidden = check_int(hidden, "hidden", low=1, high=4096, state_bounds=True)
        self.threshold = check_real(threshold, "threshold", low=0.0, high=1.0, low_open=False,
                                    high_open=False, state_bounds=True)
        self.tie = check_real(tie, "tie", low=0.0, high=1e6, low_open=False, state_bounds=True)
        self.no_return_threshold = check_real(
            no_return_threshold, "no_return_threshold", low=0.0, high=1.0, low_open=False,
            high_open=False, state_bounds=True)
        self.max_farther = None if max_farther is None else check_real(
            max_farther, "max_farther", low=0.0, high=1e6, low_open=False, state_bounds=True)
        self.hidden = hidden
        self.net = nn.Sequential(nn.Linear(N_FEATURES, hidden), nn.GELU(),
                                 nn.Linear(hidden, hidden), nn.GELU(),
                                 nn.Linear(hidden, N_CANDIDATES))
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)

    @property
    def _spec_args(self):
        # from the attributes, so that a threshold set after construction is in the spec
        return {"hidden": self.hidden, "threshold": self.threshold,
                "no_return_threshold": self.no_return_threshold, "max_farther": self.max_farther,
                "max_range": self.max_range, "wrap": self.wrap, "tie": self.tie}

    def logits(self, images: torch.Tensor, queries: torch.Tensor, wrap: bool):
        """Candidate logits of queries (missing candidates at the dtype's minimum).

        Parameters
        ----------
        images : torch.Tensor of shape (B, H, W)
            Normalised range images.
        queries : torch.Tensor of shape (B, N, 2)
            ``(v, u)`` in the images' pixel units.
        wrap : bool
            Horizontal wrap-around.

        Returns
        -------
        logits : torch.Tensor of shape (B, N, 10)
        ranges : torch.Tensor of shape (B, N, 10)
            The candidates' normalised ranges (:func:`candidates`).
        exists : torch.Tensor of bool, shape (B, N, 10)
        """
        ranges, exists, px = candidates(images, queries, wrap)
        z = self.net(_features(ranges, exists, px, queries))
        return z.masked_fill(~exists, torch.finfo(z.dtype).min), ranges, exists

    @query_doc(features="None\n    What :meth:`encode` returned (ignored).")
    def query(self, features, images, queries, wrap):
        """The chosen candidate's range at queries (see the class).

        {query_sections}
            The weights of the chosen candidate over the 4 neighbours (see Notes of the
            class).
        """
        logits, ranges, exists = self.logits(images, queries, wrap)
        choice = self.choose(self._limit(logits, ranges))
        w, r = _choice_weights(images, queries, wrap, choice)
        # a convex combination of the neighbours, in the arithmetic of InverseBilinear; the
        # extensions' own values
        extension = (choice >= FIRST_EXTENSION) & (choice < NO_RETURN)
        pred = torch.where(extension, torch.gather(ranges, -1, choice[..., None])[..., 0],
                           (w * r).sum(-1))
        return pred, w

    @fill_doc(loss_params=LOSS_PARAMS)
    def loss(self, images, queries, target, wrap):
        """Cross-entropy of the candidate probabilities towards :func:`selector_labels`.

        {loss_params}

        Returns
        -------
        loss : torch.Tensor
            0-d, the mean over the queries.
        """
        logits, ranges, exists = self.logits(images, queries, wrap)
        labels = selector_labels(ranges, exists, target, self.tie / self.max_range)
        return nn.functional.cross_entropy(logits.flatten(0, -2), labels.flatten())

    def _limit(self, logits, ranges):
        """`logits` with the candidates farther than `max_farther` allows masked out."""
        if self.max_farther is None:
            return logits
        far = ranges > ranges[..., PRIOR:PRIOR + 1] * (1.0 + self.max_farther)
        far[..., PRIOR] = False
        return logits.masked_fill(far, torch.finfo(logits.dtype).min)

    def choose(self, logits: torch.Tensor) -> torch.Tensor:
        """Index of the chosen candidate from logits (B, N, 10): (B, N) long.

        Parameters
        ----------
        logits : torch.Tensor of shape (B, N, 10)

        Returns
        -------
        choice : torch.Tensor of shape (B, N), long
        """
        return choose_candidates(torch.softmax(logits, dim=-1), self.threshold,
                                 self.no_return_threshold)

    @torch.no_grad()
    def candidate_table(self, range_image, queries, wrap: bool | None = None):
        """Every candidate's range and probability at queries (what the choice is made from).

        Parameters
        ----------
        range_image : array-like of shape (rows, cols)
            Ranges in metres, 0 where there is no return (the input rules of :meth:`predict`).
        queries : array-like of shape (n_queries, 2)
            ``(v, u)`` in the input image's pixel units.
        wrap : bool, optional
            Horizontal wrap-around; default: the model's `wrap`.

        Returns
        -------
        ranges : numpy.ndarray of float32, shape (n_queries, 10)
            The candidates of :data:`~occgp.iln.models.CANDIDATES` in metres (0 for no return
            and for a candidate that does not exist).
        probabilities : numpy.ndarray of float32, shape (n_queries, 10)
            The network's probabilities (0 for a candidate that does not exist or that
            `max_farther` excludes).

        Raises
        ------
        TypeError, ValueError
            As :meth:`predict`, and ValueError for a batch of images.
        """
        wrap = self.wrap if wrap is None else check_bool(wrap, "wrap")
        images, q, batched, _, _ = self._prepare(range_image, queries)
        if batched:
            raise ValueError("range_image must be one image (rows, cols) here, got a batch")
        device = self._device()
        was_training = self.training
        self.eval()
        try:
            logits, ranges, _ = self.logits(images.to(device) / self.max_range, q.to(device), wrap)
        finally:
            self.train(was_training)
        p = torch.softmax(self._limit(logits, ranges), dim=-1)
        return ((ranges[0] * self.max_range).cpu().numpy(), p[0].cpu().numpy())


def choose_candidates(probabilities, threshold: float,
                      no_return_threshold: float = DEFAULT_NO_RETURN_THRESHOLD):
    """The selector's choice from candidate probabilities (see :class:`CandidateSelector`).

    Parameters
    ----------
    probabilities : torch.Tensor or numpy.ndarray of shape (..., 10)
        Candidate probabilities in the order of :data:`~occgp.iln.models.CANDIDATES`.
    threshold : float
        Confidence a candidate other than the prior needs.
    no_return_threshold : float, default=0.9
        Confidence the no-return candidate needs.

    Returns
    -------
    choice : torch.Tensor or numpy.ndarray of int64, shape (...)
        The index of the chosen candidate (numpy for numpy input).
    """
    was_numpy = not isinstance(probabilities, torch.Tensor)
    p = torch.as_tensor(probabilities)
    others = p.clone()
    others[..., PRIOR] = -1.0
    drop = others[..., NO_RETURN] < no_return_threshold
    others[..., NO_RETURN] = torch.where(drop, -1.0, others[..., NO_RETURN])
    best = others.max(-1)
    take = (best.values >= threshold) & (best.values > p[..., PRIOR])
    choice = torch.where(take, best.indices, torch.full_like(best.indices, PRIOR))
    return choice.numpy() if was_numpy else choice


_WEIGHT_SOURCE = {"ext-up": "up", "ext-down": "down", "ext-left": "left", "ext-right": "right"}


def _choice_weights(images, queries, wrap, choice):
    """(B, N, 4) weights of the chosen candidates over the 4 neighbours, and their ranges."""
    _, _, wb, r = neighbourhood(images, queries, wrap)
    _, _, t, b = query_frame(queries)
    zero = torch.zeros_like(t)
    rows = {"up": torch.stack([1 - b, b, zero, zero], -1),
            "down": torch.stack([zero, zero, 1 - b, b], -1),
            "left": torch.stack([1 - t, zero, t, zero], -1),
            "right": torch.stack([zero, 1 - t, zero, t], -1)}
    table = [inverse_weights(wb, r)]
    for name in CANDIDATES[1:NO_RETURN]:
        table.append(inverse_weights(rows[_WEIGHT_SOURCE.get(name, name)], r))
    table.append(torch.zeros_like(wb))
    w = torch.stack(table, dim=-2)  # (B, N, 10, 4)
    return torch.gather(w, -2, choice[..., None, None].expand(*choice.shape, 1, 4))[..., 0, :], r
