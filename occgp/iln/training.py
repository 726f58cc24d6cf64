"""Training of the range-image models (ILN, LIIF) on simulated range-image shards.

:func:`train` takes a configuration dict (:func:`train_from_yaml` reads it from YAML)::

    seed: 0                    # model init, data order and query sampling (0 .. 2**32 - 1)
    device: cpu                # cpu, cuda, cuda:1, auto
    progress: null             # tqdm bar: null = only on a terminal, true, false
    model: {name: iln, args: {channels: 32, n_resblocks: 4, depth: 1}}
    data:
      folder: ~/.cache/occgp/iln   # shards (.npz), or a folder holding split/
      split: train
      input: 16x1024
      target: 64x1024              # or a list, e.g. [64x1024, 128x2048]
      max_images: null             # use only the first N images
    train:
      epochs: 1
      batch_size: 4                # at most 4096
      queries_per_image: 16384     # at most 2**22
      lr: 1.0e-4
      schedule: constant           # or cosine: lr * (1 + cos(pi * step / steps)) / 2
      warmup: 0                    # steps of linear warm-up before the schedule
      hard_fraction: 0.0           # share of the queries drawn at hard pixels (below)
      max_steps: null              # stop after this many steps in all
    output:
      dir: null                    # checkpoints here (last.pt, model.pt); null: none
      checkpoint_every: 0          # also every N steps (0: at epoch ends only)
    resume: null                   # a checkpoint (last.pt) to continue from

Each step draws a batch of images (a seeded, per-epoch shuffle, split across processes by a
``DistributedSampler``), samples ``queries_per_image`` random pixel centers of each image's
targets (high-resolution images of the same pose; with several target sizes the queries are
split evenly between them, so that the model sees the vertical and horizontal offsets of every
size), converts them to the input image's pixel coordinates through the LidarModels, and
minimises the model's loss (:meth:`~occgp.iln.models.RangeModel.loss`: the L1 loss between
predicted and true normalised ranges over the queries whose target has a return, or the
cross-entropy of :class:`~occgp.iln.models.CandidateSelector`) with Adam. With
``hard_fraction`` > 0 that share of the queries is drawn among the *hard* pixels, where the
planar test of inverse bilinear interpolation fails or a neighbour has no return
(:func:`sample_hard_queries`), the rest uniformly. The learning rate follows ``schedule`` after
``warmup`` steps of linear warm-up. On the CPU a run is reproducible, and a run resumed from
a checkpoint continues exactly as the uninterrupted run.

Multi-process training uses ``torch.distributed`` when ``WORLD_SIZE`` > 1 is set (``torchrun``
sets ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK``, ``MASTER_ADDR``, ``MASTER_PORT``): gloo on the CPU,
nccl on GPUs, one GPU per process (``cuda:LOCAL_RANK``). Only rank 0 writes checkpoints and shows
the progress bar.
This module holds the configuration, the query sampling, checkpoints and the training loop;
reading the shards is in ``_training_shards.py``.
"""

from __future__ import annotations

import copy
import logging
import math
import numbers
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch.nn.parallel import DistributedDataParallel
from torch.utils.data import DistributedSampler

from .._atomic import atomic_open
from .._reading import MAX_YAML_BYTES, read_regular
from .._validation import check_int
from ._range import angles_to_pixels, pixel_angles
from ._training_shards import lidar_model, load_data
from .models import RangeModel, make
from .models._base import masked_l1

__all__ = ["train", "train_from_yaml", "load_checkpoint", "sample_queries", "sample_hard_queries",
           "masked_l1", "SCHEDULES"]

logger = logging.getLogger("occgp")
logger.addHandler(logging.NullHandler())

CHECKPOINT_FORMAT = "occgp.iln.checkpoint"
CHECKPOINT_VERSION = 1
#: Upper bound of ``queries_per_image`` (memory of one step).
MAX_QUERIES = 2**22
#: The learning-rate schedules of ``config['train']['schedule']``.
SCHEDULES = ("constant", "cosine")
#: Pool of uniform draws per hard query wanted (``hard_fraction``).
_HARD_POOL = 4

DEFAULTS: dict[str, Any] = {
    "seed": 0,
    "device": "cpu",
    "progress": None,
    "model": {"name": "iln", "args": {}},
    "data": {"folder": None, "split": "train", "input": "16x1024", "target": "64x1024",
             "max_images": None},
    "train": {"epochs": 1, "batch_size": 4, "queries_per_image": 16384, "lr": 1e-4,
              "schedule": "constant", "warmup": 0, "hard_fraction": 0.0, "max_steps": None},
    "output": {"dir": None, "checkpoint_every": 0},
    "resume": None,
}


