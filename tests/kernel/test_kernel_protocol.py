"""BGKMap and AKIMap answer the map protocol (occgp.maps.OccupancyMap): the one threshold
rule, unknown cells, bounds, memory, scikit-learn parameters, files and deprecated names."""

import json
import pickle

import numpy as np
import pytest
from numpy.testing import assert_array_equal
from sklearn.base import clone

from occgp import AKIMap, BGKMap
from occgp.maps import OccupancyMap, make_map


def wall():
    y, z = np.meshgrid(np.linspace(-1, 1, 15), np.linspace(-0.4, 0.4, 7))
    return np.column_stack([np.full(y.size, 2.0), y.ravel(), z.ravel()]), np.zeros(3)


MAKERS = {
    "bgk": lambda **kw: BGKMap(0.1, **kw),
    "akimap": lambda **kw: AKIMap(0.1, random_state=0, **kw),
}
QUERY = np.array([[2.0, 0.0, 0.0], [0.5, 0.0, 0.0], [9.0, 9.0, 9.0]])


@pytest.fixture(params=MAKERS.values(), ids=MAKERS.keys())
def make(request):
    return request.param


def filled(make, **kw):
    return make(**kw).insert_scan(*wall())


def assert_same_cells(a, b):
    for x, y in zip(a.cells(), b.cells()):
        assert_array_equal(x, y)


def test_empty_and_filled_maps_are_occupancy_maps(make):
    m = make()
    assert isinstance(m, OccupancyMap)
    assert m.num_cells == 0 and m.memory_usage() >= 0
    low, high = m.bounds
    assert low.shape == high.shape == (3,) and np.isnan(low).all() and np.isnan(high).all()
    assert m.insert_scan(*wall()) is m
    assert isinstance(m, OccupancyMap)
    assert m.num_cells > 0 and m.memory_usage() > 0


def test_bounds_are_the_corners_of_the_cells(make):
    m = filled(make)
    low, high = m.bounds
    centers = m.cells().centers
    np.testing.assert_allclose(low, centers.min(axis=0) - 0.05, rtol=0, atol=1e-12)
    np.testing.assert_allclose(high, centers.max(axis=0) + 0.05, rtol=0, atol=1e-12)
    assert (low <= wall()[0].min(axis=0)).all() and (high >= wall()[0].max(axis=0)).all()


def test_occupied_at_or_above_the_threshold(make):
    m = filled(make)
    p = m.occupancy(QUERY[:1])[0]
    assert 0.5 < p < 1
    m.set_params(occupancy_threshold=p)
    assert m.is_occupied(QUERY[:1]).tolist() == [True]                 # exactly at it
    m.set_params(occupancy_threshold=float(np.nextafter(p, 1.0)))
    assert m.is_occupied(QUERY[:1]).tolist() == [False]
    assert filled(make, occupancy_threshold=p).is_occupied(QUERY[:1]).tolist() == [True]


def test_return_unknown(make):
    m = filled(make)
    occupied = m.is_occupied(QUERY)
    assert occupied.dtype == bool and occupied.tolist() == [True, False, False]
    occ, unknown = m.is_occupied(QUERY, return_unknown=True)
    assert_array_equal(occ, occupied)
    assert unknown.tolist() == [False, False, True]
    assert_array_equal(unknown, np.isnan(m.occupancy(QUERY)))
    occ, unknown = make().is_occupied(QUERY, return_unknown=True)       # empty: all unknown
    assert not occ.any() and unknown.all()
    with pytest.raises(TypeError, match="return_unknown must be a bool, got int"):
        m.is_occupied(QUERY, return_unknown=1)


def test_deprecated_threshold_keeps_the_former_rule(make):
    m = filled(make)
    p = m.occupancy(QUERY[:1])[0]
    with pytest.deprecated_call(match="occupancy_threshold"):
        assert m.is_occupied(QUERY[:1], p).tolist() == [False]          # strictly above
    with pytest.deprecated_call():
        assert m.is_occupied(QUERY, threshold=0.5).tolist() == [True, False, False]
    with pytest.deprecated_call():
        occ, unknown = m.is_occupied(QUERY, threshold=0.5, return_unknown=True)
    assert unknown.tolist() == [False, False, True]
    with pytest.deprecated_call(), pytest.raises(ValueError, match="threshold must lie in"):
        m.is_occupied(QUERY, threshold=1.5)


def test_memory_bytes_is_a_deprecated_alias(make):
    m = filled(make)
    with pytest.deprecated_call(match=r"memory_usage\(\)"):
        assert m.memory_bytes == m.memory_usage()


def test_bad_occupancy_threshold(make):
    with pytest.raises(ValueError, match=r"occupancy_threshold must lie in \(0.0, 1.0\)"):
        make(occupancy_threshold=1.0)
    with pytest.raises(TypeError, match="occupancy_threshold must be a real number"):
        make(occupancy_threshold="0.5")
    m = filled(make)
    m.occupancy_threshold = 0.0                       # changed as an attribute: checked on use
    with pytest.raises(ValueError, match="occupancy_threshold must lie in"):
        m.is_occupied(QUERY)


def test_get_params_returns_the_arguments_as_given(make):
    ell = np.float32(0.3)
    m = make(prior=ell, n_jobs=np.int64(1))
    params = m.get_params()
    assert params["prior"] is ell and params["n_jobs"] == 1
    assert params == m.get_params(deep=False)
    assert type(m)(**params).get_params() == params


