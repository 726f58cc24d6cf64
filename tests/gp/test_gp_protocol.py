"""The GP estimators as maps: occgp.maps.OccupancyMap, the registry, insert_scan,
unknown space, the threshold rule, files, octrees and parameters.

Values that pass through BLAS / LAPACK (Cholesky factors, matrix products) are
compared with ``assert_allclose`` at a stated tolerance, never bit for bit: the
kernels BLAS picks depend on the CPU and the sizes.
"""

import ast
import copy
import pathlib

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal
from sklearn.base import clone

import occgp.gp
from occgp.datasets import room_2d
from occgp.gp import (GPOM, GPOMIK, GPMixture, OccupancyGrid, SquaredExponential,
                      observations_from_scans)
from occgp.maps import OccupancyMap, available_maps, make_map, map_type

#: Relative and absolute tolerance of values computed through BLAS twice in the same
#: way (the same calls on the same sizes): rounding of a few ulps at most, so 1e-10
#: leaves a wide margin on any x86-64 CPU.
BLAS_TOL = 1e-10

FACTORIES = {
    "gpomik": lambda: GPOMIK(SquaredExponential(1.7, 0.6), noise=1e-4, optimizer=False,
                             random_state=0),
    "gpom": lambda: GPOM(SquaredExponential(0.66, 1.0), noise=0.13, optimizer=False,
                         random_state=0),
    "gp-mixture": lambda: GPMixture(random_state=0),
    "gp-grid": lambda: OccupancyGrid(resolution=0.5),
}
CLASSES = {"gpomik": GPOMIK, "gpom": GPOM, "gp-mixture": GPMixture, "gp-grid": OccupancyGrid}
NAMES = list(FACTORIES)


@pytest.fixture(scope="module")
def scans():
    return room_2d().scan(n_poses=3)


@pytest.fixture(scope="module")
def queries():
    rng = np.random.default_rng(0)
    return np.vstack([rng.uniform([-10, -8], [10, 8], size=(60, 2)), [[500.0, 500.0]]])


def _insert(model, scans):
    for s in scans:
        model.insert_scan(s.end_points, s.origin, hit=s.hit)
    return model


@pytest.fixture(scope="module")
def mapped(scans):
    return {name: _insert(FACTORIES[name](), scans) for name in NAMES}


# ------------------------------------------------------------------ registry
@pytest.mark.parametrize("name", NAMES)
def test_registered(name):
    entry = map_type(name)
    assert entry.cls is CLASSES[name]
    assert entry.formats == (".npz",)
    assert name in available_maps(dims=2)
    assert (name in available_maps(dims=3)) == (name == "gp-grid")
    assert isinstance(make_map(name, occupancy_threshold=0.6), CLASSES[name])


# ------------------------------------------------------------------ protocol
@pytest.mark.parametrize("name", NAMES)
def test_unfitted_map_answers_the_protocol(name):
    m = FACTORIES[name]()
    assert isinstance(m, OccupancyMap)
    assert np.isnan(m.occupancy([[0.0, 0.0], [1.0, 2.0]])).all()
    occupied, unknown = m.is_occupied([[0.0, 0.0]], return_unknown=True)
    assert occupied.tolist() == [False] and unknown.tolist() == [True]
    lo, hi = m.bounds
    assert np.isnan(lo).all() and np.isnan(hi).all()
    assert m.num_cells == 0 and m.memory_usage() == 0
    assert len(m.to_octree().leaves().centers) == 0


@pytest.mark.parametrize("name", NAMES)
def test_fitted_map_answers_the_protocol(name, mapped, queries):
    m = mapped[name]
    assert isinstance(m, OccupancyMap)
    p = m.occupancy(queries)
    assert p.shape == (len(queries),) and p.dtype == np.float64
    assert np.isnan(p[-1])                       # far from every observation: unknown
    assert m.num_cells > 0 and m.memory_usage() > 0
    lo, hi = m.bounds
    assert lo.shape == hi.shape == (2,) and (lo < hi).all()
    inside = np.all((queries >= lo) & (queries <= hi), axis=1)
    assert np.isnan(p[~inside]).all()            # the known space lies in the bounds


@pytest.mark.parametrize("name", ["gpomik", "gp-mixture", "gp-grid"])
def test_insert_scan_is_fit_then_update(name, scans, mapped, queries):
    ref = FACTORIES[name]()
    for i, s in enumerate(scans):
        data = observations_from_scans([s])
        ref = ref.fit(*data) if i == 0 else ref.update(*data)
    # the same calls on the same data: equal up to BLAS rounding (BLAS_TOL)
    assert_allclose(mapped[name].occupancy(queries), ref.occupancy(queries),
                    rtol=BLAS_TOL, atol=BLAS_TOL)


