"""The one face of every map (occgp.maps): the protocol, the registry, and a new map
type added in one module (docs/toy_map.py, the architecture page's worked example)."""

import importlib.util
import inspect
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from sklearn.base import clone

import occgp
import occgp.io
import occgp.evaluation
import occgp.knn
from occgp import maps
from occgp.cli import main
from occgp.cli._main import map_methods
from occgp.maps import OccupancyMap, available_maps, capabilities, make_map, map_type, register

TOY = Path(__file__).resolve().parent.parent / "docs" / "toy_map.py"


@pytest.fixture
def toy():
    """docs/toy_map.py imported as a module of its own; its registration undone after."""
    spec = importlib.util.spec_from_file_location("toy_map_example", TOY)
    module = importlib.util.module_from_spec(spec)
    sys.modules["toy_map_example"] = module
    spec.loader.exec_module(module)
    yield module.EndPointCounter
    maps._REGISTRY.pop("toy", None)
    sys.modules.pop("toy_map_example", None)


def _wall_scan(n=400, seed=0):
    rng = np.random.default_rng(seed)
    wall = np.column_stack([np.full(n, 2.0), rng.uniform(-1, 1, (n, 2))])
    return wall, np.zeros(3)


@pytest.mark.parametrize("name", ["octree", "grid", "bgk", "akimap", "knn"])
def test_every_3d_map_answers_the_protocol(name, tmp_path):
    m = make_map(name, resolution=0.2)
    assert isinstance(m, OccupancyMap)
    # on the empty map too: nothing raises, nothing is known
    assert m.num_cells == 0 and np.isnan(np.concatenate(m.bounds)).all()
    assert np.isnan(m.occupancy([[2.0, 0.0, 0.0]])).all()
    points, origin = _wall_scan()
    assert m.insert_scan(points, origin) is m
    assert m.num_cells > 0 and m.memory_usage() > 0
    lo, hi = m.bounds
    assert (lo <= points.min(axis=0) + 1e-9).all() and (hi >= points.max(axis=0) - 1e-9).all()
    p = m.occupancy(points)
    occupied, unknown = m.is_occupied(points, return_unknown=True)
    assert np.array_equal(unknown, np.isnan(p))
    threshold = m.get_params().get("occupancy_threshold", m.get_params().get("p_t"))
    with np.errstate(invalid="ignore"):
        # the one rule: at or above the threshold (a float32 map compares its log-odds,
        # so allow the last bit of a probability exactly at it)
        assert not (occupied & (p < threshold - 1e-6)).any()
        assert (occupied | unknown | (p < threshold + 1e-6)).all()
    far = [[50.0, 50.0, 50.0]]
    occ, unk = m.is_occupied(far, return_unknown=True)
    assert unk.all() and not occ.any()
    # parameters: clone builds an empty map of the same parameters
    c = clone(m)
    assert type(c) is type(m) and c.num_cells == 0
    assert c.get_params() == m.get_params()
    # files: the map's own format round-trips its evidence (.bt keeps only the state)
    formats = map_type(name).formats
    path = tmp_path / ("m" + (".ot" if ".ot" in formats else formats[0]))
    assert m.save(path) is m
    back = type(m).load(path)
    np.testing.assert_allclose(back.occupancy(points), p, rtol=0, atol=1e-6)
    # OctoMap export
    tree = m.to_octree()
    assert isinstance(tree, occgp.OccupancyOctree)
    assert tree.is_occupied(points[occupied]).all()


def test_the_threshold_rule_is_at_or_above():
    m = occgp.OccupancyOctree(0.1).set_cells([[0.05, 0.05, 0.05]], 0.0)   # p = 0.5 exactly
    assert m.is_occupied([[0.05, 0.05, 0.05]]).tolist() == [True]
    m.set_params(occupancy_threshold=0.6)
    assert m.is_occupied([[0.05, 0.05, 0.05]]).tolist() == [False]


def test_capabilities_are_discoverable():
    assert capabilities(occgp.OccupancyOctree) == {"changed_cells", "distance_field", "decay",
                                                  "merge", "project_2d", "frontiers"}
    assert {"project_2d", "frontiers"} <= capabilities(occgp.GridMap)
    assert "colors" in capabilities(occgp.ColorOctree(0.1))
    assert "variance" in map_type("bgk").capabilities
    assert set(maps.CAPABILITIES) == {"variance", "changed_cells", "distance_field", "colors",
                                      "decay", "merge", "project_2d", "frontiers"}


