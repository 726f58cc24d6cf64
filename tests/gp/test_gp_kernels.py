"""Tests of the GP kernels (occgp.gp._kernels) and the integral kernels (occgp.gp._integral_kernel)."""

import functools
import math
import warnings

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from scipy import integrate
from scipy.optimize import approx_fprime
from sklearn.gaussian_process.kernels import RBF

from occgp.gp import (ClenshawCurtis, Matern32, Simpson, SparseKernel, SquaredExponential,
                      integral_kernel)

# name -> kernel for a dimension; "-ard" has one length scale per input dimension
KERNELS = {
    "se": lambda dim: SquaredExponential(1.3, 0.8),
    "se-ard": lambda dim: SquaredExponential(1.3, [0.8, 1.2, 0.6][:dim]),
    "matern32": lambda dim: Matern32(0.7, 0.9),
    "matern32-ard": lambda dim: Matern32(0.7, [0.9, 0.6, 1.3][:dim]),
    "sparse": lambda dim: SparseKernel(1.1, 1.7),
    "sparse-ard": lambda dim: SparseKernel(1.1, [1.5, 2.2, 1.8][:dim]),
}
ISOTROPIC = ["se", "matern32", "sparse"]
RULES = {"clenshaw-curtis": ClenshawCurtis, "simpson": Simpson}
SQRT3 = np.sqrt(3.0)


def mixed(rng, dim, n_points=4, n_segments=5, scale=1.0):
    """Points (start == end) followed by segments: starts, ends."""
    points = rng.uniform(-1.0, 1.0, (n_points, dim))
    starts = rng.uniform(-1.0, 1.0, (n_segments, dim))
    ends = starts + rng.normal(0.0, scale, (n_segments, dim))
    return np.vstack([points, starts]), np.vstack([points, ends])


def central_gradient(f, theta, h=1e-5):
    """d f / d theta by central differences; f returns an array, result (..., n_theta)."""
    cols = []
    for k in range(len(theta)):
        step = np.zeros_like(theta)
        step[k] = h
        cols.append((f(theta + step) - f(theta - step)) / (2 * h))
    return np.stack(cols, axis=-1)


# ---------------------------------------------------------------- references
def scalar_profile(kernel):
    """The kernel's profile f(s) (s the squared scaled distance) on Python floats."""
    if isinstance(kernel, SquaredExponential):
        return lambda s: math.exp(-0.5 * s)
    if isinstance(kernel, Matern32):
        return lambda s: (1.0 + SQRT3 * math.sqrt(s)) * math.exp(-SQRT3 * math.sqrt(s))

    def sparse(s):
        r = math.sqrt(s)
        if r >= 1.0:
            return 0.0
        return (2.0 + math.cos(2 * math.pi * r)) / 3.0 * (1.0 - r) + math.sin(2 * math.pi * r) / (
            2 * math.pi)
    return sparse


def _quad(f, a, b, breaks, **kw):
    """scipy quad of f over [a, b], split at the break points inside it."""
    edges = [a] + sorted(t for t in breaks if a < t < b) + [b]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", integrate.IntegrationWarning)
        return sum(integrate.quad(f, lo, hi, limit=200, **kw)[0]
                   for lo, hi in zip(edges[:-1], edges[1:]))


def _roots(qa, qb, qc):
    """Real roots of qa t^2 + 2 qb t + qc."""
    disc = qb * qb - qa * qc
    if qa <= 0 or disc <= 0:
        return []
    r = np.sqrt(disc)
    return [(-qb - r) / qa, (-qb + r) / qa]


def _inner_breaks(kernel, p, A, v):
    """Kinks of s -> f(|A + s v - p|^2) (scaled): the foot of p, the support's edges."""
    m = (p - A) @ v / (v @ v)
    breaks = [m]
    if isinstance(kernel, SparseKernel):
        d2 = np.sum((A + m * v - p) ** 2)
        if d2 < 1.0:
            half = np.sqrt((1.0 - d2) / (v @ v))
            breaks += [m - half, m + half]
    return breaks


