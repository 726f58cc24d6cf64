"""ILN, LIIF and bilinear models: registry, shapes, convexity, no-return rules and bad input."""

from types import SimpleNamespace

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from occgp.iln.models import (  # noqa: E402
    ILN,
    LIIF,
    Bilinear,
    InverseBilinear,
    available_models,
    make,
    register,
    upsample_image,
)

SMALL = {
    "iln": {"channels": 16, "n_resblocks": 1, "depth": 1},
    "iln0": {"channels": 16, "n_resblocks": 1, "depth": 0},
    "iln-plain": {"channels": 16, "n_resblocks": 1, "depth": 1, "range_tokens": False,
                  "weight_prior": "none"},
    "iln-bilinear": {"channels": 16, "n_resblocks": 1, "depth": 1, "weight_prior": "bilinear"},
    "liif": {"channels": 16, "n_resblocks": 1, "hidden": [32]},
    "bilinear": {},
    "inverse-bilinear": {},
}


def _model(key, **extra):
    torch.manual_seed(0)
    name = "iln" if key.startswith("iln") else key
    return make({"name": name, "args": {**SMALL[key], **extra}})


def _image(rows=8, cols=32, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(2.0, 60.0, (rows, cols)).astype(np.float32)


def _queries(n, rows=8, cols=32, seed=1):
    rng = np.random.default_rng(seed)
    return rng.uniform([0, 0], [rows, cols], (n, 2)).astype(np.float32)


def _neighbour_ranges(img, q, wrap=True):
    """The 4 neighbours' ranges of each query, direct numpy version."""
    rows, cols = img.shape
    v, u = q[:, 0] - 0.5, q[:, 1] - 0.5
    i0, j0 = np.floor(v).astype(int), np.floor(u).astype(int)
    ii = np.clip(np.stack([i0, i0, i0 + 1, i0 + 1], 1), 0, rows - 1)
    jj = np.stack([j0, j0 + 1, j0, j0 + 1], 1)
    jj = np.mod(jj, cols) if wrap else np.clip(jj, 0, cols - 1)
    return img[ii, jj]


def test_registry_lists_models_and_rejects_duplicates():
    assert {"iln", "liif", "bilinear", "edsr-baseline"} <= set(available_models())
    with pytest.raises(ValueError, match="already registered"):
        register("iln")(type("Other", (), {}))


@pytest.mark.parametrize("key", list(SMALL))
@pytest.mark.parametrize("n", [0, 1, 10000])
def test_predict_shapes_any_query_count(key, n):
    m = _model(key)
    img = _image()
    q = _queries(n)
    out = m.predict(img, q)
    assert isinstance(out, np.ndarray) and out.shape == (n,) and out.dtype == np.float32
    batch = np.stack([img, _image(seed=3)])
    out_b = m.predict(batch, q)
    assert out_b.shape == (2, n)
    np.testing.assert_allclose(out_b[0], out, rtol=1e-5, atol=1e-4)
    out_t = m.predict(torch.from_numpy(batch), torch.from_numpy(np.stack([q, q])))
    assert isinstance(out_t, torch.Tensor) and tuple(out_t.shape) == (2, n)


def test_predict_does_not_depend_on_chunk_and_keeps_training_mode():
    m = _model("iln")
    img, q = _image(), _queries(300)
    m.train()
    a = m.predict(img, q, chunk=128)
    b = m.predict(img, q)
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-5)
    assert m.training


@pytest.mark.parametrize("key", ["iln", "iln0"])
def test_iln_output_is_a_convex_combination_of_neighbours(key):
    m = _model(key)
    img = _image()
    img[2:4, 5:9] = 0.0  # some no-return pixels
    q = _queries(3000)
    w = m.weights(img, q)
    r = _neighbour_ranges(img, q)
    valid = r > 0
    has = valid.any(1)
    np.testing.assert_allclose(w[has].sum(1), 1.0, atol=1e-5)
    assert np.all(w >= 0) and np.all(w[~valid] == 0)
    out = m.predict(img, q)
    lo = np.where(valid, r, np.inf).min(1)
    hi = np.where(valid, r, -np.inf).max(1)
    assert np.all(out[has] >= lo[has] - 1e-3) and np.all(out[has] <= hi[has] + 1e-3)
    np.testing.assert_allclose(out, (w * r).sum(1), rtol=1e-5, atol=1e-4)