def _insert(m, points, origin, **options):
    """insert_scan, with grey colours for a map that takes them (ColorOctree)."""
    if "colors" in inspect.signature(m.insert_scan).parameters:
        options["colors"] = np.full((len(points), 3), 128, np.uint8)
    return m.insert_scan(points, origin, **options)


@pytest.mark.parametrize("name", available_maps())
def test_every_listed_capability_works(name):
    """A capability a registered map lists is one it has: each is exercised on a map of
    the type (a 2D map lists none of these 3D capabilities)."""
    entry = map_type(name)
    listed = entry.capabilities
    if 3 not in entry.dims:
        assert not listed
        return
    points, origin = _wall_scan()
    m = make_map(name, resolution=0.2)
    if "changed_cells" in listed:
        m.track_changes = True
    stamped = {"stamp": 1.0} if "decay" in listed else {}
    # a map listing decay takes stamp= in insert_scan (else nothing could fade)
    _insert(m, points, origin, **stamped)
    assert m.is_occupied(points).mean() > 0.8
    for capability in listed:
        if capability == "variance":
            v = m.variance(points)
            assert v.shape == (len(points),) and np.isfinite(v).all()
        elif capability == "changed_cells":
            assert len(m.changed_cells().keys) > 0
        elif capability == "distance_field":
            assert m.distance_field([[1.0, -1.0, -1.0], [3.0, 1.0, 1.0]]) is not None
        elif capability == "colors":
            colours, known = m.colors(points)
            assert known.all() and (colours == 128).all()
        elif capability == "decay":
            assert len(m.stamps().keys) >= m.num_cells // 2
            other = clone(m)
            _insert(other, points, origin, **stamped)
            assert other.decay(100.0, max_age=1.0) > 0       # cells older than 1 fade
            assert other.occupancy(points).mean() < m.occupancy(points).mean()
        elif capability == "merge":
            merged = clone(m).merge(m)
            assert merged.num_cells == m.num_cells
        elif capability == "project_2d":
            grid = m.project_2d(-1.5, 1.5)
            assert (grid.states == 1).any()
        elif capability == "frontiers":
            assert m.frontiers() is not None
        else:                                               # a capability not tested here
            raise AssertionError(f"no check for the capability {capability!r}")


@pytest.mark.parametrize("name", [n for n in available_maps()
                                  if "resolution" in map_type(n).parameters()])
@pytest.mark.parametrize("resolution", [1e20, 1e-25, 10**400])
def test_every_map_refuses_resolutions_out_of_range(name, resolution):
    """The docs' range [1e-15, 1e14] m holds for every map built through the registry
    (make_map("bgk", resolution=1e20) was built and answered NaN at its own hits)."""
    with pytest.raises(ValueError, match=r"resolution must lie in \[1e-15, 1e\+14\] m"):
        make_map(name, resolution=resolution)
    with pytest.raises(TypeError, match="resolution must be a real number, got bool"):
        make_map(name, resolution=True)


@pytest.mark.parametrize("dims, raises, message", [
    (3.0, TypeError, r"dims must be an int or a tuple of ints \(2 or 3\), got float"),
    (True, TypeError, "dims must be an int or a tuple of ints .*got bool"),
    ((2, 3.0), TypeError, r"dims must be an int or a tuple of ints .*got \(2, 3.0\)"),
    ("3", TypeError, "dims must be an int or a tuple of ints .*got str"),
    ((), ValueError, "dims must be 2, 3 or a tuple of them"),
    ((2, 4), ValueError, "dims must be 2, 3 or a tuple of them"),
])
def test_register_names_a_bad_dims(dims, raises, message):
    with pytest.raises(raises, match=message):
        register("x", dims=dims)
    assert "x" not in available_maps()


def test_register_names_bad_formats_and_description():
    with pytest.raises(TypeError, match="formats must be a tuple of file suffixes"):
        register("x", formats=".npz")
    with pytest.raises(TypeError, match="formats must be a tuple of file suffixes"):
        register("x", formats=(3,))
    with pytest.raises(TypeError, match="description must be a str or None, got int"):
        register("x", description=3)


