from .knn import _log_odds  # noqa