def test_bilinear_equals_direct_formula():
    img = _image()
    q = _queries(2000)
    # interior queries: all 4 neighbours exist (no clamping)
    q = q[(q[:, 0] > 0.5) & (q[:, 0] < 7.5) & (q[:, 1] > 0.5) & (q[:, 1] < 31.5)]
    v, u = q[:, 0] - 0.5, q[:, 1] - 0.5
    i, j = np.floor(v).astype(int), np.floor(u).astype(int)
    a, b = v - i, u - j
    direct = (
        img[i, j] * (1 - a) * (1 - b) + img[i, j + 1] * (1 - a) * b
        + img[i + 1, j] * a * (1 - b) + img[i + 1, j + 1] * a * b
    )
    np.testing.assert_allclose(Bilinear().predict(img, q), direct, rtol=1e-5)
    # at pixel centers it returns the pixel
    centers = np.array([[2.5, 3.5], [0.5, 0.5], [7.5, 31.5]], dtype=np.float32)
    np.testing.assert_allclose(Bilinear().predict(img, centers), img[[2, 0, 7], [3, 0, 31]], rtol=1e-6)


def test_inverse_bilinear_equals_direct_formula():
    img, q = _image(), _queries(500)
    img[2:4, 5:9] = 0.0
    r = _neighbour_ranges(img, q).astype(np.float64)
    b = _bilinear_weights(q) * (r > 0)
    inverse = (b / np.where(r > 0, r, 1.0)).sum(1)
    ok = b.sum(1) > 1e-12
    expected = np.where(ok, b.sum(1) / np.where(ok, inverse, 1.0), 0.0)
    m = InverseBilinear()
    np.testing.assert_allclose(m.predict(img, q), expected, rtol=1e-5)
    w = m.weights(img, q)
    np.testing.assert_allclose(w[ok].sum(1), 1.0, atol=1e-6)
    np.testing.assert_allclose((w * r).sum(1), expected, rtol=1e-5)
    flat = np.full((8, 32), 12.5, np.float32)   # a constant image stays constant
    np.testing.assert_allclose(m.predict(flat, q), 12.5, rtol=1e-6)


def test_bilinear_wraps_horizontally_and_clamps_vertically():
    img = _image()
    q = np.array([[3.0, 0.0], [3.0, 32.0], [0.0, 10.0]], dtype=np.float32)
    out = Bilinear().predict(img, q)
    seam = 0.5 * (img[2, 0] + img[2, 31]) * 0.5 + 0.5 * (img[3, 0] + img[3, 31]) * 0.5
    np.testing.assert_allclose(out[:2], seam, rtol=1e-5)
    np.testing.assert_allclose(out[2], 0.5 * (img[0, 9] + img[0, 10]), rtol=1e-5)
    # without wrap-around the left edge is clamped to column 0
    out = Bilinear(wrap=False).predict(img, q[:1])
    np.testing.assert_allclose(out, 0.5 * (img[2, 0] + img[3, 0]), rtol=1e-5)


@pytest.mark.parametrize("key", list(SMALL))
def test_no_return_neighbours_never_blend_and_all_missing_returns_zero(key):
    m = _model(key)
    img = _image()
    img[:, 10:14] = 0.0
    q = np.array(
        [[4.0, 12.0],   # all 4 neighbours lack a return
         [4.0, 10.0],   # 2 of 4 lack a return (left pair valid)
         [4.2, 14.3]],  # right pair valid, left pair missing
        dtype=np.float32,
    )
    out = m.predict(img, q)
    assert out[0] == 0.0
    w = m.weights(img, q)
    np.testing.assert_array_equal(w[0], 0.0)
    assert np.all(w[1, [1, 3]] == 0) and np.all(w[2, [0, 2]] == 0)
    if key != "liif":  # ILN and bilinear output lies within the valid neighbours' ranges
        r = _neighbour_ranges(img, q)
        for k in (1, 2):
            valid = r[k][r[k] > 0]
            assert valid.min() - 1e-3 <= out[k] <= valid.max() + 1e-3


