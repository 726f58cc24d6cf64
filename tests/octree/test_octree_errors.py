"""Bad input to OccupancyOctree (and to GridMap, for the checks of insert_scan they share):
a clear error naming the argument, and the map unchanged."""

import numpy as np
import pytest

from occgp import GridMap, OccupancyOctree
from octomap_reference import leaf_values
from _helpers import grid_values

#: The value of each cell of a map, by its class.
VALUES = {OccupancyOctree: leaf_values, GridMap: grid_values}


@pytest.fixture
def m():
    return OccupancyOctree(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 0])


@pytest.fixture(params=[OccupancyOctree, GridMap], ids=["octree", "grid"])
def any_map(request):
    """The octree or the grid, after one scan (for the input checks they share)."""
    return request.param(0.1).insert_scan([[1.0, 0, 0], [0, 1.0, 0]], [0, 0, 0])


@pytest.mark.parametrize("bad", [np.zeros((5, 2)), np.zeros(3), np.zeros((2, 3, 1)), [[1, 2]]])
def test_insert_rejects_bad_shape(any_map, bad):
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 3\), got"):
        any_map.insert_scan(bad, [0.0, 0.0, 0.0])


@pytest.mark.parametrize("bad", [[["a", "b", "c"]], np.zeros((2, 3), dtype=complex),
                                 np.array([[None, 1, 2]], dtype=object)])
def test_insert_rejects_non_numeric(any_map, bad):
    with pytest.raises(TypeError, match="points must hold real numbers, got dtype"):
        any_map.insert_scan(bad, [0.0, 0.0, 0.0])


def test_insert_rejects_ragged(m):
    with pytest.raises(ValueError, match="points must be a numeric array"):
        m.insert_scan([[1, 2, 3], [1, 2]], [0, 0, 0])


@pytest.mark.parametrize("value", [np.nan, np.inf, -np.inf])
def test_insert_rejects_non_finite_points_and_keeps_map(any_map, value):
    values = VALUES[type(any_map)]
    before = values(any_map)
    pts = np.ones((10, 3))
    pts[7, 1] = value
    with pytest.raises(ValueError, match=r"points must be finite: 1 of 10 rows .* row 7"):
        any_map.insert_scan(pts, [0, 0, 0])
    assert values(any_map) == before


@pytest.mark.parametrize("bad, match", [
    ([0, 0], r"origin must have shape \(3,\), got \(2,\)"),
    ([[0, 0, 0]], r"origin must have shape \(3,\), got \(1, 3\)"),
    ([0, np.nan, 0], "origin must be finite"),
    (["x", "y", "z"], "origin must hold real numbers"),
])
def test_insert_rejects_bad_origin(any_map, bad, match):
    err = TypeError if "real numbers" in match else ValueError
    with pytest.raises(err, match=match):
        any_map.insert_scan([[1.0, 1, 1]], bad)


def test_points_outside_key_range_rejected_and_map_unchanged(m):
    before = leaf_values(m)
    pts = np.array([[1.0, 0, 0], [4000.0, 0, 0], [0, -3300, 0]])
    with pytest.raises(ValueError, match=r"2 of 3 points lie outside the octree's key range "
                                         r"\[-3276.8, 3276.8\) m .* row 1\); the map is unchanged"):
        m.insert_scan(pts, [0, 0, 0])
    assert leaf_values(m) == before
    with pytest.raises(ValueError, match=r"origin \[5000.0, 0.0, 0.0\] lies outside"):
        m.insert_scan([[1.0, 0, 0]], [5000, 0, 0])
    assert leaf_values(m) == before


def test_far_points_are_fine_when_max_range_truncates_them(m):
    m.insert_scan([[4000.0, 0, 0]], [0, 0, 0], max_range=2.0)
    assert not m.is_occupied([[1.5, 0, 0]])[0]


