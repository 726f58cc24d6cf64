"""The range-image shards :func:`occgp.iln.training.train` reads: the ``.npz`` files of a
folder (or of its split subfolder), checked, with the LiDAR fields they were made with."""

from __future__ import annotations

import glob
import json
import numbers
import os
import zipfile
import zlib
from pathlib import Path
from types import SimpleNamespace

import numpy as np

__all__ = ["load_data", "lidar_model", "read_shards", "shard_files"]

_SHARD_FORMAT = "occgp.iln.shard"


def shard_files(folder: Path, split: str) -> list[Path]:
    if not folder.is_dir():
        raise FileNotFoundError(f"config['data']['folder'] {str(folder)!r} is not a folder")
    sub = folder / split
    if sub.is_dir() and glob.glob(str(sub / "*.npz")):
        folder = sub
    files = sorted(Path(p) for p in glob.glob(str(folder / "*.npz")))
    if not files:
        raise FileNotFoundError(f"no .npz shards in {str(folder)!r} (nor in its {split!r} subfolder)")
    return files


def read_shards(files: list[Path], keys: list[str]) -> tuple[dict, dict]:
    """Arrays of `keys` concatenated over the shards, and the lidar fields; checks every entry."""
    arrays: dict[str, list] = {k: [] for k in keys}
    lidar = None
    for f in files:
        try:
            z = np.load(f, allow_pickle=False)
        except (ValueError, zipfile.BadZipFile, EOFError, OSError) as exc:
            raise OSError(f"cannot read shard {str(f)!r}: not an .npz archive ({exc})") from None
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise OSError(f"cannot read shard {str(f)!r}: not an .npz archive (a single .npy array)")
        try:
            with z:
                names = set(z.files)
                missing = [k for k in ("format", "lidar", *keys) if k not in names]
                if missing:
                    raise ValueError(f"shard {str(f)!r} lacks the entries {missing}")
                if str(z["format"]) != _SHARD_FORMAT:
                    raise ValueError(f"shard {str(f)!r} has format {str(z['format'])!r}, expected {_SHARD_FORMAT!r}")
                text = str(z["lidar"])
                for k in keys:
                    a = z[k]
                    rows, cols = (int(s) for s in k[1:].split("x"))
                    if a.dtype != np.float32 or a.ndim != 3 or a.shape[1:] != (rows, cols):
                        raise ValueError(
                            f"shard {str(f)!r} entry {k!r} must be float32 (n, {rows}, {cols}), "
                            f"got {a.dtype} {a.shape}"
                        )
                    arrays[k].append(a)
        except (zipfile.BadZipFile, EOFError, OSError, zlib.error) as exc:
            raise OSError(f"cannot read shard {str(f)!r}: {exc}") from None
        try:
            fields = json.loads(text)
        except ValueError:
            raise ValueError(f"shard {str(f)!r} has a 'lidar' entry that is not JSON") from None
        if lidar is None:
            lidar = fields
        elif fields != lidar:
            raise ValueError(f"shard {str(f)!r} has another LidarModel ({fields}) than the first ({lidar})")
    out = {k: np.concatenate(v) for k, v in arrays.items()}
    n = {k: len(v) for k, v in out.items()}
    if len(set(n.values())) != 1:
        raise ValueError(f"shards hold different numbers of images per size: {n}")
    return out, lidar


def lidar_model(fields: dict, size: tuple[int, int]):
    try:
        from ._range import LidarModel
    except ImportError:  # pragma: no cover - until occgp.iln._range lands
        return SimpleNamespace(rows=size[0], cols=size[1], vertical_fov=tuple(fields["vertical_fov"]),
                               horizontal_fov=float(fields["horizontal_fov"]),
                               max_range=float(fields["max_range"]))
    return LidarModel(size[0], size[1], tuple(fields["vertical_fov"]), fields["horizontal_fov"],
                      fields["max_range"])


def load_data(cfg: dict, chk: dict):
    d = cfg["data"]
    folder = Path(os.path.expanduser(str(d["folder"])))
    files = shard_files(folder, d["split"])
    keys = [f"r{s[0]}x{s[1]}" for s in (chk["input"], *chk["targets"])]
    if keys[0] in keys[1:]:
        raise ValueError(f"config['data']['input'] and ['target'] must differ, both hold {keys[0][1:]}")
    arrays, lidar = read_shards(files, keys)
    images = [arrays[k] for k in keys]
    if chk["max_images"] is not None:
        images = [a[: chk["max_images"]] for a in images]
    for name, a in zip(("input",) + ("target",) * len(chk["targets"]), images):
        if len(a) == 0:
            raise ValueError(f"the shards in {str(folder)!r} hold no {name} images")
        if not np.isfinite(a).all() or (a < 0).any():
            raise ValueError(f"the {name} images of the shards in {str(folder)!r} must be finite and >= 0")
    return images[0], images[1:], lidar
