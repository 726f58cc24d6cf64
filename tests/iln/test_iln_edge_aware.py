"""The edge-aware interpolation rule: planes, steps, no-returns, borders, registry, bad input."""

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from occgp.iln import evaluate, upsample_range_image  # noqa: E402
from occgp.iln.models import (  # noqa: E402
    EdgeAwareInterpolation,
    InverseBilinear,
    available_models,
    make,
)


def _plane(rows=6, cols=8):
    """Ranges whose inverse is linear in the row and the column (a plane seen by the sensor)."""
    v = np.arange(rows)[:, None] + 0.5
    u = np.arange(cols)[None, :] + 0.5
    return (1.0 / (0.05 + 0.01 * v + 0.002 * u)).astype(np.float32)


def _queries(n, rows, cols, seed=1):
    return np.random.default_rng(seed).uniform([0, 0], [rows, cols], (n, 2)).astype(np.float32)


def _reference(img, q, tol=0.05, wrap=True, copy_no_returns=False):
    """The rule of the class docstring, query by query (slow, plain numpy)."""
    rows, cols = img.shape
    out = np.zeros(len(q))

    def inv_interp(pairs):        # [(weight, range)] -> inverse-range value or None
        w = sum(a for a, r in pairs if r > 0)
        return None if w <= 1e-12 else sum(a / r for a, r in pairs if r > 0) / w

    for n, (vq, uq) in enumerate(q.astype(np.float64)):
        v, u = vq - 0.5, uq - 0.5
        i, j = int(np.floor(v)), int(np.floor(u))
        t, b = v - i, u - j
        j0, j1 = (j % cols, (j + 1) % cols) if wrap else (min(max(j, 0), cols - 1),
                                                          min(max(j + 1, 0), cols - 1))

        def row(k):
            if not 0 <= k < rows:
                return None
            return inv_interp([(1 - b, img[k, j0]), (b, img[k, j1])])

        ic, ic1 = min(max(i, 0), rows - 1), min(max(i + 1, 0), rows - 1)
        p = inv_interp([((1 - t) * (1 - b), img[ic, j0]), ((1 - t) * b, img[ic, j1]),
                        (t * (1 - b), img[ic1, j0]), (t * b, img[ic1, j1])])
        if p is None:
            continue
        s = {d: row(i + d) for d in (-1, 0, 1, 2)}
        exts = []
        if s[-1] is not None and s[0] is not None:
            exts.append(s[0] + t * (s[0] - s[-1]))
        if s[1] is not None and s[2] is not None:
            exts.append(s[1] + (1 - t) * (s[1] - s[2]))
        if exts and not any(abs(e - p) <= tol * p for e in exts):
            k = ic if t <= 0.5 else ic1
            value = inv_interp([(1 - b, img[k, j0]), (b, img[k, j1])])
            if value is None:
                out[n] = 0.0 if copy_no_returns else 1.0 / p
            else:
                out[n] = 1.0 / value
        else:
            out[n] = 1.0 / p
    return out


def test_registered_without_parameters_and_spec_round_trip():
    assert "edge-aware" in available_models()
    m = make({"name": "edge-aware", "args": {"tolerance": 0.1, "wrap": False}})
    assert isinstance(m, EdgeAwareInterpolation)
    assert list(m.parameters()) == [] and m.tolerance == 0.1 and m.wrap is False
    spec = m.spec()
    assert spec["name"] == "edge-aware" and spec["args"]["tolerance"] == 0.1
    m2 = make(spec, load_sd=True)
    img = _plane()
    img[3:] *= 2.0
    q = _queries(50, 6, 8)
    np.testing.assert_array_equal(m.predict(img, q), m2.predict(img, q))


def test_plane_equals_inverse_bilinear():
    img = _plane(8, 16)
    q = _queries(500, 8, 16)
    ours = EdgeAwareInterpolation().predict(img, q)
    np.testing.assert_allclose(ours, InverseBilinear().predict(img, q), rtol=1e-5)
    np.testing.assert_allclose(ours, _reference(img, q), rtol=1e-5)


