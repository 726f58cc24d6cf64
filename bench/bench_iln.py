"""The candidate selector, ILN, LIIF and the analytic rules: Table 4.1 and the mapping of §4.4.5.

Prints, all measured in this run:

1. The hardware: CPU model, cores, torch threads, torch version, device.
2. **Table 4.1's layout**: bilinear, inverse bilinear (bilinear interpolation
   of 1 / r, ILN's untrained weight prior: what the training adds is ILN's
   row against it), edge-aware interpolation (inverse bilinear that copies
   the nearer row across depth edges, no training:
   :class:`occgp.iln.models.EdgeAwareInterpolation`), LIIF, ILN and the
   candidate selector (:class:`occgp.iln.models.CandidateSelector`, the
   shipped model: a learnt choice among analytic candidates) up-sampling 16 x 1024 range images to 64 x 1024, 128 x 2048 and
   256 x 4096 (the last out of the training distribution, on the first
   ``--n-large`` images only) on held-out simulated outdoor scenes (test
   seeds ``100000 + ...`` of ``occgp.iln.data.make_dataset``, 2 road poses
   per scene): MAE of the ranges over the true returns, IoU / precision /
   recall / F1 of the 3D points on a 0.1 m voxel grid, each averaged over
   the images (:func:`occgp.iln.evaluate.evaluate`), with the up-sampling
   time per image.
   **The per-region table** of the same runs
   (``evaluate(..., regions=True)``): the MAE on planar pixels (inverse
   bilinear within 0.5 m of a true return), on depth edges (inverse bilinear
   off by more than 0.5 m) and on no-return boundaries (the true pixel or an
   input pixel its query reads has no return), and each region's share of
   the pixels, pooled over the images.
3. **The mapping table** (Fig. 4.10 as a table), with one more row for the
   selector's map mode (``max_farther=0.02``: it never lengthens the
   prior's range): 0.2 m octrees
   (``method="auto"``) from the 16-beam scans of a trajectory in a held-out
   scene, from their up-sampling to 64 x 1024 and 128 x 2048 by each model,
   and from the true 64 x 1024 scans; ROC AUC on exact ground-truth cells,
   the fraction of test cells known, and the time per scan split into
   up-sampling and map update (:func:`occgp.iln.experiment.mapping_experiment`).
4. The training time of each checkpoint, read from its metadata.
5. CPU inference time 16 x 1024 -> 64 x 1024 per scan (:func:`cpu_inference_time`).
6. Where a CUDA GPU is available: training throughput of the full-size ILN
   (64 channels, 16 residual blocks) there, and its inference time.
7. The targets of the shipped model, met or missed, as measured above: at
   64 x 1024 and 128 x 2048 the selector's IoU at least the best of inverse
   bilinear and edge-aware + 0.02 and its MAE at most 0.95 x the lower of
   theirs; CPU inference within 0.5 s per scan; the map from its 64 x 1024
   scans within 0.005 of the true scans' AUC.

``--realistic`` simulates the test images with the default sensor effects
and vegetation (:class:`occgp.iln.SensorEffects`,
``outdoor_scene(vegetation=True)``); the mapping table keeps its exact scans.

Models: ``--iln``, ``--liif`` and ``--selector`` take checkpoints written by
``occgp iln train`` (``last.pt`` or ``model.pt``); by default the ones
shipped in ``occgp/iln/weights/`` (the first ``*.pt`` whose spec names
that model). Rows of a model without a checkpoint are left out, and the
bench says why; ``--untrained`` fills them with untrained models of the
shipped small configuration (a smoke run of the code, not a result).

Run: ``python bench/bench_iln.py`` (32 test images at 64 x 1024 and
128 x 2048, 4 of them at 256 x 4096, 4 mapping scans; about 9 minutes on 2
otherwise idle cores, mostly ILN at 128 x 2048 and LIIF and ILN at
256 x 4096); ``--quick`` (4 test images, 2 at 256 x 4096, 3 scans, fewer
test cells: a few minutes) for a smoke run.
"""

