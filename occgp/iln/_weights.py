"""The models that ship with occgp (``occgp/iln/weights/``; see its README)."""

from __future__ import annotations

from pathlib import Path

#: The shipped checkpoints, by model name; each is ``model.pt`` of an ``occgp iln train`` run
#: (its spec and state_dict, its configuration, training seconds and hardware).
WEIGHTS = {"selector": "selector.pt", "iln": "iln_small.pt", "liif": "liif_small.pt"}
FOLDER = Path(__file__).resolve().parent / "weights"


def pretrained(name: str = "selector", *, device="cpu"):
    """A model trained by occgp's own command and shipped with the package.

    ``selector`` (the default, and the model ``"pretrained"`` names elsewhere
    in :mod:`occgp.iln`) is the candidate selector of
    ``occgp/iln/configs/selector.yaml``
    (:class:`~occgp.iln.models.CandidateSelector`: inverse bilinear
    interpolation, replaced by a copy or a planar extension of a neighbouring
    row or column, or by no return, where a small network is confident),
    trained on simulated 16x1024 inputs with 64x1024 and 128x2048 targets,
    its thresholds chosen on held-out training scenes. ``iln`` is the small
    ILN of ``occgp/iln/configs/small.yaml`` and ``liif`` the LIIF-style
    baseline of ``small_liif.yaml``, trained with the same budget (500 steps
    of 4 images x 16,384 queries) on 500 simulated 16x1024 -> 64x1024
    range-image pairs. ``occgp/iln/weights/README.md`` records the commands,
    the seeds, the training times and the hardware.

    Parameters
    ----------
    name : {"selector", "iln", "liif"}, default="selector"
        Which model.
    device : str or torch.device, default="cpu"
        Where to put it.

    Returns
    -------
    model : occgp.iln.models.RangeModel
        In evaluation mode; ``model.predict(range_image, queries)`` up-samples.

    Raises
    ------
    ValueError
        If `name` is not a shipped model.
    OSError
        If its file is missing from this installation, or is not an
        ``occgp iln train`` checkpoint.
    ImportError
        If PyTorch is not installed.
    """
    if not isinstance(name, str) or name not in WEIGHTS:
        raise ValueError(f"name must be one of {sorted(WEIGHTS)}, got {name!r}")
    from .models import make
    from .training import load_checkpoint

    path = FOLDER / WEIGHTS[name]
    if not path.is_file():
        raise OSError(f"the shipped weights {path} are missing from this installation "
                      f"(reinstall occgp, or train a model with `occgp iln train`)")
    try:
        checkpoint = load_checkpoint(path)
    except ValueError as exc:
        raise OSError(f"{path}: {exc}") from None
    model = make(checkpoint["model"], load_sd=True).to(device)
    return model.eval()