def test_clone_builds_an_empty_map_with_the_same_parameters(make):
    m = filled(make, occupancy_threshold=0.6)
    c = clone(m)
    assert type(c) is type(m) and c is not m
    assert c.num_cells == 0 and c.get_params() == m.get_params()
    assert_same_cells(c.insert_scan(*wall()), filled(make, occupancy_threshold=0.6))


def test_clone_of_an_akimap_with_a_generator():
    m = AKIMap(0.1, random_state=np.random.default_rng(4))
    c = clone(m)
    assert isinstance(c.random_state, np.random.Generator) and c.random_state is not m.random_state
    assert_same_cells(c.insert_scan(*wall()), m.insert_scan(*wall()))


def test_set_params_changes_later_updates(make):
    m = make().set_params(prior=0.01, max_cells_per_update=10**8)
    assert m.prior == 0.01 and m.get_params()["max_cells_per_update"] == 10**8
    assert_same_cells(m.insert_scan(*wall()), filled(make, prior=0.01))


def test_set_params_resolution_of_an_empty_map():
    m = BGKMap(0.1).set_params(resolution=0.2)
    assert m.resolution == 0.2
    assert_same_cells(m.insert_scan(*wall()), BGKMap(0.2).insert_scan(*wall()))
    assert BGKMap(0.1).insert_scan(*wall()).set_params(resolution=0.1).resolution == 0.1


def test_set_params_random_state_restarts_the_stream():
    m = AKIMap(0.1, random_state=0).set_params(random_state=7)
    assert_same_cells(m.insert_scan(*wall()), AKIMap(0.1, random_state=7).insert_scan(*wall()))
    again = AKIMap(0.1, random_state=0).insert_scan(*wall())
    state = again._rng.bit_generator.state
    again.set_params(random_state=0, n_jobs=1)              # the same seed: not restarted
    assert again._rng.bit_generator.state == state


REJECTED = [
    (dict(prior=0.5, n_jobs=0), ValueError, "n_jobs must be None"),
    (dict(occupancy_threshold=2.0), ValueError, "occupancy_threshold must lie in"),
    (dict(max_cells_per_update=1.5), TypeError, "max_cells_per_update must be a positive int"),
    (dict(resolution=0.2), ValueError, "resolution cannot change while the map holds cells"),
    (dict(color=1), ValueError, "'color' is not a parameter of"),
]
REJECTED_BGK = [(dict(ell=-1.0), ValueError, "ell must lie in"),
                (dict(free_sample_distance=0.5), ValueError, "is not a parameter of BGKMap")]
REJECTED_AKI = [(dict(variant="paper"), ValueError, "variant must be one of"),
                (dict(random_state=-1), ValueError, "random_state must be None"),
                (dict(ell=0.2), ValueError, "is not a parameter of AKIMap")]


@pytest.mark.parametrize("name, params, exc, match",
                         [(n, *case) for n in MAKERS for case in REJECTED]
                         + [("bgk", *case) for case in REJECTED_BGK]
                         + [("akimap", *case) for case in REJECTED_AKI])
def test_rejected_set_params_changes_nothing(name, params, exc, match):
    m = filled(MAKERS[name])
    before, cells = m.get_params(), m.cells()
    state = m._rng.bit_generator.state if isinstance(m, AKIMap) else None
    with pytest.raises(exc, match=match):
        m.set_params(**params)
    assert m.get_params() == before
    for x, y in zip(cells, m.cells()):
        assert_array_equal(x, y)
    if state is not None:
        assert m._rng.bit_generator.state == state
    assert_same_cells(m.insert_scan(*wall()), filled(MAKERS[name]).insert_scan(*wall()))


def test_insert_scan_takes_no_options(make):
    m = make()
    with pytest.raises(TypeError, match="insert_scan takes no options, got 'max_range'"):
        m.insert_scan(*wall(), max_range=3.0)
    assert m.num_cells == 0


def test_save_load_round_trip_keeps_the_threshold(make, tmp_path):
    m = filled(make, occupancy_threshold=0.7)
    assert m.save(tmp_path / "m.npz") is m
    back = type(m).load(tmp_path / "m.npz")
    assert back.get_params() == m.get_params() and back.occupancy_threshold == 0.7
    assert_same_cells(m, back)
    assert_array_equal(back.is_occupied(QUERY), m.is_occupied(QUERY))
    assert back.bounds[0].tolist() == m.bounds[0].tolist()
    restored = pickle.loads(pickle.dumps(m))
    assert restored.occupancy_threshold == 0.7
    assert_same_cells(m, restored)


def test_files_without_occupancy_threshold_still_load(make, tmp_path):
    """Files written before occupancy_threshold existed read with its default."""
    m = filled(make)
    m.save(tmp_path / "m.npz")
    with np.load(tmp_path / "m.npz", allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    params = json.loads(str(arrays["params"]))
    del params["occupancy_threshold"]
    arrays["params"] = np.array(json.dumps(params))
    np.savez_compressed(tmp_path / "old.npz", **arrays)
    back = type(m).load(tmp_path / "old.npz")
    assert back.occupancy_threshold == 0.5
    assert_same_cells(m, back)


def test_registry_builds_the_maps_and_to_octree_takes_the_threshold():
    m = make_map("bgk", resolution=0.1, occupancy_threshold=0.6).insert_scan(*wall())
    assert isinstance(m, BGKMap) and m.occupancy_threshold == 0.6
    assert m.to_octree().occupancy_threshold == 0.6
    assert make_map("akimap").random_state == 0
    cells = m.cells().centers
    assert_array_equal(m.to_octree().is_occupied(cells), m.is_occupied(cells))