def _outer_breaks(kernel, Ao, vo, Ai, vi):
    """Where t -> int f(|Ao + t vo - Ai - s vi|^2) ds loses smoothness (scaled)."""
    ei = vi @ vi
    w0 = (Ao - Ai) - ((Ao - Ai) @ vi) / ei * vi        # offset from the inner line
    w1 = vo - (vo @ vi) / ei * vi
    breaks = []
    if w1 @ w1 > 0:
        breaks.append(-(w0 @ w1) / (w1 @ w1))           # closest to the inner line
    for Q in (Ai, Ai + vi):
        breaks.append(-((Ao - Q) @ vo) / (vo @ vo))    # closest to an inner end
    m0, m1 = ((Ao - Ai) @ vi) / ei, (vo @ vi) / ei
    if m1 != 0:
        breaks += [-m0 / m1, (1.0 - m0) / m1]           # foot passes an inner end
    if isinstance(kernel, SparseKernel):                 # support edge crossings
        for Q in (Ai, Ai + vi):
            breaks += _roots(vo @ vo, vo @ (Ao - Q), (Ao - Q) @ (Ao - Q) - 1.0)
        breaks += _roots(w1 @ w1, w0 @ w1, w0 @ w0 - 1.0)
    return breaks


def segment_point_reference(kernel, start, end, x, epsabs=1e-15):
    """int_0^|l| k(l(s), x) ds by adaptive quadrature split at the foot of x."""
    inv = kernel.inverse_length_scales(len(x))
    A, v, p = start * inv, (end - start) * inv, x * inv
    profile = scalar_profile(kernel)

    def f(t):
        return profile(sum((a + t * b - c) ** 2 for a, b, c in zip(A, v, p)))

    val = _quad(f, 0.0, 1.0, _inner_breaks(kernel, p, A, v), epsabs=epsabs, epsrel=1e-13)
    return kernel.variance * np.linalg.norm(end - start) * val


def segment_segment_reference(kernel, s1, e1, s2, e2):
    """The double integral by nested adaptive quadrature split at every kink."""
    inv = kernel.inverse_length_scales(len(s1))
    Ao, vo, Ai, vi = s1 * inv, (e1 - s1) * inv, s2 * inv, (e2 - s2) * inv
    profile = scalar_profile(kernel)
    bi = vi.tolist()

    def outer(t):
        p = Ao + t * vo
        c = (p - Ai).tolist()

        def f(s):
            return profile(sum((s * b - x) ** 2 for b, x in zip(bi, c)))

        return _quad(f, 0.0, 1.0, _inner_breaks(kernel, p, Ai, vi), epsabs=1e-15, epsrel=1e-13)

    val = _quad(outer, 0.0, 1.0, _outer_breaks(kernel, Ao, vo, Ai, vi),
                epsabs=1e-14, epsrel=1e-12)
    return kernel.variance * np.linalg.norm(e1 - s1) * np.linalg.norm(e2 - s2) * val


def entry(kernel, s1, e1, s2, e2, quadrature):
    """K[0, 1] and sqrt(K[0, 0] K[1, 1]) of two observations."""
    K = integral_kernel(kernel, np.array([s1, s2]), np.array([e1, e2]), quadrature=quadrature)
    return K[0, 1], np.sqrt(K[0, 0] * K[1, 1])


# ------------------------------------------------------------- point kernels
@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("name", list(KERNELS))
def test_kernel_matrix_is_symmetric_with_the_variance_on_its_diagonal(name, dim):
    kernel = KERNELS[name](dim)
    X = np.random.default_rng(0).uniform(-1.0, 1.0, (7, dim))
    K = kernel(X)
    assert K.shape == (7, 7)
    assert_array_equal(K, K.T)
    assert_allclose(np.diag(K), kernel.variance, rtol=1e-15)
    assert_allclose(kernel.diag(X), kernel.variance)
    off = K[~np.eye(7, dtype=bool)]
    assert (off < kernel.variance).all() and (off >= 0).all()
    Y = X[:3] + 0.1
    assert kernel(X, Y).shape == (7, 3)
    assert_allclose(kernel(X, Y), kernel(Y, X).T, rtol=1e-15)