@pytest.mark.slow
def test_gpom_insert_scan_is_one_fit_on_all_observations(scans, mapped, queries):
    ref = FACTORIES["gpom"]().fit(*observations_from_scans(scans))
    m = mapped["gpom"]
    assert_array_equal(m.X_train_, ref.X_train_)      # no arithmetic: exactly the same points
    # the same fit on the same points: equal up to BLAS rounding (BLAS_TOL)
    assert_allclose(m.predict_proba(queries), ref.predict_proba(queries),
                    rtol=BLAS_TOL, atol=BLAS_TOL)


def test_grid_without_clamping_insert_scan_is_one_fit(scans, queries):
    params = dict(resolution=0.5, clamping_min=1e-9, clamping_max=1 - 1e-9)
    m = _insert(OccupancyGrid(**params), scans)
    ref = OccupancyGrid(**params).fit(*observations_from_scans(scans))
    assert_array_equal(m.keys_, ref.keys_)
    # log-odds sums in another order: a few ulps (1e-12)
    assert_allclose(m.log_odds_, ref.log_odds_, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", NAMES)
def test_occupancy_is_predict_proba_where_known(name, mapped, queries):
    m = mapped[name]
    p = m.occupancy(queries)
    known = ~np.isnan(p)
    assert known[:-1].sum() >= 5
    # the same predict_proba call on the same points (BLAS_TOL)
    assert_allclose(p[known], m.predict_proba(queries)[known], rtol=BLAS_TOL, atol=BLAS_TOL)


def test_grid_predict_proba_keeps_the_prior_where_occupancy_is_nan(mapped, queries):
    m = mapped["gp-grid"]
    p = m.occupancy(queries)
    assert_array_equal(np.isnan(p), ~m.is_known(queries))
    assert (m.predict_proba(queries)[np.isnan(p)] == 0.5).all()


@pytest.mark.parametrize("name", NAMES)
def test_is_occupied_at_or_above_the_threshold(name, mapped, queries):
    m = copy.deepcopy(mapped[name])
    p = m.occupancy(queries)
    j = int(np.flatnonzero(~np.isnan(p))[0])
    m.set_params(occupancy_threshold=float(p[j]))
    assert m.is_occupied(queries[j:j + 1]).tolist() == [True]             # equal: occupied
    m.set_params(occupancy_threshold=float(np.nextafter(p[j], 1.0)))
    assert m.is_occupied(queries[j:j + 1]).tolist() == [False]
    occupied, unknown = m.is_occupied(queries, return_unknown=True)
    assert_array_equal(unknown, np.isnan(p))
    assert not occupied[unknown].any()
    assert_array_equal(occupied[~unknown], p[~unknown] >= m.occupancy_threshold)


# ------------------------------------------------------------------- files
@pytest.mark.parametrize("name", NAMES)
def test_save_load_round_trip(name, mapped, queries, tmp_path):
    m = mapped[name]
    path = tmp_path / "map.npz"
    assert m.save(path) is m
    back = CLASSES[name].load(path)
    assert back.get_params().keys() == m.get_params().keys()
    assert back.num_cells == m.num_cells
    # rebuilt from the same arrays (GPMixture: the same calls replayed): BLAS_TOL
    assert_allclose(back.occupancy(queries), m.occupancy(queries), rtol=BLAS_TOL,
                    atol=BLAS_TOL)
    FACTORIES[name]().save(tmp_path / "empty.npz")
    empty = CLASSES[name].load(tmp_path / "empty.npz")
    assert empty.num_cells == 0 and not np.isnan(empty.get_params()["occupancy_threshold"])


@pytest.mark.parametrize("name", ["gpomik", "gp-mixture", "gp-grid"])
def test_loaded_map_goes_on_inserting_scans(name, scans, mapped, queries, tmp_path):
    path = tmp_path / "map.npz"
    _insert(FACTORIES[name](), scans[:2]).save(path)
    back = _insert(CLASSES[name].load(path), scans[2:])
    # the same calls on the same data (BLAS_TOL)
    assert_allclose(back.occupancy(queries), mapped[name].occupancy(queries),
                    rtol=BLAS_TOL, atol=BLAS_TOL)


def test_old_files_without_occupancy_threshold_load(mapped, tmp_path):
    import json

    from _helpers import rewrite_npz as rewrite

    path = mapped["gpomik"].save(tmp_path / "new.npz") and tmp_path / "new.npz"
    with np.load(path) as f:
        params = json.loads(str(f["params"]))
    del params["occupancy_threshold"]
    old = rewrite(path, tmp_path / "old.npz", params=np.array(json.dumps(params)))
    assert GPOMIK.load(old).occupancy_threshold == 0.5


# ------------------------------------------------------------------ octrees
@pytest.mark.parametrize("name", NAMES)
def test_to_octree_holds_one_layer_of_the_posterior(name, mapped):
    m = mapped[name]
    res = 1.0
    tree = m.to_octree(resolution=res)
    centers, sizes, log_odds = tree.leaves()
    assert len(centers) > 0 and (sizes == res).all()
    assert_allclose(centers[:, 2], 0.5 * res)              # the layer holding z = 0
    p = m.occupancy(centers[:, :2])
    assert not np.isnan(p).any()
    # float32 log-odds in the octree, clamped to [0.001, 0.999]
    assert_allclose(tree.occupancy(centers), np.clip(p, 0.001, 0.999), rtol=1e-5, atol=1e-6)
    assert tree.occupancy_threshold == m.occupancy_threshold


def test_grid_to_octree_copies_its_cells(mapped):
    m = mapped["gp-grid"]
    tree = m.to_octree()
    assert tree.resolution == m.resolution
    assert len(tree.leaves().centers) == m.num_cells
    centers, proba = m.cells()
    assert_allclose(tree.occupancy(np.column_stack([centers, np.zeros(len(centers))])), proba,
                    rtol=1e-6)


def test_grid_3d_insert_scan_and_octree():
    m = OccupancyGrid(resolution=0.5).insert_scan([[2.2, 0.1, 0.3], [0.2, 2.1, 0.3]],
                                                  [0.1, 0.1, 0.3])
    assert m.n_dims_ == 3 and isinstance(m, OccupancyMap)
    tree = m.to_octree()
    centers, proba = m.cells()
    assert_allclose(tree.occupancy(centers), proba, rtol=1e-6)


# --------------------------------------------------------------- bad input
@pytest.mark.parametrize("name", ["gpomik", "gpom", "gp-mixture"])
def test_3d_scan_to_a_2d_map_says_so(name):
    with pytest.raises(ValueError, match="maps 2D scans"):
        FACTORIES[name]().insert_scan(np.ones((4, 3)), np.zeros(3))


@pytest.mark.parametrize("name", NAMES)
def test_insert_scan_rejects_bad_input(name, mapped):
    m = FACTORIES[name]()
    with pytest.raises(ValueError, match="origin must have shape"):
        m.insert_scan(np.ones((4, 2)), np.zeros(3))
    with pytest.raises(ValueError, match=r"hit must have shape \(4,\)"):
        m.insert_scan(np.ones((4, 2)), np.zeros(2), hit=np.ones(3, bool))
    with pytest.raises(TypeError, match="hit must be a bool array"):
        m.insert_scan(np.ones((4, 2)), np.zeros(2), hit=np.ones(4))
    with pytest.raises(ValueError, match="points must have shape"):
        m.insert_scan(np.ones(4), np.zeros(2))
    assert not hasattr(m, "n_dims_")
    fitted = mapped[name]
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 2\)"):
        fitted.occupancy(np.ones((3, 3)))


