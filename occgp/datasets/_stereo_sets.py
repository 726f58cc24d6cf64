"""The k-NN paper's 20 simulated stereo data sets at several noise levels
(:func:`stereo_datasets`, :class:`StereoDataset`); the scenes and the camera are in
``_stereo.py``."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from .._validation import check_int, check_real
from ..io import Scan
from ._stereo import (ENVIRONMENTS, TETROMINOES, StereoCamera, TetrominoScene, simulate_stereo,
                      tetromino_scene)

__all__ = ["StereoDataset", "stereo_datasets"]


class StereoDataset(NamedTuple):
    """One simulated stereo data set: a scene, a camera noise level and seeds.

    Cheap to make; :meth:`scene` and :meth:`scans` build it on demand.

    Attributes
    ----------
    layout : str
    texture : bool
    environment : str
    depth_noise : float
        The camera's ``depth_noise`` (metres at 1 m).
    scene_seed : int
        Seed of :func:`tetromino_scene` (shared across noise levels).
    seed : int
        Seed of :func:`simulate_stereo` (distinct per data set).
    """

    layout: str
    texture: bool
    environment: str
    depth_noise: float
    scene_seed: int
    seed: int

    @property
    def name(self) -> str:
        """``"<layout>_<textured|plain>_<environment>_noise<depth_noise>"``."""
        return (f"{self.layout}_{'textured' if self.texture else 'plain'}_{self.environment}"
                f"_noise{self.depth_noise:g}")

    def scene(self) -> TetrominoScene:
        """Build the data set's :func:`tetromino_scene`.

        Returns
        -------
        scene : TetrominoScene
            ``tetromino_scene(layout, texture=texture, environment=environment,
            seed=scene_seed)``.

        Raises
        ------
        ValueError, TypeError
            As :func:`tetromino_scene`, for fields set to invalid values.
        """
        return tetromino_scene(self.layout, texture=self.texture, environment=self.environment,
                               seed=self.scene_seed)

    def camera(self, **kwargs) -> StereoCamera:
        """The data set's camera: ``StereoCamera(depth_noise=self.depth_noise, **kwargs)``.

        Parameters
        ----------
        **kwargs
            Other :class:`StereoCamera` arguments (`width`, `height`, `fov`,
            `max_depth`, `speckle`, `missing`); not `depth_noise`.

        Returns
        -------
        camera : StereoCamera

        Raises
        ------
        ValueError, TypeError
            As :class:`StereoCamera`, and TypeError for an unknown keyword or
            `depth_noise`.
        """
        return StereoCamera(depth_noise=self.depth_noise, **kwargs)

    def scans(self, camera: StereoCamera | None = None, **kwargs) -> list[Scan]:
        """Simulate the data set's scans with :func:`simulate_stereo`.

        ``simulate_stereo(self.scene(), camera, seed=self.seed, **kwargs)``.

        Parameters
        ----------
        camera : StereoCamera, default=None
            None: :meth:`camera` (the default camera at this data set's noise
            level). A given camera is used as it is, whatever its
            `depth_noise`.
        **kwargs
            Other :func:`simulate_stereo` arguments (`n_frames`, `orbits`,
            `radius`, `height`, `voxel`, `progress`); not `seed`.

        Returns
        -------
        scans : list of Scan
            As :func:`simulate_stereo`.

        Raises
        ------
        ValueError, TypeError
            As :meth:`scene` and :func:`simulate_stereo`.
        """
        return simulate_stereo(self.scene(), self.camera() if camera is None else camera,
                               seed=self.seed, **kwargs)


def stereo_datasets(noise_levels: ArrayLike = (0.005, 0.01, 0.02), *,
                    seed: int = 0) -> list[StereoDataset]:
    """The paper's 20 data sets (5 layouts x 2 textures x 2 environments) per noise level.

    Parameters
    ----------
    noise_levels : sequence of float, default=(0.005, 0.01, 0.02)
        Camera ``depth_noise`` values (metres at 1 m), each in [0, 1]; at
        least one.
    seed : int, default=0
        Data set ``j`` of the 20 builds its scene with seed ``20 * seed + j``
        (the same scene at every noise level); data set ``i`` of the list
        simulates with seed ``len(list) * seed + i`` (distinct).

    Returns
    -------
    datasets : list of StereoDataset
        ``20 * len(noise_levels)`` specs, noise level outermost, then
        layout, texture (True first), environment. Nothing is built.

    Raises
    ------
    TypeError
        If a noise level is not a real number or `seed` not an int.
    ValueError
        If `noise_levels` is empty or a level lies outside [0, 1].

    Examples
    --------
    >>> sets = stereo_datasets()
    >>> len(sets), sets[0].name, sets[-1].name
    (60, 'I_textured_buildings_noise0.005', 'S_plain_open_noise0.02')
    >>> len(sets[0].scans(StereoCamera(32, 18), n_frames=2))
    4
    """
    seed = check_int(seed, "seed", low=0)
    if isinstance(noise_levels, (str, bytes)) or not np.iterable(noise_levels):
        raise TypeError(f"noise_levels must be a sequence of real numbers, "
                        f"got {type(noise_levels).__name__}")
    levels = [check_real(v, f"noise_levels[{i}]", low=0.0, high=1.0, low_open=False,
                         high_open=False) for i, v in enumerate(noise_levels)]
    if not levels:
        raise ValueError("noise_levels must hold at least one noise level, got none")
    combos = [(layout, texture, env) for layout in TETROMINOES for texture in (True, False)
              for env in ENVIRONMENTS]
    n = len(levels) * len(combos)
    return [StereoDataset(layout, texture, env, level, len(combos) * seed + j,
                          n * seed + a * len(combos) + j)
            for a, level in enumerate(levels)
            for j, (layout, texture, env) in enumerate(combos)]
