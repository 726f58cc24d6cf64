"""Kernel maps' save / load: exact round trips and clear errors for bad files."""

import json
import zipfile

import numpy as np
import pytest
from numpy.testing import assert_array_equal

from occgp import AKIMap, BGKMap
from _helpers import rewrite_npz as rewrite


def wall(shift=0.0):
    y, z = np.meshgrid(np.linspace(-1, 1, 15), np.linspace(-0.4, 0.4, 7))
    points = np.column_stack([np.full(y.size, 2.0 + shift), y.ravel(), z.ravel()])
    return points, np.array([shift, 0.1, 0.0])


QUERY = np.random.default_rng(0).uniform([-1, -1.5, -1], [4, 1.5, 1], (500, 3))

MAKERS = {
    "bgk": lambda: BGKMap(0.1, ell=0.25),
    "aki-int": lambda: AKIMap(0.1, random_state=3),
    "aki-pcg": lambda: AKIMap(0.1, random_state=np.random.default_rng(5)),
    "aki-range": lambda: AKIMap(0.1, max_range=2.1, random_state=3),
    "bgk-range": lambda: BGKMap(0.1, max_range=2.1),
    "aki-drop": lambda: AKIMap(0.1, max_range=2.1, far_beams="drop", random_state=3),
    "aki-mt": lambda: AKIMap(0.1, variant="published",
                             random_state=np.random.Generator(np.random.MT19937(7))),
    "aki-philox": lambda: AKIMap(0.1, random_state=np.random.Generator(np.random.Philox(1))),
}


def assert_same_map(a, b):
    assert type(a) is type(b)
    for x, y in zip(a.cells(), b.cells()):
        assert_array_equal(x, y)
    assert_array_equal(a.occupancy(QUERY), b.occupancy(QUERY))
    assert_array_equal(a.variance(QUERY), b.variance(QUERY))
    assert a.num_cells == b.num_cells


@pytest.fixture
def saved(tmp_path):
    m = AKIMap(0.1, random_state=0).update(*wall())
    path = tmp_path / "aki.npz"
    m.save(path)
    return m, path


@pytest.mark.parametrize("make", MAKERS.values(), ids=MAKERS.keys())
def test_loaded_map_predicts_and_updates_exactly_as_the_original(make, tmp_path):
    m = make()
    m.update(*wall()).update(*wall(0.3))
    assert m.save(tmp_path / "m.npz") is m
    back = type(m).load(tmp_path / "m.npz")
    assert_same_map(m, back)
    params, back_params = m.get_params(), back.get_params()
    if isinstance(params.get("random_state"), np.random.Generator):
        assert back_params.pop("random_state") is back._rng
        params.pop("random_state")
    assert back_params == params
    if isinstance(m, AKIMap):
        for f, g in zip(m.last_bandwidths_, back.last_bandwidths_):
            assert_array_equal(f, g)
            assert f.dtype == g.dtype
    m.update(*wall(0.6))
    back.update(*wall(0.6))
    assert_same_map(m, back)                        # AKIMap: the same free samples drawn
    if isinstance(m, AKIMap):
        assert_array_equal(m._rng.random(4), back._rng.random(4))


@pytest.mark.parametrize("make", [lambda: BGKMap(0.2, prior=0.5, max_range=None),
                                  lambda: AKIMap(0.2, bandwidth_floor=0.0, n_jobs=2)])
def test_empty_map_and_its_parameters_round_trip(make, tmp_path):
    m = make()
    path = tmp_path / "empty"                       # written as named, no suffix added
    m.save(path)
    assert path.exists() and not (tmp_path / "empty.npz").exists()
    back = type(m).load(str(path))
    assert back.num_cells == 0 and back.get_params() == m.get_params()
    assert np.isnan(back.occupancy(QUERY)).all()
    assert_same_map(m.update(*wall()), back.update(*wall()))


def test_file_is_plain_arrays(saved):
    m, path = saved
    with np.load(path, allow_pickle=False) as z:
        assert str(z["format"]) == "occgp.kernel_map" and int(z["version"]) == 1
        assert str(z["class"]) == "AKIMap"
        assert json.loads(str(z["params"]))["random_state"] == 0
        assert z["keys"].dtype == np.uint16 and z["alpha"].dtype == np.float32
        cells = m.cells()
        centers = (z["keys"].astype(np.float64) - 32768 + 0.5) * m.resolution
        assert_array_equal(centers, cells.centers)
        assert_array_equal(z["alpha"] + np.float64(m.prior), cells.alpha)


# ---------------------------------------------------------------- bad files


