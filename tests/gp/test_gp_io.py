"""GP models' save / load (GPOMIK, GPOM): exact round trips and clear errors."""

import json

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.exceptions import NotFittedError

from occgp.gp import GPOM, GPOMIK, Matern32, Simpson, SquaredExponential
from _helpers import rewrite_npz as rewrite

X = np.random.default_rng(0).uniform([-1, -2], [4, 2], (300, 2))


def wall(n=6, x=2.0, origin=(0.0, 0.0), y_range=(-1.0, 1.0)):
    y = np.linspace(*y_range, n)
    hits = np.column_stack([np.full(n, x), y])
    return hits, np.tile(origin, (n, 1)).astype(float), hits.copy()


def assert_same_predictions(a, b):
    ma, va = a.predict(X, return_var=True)
    mb, vb = b.predict(X, return_var=True)
    assert_array_equal(ma, mb)
    assert_array_equal(va, vb)
    assert_array_equal(a.predict_proba(X), b.predict_proba(X))


GPOMIKS = {
    "fixed": lambda: GPOMIK(optimizer=False),
    "fitted-cells-kl": lambda: GPOMIK(random_state=0, n_restarts=0, max_cell_size=8,
                                      kl_threshold=1e-4),
    "ard-simpson-gen": lambda: GPOMIK(SquaredExponential(1.0, [0.5, 0.7]), n_restarts=0,
                                      quadrature=Simpson(tol=1e-6),
                                      random_state=np.random.default_rng(2)),
    "list-bounds": lambda: GPOMIK(SquaredExponential(1.0, 0.6), optimizer=False,
                                  noise_bounds=[1e-3, 1.0]),
}


@pytest.mark.parametrize("make", GPOMIKS.values(), ids=GPOMIKS.keys())
def test_gpomik_loaded_predicts_and_updates_exactly_as_the_original(make, tmp_path):
    m = make().fit(*wall())
    for step in range(2):
        assert m.save(tmp_path / "m.npz") is m
        back = GPOMIK.load(tmp_path / "m.npz")
        assert_same_predictions(m, back)
        for attr in ("noise_", "jitter_", "plsc_", "n_dims_", "n_accepted_", "n_rejected_"):
            assert getattr(back, attr) == getattr(m, attr)
        assert repr(back.kernel_) == repr(m.kernel_) and len(back.cells_) == len(m.cells_)
        scan = wall(5, 2.5 + 0.3 * step, (0.2, 0.1 * step))
        m.update(*scan)
        back.update(*scan)
        assert_same_predictions(m, back)
        assert (back.n_accepted_, back.n_rejected_) == (m.n_accepted_, m.n_rejected_)
        for c, d in zip(m.cells_, back.cells_):
            assert_array_equal(c.L, d.L)
            assert_array_equal(c.alpha, d.alpha)


def test_gpomik_parameters_round_trip(tmp_path):
    m = GPOMIK(Matern32(2.0, [0.5, 0.6], variance_bounds=(0.1, 10.0)), noise=0.02,
               noise_bounds=(1e-3, 0.5), quadrature="simpson", n_restarts=3,
               max_cell_size=None, kl_threshold=0.0, random_state=7, n_jobs=2)
    m.save(tmp_path / "u")
    back = GPOMIK.load(tmp_path / "u")
    assert repr(back) == repr(m) and not hasattr(back, "cells_")
    assert back.noise_bounds == (1e-3, 0.5) and back.kernel.length_scale == [0.5, 0.6]
    with pytest.raises(NotFittedError):
        back.predict(X)


@pytest.mark.parametrize("kw", [dict(optimizer=False), dict(random_state=0, n_restarts=0),
                                dict(random_state=np.random.RandomState(3), n_restarts=0)])
def test_gpom_loaded_predicts_exactly_as_the_original(kw, tmp_path):
    hits = np.c_[np.full(9, 2.0), 2.0 * np.tan(np.linspace(-0.6, 0.6, 9))]
    m = GPOM(**kw).fit(hits, np.zeros_like(hits), hits)
    m.save(tmp_path / "m.npz")
    back = GPOM.load(tmp_path / "m.npz")
    assert_same_predictions(m, back)
    assert_array_equal(back.X_train_, m.X_train_)
    assert back.plsc_ == m.plsc_ and back.noise_ == m.noise_


# ---------------------------------------------------------------- bad files
def json_with(path, key, **changes):
    with np.load(path) as z:
        value = json.loads(str(z[key]))
    value.update(changes)
    return np.array(json.dumps(value))


