"""Map plugins (the ``occgp.maps`` entry-point group), ``occgp map -h``'s list of map
types, and the one call every registered map answers: ``insert_scan(points, origin)``.

A plugin here is a distribution installed the way pip leaves one, without a network: a
``NAME-VERSION.dist-info`` folder (METADATA, entry_points.txt) beside its module, in a
folder put on ``sys.path`` (in-process) or on ``PYTHONPATH`` (the command line in a fresh
interpreter).
"""

import importlib
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest

import occgp
import occgp.io
from occgp import maps
from occgp.cli._main import _map_types_help
from occgp.maps import MapPluginWarning, available_maps, make_map, map_type

PLUGIN_MODULE = '''
"""A map plugin: an octree whose end cells are marked twice per scan."""
from occgp import OccupancyOctree
from occgp.maps import register


@register("twice-octree", formats=(".ot",), description="An octree that inserts each "
          "scan twice (a plugin's test map)", resolution=0.25)
class TwiceOctree(OccupancyOctree):
    """An octree that inserts each scan twice."""

    def insert_scan(self, points, origin, **options):
        super().insert_scan(points, origin, **options)
        return super().insert_scan(points, origin, **options)
'''


def write_dist(folder, dist, version, entry_points, modules):
    """Install a distribution as pip does, without a network: its modules and a
    ``dist-info`` folder (METADATA, entry_points.txt, RECORD) in `folder`."""
    info = folder / f"{dist.replace('-', '_')}-{version}.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: {version}\n")
    (info / "entry_points.txt").write_text(
        "[occgp.maps]\n" + "".join(f"{k} = {v}\n" for k, v in entry_points.items()))
    (info / "RECORD").write_text("")
    for name, text in modules.items():
        (folder / f"{name}.py").write_text(textwrap.dedent(text))
    return folder


@pytest.fixture
def plugins(monkeypatch):
    """Put plugin folders on sys.path and have the registry read the entry points anew;
    the registry, sys.path and sys.modules are as they were after the test."""
    registry = dict(maps._REGISTRY)
    modules = set(sys.modules)
    available_maps()                                  # the built-in maps first

    def add(folder):
        monkeypatch.syspath_prepend(str(folder))
        importlib.invalidate_caches()
        monkeypatch.setattr(maps, "_plugins_loaded", False)

    yield add
    maps._REGISTRY.clear()
    maps._REGISTRY.update(registry)
    for name in set(sys.modules) - modules:
        if name.startswith("occgp_test_"):
            del sys.modules[name]