@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap], ids=["octree", "grid"])
@pytest.mark.parametrize("far", [
    np.array([[1e39, 0, 0]]),                          # beyond float range
    np.array([[1e20, 1e20, 0]]),                       # a float square overflows
    np.array([[1e20, 0, 0]], dtype=np.float32),        # the same in float32 points
    np.array([[-3e38, 0, 3e38]], dtype=np.float32),
], ids=["float64-beyond-float", "float64-overflowing-square", "float32", "float32-max"])
def test_rays_to_overflowing_points_are_cut_at_max_range(cls, far):
    """A ray whose float squared length overflows is cut at max_range as a near point on
    its line is (the double-precision cut of insert_scan), in float32 points too."""
    m = cls(0.1).insert_scan(far, [0, 0, 0], max_range=2.0)
    near = far.astype(np.float64) / np.linalg.norm(far.astype(np.float64)) * 4.0
    ref = cls(0.1).insert_scan(near, [0, 0, 0], max_range=2.0)
    assert VALUES[cls](m) == VALUES[cls](ref)
    assert m.num_cells == ref.num_cells > 0


@pytest.mark.parametrize("kwargs, err, match", [
    (dict(mode="fast"), ValueError, r"mode must be one of \('scan', 'ray'\), got 'fast'"),
    (dict(max_range=0.0), ValueError, r"max_range must lie in \(0.0, inf\), got 0.0"),
    (dict(max_range=-1.0), ValueError, "max_range must lie in"),
    (dict(max_range=np.nan), ValueError, "max_range must lie in"),
    (dict(max_range="5"), TypeError, "max_range must be a real number, got str"),
    (dict(discretize=1), TypeError, "discretize must be a bool"),
    (dict(discretize=True, mode="ray"), ValueError, "discretize=True is only defined"),
])
def test_insert_rejects_bad_options(m, kwargs, err, match):
    with pytest.raises(err, match=match):
        m.insert_scan([[1.0, 0, 0]], [0, 0, 0], **kwargs)


@pytest.mark.parametrize("kwargs, err, match", [
    (dict(resolution=0.0), ValueError, r"resolution must lie in \(0.0, inf\), got 0.0"),
    (dict(resolution=-0.1), ValueError, "resolution must lie in"),
    (dict(resolution=np.inf), ValueError, "resolution must lie in"),
    (dict(resolution="0.1"), TypeError, "resolution must be a real number, got str"),
    (dict(resolution=True), TypeError, "resolution must be a real number, got bool"),
    (dict(prob_hit=1.0), ValueError, r"prob_hit must lie in \(0.5, 1.0\), got 1.0"),
    (dict(prob_hit=0.4), ValueError, "prob_hit must lie in"),
    (dict(prob_miss=0.0), ValueError, r"prob_miss must lie in \(0.0, 0.5\)"),
    (dict(prob_miss=0.6), ValueError, "prob_miss must lie in"),
    (dict(clamping_min=0.6), ValueError, r"clamping_min must lie in \(0.0, 0.5\)"),
    (dict(clamping_max=0.4), ValueError, r"clamping_max must lie in \(0.5, 1.0\)"),
    (dict(occupancy_threshold=1.5), ValueError, "occupancy_threshold must lie in"),
])
@pytest.mark.parametrize("cls", [OccupancyOctree, GridMap], ids=["octree", "grid"])
def test_constructor_rejects_bad_parameters(cls, kwargs, err, match):
    kwargs = {"resolution": 0.1, **kwargs}
    with pytest.raises(err, match=match):
        cls(**kwargs)