def params_with(path, **changes):
    with np.load(path) as z:
        params = json.loads(str(z["params"]))
    params.update(changes)
    return np.array(json.dumps(params))


def test_missing_file_directory_and_path_type(tmp_path):
    with pytest.raises(FileNotFoundError, match="no such file.*nothere"):
        BGKMap.load(tmp_path / "nothere.npz")
    with pytest.raises(IsADirectoryError, match="is not a file"):
        BGKMap.load(tmp_path)
    with pytest.raises(TypeError, match="path must be a str or os.PathLike, got int"):
        BGKMap.load(3)
    with pytest.raises(TypeError, match="path must be a str or os.PathLike, got list"):
        BGKMap(0.1).save([1])
    with pytest.raises(OSError):
        BGKMap(0.1).save(tmp_path / "no" / "dir" / "m.npz")


@pytest.mark.parametrize("content", [b"", b"hello, not a map\n", b"PK\x03\x04broken",
                                     b"\x93NUMPY\x01\x00"])
def test_not_an_npz_archive(tmp_path, content):
    path = tmp_path / "bad.npz"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=r"bad\.npz: not an occgp\.kernel_map \.npz file"):
        BGKMap.load(path)


def test_single_npy_array(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros(3))
    with pytest.raises(ValueError, match=r"a single \.npy array"):
        BGKMap.load(tmp_path / "a.npy")
    with open(tmp_path / "huge.npy", "wb") as f:      # refused before any allocation
        np.lib.format.write_array_header_1_0(
            f, {"descr": "<f8", "fortran_order": False, "shape": (10 ** 12,)})
    with pytest.raises(ValueError, match=r"a single \.npy array"):
        BGKMap.load(tmp_path / "huge.npy")


def test_truncated_file_is_an_error(saved, tmp_path):
    m, path = saved
    data = path.read_bytes()
    for n in np.linspace(1, len(data) - 1, 40).astype(int):
        (tmp_path / "cut.npz").write_bytes(data[:n])
        with pytest.raises(ValueError, match=r"cut\.npz: "):
            AKIMap.load(tmp_path / "cut.npz")


def test_flipped_bytes_are_caught_or_harmless(saved, tmp_path):
    m, path = saved
    data = bytearray(path.read_bytes())
    rng = np.random.default_rng(1)
    caught = 0
    for pos in rng.choice(len(data), 60, replace=False):
        bad = data.copy()
        bad[pos] ^= 0x5A
        (tmp_path / "flip.npz").write_bytes(bytes(bad))
        try:
            back = AKIMap.load(tmp_path / "flip.npz")
        except (ValueError, OSError):
            caught += 1
        else:                                       # e.g. a time stamp: the same map
            assert_same_map(m, back)
    assert caught > 30