def test_liif_is_area_weighted_ensemble():
    m = _model("liif")
    img, q = _image(), _queries(50)
    w = m.weights(img, q)
    np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-5)
    # with 4 returns the ensemble weights are the bilinear weights
    np.testing.assert_allclose(w, Bilinear().weights(img, q), atol=1e-6)


@pytest.mark.parametrize("key", list(SMALL))
def test_spec_round_trip_gives_identical_outputs(key):
    m = _model(key)
    img, q = _image(), _queries(200)
    spec = m.spec()
    m2 = make(spec, load_sd=True)
    np.testing.assert_array_equal(m.predict(img, q), m2.predict(img, q))
    assert m2.spec(with_sd=False) == {"name": spec["name"], "args": spec["args"]}


def test_iln_range_tokens_embed_relative_log_ranges_of_neighbours_with_returns():
    # Encoder and position embedding zeroed, no attention: the logits are head(range_embed(
    # log r_t - mean log r)). With logit_t = -(log r_t - mean) the weights are proportional to
    # 1 / r_t and the output is the harmonic mean of the neighbours with returns.
    m = _model("iln0", weight_prior="none")
    with torch.no_grad():
        for p in list(m.encoder.parameters()) + list(m.pos_embed.parameters()):
            p.zero_()
        m.range_embed.weight.zero_()
        m.range_embed.bias.zero_()
        m.range_embed.weight[0, 0] = 1.0
        m.head.weight.zero_()
        m.head.bias.fill_(3.0)
        m.head.weight[0, 0] = -1.0
    img = _image()
    img[2:4, 5:9] = 0.0
    q = _queries(2000)
    r = _neighbour_ranges(img, q)
    valid = r > 0
    has = valid.any(1)
    inverse = np.where(valid, 1.0 / np.where(valid, r, 1.0), 0.0).sum(1)
    out = m.predict(img, q)
    np.testing.assert_allclose(out[has], valid.sum(1)[has] / inverse[has], rtol=1e-4)
    assert np.all(out[~has] == 0)
    assert _model("iln-plain").range_embed is None
    assert not any("range_embed" in k for k in _model("iln-plain").state_dict())


def _bilinear_weights(q, rows=8, cols=32):
    v, u = q[:, 0] - 0.5, q[:, 1] - 0.5
    a, b = v - np.floor(v), u - np.floor(u)
    return np.stack([(1 - a) * (1 - b), (1 - a) * b, a * (1 - b), a * b], 1)


@pytest.mark.parametrize("prior", ["bilinear", "inverse-range"])
def test_untrained_iln_is_its_weight_prior(prior):
    # The head starts at zero: the logits are the prior alone, log(b_t + eps) [- log r_t].
    m = _model("iln", weight_prior=prior)
    img = _image()
    img[2:4, 5:9] = 0.0
    q = _queries(3000)
    r = _neighbour_ranges(img, q).astype(np.float64)
    valid = r > 0
    has = valid.any(1)
    w = (_bilinear_weights(q) + 1e-4) * valid
    if prior == "inverse-range":
        w = w / np.where(valid, r, 1.0)
    w = w / np.where(has, w.sum(1), 1.0)[:, None]
    np.testing.assert_allclose(m.weights(img, q), w, atol=2e-5)
    np.testing.assert_allclose(m.predict(img, q), (w * r).sum(1), rtol=1e-4, atol=1e-3)
    if prior == "inverse-range":  # on a flat range image it is plain inverse-range bilinear
        assert np.allclose(m.predict(np.full((8, 32), 7.0, np.float32), q), 7.0)


def test_iln_depth_zero_has_no_attention():
    m = _model("iln0")
    assert isinstance(m, ILN) and isinstance(_model("liif"), LIIF)
    assert len(m.blocks) == 0 and not any("attn" in k for k in m.state_dict())