@pytest.mark.parametrize("name", NAMES)
def test_empty_scan_changes_nothing(name, mapped):
    assert FACTORIES[name]().insert_scan(np.empty((0, 2)), [0.0, 0.0]).num_cells == 0


# -------------------------------------------------------------- parameters
@pytest.mark.parametrize("name", NAMES)
def test_clone_and_params(name, mapped):
    m = mapped[name]
    c = clone(m)
    assert c.num_cells == 0 and isinstance(c, OccupancyMap)
    assert c.get_params()["occupancy_threshold"] == 0.5
    assert c.set_params(occupancy_threshold=0.7) is c and c.occupancy_threshold == 0.7


@pytest.mark.parametrize("name, params, error", [
    ("gpomik", dict(noise=-1.0), ValueError), ("gpom", dict(free_step=0.0), ValueError),
    ("gp-mixture", dict(combine="mean"), ValueError), ("gp-grid", dict(resolution=-1), ValueError),
    ("gpomik", dict(occupancy_threshold=1.5), ValueError),
    ("gp-grid", dict(occupancy_threshold="high"), TypeError),
    ("gpomik", dict(kernel__variance=-1.0), ValueError),
])
def test_rejected_set_params_changes_nothing(name, params, error):
    m = FACTORIES[name]()
    before = m.get_params(deep=True)
    name_of = next(iter(params)).split("__")[-1]
    with pytest.raises(error, match=name_of):
        if "occupancy_threshold" in params:
            m.set_params(**params)
        else:   # a valid change in the same call is undone too
            m.set_params(occupancy_threshold=0.6, **params)
    after = m.get_params(deep=True)
    assert after.keys() == before.keys()
    for k in before:
        if hasattr(before[k], "get_params"):
            assert after[k] is before[k]
        else:
            assert after[k] == before[k], k


def test_unknown_parameter_is_rejected():
    with pytest.raises(ValueError, match="colour"):
        GPOMIK().set_params(colour=1)


# ------------------------------------------------------------------ layout
GP_DIR = pathlib.Path(occgp.gp.__file__).parent


@pytest.mark.parametrize("path", sorted(GP_DIR.glob("*.py")), ids=lambda p: p.name)
def test_gp_modules_share_no_private_names(path):
    """occgp.gp's modules import only public names from each other (a private module
    is fine), and stay under ~800 lines."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            private = [a.name for a in node.names if a.name.startswith("_")]
            assert not private, f"{path.name} imports {private} from .{node.module}"
    assert len(path.read_text().splitlines()) <= 800