@pytest.mark.parametrize("dim", [1, 3])
def test_kernel_profiles_match_their_formulas(dim):
    rng = np.random.default_rng(0)
    ls = np.array([0.7, 1.1, 1.6][:dim])
    X, Y = rng.uniform(-1.0, 1.0, (6, dim)), rng.uniform(-1.0, 1.0, (5, dim))
    r = np.sqrt((((X[:, None] - Y[None]) / ls) ** 2).sum(-1))
    assert_allclose(SquaredExponential(2.0, ls)(X, Y), 2.0 * np.exp(-0.5 * r ** 2), rtol=1e-14)
    assert_allclose(Matern32(2.0, ls)(X, Y), 2.0 * (1 + SQRT3 * r) * np.exp(-SQRT3 * r),
                    rtol=1e-14)
    two_pi_r = 2 * np.pi * r
    sparse = np.where(r < 1, (2 + np.cos(two_pi_r)) / 3 * (1 - r) + np.sin(two_pi_r) / (2 * np.pi),
                      0.0)
    assert_allclose(SparseKernel(2.0, ls)(X, Y), 2.0 * sparse, rtol=1e-13, atol=1e-15)
    # the sparse kernel is exactly 0 outside its support, and continuous at its edge
    k = SparseKernel(1.0, 1.0)
    assert k([[0.0]], [[1.0], [1.5]]).tolist() == [[0.0, 0.0]]
    assert k([[0.0]], [[1.0 - 1e-6]])[0, 0] < 1e-15


@pytest.mark.parametrize("name", list(KERNELS))
def test_theta_bounds_and_with_theta_round_trip(name):
    kernel = KERNELS[name](3)
    ls = np.atleast_1d(kernel.length_scale)
    assert kernel.n_theta == 1 + ls.size == len(kernel.hyperparameter_names)
    assert_allclose(kernel.theta, np.log(np.r_[kernel.variance, ls]))
    bounds = kernel.bounds
    assert bounds.shape == (kernel.n_theta, 2)
    assert_allclose(bounds[0], np.log([1e-3, 1e3]))
    assert_allclose(bounds[1:], np.log([[1e-2, 1e2]] * ls.size))
    # round trip
    same = kernel.with_theta(kernel.theta)
    assert same == kernel and same is not kernel
    theta = kernel.theta + np.linspace(-0.5, 0.4, kernel.n_theta)
    other = kernel.with_theta(theta)
    assert_allclose(other.theta, theta, rtol=1e-14)
    assert_allclose(other.variance, np.exp(theta[0]))
    assert_allclose(np.atleast_1d(other.length_scale), np.exp(theta[1:]))
    assert other.anisotropic == kernel.anisotropic
    assert_allclose(other.bounds, bounds)
    assert_allclose(kernel.theta, np.log(np.r_[kernel.variance, ls]))   # original untouched
    # custom bounds travel with the copies
    custom = type(kernel)(1.0, 1.0, variance_bounds=(0.1, 10.0), length_scale_bounds=(0.5, 2.0))
    assert_allclose(custom.with_theta([0.1, 0.2]).bounds, np.log([[0.1, 10.0], [0.5, 2.0]]))


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", list(KERNELS))
def test_kernel_gradient_matches_finite_differences(name, dim):
    kernel = KERNELS[name](dim)
    X = np.random.default_rng(0).uniform(-1.0, 1.0, (6, dim))
    K, K_gradient = kernel(X, eval_gradient=True)
    assert K_gradient.shape == (6, 6, kernel.n_theta)
    assert_array_equal(K, kernel(X))

    def flat(theta):
        return kernel.with_theta(theta)(X).ravel()

    numeric = approx_fprime(kernel.theta, flat, 1e-7).reshape(6, 6, -1)
    assert_allclose(K_gradient, numeric, rtol=1e-5, atol=1e-6)
    assert_allclose(K_gradient, central_gradient(lambda t: kernel.with_theta(t)(X), kernel.theta),
                    rtol=1e-8, atol=1e-9)