# ------------------------------------------------------------------------------------- config


def _merge(config: Any) -> dict:
    if not isinstance(config, dict):
        raise TypeError(f"config must be a dict, got {type(config).__name__}")
    out = copy.deepcopy(DEFAULTS)
    unknown = sorted(set(config) - set(DEFAULTS))
    if unknown:
        raise ValueError(f"config has unknown key(s) {unknown}; expected some of {sorted(DEFAULTS)}")
    for key, value in config.items():
        if isinstance(DEFAULTS[key], dict) and key != "model":
            if value is None:
                continue
            if not isinstance(value, dict):
                raise TypeError(f"config['{key}'] must be a dict, got {type(value).__name__}")
            bad = sorted(set(value) - set(DEFAULTS[key]))
            if bad:
                raise ValueError(
                    f"config['{key}'] has unknown key(s) {bad}; expected some of {sorted(DEFAULTS[key])}"
                )
            out[key].update(copy.deepcopy(value))
        else:
            out[key] = copy.deepcopy(value)
    return out


def _int(value, name, low, allow_none=False, high=None):
    if value is None and allow_none:
        return None
    return check_int(value, name, low=low, high=high, state_bounds=True)


def _size(value, name):
    if isinstance(value, str):
        parts = value.lower().lstrip("r").split("x")
        if len(parts) == 2 and all(p.strip().isdigit() for p in parts):
            rows, cols = (int(p) for p in parts)
            if rows > 0 and cols > 0:
                return rows, cols
    elif isinstance(value, (list, tuple)) and len(value) == 2:
        return _int(value[0], f"{name}[0]", 1), _int(value[1], f"{name}[1]", 1)
    raise ValueError(f"{name} must be a size like '64x1024' or [64, 1024], got {value!r}")


def _targets(value) -> list:
    """The target sizes: one size, or a non-empty list of distinct sizes."""
    name = "config['data']['target']"
    if isinstance(value, (list, tuple)) and value and not all(isinstance(v, numbers.Integral)
                                                               for v in value):
        sizes = [_size(v, f"{name}[{k}]") for k, v in enumerate(value)]
        if len(set(sizes)) != len(sizes):
            raise ValueError(f"{name} must not repeat a size, got {value!r}")
        return sizes
    return [_size(value, name)]


def _device(value) -> torch.device:
    if value is None or value == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if not isinstance(value, (str, torch.device)):
        raise TypeError(f"config['device'] must be a str like 'cpu' or 'cuda:0', got {type(value).__name__}")
    try:
        device = torch.device(value)
    except (RuntimeError, ValueError):
        raise ValueError(f"config['device'] must be 'cpu', 'cuda', 'cuda:N' or 'auto', got {value!r}") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"config['device'] is {value!r} but CUDA is not available here")
    if device.type not in ("cpu", "cuda"):
        raise ValueError(f"config['device'] must be 'cpu', 'cuda', 'cuda:N' or 'auto', got {value!r}")
    return device


