"""The one parameter mechanism (occgp._params) and the one name per concept."""

import warnings
from numbers import Integral, Real

import numpy as np
import pytest
from sklearn.base import clone

import occgp
from occgp import AKIMap, KNNMap
from occgp._params import (DEFAULT_RESOLUTION, Check, Interval, Options, ParamsMixin,
                           renamed_keywords, validate_params)
from occgp._validation import check_n_jobs
from occgp.knn import ScanReplay, check_knn_params


class Thing(ParamsMixin):
    _parameter_constraints = {
        "size": [Interval(Real, 0, None, closed="neither")],
        "count": [Interval(Integral, 1, 10)],
        "kind": [Options(("a", "b"))],
        "limit": [None, Interval(Real, 0, None, closed="neither")],
        "n_jobs": [Check(check_n_jobs, "None or a non-zero int")],
        "flag": ["boolean"],
    }
    _deprecated_params = {"old_size": "size"}

    def __init__(self, size=1.0, *, count=2, kind="a", limit=None, n_jobs=None, flag=False,
                 **deprecated):
        if deprecated:
            size = self._renamed(deprecated, size=size)["size"]
        self.size, self.count, self.kind = size, count, kind
        self.limit, self.n_jobs, self.flag = limit, n_jobs, flag


class SubThing(Thing):
    _parameter_constraints = {**Thing._parameter_constraints,
                              "extra": [Interval(Real, 0, 1, closed="both")]}

    def __init__(self, size=1.0, *, count=2, kind="a", limit=None, n_jobs=None, flag=False,
                 extra=0.5):
        super().__init__(size, count=count, kind=kind, limit=limit, n_jobs=n_jobs, flag=flag)
        self.extra = extra


def test_get_params_and_clone():
    t = Thing(2.0, count=3, kind="b")
    assert t.get_params() == dict(size=2.0, count=3, kind="b", limit=None, n_jobs=None,
                                  flag=False)
    c = clone(t)
    assert type(c) is Thing and c is not t and c.get_params() == t.get_params()
    assert SubThing().get_params()["extra"] == 0.5


@pytest.mark.parametrize("bad, exc, match", [
    (dict(size=0.0), ValueError, r"size must lie in \(0.0, inf\), got 0.0"),
    (dict(size="1"), TypeError, "size must be a real number, got str"),
    (dict(count=11), ValueError, r"count must lie in \[1, 10\], got 11"),
    (dict(count=1.5), TypeError, "count must be a positive int, got float"),
    (dict(kind="c"), ValueError, r"kind must be one of \('a', 'b'\), got 'c'"),
    (dict(limit=-1.0), ValueError, r"limit must lie in \(0.0, inf\)"),
    (dict(n_jobs=0), ValueError, "n_jobs must be None"),
    (dict(flag=1), TypeError, "flag must be a bool"),
    (dict(size=2.0, count=0), ValueError, "count"),
    (dict(nope=1), ValueError, r"'nope' is not a parameter of Thing; its parameters are size"),
])
def test_a_rejected_set_params_changes_nothing(bad, exc, match):
    t = Thing()
    before = t.get_params()
    with pytest.raises(exc, match=match):
        t.set_params(**bad)
    assert t.get_params() == before


def test_set_params_stores_values_as_given():
    t = Thing().set_params(size=3, limit=np.float64(2.0), kind="b")
    assert t.size == 3 and type(t.size) is int and t.kind == "b" and t.limit == 2.0
    assert t.set_params() is t


def test_subclasses_extend_the_table():
    with pytest.raises(ValueError, match=r"extra must lie in \[0.0, 1.0\]"):
        SubThing().set_params(extra=2.0)
    with pytest.raises(ValueError, match="size"):
        SubThing().set_params(size=-1.0)


def test_validate_params_lists_several_constraints():
    table = {"x": [None, "boolean", Options(("auto",))]}
    assert validate_params(table, {"x": None, "y": object()})["x"] is None
    with pytest.raises(ValueError, match=r"x of T must be None or a bool or one of "
                                         r"\('auto',\), got 'no'"):
        validate_params(table, {"x": "no"}, "T")


def test_deprecated_names_warn_and_map_to_the_new_ones():
    with pytest.warns(DeprecationWarning, match="'old_size' is deprecated.*use 'size'"):
        t = Thing(old_size=4.0)
    assert t.size == 4.0 and "old_size" not in t.get_params()
    with pytest.warns(DeprecationWarning, match="use 'size'"):
        t.set_params(old_size=5.0)
    assert t.size == 5.0
    with pytest.raises(TypeError, match="unexpected keyword argument 'other'"):
        Thing(other=1)
    with pytest.raises(TypeError, match="got both 'old_size'"), \
            pytest.warns(DeprecationWarning):
        Thing(2.0, old_size=3.0)


def test_default_resolution():
    assert DEFAULT_RESOLUTION == 0.1
    for cls in (KNNMap, AKIMap, occgp.BGKMap):
        assert cls().resolution == DEFAULT_RESOLUTION