@pytest.mark.parametrize("kwargs, error, match", [
    (dict(variance=0.0), ValueError, "variance must be positive"),
    (dict(variance=np.inf), ValueError, "variance must be positive"),
    (dict(variance=True), TypeError, "variance must be a real number"),
    (dict(variance="1"), TypeError, "variance must be a real number"),
    (dict(length_scale=-1.0), ValueError, "length_scale must be a positive"),
    (dict(length_scale=[1.0, np.nan]), ValueError, "length_scale must be a positive"),
    (dict(length_scale=[[1.0, 2.0]]), ValueError, "length_scale must be a positive"),
    (dict(length_scale="a"), TypeError, "length_scale must hold real numbers"),
    (dict(variance_bounds=(1.0, 0.5)), ValueError, r"variance_bounds must satisfy 0 < low"),
    (dict(length_scale_bounds=(0.0, 1.0)), ValueError, "length_scale_bounds must satisfy"),
    (dict(length_scale_bounds=None), TypeError, "length_scale_bounds must be a pair"),
])
@pytest.mark.parametrize("cls", [SquaredExponential, Matern32, SparseKernel])
def test_kernel_rejects_bad_parameters(cls, kwargs, error, match):
    kernel = cls(**kwargs)   # __init__ stores, does not check
    with pytest.raises(error, match=match):
        kernel.theta
    with pytest.raises(error, match=match):
        kernel([[0.0, 0.0]])


