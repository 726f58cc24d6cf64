"""Sensor effects on simulated range images: range noise and dropped returns (numpy only).

:func:`~occgp.iln.simulate_range_image` casts exact, noise-free images:
every ray that meets a surface within ``max_range`` returns its exact
range. Real spinning LiDARs do not. :class:`SensorEffects` describes how
a real sensor departs from that, and :func:`apply_sensor_effects` applies
it to a clean image:

* **range noise**: each return moves along its ray by a Gaussian error of
  standard deviation ``range_noise`` metres;
* **grazing dropout**: a return is lost with a probability that rises as
  the incidence angle between the beam and the surface normal nears 90
  degrees (the far ground, walls seen edge-on); the normals are estimated
  from the clean image itself (finite differences of the 3D points of
  neighbouring pixels);
* **dark dropout**: a return from a dark surface (low reflectivity, e.g.
  asphalt, black cars, windows) is lost more often, the more so the
  farther it is;
* **range falloff**: returns near ``max_range`` are lost with a
  probability rising to ``range_dropout`` at ``max_range``.

The probabilities combine as independent causes: a return survives all
three with probability ``(1 - p_grazing) (1 - p_dark) (1 - p_range)``.
:func:`solid_reflectivity` gives a seeded reflectivity to each solid of a
scene by its kind (its label), for the per-pixel reflectivity of
``simulate_range_image(..., return_ids=True)``.

The defaults were matched to real frames: see the Notes of :class:`SensorEffects`.
"""

from __future__ import annotations

import dataclasses
import numbers

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import check_real
from ._range import LidarModel, check_pixels

__all__ = ["SensorEffects", "apply_sensor_effects", "solid_reflectivity", "REFLECTIVITY"]

#: Reflectivity range ``(low, high)`` of each kind of solid (the labels of
#: :func:`occgp.datasets.outdoor_scene`) at a near-infrared LiDAR's wavelength:
#: asphalt and glass are dark, vegetation and light facades bright.
REFLECTIVITY = {
    "ground": (0.1, 0.25), "curb": (0.25, 0.45), "hill": (0.2, 0.45),
    "building": (0.1, 0.7), "wall": (0.2, 0.6),
    "pole": (0.15, 0.5), "pole_arm": (0.15, 0.5),
    "tree_trunk": (0.1, 0.3), "tree_crown": (0.35, 0.6),
    "bush": (0.35, 0.6), "hedge": (0.35, 0.6), "grass": (0.3, 0.55),
    "car_body": (0.03, 0.8), "car_cabin": (0.02, 0.12),
}
#: Reflectivity range of a label missing from :data:`REFLECTIVITY`.
DEFAULT_REFLECTIVITY = (0.2, 0.5)
_PROBABILITIES = ("grazing_dropout", "dark_dropout", "range_dropout")


