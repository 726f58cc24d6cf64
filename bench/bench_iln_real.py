"""Up-sampling scored on real LiDAR frames: every 4th beam kept, the others predicted.

For each real frame of ``../shared/data/lidar_frames/`` (relative to the
project root; skipped with a message when absent):

* ``kitti_hdl64e_front.bin`` -- KITTI's Velodyne HDL-64E, front half; its
  beams from the file's scan order, their elevations measured in the frame;
* ``os1_64_full.bin`` -- an Ouster OS1-64 (RELLIS-3D); beams from the record
  order, elevations measured in the frame;

the range image (64 x 2048, one row per beam,
:func:`occgp.iln.read_lidar_frame`) keeps rows 0, 4, 8, ... as the input and
each model predicts the other 48 beams at their true elevations
(:func:`occgp.iln.real_frame_scores`). Printed: the frame's measured beam
table (ends and pitches), then per model the MAE of the ranges over the true
returns of the predicted beams, IoU / precision / recall of their points on a
0.1 m voxel grid, the IoU as a ratio to bilinear's, and the up-sampling time.

Models: bilinear, inverse bilinear, the edge-aware rule, the shipped ILN
(``pretrained("iln")``, trained on exact simulated 16 x 1024 CARLA-geometry
images) and the shipped candidate selector (``pretrained("selector")``,
trained on simulated CARLA-geometry images with sensor effects and
vegetation, its thresholds chosen on held-out simulated scenes: neither saw
a real frame). The targets: the selector's IoU at least 1.1 x bilinear's and
above inverse bilinear's, its MAE below both.

Run: ``python bench/bench_iln_real.py`` (under a minute on 2 cores).
"""

from __future__ import annotations

import argparse
import platform
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT / ".." / "shared" / "data" / "lidar_frames"
FRAMES = (("KITTI HDL-64E (front half)", "kitti_hdl64e_front.bin", "hdl64e"),
          ("Ouster OS1-64 (RELLIS-3D)", "os1_64_full.bin", "os1-64"))


def _models():
    from occgp.iln import pretrained
    return {"bilinear": "bilinear", "inverse bilinear": "inverse-bilinear",
            "edge-aware": "edge-aware", "ILN (shipped)": pretrained("iln"),
            "selector (shipped)": pretrained("selector")}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep-every", type=int, default=4, help="keep every k-th beam")
    parser.add_argument("--cols", type=int, default=2048, help="range image columns")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    import torch

    from occgp.iln import format_real_table, read_lidar_frame, real_frame_scores

    print(f"{platform.processor() or platform.machine()}, torch {torch.__version__}, "
          f"{torch.get_num_threads()} threads, device cpu")
    models = _models()
    for title, name, sensor in FRAMES:
        path = DATA / name
        if not path.exists():
            print(f"\n{title}: skipped, {path} is absent")
            continue
        image, lidar = read_lidar_frame(path, sensor, cols=args.cols)
        e = lidar.elevations()
        pitch = -np.diff(e)
        print(f"\n{title}: {image.shape[0]} x {image.shape[1]}, "
              f"{int((image > 0).sum())} returns; beams {e[0]:+.2f} to {e[-1]:+.2f} deg, "
              f"pitch rows 0-31 median {np.median(pitch[:31]):.3f}, rows 32-63 median "
              f"{np.median(pitch[32:]):.3f} deg")
        rows = real_frame_scores(models, image, lidar, keep_every=args.keep_every)
        print(f"keep every {args.keep_every}th beam ({len(range(0, lidar.rows, args.keep_every))}"
              f" of {lidar.rows}), the others predicted at their elevations:")
        print(format_real_table(rows))
        score = {r["model"]: r for r in rows}
        sel, bil, inv = (score[k] for k in ("selector (shipped)", "bilinear",
                                            "inverse bilinear"))
        for text, ok in ((f"IoU {sel['iou']:.3f} >= 1.1 x bilinear's {bil['iou']:.3f} = "
                          f"{1.1 * bil['iou']:.3f}", sel["iou"] >= 1.1 * bil["iou"]),
                         (f"IoU {sel['iou']:.3f} > inverse bilinear's {inv['iou']:.3f}",
                          sel["iou"] > inv["iou"]),
                         (f"MAE {sel['mae']:.3f} below bilinear's {bil['mae']:.3f} and inverse "
                          f"bilinear's {inv['mae']:.3f}",
                          sel["mae"] < min(bil["mae"], inv["mae"]))):
            print(f"  target, selector: {text}: {'met' if ok else 'MISSED'}")


if __name__ == "__main__":
    main()