def _check_config(cfg: dict) -> dict:
    """Validated values of a merged config (raises before any work)."""
    t, d, o = cfg["train"], cfg["data"], cfg["output"]
    out = {
        "seed": _int(cfg["seed"], "config['seed']", 0, high=2**32 - 1),
        "epochs": _int(t["epochs"], "config['train']['epochs']", 1, high=10**6),
        "batch_size": _int(t["batch_size"], "config['train']['batch_size']", 1, high=4096),
        "queries": _int(t["queries_per_image"], "config['train']['queries_per_image']", 1,
                        high=MAX_QUERIES),
        "max_steps": _int(t["max_steps"], "config['train']['max_steps']", 1, allow_none=True,
                          high=10**9),
        "max_images": _int(d["max_images"], "config['data']['max_images']", 1, allow_none=True),
        "checkpoint_every": _int(o["checkpoint_every"], "config['output']['checkpoint_every']", 0),
        "input": _size(d["input"], "config['data']['input']"),
        "targets": _targets(d["target"]),
        "warmup": _int(t["warmup"], "config['train']['warmup']", 0, high=10**9),
    }
    if t["schedule"] not in SCHEDULES:
        raise ValueError(f"config['train']['schedule'] must be one of {list(SCHEDULES)}, got "
                         f"{t['schedule']!r}")
    out["schedule"] = t["schedule"]
    frac = t["hard_fraction"]
    if isinstance(frac, bool) or not isinstance(frac, numbers.Real) or not 0 <= frac <= 1:
        raise ValueError(f"config['train']['hard_fraction'] must be a number in [0, 1], got {frac!r}")
    out["hard_fraction"] = float(frac)
    lr = t["lr"]
    if isinstance(lr, bool) or not isinstance(lr, numbers.Real) or not (math.isfinite(lr) and lr > 0):
        raise ValueError(f"config['train']['lr'] must be a finite number > 0, got {lr!r}")
    out["lr"] = float(lr)
    if cfg["progress"] is not None and not isinstance(cfg["progress"], bool):
        raise TypeError(f"config['progress'] must be true, false or null, got {cfg['progress']!r}")
    for key, value in (("config['data']['folder']", d["folder"]), ("config['output']['dir']", o["dir"]),
                       ("config['resume']", cfg["resume"])):
        if value is not None and not isinstance(value, (str, os.PathLike)):
            raise TypeError(f"{key} must be a path (str), got {type(value).__name__}")
    if d["folder"] is None:
        raise ValueError("config['data']['folder'] must name the folder of the training shards")
    if not isinstance(d["split"], str):
        raise TypeError(f"config['data']['split'] must be a str, got {type(d['split']).__name__}")
    model = cfg["model"]
    if not isinstance(model, dict):
        raise TypeError(f"config['model'] must be a dict {{name:, args:}}, got {type(model).__name__}")
    return out


def _query_table(in_model, out_model) -> torch.Tensor:
    """Input-pixel coordinates (v, u) of every target pixel center, shape (rows * cols, 2)."""
    elev, azim = pixel_angles(out_model)
    v, u = angles_to_pixels(in_model, elev.ravel(), azim.ravel())
    v = np.clip(v, 0, in_model.rows)
    u = np.clip(u, 0, in_model.cols)
    return torch.from_numpy(np.stack([v, u], axis=-1).astype(np.float32))


def sample_queries(targets: torch.Tensor, table: torch.Tensor, n: int, generator: torch.Generator):
    """Random target pixels of each image: their input-pixel coordinates and target ranges.

    Parameters
    ----------
    targets : torch.Tensor of shape (batch, rows, cols)
        Target (high-resolution) range images.
    table : torch.Tensor of shape (rows * cols, 2)
        Input-pixel coordinates (v, u) of each target pixel center.
    n : int
        Queries per image (drawn uniformly, with replacement).
    generator : torch.Generator
        Source of the draws (on the CPU).

    Returns
    -------
    queries : torch.Tensor of shape (batch, n, 2)
    ranges : torch.Tensor of shape (batch, n)
    """
    b = targets.shape[0]
    idx = torch.randint(0, table.shape[0], (b, n), generator=generator).to(targets.device)
    queries = table.to(targets.device)[idx]
    ranges = torch.gather(targets.reshape(b, -1), 1, idx)
    return queries, ranges


def sample_hard_queries(images: torch.Tensor, targets: torch.Tensor, table: torch.Tensor, n: int,
                        hard_fraction: float, generator: torch.Generator, wrap: bool):
    """Like :func:`sample_queries`, with a share of the queries drawn at hard pixels.

    ``round(hard_fraction * n)`` queries of each image are the first hard ones of a pool of
    uniform draws (``4 n`` of them; topped up with other pool draws where the pool holds
    fewer), the rest uniform draws. A pixel is hard where the planar test of inverse bilinear
    interpolation fails or a neighbour has no return
    (:func:`occgp.iln.models.hard_queries`).

    Parameters
    ----------
    images : torch.Tensor of shape (batch, in_rows, in_cols)
        The normalised input images.
    targets : torch.Tensor of shape (batch, rows, cols)
        Target images.
    table : torch.Tensor of shape (rows * cols, 2)
        Input-pixel coordinates (v, u) of each target pixel center.
    n : int
        Queries per image.
    hard_fraction : float
        Share of hard queries, in [0, 1].
    generator : torch.Generator
        Source of the draws (on the CPU).
    wrap : bool
        Horizontal wrap-around of the input images.

    Returns
    -------
    queries : torch.Tensor of shape (batch, n, 2)
    ranges : torch.Tensor of shape (batch, n)
    """
    from .models import hard_queries
    from .models._candidates import candidates

    k = int(round(hard_fraction * n))
    if k == 0:
        return sample_queries(targets, table, n, generator)
    b = targets.shape[0]
    device = targets.device
    pool = torch.randint(0, table.shape[0], (b, _HARD_POOL * k), generator=generator).to(device)
    with torch.no_grad():
        hard = hard_queries(*candidates(images, table.to(device)[pool], wrap))
    order = torch.argsort((~hard).to(torch.int8), dim=1, stable=True)[:, :k]
    idx = torch.gather(pool, 1, order)
    if k < n:
        rest = torch.randint(0, table.shape[0], (b, n - k), generator=generator).to(device)
        idx = torch.cat([idx, rest], dim=1)
    return table.to(device)[idx], torch.gather(targets.reshape(b, -1), 1, idx)