@dataclasses.dataclass(frozen=True)
class SensorEffects:
    """How a real LiDAR departs from an exact range image (see :func:`apply_sensor_effects`).

    The defaults look like the real KITTI and OS1-64 frames (see the Notes
    for what was matched). Set a field to 0 to switch its effect off.

    Parameters
    ----------
    range_noise : float, default=0.02
        Standard deviation of the Gaussian range error, metres, in [0, 1].
    grazing_dropout : float, default=1.0
        Probability of losing a return at an incidence angle of 90 degrees,
        in [0, 1].
    grazing_angle : float, default=86.0
        Incidence angle (degrees, in [0, 90)) where grazing dropouts start:
        the probability rises as ``grazing_dropout * s**2``, ``s = (angle -
        grazing_angle) / (90 - grazing_angle)`` clipped to [0, 1].
    dark_dropout : float, default=1.0
        Probability of losing a return of reflectivity 0 at ``max_range``,
        in [0, 1]: a return of reflectivity ``rho`` at range ``r`` is lost
        with probability ``dark_dropout * max(0, 1 - rho /
        dark_reflectivity) * r / max_range``.
    dark_reflectivity : float, default=0.15
        Reflectivity (in (0, 1]) at and above which a surface is not dark.
    range_dropout : float, default=0.5
        Probability of losing a return at ``max_range``, in [0, 1]: it rises
        linearly from 0 at ``range_falloff * max_range``.
    range_falloff : float, default=0.75
        Fraction of ``max_range`` (in [0, 1)) where the range falloff starts.

    Raises
    ------
    TypeError
        If a field is not a real number.
    ValueError
        If a field is NaN or out of its range (a negative noise, a
        probability outside [0, 1]), naming the field.

    Notes
    -----
    The defaults were matched to the real frames of ``shared/data/lidar_frames``
    read by :func:`occgp.iln.read_lidar_frame` (KITTI's HDL-64E, front 170
    degrees; an Ouster OS1-64 in RELLIS-3D), at 1024 columns:

    * single missing returns on the flat ground (a pixel without a return
      between ground returns at the range of the flat ground, within 3 pixels
      on both sides): none up to 36 m (incidence 87.2 degrees) in the KITTI
      frame; in the OS1-64 frame (sensor 1.26 m high) about 1 % at 5 to 6 m,
      none from 6 to 20 m, 3 % at 28 m (87.4 degrees) and 26 % at 36 m (88
      degrees): hence grazing dropouts only beyond 86 degrees, rising fast;
    * single missing returns inside a surface (a pixel without a return whose
      neighbours above and below return consistent ranges) in KITTI's rows
      looking -1 to -7 degrees: 0.3 % at 0 to 10 m, 0.6 % at 10 to 20 m, none
      at 20 to 45 m; with the defaults 0.1 to 0.4 % of the simulated pixels
      below the horizon are lost;
    * range noise on the flat ground, estimated from the second differences of
      the ranges along a row (robust: ``1.4826 * MAD / sqrt(6)``): 0.65 cm
      (KITTI) and 1.0 cm (OS1-64, over grass) at 1024 columns; the default 2
      cm is the HDL-64E's specified accuracy, an upper bound on both.

    Most other missing returns of the real frames lie in gaps wider than 3
    pixels without a return above or below either (sky, windows, dark cars,
    distant ground) or at depth edges (mixed pixels), which these effects do
    not model beyond the dark surfaces and the far falloff: over 4 held-out
    scenes the defaults raise the no-return fraction of simulated HDL-64E
    images (front 170 degrees) from 5.5 % to 6.0 %, where the KITTI frame
    has 12.2 %.

    Examples
    --------
    >>> SensorEffects().range_noise
    0.02
    >>> SensorEffects(range_noise=0.01, grazing_dropout=0.0).as_dict()["grazing_dropout"]
    0.0
    """

    range_noise: float = 0.02
    grazing_dropout: float = 1.0
    grazing_angle: float = 86.0
    dark_dropout: float = 1.0
    dark_reflectivity: float = 0.15
    range_dropout: float = 0.5
    range_falloff: float = 0.75

    def __post_init__(self):
        checks = {"range_noise": dict(low=0.0, high=1.0, low_open=False, high_open=False),
                  "grazing_angle": dict(low=0.0, high=90.0, low_open=False),
                  "dark_reflectivity": dict(low=0.0, high=1.0, high_open=False),
                  "range_falloff": dict(low=0.0, high=1.0, low_open=False)}
        for name in _PROBABILITIES:
            checks[name] = dict(low=0.0, high=1.0, low_open=False, high_open=False)
        for name, bounds in checks.items():
            object.__setattr__(self, name, check_real(getattr(self, name), name, **bounds))

    def as_dict(self) -> dict:
        """The fields as a dict of floats (the shards' record of the effects).

        Returns
        -------
        fields : dict
            ``{field name: float}``, read back by :meth:`from_dict`.
        """
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, fields) -> "SensorEffects":
        """The effects of :meth:`as_dict`'s `fields`.

        Parameters
        ----------
        fields : dict
            Field name -> value; fields left out keep their defaults.

        Returns
        -------
        SensorEffects

        Raises
        ------
        TypeError
            If `fields` is not a dict or a value is not a real number.
        ValueError
            If `fields` has an unknown key or a value is out of range.
        """
        if not isinstance(fields, dict):
            raise TypeError(f"fields must be a dict of SensorEffects fields, got "
                            f"{type(fields).__name__}")
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(fields) - known)
        if unknown:
            raise ValueError(f"fields has unknown SensorEffects fields {unknown} "
                             f"(known: {sorted(known)})")
        return cls(**fields)


