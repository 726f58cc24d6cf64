"""Per-region scores of up-sampled range images: planar pixels, depth edges, no-return boundaries."""

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from occgp.iln.metrics import REGIONS, region_masks

torch = pytest.importorskip("torch")

from occgp.iln import LidarModel, upsample_range_image  # noqa: E402
from occgp.iln.evaluate import (REGION_COLUMNS, evaluate, format_region_table,  # noqa: E402
                                format_table)


def test_region_masks_split_every_pixel_by_precedence():
    truth = np.array([[10.0, 10.0, 0.0, 10.0, 10.0, 10.0]])
    prior = np.array([[10.4, 10.6, 3.0, 20.0, 9.0, 10.5]])
    near = np.array([[False, False, False, True, False, False]])
    m = region_masks(truth, prior, near)
    assert_array_equal(m["planar"], [[1, 0, 0, 0, 0, 1]])
    assert_array_equal(m["edge"], [[0, 1, 0, 0, 1, 0]])
    assert_array_equal(m["boundary"], [[0, 0, 1, 1, 0, 0]])
    assert sum(m[r].astype(int) for r in REGIONS).tolist() == [[1] * 6]
    m = region_masks(truth, prior, near, edge_threshold=1.5)
    assert_array_equal(m["edge"], [[0, 0, 0, 0, 0, 0]])


@pytest.mark.parametrize("args, kwargs, exc, match", [
    (([[1.0]], [[1.0, 2.0]], [[True]]), {}, ValueError, "must have the same shape"),
    (([[1.0]], [[1.0]], [[1]]), {}, TypeError, "near_no_return must hold booleans"),
    (([[1.0]], [[-1.0]], [[True]]), {}, ValueError, "prior must hold ranges >= 0"),
    (([[np.nan]], [[1.0]], [[True]]), {}, ValueError, "truth must be finite"),
    (([[1.0]], [[1.0]], [[True]]), {"edge_threshold": 0.0}, ValueError,
     "edge_threshold must be a finite number > 0"),
    (([[1.0]], [[1.0]], [[True]]), {"edge_threshold": "1"}, TypeError,
     "edge_threshold must be a real number"),
])
def test_region_masks_rejects_bad_input(args, kwargs, exc, match):
    with pytest.raises(exc, match=match):
        region_masks(*args, **kwargs)


def _case():
    """A 4 x 64 input with one hole at (1, 10); a 16 x 128 truth equal to inverse bilinear
    except one depth edge (+3 m) and one true no-return."""
    low = np.full((4, 64), 10.0, np.float32)
    low[:, 32:] = 20.0
    low[1, 10] = 0.0
    truth = upsample_range_image(low, rows=16, cols=128, model="inverse-bilinear",
                                 lidar=LidarModel.carla(4, 64))
    truth[12, 100] += 3.0                           # a depth edge
    truth[14, 40] = 0.0                             # a true no-return
    return low, truth


def test_evaluate_regions_finds_the_pixels_by_hand():
    low, truth = _case()
    rows = evaluate({"ib": "inverse-bilinear", "b": "bilinear"}, {"4x64": low[None],
                    "16x128": truth[None]}, in_size="4x64", out_sizes=["16x128"],
                    progress=False, regions=True)
    n = 16 * 128
    # queries reading input pixel (1, 10): out rows 2..9 (v in (0.5, 2.5)), cols 19..22
    # (u in (9.5, 11.5)): 32 pixels, and the true no-return
    for row in rows:
        assert row["share_boundary"] == pytest.approx(33 / n)
        assert row["share_edge"] == pytest.approx(1 / n)
        assert row["share_planar"] == pytest.approx((n - 34) / n)
        assert sum(row[f"share_{r}"] for r in REGIONS) == pytest.approx(1.0)
    ib = rows[0]
    assert ib["mae_edge"] == pytest.approx(3.0, rel=1e-5)
    assert ib["mae_planar"] == pytest.approx(0.0, abs=1e-5)
    assert ib["mae_boundary"] == pytest.approx(0.0, abs=1e-5)
    # bilinear differs from inverse bilinear between the 10 m and 20 m columns only (planar)
    b = rows[1]
    pred = upsample_range_image(low, rows=16, cols=128, model="bilinear",
                                lidar=LidarModel.carla(4, 64))
    err = np.abs(pred - truth)
    planar = np.ones((16, 128), bool)
    planar[2:10, 19:23] = False
    planar[12, 100] = planar[14, 40] = False
    assert b["mae_planar"] == pytest.approx(err[planar].mean(), rel=1e-5)
    assert b["mae_planar"] > 0.01


def test_evaluate_without_regions_keeps_its_rows_and_tables():
    low, truth = _case()
    images = {"4x64": low[None], "16x128": truth[None]}
    plain = evaluate(["inverse-bilinear"], images, in_size="4x64", out_sizes=["16x128"],
                     progress=False)
    full = evaluate(["inverse-bilinear"], images, in_size="4x64", out_sizes=["16x128"],
                    progress=False, regions=True, edge_threshold=5.0)
    assert not set(REGION_COLUMNS) & set(plain[0])
    assert set(REGION_COLUMNS) <= set(full[0])
    assert full[0]["share_edge"] == 0.0 and np.isnan(full[0]["mae_edge"])
    for key in ("mae", "iou", "precision", "recall", "f1", "n_images"):
        assert plain[0][key] == full[0][key]
    assert format_table(full) == format_table(plain)
    table = format_region_table(full)
    assert "planar share" in table and "boundary MAE" in table and "nan" in table
    with pytest.raises(ValueError, match=r"lacks \['share_planar'"):
        format_region_table(plain)
    with pytest.raises(TypeError, match="regions must be a bool"):
        evaluate(["bilinear"], images, in_size="4x64", out_sizes=["16x128"], regions=1)
    with pytest.raises(ValueError, match="edge_threshold"):
        evaluate(["bilinear"], images, in_size="4x64", out_sizes=["16x128"], regions=True,
                 edge_threshold=-1.0)