def test_step_edge_copies_the_nearer_row():
    img = np.full((6, 8), 10.0, np.float32)
    img[3:] = 30.0                                   # a step between rows 2 and 3
    m = EdgeAwareInterpolation()
    q = np.array([[3.0 + f, 4.3] for f in (0.1, 0.4, 0.5, 0.6, 0.9)], np.float32)
    # fractions t = 0.6, 0.9 (lower nearer), 0 (on row 3), 0.1, 0.4 (upper nearer)
    np.testing.assert_allclose(m.predict(img, q), [30, 30, 30, 30, 30])
    q = np.array([[2.5 + f, 4.3] for f in (0.1, 0.4, 0.5)], np.float32)
    np.testing.assert_allclose(m.predict(img, q), [10, 10, 10])   # t <= 0.5: upper (ties too)
    q = np.array([[3.25, 1.0], [2.75, 7.9]], np.float32)
    w = m.weights(img, q)
    np.testing.assert_allclose(w[0], [0, 0, 0.5, 0.5], atol=1e-6)   # the lower row only
    np.testing.assert_allclose(w[1].sum(), 1.0) and np.testing.assert_allclose(w[1][2:], 0)
    inv = InverseBilinear().predict(img, q)
    assert 10 < inv[0] < 30                          # inverse bilinear blends the two surfaces


def test_tolerance_switches_between_copy_and_inverse_bilinear():
    img = _plane()
    img[3:] *= 1.08                                  # a small step: 1/r off by about 7 %
    q = np.array([[3.2, 4.0]], np.float32)
    inv = InverseBilinear().predict(img, q)
    assert EdgeAwareInterpolation(tolerance=0.2).predict(img, q) == pytest.approx(inv)
    copied = EdgeAwareInterpolation(tolerance=0.01).predict(img, q)
    assert copied != pytest.approx(inv)
    assert copied == pytest.approx(1.0 / (0.05 + 0.01 * 3.5 + 0.002 * 4.0) * 1.08, rel=1e-5)
    big = EdgeAwareInterpolation(tolerance=1e9)
    q = _queries(300, 6, 8)
    np.testing.assert_allclose(big.predict(img, q), InverseBilinear().predict(img, q), rtol=1e-6)


def test_no_return_rows_and_neighbours():
    img = _plane(6, 8)
    img[:2] = 0.0                                    # sky above row 2
    m = EdgeAwareInterpolation()
    # between row 1 (no return) and row 2; lower extension from rows 2 and 3
    near_lower = m.predict(img, [[2.4, 4.0]])        # t = 0.9: extension agrees, keeps P
    assert near_lower[0] == pytest.approx(img[2, 3:5].mean(), rel=1e-3)
    steep = img.copy()
    steep[3:] *= 3.0                                 # rows 2 and 3 no longer on one plane
    # t = 0.1: the nearer row has no return: kept inverse bilinear, or copied with the option
    assert m.predict(steep, [[1.6, 4.0]])[0] == pytest.approx(steep[2, 3:5].mean(), rel=1e-3)
    copier = EdgeAwareInterpolation(copy_no_returns=True)
    assert copier.predict(steep, [[1.6, 4.0]])[0] == 0.0
    assert m.predict(steep, [[2.4, 4.0]])[0] == pytest.approx(steep[2, 3:5].mean(), rel=1e-3)
    # all 4 neighbours without a return: no return
    assert m.predict(img, [[1.0, 4.0]])[0] == 0.0
    # a no-return in an extension row: that extension does not exist
    holes = np.full((6, 8), 10.0, np.float32)
    holes[3:] = 30.0
    holes[1] = 0.0                                   # upper extension of rows 2|3 gone
    q = np.array([[3.2, 4.0], [2.9, 4.0]], np.float32)
    np.testing.assert_allclose(m.predict(holes, q), _reference(holes, q), rtol=1e-5)
    np.testing.assert_allclose(m.predict(holes, q), [30.0, 10.0])


def test_borders_use_the_one_side_available():
    img = np.array([[10.0] * 4, [20.0] * 4, [20.0] * 4], np.float32)
    m = EdgeAwareInterpolation()
    # between rows 0 and 1: only the lower extension (rows 1, 2) exists, and it misses P
    np.testing.assert_allclose(m.predict(img, [[0.8, 2.0], [1.3, 2.0]]), [10.0, 20.0])
    # beyond the outermost row centers: that row alone
    np.testing.assert_allclose(m.predict(img, [[0.1, 2.0], [3.0, 2.0]]), [10.0, 20.0])
    # two rows: no extension exists, inverse bilinear stays
    two = img[:2]
    q = _queries(40, 2, 4)
    np.testing.assert_allclose(m.predict(two, q), InverseBilinear().predict(two, q), rtol=1e-6)