@pytest.mark.parametrize("method", ["occupancy", "log_odds", "is_occupied"])
def test_queries_reject_bad_points(any_map, method):
    with pytest.raises(ValueError, match=r"points must have shape \(n_points, 3\)"):
        getattr(any_map, method)([1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="points must be finite"):
        getattr(any_map, method)([[np.nan, 0, 0]])


def test_queries_outside_key_range_are_unknown(m):
    assert np.isnan(m.occupancy([[1e6, 0, 0], [0, 0, -1e30]])).all()


def test_cast_rays_rejects_bad_input(m):
    with pytest.raises(ValueError, match="directions must be non-zero, got 1 zero"):
        m.cast_rays([0, 0, 0], [[1, 0, 0], [0, 0, 0]])
    with pytest.raises(ValueError, match=r"origins must have shape \(3,\) or \(2, 3\)"):
        m.cast_rays(np.zeros((3, 3)), [[1, 0, 0], [0, 1, 0]])
    with pytest.raises(ValueError, match=r"max_range must be a scalar or of shape \(1,\)"):
        m.cast_rays([0, 0, 0], [[1, 0, 0]], max_range=[1.0, 2.0])
    with pytest.raises(ValueError, match="max_range must be positive and finite"):
        m.cast_rays([0, 0, 0], [[1, 0, 0]], max_range=[-1.0])
    with pytest.raises(ValueError, match="1 of 1 origins lie outside"):
        m.cast_rays([[1e5, 0, 0]], [[1, 0, 0]])


def test_leaves_rejects_bad_bbox(m):
    with pytest.raises(ValueError, match=r"bbox must have shape \(2, 3\)"):
        m.leaves(bbox=[0, 0, 0])
    with pytest.raises(ValueError, match="bbox must have min <= max"):
        m.leaves(bbox=[[1, 1, 1], [0, 0, 0]])
    with pytest.raises(TypeError, match="bbox must hold real numbers"):
        m.leaves(bbox=[["a"] * 3] * 2)


# ---------------------------------------------------------------------- files
def test_load_missing_file_raises_oserror(tmp_path):
    with pytest.raises(OSError):
        OccupancyOctree.load(tmp_path / "nope.bt")


def test_save_rejects_unknown_suffix(m, tmp_path):
    with pytest.raises(ValueError, match=r"path must end in .bt or .ot"):
        m.save(tmp_path / "map.png")
    with pytest.raises(ValueError, match=r"format must be one of \('bt', 'ot'\)"):
        m.to_bytes("png")


@pytest.mark.parametrize("fmt", ["bt", "ot"])
def test_truncated_files_raise_clear_errors(m, tmp_path, fmt):
    data = m.to_bytes(fmt)
    header_end = data.index(b"data\n") + 5
    for cut in (header_end + 1, len(data) - 1, header_end - 3, 10):
        path = tmp_path / f"cut.{fmt}"
        path.write_bytes(data[:cut])
        with pytest.raises(ValueError, match=r"cut\.(bt|ot): (truncated|corrupt)|not an OctoMap"):
            OccupancyOctree.load(path)


def test_corrupt_files_raise_clear_errors(m):
    data = m.to_bytes("ot")
    with pytest.raises(ValueError, match="not an OctoMap file"):
        OccupancyOctree.from_bytes(b"hello\nworld\n")
    with pytest.raises(ValueError, match="holds a 'ColorOcTree' tree"):
        OccupancyOctree.from_bytes(data.replace(b"id OcTree", b"id ColorOcTree"))
    with pytest.raises(ValueError, match="(header announces|corrupt header: it announces) 99 nodes"):
        size = data.split(b"size ")[1].split(b"\n")[0]
        OccupancyOctree.from_bytes(data.replace(b"size " + size, b"size 99"))
    with pytest.raises(ValueError, match="malformed header"):
        OccupancyOctree.from_bytes(data.replace(b"res 0.1", b"res abc"))
    with pytest.raises(ValueError, match="header resolution must be positive"):
        OccupancyOctree.from_bytes(data.replace(b"res 0.1", b"res -1"))
    with pytest.raises(TypeError, match="data must be bytes"):
        OccupancyOctree.from_bytes("text")


def test_deep_binary_tree_is_refused():
    """Child code 11 (inner) on every level: deeper than 16 levels, refused before reading."""
    from occgp.io._octomap_format import write_header

    body = b"\x03\x00" * 40
    with pytest.raises(ValueError, match="deeper than the 16 levels"):
        OccupancyOctree.from_bytes(write_header(True, 41, 0.1) + body)


def test_non_finite_values_in_ot_are_refused(m):
    data = bytearray(m.to_bytes("ot"))
    start = data.index(b"data\n") + 5
    data[start:start + 4] = np.float32(np.nan).tobytes()
    with pytest.raises(ValueError, match="non-finite log-odds"):
        OccupancyOctree.from_bytes(bytes(data))