def test_encoder_padding_is_circular_horizontally():
    m = _model("iln")
    img = _image()
    f1 = m.encode(torch.from_numpy(img)[None] / 80, True)
    f2 = m.encode(torch.from_numpy(np.roll(img, 5, axis=1))[None] / 80, True)
    torch.testing.assert_close(torch.roll(f1, 5, dims=-1), f2, rtol=1e-5, atol=1e-5)


def test_model_follows_device():
    m = Bilinear().to("cpu")
    assert m._device().type == "cpu"
    img, q = _image(), _queries(10)
    out = m.predict(torch.from_numpy(img), torch.from_numpy(q))
    assert out.device.type == "cpu"


def test_upsample_image_full_resolution():
    lo = SimpleNamespace(rows=8, cols=32, vertical_fov=(-15.0, 15.0), horizontal_fov=360.0)
    hi = SimpleNamespace(rows=32, cols=64, vertical_fov=(-15.0, 15.0), horizontal_fov=360.0)
    img = _image()
    out = upsample_image(Bilinear(), img, lo, hi)
    assert out.shape == (32, 64) and out.dtype == np.float32
    # out pixel (i, j) sits at input (v, u) = ((i + .5) / 4, (j + .5) / 2)
    ii, jj = np.meshgrid(np.arange(32), np.arange(64), indexing="ij")
    q = np.stack([(ii + 0.5) / 4, (jj + 0.5) / 2], -1).reshape(-1, 2).astype(np.float32)
    np.testing.assert_allclose(out.ravel(), Bilinear().predict(img, q), rtol=1e-5)
    # a wider output field of view: rows outside the input's get no return
    wide = SimpleNamespace(rows=16, cols=32, vertical_fov=(-30.0, 30.0), horizontal_fov=360.0)
    out = upsample_image(Bilinear(), img, lo, wide)
    assert np.all(out[:3] == 0) and np.all(out[-3:] == 0) and np.all(out[5:11] > 0)
    batch = upsample_image(_model("iln"), torch.from_numpy(np.stack([img, img])), lo, hi)
    assert isinstance(batch, torch.Tensor) and tuple(batch.shape) == (2, 32, 64)


# ---------------------------------------------------------------------------------- bad input

BAD_PREDICT = [
    (np.zeros((2, 3, 4, 5)), _queries(3), ValueError, r"range_image must have shape \(rows, cols\)"),
    (np.zeros((0, 32)), _queries(3), ValueError, "range_image must not be empty"),
    (np.full((8, 32), np.nan), _queries(3), ValueError, "range_image must be finite"),
    (np.full((8, 32), np.inf), _queries(3), ValueError, "range_image must be finite"),
    (-np.ones((8, 32)), _queries(3), ValueError, "range_image must be non-negative"),
    (np.full((8, 32), 1e30), _queries(3), ValueError, r"range_image must hold ranges <= 1e\+06 m"),
    ("image", _queries(3), TypeError, "range_image must be a numpy array or a torch tensor"),
    (None, _queries(3), TypeError, "range_image must be a numpy array or a torch tensor"),
    (np.ones((8, 32), dtype=complex), _queries(3), TypeError, "range_image must hold real numbers"),
    (_image(), np.zeros((3, 3)), ValueError, r"queries must have shape \(n_queries, 2\)"),
    (_image(), np.zeros(2), ValueError, r"queries must have shape \(n_queries, 2\)"),
    (_image(), np.array([[np.nan, 1.0]]), ValueError, "queries must be finite"),
    (_image(), np.array([[9.0, 1.0]]), ValueError, "queries must lie within the input image"),
    (_image(), np.array([[1.0, -0.1]]), ValueError, "queries must lie within the input image"),
    (_image(), np.array([[1.0, 1e30]]), ValueError, "queries must lie within the input image"),
    (_image(), np.zeros((2, 3, 2)), ValueError, r"queries of shape \(batch, n_queries, 2\) need"),
    (np.ones((2, 8, 32)), np.zeros((3, 4, 2)), ValueError, "queries batch size 3 does not match"),
    (_image(), "q", TypeError, "queries must be a numpy array or a torch tensor"),
]