def test_wrong_format_version_and_class(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "bad.npz"
    with pytest.raises(ValueError,
                       match=r"its format is 'octomap', expected 'occgp.kernel_map'"):
        AKIMap.load(rewrite(path, bad, format=np.array("octomap")))
    with pytest.raises(ValueError, match=r"no 'format' entry"):
        AKIMap.load(rewrite(path, bad, format=None))
    with pytest.raises(ValueError, match=r"'format' must be a 0-d str array"):
        AKIMap.load(rewrite(path, bad, format=np.zeros(2)))
    with pytest.raises(ValueError, match=r"format version 2 is not supported"):
        AKIMap.load(rewrite(path, bad, version=np.array(2)))
    with pytest.raises(ValueError, match=r"array 'version' must have dtype int64"):
        AKIMap.load(rewrite(path, bad, version=np.array(1.0)))
    with pytest.raises(ValueError, match=r"holds a 'AKIMap', expected 'BGKMap'"):
        BGKMap.load(path)
    BGKMap(0.1).save(bad)
    with pytest.raises(ValueError, match=r"holds a 'BGKMap', expected 'AKIMap'"):
        AKIMap.load(bad)


def test_missing_misshaped_and_unexpected_arrays(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "bad.npz"
    with np.load(path) as z:
        keys, alpha, beta = z["keys"], z["alpha"], z["beta"]
    n = len(keys)
    cases = [
        (dict(alpha=None), r"array 'alpha' is missing"),
        (dict(rng=None), r"array 'rng' is missing"),
        (dict(alpha=alpha[:-1]), rf"array 'alpha' must have shape \({n},\), got \({n - 1},\)"),
        (dict(keys=keys[:, :2]), rf"array 'keys' must have shape \({n}, 3\), got \({n}, 2\)"),
        (dict(alpha=alpha.astype(np.float64)), r"array 'alpha' must have dtype float32, got"),
        (dict(keys=keys.astype(np.int64)), r"array 'keys' must have dtype uint16"),
        (dict(extra=np.zeros(3)), r"unexpected entries \['extra.npy'\]"),
        (dict(bw_weight=None), r"the last bandwidths need all of"),
        (dict(bw_scale=np.zeros(2)), r"array 'bw_scale' must have shape"),
    ]
    for changes, match in cases:
        with pytest.raises(ValueError, match=r"bad\.npz: .*" + match):
            AKIMap.load(rewrite(path, bad, **changes))


def test_pickled_object_array_is_refused(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "bad.npz"
    with pytest.raises(ValueError, match=r"array 'alpha' must have dtype float32, got object"):
        AKIMap.load(rewrite(path, bad, alpha=np.array([{"a": 1}] * 3, dtype=object)))


def test_bad_evidence(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "bad.npz"
    with np.load(path) as z:
        keys, alpha = z["keys"], z["alpha"]
    for value, match in [(np.nan, "holds NaN or inf"), (np.inf, "holds NaN or inf"),
                         (-1.0, "holds negative values")]:
        a = alpha.copy()
        a[3] = value
        with pytest.raises(ValueError, match=r"array 'alpha' " + match):
            AKIMap.load(rewrite(path, bad, alpha=a))
    k = keys.copy()
    k[1] = k[0]
    with pytest.raises(ValueError, match=r"array 'keys' holds a cell more than once"):
        AKIMap.load(rewrite(path, bad, keys=k))
    with np.load(path) as z:
        prec = z["bw_precision"].copy()
    prec[0, 0, 0] = np.nan
    with pytest.raises(ValueError, match=r"array 'bw_precision' holds NaN or inf"):
        AKIMap.load(rewrite(path, bad, bw_precision=prec))
    with pytest.raises(ValueError, match=r"'bw_n_same' holds counts under 1"):
        AKIMap.load(rewrite(path, bad, bw_n_same=np.zeros(len(prec), dtype=np.int64)))


def test_bad_parameters(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "bad.npz"
    cases = [
        (np.array("{not json"), r"corrupt 'params' entry: not valid JSON"),
        (np.array("[" * 100000 + "]" * 100000), r"corrupt 'params' entry"),
        (np.array("[1, 2]"), r"expected a JSON object, got list"),
        (np.array('{"resolution": NaN}'), r"not valid JSON \(non-finite number NaN\)"),
        (params_with(path, color=1), r"the parameters of a AKIMap must be"),
        (params_with(path, resolution=-1.0),
         r"bad parameters of a AKIMap: resolution must lie in \(0.0, inf\), got -1.0"),
        (params_with(path, variant="other"), r"bad parameters of a AKIMap: variant must"),
        (params_with(path, random_state="seven"), r"bad parameters of a AKIMap: random_state"),
    ]
    for params, match in cases:
        with pytest.raises(ValueError, match=r"bad\.npz: .*" + match):
            AKIMap.load(rewrite(path, bad, params=params))


def test_akimap_max_range_is_saved_and_older_files_without_it_load_with_none(saved, tmp_path):
    m, path = saved
    limited = AKIMap(0.1, max_range=2.1, random_state=0).update(*wall())
    limited.save(tmp_path / "limited.npz")
    assert AKIMap.load(tmp_path / "limited.npz").max_range == 2.1
    with np.load(path) as z:
        params = json.loads(str(z["params"]))
    assert params["max_range"] is None
    del params["max_range"]                    # as written before AKIMap had max_range
    old = AKIMap.load(rewrite(path, tmp_path / "old.npz", params=np.array(json.dumps(params))))
    assert old.max_range is None
    for x, y in zip(old.cells(), m.cells()):
        assert_array_equal(x, y)
    with pytest.raises(ValueError, match=r"bad parameters of a AKIMap: max_range must lie"):
        AKIMap.load(rewrite(path, tmp_path / "bad.npz", params=params_with(path,
                                                                              max_range=-3.0)))
    # an old pickle's parameters (no max_range) rebuild the map too
    from occgp.kernel._kernel_io import restore_kernel_map
    keys, alpha, beta = m._cells_arrays()
    back = restore_kernel_map(AKIMap, params, keys, alpha, beta)
    assert back.max_range is None and back.num_cells == m.num_cells


@pytest.mark.parametrize("cls", [BGKMap, AKIMap])
def test_far_beams_is_saved_and_older_files_without_it_load_with_their_rule(cls, tmp_path):
    """Files and pickles written before far_beams existed: with a max_range, their maps
    dropped the beams beyond it (far_beams="drop"); without one, the default."""
    from occgp.kernel._kernel_io import restore_kernel_map
    kw = {"random_state": 0} if cls is AKIMap else {}
    for far_beams in ("cut", "drop"):
        m = cls(0.1, max_range=2.1, far_beams=far_beams, **kw).update(*wall())
        m.save(tmp_path / "m.npz")
        assert cls.load(tmp_path / "m.npz").far_beams == far_beams
    for max_range, rule in ((2.1, "drop"), (None, "cut")):
        written = cls(0.1, max_range=max_range, far_beams=rule, **kw).update(*wall())
        written.save(tmp_path / "new.npz")
        with np.load(tmp_path / "new.npz") as z:
            params = json.loads(str(z["params"]))
        del params["far_beams"]                  # as written before far_beams existed
        old = cls.load(rewrite(tmp_path / "new.npz", tmp_path / "old.npz",
                               params=np.array(json.dumps(params))))
        assert old.far_beams == rule and old.max_range == max_range
        assert_same_map(old, written)
        old.update(*wall(0.3))
        assert_same_map(old, written.update(*wall(0.3)))    # and goes on by the same rule
        keys, alpha, beta = written._cells_arrays()
        assert restore_kernel_map(cls, dict(params), keys, alpha, beta).far_beams == rule
    with pytest.raises(ValueError, match=r"bad parameters of a .*far_beams must be one of"):
        cls.load(rewrite(tmp_path / "new.npz", tmp_path / "bad.npz",
                         params=params_with(tmp_path / "new.npz", far_beams="keep")))


def mt_state(key):
    return {"bit_generator": "MT19937", "state": {"key": key, "pos": 0}}


def test_bad_random_state(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "bad.npz"
    with np.load(path) as z:
        state = json.loads(str(z["rng"]))
    cases = [
        ({"bit_generator": "os.system"}, r"expected a bit generator among"),
        ([1, 2], r"expected a bit generator among"),
        ({**state, "state": {"state": "x", "inc": 1}}, r"corrupt random state of its PCG64"),
        ({**state, "state": None}, r"corrupt random state of its PCG64"),
        (mt_state({"__ndarray__": "<u4", "data": [-1]}), r"corrupt random state of its MT"),
        (mt_state({"__ndarray__": "|O", "data": [1]}), r"corrupt random state of its MT19937"),
        (mt_state([1, 2]), r"corrupt random state of its MT19937"),
    ]
    for value, match in cases:
        with pytest.raises(ValueError, match=r"bad\.npz: .*" + match):
            AKIMap.load(rewrite(path, bad, rng=np.array(json.dumps(value))))


def _replace_member(src, dst, name, data):
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, data if info.filename == name else zin.read(info))
    return dst


def test_lying_headers_are_refused_before_any_allocation(saved, tmp_path):
    m, path = saved
    bad = tmp_path / "bad.npz"
    header = {"descr": "<u2", "fortran_order": False, "shape": (10 ** 12, 3)}
    import io
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, header)
    with pytest.raises(ValueError, match=r"array 'keys': its header announces "
                                         r"6000000000000 bytes of data, the archive holds 0"):
        AKIMap.load(_replace_member(path, bad, "keys.npy", buf.getvalue()))
    with pytest.raises(ValueError, match=r"corrupt array 'alpha'"):
        AKIMap.load(_replace_member(path, bad, "alpha.npy", b"\x93NUMPY\x09\x00xx"))
    # a member far larger than deflate could make from its compressed size
    with zipfile.ZipFile(bad, "w", compression=zipfile.ZIP_BZIP2) as z:
        for key, value in [("format", np.array("occgp.kernel_map")),
                           ("version", np.array(1)), ("class", np.array("BGKMap")),
                           ("params", np.array(json.dumps(BGKMap(0.1).get_params()))),
                           ("keys", np.zeros((2_000_000, 3), np.uint16)),
                           ("alpha", np.zeros(2_000_000, np.float32)),
                           ("beta", np.zeros(2_000_000, np.float32))]:
            with z.open(key + ".npy", "w") as f:
                np.lib.format.write_array(f, value)
    with pytest.raises(ValueError, match=r"corrupt array 'keys': 12000128 bytes from"):
        BGKMap.load(bad)


def test_parameters_changed_after_construction(tmp_path):
    m = BGKMap(0.1, n_jobs=np.int64(1)).update(*wall())
    m.save(tmp_path / "a.npz")                       # numpy ints saved as ints
    assert_same_map(m, BGKMap.load(tmp_path / "a.npz"))
    m.prior = -1.0
    with pytest.raises(ValueError, match=r"prior must lie in \(0.0, inf\), got -1.0"):
        m.save(tmp_path / "b.npz")
    assert not (tmp_path / "b.npz").exists()