# ------------------------------------------------------------------ the renames
def test_knnmap_old_names():
    with pytest.warns(DeprecationWarning, match="'p_t' is deprecated.*'occupancy_threshold'"):
        m = KNNMap(0.1, p_t=0.6)
    assert m.occupancy_threshold == 0.6
    with pytest.warns(DeprecationWarning, match="'sensor_range' is deprecated.*'max_range'"):
        m = KNNMap(0.1, sensor_range=3.0)
    assert m.max_range == 3.0
    with pytest.warns(DeprecationWarning, match="'max_range'"):
        assert m.sensor_range == 3.0
    with pytest.warns(DeprecationWarning, match="'occupancy_threshold'"):
        assert m.p_t == 0.5
    with pytest.warns(DeprecationWarning, match="'occupancy_threshold'"):
        m.set_params(p_t=0.7)
    assert m.occupancy_threshold == 0.7
    with pytest.warns(DeprecationWarning) as caught:
        q = check_knn_params(dict(k=1, p_u=0.9, p_l=0.3, p_m=0.2, p_m_out=0.4, p_min=0.05,
                                  p_max=0.95, p_t=0.5, sensor_range=4.0))
    messages = " ".join(str(w.message) for w in caught)
    assert "'p_t' is deprecated" in messages and "'sensor_range' is deprecated" in messages
    assert q["max_range"] == 4.0 and q["occupancy_threshold"] == 0.5 and "p_t" not in q


def test_knnmap_pickles_of_old_names_load():
    import pickle
    from occgp.knn._map import _rebuild_knn
    m = KNNMap(0.1, max_range=3.0, occupancy_threshold=0.6)
    cls, (klass, params, data, scores, history) = m.__reduce__()
    old = {{"max_range": "sensor_range", "occupancy_threshold": "p_t"}.get(k, k): v
           for k, v in params.items()}
    back = _rebuild_knn(klass, old, data, scores, history)
    assert back.get_params() == m.get_params()
    assert pickle.loads(pickle.dumps(m)).get_params() == m.get_params()


def test_akimap_schedule_range(tmp_path):
    with pytest.warns(DeprecationWarning, match="'sensor_range' is deprecated.*'schedule_range'"):
        m = AKIMap(0.1, sensor_range=8.0)
    assert m.schedule_range == 8.0 and "sensor_range" not in m.get_params()
    with pytest.warns(DeprecationWarning, match="'schedule_range'"):
        assert m.sensor_range == 8.0
    # a file written with the old name still loads (without a warning)
    import json
    path = tmp_path / "m.npz"
    m.save(path)
    with np.load(path) as f:
        arrays = dict(f)
    params = json.loads(str(arrays["params"]))
    params["sensor_range"] = params.pop("schedule_range")
    arrays["params"] = np.array(json.dumps(params))
    np.savez(path, **arrays)
    assert AKIMap.load(path).schedule_range == 8.0


def test_replay_and_grid_search_old_names():
    scans = [(np.array([[1.0, 0.0, 0.0], [1.0, 0.1, 0.0]]), np.zeros(3))]
    with pytest.warns(DeprecationWarning, match="'max_range'"):
        rep = ScanReplay(scans, 0.1, sensor_range=3.0)
    assert rep.max_range == 3.0
    with pytest.warns(DeprecationWarning, match="use centers"):
        rep.centres


@pytest.mark.parametrize("name", occgp.available_maps())
def test_every_map_has_the_one_names(name):
    m = occgp.make_map(name)
    params = m.get_params()
    assert not {"sensor_range", "p_t", "centres"} & set(params)
    before = m.get_params(deep=False)
    with pytest.raises(ValueError, match="'no_such' is not a"):
        m.set_params(no_such=1)
    if "occupancy_threshold" in params:
        with pytest.raises(ValueError, match="occupancy_threshold"):
            m.set_params(occupancy_threshold=1.5)
    if "max_range" in params:
        with pytest.raises((ValueError, TypeError), match="max_range"):
            m.set_params(max_range=-1.0)
    after = m.get_params(deep=False)
    assert after.keys() == before.keys()
    assert all(after[k] is before[k] or after[k] == before[k] for k in before)
    clone(m)


def test_renamed_keywords_keeps_the_old_name_for_one_release():
    @renamed_keywords(centres="centers")
    def count(centers, *, scale=1):
        """Count."""
        return len(centers) * scale

    assert count.__name__ == "count" and count.__doc__ == "Count."
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert count([1, 2]) == count(centers=[1, 2], scale=1) == 2
    with pytest.warns(DeprecationWarning, match="count: the parameter 'centres' is deprecated "
                      "and will be removed in the next release; use 'centers' instead") as rec:
        assert count(centres=[1, 2, 3], scale=2) == 6
    assert rec[0].filename == __file__                       # points at the caller
    with pytest.raises(TypeError, match="got both 'centres' .* and 'centers'"), \
            pytest.warns(DeprecationWarning):
        count(centers=[1], centres=[1])