from __future__ import annotations

import argparse
import glob
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: The shipped small configurations (--untrained builds their models).
CONFIGS = {"iln": "small.yaml", "liif": "small_liif.yaml"}
#: The full-size ILN of the dissertation (EDSR-baseline 64 x 16, one attention layer).
FULL_ILN = {"name": "iln", "args": {"channels": 64, "n_resblocks": 16, "depth": 1}}
SIZES = ("16x1024", "64x1024", "128x2048", "256x4096")
#: The selector's map mode in the mapping table: never lengthen the prior's range by more.
MAP_MAX_FARTHER = 0.02
MAP_ROW = f"Selector max_farther={MAP_MAX_FARTHER:g}"
OUT_SIZES = ((64, 1024), (128, 2048), (256, 4096))


def log(msg):
    print(msg, file=sys.stderr, flush=True)


# ------------------------------------------------------------------------------ hardware
def hardware():
    """A line naming the CPU, its cores, torch's threads and version, and the device."""
    import torch

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    gpu = (f", GPU {torch.cuda.get_device_name(0)}" if torch.cuda.is_available()
           else ", no CUDA GPU")
    return (f"CPU {cpu} ({cores} cores available), torch {torch.__version__} with "
            f"{torch.get_num_threads()} threads, device cpu{gpu}; Python "
            f"{platform.python_version()}, numpy {np.__version__}")


# ------------------------------------------------------------------------------ models
def _find_checkpoint(name):
    """The first checkpoint in occgp/iln/weights/ whose spec is model `name`, or None."""
    import occgp.iln
    from occgp.iln.training import load_checkpoint

    folder = Path(occgp.iln.__file__).parent / "weights"
    for path in sorted(glob.glob(str(folder / "*.pt"))):
        try:
            ckpt = load_checkpoint(path)
        except (OSError, ValueError):
            continue
        if ckpt.get("model", {}).get("name") == name:
            return path
    return None


def load_model(path):
    """``(model, checkpoint dict)`` of a checkpoint written by occgp iln train."""
    from occgp.iln.models import make
    from occgp.iln.training import load_checkpoint

    ckpt = load_checkpoint(path)
    return make(ckpt["model"], load_sd=True).eval(), ckpt


def training_time(ckpt):
    """``(seconds or None, description)`` of a checkpoint's recorded training time."""
    meta = ckpt.get("meta") if isinstance(ckpt.get("meta"), dict) else {}
    for source in (ckpt, meta):
        for key in ("train_seconds", "training_seconds", "elapsed_seconds", "seconds"):
            value = source.get(key)
            if isinstance(value, (int, float)):
                where = source.get("hardware") or source.get("device") or ckpt.get(
                    "config", {}).get("device")
                return float(value), f"{value / 60:.1f} min" + (f" on {where}" if where else "")
    return None, "not recorded in the checkpoint"


def small_spec(name):
    """The model spec of the shipped small configuration of `name` (occgp/iln/configs/)."""
    import yaml

    import occgp.iln

    path = Path(occgp.iln.__file__).parent / "configs" / CONFIGS[name]
    with open(path) as fh:
        return yaml.safe_load(fh)["model"]


