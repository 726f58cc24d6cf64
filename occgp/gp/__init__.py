"""Gaussian-process occupancy maps.

* kernels with ARD length scales and log-space hyper-parameters
  (:class:`SquaredExponential`, :class:`Matern32`, :class:`SparseKernel`);
* integral kernels between points and line segments (:func:`integral_kernel`)
  with adaptive-order quadrature (:class:`ClenshawCurtis`, :class:`Simpson`);
* :class:`GPOMIK`, the GP occupancy map with integral kernels (one
  factorised covariance for all queries, Cholesky updates, spatial cells, KL
  active sampling), and :class:`GPOM`, the earlier map with a local GP per
  query; both turn the latent GP into probabilities by PLSC
  (:func:`fit_plsc`);
* :class:`GPMixture`, a mixture of GPOMIK experts (Kim & Kim): hits
  clustered by :class:`LineTracking`, :class:`DirichletProcessClustering` or
  :class:`PlaneClustering`, beams assigned by :func:`assign_beams`, tiny
  clusters merged by :func:`merge_small_clusters`, predictions merged by a
  committee rule (:func:`combine_predictions`);
* :func:`thin_observations`, the policy by which the GP maps keep a budget of
  observations from a dense log;
* the log-odds :class:`OccupancyGrid` baseline and :func:`predict_grid`.
"""

from ._beams import assign_beams, merge_small_clusters
from ._clustering import DirichletProcessClustering
from ._lines import LineTracking
from ._planes import PlaneClustering
from ._committee import COMBINE_RULES, combine_predictions
from ._gpom import GPOM
from ._gpomik import GPOMIK
from ._mixture import GPMixture
from ._grid_eval import grid_points, predict_grid
from ._occupancy_grid import OccupancyGrid
from ._integral_kernel import integral_kernel
from ._kernels import Matern32, SparseKernel, SquaredExponential
from ._observations import Observations, observations_from_scans
from ._plsc import fit_plsc, loo_predictions, plsc_proba
from ._quadrature import ClenshawCurtis, Simpson, clenshaw_curtis, simpson
from ._thinning import thin_observations

__all__ = [
    "SquaredExponential", "Matern32", "SparseKernel",
    "integral_kernel", "ClenshawCurtis", "Simpson", "clenshaw_curtis", "simpson",
    "GPOMIK", "GPOM", "OccupancyGrid", "grid_points", "predict_grid",
    "Observations", "observations_from_scans", "thin_observations",
    "loo_predictions", "fit_plsc", "plsc_proba",
    "GPMixture", "LineTracking", "DirichletProcessClustering", "PlaneClustering",
    "assign_beams", "merge_small_clusters", "COMBINE_RULES", "combine_predictions",
]