@pytest.mark.parametrize("key", ["iln", "bilinear"])
@pytest.mark.parametrize("image, queries, exc, match", BAD_PREDICT)
def test_predict_rejects_bad_input(key, image, queries, exc, match):
    with pytest.raises(exc, match=match):
        _model(key).predict(image, queries)


def test_predict_rejects_bad_chunk_and_wrap():
    with pytest.raises(ValueError, match="chunk must be >= 1"):
        Bilinear().predict(_image(), _queries(2), chunk=0)
    with pytest.raises(TypeError, match="wrap must be a bool"):
        Bilinear().predict(_image(), _queries(2), wrap="yes")


@pytest.mark.parametrize(
    "spec, exc, match",
    [
        ("iln", TypeError, "spec must be a dict"),
        ({"args": {}}, ValueError, "spec must have a 'name' key"),
        ({"name": "nope"}, ValueError, r"spec\['name'\] must be one of"),
        ({"name": "iln", "args": [1]}, TypeError, r"spec\['args'\] must be a dict"),
        ({"name": "iln", "args": {"colour": 1}}, ValueError, r"unknown argument\(s\) \['colour'\]"),
        ({"name": "iln", "args": {"channels": 12}}, ValueError, "channels must be a multiple of heads=8"),
        ({"name": "iln", "args": {"channels": 0}}, ValueError, "channels must be >= 1"),
        ({"name": "iln", "args": {"channels": 16.5}}, TypeError, "channels must be an int"),
        ({"name": "iln", "args": {"depth": -1}}, ValueError, "depth must be >= 0"),
        ({"name": "iln", "args": {"max_range": 0.0}}, ValueError, "max_range must be a finite number > 0"),
        ({"name": "iln", "args": {"max_range": float("nan")}}, ValueError, "max_range must be a finite"),
        ({"name": "liif", "args": {"hidden": "64"}}, TypeError, "hidden must be a list of ints"),
        ({"name": "bilinear", "args": {"wrap": 1}}, TypeError, "wrap must be a bool"),
        ({"name": "iln", "args": {"range_tokens": "yes"}}, TypeError, "range_tokens must be a bool"),
        ({"name": "iln", "args": {"weight_prior": "cubic"}}, ValueError,
         r"weight_prior must be one of \['inverse-range', 'bilinear', 'none'\], got 'cubic'"),
        ({"name": "iln", "args": {"weight_prior": None}}, TypeError, "weight_prior must be one of"),
    ],
)
def test_make_rejects_bad_specs(spec, exc, match):
    with pytest.raises(exc, match=match):
        make(spec)


def test_make_load_sd_errors():
    spec = {"name": "iln", "args": SMALL["iln"]}
    with pytest.raises(ValueError, match=r"load_sd=True needs spec\['sd'\]"):
        make(spec, load_sd=True)
    other = _model("iln", channels=8).spec()
    with pytest.raises(ValueError, match=r"spec\['sd'\] does not fit model 'iln'"):
        make({**spec, "sd": other["sd"]}, load_sd=True)


def test_upsample_image_rejects_bad_input():
    lo = SimpleNamespace(rows=8, cols=32, vertical_fov=(-15.0, 15.0), horizontal_fov=360.0)
    with pytest.raises(ValueError, match=r"image must have shape \(8, 32\) of in_model"):
        upsample_image(Bilinear(), np.ones((4, 32)), lo, lo)
    with pytest.raises(TypeError, match="in_model must be a LidarModel"):
        upsample_image(Bilinear(), _image(), object(), lo)
    with pytest.raises(TypeError, match="model must be an occgp.iln model"):
        upsample_image(object(), _image(), lo, lo)
    with pytest.raises(ValueError, match="image must be finite"):
        upsample_image(Bilinear(), np.full((8, 32), np.nan), lo, lo)
