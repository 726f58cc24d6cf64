"""Comparison rows as records and as a plain-text table."""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np

from ._protocols import MapResult

__all__ = ["rows_to_records", "format_table"]

_LABELS = {
    "method": "method", "data_fraction": "data", "auc": "AUC", "mse": "MSE",
    "acc_occupied": "acc occ", "acc_free": "acc free", "tpr_fdr_auc": "TPR-FDR AUC",
    "seconds": "time [s]", "n_scans": "scans", "n_points": "points",
    "n_test": "test points", "unknown_fraction": "unknown",
}
_DEFAULT_COLUMNS = ("method", "data_fraction", "auc", "mse", "acc_occupied",
                    "acc_free", "tpr_fdr_auc", "seconds")


def rows_to_records(rows: Iterable[MapResult | Mapping[str, Any]]) -> list[dict[str, Any]]:
    """Rows as plain dicts, without the built maps.

    Parameters
    ----------
    rows : iterable of MapResult or dict
        Rows from :func:`compare_methods` or :func:`equal_time_comparison`.

    Returns
    -------
    records : list of dict
        One dict per row, ready for ``pandas.DataFrame`` or
        :class:`csv.DictWriter`.

    Raises
    ------
    TypeError
        If a row is neither a MapResult nor a mapping.

    Examples
    --------
    >>> row = MapResult("m", 0.9, 0.1, 0.8, 0.95, 0.85, 1.5, 2, 100, 40, 0.0)
    >>> list(rows_to_records([row])[0])[:4]
    ['method', 'auc', 'mse', 'acc_occupied']
    """
    records = []
    for i, row in enumerate(rows):
        if not isinstance(row, (MapResult, Mapping)):
            raise TypeError(f"rows[{i}] must be a MapResult or a dict, "
                            f"got {type(row).__name__}")
        rec = row._asdict() if isinstance(row, MapResult) else dict(row)
        rec.pop("map", None)
        records.append(rec)
    return records


def _format_cell(column, value, floatfmt):
    if isinstance(value, (float, np.floating)):
        return f"{value:.0%}" if column == "data_fraction" else format(value, floatfmt)
    return str(value)


def format_table(rows: Iterable[MapResult | Mapping[str, Any]],
                 columns: Sequence[str] | None = None, floatfmt: str = ".3f") -> str:
    """Format rows as a plain-text table with aligned columns.

    Text columns are left-aligned and numeric ones right-aligned;
    ``data_fraction`` prints as a percentage. Built maps are never printed.

    Parameters
    ----------
    rows : iterable of MapResult or dict
        Rows from :func:`compare_methods` or :func:`equal_time_comparison`.
    columns : sequence of str, optional
        Fields to show, in order. Default: method, data_fraction, auc, mse,
        acc_occupied, acc_free, tpr_fdr_auc, seconds.
    floatfmt : str, default=".3f"
        Format specification of floats.

    Returns
    -------
    table : str
        A header, a rule of dashes and one line per row, all of one width.

    Raises
    ------
    ValueError
        If a column is missing from a row.
    TypeError
        If a row is neither a MapResult nor a mapping.

    Examples
    --------
    >>> row = MapResult("BGK", 0.881, 0.119, 0.378, 0.979, 0.7, 3.06, 12, 42000, 1000, 0.1)
    >>> print(format_table([row], columns=["method", "auc", "seconds"]))
    method    AUC  time [s]
    ------  -----  --------
    BGK     0.881     3.060
    """
    records = rows_to_records(rows)
    columns = list(_DEFAULT_COLUMNS if columns is None else columns)
    for i, rec in enumerate(records):
        missing = [c for c in columns if c not in rec]
        if missing:
            raise ValueError(f"columns {missing} are not in rows[{i}], "
                             f"which holds {list(rec)}")
    header = [_LABELS.get(c, str(c)) for c in columns]
    cells = [[_format_cell(c, rec[c], floatfmt) for c in columns] for rec in records]
    numeric = [all(isinstance(rec[c], (int, float, np.number)) for rec in records)
               for c in columns]
    widths = [max([len(h)] + [len(r[j]) for r in cells]) for j, h in enumerate(header)]

    def line(items):
        return "  ".join(s.rjust(w) if num else s.ljust(w)
                         for s, w, num in zip(items, widths, numeric))

    return "\n".join([line(header), "  ".join("-" * w for w in widths)]
                     + [line(r) for r in cells])