def _lr_factor(step: int, total: int, warmup: int, schedule: str) -> float:
    """The learning rate of `step` (0-based) as a share of the configured one."""
    if step < warmup:
        return (step + 1) / (warmup + 1)
    if schedule == "cosine":
        span = max(total - warmup, 1)
        return 0.5 * (1.0 + math.cos(math.pi * min(step - warmup, span) / span))
    return 1.0


def _step_generator(seed: int, step: int, rank: int) -> torch.Generator:
    state = np.random.SeedSequence([seed, step, rank]).generate_state(2, dtype=np.uint32)
    return torch.Generator().manual_seed(int(state[0]) << 32 | int(state[1]))


# ---------------------------------------------------------------------------------- checkpoint


def _save(path: Path, payload: dict) -> None:
    """Write a checkpoint atomically: the previous one stays intact if the write fails."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_open(path) as fh:
        torch.save(payload, fh)


def load_checkpoint(path, map_location="cpu") -> dict:
    """Read a checkpoint written by :func:`train`.

    Parameters
    ----------
    path : str or os.PathLike
        The checkpoint file (``last.pt``, ``epoch-*.pt`` or ``model.pt``); ``~`` is expanded.
    map_location : str, torch.device, dict or callable, default="cpu"
        Where the tensors are loaded, as ``torch.load``'s `map_location`.

    Returns
    -------
    checkpoint : dict
        Keys ``model`` (a spec with ``sd``: ``make(ckpt["model"], load_sd=True)`` rebuilds the
        model), ``optimizer``, ``epoch``, ``step``, ``config``, ``losses``, ``format`` and
        ``version``. ``model.pt`` files hold only ``model``, ``config``, ``step``, ``format``
        and ``version``.

    Raises
    ------
    FileNotFoundError
        If `path` does not exist.
    OSError
        If `path` cannot be read or is not a torch checkpoint (also when ``torch.load``
        rejects `map_location`).
    ValueError
        If it is not an occgp.iln checkpoint (not a dict, or another ``format``), or has
        another ``version``.
    """
    path = Path(os.path.expanduser(str(path)))
    try:
        ckpt = torch.load(path, map_location=map_location, weights_only=True)
    except FileNotFoundError:
        raise FileNotFoundError(f"checkpoint {str(path)!r} does not exist") from None
    except Exception as exc:  # torch raises many types for a corrupt file
        raise OSError(f"cannot read checkpoint {str(path)!r}: {exc}") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        raise ValueError(f"{str(path)!r} is not an occgp.iln checkpoint (format {CHECKPOINT_FORMAT!r})")
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise ValueError(f"checkpoint {str(path)!r} has version {ckpt.get('version')!r}, expected {CHECKPOINT_VERSION}")
    return ckpt


# ---------------------------------------------------------------------------------- training


def _setup_distributed(device: torch.device):
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return 0, 1, device, False
    rank = int(os.environ["RANK"])
    local_rank = int(os.environ.get("LOCAL_RANK", rank))
    if device.type == "cuda":
        device = torch.device("cuda", local_rank)
        torch.cuda.set_device(device)
    created = False
    if not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo", rank=rank, world_size=world)
        created = True
    return dist.get_rank(), dist.get_world_size(), device, created


def _hardware(device, world: int) -> str:
    """Where training runs, in words: processor, threads, torch version, device, processes."""
    import platform

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((line.split(":", 1)[1].strip() for line in f
                        if line.startswith("model name")), cpu)
    except OSError:
        pass
    where = str(device)
    if device.type == "cuda":
        where = f"{device} ({torch.cuda.get_device_name(device)})"
    return (f"{cpu}, {os.cpu_count()} cores, {torch.get_num_threads()} torch threads, "
            f"torch {torch.__version__}, device {where}, {world} process(es)")


def train(config: dict) -> dict:
    """Train a range-image model (see the module docstring for the configuration).

    Parameters
    ----------
    config : dict
        Configuration; missing keys take the defaults of ``DEFAULTS``.

    Returns
    -------
    result : dict
        ``model`` (the trained model, unwrapped, on the training device), ``losses`` (the loss of
        every step run here, averaged over processes), ``step`` (steps done in all, including
        those before a resume) and ``checkpoint`` (path of ``last.pt`` or None).

    Raises
    ------
    TypeError, ValueError
        If a configuration value has a wrong type or value (the message names it), or the model
        has no parameters to train (``bilinear``).
    OSError
        If the shard folder, a shard or the checkpoint to resume from cannot be read, or a
        checkpoint cannot be written.

    Notes
    -----
    The checkpoints (``last.pt``, ``model.pt``) are written atomically: the previous file
    stays intact if the write fails (full disk, interrupted run).
    """
    cfg = _merge(config)
    chk = _check_config(cfg)
    device = _device(cfg["device"])
    resume = None
    if cfg["resume"] is not None:
        resume = load_checkpoint(cfg["resume"])
    inputs, targets, lidar = load_data(cfg, chk)
    in_model = lidar_model(lidar, chk["input"])
    out_models = [lidar_model(lidar, size) for size in chk["targets"]]

    rank, world, device, created = _setup_distributed(device)
    try:
        return _run(cfg, chk, device, rank, world, resume, inputs, targets, in_model, out_models)
    finally:
        if created:
            dist.destroy_process_group()


def _run(cfg, chk, device, rank, world, resume, inputs, targets, in_model, out_models):
    seed = chk["seed"]
    torch.manual_seed(seed)
    if resume is not None:
        spec = resume["model"]
    else:
        spec = copy.deepcopy(cfg["model"])
        args = spec.setdefault("args", {}) or {}
        spec["args"] = args
        if isinstance(args, dict) and spec.get("name") != "edsr-baseline":
            args.setdefault("max_range", float(in_model.max_range))
            args.setdefault("wrap", float(in_model.horizontal_fov) >= 360.0)
    model = make(spec, load_sd=resume is not None)
    if not isinstance(model, RangeModel):
        raise ValueError(f"config['model'] must be a range-image model (iln, liif), got {spec.get('name')!r}")
    if not any(True for _ in model.parameters()):
        raise ValueError(f"config['model'] {spec.get('name')!r} has no parameters to train")
    model.to(device)
    max_range = model.max_range
    optimizer = torch.optim.Adam(model.parameters(), lr=chk["lr"])
    if resume is not None:
        optimizer.load_state_dict(resume["optimizer"])
    net = model
    if world > 1:
        net = DistributedDataParallel(model, device_ids=[device.index] if device.type == "cuda" else None)

    x_all = torch.from_numpy(inputs) / max_range
    y_all = [torch.from_numpy(t) / max_range for t in targets]
    tables = [_query_table(in_model, m) for m in out_models]
    # queries per image and target size: split evenly, the remainder to the first sizes
    split = [chk["queries"] // len(tables) + (k < chk["queries"] % len(tables))
             for k in range(len(tables))]
    sampler = DistributedSampler(range(len(x_all)), num_replicas=world, rank=rank, shuffle=True,
                                 seed=seed, drop_last=False)
    bs = chk["batch_size"]
    steps_per_epoch = math.ceil(len(sampler) / bs)
    total = chk["epochs"] * steps_per_epoch
    if chk["max_steps"] is not None:
        total = min(total, chk["max_steps"])
    step = 0
    losses: list[float] = []
    if resume is not None:
        step = int(resume["step"])
        if int(resume.get("steps_per_epoch", steps_per_epoch)) != steps_per_epoch:
            raise ValueError(
                f"config['resume'] checkpoint has {resume['steps_per_epoch']} steps per epoch, this "
                f"configuration {steps_per_epoch}: use the same data, batch_size and processes"
            )
    # wall-clock seconds of training, summed over resumes, and where it ran
    seconds_before = float(resume.get("train_seconds", 0.0)) if resume is not None else 0.0
    started = time.perf_counter()
    hardware = _hardware(device, world)
    out_dir = cfg["output"]["dir"]
    out_dir = Path(os.path.expanduser(str(out_dir))) if out_dir is not None else None
    last = out_dir / "last.pt" if out_dir is not None else None

    def save(epoch: int) -> None:
        if last is None or rank != 0:
            return
        _save(last, {
            "format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION,
            "model": model.spec(), "optimizer": optimizer.state_dict(), "epoch": epoch,
            "step": step, "steps_per_epoch": steps_per_epoch, "config": _plain(cfg),
            "losses": [float(v) for v in losses], "world_size": world,
            "train_seconds": seconds_before + time.perf_counter() - started,
            "hardware": hardware,
        })

    from tqdm.auto import tqdm

    show = cfg["progress"]
    bar = tqdm(total=total, initial=min(step, total), desc="iln train", unit="step",
               disable=(rank != 0) or (None if show is None else not show))
    net.train()
    running = None
    try:
        while step < total:
            epoch, k = divmod(step, steps_per_epoch)
            sampler.set_epoch(epoch)
            order = list(sampler)[k * bs:]
            for s in range(0, len(order), bs):
                if step >= total:
                    break
                idx = torch.tensor(order[s:s + bs])
                x = x_all[idx].to(device)
                gen = _step_generator(seed, step, rank)
                drawn = [sample_hard_queries(x, y[idx].to(device), table, n, chk["hard_fraction"],
                                             gen, model.wrap)
                         for y, table, n in zip(y_all, tables, split) if n > 0]
                q = torch.cat([d[0] for d in drawn], dim=1)
                t = torch.cat([d[1] for d in drawn], dim=1)
                for group in optimizer.param_groups:
                    group["lr"] = chk["lr"] * _lr_factor(step, total, chk["warmup"], chk["schedule"])
                loss = net(x, q, target=t)
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
                value = loss.detach()
                if world > 1:
                    dist.all_reduce(value)
                    value = value / world
                value = float(value)
                losses.append(value)
                step += 1
                running = value if running is None else 0.9 * running + 0.1 * value
                bar.update(1)
                bar.set_postfix(loss=f"{running:.4f}")
                every = chk["checkpoint_every"]
                if every and step % every == 0:
                    save(epoch)
                if step % steps_per_epoch == 0:
                    logger.info("iln train: epoch %d done, step %d, loss %.5f", epoch + 1, step, running)
                    save(epoch + 1)
    finally:
        bar.close()
    save(step // steps_per_epoch)
    if out_dir is not None and rank == 0:
        _save(out_dir / "model.pt", {
            "format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION,
            "model": model.spec(), "step": step, "config": _plain(cfg),
            "train_seconds": seconds_before + time.perf_counter() - started,
            "hardware": hardware,
        })
    return {"model": model, "losses": losses, "step": step, "checkpoint": str(last) if last else None}


def _plain(cfg: dict) -> dict:
    """The config with paths as str (torch.load(weights_only=True) reads it back)."""
    def conv(v):
        if isinstance(v, dict):
            return {str(k): conv(x) for k, x in v.items()}
        if isinstance(v, (list, tuple)):
            return [conv(x) for x in v]
        if isinstance(v, os.PathLike):
            return str(v)
        return v
    return conv(cfg)


def train_from_yaml(path) -> dict:
    """Read a YAML configuration file and :func:`train` with it.

    Parameters
    ----------
    path : str or os.PathLike
        A YAML file holding one mapping, the configuration :func:`train` takes (missing keys
        take the defaults of ``DEFAULTS``); ``~`` is expanded.

    Returns
    -------
    result : dict
        What :func:`train` returns: ``model``, ``losses``, ``step`` and ``checkpoint``.

    Raises
    ------
    OSError
        If `path` cannot be read or is not a regular file (a named pipe, a
        device), or as :func:`train`.
    ValueError
        If the file is larger than 1 MiB or not valid YAML of a mapping, or as
        :func:`train`.
    TypeError
        As :func:`train`.
    """
    import yaml

    path = Path(os.path.expanduser(str(path)))
    try:
        text = read_regular(path, limit=MAX_YAML_BYTES, what="a configuration").decode("utf-8")
    except OSError as exc:
        raise type(exc)(f"cannot read the configuration {str(path)!r}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ValueError(f"configuration {str(path)!r} is not UTF-8 text (a YAML file)") from None
    try:
        config = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ValueError(f"configuration {str(path)!r} is not valid YAML: {exc}") from None
    if not isinstance(config, dict):
        raise ValueError(f"configuration {str(path)!r} must be a YAML mapping, got {type(config).__name__}")
    return train(config)
