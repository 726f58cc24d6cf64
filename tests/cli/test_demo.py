"""occgp demo: the exact-ground-truth protocol, its three tables and its files."""

import io

import pytest

import occgp.cli._demo as demo_module
import occgp.cli._main as cli
from occgp import OccupancyOctree
from occgp.gp import GPOM, GPOMIK, GPMixture, OccupancyGrid

TABLE_HEADER = "method"


def _subset(factory, names):
    return lambda resolution: {k: v for k, v in factory(resolution).items() if k in names}


@pytest.fixture(scope="module")
def quick_demo(tmp_path_factory):
    """The demo at 0.25 m with a few methods of each table (the pipeline unchanged),
    run once for the tests of this module."""
    outdir = tmp_path_factory.mktemp("demo")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(demo_module, "mapping_methods", _subset(
            cli.mapping_methods, {"octree (scan)", "grid (scan)", "AKIMap"}))
        mp.setattr(demo_module, "noisy_mapping_methods", _subset(
            cli.noisy_mapping_methods, {"octree, stereo"}))
        mp.setattr(demo_module, "gp_mapping_methods", _subset(
            cli.gp_mapping_methods, {"GPOM", "log-odds grid"}))
        out = io.StringIO()
        rows = cli.demo(outdir, resolution=0.25, progress=False, out=out)
    return rows, out.getvalue(), outdir


@pytest.mark.slow
def test_demo_prints_three_tables_on_exact_ground_truth(quick_demo):
    rows, text, _ = quick_demo
    assert [r.method for r in rows] == ["octree (scan)", "grid (scan)", "AKIMap",
                                        "octree, stereo", "GPOM", "log-odds grid"]
    assert "exact ground truth" in text and "cells the scans could see" in text
    header = [line for line in text.splitlines() if line.startswith(TABLE_HEADER)]
    assert len(header) == 3 and all("unknown" in h and "AUC" in h for h in header)
    # the tables in order: 3D, stereo, 2D
    assert text.index("AKIMap") < text.index("stereo: plain boxes") < text.index("2D: room")
    assert text.index("2D: room") < text.index("log-odds grid")
    by_name = {r.method: r for r in rows}
    three_d = [by_name[n] for n in ("octree (scan)", "grid (scan)", "AKIMap")]
    assert len({r.n_test for r in three_d}) == 1           # one 3D test set
    assert by_name["octree, stereo"].n_test % 2 == 0        # its own, balanced
    assert by_name["grid (scan)"].auc == by_name["octree (scan)"].auc
    # the protocol tells methods apart: AKIMap fills the gaps between rays, the octree not
    assert by_name["AKIMap"].auc > by_name["octree (scan)"].auc + 0.1
    assert by_name["octree (scan)"].unknown_fraction > by_name["AKIMap"].unknown_fraction
    assert by_name["GPOM"].auc > by_name["log-odds grid"].auc + 0.05
    assert by_name["GPOM"].unknown_fraction == 0 < by_name["log-odds grid"].unknown_fraction
    assert all(0.5 < r.auc < 1 and r.seconds > 0 for r in rows)


@pytest.mark.slow
def test_demo_writes_map_and_figures(quick_demo):
    rows, text, outdir = quick_demo
    for name in ("map.bt", "slice.png", "roc.png", "gp_2d.png"):
        assert (outdir / name).stat().st_size > 1000, name
        assert name in text
    for name in ("slice.png", "roc.png", "gp_2d.png"):
        assert (outdir / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    tree = OccupancyOctree.load(outdir / "map.bt")          # the scan-mode octree
    assert tree.resolution == 0.25
    assert tree.num_leaves == OccupancyOctree.from_bytes(
        rows[0].map.to_bytes("bt")).num_leaves


@pytest.mark.slow
def test_demo_test_sets_are_balanced(quick_demo):
    rows, text, _ = quick_demo
    octree, gpom = rows[0], rows[4]
    assert octree.n_test % 2 == 0 and gpom.n_test % 2 == 0
    assert f"{octree.n_test // 2:,} occupied, {octree.n_test // 2:,} free" in text
    assert f"{gpom.n_test // 2:,} occupied, {gpom.n_test // 2:,} free" in text


def test_gp_mapping_methods_build_unfitted_models():
    methods = cli.gp_mapping_methods(0.2)
    assert list(methods) == ["GPOMIK", "GPOM", "GP mixture", "log-odds grid"]
    kinds = {"GPOMIK": GPOMIK, "GPOM": GPOM, "GP mixture": GPMixture,
             "log-odds grid": OccupancyGrid}
    for name, factory in methods.items():
        first, second = factory(), factory()
        assert isinstance(first, kinds[name]) and first is not second
        assert callable(first.fit) and callable(first.predict_proba)
    assert methods["log-odds grid"]().resolution == 0.2
    assert methods["GPOMIK"]().optimizer is False and methods["GPOM"]().optimizer is False


def test_demo_command_line(monkeypatch, tmp_path, capsys):
    seen = {}
    monkeypatch.setattr(cli, "demo", lambda outdir, **kw: seen.update(outdir=outdir, **kw))
    assert cli.main(["demo", "-o", str(tmp_path), "--resolution", "0.5", "--seed", "2",
                     "--no-progress"]) == 0
    assert seen == {"outdir": str(tmp_path), "resolution": 0.5, "seed": 2, "progress": False}