def _wall(n=300, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([np.full(n, 2.05), rng.uniform(-1, 1, (n, 2))]), np.zeros(3)


def test_a_plugin_distribution_is_listed_and_built(plugins, tmp_path):
    plugins(write_dist(tmp_path, "occgp-twice", "0.1", {"twice": "occgp_test_twice"},
                       {"occgp_test_twice": PLUGIN_MODULE}))
    names = available_maps()
    assert names[-1] == "twice-octree" and "octree" in names
    assert "twice-octree" in available_maps(dims=3)
    entry = map_type("twice-octree")
    assert entry.plugin == "twice = occgp_test_twice (distribution occgp-twice)"
    assert map_type("octree").plugin is None
    points, origin = _wall()
    m = make_map("twice-octree", prob_hit=0.8).insert_scan(points, origin)
    assert m.prob_hit == 0.8 and type(m).__name__ == "TwiceOctree"
    # two updates of each end cell: log-odds 2 * logit(0.8)
    np.testing.assert_allclose(m.log_odds(points), 2 * np.log(4), rtol=1e-6)
    help_text = _map_types_help(width=200)
    assert "* twice-octree" in help_text
    assert "[plugin twice = occgp_test_twice (distribution occgp-twice)]" in help_text
    # the entry points are read once
    assert available_maps() == names


def test_a_plugin_entry_point_may_name_a_function(plugins, tmp_path):
    module = '''
    def setup():
        from occgp import OccupancyOctree
        from occgp.maps import register
        register("fn-octree", description="Registered by a function", resolution=0.3)(
            type("FnOctree", (OccupancyOctree,), {"__module__": __name__}))
    '''
    plugins(write_dist(tmp_path, "occgp-fn", "1.0", {"fn": "occgp_test_fn:setup"},
                       {"occgp_test_fn": module}))
    assert "fn-octree" in available_maps()
    assert make_map("fn-octree").resolution == 0.3
    assert map_type("fn-octree").description == "Registered by a function"


def test_occgp_map_builds_a_plugins_map(tmp_path):
    """The command line in a fresh interpreter finds the plugin on PYTHONPATH."""
    site = write_dist(tmp_path / "site", "occgp-twice", "0.1", {"twice": "occgp_test_twice"},
                      {"occgp_test_twice": PLUGIN_MODULE})
    points, origin = _wall()
    occgp.io.write_pcd(tmp_path / "scan.pcd", points)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(site)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    cmd = [sys.executable, "-c", "import sys; from occgp.cli import main; "
           "sys.exit(main(sys.argv[1:]))"]
    help_run = subprocess.run(cmd + ["map", "-h"], env=env, capture_output=True, text=True,
                              timeout=120)
    assert help_run.returncode == 0, help_run.stderr
    assert "twice-octree" in help_run.stdout and "a plugin's test map" in help_run.stdout
    run = subprocess.run(cmd + ["map", str(tmp_path / "scan.pcd"), "-o",
                                str(tmp_path / "m.ot"), "--method", "twice-octree",
                                "--param", "prob_hit=0.8", "--no-progress"],
                         env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    assert "wrote" in run.stdout and not run.stderr
    m = occgp.OccupancyOctree.load(tmp_path / "m.ot")
    np.testing.assert_allclose(m.log_odds(points), 2 * np.log(4), rtol=1e-6)
    assert m.resolution == pytest.approx(0.25)        # the plugin's registered default
    # a parameter the plugin's map does not take is a usage error, as for any map
    bad = subprocess.run(cmd + ["map", str(tmp_path / "scan.pcd"), "-o",
                                str(tmp_path / "b.ot"), "--method", "twice-octree",
                                "--param", "k=3"], env=env, capture_output=True, text=True,
                         timeout=120)
    assert bad.returncode == 2 and "takes no parameter 'k'" in bad.stderr


def test_a_broken_plugin_is_a_warning_naming_it(plugins, tmp_path):
    broken = '''
    from occgp.maps import register
    from occgp import OccupancyOctree
    register("half-done", description="registered before the import fails")(
        type("HalfDone", (OccupancyOctree,), {"__module__": __name__}))
    import occgp_no_such_dependency
    '''
    plugins(write_dist(tmp_path, "occgp-broken", "0.2",
                       {"broken": "occgp_test_broken", "missing": "occgp_test_missing",
                        "twice": "occgp_test_twice"},
                       {"occgp_test_broken": broken, "occgp_test_twice": PLUGIN_MODULE}))
    with pytest.warns(MapPluginWarning) as caught:
        names = available_maps()
    messages = [str(w.message) for w in caught]
    assert len(messages) == 2
    assert ("the map plugin broken = occgp_test_broken (distribution occgp-broken) failed "
            "to load and is skipped: ModuleNotFoundError") in messages[0]
    assert "occgp_no_such_dependency" in messages[0]
    assert "the map plugin missing = occgp_test_missing" in messages[1]
    # the other maps, the other plugin's included, work; the broken one left nothing
    assert "half-done" not in names and "twice-octree" in names
    points, origin = _wall()
    assert make_map("octree").insert_scan(points, origin).is_occupied(points).all()
    with pytest.raises(ValueError, match="unknown map type 'half-done'"):
        make_map("half-done")


def test_a_plugin_cannot_take_a_built_in_name(plugins, tmp_path):
    clash = '''
    from occgp.maps import register

    @register("octree", description="not OctoMap's")
    class FakeOctree:
        """A plugin's map named as a built-in one."""
    '''
    other = '''
    from occgp.maps import register

    @register("twice-octree")
    class Impostor:
        """A second plugin's map under the first one's name."""
    '''
    plugins(write_dist(tmp_path, "occgp-clash", "0.1",
                       {"clash": "occgp_test_clash", "twice": "occgp_test_twice",
                        "other": "occgp_test_other"},
                       {"occgp_test_clash": clash, "occgp_test_twice": PLUGIN_MODULE,
                        "occgp_test_other": other}))
    with pytest.warns(MapPluginWarning) as caught:
        available_maps()
    messages = sorted(str(w.message) for w in caught)
    assert len(messages) == 2
    clash_msg = next(m for m in messages if "occgp_test_clash" in m)
    assert ("map type 'octree' is taken by occgp.octree.OccupancyOctree (occgp's built-in "
            "map); occgp_test_clash.FakeOctree cannot be registered under it by the plugin "
            "clash = occgp_test_clash (distribution occgp-clash)") in clash_msg
    other_msg = next(m for m in messages if "occgp_test_other" in m)
    assert ("map type 'twice-octree' is taken by occgp_test_twice.TwiceOctree (the plugin "
            "twice = occgp_test_twice (distribution occgp-clash))") in other_msg
    assert map_type("octree").cls is occgp.OccupancyOctree
    assert map_type("twice-octree").cls.__module__ == "occgp_test_twice"


def test_occgp_map_help_lists_every_registered_map():
    text = _map_types_help(width=300)
    for name in available_maps():
        line = next(ln for ln in text.splitlines() if f" {name} " in ln)
        assert map_type(name).description.rstrip(".") in line


@pytest.mark.parametrize("name", available_maps())
def test_every_registered_map_takes_a_plain_scan(name):
    """The one face: ``insert_scan(points, origin)`` and nothing else, for every map
    (the colour tree without colours, the 2D maps with 2D points)."""
    entry = map_type(name)
    dims = 3 if 3 in entry.dims else 2
    rng = np.random.default_rng(0)
    angle = rng.uniform(0, 2 * np.pi, 60)
    points = 1.5 * np.column_stack([np.cos(angle), np.sin(angle)])
    origin = np.zeros(dims)
    if dims == 3:
        points = np.column_stack([points, rng.uniform(0.1, 0.9, 60)])
        origin[2] = 0.5
    m = make_map(name)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert m.insert_scan(points, origin) is m
    assert m.num_cells > 0
    p = m.occupancy(points)
    assert p.shape == (60,) and np.isfinite(p).any()
    assert np.nanmin(p) >= 0 and np.nanmax(p) <= 1