def test_kernel_rejects_bad_calls():
    kernel = SquaredExponential(1.0, [1.0, 2.0])
    with pytest.raises(ValueError, match=r"theta must be a finite array of shape \(3,\)"):
        kernel.with_theta([0.0, 0.0])
    with pytest.raises(ValueError, match=r"theta must be a finite array"):
        kernel.with_theta([0.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="eval_gradient is only supported when Y is None"):
        kernel(np.zeros((2, 2)), np.zeros((2, 2)), eval_gradient=True)
    with pytest.raises(ValueError, match="same number of columns"):
        kernel(np.zeros((2, 2)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="length_scale has 2 entries but the inputs have 3"):
        kernel(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="'nu' is not a parameter of"):
        kernel.set_params(nu=1.5)
    assert kernel.set_params(variance=2.0).variance == 2.0


# ------------------------------------------------------------ integral kernels
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", list(KERNELS))
def test_integral_kernel_gradient_matches_finite_differences(name, dim):
    kernel = KERNELS[name](dim)
    starts, ends = mixed(np.random.default_rng(0), dim)
    K, K_gradient = integral_kernel(kernel, starts, ends, eval_gradient=True)
    assert K_gradient.shape == (9, 9, kernel.n_theta)
    assert_array_equal(K, integral_kernel(kernel, starts, ends))
    assert_array_equal(K_gradient, np.swapaxes(K_gradient, 0, 1))

    def matrix(theta):
        return integral_kernel(kernel.with_theta(theta), starts, ends)

    numeric = central_gradient(matrix, kernel.theta)
    scale = np.abs(K_gradient).max()
    assert_allclose(K_gradient, numeric, rtol=0, atol=1e-7 * scale)
    # the variance's column is the matrix itself
    assert_allclose(K_gradient[..., 0], K, rtol=1e-15)


@pytest.mark.parametrize("rule", list(RULES))
@pytest.mark.parametrize("dim", [1, 2, 3])
@pytest.mark.parametrize("name", list(KERNELS))
def test_segment_point_entries_match_quad(name, dim, rule):
    kernel = KERNELS[name](dim)
    rng = np.random.default_rng(0)
    for i in range(8):
        start = rng.uniform(-1.0, 1.0, dim)
        direction = rng.normal(size=dim)
        end = start + 10 ** rng.uniform(-3, 0.8) * direction / np.linalg.norm(direction)
        foot = start + rng.uniform(-0.3, 1.3) * (end - start)
        x = foot + (0.0 if i % 3 == 0 else rng.normal(0.0, [1e-3, 0.3, 1.0][i % 3], dim))
        got, norm = entry(kernel, start, end, x, x, RULES[rule]())
        want = segment_point_reference(kernel, start, end, x)
        assert abs(got - want) <= 1e-8 * norm, (i, got, want)


def _pairs(dim):
    """Segment pairs: random, crossing, collinear overlapping, parallel, self."""
    rng = np.random.default_rng(1)
    z, ex, ey = np.zeros(dim), np.eye(dim)[0], np.eye(dim)[1]
    pairs = []
    for _ in range(2):
        s1, s2 = rng.uniform(-1.0, 1.0, (2, dim))
        pairs.append((s1, s1 + rng.normal(0.0, 1.2, dim), s2, s2 + rng.normal(0.0, 1.2, dim)))
    pairs += [
        (-ex, ex, 0.2 * ex - 0.7 * ey, 0.1 * ex + 0.9 * ey),        # crossing
        (z, 4 * ex, 0.05 * ey - ex, 0.4 * ey + 5 * ex),             # crossing at a small angle
        (z, 2 * ex, 0.5 * ex, 3.1 * ex),                            # collinear, overlapping
        (z, 3 * ex, 0.3 * ey, 2.5 * ex + 0.3 * ey),                 # parallel, close
        (z, 1e-3 * ex, 0.1 * ey, 2 * ex + 0.1 * ey),                # very short against long
    ]
    if dim == 3:
        pairs.append((-ex, ex, 0.1 * np.eye(3)[2] - ey, 0.1 * np.eye(3)[2] + ey))   # skew
    s = rng.uniform(-1.0, 1.0, dim)
    pairs.append((s, s + 1.5 * ey, s, s + 1.5 * ey))                # self-covariance
    return pairs


@functools.lru_cache(maxsize=None)
def _segment_segment_references(name, dim):
    kernel = KERNELS[name](dim)
    return [segment_segment_reference(kernel, *pair) for pair in _pairs(dim)]


@pytest.mark.parametrize("rule", list(RULES))
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", list(KERNELS))
def test_segment_segment_entries_match_nested_quad(name, dim, rule):
    kernel = KERNELS[name](dim)
    refs = _segment_segment_references(name, dim)
    for i, (pair, want) in enumerate(zip(_pairs(dim), refs)):
        got, norm = entry(kernel, *pair, RULES[rule]())
        assert abs(got - want) <= 1e-8 * norm, (i, got, want)


def test_segment_segment_reference_is_converged():
    # the nested reference agrees with an independent closed form: SE, two parallel
    # segments at distance d, int int exp(-((t - s)^2 + d^2) / 2)
    kernel = SquaredExponential(1.0, 1.0)
    d, L = 0.3, 2.0
    want = segment_segment_reference(kernel, np.array([0.0, 0]), np.array([L, 0]),
                                     np.array([0.0, d]), np.array([L, d]))
    inner = integrate.quad(lambda u: (L - abs(u)) * np.exp(-0.5 * u * u), -L, L,
                           points=[0.0], epsabs=1e-15, epsrel=1e-13)[0]
    assert_allclose(want, np.exp(-0.5 * d * d) * inner, rtol=1e-12)


@pytest.mark.parametrize("rule", list(RULES))
@pytest.mark.parametrize("case", ["beyond-end-near", "beyond-end-far", "behind-start", "middle",
                                  "middle-off-line", "short-1e-3", "short-1e-6",
                                  "short-1e-6-off-line", "at-closed-form-switch"])
def test_squared_exponential_segment_point_closed_form(case, rule):
    length_scale = 0.7
    kernel = SquaredExponential(1.0, length_scale)
    ex, ey = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    start, length = np.array([0.3, -0.2]), 1.5 * length_scale
    x_of = {
        "beyond-end-near": lambda L: start + (L + 0.4) * ex,
        "beyond-end-far": lambda L: start + (L + 7.0 * length_scale) * ex,
        "behind-start": lambda L: start - 3.0 * ex,
        "middle": lambda L: start + 0.5 * L * ex,
        "middle-off-line": lambda L: start + 0.5 * L * ex + 0.3 * ey,
    }
    if case.startswith("short"):
        length = float(case.split("-")[1] + "-" + case.split("-")[2]) * length_scale
        x = start + 0.5 * length * ex + (0.2 * ey if case.endswith("off-line") else 0.0)
    elif case == "at-closed-form-switch":   # the erf form starts at 0.25 length scales
        length = 0.25 * length_scale
        x = start + 1.1 * length * ex + 0.1 * ey
    else:
        x = x_of[case](length)
    end = start + length * ex
    K, K_gradient = integral_kernel(kernel, np.array([start, x]), np.array([end, x]),
                                    quadrature=RULES[rule](), eval_gradient=True)
    want = segment_point_reference(kernel, start, end, x, epsabs=0.0)
    assert_allclose(K[0, 1], want, rtol=1e-12, atol=1e-300)
    # d/dlog(l) = int (|q|^2 exp(-|q|^2 / 2)) ds with q the scaled difference
    q = lambda t: (start + t * (end - start) - x) / length_scale  # noqa: E731
    grad = length * _quad(lambda t: np.sum(q(t) ** 2) * np.exp(-0.5 * np.sum(q(t) ** 2)), 0, 1,
                          [np.clip((x - start) @ ex / length, 0, 1)], epsabs=0, epsrel=1e-13)
    assert_allclose(K_gradient[0, 1, 1], grad, rtol=1e-10, atol=1e-300)
    # the tiny segment is the point times its length, to first order
    if case.startswith("short"):
        assert_allclose(K[0, 1], length * kernel(x[None], (0.5 * (start + end))[None])[0, 0],
                        rtol=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", ISOTROPIC + ["sparse-ard"])
def test_integral_kernel_is_exactly_symmetric_and_positive_semidefinite(name, dim):
    kernel = KERNELS[name](dim)
    starts, ends = mixed(np.random.default_rng(0), dim, n_points=60, n_segments=90, scale=0.7)
    starts, ends = 2.0 * starts, 2.0 * ends
    K = integral_kernel(kernel, starts, ends)       # no jitter, no noise
    assert K.shape == (150, 150)
    assert_array_equal(K, K.T)
    assert np.linalg.eigvalsh(K).min() >= -1e-10 * np.trace(K)
    # the point block is the plain kernel
    assert_allclose(K[:60, :60], kernel(starts[:60]), rtol=1e-13, atol=1e-14 * kernel.variance)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", list(KERNELS))
def test_zero_length_segments_are_points(name, dim):
    kernel = KERNELS[name](dim)
    starts, ends = mixed(np.random.default_rng(0), dim)
    points = starts[:4]
    K, K_gradient = integral_kernel(kernel, starts, ends, eval_gradient=True)
    P, P_gradient = kernel(points, eval_gradient=True)
    assert_allclose(K[:4, :4], P, rtol=1e-13, atol=1e-14 * kernel.variance)
    assert_allclose(K_gradient[:4, :4], P_gradient, rtol=1e-12, atol=1e-15)
    # the points' rows in the mixed matrix are those of the points alone against everything
    assert_array_equal(integral_kernel(kernel, points, points, starts, ends), K[:4])
    # a segment shrinking to a point: its row divided by its length tends to the point's row
    eps = 1e-7
    short_ends = ends.copy()
    short_ends[:4] += eps * np.eye(dim)[0]
    S = integral_kernel(kernel, starts, short_ends)
    assert_allclose(S[:4, 4:] / eps, K[:4, 4:], rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("name", ISOTROPIC)
def test_integral_kernel_does_not_depend_on_threads(name, dim):
    kernel = KERNELS[name](dim)
    starts, ends = mixed(np.random.default_rng(0), dim, n_points=15, n_segments=25)
    K = integral_kernel(kernel, starts, ends, n_jobs=1)
    assert_array_equal(integral_kernel(kernel, starts, ends, n_jobs=2), K)
    assert_array_equal(integral_kernel(kernel, starts, ends, n_jobs=-1), K)
    K1, G1 = integral_kernel(kernel, starts, ends, eval_gradient=True, n_jobs=1)
    K2, G2 = integral_kernel(kernel, starts, ends, eval_gradient=True, n_jobs=2)
    assert_array_equal(K1, K2)
    assert_array_equal(G1, G2)
    # two sets that happen to be the same: the symmetric matrix, bit for bit
    assert_array_equal(integral_kernel(kernel, starts, ends, starts, ends, n_jobs=2), K)
    # rectangular blocks are the blocks of the full matrix
    assert_array_equal(integral_kernel(kernel, starts[:7], ends[:7], starts[7:], ends[7:]),
                       K[:7, 7:])


def test_integral_kernel_accepts_quadrature_names_and_lists():
    kernel = Matern32()
    starts, ends = [[0.0, 0.0], [1.0, 0.5]], [[1.0, 1.0], [1.0, 0.5]]
    K = integral_kernel(kernel, starts, ends)
    assert_array_equal(integral_kernel(kernel, starts, ends, quadrature="clenshaw-curtis"), K)
    assert_array_equal(integral_kernel(kernel, starts, ends, quadrature=ClenshawCurtis()), K)
    assert_allclose(integral_kernel(kernel, starts, ends, quadrature="simpson"), K, rtol=1e-9)
    assert integral_kernel(kernel, np.empty((0, 2)), np.empty((0, 2))).shape == (0, 0)
    empty = np.empty((0, 2))
    assert integral_kernel(kernel, starts, ends, empty, empty).shape == (2, 0)


@pytest.mark.parametrize("call, error, match", [
    (lambda: integral_kernel(RBF(), [[0.0, 0]], [[1.0, 0]]), TypeError,
     "kernel must be one of occgp.gp's kernels"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0]], quadrature="gauss"),
     ValueError, "quadrature must be 'clenshaw-curtis', 'simpson'"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0]],
                             quadrature=ClenshawCurtis(tol=0.0)), ValueError, "tol must be"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0]], [[0.0, 0]]),
     ValueError, "starts2 and ends2 must be given together"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0]], [[0.0, 0]], [[1.0, 0]],
                             eval_gradient=True), ValueError, "eval_gradient is only supported"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0], [2.0, 0]]), ValueError,
     "observation_starts and observation_ends must have the same shape"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, np.nan]], [[1.0, 0]]), ValueError,
     "observation_starts must be finite"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[np.inf, 0]]), ValueError,
     "observation_ends must be finite"),
    (lambda: integral_kernel(SquaredExponential(), np.zeros((2, 4)), np.zeros((2, 4))), ValueError,
     r"observation_starts must have shape \(n, D\) with D in 1..3"),
    (lambda: integral_kernel(SquaredExponential(), np.zeros(2), np.zeros(2)), ValueError,
     r"observation_starts must have shape \(n, D\)"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0, 0]]), ValueError,
     r"observation_ends must have shape \(n_points, 2\)"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0]], [[0.0, 0, 0]],
                             [[1.0, 0, 0]]), ValueError,
     r"observation2_starts must have shape \(n_points, 2\)"),
    (lambda: integral_kernel(SquaredExponential(), [["a", "b"]], [[1.0, 0]]), TypeError,
     "observation_starts must hold real numbers"),
    (lambda: integral_kernel(SquaredExponential(1.0, [1.0, 1.0, 1.0]), [[0.0, 0]], [[1.0, 0]]),
     ValueError, "length_scale has 3 entries but the inputs have 2 dimensions"),
    (lambda: integral_kernel(SquaredExponential(), [[0.0, 0]], [[1.0, 0]], n_jobs=0), ValueError,
     "n_jobs must be"),
])
def test_integral_kernel_rejects_bad_input(call, error, match):
    with pytest.raises(error, match=match):
        call()