def solid_reflectivity(labels, seed: int = 0) -> NDArray[np.float64]:
    """A seeded reflectivity for each solid of a scene, drawn by its kind.

    Each solid draws uniformly from its label's range in
    :data:`REFLECTIVITY` (``DEFAULT_REFLECTIVITY``, 0.2 to 0.5, for other
    labels).

    Parameters
    ----------
    labels : sequence of str
        The solids' labels, e.g. ``scene.labels`` of
        :func:`occgp.datasets.outdoor_scene`.
    seed : int, default=0
        Non-negative; the same labels and seed give the same values.

    Returns
    -------
    reflectivity : ndarray of float64, shape (len(labels),)
        In (0, 1).

    Raises
    ------
    TypeError
        If `labels` is not a sequence of str or `seed` not an int.
    ValueError
        If `seed` is negative.

    Examples
    --------
    >>> rho = solid_reflectivity(["ground", "car_cabin", "tree_crown"], seed=1)
    >>> bool(rho[1] < 0.12 < 0.35 < rho[2])
    True
    """
    from .._validation import check_int  # noqa: PLC0415

    seed = check_int(seed, "seed", low=0)
    if isinstance(labels, str) or not hasattr(labels, "__iter__"):
        raise TypeError(f"labels must be a sequence of str, got {type(labels).__name__}")
    labels = list(labels)
    if not all(isinstance(label, str) for label in labels):
        raise TypeError("labels must be a sequence of str")
    bounds = np.array([REFLECTIVITY.get(label, DEFAULT_REFLECTIVITY) for label in labels],
                      dtype=np.float64).reshape(-1, 2)
    u = np.random.default_rng([seed, 8819]).random(len(labels))
    return bounds[:, 0] + u * (bounds[:, 1] - bounds[:, 0])


def _check_effects(effects):
    if not isinstance(effects, SensorEffects):
        raise TypeError(f"effects must be a SensorEffects, got {type(effects).__name__}")
    return effects


def _check_rng(rng):
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (bool, np.bool_)) or not isinstance(rng, (numbers.Integral, np.integer)):
        raise TypeError(f"rng must be a numpy Generator or a non-negative int seed, got "
                        f"{type(rng).__name__}")
    if rng < 0:
        raise ValueError(f"rng must be a non-negative int seed, got {rng}")
    return np.random.default_rng(int(rng))


def _check_pixels(arr, model, name, low, high):
    arr = check_pixels(arr, model, name)
    if arr.size and (arr.min() < low or arr.max() > high):
        raise ValueError(f"{name} must lie in [{low:g}, {high:g}], got values from "
                         f"{float(arr.min())!r} to {float(arr.max())!r}")
    return arr


def _tangent(points, valid, axis, wrap):
    """Per pixel, the shorter of the forward and backward differences of `points` along
    `axis` between pixels that both have a return; and whether there was one."""
    n = points.shape[axis]
    fwd = np.roll(points, -1, axis=axis) - points
    ok_f = valid & np.roll(valid, -1, axis=axis)
    bwd = points - np.roll(points, 1, axis=axis)
    ok_b = valid & np.roll(valid, 1, axis=axis)
    if not wrap:  # no neighbour beyond the first and last row / column
        last = [slice(None)] * 2
        last[axis] = n - 1
        ok_f[tuple(last)] = False
        last[axis] = 0
        ok_b[tuple(last)] = False
    if n == 1:
        ok_f[:] = ok_b[:] = False
    len_f = np.where(ok_f, np.einsum("...k,...k->...", fwd, fwd), np.inf)
    len_b = np.where(ok_b, np.einsum("...k,...k->...", bwd, bwd), np.inf)
    return np.where((len_f <= len_b)[..., None], fwd, bwd), ok_f | ok_b