def resolve_models(args):
    """``{row name: model}``, ``{row name: checkpoint dict}`` and notes on missing rows."""
    import torch

    from occgp.iln.models import make

    models = {"Bilinear": make({"name": "bilinear"}),
              "Inverse bilinear": make({"name": "inverse-bilinear"}),
              "Edge-aware": make({"name": "edge-aware"})}
    ckpts, notes = {}, []
    for label, name, path in (("LIIF", "liif", args.liif), ("ILN", "iln", args.iln),
                              ("Selector", "selector", args.selector)):
        path = path or _find_checkpoint(name)
        if path is not None:
            models[label], ckpts[label] = load_model(path)
            ckpts[label]["path"] = path
        elif args.untrained and name in CONFIGS:
            torch.manual_seed(0)
            models[f"{label} (untrained)"] = make(small_spec(name)).eval()
            notes.append(f"{label}: no checkpoint; its rows use an UNTRAINED model of the "
                         f"small configuration (--untrained): a smoke run, not a result")
        else:
            config = CONFIGS.get(name, "selector.yaml")
            notes.append(f"{label}: rows not printed: no checkpoint given (--{name}) and "
                         f"none in occgp/iln/weights/ (train one with `occgp iln train "
                         f"occgp/iln/configs/{config}`)")
    return models, ckpts, notes


