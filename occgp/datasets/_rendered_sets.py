"""The k-NN paper's 20 stereo data sets, rendered and matched by StereoSGBM
(:func:`rendered_stereo_datasets`, :class:`RenderedStereoDataset`); the pipeline they
run is in ``_sgbm.py``."""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import NamedTuple

from .._validation import check_int
from ..io import Scan
from ._render import StereoPair, StereoRig
from ._sgbm import render_orbit, stereo_scans
from ._stereo import ENVIRONMENTS, TETROMINOES, TetrominoScene, tetromino_scene

__all__ = ["RenderedStereoDataset", "rendered_stereo_datasets"]


class RenderedStereoDataset(NamedTuple):
    """One of the paper's 20 data sets, rendered and matched (:func:`rendered_stereo_datasets`).

    Cheap to make; :meth:`scene`, :meth:`render` and :meth:`scans` build it on demand.

    Attributes
    ----------
    layout : str
    texture : bool
    environment : str
    scene_seed : int
        Seed of :func:`~occgp.datasets.tetromino_scene`.
    seed : int
        Seed of the renderer's sensor noise (and of pose errors).
    half : str
        ``"tune"`` or ``"test"``: the half of the 20 data sets that chooses
        defaults and the half that reports on them (each layout, texture and
        environment is in both halves).
    """

    layout: str
    texture: bool
    environment: str
    scene_seed: int
    seed: int
    half: str

    @property
    def name(self) -> str:
        """``"<layout>_<textured|plain>_<environment>"``."""
        return f"{self.layout}_{'textured' if self.texture else 'plain'}_{self.environment}"

    def scene(self) -> TetrominoScene:
        """Build the data set's :func:`~occgp.datasets.tetromino_scene`.

        Returns
        -------
        scene : TetrominoScene
        """
        return tetromino_scene(self.layout, texture=self.texture, environment=self.environment,
                               seed=self.scene_seed)

    def render(self, rig: StereoRig | None = None, **kwargs) -> list[StereoPair]:
        """Render the keyframes: ``render_orbit(self.scene(), rig, seed=self.seed, **kwargs)``.

        Parameters
        ----------
        rig : StereoRig or None, default=None
        **kwargs
            Other :func:`render_orbit` arguments (`n_frames`, `orbits`,
            `radius`, `height`, `truth`, `n_jobs`); not `seed`.

        Returns
        -------
        pairs : list of StereoPair
        """
        return render_orbit(self.scene(), rig, seed=self.seed, **kwargs)

    def scans(self, params: Mapping[str, int] | None = None, *,
              rig: StereoRig | None = None, pairs: Sequence[StereoPair] | None = None,
              voxel: float | None = 0.1, pose_noise: tuple[float, float] | None = None,
              n_jobs: int | None = None, **kwargs) -> list[Scan]:
        """The data set's clouds for one StereoSGBM parameter set.

        Parameters
        ----------
        params : dict or None, default=None
            StereoSGBM parameters (:func:`match_stereo`).
        rig : StereoRig or None, default=None
        pairs : sequence of StereoPair or None, default=None
            Keyframes already rendered (:meth:`render`, with the same `rig`);
            None renders them.
        voxel, pose_noise, n_jobs
            As :func:`stereo_scans` (pose errors seeded by :attr:`seed`).
        **kwargs
            :func:`render_orbit` arguments when `pairs` is None.

        Returns
        -------
        scans : list of Scan
        """
        rig = StereoRig() if rig is None else rig
        if pairs is None:
            pairs = self.render(rig, n_jobs=n_jobs, **kwargs)
        elif kwargs:
            raise TypeError(f"render arguments {sorted(kwargs)} are not used when pairs are "
                            "given")
        return stereo_scans(pairs, rig, params, voxel=voxel, pose_noise=pose_noise,
                            seed=self.seed, n_jobs=n_jobs)


def rendered_stereo_datasets(seed: int = 0) -> list[RenderedStereoDataset]:
    """The paper's 20 data sets (5 layouts x 2 textures x 2 environments), to render.

    Data set ``j`` (layout outermost, then texture, textured first, then
    environment) builds its scene with seed ``20 * seed + j`` and renders
    with seed ``20 * seed + j`` too. Its half is ``"tune"`` when
    ``layout_index + texture + environment_index`` is even, else ``"test"``:
    10 and 10, each layout twice in each half, each texture and environment
    five times.

    Parameters
    ----------
    seed : int, default=0

    Returns
    -------
    datasets : list of RenderedStereoDataset
        Nothing is built.

    Raises
    ------
    TypeError, ValueError
        If `seed` is not a non-negative int.

    Examples
    --------
    >>> sets = rendered_stereo_datasets()
    >>> len(sets), sets[0].name, sets[0].half, sum(d.half == "tune" for d in sets)
    (20, 'I_textured_buildings', 'test', 10)
    """
    seed = check_int(seed, "seed", low=0)
    out = []
    for j, (a, texture, e) in enumerate(itertools.product(range(len(TETROMINOES)),
                                                         (True, False),
                                                         range(len(ENVIRONMENTS)))):
        half = "tune" if (a + int(texture) + e) % 2 == 0 else "test"
        out.append(RenderedStereoDataset(tuple(TETROMINOES)[a], texture, ENVIRONMENTS[e],
                                         20 * seed + j, 20 * seed + j, half))
    return out