@pytest.fixture
def saved(tmp_path):
    m = GPOMIK(random_state=0, n_restarts=0, max_cell_size=8).fit(*wall())
    m.save(tmp_path / "g.npz")
    return m, tmp_path / "g.npz"


def test_wrong_class_and_format(saved, tmp_path):
    m, path = saved
    with pytest.raises(ValueError, match=r"holds a 'GPOMIK', expected 'GPOM'"):
        GPOM.load(path)
    with pytest.raises(ValueError, match=r"not an occgp.gp_model \.npz file"):
        GPOMIK.load(rewrite(path, tmp_path / "b.npz", format=np.array("occgp.kernel_map")))
    (tmp_path / "t.npz").write_bytes(path.read_bytes()[:-40])
    with pytest.raises(ValueError, match=r"t\.npz: not an occgp.gp_model \.npz file"):
        GPOMIK.load(tmp_path / "t.npz")
    with pytest.raises(FileNotFoundError, match="no such file"):
        GPOM.load(tmp_path / "none.npz")


def test_bad_fitted_state(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "b.npz"
    with np.load(path) as z:
        sizes, L, y, alpha = z["cell_sizes"], z["L"], z["y"], z["alpha"]
    L0 = L.copy()
    L0[0] = -1.0                                     # the first diagonal entry
    a = alpha.copy()
    a[0] = np.nan
    cases = [
        (dict(L=None), r"a fitted GPOMIK needs all of"),
        (dict(L=L[:-1]), r"'L' must hold the lower triangles"),
        (dict(L=L0), r"local model 0 has a diagonal entry <= 0"),
        (dict(alpha=a), r"array 'alpha' holds NaN or inf"),
        (dict(cell_sizes=sizes + 1), r"'cell_sizes' must be positive and sum to"),
        (dict(y=-y), r"the hits must be points with target 1"),
        (dict(labels=np.zeros_like(y)), r"'labels' must be \+1 \(hit\) or -1 \(beam\)"),
        (dict(fitted=json_with(path, "fitted", noise_=-1.0)), r"noise_ must lie in"),
        (dict(fitted=json_with(path, "fitted", n_accepted_=3)), r"n_accepted_ must be"),
        (dict(fitted=json_with(path, "fitted", plsc_=[1, 2])), r"plsc_ must be a pair"),
        (dict(fitted=json_with(path, "fitted", kernel_=1)), r"kernel must be one of"),
        (dict(fitted=json_with(path, "fitted", quadrature_="simpson")),
         r"quadrature_ must be a ClenshawCurtis or Simpson"),
        (dict(fitted=json_with(path, "fitted", kernel_={"__object__": "os.system",
                                                         "params": {}})),
         r"corrupt 'fitted' entry \(ValueError: unknown class 'os.system'"),
        (dict(fitted=json_with(path, "fitted", color=1)), r"the fitted state of a GPOMIK must"),
        (dict(params=json_with(path, "params", noise=-1)),
         r"bad parameters of a GPOMIK: noise"),
        (dict(params=json_with(path, "params", kernel={"__object__": "Matern32",
                                                       "params": {"colour": 1}})),
         r"corrupt 'params' entry \(TypeError"),
    ]
    for changes, match in cases:
        with pytest.raises(ValueError, match=r"b\.npz: .*" + match):
            GPOMIK.load(rewrite(path, bad, **changes))


def test_gpom_bad_training_set(tmp_path):
    hits = np.c_[np.full(4, 2.0), np.linspace(-1, 1, 4)]
    path = tmp_path / "m.npz"
    GPOM(optimizer=False).fit(hits, np.zeros_like(hits), hits).save(path)
    with np.load(path) as z:
        y = z["y_train"]
    for changes, match in [(dict(y_train=-np.ones_like(y)), r"'y_train' must be \+1"),
                           (dict(y_train=y[::-1].copy()), r"'y_train' must be \+1"),
                           (dict(X_train=np.zeros((len(y), 4))), r"1 to 3 dimensions"),
                           (dict(X_train=np.zeros((3, 2))), r"'y_train' must have shape")]:
        with pytest.raises(ValueError, match=r"b\.npz: .*" + match):
            GPOM.load(rewrite(path, tmp_path / "b.npz", **changes))


def test_unsavable_parameter(tmp_path):
    with pytest.raises(TypeError, match=r"cannot save this GPOMIK: .*type object"):
        GPOMIK(noise=object()).save(tmp_path / "x.npz")
    assert not (tmp_path / "x.npz").exists()