# ------------------------------------------------------------------------------ data
def test_images(args):
    """Held-out test images at every size: from --data's test shards, or simulated here."""
    from occgp.iln.data import load_shards, make_dataset

    if args.data:
        folder = Path(args.data)
        folder = folder / "test" if (folder / "test").is_dir() else folder
        images, meta = load_shards(folder, SIZES, return_meta=True)
        n = min(args.n_images, len(images[(16, 1024)]))
        return {k: v[:n] for k, v in images.items()}, meta["model"], f"{folder} (first {n})"
    n_scenes = max(1, args.n_images // 2)
    realistic = {}
    if args.realistic:
        from occgp.iln import SensorEffects

        realistic = {"effects": SensorEffects(), "vegetation": True}
    with tempfile.TemporaryDirectory(prefix="occgp-bench-iln-") as tmp:
        make_dataset(tmp, 0, n_scenes, sizes=SIZES, images_per_scene=2, progress=False,
                     n_jobs=args.n_jobs, **realistic)
        images, meta = load_shards(Path(tmp) / "test", SIZES, return_meta=True)
    n = min(args.n_images, len(images[(16, 1024)]))
    seeds = sorted(set(meta["seeds"][:n].tolist()))
    kind = (" with sensor effects (SensorEffects(): 2 cm noise, dropouts) and vegetation"
            if args.realistic else ", exact ray casting")
    return ({k: v[:n] for k, v in images.items()}, meta["model"],
            f"{n} images of {len(seeds)} held-out scenes (seeds {seeds[0]}..{seeds[-1]}), "
            f"2 random road poses each{kind}")


# ------------------------------------------------------------------------------ timing
def cpu_inference_time(model, *, repeats=5, in_size=(16, 1024), out_size=(64, 1024), seed=0):
    """Median CPU seconds to up-sample one simulated scan from `in_size` to `out_size`.

    The scan is a 16 x 1024 image of a held-out outdoor scene; the model runs
    on the CPU with torch's current thread count, after one warm-up call.

    Parameters
    ----------
    model : RangeModel
        Moved to the CPU for the measurement and back afterwards.
    repeats : int, default=5
    in_size, out_size : (int, int)
    seed : int, default=0
        Offset of the test scene's seed.

    Returns
    -------
    seconds : float
    """
    import copy

    from occgp.datasets import outdoor_scene
    from occgp.iln._range import LidarModel
    from occgp.iln.data import TEST_SEED_OFFSET, simulate_range_image
    from occgp.iln._common import predict_image

    scene = outdoor_scene(TEST_SEED_OFFSET + seed)
    lidar = LidarModel.carla()
    image = simulate_range_image(scene, scene.trajectory(1)[0], lidar.with_size(*in_size))
    net = copy.deepcopy(model).to("cpu").eval()
    args = (net, image, lidar.with_size(*in_size), lidar.with_size(*out_size))
    predict_image(*args)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        predict_image(*args)
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def gpu_benchmark(steps=50, batch_size=16, quick=False, device="cuda", spec=None):
    """Train the full-size ILN on the GPU for `steps` steps; throughput and inference time.

    The training data are simulated here (16 x 1024 inputs, 128 x 2048 targets, as the
    dissertation trains). Returns a list of printable lines, or None without CUDA
    (`device` and `spec` let a CPU smoke run check this code with a small model).
    """
    import torch

    device = torch.device(device)
    if device.type == "cuda" and not torch.cuda.is_available():
        return None
    from occgp.iln._range import LidarModel
    from occgp.iln.data import load_shards, make_dataset
    from occgp.iln.models import upsample_image
    from occgp.iln.training import train

    spec = FULL_ILN if spec is None else spec

    def sync():
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    name = torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu"
    lines = [f"device: {name}"]
    n_scenes = 2 if quick else 8
    with tempfile.TemporaryDirectory(prefix="occgp-bench-iln-gpu-") as tmp:
        make_dataset(tmp, n_scenes, 1, sizes=("16x1024", "128x2048"),
                     images_per_scene=max(1, batch_size // 2), progress=False)
        config = {"seed": 0, "device": str(device), "progress": False, "model": spec,
                  "data": {"folder": tmp, "split": "train", "input": "16x1024",
                           "target": "128x2048"},
                  "train": {"epochs": 10_000, "batch_size": batch_size,
                            "queries_per_image": 16384, "lr": 1e-4, "max_steps": 2}}
        train(config)                                        # warm-up (cuDNN, allocator)
        sync()
        config["train"]["max_steps"] = steps
        t0 = time.perf_counter()
        result = train(config)
        sync()
        seconds = time.perf_counter() - t0
        lines.append(f"ILN {spec['args']}: {steps} steps of {batch_size} images x 16,384 "
                     f"queries in {seconds:.1f} s (data loading included): "
                     f"{steps / seconds:.2f} steps/s, {steps * batch_size / seconds:.1f} "
                     f"images/s; loss {result['losses'][0]:.4f} -> {result['losses'][-1]:.4f}")
        model = result["model"].eval()
        images = load_shards(Path(tmp) / "test", ["16x1024"])[(16, 1024)]
    lidar = LidarModel.carla()
    x = torch.from_numpy(images[:1]).to(device)
    for out in OUT_SIZES:
        upsample_image(model, x, lidar, lidar.with_size(*out))
        sync()
        t0 = time.perf_counter()
        for _ in range(5):
            upsample_image(model, x, lidar, lidar.with_size(*out))
        sync()
        lines.append(f"inference 16x1024 -> {out[0]}x{out[1]}: "
                     f"{(time.perf_counter() - t0) / 5 * 1e3:.1f} ms per scan")
    return lines


# ------------------------------------------------------------------------------ main
def _row(rows, method, resolution):
    return next((r for r in rows if r["method"] == method and r["resolution"] == resolution),
                None)


def targets(rows, mapping_rows, inference, models):
    """The targets of the shipped model (the selector), met or missed, as printable lines."""
    out = []

    def mark(ok):
        return "met" if ok else "MISSED"

    sel = next((m for m in models if m.startswith("Selector")), None)
    if sel is None:
        return ["targets: not measured (no selector checkpoint)"]
    for res in ("64x1024", "128x2048"):
        s = _row(rows, sel, res)
        base = [r for r in (_row(rows, "Inverse bilinear", res), _row(rows, "Edge-aware", res))
                if r is not None]
        best_iou = max(r["iou"] for r in base)
        low_mae = min(r["mae"] for r in base)
        out.append(f"selector IoU >= best of inverse bilinear / edge-aware + 0.02 at {res}: "
                   f"{s['iou']:.3f} vs {best_iou:.3f} + 0.02 = {best_iou + 0.02:.3f}: "
                   f"{mark(s['iou'] >= best_iou + 0.02)}")
        out.append(f"selector MAE <= 0.95 x the lower of theirs at {res}: {s['mae']:.3f} vs "
                   f"0.95 x {low_mae:.3f} = {0.95 * low_mae:.3f}: "
                   f"{mark(s['mae'] <= 0.95 * low_mae)}")
    if sel in inference:
        out.append(f"CPU inference 16x1024 -> 64x1024 <= 0.5 s per scan: {inference[sel]:.3f} s: "
                   f"{mark(inference[sel] <= 0.5)}")
    if mapping_rows:
        true = next((r for r in mapping_rows if r["method"] == "64x1024 (true)"), None)
        up = next((r for r in mapping_rows if r["method"] == f"{sel} 64x1024"), None)
        if true is not None and up is not None:
            out.append(f"mapping AUC from the selector's 64x1024 scans >= true 64x1024 AUC - "
                       f"0.005: {up['auc']:.3f} vs {true['auc']:.3f} - 0.005 = "
                       f"{true['auc'] - 0.005:.3f}: {mark(up['auc'] >= true['auc'] - 0.005)}")
        mode = next((r for r in mapping_rows if r["method"] == f"{MAP_ROW} 64x1024"), None)
        if true is not None and mode is not None:
            out.append(f"(the same with the selector's map mode, max_farther="
                       f"{MAP_MAX_FARTHER:g}): {mode['auc']:.3f} vs {true['auc'] - 0.005:.3f}: "
                       f"{mark(mode['auc'] >= true['auc'] - 0.005)}")
    iln = next((m for m in models if m.startswith("ILN")), None)
    if iln is not None:
        i = _row(rows, iln, "64x1024")
        s = _row(rows, sel, "64x1024")
        out.append(f"(not a target) the shipped ILN at 64x1024: IoU {i['iou']:.3f}, MAE "
                   f"{i['mae']:.3f}; the selector: IoU {s['iou']:.3f}, MAE {s['mae']:.3f}")
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--iln", help="ILN checkpoint (default: the shipped one)")
    parser.add_argument("--liif", help="LIIF checkpoint (default: the shipped one)")
    parser.add_argument("--selector", help="selector checkpoint (default: the shipped one)")
    parser.add_argument("--realistic", action="store_true",
                        help="test images with sensor effects and vegetation (SensorEffects(), "
                             "outdoor_scene(vegetation=True)) instead of exact ones")
    parser.add_argument("--data", help="dataset folder of make_dataset (its test/ shards, all "
                                       "four sizes); default: simulate held-out scenes here")
    parser.add_argument("--n-images", type=int, default=None, help="test images (default 32; "
                                                                   "quick: 4)")
    parser.add_argument("--n-large", type=int, default=None,
                        help="of them, those also scored at 256x4096 (default 4; quick: 2)")
    parser.add_argument("--n-scans", type=int, default=None, help="mapping scans (default 4; "
                                                                  "quick: 3)")
    parser.add_argument("--n-jobs", type=int, default=None, help="joblib workers simulating")
    parser.add_argument("--quick", action="store_true", help="a smoke run of a few minutes")
    parser.add_argument("--untrained", action="store_true",
                        help="untrained small models in place of missing checkpoints")
    parser.add_argument("--no-gpu", action="store_true", help="skip the GPU section")
    args = parser.parse_args(argv)
    args.n_images = args.n_images or (4 if args.quick else 32)
    args.n_large = min(args.n_large or (2 if args.quick else 4), args.n_images)
    args.n_scans = args.n_scans or (3 if args.quick else 4)

    import torch

    from occgp.iln.evaluate import evaluate, format_region_table, format_table
    from occgp.iln.experiment import format_mapping_table, mapping_experiment

    print(f"occgp ILN bench{' (quick)' if args.quick else ''}\nhardware: {hardware()}\n")
    models, ckpts, notes = resolve_models(args)
    for note in notes:
        print(f"note: {note}")
    if notes:
        print()

    log("simulating the test images ...")
    t0 = time.perf_counter()
    images, lidar, source = test_images(args)
    log(f"  {time.perf_counter() - t0:.1f} s")
    n = len(images[(16, 1024)])
    n_large = min(args.n_large, n)
    print(f"Table 4.1 layout: 16x1024 inputs up-sampled to each test resolution; {source}; "
          f"256x4096 on the first {n_large} of them; MAE in metres over the true returns, "
          f"voxel scores on a 0.1 m grid; means over images; time: up-sampling seconds per "
          f"image on the CPU")
    t0 = time.perf_counter()
    rows = evaluate(models, images, in_size=(16, 1024), out_sizes=OUT_SIZES[:2], lidar=lidar,
                    progress=None, regions=True)
    rows += evaluate(models, {k: v[:n_large] for k, v in images.items()}, in_size=(16, 1024),
                     out_sizes=OUT_SIZES[2:], lidar=lidar, progress=None, regions=True)
    log(f"  evaluated in {time.perf_counter() - t0:.1f} s")
    print(format_table(rows, with_time=True))
    print("\nPer region (the same runs): MAE in metres over the true returns of planar pixels "
          "(inverse bilinear within 0.5 m),\ndepth edges (inverse bilinear off by > 0.5 m) and "
          "no-return boundaries (the true pixel or one of the 4 input pixels its query reads has "
          "no return);\nshare: the region's fraction of all pixels; both pooled over the images")
    print(format_region_table(rows))

    up_models = {k: v for k, v in models.items()}
    if "Selector" in models:
        import copy

        mapper = copy.deepcopy(models["Selector"])
        mapper.max_farther = MAP_MAX_FARTHER
        up_models[MAP_ROW] = mapper
    n_cells = 30_000 if args.quick else 100_000
    print(f"\nMapping (Sec. 4.4.5, Fig. 4.10 as a table): {args.n_scans} scans along the main "
          f"road of a held-out scene (outdoor_scene(100000), 80 m), 0.2 m octrees, "
          f"insert_scan(method='auto');\nAUC on a seeded sample of {n_cells:,} lattice cells "
          f"(those in view of the true 64x1024 scans within 25 m, labelled exactly); "
          f"unknown = p 0.5; time per scan")
    t0 = time.perf_counter()
    mapping_rows = mapping_experiment(up_models, n_scans=args.n_scans, lidar=lidar,
                                      n_test_cells=n_cells, progress=None)
    log(f"  mapped in {time.perf_counter() - t0:.1f} s")
    print(format_mapping_table(mapping_rows))
    r0 = mapping_rows[0]
    print(f"test cells: {r0['n_test']:,} ({r0['n_occupied']:,} occupied)")

    print("\nTraining time (checkpoint metadata):")
    if not ckpts:
        print("  no checkpoint loaded")
    for label, ckpt in ckpts.items():
        _, text = training_time(ckpt)
        n_params = sum(p.numel() for p in models[label].parameters())
        print(f"  {label}: {ckpt['path']}: {ckpt['model']['name']} {ckpt['model']['args']}, "
              f"{n_params:,} parameters, step {ckpt.get('step')}, seed "
              f"{ckpt.get('config', {}).get('seed')}; training time: {text}")

    print(f"\nCPU inference 16x1024 -> 64x1024 ({torch.get_num_threads()} threads, median of "
          f"{2 if args.quick else 5}):")
    inference = {}
    for label, model in models.items():
        inference[label] = cpu_inference_time(model, repeats=2 if args.quick else 5)
        print(f"  {label}: {inference[label]:.3f} s per scan")

    if not args.no_gpu:
        lines = gpu_benchmark(steps=10 if args.quick else 50, quick=args.quick)
        print("\nGPU:" if lines else "\nGPU: no CUDA device; GPU training throughput and "
                                     "inference not measured")
        for line in lines or []:
            print(f"  {line}")

    print("\nTargets:")
    for line in targets(rows, mapping_rows, inference, models):
        print(f"  {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