def test_registry_lists_builds_and_rejects():
    names = available_maps()
    assert {"octree", "color-octree", "grid", "bgk", "akimap", "knn"} <= set(names)
    assert set(available_maps(dims=3)) <= set(names)
    assert map_type("octree").cls is occgp.OccupancyOctree
    assert map_type("akimap").defaults == {"random_state": 0}
    assert make_map("octree").resolution == 0.1         # the registered default
    assert make_map("akimap").random_state == 0
    assert make_map("akimap", random_state=3).random_state == 3
    with pytest.raises(ValueError, match=r"unknown map type 'nope'; available: octree"):
        make_map("nope")
    with pytest.raises(ValueError, match=r"the 'octree' map takes no parameter 'k'"):
        make_map("octree", k=3)
    with pytest.raises(ValueError, match="dims must be 2, 3 or None"):
        available_maps(dims=4)
    with pytest.raises(TypeError, match="name must be a str"):
        register(3)
    with pytest.raises(ValueError, match="name must be lower-case"):
        register("Bad Name")
    with pytest.raises(ValueError, match="dims must be 2, 3"):
        register("x", dims=5)
    with pytest.raises(ValueError, match="formats must be file suffixes"):
        register("x", formats=("npz",))
    with pytest.raises(ValueError, match="map type 'octree' is taken by occgp.octree"):
        register("octree")(type("Other", (), {}))
    # every registered 3D map, the colour tree too (a plain scan: occupancy only)
    assert "octree" in map_methods() and "color-octree" in map_methods()
    assert set(map_methods()) == set(available_maps(dims=3))


def test_a_new_map_type_is_one_module_and_one_line(toy, tmp_path, capsys):
    assert "toy" in available_maps(dims=3) and "toy" in map_methods()
    m = make_map("toy", resolution=0.2)
    assert isinstance(m, toy) and isinstance(m, OccupancyMap)
    # occgp map builds it from scan files, in its own format and as an octree
    points, origin = _wall_scan()
    occgp.io.write_pcd(tmp_path / "scan.pcd", points)
    for out in ("toy.npz", "toy.bt"):
        assert main(["map", str(tmp_path / "scan.pcd"), "-o", str(tmp_path / out),
                     "--method", "toy", "--resolution", "0.2", "--no-progress"]) == 0
    assert "→" in capsys.readouterr().out
    back = toy.load(tmp_path / "toy.npz")
    np.testing.assert_array_equal(back.occupancy(points),
                                  make_map("toy", resolution=0.2)
                                  .insert_scan(points, origin).occupancy(points))
    tree = occgp.OccupancyOctree.load(tmp_path / "toy.bt")
    assert tree.is_occupied(points).all()
    # the evaluation harness builds and scores it by name, beside the octree
    test = occgp.evaluation.TestSet(np.vstack([points, [[1.0, 0.0, 0.0]]]),
                                    np.r_[np.ones(len(points), bool), False])
    rows = occgp.evaluation.compare_methods(["toy", "octree"], [(points, origin)], test,
                                            progress=False)
    assert [r.method for r in rows] == ["toy", "octree"]
    assert isinstance(rows[0].map, toy) and rows[0].map.resolution == 0.1
    assert rows[0].auc == pytest.approx(rows[0].auc) and 0.0 <= rows[0].mse <= 1.0


def test_deprecated_names_warn():
    m = occgp.OccupancyOctree(0.1).set_params()
    m.track_changes = True
    m.insert_scan([[1.0, 0, 0]], [0, 0, 0])
    changes = m.changed_cells()
    with pytest.deprecated_call(match="Changes.centers"):
        centres = changes.centres
    np.testing.assert_array_equal(centres, changes.centers)
    replay = occgp.knn.ScanReplay([_wall_scan()], 0.2)
    with pytest.deprecated_call(match="num_cells"):
        assert replay.n_cells == replay.num_cells
    with pytest.deprecated_call(match="centers"):
        np.testing.assert_array_equal(replay.centres, replay.centers)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert replay.num_cells == len(replay.centers)