def _incidence_cosines(image: NDArray, model: LidarModel) -> NDArray[np.float64]:
    """``|cos|`` of the angle between each pixel's ray and the surface normal estimated from
    the image (1.0 where no normal can be estimated: a pixel without a return in a row or a
    column beside it)."""
    dirs = model.directions()
    valid = image > 0
    points = image[..., None] * dirs
    t_u, ok_u = _tangent(points, valid, 1, model.full_circle)
    t_v, ok_v = _tangent(points, valid, 0, False)
    normal = np.cross(t_u, t_v)
    norm = np.sqrt(np.einsum("...k,...k->...", normal, normal))
    ok = ok_u & ok_v & (norm > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        cos = np.abs(np.einsum("...k,...k->...", normal, dirs)) / norm
    return np.where(ok, np.minimum(cos, 1.0), 1.0)


def apply_sensor_effects(image: ArrayLike, model: LidarModel, effects: SensorEffects, rng,
                         *, reflectivity: ArrayLike | None = None) -> NDArray[np.float32]:
    """A clean range image as a real sensor would return it: noisy ranges, dropped returns.

    Each return (range > 0) of `image` is dropped with the probability of
    the effects (see :class:`SensorEffects`): grazing incidence (the
    surface normals estimated from `image` by finite differences of the 3D
    points of neighbouring pixels, the shorter of the two one-sided
    differences in each direction, so that depth edges do not bend them),
    dark surfaces (only with `reflectivity`) and ranges near
    ``model.max_range``. The returns kept move by Gaussian noise of
    ``effects.range_noise`` metres, clipped to ``[0.001, max_range]`` (a
    clean range below 1 mm is not lowered).
    Pixels without a return stay 0. Apply it to each image (and each
    size of one pose) on its own: the effects are drawn per pixel.

    Parameters
    ----------
    image : array-like of shape (model.rows, model.cols)
        Clean ranges in metres, 0.0 for no return, e.g. from
        :func:`~occgp.iln.simulate_range_image`.
    model : LidarModel
        The sensor of `image`.
    effects : SensorEffects
    rng : numpy.random.Generator or int
        The random draws (an int seeds a new Generator): the same `rng`
        state gives the same image.
    reflectivity : array-like of shape (model.rows, model.cols), optional
        Reflectivity of the surface of each pixel, in [0, 1] (ignored where
        there is no return), e.g. ``solid_reflectivity(scene.labels)[ids]``
        with the ids of ``simulate_range_image(..., return_ids=True)``.
        Without it there are no dark dropouts.

    Returns
    -------
    image : ndarray of float32, shape (model.rows, model.cols)
        A new image; `image` is unchanged.

    Raises
    ------
    TypeError
        If `model` is not a LidarModel, `effects` not a SensorEffects,
        `rng` neither a Generator nor an int, or `image` / `reflectivity`
        do not hold real numbers.
    ValueError
        If `image` or `reflectivity` does not have the model's shape, holds
        NaN or inf, or values out of range (`image`: [0, max_range],
        `reflectivity`: [0, 1]), or `rng` is a negative int.

    Examples
    --------
    >>> from occgp.datasets import outdoor_scene
    >>> from occgp.iln import LidarModel, simulate_range_image
    >>> scene, model = outdoor_scene(0, size=40), LidarModel.carla(16, 256)
    >>> clean = simulate_range_image(scene, scene.trajectory(1)[0], model)
    >>> noisy = apply_sensor_effects(clean, model, SensorEffects(), rng=0)
    >>> kept = (noisy > 0) & (clean > 0)
    >>> bool(0.005 < np.std(noisy[kept] - clean[kept]) < 0.05), bool((noisy[clean == 0] == 0).all())
    (True, True)
    """
    if not isinstance(model, LidarModel):
        raise TypeError(f"model must be a LidarModel, got {type(model).__name__}")
    limit = float(np.float32(model.max_range))
    clean = _check_pixels(image, model, "image", 0.0, limit)
    effects = _check_effects(effects)
    rng = _check_rng(rng)
    rho = None if reflectivity is None else _check_pixels(reflectivity, model, "reflectivity",
                                                          0.0, 1.0)
    keep = np.ones(model.shape)
    hit = clean > 0
    if effects.grazing_dropout > 0:
        angle = np.degrees(np.arccos(_incidence_cosines(clean, model)))
        s = np.clip((angle - effects.grazing_angle) / (90.0 - effects.grazing_angle), 0.0, 1.0)
        keep *= 1.0 - effects.grazing_dropout * s * s
    if effects.dark_dropout > 0 and rho is not None:
        dark = np.clip(1.0 - rho / effects.dark_reflectivity, 0.0, 1.0)
        keep *= 1.0 - effects.dark_dropout * dark * (clean / model.max_range)
    if effects.range_dropout > 0:
        start = effects.range_falloff * model.max_range
        ramp = np.clip((clean - start) / (model.max_range - start), 0.0, 1.0)
        keep *= 1.0 - effects.range_dropout * ramp
    u = rng.random(model.shape)
    noise = rng.standard_normal(model.shape) * effects.range_noise
    kept = hit & (u < keep)
    noisy = np.minimum(np.maximum(clean + noise, np.minimum(clean, 1e-3)), limit)
    out = np.where(kept, noisy, 0.0)
    return out.astype(np.float32)