@pytest.mark.parametrize("wrap, copy_no_returns", [(True, False), (False, False), (True, True)])
def test_matches_reference_on_random_images_with_holes(wrap, copy_no_returns):
    rng = np.random.default_rng(3)
    img = rng.uniform(2.0, 60.0, (7, 12)).astype(np.float32)
    img[rng.random(img.shape) < 0.2] = 0.0
    smooth = _plane(7, 12)
    img[:3] = smooth[:3]                             # planar rows where the extensions agree
    q = _queries(2000, 7, 12, seed=4)
    m = EdgeAwareInterpolation(wrap=wrap, copy_no_returns=copy_no_returns)
    ours = m.predict(img, q)
    ref = _reference(img, q, wrap=wrap, copy_no_returns=copy_no_returns)
    np.testing.assert_allclose(ours, ref, rtol=2e-5, atol=1e-5)
    dropped = (ours == 0) & (InverseBilinear(wrap=wrap).predict(img, q) > 0)
    assert dropped.any() == copy_no_returns          # returns turned into no-returns only on ask
    w = m.weights(img, q)
    sums = w.sum(-1)
    assert np.all((np.abs(sums - 1) < 1e-5) | (sums == 0))
    assert np.all((sums == 0) == (ours == 0))


def test_dtypes_shapes_and_batches():
    img = _plane()
    img[3:] *= 2.0
    q = _queries(17, 6, 8)
    m = EdgeAwareInterpolation()
    out = m.predict(img, q)
    assert out.dtype == np.float32 and out.shape == (17,)
    batch = m.predict(np.stack([img, img * 0.5]), q)
    assert batch.shape == (2, 17)
    np.testing.assert_allclose(batch[1], out * 0.5, rtol=1e-5)
    t = m.predict(torch.from_numpy(img), torch.from_numpy(q))
    assert isinstance(t, torch.Tensor) and t.dtype == torch.float32
    np.testing.assert_allclose(t.numpy(), out)
    np.testing.assert_allclose(m.predict(img.astype(np.float64), q, chunk=5), out)
    images = torch.from_numpy(np.stack([img, img]) / 80.0)
    assert m(images.float(), torch.from_numpy(np.stack([q, q]))).shape == (2, 17)


def test_names_work_in_the_front_ends():
    rng = np.random.default_rng(0)
    low = rng.uniform(5, 20, (1, 4, 64)).astype(np.float32)
    rows = evaluate(["edge-aware"], {"4x64": low, "16x64": np.repeat(low, 4, axis=1)},
                    in_size="4x64", out_sizes=["16x64"], progress=False)
    assert rows[0]["method"] == "edge-aware" and rows[0]["n_images"] == 1
    up = upsample_range_image(np.full((16, 1024), 12.0, np.float32), model="edge-aware")
    np.testing.assert_allclose(up[2:-2], 12.0, rtol=1e-5)


@pytest.mark.parametrize("args, exc, match", [
    ({"tolerance": 0.0}, ValueError, "tolerance must be a finite number > 0"),
    ({"tolerance": -0.1}, ValueError, "tolerance must be a finite number > 0"),
    ({"tolerance": float("nan")}, ValueError, "tolerance must be a finite number > 0"),
    ({"tolerance": float("inf")}, ValueError, "tolerance must be a finite number > 0"),
    ({"tolerance": "5%"}, TypeError, "tolerance must be a real number"),
    ({"tolerance": True}, TypeError, "tolerance must be a real number"),
    ({"wrap": 1}, TypeError, "wrap must be a bool"),
    ({"copy_no_returns": "no"}, TypeError, "copy_no_returns must be a bool"),
    ({"max_range": 0.0}, ValueError, "max_range must be a finite number > 0"),
    ({"rows": 2}, ValueError, r"unknown argument\(s\) \['rows'\]"),
])
def test_bad_parameters(args, exc, match):
    with pytest.raises(exc, match=match):
        make({"name": "edge-aware", "args": args})
